// Measurements of the web app in headless Chromium (WebGPU on SwiftShader), not checks: run by
// hand (run.sh does not), numbers go to docs/web-app.md. Starts no server; point E2E_URL at one
// (e.g. `scribblefield serve www --port 8080`).
//
//   E2E_URL         page to open (required)
//   E2E_BIG_SCENE   a large archive served next to the page (e.g. made with
//                   `scribblefield demo-scene -o www/big.scene.zip --frames 300 --size 320x240`):
//                   how long it takes to open and how responsive the page stays while decoding
//   E2E_STARTUP     an archive served next to the page, opened with the page's defaults: how
//                   long from the scene shown to training (the scene uploaded, the kernels
//                   built, two strokes drawn meanwhile), and how soon those two strokes
//                   register against two drawn while training
//   E2E_OPTIONS     page options for the training measurements (default below)
//   E2E_SKIP_TRAIN  set to skip the training measurements
//   CHROMIUM        browser binary (default /usr/bin/chromium)
//
// Training: the wall-clock profile of a step (`#profile=1`: an empty submission, whole steps,
// each stage submitted alone, a frame render), the per-step submit and GPU-wait times while
// training, and how soon a stroke drawn while training shows in the mask (quick render, then
// full).
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { chromium } from "playwright-core";
import { CHROMIUM_ARGS, clearSaves, openPage, parseStatus, settledStatus, status, waitForStatus } from "./lib.mjs";

const url = process.env.E2E_URL;
if (!url) {
  console.error("E2E_URL is not set");
  process.exit(2);
}
const OPTIONS = process.env.E2E_OPTIONS || "model=tiny&res=4&rays=1200&coarse=4";
const chromiumPath = process.env.CHROMIUM || "/usr/bin/chromium";
const userDataDir = mkdtempSync(join(tmpdir(), "scribblefield-measure-"));
const consoleLog = [];

// Installed before the page's scripts: when the status changes, animation frames (the longest
// gap between two), and long tasks (over 50 ms on the main thread).
function watchPage() {
  window.__m = { statuses: [], frames: [], longTasks: [] };
  const seen = () => {
    const s = document.body?.dataset.status || "";
    const last = window.__m.statuses[window.__m.statuses.length - 1];
    if (!last || last[1] !== s) window.__m.statuses.push([performance.now(), s]);
  };
  new MutationObserver(seen).observe(document, { attributes: true, subtree: true, attributeFilter: ["data-status"] });
  const frame = (t) => { window.__m.frames.push(t); requestAnimationFrame(frame); };
  requestAnimationFrame(frame);
  new PerformanceObserver((list) => {
    for (const e of list.getEntries()) window.__m.longTasks.push([e.startTime, e.duration]);
  }).observe({ type: "longtask", buffered: true });
}

// A horizontal stroke across the middle of the frame view `[x, y, w, h]`, at `row` of its height.
async function dragAcross(page, [x, y, w, h], row, steps = 1) {
  await page.mouse.move(x + w * 0.3, y + h * row);
  await page.mouse.down();
  await page.mouse.move(x + w * 0.5, y + h * row, { steps });
  await page.mouse.up();
}

let context;
try {
  context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: chromiumPath,
    headless: false,
    args: CHROMIUM_ARGS,
    viewport: { width: 1024, height: 720 },
  });
  await context.addInitScript(watchPage);

  if (process.env.E2E_BIG_SCENE) {
    const page = await openPage(context, new URL(`#scene=${process.env.E2E_BIG_SCENE}&model=tiny`, url).href, "big", consoleLog);
    const s = await settledStatus(page, 600_000);
    const m = await page.evaluate(() => window.__m);
    const at = (pred) => m.statuses.find(([, st]) => pred(st))?.[0];
    const decodeStart = at((st) => parseStatus(st).state === "decoding");
    const ready = at((st) => parseStatus(st).state === "ready");
    const inDecode = (t) => t >= decodeStart && t <= ready;
    const frames = m.frames.filter(inDecode);
    let gap = 0;
    for (let i = 1; i < frames.length; i++) gap = Math.max(gap, frames[i] - frames[i - 1]);
    const long = m.longTasks.filter(([t]) => inDecode(t));
    const longest = long.reduce((a, [, d]) => Math.max(a, d), 0);
    const progress = m.statuses.filter(([t, st]) => inDecode(t) && parseStatus(st).frames > 0).length;
    console.log(`big scene: ${JSON.stringify(s).slice(0, 60)}`);
    console.log(`  download ${((decodeStart - m.statuses[0][0]) / 1000).toFixed(1)} s, decode ${((ready - decodeStart) / 1000).toFixed(1)} s`);
    console.log(`  while decoding: ${frames.length} animation frames, longest gap ${gap.toFixed(0)} ms, ` +
      `${progress} progress updates, ${long.length} long tasks (longest ${longest.toFixed(0)} ms)`);
    await page.close();
  }

  if (process.env.E2E_STARTUP) {
    const page = await openPage(context, new URL(`#scene=${process.env.E2E_STARTUP}`, url).href, "startup", consoleLog);
    let s = await settledStatus(page, 600_000);
    const shown = Date.now();
    // Two strokes, each timed from the first mouse event until the page counts it.
    const twoStrokes = async (what) => {
      const times = [];
      for (let i = 0; i < 2; i++) {
        const before = (await status(page)).strokes;
        const start = Date.now();
        await dragAcross(page, s.view, 0.4 + 0.1 * i, 5);
        await waitForStatus(page, (t) => t.strokes === before + 1, "the stroke", 300_000);
        times.push(((Date.now() - start) / 1000).toFixed(1));
      }
      console.log(`startup: strokes ${what} registered ${times.join(" s, ")} s after their first mouse event`);
    };
    await twoStrokes(`while the kernels build (training ${s.training})`);
    s = await waitForStatus(page, (t) => t.training === "running", "training", 600_000);
    console.log(`startup: scene shown -> training running ${((Date.now() - shown) / 1000).toFixed(1)} s`);
    s = await waitForStatus(page, (t) => t.steps >= 1, "a step", 600_000);
    await twoStrokes("while training");
    // The strokes were saved for this scene: the training measurement below starts from none.
    await clearSaves(page);
    await page.close();
  }

  if (!process.env.E2E_SKIP_TRAIN) {
    const page = await openPage(context, new URL(`#scene=demo.scene.zip&${OPTIONS}&profile=1`, url).href, "train", consoleLog);
    await settledStatus(page, 300_000);
    const started = Date.now();
    await page.waitForFunction(() => !!document.body.dataset.profile, null, { timeout: 600_000, polling: 500 });
    console.log(`profile (ms; after ${((Date.now() - started) / 1000).toFixed(0)} s): ` +
      await page.evaluate(() => document.body.dataset.profile));
    let s = await waitForStatus(page, (t) => t.steps >= 6 && t.mask === "full",
      "training", 600_000);
    console.log(`training: step_ms=${s.step_ms.join("+")} (submit+wait per step) sps=${s.sps} batch=${s.batch}`);
    // A stroke while training runs: how soon the mask is refreshed for it.
    await dragAcross(page, s.view, 0.5);
    const drawn = Date.now();
    s = await waitForStatus(page, (t) => t.strokes === 1, "the stroke", 60_000);
    const stepAtStroke = s.steps;
    let coarseAt, fullAt;
    while (!fullAt && Date.now() - drawn < 600_000) {
      s = await status(page);
      const fresh = s.rendered > stepAtStroke;
      if (fresh && s.mask === "coarse" && !coarseAt) coarseAt = Date.now();
      if (fresh && s.mask === "full") fullAt = Date.now();
      await new Promise((r) => setTimeout(r, 100));
    }
    const secs = (t) => (t ? `${((t - drawn) / 1000).toFixed(1)} s` : "never");
    console.log(`stroke while training: quick mask after ${secs(coarseAt)}, full after ${secs(fullAt)}; ` +
      `page says refresh_ms=${JSON.stringify(s.refresh_ms)}`);
  }
} catch (e) {
  console.log(`FAIL ${e.message}`);
  for (const line of consoleLog.slice(-50)) console.log(line);
} finally {
  await context?.close().catch(() => {});
  rmSync(userDataDir, { recursive: true, force: true });
}
