// Smoke test of the served web app in headless Chromium (WebGPU on SwiftShader): the demo scene
// loads, shows the expected frame count, the arrow keys step through frames, and a missing
// scene is reported in the page. Starts no server: run.sh does, or point E2E_URL at one.
//
//   E2E_URL      page to open, e.g. http://127.0.0.1:8080/ (required)
//   E2E_OUT      folder for screenshots (default /tmp/e2e)
//   E2E_FRAMES   frame count the loaded scene must have (default 36, the demo scene's)
//   CHROMIUM     browser binary (default /usr/bin/chromium)
import { mkdirSync, mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { inflateSync } from "node:zlib";
import { chromium } from "playwright-core";

const url = process.env.E2E_URL;
if (!url) {
  console.error("E2E_URL is not set: give the URL of the served page, e.g. E2E_URL=http://127.0.0.1:8080/");
  process.exit(2);
}
const outDir = process.env.E2E_OUT || "/tmp/e2e";
const expectedFrames = Number(process.env.E2E_FRAMES || 36);
const chromiumPath = process.env.CHROMIUM || "/usr/bin/chromium";
// Compiling the wasm and starting WebGPU on a CPU rasterizer is slow on a small machine.
const LOAD_TIMEOUT_MS = 180_000;
const STEP_TIMEOUT_MS = 15_000;
// Measured: about 10,000 with the demo frame on screen, about 340 for the UI with an error
// message (anti-aliased red text), 0 for an empty canvas.
const MIN_FRAME_COLOURS = 2000;

const CHROMIUM_ARGS = [
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
];

mkdirSync(outDir, { recursive: true });
const userDataDir = mkdtempSync(join(tmpdir(), "scribblefield-e2e-"));
const consoleLog = [];
let passed = 0;
let failed = 0;

async function check(name, body) {
  try {
    await body();
    passed += 1;
    console.log(`ok   ${name}`);
  } catch (e) {
    failed += 1;
    console.log(`FAIL ${name}: ${e.message}`);
  }
}

function assert(condition, message) {
  if (!condition) throw new Error(message);
}

/// Decodes an 8-bit RGB or RGBA PNG (what Chromium's screenshots are) into {width, height, rgba}.
function decodePng(png) {
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
      assert(data[8] === 8 && (data[9] === 2 || data[9] === 6) && data[12] === 0, "unexpected PNG format");
      colourType = data[9];
    } else if (type === "IDAT") {
      idat.push(data);
    }
    pos += 12 + length;
  }
  const bpp = colourType === 6 ? 4 : 3;
  const raw = inflateSync(Buffer.concat(idat));
  const stride = width * bpp;
  const rgba = Buffer.alloc(width * height * 4, 255);
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
    for (let x = 0; x < width; x++) line.copy(rgba, (y * width + x) * 4, x * bpp, x * bpp + 3);
    prev = line;
  }
  return { width, height, rgba };
}

/// Distinct clearly coloured (not grey) pixel values: the UI around the frame is grey with a
/// few accent colours, a rendered frame has hundreds.
function saturatedColours(png) {
  const { rgba } = decodePng(png);
  const seen = new Set();
  for (let i = 0; i < rgba.length; i += 4) {
    const [r, g, b] = [rgba[i], rgba[i + 1], rgba[i + 2]];
    if (Math.max(r, g, b) - Math.min(r, g, b) > 40) seen.add((r << 16) | (g << 8) | b);
  }
  return seen.size;
}

async function status(page) {
  return page.evaluate(() => document.body.dataset.status || "");
}

/// Waits until data-status is no longer a loading state; returns it.
async function settledStatus(page) {
  await page.waitForFunction(
    () => /^(ready|error|crashed)/.test(document.body.dataset.status || ""),
    null,
    { timeout: LOAD_TIMEOUT_MS, polling: 250 },
  );
  return status(page);
}

function statusField(statusText, name) {
  const match = statusText.match(new RegExp(`\\b${name}=(\\S+)`));
  return match ? match[1] : undefined;
}

async function openPage(context, pageUrl, label) {
  const page = await context.newPage();
  page.on("console", (m) => consoleLog.push(`[${label}] console.${m.type()}: ${m.text()}`));
  page.on("pageerror", (e) => consoleLog.push(`[${label}] page error: ${e.message}`));
  page.on("requestfailed", (r) => consoleLog.push(`[${label}] request failed: ${r.url()} ${r.failure()?.errorText}`));
  await page.goto(pageUrl, { waitUntil: "load" });
  return page;
}

let context;
try {
  context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: chromiumPath,
    // Headless mode comes from --headless=new in the args, so the flags are exactly ours.
    headless: false,
    args: CHROMIUM_ARGS,
    viewport: { width: 1280, height: 800 },
  });

  const page = await openPage(context, url, "demo");
  const started = Date.now();
  const loaded = await settledStatus(page);
  console.log(`page status after ${((Date.now() - started) / 1000).toFixed(1)} s: ${loaded}`);

  await check("the demo scene loads", async () => {
    assert(loaded.startsWith("ready"), `status is "${loaded}"`);
  });
  await check(`the scene has ${expectedFrames} frames`, async () => {
    assert(statusField(loaded, "frames") === String(expectedFrames), `status is "${loaded}"`);
    assert(statusField(loaded, "frame") === "0", `the first frame shown should be 0: "${loaded}"`);
  });
  await check("ArrowRight shows the next frame (visible in a screenshot), ArrowLeft the previous", async () => {
    assert(loaded.startsWith("ready"), "no scene to step through");
    await page.focus("#scribblefield");
    await page.keyboard.press("ArrowRight");
    await page.waitForFunction(() => / frame=1\b/.test(document.body.dataset.status), null, {
      timeout: STEP_TIMEOUT_MS,
    });
    const shot = await page.screenshot({ path: join(outDir, "smoke-frame1.png") });
    const colours = saturatedColours(shot);
    assert(colours >= MIN_FRAME_COLOURS, `the screenshot has ${colours} distinct saturated colours, ` +
      `fewer than the ${MIN_FRAME_COLOURS} of a visible frame: is the canvas blank?`);
    console.log(`     (screenshot: ${colours} distinct saturated colours)`);
    await page.keyboard.press("ArrowLeft");
    await page.waitForFunction(() => / frame=0\b/.test(document.body.dataset.status), null, {
      timeout: STEP_TIMEOUT_MS,
    });
  });
  await page.screenshot({ path: join(outDir, "smoke.png") });

  const missing = new URL(url);
  missing.hash = "scene=does-not-exist.scene.zip";
  const errorPage = await openPage(context, missing.href, "missing scene");
  const errorStatus = await settledStatus(errorPage);
  await check("a missing scene is reported with the URL and HTTP 404", async () => {
    assert(errorStatus.startsWith("error:"), `status is "${errorStatus}"`);
    assert(errorStatus.includes("does-not-exist.scene.zip"), `the message does not name the URL: "${errorStatus}"`);
    assert(errorStatus.includes("404"), `the message does not give the HTTP status: "${errorStatus}"`);
  });
  await errorPage.screenshot({ path: join(outDir, "smoke-missing-scene.png") });
} catch (e) {
  failed += 1;
  console.log(`FAIL the test could not run: ${e.message}`);
} finally {
  await context?.close().catch(() => {});
  rmSync(userDataDir, { recursive: true, force: true });
}

console.log(`screenshots in ${outDir}`);
if (failed > 0) {
  console.log("--- browser console ---");
  for (const line of consoleLog) console.log(line);
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed > 0 ? 1 : 0);
