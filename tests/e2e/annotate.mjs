// End-to-end test of annotating in headless Chromium (WebGPU on SwiftShader): load the demo
// scene, draw scribbles of every class with real mouse events, let the field train, download
// the masks zip and score it against the scene's ground truth; then reload and find the
// scribbles restored from the saved snapshots, and open a share link (with the saves cleared) and
// find the same scribbles. Starts no server: run.sh does, or point E2E_URL at one.
//
//   E2E_URL        page to open, e.g. http://127.0.0.1:8080/ (required)
//   E2E_DEMO       the demo archive the page serves, for its ground truth (default www/demo.scene.zip)
//   E2E_OUT        folder for screenshots and the downloaded zip (default /tmp/e2e)
//   E2E_STEPS      training steps to wait for after the last scribble (default below)
//   E2E_MIN_IOU    mean IoU the masks must reach (default below)
//   CHROMIUM       browser binary (default /usr/bin/chromium)
import { mkdirSync, readFileSync, writeFileSync } from "node:fs";
import { join } from "node:path";
import {
  assert, Checks, clearSaves, decodePng, drawFrameStroke, goToFrame, openPage, planFrameStrokes, readZip,
  runBrowserTest, saturatedColours, settledStatus, show, status, waitForStatus,
} from "./lib.mjs";

const url = process.env.E2E_URL;
if (!url) {
  console.error("E2E_URL is not set: give the URL of the served page, e.g. E2E_URL=http://127.0.0.1:8080/");
  process.exit(2);
}
const outDir = process.env.E2E_OUT || "/tmp/e2e";
const demoPath = process.env.E2E_DEMO || "www/demo.scene.zip";
// Training steps after the last scribble before the masks are downloaded, and the mean IoU
// they must reach. Measured on a loaded 2-core machine: 0.353 (4 frames scribbled) and 0.317
// (these 2 frames); answering "background" everywhere scores 0.089. The bar sits well above
// that and below the measurements. docs/web-app.md has the rest of the measurements.
const STEPS = Number(process.env.E2E_STEPS || 30);
const MIN_IOU = Number(process.env.E2E_MIN_IOU || 0.2);
// The page's options for a CPU rasterizer: the tiny model, frames at a quarter of their size
// (40 x 30), and batches of 1200 rays, one render tile per frame (on SwiftShader every wait for
// the GPU also waits for the page's repaints, so fewer, larger batches get more done). coarse=4
// makes the page render a stale mask at 1/4 first even though a 40 x 30 frame is one tile
// anyway, so the test sees the quick render come before the full one.
const PAGE_OPTIONS = process.env.E2E_PAGE_OPTIONS || "model=tiny&res=4&rays=1200&coarse=4";
// Frames scribbled on: spread around the demo's orbit so every object is seen from several
// sides. Brush radius is the app's default for 160 x 120 frames.
// Two frames from opposite sides of the orbit; more are added only when a class is missing.
const SCRIBBLE_FRAMES = [0, 18];
const SPARE_FRAMES = [9, 27, 5, 14, 23, 32];
const BRUSH_RADIUS = 4;
const LOAD_TIMEOUT_MS = 180_000;
const TRAIN_TIMEOUT_MS = 600_000;
const EXPORT_TIMEOUT_MS = 600_000;
const VOID = 255;

mkdirSync(outDir, { recursive: true });
const consoleLog = [];
const checks = new Checks();
const t0 = Date.now();
const elapsed = () => `${((Date.now() - t0) / 1000).toFixed(0)} s`;

// The demo's ground truth, straight from the archive the page loads.
const demo = readZip(readFileSync(demoPath));
const sceneJson = JSON.parse(demo.get("scene.json").toString("utf8"));
const classes = sceneJson.classes;
const gt = sceneJson.frames.map((f) => decodePng(demo.get(f.gt)));
const [W, H] = [sceneJson.width, sceneJson.height];

/// One stroke per class visible on `frame` (see lib.mjs).
function planStrokes(frame) {
  return planFrameStrokes(gt[frame].data, W, H, BRUSH_RADIUS);
}

/// Draws `stroke` (frame pixels) with the mouse.
function drawStroke(page, stroke) {
  return drawFrameStroke(page, stroke, W, H);
}

function labelledOf(s) {
  return [s.strokes, s.labelled];
}

/// Per-class IoU over every frame (void pixels ignored) and their mean over the classes the
/// ground truth has.
function meanIou(masks) {
  const n = classes.length;
  const inter = new Float64Array(n), union = new Float64Array(n), present = new Array(n).fill(false);
  for (let f = 0; f < gt.length; f++) {
    const g = gt[f].data, m = masks[f].data;
    for (let i = 0; i < g.length; i++) {
      if (g[i] === VOID) continue;
      present[g[i]] = true;
      if (g[i] === m[i]) { inter[g[i]] += 1; union[g[i]] += 1; } else {
        union[g[i]] += 1;
        if (m[i] < n) union[m[i]] += 1;
      }
    }
  }
  const per = [...inter].map((v, c) => (present[c] ? v / Math.max(1, union[c]) : null));
  const valid = per.filter((v) => v !== null);
  return { mean: valid.reduce((a, b) => a + b, 0) / valid.length, per };
}

await runBrowserTest("annotate", {
  checks,
  consoleLog,
  // Smaller than the smoke test's: on SwiftShader every repaint of the page takes about a
  // second at 1280 x 800, and each mouse event is one repaint.
  viewport: { width: 1024, height: 720 },
  acceptDownloads: true,
  consoleLines: 200,
  summary: () => `screenshots in ${outDir} (${elapsed()} in all)`,
}, async (context) => {
  const sceneUrl = new URL("demo.scene.zip", url).href;
  const pageUrl = new URL(url);
  pageUrl.hash = `scene=demo.scene.zip&export=voc,coco&${PAGE_OPTIONS}`;
  const page = await openPage(context, pageUrl.href, "annotate", consoleLog);
  const loadStart = Date.now();
  let s = await settledStatus(page, LOAD_TIMEOUT_MS);
  const loadSeconds = (Date.now() - loadStart) / 1000;
  console.log(`demo scene loaded in ${loadSeconds.toFixed(1)} s: ${show(s)}`);
  await checks.check("the demo scene loads and starts training", async () => {
    assert(s.state === "ready", `status is ${show(s)}`);
    s = await waitForStatus(page, (t) => {
      if (t.training === "failed") throw new Error(`training failed: ${t.failure}`);
      return t.training === "running";
    }, "training to start", LOAD_TIMEOUT_MS);
    console.log(`     training started at ${elapsed()}`);
    // Nothing is drawn yet: the field's first render shows no classes over the frame.
    s = await waitForStatus(page, (t) => t.rendered >= 0, "a first render", 120_000);
    assert(s.classes_shown === false, `classes shown before any stroke: ${show(s)}`);
  });

  // Scribble: every class visible on each chosen frame, until every class has some.
  let expectedStrokes = 0;
  const drawn = new Set();
  await checks.check("scribbles of every class, drawn with the mouse, are recorded", async () => {
    await page.focus("#scribblefield");
    // Paused while drawing, as one would on a slow device: on SwiftShader a training step takes
    // seconds and every repaint of the page waits for it.
    await page.keyboard.press("Space");
    await waitForStatus(page, (t) => t.training === "paused", "the pause", 120_000);
    const frames = [...SCRIBBLE_FRAMES];
    for (const spare of SPARE_FRAMES) {
      const seen = new Set(frames.flatMap((f) => planStrokes(f).map((st) => st.class)));
      if (classes.every((_, c) => seen.has(c))) break;
      if (planStrokes(spare).some((st) => !seen.has(st.class))) frames.push(spare);
    }
    for (const frame of frames) {
      await goToFrame(page, frame);
      for (const stroke of planStrokes(frame)) {
        await drawStroke(page, stroke);
        expectedStrokes += 1;
        drawn.add(stroke.class);
        await waitForStatus(page, (t) => t.strokes === expectedStrokes,
          `stroke ${expectedStrokes}`, 60_000);
        console.log(`     stroke ${expectedStrokes}: class ${stroke.class} on frame ${frame} (${elapsed()})`);
      }
    }
    await page.keyboard.press("Space");
    await waitForStatus(page, (t) => t.training === "running", "the resume", 120_000);
    const missing = classes.map((_, c) => c).filter((c) => !drawn.has(c));
    assert(missing.length === 0, `classes never scribbled: ${missing}`);
    s = await waitForStatus(page, (t) => t.saved === true, "the autosave", 30_000);
    console.log(`     ${expectedStrokes} strokes, ${s.labelled} labelled pixels (${elapsed()})`);
  });
  const labelledAfterDrawing = labelledOf(s);
  await page.screenshot({ path: join(outDir, "annotate-scribbles.png") });

  // Train, then look at a frame nobody scribbled on.
  const stepsAtLastStroke = s.steps;
  const trainStart = Date.now();
  await checks.check(`the field trains ${STEPS} more steps with the labels`, async () => {
    s = await waitForStatus(page, (t) => t.steps >= stepsAtLastStroke + STEPS,
      `${STEPS} steps`, TRAIN_TIMEOUT_MS);
    const seconds = (Date.now() - trainStart) / 1000;
    console.log(`     ${STEPS} steps in ${seconds.toFixed(0)} s (${(STEPS / seconds).toFixed(2)} steps/s; page says ` +
      `sps=${s.sps}, loss=${s.loss})`);
  });
  await checks.check("a frame shown is refreshed at low resolution first, then in full", async () => {
    await goToFrame(page, 5);
    const shown = Date.now();
    const seen = [];
    let last;
    while (Date.now() - shown < 240_000) {
      last = await status(page);
      const mask = last.mask;
      if (last.frame === 5 && seen[seen.length - 1]?.[0] !== mask) seen.push([mask, Date.now() - shown]);
      if (mask === "full") break;
      await new Promise((r) => setTimeout(r, 100));
    }
    console.log(`     masks of frame 5: ${seen.map(([m, ms]) => `${m} at ${(ms / 1000).toFixed(1)} s`).join(", ")}; ` +
      `page says refresh_ms=${JSON.stringify(last.refresh_ms)}, step_ms=${JSON.stringify(last.step_ms)}`);
    const order = seen.map(([m]) => m).filter((m) => m !== "none");
    assert(order[0] === "coarse" && order.includes("full"), `masks came as ${order.join(", ") || "nothing"}`);
    assert(last.classes_shown === true, `the field trained on the strokes, yet no classes are shown: ${show(last)}`);
  });
  const shot = await page.screenshot({ path: join(outDir, "annotate-mask-frame5.png") });
  console.log(`     (screenshot of frame 5 with the mask: ${saturatedColours(shot)} saturated colours)`);
  await checks.check("the side panel shows the rendered features through a PCA", async () => {
    const field = (await status(page)).features;
    assert(field, "the status gives no features panel (no render of this frame shown?)");
    const [x, y, width, height] = field;
    assert(width > 20 && height > 10, `the features image is ${width} x ${height}`);
    const png = await page.screenshot({ path: join(outDir, "annotate-features.png"), clip: { x, y, width, height } });
    const { data, channels } = decodePng(png);
    const distinct = new Set();
    for (let i = 0; i < data.length; i += channels) distinct.add((data[i] << 16) | (data[i + 1] << 8) | data[i + 2]);
    console.log(`     features panel ${width} x ${height}: ${distinct.size} distinct colours, ${saturatedColours(png)} saturated`);
    // A blank panel is one colour; a flat grey fallback a handful (edges).
    assert(distinct.size >= 30, `only ${distinct.size} distinct colours: is the panel blank?`);
  });

  // Download the masks and score them.
  await checks.check(`the downloaded masks reach a mean IoU of ${MIN_IOU}`, async () => {
    const exportStart = Date.now();
    const downloadPromise = page.waitForEvent("download", { timeout: EXPORT_TIMEOUT_MS });
    let downloaded = false;
    downloadPromise.then(() => { downloaded = true; }, () => {});
    // A key press can be lost while the page is busy (seen once in CI: no export in 600 s, and
    // the same build passed on the next run): press again until the export shows in the status.
    for (let attempt = 1; attempt <= 3; attempt++) {
      await page.keyboard.press("d");
      const started = await waitForStatus(page, (t) => downloaded || t.training === "exporting",
        "the export to start", 20_000).then(() => true, () => false);
      if (started) break;
      console.log(`     no export ${attempt * 20} s after pressing d; pressing it again`);
    }
    const download = await downloadPromise;
    const zipPath = join(outDir, download.suggestedFilename());
    await download.saveAs(zipPath);
    console.log(`     ${download.suggestedFilename()} after ${((Date.now() - exportStart) / 1000).toFixed(0)} s`);
    const files = readZip(readFileSync(zipPath));
    const manifest = JSON.parse(files.get("classes.json").toString("utf8"));
    assert(manifest.frames === gt.length, `the manifest lists ${manifest.frames} frames`);
    assert(JSON.stringify(manifest.classes.map((c) => c.name)) === JSON.stringify(classes.map((c) => c.name)),
      "the manifest's classes are not the scene's");
    const labels = JSON.parse(files.get("labels.json").toString("utf8"));
    const strokes = labels.frames.reduce((n, f) => n + f.strokes.length, 0);
    assert(strokes === expectedStrokes, `labels.json has ${strokes} strokes, ${expectedStrokes} were drawn`);
    assert(files.has("preview/00000.png"), "no colour previews");
    // The formats the address ticked (#export=voc,coco), and every mask by its frame's name.
    const byName = [...files.keys()].filter((n) => n.startsWith("by-name/") && n.endsWith(".png"));
    assert(byName.length === gt.length, `${byName.length} masks under by-name/, ${gt.length} frames`);
    const labelmap = files.get("voc/labelmap.txt");
    assert(labelmap, "no voc/labelmap.txt in the download");
    const voc = [...files.keys()].filter((n) => n.startsWith("voc/SegmentationClass/"));
    assert(voc.length === gt.length, `${voc.length} VOC masks, ${gt.length} frames`);
    assert(files.has("coco.json"), "no coco.json in the download");
    const coco = JSON.parse(files.get("coco.json").toString("utf8"));
    assert(coco.images.length === gt.length && coco.annotations.length >= gt.length,
      `coco.json has ${coco.images.length} images and ${coco.annotations.length} annotations`);
    console.log(`     download: ${byName.length} masks by name, ${voc.length} VOC masks, ` +
      `${coco.annotations.length} COCO annotations, labelmap of ${labelmap.toString("utf8").split("\n").length} lines`);
    const masks = manifest.files.map((name) => decodePng(files.get(name)));
    assert(masks.every((m) => m.width === W && m.height === H && m.channels === 1), "masks have the wrong format");
    const iou = meanIou(masks);
    console.log(`     mean IoU ${iou.mean.toFixed(3)}; per class ` +
      iou.per.map((v, c) => `${classes[c].name} ${v === null ? "-" : v.toFixed(3)}`).join(", "));
    assert(iou.mean >= MIN_IOU, `mean IoU ${iou.mean.toFixed(3)} is below ${MIN_IOU}`);
  });

  // Reload: the autosave brings the scribbles back.
  await checks.check("after a reload the scribbles are restored", async () => {
    await page.reload({ waitUntil: "load" });
    const r = await settledStatus(page, LOAD_TIMEOUT_MS);
    assert(r.state === "ready", `status is ${show(r)}`);
    assert(JSON.stringify(labelledOf(r)) === JSON.stringify(labelledAfterDrawing),
      `strokes/labelled pixels are ${labelledOf(r)}, were ${labelledAfterDrawing}`);
    await page.screenshot({ path: join(outDir, "annotate-reloaded.png") });
  });

  // A share link carries the scribbles without the autosave.
  await checks.check("a share link opens the scene with the same scribbles", async () => {
    await page.focus("#scribblefield");
    await page.keyboard.press("l");
    await page.waitForFunction(() => !!document.body.dataset.shareLink, null, { timeout: 30_000 });
    const link = await page.evaluate(() => document.body.dataset.shareLink);
    console.log(`     share link of ${link.length} characters`);
    assert(link.includes("scene=") && link.includes("labels="), `odd link: ${link.slice(0, 200)}`);
    assert(decodeURIComponent(new URL(link).hash).includes(sceneUrl), `the link does not name ${sceneUrl}`);
    await clearSaves(page);
    await page.close();
    const shared = await openPage(context, link, "share link", consoleLog);
    const r = await settledStatus(shared, LOAD_TIMEOUT_MS);
    assert(r.state === "ready", `status is ${show(r)}`);
    assert(JSON.stringify(labelledOf(r)) === JSON.stringify(labelledAfterDrawing),
      `strokes/labelled pixels are ${labelledOf(r)}, were ${labelledAfterDrawing}`);
    const hash = await shared.evaluate(() => location.hash);
    assert(!hash.includes("labels="), `the address still carries the labels: ${hash.slice(0, 80)}`);
    await shared.screenshot({ path: join(outDir, "annotate-share-link.png") });
  });
  writeFileSync(join(outDir, "annotate-load-seconds.txt"), `${loadSeconds}\n`);
});
