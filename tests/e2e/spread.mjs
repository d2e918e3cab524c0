// End-to-end test of spreading strokes over a photo capture with sparse depth (a COLMAP model's
// points) in headless Chromium: the walks that carry two strokes on one photo to the other
// photos take seconds, and the page must keep drawing meanwhile (they run in slices and give
// the thread back: src/pause.rs). Draws one stroke per class on photo 0, then checks that
// the page said "spreading", that no task held the page's thread for long while it did, and
// that the labels reached other photos. Starts no server: run.sh does, or point E2E_URL at one.
//
//   E2E_URL        page to open, e.g. http://127.0.0.1:8080/ (required)
//   E2E_SPARSE     the served archive of a capture with sparse depth (its ground truth plans the
//                  strokes), e.g. www/e2e-sparse.scene.zip
//   E2E_OUT        folder for screenshots (default /tmp/e2e)
//   CHROMIUM       browser binary (default /usr/bin/chromium)
import { mkdirSync, readFileSync } from "node:fs";
import { basename, join } from "node:path";
import {
  assert, Checks, decodePng, drawFrameStroke, openPage, planFrameStrokes, readZip, runBrowserTest, settledStatus,
  show, status, waitForStatus,
} from "./lib.mjs";

const url = process.env.E2E_URL;
const archivePath = process.env.E2E_SPARSE;
if (!url || !archivePath) {
  console.error("E2E_URL and E2E_SPARSE must be set: the served page and the archive of a capture with sparse depth");
  process.exit(2);
}
const outDir = process.env.E2E_OUT || "/tmp/e2e";
// Training is paused before drawing: the spreading is what is under test, and on SwiftShader
// every training step holds the GPU for seconds.
const PAGE_OPTIONS = "model=tiny&rays=256&res=1";
const BRUSH_RADIUS = 3;
const LOAD_TIMEOUT_MS = 180_000;
const SPREAD_TIMEOUT_MS = 300_000;
// The longest the page's thread may be held while the strokes spread. Before the walks ran in
// slices, one spread held it for its whole length (seconds); a slice is 12 ms plus one repaint.
const MAX_TASK_MS = 1000;

mkdirSync(outDir, { recursive: true });
const consoleLog = [];
const checks = new Checks();

const archive = readZip(readFileSync(archivePath));
const sceneJson = JSON.parse(archive.get("scene.json").toString("utf8"));
const [W, H] = [sceneJson.width, sceneJson.height];
const strokes = planFrameStrokes(decodePng(archive.get(sceneJson.frames[0].gt)).data, W, H, BRUSH_RADIUS);

await runBrowserTest("spread", {
  checks,
  consoleLog,
  viewport: { width: 1024, height: 720 },
  consoleLines: 40,
}, async (context) => {
  const pageUrl = new URL(url);
  pageUrl.hash = `scene=${basename(archivePath)}&${PAGE_OPTIONS}`;
  const page = await openPage(context, pageUrl.href, "spread", consoleLog);
  let s = await settledStatus(page, LOAD_TIMEOUT_MS);
  console.log(`capture with sparse depth loaded: ${show(s)}`);

  let seen = [];
  let longest = 0;
  let spreadMs = 0;
  await checks.check("two strokes on one photo spread while the page keeps drawing", async () => {
    assert(s.state === "ready", `status is ${show(s)}`);
    assert(strokes.length >= 2, `the ground truth of photo 0 gives ${strokes.length} strokes`);
    await waitForStatus(page, (t) => {
      if (t.training === "failed") throw new Error(`training failed: ${t.failure}`);
      return t.training === "running";
    }, "training to start", LOAD_TIMEOUT_MS);
    await page.focus("#scribblefield");
    await page.keyboard.press("Space");
    await waitForStatus(page, (t) => t.training === "paused", "the pause", 120_000);
    // The longest the page's thread went without running a 20 ms timer, from here on (a task
    // that holds the thread delays every timer behind it).
    await page.evaluate(() => {
      window.heldMs = 0;
      let last = performance.now();
      setInterval(() => {
        const now = performance.now();
        window.heldMs = Math.max(window.heldMs, now - last - 20);
        last = now;
      }, 20);
    });
    // The probe must see a task that holds the thread, or its silence below proves nothing.
    await page.evaluate(() => { const t = performance.now(); while (performance.now() - t < 300); });
    await page.waitForFunction(() => window.heldMs >= 250, null, { timeout: 10_000 });
    await page.evaluate(() => { window.heldMs = 0; });
    for (const stroke of strokes.slice(0, 2)) await drawFrameStroke(page, stroke, W, H);
    await waitForStatus(page, (t) => t.strokes === 2, "both strokes", 60_000);
    const start = Date.now();
    let spreadStart = null;
    for (;;) {
      const t = await status(page);
      if (seen[seen.length - 1] !== t.training) seen.push(t.training);
      if (t.training === "spreading" && spreadStart === null) spreadStart = Date.now();
      if (spreadStart !== null && t.training !== "spreading") {
        spreadMs = Date.now() - spreadStart;
        s = t;
        break;
      }
      assert(Date.now() - start < SPREAD_TIMEOUT_MS, `no end of spreading; states ${seen.join(", ")}`);
      await new Promise((r) => setTimeout(r, 100));
    }
    longest = await page.evaluate(() => window.heldMs);
    console.log(`     states ${seen.join(" -> ")}; spreading showed for ${(spreadMs / 1000).toFixed(1)} s; ` +
      `longest hold of the page's thread ${longest.toFixed(0)} ms; trains on ${JSON.stringify(s.spread)}`);
    assert(longest < MAX_TASK_MS, `a task held the page's thread for ${longest.toFixed(0)} ms`);
  });
  await checks.check("the labels reach photos nobody drew on", async () => {
    s = await waitForStatus(page, (t) => Array.isArray(t.spread), "the spread labels", 60_000);
    const [pixels, frames] = s.spread;
    assert(frames > 1, `labels on ${frames} frame(s), ${pixels} pixels`);
    assert(pixels > s.labelled, `${pixels} pixels to train on from ${s.labelled} drawn`);
  });
  await page.screenshot({ path: join(outDir, "spread.png") });
});
