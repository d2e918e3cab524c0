// Shared pieces of the browser tests: Chromium's flags, the run of one test script, a tiny
// check runner, PNG and zip decoding (node has zlib but no image or archive reader), and reading
// the page's status.
import { mkdtempSync, readdirSync, readFileSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { basename, join } from "node:path";
import { crc32, inflateRawSync, inflateSync } from "node:zlib";
import { chromium } from "playwright-core";

export const CHROMIUM_ARGS = [
  "--headless=new",
  "--no-sandbox",
  "--enable-unsafe-webgpu",
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  "--no-first-run",
  "--disable-quic",
  // Without these the WebGPU canvas is never composited in headless mode (chrome://gpu says
  // "WebGPU interop: Disabled") and screenshots show an empty canvas: SwiftShader's Vulkan and
  // GL give the compositor a GPU to share the canvas with.
  "--use-angle=swiftshader",
  "--enable-features=Vulkan",
  "--use-vulkan=swiftshader",
  // A page in a background or headless tab must not have its timers throttled: training runs
  // on them.
  "--disable-background-timer-throttling",
  "--disable-renderer-backgrounding",
  "--disable-backgrounding-occluded-windows",
];

export function assert(condition, message) {
  if (!condition) throw new Error(message);
}

/// Runs named checks, counting passes and failures; a failed check does not stop the others.
export class Checks {
  constructor() {
    this.passed = 0;
    this.failed = 0;
  }

  async check(name, body) {
    try {
      await body();
      this.passed += 1;
      console.log(`ok   ${name}`);
    } catch (e) {
      this.failed += 1;
      console.log(`FAIL ${name}: ${e.message}`);
    }
  }
}

/// Decodes an 8-bit grey, RGB or RGBA PNG into {width, height, channels, data} (data holds
/// `channels` bytes per pixel, rows top to bottom).
export function decodePng(png) {
  let pos = 8;
  let width = 0, height = 0, colourType = 0;
  const idat = [];
  while (pos < png.length) {
    const length = png.readUInt32BE(pos);
    const type = png.toString("latin1", pos + 4, pos + 8);
    const data = png.subarray(pos + 8, pos + 8 + length);
    if (type === "IHDR") {
      width = data.readUInt32BE(0);
      height = data.readUInt32BE(4);
      colourType = data[9];
      assert(data[8] === 8 && [0, 2, 6].includes(colourType) && data[12] === 0,
        `unsupported PNG (bit depth ${data[8]}, colour type ${colourType}, interlace ${data[12]})`);
    } else if (type === "IDAT") {
      idat.push(data);
    }
    pos += 12 + length;
  }
  const bpp = { 0: 1, 2: 3, 6: 4 }[colourType];
  const raw = inflateSync(Buffer.concat(idat));
  const stride = width * bpp;
  const out = Buffer.alloc(width * height * bpp);
  let prev = Buffer.alloc(stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const line = Buffer.from(raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1)));
    for (let i = 0; i < stride; i++) {
      const a = i >= bpp ? line[i - bpp] : 0, b = prev[i], c = i >= bpp ? prev[i - bpp] : 0;
      const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
      const predictor = [0, a, b, (a + b) >> 1, pa <= pb && pa <= pc ? a : pb <= pc ? b : c][filter];
      line[i] = (line[i] + predictor) & 255;
    }
    line.copy(out, y * stride);
    prev = line;
  }
  return { width, height, channels: bpp, data: out };
}

/// Distinct clearly coloured (not grey) pixel values of a screenshot: the UI around the frame
/// is grey with a few accent colours, a rendered frame has hundreds.
export function saturatedColours(png) {
  const { data, channels } = decodePng(png);
  const seen = new Set();
  for (let i = 0; i < data.length; i += channels) {
    const [r, g, b] = [data[i], data[i + 1], data[i + 2]];
    if (Math.max(r, g, b) - Math.min(r, g, b) > 40) seen.add((r << 16) | (g << 8) | b);
  }
  return seen.size;
}

/// The entries of a zip archive (stored or deflated) as a Map from name to bytes.
export function readZip(zip) {
  // The end-of-central-directory record is in the last 64 KiB + 22 bytes.
  let eocd = -1;
  for (let i = zip.length - 22; i >= Math.max(0, zip.length - 65558); i--) {
    if (zip.readUInt32LE(i) === 0x06054b50) { eocd = i; break; }
  }
  assert(eocd >= 0, "not a zip archive (no end of central directory)");
  const count = zip.readUInt16LE(eocd + 10);
  let pos = zip.readUInt32LE(eocd + 16);
  const entries = new Map();
  for (let n = 0; n < count; n++) {
    assert(zip.readUInt32LE(pos) === 0x02014b50, "damaged zip central directory");
    const method = zip.readUInt16LE(pos + 10);
    const compressed = zip.readUInt32LE(pos + 20);
    const nameLength = zip.readUInt16LE(pos + 28);
    const extraLength = zip.readUInt16LE(pos + 30);
    const commentLength = zip.readUInt16LE(pos + 32);
    const local = zip.readUInt32LE(pos + 42);
    const name = zip.toString("utf8", pos + 46, pos + 46 + nameLength);
    const dataStart = local + 30 + zip.readUInt16LE(local + 26) + zip.readUInt16LE(local + 28);
    const data = zip.subarray(dataStart, dataStart + compressed);
    assert(method === 0 || method === 8, `${name}: unsupported zip compression ${method}`);
    entries.set(name, method === 0 ? Buffer.from(data) : inflateRawSync(data));
    pos += 46 + nameLength + extraLength + commentLength;
  }
  return entries;
}

/// A zip archive of `files` (`[name, Buffer]` pairs), stored without compression: what a user
/// makes of a capture folder to drop it on the page as one file.
export function writeZip(files) {
  const locals = [];
  const central = [];
  let offset = 0;
  for (const [name, data] of files) {
    const nameBytes = Buffer.from(name, "utf8");
    const header = Buffer.alloc(30);
    header.writeUInt32LE(0x04034b50, 0);
    header.writeUInt16LE(20, 4);
    header.writeUInt32LE(crc32(data), 14);
    header.writeUInt32LE(data.length, 18);
    header.writeUInt32LE(data.length, 22);
    header.writeUInt16LE(nameBytes.length, 26);
    const entry = Buffer.alloc(46);
    entry.writeUInt32LE(0x02014b50, 0);
    entry.writeUInt16LE(20, 4);
    entry.writeUInt16LE(20, 6);
    entry.writeUInt32LE(crc32(data), 16);
    entry.writeUInt32LE(data.length, 20);
    entry.writeUInt32LE(data.length, 24);
    entry.writeUInt16LE(nameBytes.length, 28);
    entry.writeUInt32LE(offset, 42);
    locals.push(header, nameBytes, data);
    central.push(entry, nameBytes);
    offset += header.length + nameBytes.length + data.length;
  }
  const directory = Buffer.concat(central);
  const end = Buffer.alloc(22);
  end.writeUInt32LE(0x06054b50, 0);
  end.writeUInt16LE(files.length, 8);
  end.writeUInt16LE(files.length, 10);
  end.writeUInt32LE(directory.length, 12);
  end.writeUInt32LE(offset, 16);
  return Buffer.concat([...locals, directory, end]);
}

/// The page's status (`data-status`, a JSON object with a `state`; docs/web-app.md lists its
/// fields), or `{state: "unreadable", text}` when the attribute holds no JSON.
export function parseStatus(text) {
  try {
    const parsed = JSON.parse(text || "{}");
    return parsed && typeof parsed === "object" ? parsed : { state: "unreadable", text };
  } catch {
    return { state: "unreadable", text };
  }
}

export async function status(page) {
  return parseStatus(await page.evaluate(() => document.body.dataset.status || ""));
}

/// A status for messages.
export function show(status) {
  return JSON.stringify(status);
}

/// Waits until `predicate(status)` holds (polling the page); returns the status.
export async function waitForStatus(page, predicate, what, timeoutMs) {
  const start = Date.now();
  let last = {};
  while (Date.now() - start < timeoutMs) {
    last = await status(page);
    if (predicate(last)) return last;
    if (last.state === "error" || last.state === "crashed") throw new Error(`waiting for ${what}: the page says ${show(last)}`);
    await new Promise((r) => setTimeout(r, 250));
  }
  throw new Error(`waiting for ${what}: timed out after ${timeoutMs / 1000} s; status ${show(last)}`);
}

/// Waits until data-status is no longer a loading state; returns it.
export async function settledStatus(page, timeoutMs) {
  await page.waitForFunction(
    () => {
      try {
        return ["ready", "error", "crashed"].includes(JSON.parse(document.body.dataset.status).state);
      } catch {
        return false;
      }
    },
    null,
    { timeout: timeoutMs, polling: 250 },
  );
  return status(page);
}

/**
 * Runs one browser test script's body and ends the process with its result. Launches Chromium
 * (`CHROMIUM`, default /usr/bin/chromium) with our flags and a fresh profile, gives `body` the
 * browser context, counts a throw out of `body` as a failed check, and always closes the browser
 * and removes the profile (then runs `cleanup`). Prints `summary()` if given, the last
 * `consoleLines` lines of `consoleLog` when a check failed, and `name: N passed, M failed`; the
 * exit status is 1 when a check failed.
 */
export async function runBrowserTest(name, options, body) {
  const {
    checks, consoleLog, viewport = { width: 1024, height: 720 }, acceptDownloads = true, consoleLines = 60,
    summary, cleanup,
  } = options;
  const userDataDir = mkdtempSync(join(tmpdir(), `scribblefield-${name}-`));
  let context;
  try {
    context = await chromium.launchPersistentContext(userDataDir, {
      executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
      // Headless mode comes from --headless=new in the args, so the flags are exactly ours.
      headless: false,
      args: CHROMIUM_ARGS,
      viewport,
      acceptDownloads,
    });
    await body(context);
  } catch (e) {
    checks.failed += 1;
    console.log(`FAIL the test itself: ${e.stack || e.message}`);
  } finally {
    await context?.close().catch(() => {});
    rmSync(userDataDir, { recursive: true, force: true });
    cleanup?.();
  }
  if (summary) console.log(summary());
  if (checks.failed > 0) {
    console.log("--- browser console ---");
    for (const line of consoleLog.slice(-consoleLines)) console.log(line);
  }
  console.log(`${name}: ${checks.passed} passed, ${checks.failed} failed`);
  process.exit(checks.failed > 0 ? 1 : 0);
}

export async function openPage(context, pageUrl, label, consoleLog) {
  const page = await context.newPage();
  page.on("console", (m) => consoleLog.push(`[${label}] console.${m.type()}: ${m.text()}`));
  page.on("pageerror", (e) => consoleLog.push(`[${label}] page error: ${e.message}`));
  page.on("requestfailed", (r) => consoleLog.push(`[${label}] request failed: ${r.url()} ${r.failure()?.errorText}`));
  await page.goto(pageUrl, { waitUntil: "load" });
  return page;
}

/// Deletes every saved annotation of the page's origin: the IndexedDB stores and local storage.
export function clearSaves(page) {
  return page.evaluate(() => new Promise((resolve, reject) => {
    localStorage.clear();
    const open = indexedDB.open("scribblefield");
    open.onerror = () => reject(open.error);
    open.onsuccess = () => {
      const db = open.result;
      const stores = [...db.objectStoreNames];
      if (stores.length === 0) { db.close(); resolve(); return; }
      const tx = db.transaction(stores, "readwrite");
      for (const s of stores) tx.objectStore(s).clear();
      tx.oncomplete = () => { db.close(); resolve(); };
      tx.onerror = () => reject(tx.error);
    };
  }));
}

const VOID_CLASS = 255;

/// Chessboard-free distance (in pixels, 4-neighbour) from each pixel of a `w` x `h` class map to
/// the nearest pixel of another class, void or the image edge: where a careful annotator can
/// put the brush.
function distanceToBoundary(ids, w, h) {
  const d = new Int32Array(w * h).fill(1 << 20);
  const queue = [];
  for (let y = 0; y < h; y++) {
    for (let x = 0; x < w; x++) {
      const i = y * w + x, c = ids[i];
      const edge = x === 0 || y === 0 || x === w - 1 || y === h - 1;
      const differs = edge || ids[i - 1] !== c || ids[i + 1] !== c || ids[i - w] !== c || ids[i + w] !== c;
      if (c === VOID_CLASS || differs) { d[i] = 0; queue.push(i); }
    }
  }
  for (let q = 0; q < queue.length; q++) {
    const i = queue[q], x = i % w;
    for (const j of [x > 0 ? i - 1 : -1, x < w - 1 ? i + 1 : -1, i - w, i + w]) {
      if (j >= 0 && j < w * h && d[j] > d[i] + 1) { d[j] = d[i] + 1; queue.push(j); }
    }
  }
  return d;
}

/// One horizontal stroke per class of the ground-truth class map `ids` (`w` x `h`), through the
/// class's most interior pixel and staying `brushRadius` inside it:
/// [{class, points: [[x, y], ...]}] in frame pixels.
export function planFrameStrokes(ids, w, h, brushRadius) {
  const d = distanceToBoundary(ids, w, h);
  const best = new Map();
  for (let i = 0; i < w * h; i++) {
    const c = ids[i];
    if (c !== VOID_CLASS && (!best.has(c) || d[i] > d[best.get(c)])) best.set(c, i);
  }
  const strokes = [];
  for (const [c, i] of [...best.entries()].sort((a, b) => a[0] - b[0])) {
    const room = d[i] - brushRadius - 1;
    if (room < 1) continue;
    const [x, y] = [i % w + 0.5, Math.floor(i / w) + 0.5];
    const half = Math.min(room, 14);
    // Only as far as the class continues along the row.
    let left = 0, right = 0;
    while (left < half && d[i - left - 1] > brushRadius && ids[i - left - 1] === c) left++;
    while (right < half && d[i + right + 1] > brushRadius && ids[i + right + 1] === c) right++;
    strokes.push({ class: c, points: [[x - left, y], [x, y], [x + right, y]] });
  }
  return strokes;
}

/// Steps the page to `frame` with the arrow keys.
export async function goToFrame(page, frame) {
  const current = (await status(page)).frame;
  const key = frame > current ? "ArrowRight" : "ArrowLeft";
  for (let i = 0; i < Math.abs(frame - current); i++) await page.keyboard.press(key);
  await waitForStatus(page, (t) => t.frame === frame, `frame ${frame}`, 60_000);
}

/// Draws `stroke` (points in pixels of a `w` x `h` frame) with the mouse: select the class by
/// its number key, press, move, release.
export async function drawFrameStroke(page, stroke, w, h) {
  await page.keyboard.press(String(stroke.class + 1));
  await waitForStatus(page, (t) => t.class === stroke.class, `class ${stroke.class}`, 30_000);
  const [x0, y0, vw, vh] = (await status(page)).view;
  const toScreen = ([x, y]) => [x0 + (x / w) * vw, y0 + (y / h) * vh];
  const [first, ...rest] = stroke.points.map(toScreen);
  await page.mouse.move(...first);
  await page.mouse.down();
  for (const p of rest) await page.mouse.move(...p);
  await page.mouse.up();
}

/// The pack settings form shown when a capture is picked or dropped (`data-pack-setup`:
/// src/app/packing/setup.rs), or null when it is not shown.
export async function packSetup(page) {
  return page.evaluate(() => {
    const s = document.body.dataset.packSetup;
    return s ? JSON.parse(s) : null;
  });
}

/// Waits until the pack settings form (or its absence, null) satisfies `predicate`; returns it.
export async function waitForPackSetup(page, predicate, what, timeoutMs) {
  const start = Date.now();
  let last = null;
  while (Date.now() - start < timeoutMs) {
    last = await packSetup(page);
    if (predicate(last)) return last;
    await new Promise((r) => setTimeout(r, 250));
  }
  throw new Error(`waiting for ${what}: timed out after ${timeoutMs / 1000} s; the pack settings are ` +
    JSON.stringify(last && { values: last.values, errors: last.errors, estimate: last.estimate }));
}

/// Clicks the middle of a control of the pack settings form (`rects` in data-pack-setup).
export async function clickPackControl(page, control) {
  const setup = await packSetup(page);
  assert(setup && setup.rects[control], `no pack settings control ${control}: ${JSON.stringify(setup)}`);
  const [x, y, w, h] = setup.rects[control];
  await page.mouse.click(x + w / 2, y + h / 2);
}

/// Types `value` into a field of the pack settings form in place of what it holds, and waits
/// until the form has it.
export async function setPackField(page, field, value) {
  const before = (await packSetup(page)).values[field];
  await clickPackControl(page, field);
  await page.keyboard.press("End");
  for (let i = 0; i < before.length; i++) await page.keyboard.press("Backspace");
  await page.keyboard.type(value);
  return waitForPackSetup(page, (s) => s && s.values[field] === value, `${field} = ${value} in the pack settings`,
    60_000);
}

/// Closes the pack settings with their Cancel button, clicking again where a click was lost
/// while the page was busy (as `startPack` does).
export async function cancelPackSetup(page) {
  for (let attempt = 1; ; attempt++) {
    await clickPackControl(page, "cancel");
    try {
      await waitForPackSetup(page, (s) => s === null, "the settings to close", 20_000);
      return;
    } catch (e) {
      if (attempt === 3) throw e;
    }
  }
}

/// Waits for the pack settings of a capture just picked or dropped, then starts packing with
/// them (the form's Start button); returns the settings as they were.
export async function startPack(page, timeoutMs) {
  const setup = await waitForPackSetup(page, (s) => s && s.estimate, "the pack settings and their estimate",
    timeoutMs);
  // A click can be lost while the page is busy (annotate.mjs): click again.
  for (let attempt = 1; ; attempt++) {
    await clickPackControl(page, "start");
    try {
      await waitForPackSetup(page, (s) => s === null, "packing to start", 20_000);
      return setup;
    } catch (e) {
      if (attempt === 3) throw e;
    }
  }
}

/// Every file below `dir`, named by its path from `dir`'s parent (`prefix/...`), for a zip.
export function filesUnder(dir, prefix) {
  return readdirSync(dir, { withFileTypes: true }).flatMap((e) => e.isDirectory()
    ? filesUnder(join(dir, e.name), `${prefix}/${e.name}`)
    : [[`${prefix}/${e.name}`, readFileSync(join(dir, e.name))]]);
}

/// Drops a zip of the folder `dir` on the page's canvas, as a user drops a file; returns the zip.
export async function dropZip(page, dir) {
  const zip = writeZip(filesUnder(dir, basename(dir)));
  const canvas = await page.$("#scribblefield");
  const dataTransfer = await page.evaluateHandle(([name, base64]) => {
    const bytes = Uint8Array.from(atob(base64), (c) => c.charCodeAt(0));
    const transfer = new DataTransfer();
    transfer.items.add(new File([bytes], name, { type: "application/zip" }));
    return transfer;
  }, [`${basename(dir)}.zip`, zip.toString("base64")]);
  await canvas.dispatchEvent("dragenter", { dataTransfer });
  await canvas.dispatchEvent("dragover", { dataTransfer });
  await canvas.dispatchEvent("drop", { dataTransfer });
  return zip;
}

/// What the latest pack took and its settings estimated (`data-pack-result`), or null.
export async function packResult(page) {
  return page.evaluate(() => JSON.parse(document.body.dataset.packResult || "null"));
}

/// Waits until a pack started on `page` (a page of its own: the scene open before is ready too)
/// has finished and its scene is open.
export async function waitForPacked(page, what, timeoutMs) {
  const start = Date.now();
  while (!(await packResult(page))) {
    const t = await status(page);
    if (t.state === "error" || t.state === "crashed") throw new Error(`waiting for ${what}: the page says ${show(t)}`);
    assert(Date.now() - start < timeoutMs, `waiting for ${what}: not packed after ${timeoutMs / 1000} s`);
    await new Promise((r) => setTimeout(r, 250));
  }
  return waitForStatus(page, (t) => t.state === "ready", what, timeoutMs);
}

/// Waits until the page shows an error (not waitForStatus, which stops at one); returns the status.
export async function waitForError(page, timeoutMs) {
  await page.waitForFunction(() => {
    try {
      return ["error", "crashed"].includes(JSON.parse(document.body.dataset.status).state);
    } catch {
      return false;
    }
  }, null, { timeout: timeoutMs, polling: 100 });
  return status(page);
}
