// End-to-end test of keeping annotations (saves in IndexedDB) in headless Chromium: an old build's
// local-storage save is migrated; two tabs on one scene (the second follows read-only, takes
// over when the first closes, and a reload loses no stroke); a corrupted save is set aside and
// the next edit leaves it alone; a full disk (IndexedDB put stubbed to fail) shows "not saved",
// also in the GPU-lost notice, and a second tab taking over from it keeps the edit it could
// not save; a reload in the middle of training loses nothing; opening a
// share link, twice, keeps the version it displaced among the snapshots; a changed archive at
// the same URL (an entry added, served through a route) gets none of the old labels but is
// offered them. Starts no server:
// run.sh does, or point E2E_URL at one.
//
//   E2E_URL    page to open, e.g. http://127.0.0.1:8080/ (required)
//   E2E_DEMO   the demo archive the page serves (default www/demo.scene.zip)
//   E2E_OUT    folder for screenshots (default /tmp/e2e)
//   CHROMIUM   browser binary (default /usr/bin/chromium)
import { mkdirSync, readFileSync } from "node:fs";
import { crc32 } from "node:zlib";
import { join } from "node:path";
import { assert, Checks, openPage, runBrowserTest, settledStatus, show, status, waitForStatus } from "./lib.mjs";

const url = process.env.E2E_URL;
if (!url) {
  console.error("E2E_URL is not set: give the URL of the served page, e.g. E2E_URL=http://127.0.0.1:8080/");
  process.exit(2);
}
const outDir = process.env.E2E_OUT || "/tmp/e2e";
// The annotate test's CPU-rasterizer options: the tiny model on frames at a quarter size.
const PAGE_OPTIONS = "model=tiny&res=4&rays=1200";
const LOAD_TIMEOUT_MS = 180_000;
const SAVE_TIMEOUT_MS = 30_000;
const TRAIN_TIMEOUT_MS = 400_000;
// The demo scene's frames: 160 x 120.
const [W, H] = [160, 120];

mkdirSync(outDir, { recursive: true });
const consoleLog = [];
const checks = new Checks();
const t0 = Date.now();
const elapsed = () => `${((Date.now() - t0) / 1000).toFixed(0)} s`;

const pageUrl = new URL(url);
pageUrl.hash = `scene=demo.scene.zip&${PAGE_OPTIONS}`;
const sceneUrl = new URL("demo.scene.zip", url).href;

/// The old build's autosave of one stroke on frame 3, as it wrote it to local storage.
function legacySave() {
  return JSON.stringify({
    format: "scribblefield-autosave", version: 1, frames: 36, width: W, height: H, saved_at_ms: Date.now() - 60_000,
    labels: {
      format: "scribblefield-labels", version: 1,
      classes: [{ name: "old class", color: [10, 200, 30] }, { name: "other", color: [200, 10, 30] }],
      frames: [{ frame: 3, strokes: [{ class: 0, radius: 4, points: [[20, 20], [30, 20]] }] }],
    },
  });
}

const open = async (label, setup) => {
  const page = await context.newPage();
  page.on("console", (m) => consoleLog.push(`[${label}] console.${m.type()}: ${m.text()}`));
  page.on("pageerror", (e) => consoleLog.push(`[${label}] page error: ${e.message}`));
  if (setup) await setup(page);
  await page.goto(pageUrl.href, { waitUntil: "load" });
  const s = await settledStatus(page, LOAD_TIMEOUT_MS);
  assert(s.state === "ready", `${label}: status is ${show(s)}`);
  return page;
};

/// Draws a short horizontal stroke at row `y` of the frame shown (frame pixels).
async function draw(page, y) {
  const s = await status(page);
  const [vx, vy, vw, vh] = s.view;
  const at = (x) => [vx + (x / W) * vw, vy + (y / H) * vh];
  await page.mouse.move(...at(50));
  await page.mouse.down();
  await page.mouse.move(...at(70));
  await page.mouse.move(...at(90));
  await page.mouse.up();
}

/// Draws a stroke and waits until the page counts it and has saved it.
async function drawSaved(page, y) {
  const before = (await status(page)).strokes;
  await draw(page, y);
  return waitForStatus(page, (t) => t.strokes === before + 1 && t.save.state === "saved",
    `stroke ${before + 1} saved`, SAVE_TIMEOUT_MS);
}

/// The records of IndexedDB store `name` (`snapshots` or `aside`) as [key, value] pairs.
function records(page, name) {
  return page.evaluate((store) => new Promise((resolve, reject) => {
    const open = indexedDB.open("scribblefield");
    open.onerror = () => reject(open.error);
    open.onsuccess = () => {
      const tx = open.result.transaction(store, "readonly");
      const keys = tx.objectStore(store).getAllKeys();
      const values = tx.objectStore(store).getAll();
      tx.oncomplete = () => { resolve(keys.result.map((k, i) => [k, values.result[i]])); open.result.close(); };
      tx.onerror = () => reject(tx.error);
    };
  }), name);
}

function putRecord(page, key, value) {
  return page.evaluate(([k, v]) => new Promise((resolve, reject) => {
    const open = indexedDB.open("scribblefield");
    open.onsuccess = () => {
      const tx = open.result.transaction("snapshots", "readwrite");
      tx.objectStore("snapshots").put(v, k);
      tx.oncomplete = () => { resolve(); open.result.close(); };
      tx.onerror = () => reject(tx.error);
    };
  }), [key, value]);
}

/// `zip` with one more stored entry (`name`, `text`) at the end: other content, so another
/// content id, for a scene that decodes the same.
function withExtraEntry(zip, name, text) {
  let eocd = zip.length - 22;
  while (eocd >= 0 && zip.readUInt32LE(eocd) !== 0x06054b50) eocd--;
  assert(eocd >= 0, "no end of central directory");
  const count = zip.readUInt16LE(eocd + 10), cdSize = zip.readUInt32LE(eocd + 12), cdOffset = zip.readUInt32LE(eocd + 16);
  const data = Buffer.from(text), fileName = Buffer.from(name), crc = crc32(data);
  const local = Buffer.alloc(30);
  local.writeUInt32LE(0x04034b50, 0); local.writeUInt16LE(20, 4);
  local.writeUInt32LE(crc, 14); local.writeUInt32LE(data.length, 18); local.writeUInt32LE(data.length, 22);
  local.writeUInt16LE(fileName.length, 26);
  const central = Buffer.alloc(46);
  central.writeUInt32LE(0x02014b50, 0); central.writeUInt16LE(20, 4); central.writeUInt16LE(20, 6);
  central.writeUInt32LE(crc, 16); central.writeUInt32LE(data.length, 20); central.writeUInt32LE(data.length, 24);
  central.writeUInt16LE(fileName.length, 28); central.writeUInt32LE(cdOffset, 42);
  const end = Buffer.from(zip.subarray(eocd, eocd + 22));
  const newCdOffset = cdOffset + 30 + fileName.length + data.length;
  end.writeUInt16LE(count + 1, 8); end.writeUInt16LE(count + 1, 10);
  end.writeUInt32LE(cdSize + 46 + fileName.length, 12); end.writeUInt32LE(newCdOffset, 16); end.writeUInt16LE(0, 20);
  return Buffer.concat([zip.subarray(0, cdOffset), local, fileName, data,
    zip.subarray(cdOffset, cdOffset + cdSize), central, fileName, end]);
}

const strokesOf = (s) => s.save.snapshots.map(([, n]) => n);

let sceneId;
// The browser, for `open` above.
let context;
await runBrowserTest("durable", {
  checks,
  consoleLog,
  viewport: { width: 1024, height: 720 },
  acceptDownloads: true,
  consoleLines: 150,
  summary: () => `durable: ${elapsed()} in all`,
}, async (browser) => {
  context = browser;
  // --- migration and two tabs ---
  let a, b;
  const legacyKey = `scribblefield/labels/${sceneUrl}`;
  await checks.check("an old local-storage save is migrated into the snapshots and left in place", async () => {
    a = await open("tab A", (page) => page.addInitScript(([k, v]) => {
      if (location.hash.includes("scene=") && !localStorage.getItem(k)) localStorage.setItem(k, v);
    }, [legacyKey, legacySave()]));
    const s = await status(a);
    console.log(`     tab A: ${show(s.save)} (${elapsed()})`);
    assert(s.strokes === 1 && s.classes === 2, `strokes ${s.strokes}, classes ${s.classes}`);
    assert(s.save.snapshots.length === 1 && s.save.snapshots[0][1] === 1, `snapshots ${show(s.save.snapshots)}`);
    assert(s.save.scene.length === 32, `scene id ${s.save.scene}`);
    sceneId = s.save.scene;
    assert(await a.evaluate((k) => !!localStorage.getItem(k), legacyKey), "the old entry is gone");
  });

  await checks.check("a second tab on the scene follows read-only, then takes over; a reload loses no stroke", async () => {
    await a.focus("#scribblefield");
    await drawSaved(a, 40);
    b = await open("tab B");
    let sb = await status(b);
    assert(sb.save.state === "read_only", `tab B: ${show(sb.save)}`);
    assert(sb.strokes === 2, `tab B shows ${sb.strokes} strokes, tab A saved 2`);
    // An edit in the follower is refused, not saved over the writer's.
    await b.focus("#scribblefield");
    await draw(b, 60);
    await new Promise((r) => setTimeout(r, 3000));
    sb = await status(b);
    assert(sb.strokes === 2, `the read-only tab took a stroke: ${sb.strokes}`);
    // The writer draws: the follower follows.
    await a.focus("#scribblefield");
    await drawSaved(a, 80);
    await waitForStatus(b, (t) => t.strokes === 3, "tab B to follow tab A's stroke", SAVE_TIMEOUT_MS);
    // The writer goes: the follower takes over, with everything the writer saved.
    await a.close();
    sb = await waitForStatus(b, (t) => t.save.state === "saved", "tab B to take over", 60_000);
    assert(sb.strokes === 3, `after taking over tab B has ${sb.strokes} strokes`);
    await b.focus("#scribblefield");
    await drawSaved(b, 100);
    await b.reload({ waitUntil: "load" });
    sb = await settledStatus(b, LOAD_TIMEOUT_MS);
    console.log(`     after the reload: ${sb.strokes} strokes, snapshots ${show(sb.save.snapshots)} (${elapsed()})`);
    assert(sb.strokes === 4, `after the reload tab B has ${sb.strokes} strokes, 4 were drawn`);
  });

  // --- a corrupted save ---
  await checks.check("a corrupted save is set aside, and the next edit does not destroy it", async () => {
    let s = await status(b);
    const newest = s.save.snapshots[s.save.snapshots.length - 1];
    const key = `${s.save.scene}/${String(newest[0]).padStart(12, "0")}`;
    const garbage = "{\"format\": \"scribblefield-snapshot\", damaged";
    await putRecord(b, key, garbage);
    await b.reload({ waitUntil: "load" });
    s = await settledStatus(b, LOAD_TIMEOUT_MS);
    console.log(`     after corrupting ${key}: ${show(s.save)}; ${s.strokes} strokes`);
    assert(s.save.aside.length === 1, `set aside: ${show(s.save.aside)}`);
    assert(!s.save.snapshots.some(([seq]) => seq === newest[0]), "the damaged record is still listed");
    await b.focus("#scribblefield");
    await drawSaved(b, 50);
    const aside = await records(b, "aside");
    const kept = aside.find(([k]) => k === s.save.aside[0]);
    assert(kept && kept[1] === garbage, `the set-aside record changed: ${JSON.stringify(kept)}`);
    const snaps = await records(b, "snapshots");
    assert(!snaps.some(([, v]) => v === garbage), "the damaged record is still among the snapshots");
  });
  const strokesBefore = (await status(b)).strokes;
  await b.close();
  let follower;

  // --- a full disk ---
  await checks.check("a failing write (quota) shows \"not saved\", also in the GPU-lost notice", async () => {
    const c = await open("full disk", (page) => page.addInitScript(() => {
      IDBObjectStore.prototype.put = function () {
        throw new DOMException("The quota has been exceeded.", "QuotaExceededError");
      };
    }));
    // Closed whatever happens: while open it holds the scene's lock.
    try {
      await c.focus("#scribblefield");
      await draw(c, 30);
      const s = await waitForStatus(c, (t) => t.strokes === strokesBefore + 1 && t.save.state !== "saving",
        "the failed save", SAVE_TIMEOUT_MS);
      console.log(`     ${show(s.save.state)}: ${s.save.error}`);
      assert(s.save.state === "failed" && /quota/i.test(s.save.error), `save: ${show(s.save)}`);
      assert(s.saved === false, "saved is true");
      await c.screenshot({ path: join(outDir, "durable-not-saved-banner.png") });
      await c.evaluate(() => { document.body.dataset.gpuLost = "test: device lost"; });
      await c.waitForFunction(() => /GPU stopped/.test(document.getElementById("notice-text").textContent),
        null, { timeout: 10_000 });
      const notice = await c.evaluate(() => document.getElementById("notice-text").textContent);
      assert(/NOT be saved/.test(notice) && !/annotations are saved/.test(notice), `notice: ${notice}`);
      await c.screenshot({ path: join(outDir, "durable-not-saved-gpu-lost.png") });
      // Opened while this tab still saves: it follows, and takes over once this one closes.
      follower = await open("follower");
      const f = await status(follower);
      assert(f.save.state === "read_only", `the second tab: ${show(f.save)}`);
    } finally {
      await c.close();
    }
  });

  await checks.check("a tab taking over from one that could not save keeps the edit it could not save", async () => {
    assert(follower, "no second tab was opened");
    try {
      const f = await waitForStatus(follower, (t) => t.save.state === "saved", "the second tab to take over", 60_000);
      console.log(`     after taking over: ${f.strokes} strokes; snapshots ${show(f.save.snapshots)}`);
      assert(f.strokes === strokesBefore + 1, `the second tab has ${f.strokes} strokes, the closed one drew ${strokesBefore + 1}`);
    } finally {
      await follower.close();
    }
  });

  // --- a reload while training ---
  let d;
  await checks.check("a reload in the middle of training loses nothing", async () => {
    d = await open("training");
    // The tab closed just before may hold the scene's lock a moment longer: draw once this
    // tab saves, or the stroke would be refused as read-only.
    const before = (await waitForStatus(d, (t) => t.save.state === "saved", "the tab to save the scene",
      SAVE_TIMEOUT_MS)).strokes;
    await waitForStatus(d, (t) => {
      if (t.training === "failed") throw new Error(`training failed: ${t.failure}`);
      return t.training === "running" && t.steps > 0;
    }, "training to run", TRAIN_TIMEOUT_MS);
    await d.focus("#scribblefield");
    await draw(d, 70);
    await waitForStatus(d, (t) => t.strokes === before + 1, "the stroke", SAVE_TIMEOUT_MS).catch(async (e) => {
      await d.screenshot({ path: join(outDir, "durable-stroke-missing.png") });
      throw e;
    });
    // No wait for the save: reload at once.
    await d.reload({ waitUntil: "load" });
    const s = await settledStatus(d, LOAD_TIMEOUT_MS);
    console.log(`     before ${before} strokes + 1; after the reload ${s.strokes} (${elapsed()})`);
    assert(s.strokes === before + 1, `after the reload ${s.strokes} strokes, ${before + 1} were drawn`);
  });

  // --- share links ---
  await checks.check("opening a share link (twice) keeps the version it displaced among the snapshots", async () => {
    await d.focus("#scribblefield");
    await d.keyboard.press("l");
    await d.waitForFunction(() => !!document.body.dataset.shareLink, null, { timeout: 30_000 });
    const link = await d.evaluate(() => document.body.dataset.shareLink);
    const linked = (await status(d)).strokes;
    const mine = (await drawSaved(d, 90)).strokes;
    await d.close();
    for (const round of [1, 2]) {
      const page = await openPage(context, link, `link ${round}`, consoleLog);
      const s = await settledStatus(page, LOAD_TIMEOUT_MS);
      const saved = await waitForStatus(page, (t) => t.save.state === "saved", "the link's save", SAVE_TIMEOUT_MS);
      console.log(`     link ${round}: ${s.strokes} strokes; snapshots hold ${show(strokesOf(saved))}`);
      assert(s.strokes === linked, `the link opened ${s.strokes} strokes, it holds ${linked}`);
      assert(strokesOf(saved).includes(mine), `no snapshot of the ${mine} strokes the link displaced`);
      await page.close();
    }
  });

  // --- another archive at the same URL ---
  await checks.check("a changed archive at the same URL does not get the old labels; they are offered", async () => {
    const demo = readFileSync(process.env.E2E_DEMO || "www/demo.scene.zip");
    const changed = withExtraEntry(demo, "changed.txt", "another version of the archive");
    const page = await open("changed archive", (p) => p.route("**/demo.scene.zip",
      (route) => route.fulfill({ body: changed, contentType: "application/zip" })));
    try {
      const s = await status(page);
      console.log(`     changed archive: ${s.strokes} strokes; ${show(s.save)}`);
      assert(s.save.scene.length === 32 && s.save.scene !== sceneId, `the content id did not change: ${s.save.scene}`);
      assert(s.strokes === 0, `the changed archive opened with ${s.strokes} strokes of the old one`);
      assert(s.save.others > 0, "the old version's snapshots are not offered");
    } finally {
      await page.close();
    }
  });
});
