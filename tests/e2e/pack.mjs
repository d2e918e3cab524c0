// End-to-end test of packing a capture in the page (src/app/packing.rs) in headless Chromium:
// a folder that is no capture is refused with the command line's error; then a COLMAP capture
// folder is set on the page's folder input, its pack settings are started as the page options
// give them, it is packed in wasm (downscaled, a few frames, baseline features), opened for
// annotation, scribbled on, trained until the page shows masks, and the masks and the packed
// archive are downloaded and checked; a zip of the folder and the folder itself are dropped on
// the page (the folder through Chrome DevTools' Input.dispatchDragEvent, which hands the page
// real directory entries) and pack to the same scene; the pack settings' estimate follows
// changed settings, bad values are refused, Cancel leaves the open scene, and the pack uses what
// was changed; last, a pack with a long autoencoder fit is cancelled. Starts no server: run.sh
// does, or point E2E_URL at one.
//
//   E2E_URL        page to open, e.g. http://127.0.0.1:8080/ (required)
//   E2E_CAPTURE    the capture folder, e.g. ../shared/data/alexander-colmap (required)
//   E2E_REFERENCE  the same capture packed by the command line with the same options
//                  (`pack E2E_CAPTURE --max-size 96 --every 9 --no-features`): its ground truth plans the
//                  strokes, and the page's scene must match it (required)
//   E2E_OUT        folder for screenshots and the downloaded zip (default /tmp/e2e)
//   CHROMIUM       browser binary (default /usr/bin/chromium)
import { mkdirSync, mkdtempSync, readdirSync, readFileSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { basename, join, resolve } from "node:path";
import {
  assert, cancelPackSetup, Checks, clickPackControl, decodePng, drawFrameStroke, dropZip, openPage, packResult, packSetup,
  planFrameStrokes, readZip, runBrowserTest, setPackField, settledStatus, show, startPack, status, waitForError,
  waitForPackSetup, waitForPacked, waitForStatus,
} from "./lib.mjs";

const url = process.env.E2E_URL;
const capturePath = process.env.E2E_CAPTURE;
const referencePath = process.env.E2E_REFERENCE;
if (!url || !capturePath || !referencePath) {
  console.error("E2E_URL, E2E_CAPTURE and E2E_REFERENCE must be set: the served page, a capture folder and its " +
    "archive packed by the command line with --max-size 96 --every 9");
  process.exit(2);
}
const outDir = process.env.E2E_OUT || "/tmp/e2e";
// An RGB-D capture beside the photo capture (the YCB clip), when the shared data has it: its
// pack settings must keep the depth captures' defaults.
const depthCapturePath = [resolve(capturePath, "..", "ycb-video-0000")].find((p) => {
  try {
    return readdirSync(join(p, "depth")).length > 0;
  } catch {
    return false;
  }
});
// Packing as `pack --max-size 96 --every 9 --features baseline --feature-stride 4
// --autoencoder-steps 100`: tiny frames and few steps keep SwiftShader quick. The tiny model,
// and small batches so a step is short.
const PAGE_OPTIONS = "pack-size=96&pack-every=9&pack-stride=4&pack-steps=100&model=tiny&rays=256";
const BRUSH_RADIUS = 3;
const PACK_TIMEOUT_MS = 300_000;
const TRAIN_TIMEOUT_MS = 600_000;
const EXPORT_TIMEOUT_MS = 600_000;

mkdirSync(outDir, { recursive: true });
const consoleLog = [];
const checks = new Checks();
const t0 = Date.now();
const elapsed = () => `${((Date.now() - t0) / 1000).toFixed(0)} s`;

const reference = readZip(readFileSync(referencePath));
const sceneJson = JSON.parse(reference.get("scene.json").toString("utf8"));
const [W, H] = [sceneJson.width, sceneJson.height];
const strokes = planFrameStrokes(decodePng(reference.get(sceneJson.frames[0].gt)).data, W, H, BRUSH_RADIUS);

// A folder with files but no capture layout: what a user picks by mistake.
const notCapture = join(mkdtempSync(join(tmpdir(), "scribblefield-e2e-")), "holiday");
mkdirSync(notCapture);
writeFileSync(join(notCapture, "notes.txt"), "not a capture\n");
writeFileSync(join(notCapture, "photo.jpg"), readFileSync(join(capturePath, "images", "DSC05083.JPG")));

/// Prints the estimate beside what packing took, for the record (docs/web-app.md).
function reportEstimate(r) {
  assert(r && r.estimate, `no pack result with an estimate: ${JSON.stringify(r)}`);
  const e = r.estimate;
  const stages = (x) => Object.entries(x.stages).map(([k, v]) => `${k} ${v.toFixed(1)}`).join(", ");
  console.log(`     packed in ${r.seconds.toFixed(1)} s (${stages(r)}), archive ${r.archive_bytes} bytes, ` +
    `wasm memory grew ${(r.memory_growth_bytes / 1e6).toFixed(1)} MB`);
  console.log(`     estimated ${e.seconds.toFixed(1)} s (${stages(e)}), archive ${e.archive_bytes} bytes, ` +
    `memory ${(e.memory_bytes / 1e6).toFixed(1)} MB`);
}

/// Drops a folder of this machine on the page as a user would: Chrome DevTools'
/// Input.dispatchDragEvent with the folder's path hands the page a drop whose item is a real
/// directory entry (webkitGetAsEntry), which index.html walks. (A DataTransfer made by a script
/// cannot hold a directory.)
async function dropFolder(context, page, folder) {
  const cdp = await context.newCDPSession(page);
  const [x, y] = await page.evaluate(() => [window.innerWidth / 2, window.innerHeight / 2]);
  const data = { items: [], files: [resolve(folder)], dragOperationsMask: 1 };
  for (const type of ["dragEnter", "dragOver", "drop"]) {
    await cdp.send("Input.dispatchDragEvent", { type, x, y, data });
  }
  await cdp.detach();
}

let pickedSceneJson = null;

await runBrowserTest("pack", {
  checks,
  consoleLog,
  viewport: { width: 1024, height: 720 },
  consoleLines: 40,
  cleanup: () => rmSync(join(notCapture, ".."), { recursive: true, force: true }),
}, async (context) => {
  const pageUrl = new URL(url);
  pageUrl.hash = PAGE_OPTIONS;
  const page = await openPage(context, pageUrl.href, "pack", consoleLog);
  let s = await settledStatus(page, PACK_TIMEOUT_MS);
  console.log(`page open with the demo scene: ${s.state} (${elapsed()})`);

  await checks.check("a folder that is no capture gets the command line's error", async () => {
    await page.setInputFiles("#capture-folder", notCapture);
    await startPack(page, PACK_TIMEOUT_MS);
    s = await waitForError(page, PACK_TIMEOUT_MS);
    assert(s.state === "error", `status is ${show(s)}`);
    assert(s.message.startsWith("holiday: not a capture layout scribblefield knows; expected one of: an autolabel"),
      `the message is ${JSON.stringify(s.message)}`);
    console.log(`     ${s.message.slice(0, 90)}…`);
  });
  await page.screenshot({ path: join(outDir, "pack-refused.png") });

  const stages = [];
  await checks.check("a COLMAP capture folder packs in the page and opens for annotation", async () => {
    await page.setInputFiles("#capture-folder", capturePath);
    const setup = await startPack(page, PACK_TIMEOUT_MS);
    const start = Date.now();
    // The settings start as the page options give them, and the estimate says what comes.
    const v = setup.values;
    assert(v.max_size === "96" && v.every === "9" && v.max_frames === "" && v.features && v.stride === "4" &&
      v.steps === "100", `the pack settings start as ${JSON.stringify(v)}, not as the page options`);
    assert(setup.images === 52 && setup.estimate.frames === sceneJson.frames.length &&
      setup.estimate.size[0] === W && setup.estimate.size[1] === H,
      `the estimate is ${JSON.stringify(setup.estimate)} of ${setup.images} images; the command line packed ` +
      `${sceneJson.frames.length} frames of ${W}x${H}`);
    // The error of the folder before stays up until packing starts.
    let packing = false;
    for (;;) {
      s = await status(page);
      packing ||= s.state === "packing";
      const stage = s.state === "packing" ? s.stage : s.state;
      if (packing && stages[stages.length - 1] !== stage) stages.push(stage);
      if (packing && s.state === "ready") break;
      if (packing && (s.state === "error" || s.state === "crashed")) throw new Error(`the page says ${show(s)}`);
      assert(Date.now() - start < PACK_TIMEOUT_MS, `not ready after ${PACK_TIMEOUT_MS / 1000} s: ${show(s)}`);
      await new Promise((r) => setTimeout(r, 100));
    }
    console.log(`     stages ${stages.join(" -> ")} in ${((Date.now() - start) / 1000).toFixed(0)} s`);
    assert(s.state === "ready", `status is ${show(s)}`);
    // The status is looked at every 100 ms: on a quick machine the frames or the autoencoder's
    // 100 steps pass between two looks, so only a stage of the feature work must be seen.
    assert(stages.some((stage) => ["frames", "features", "autoencoder"].includes(stage)),
      `no packing stage seen: ${stages.join(", ")}`);
    assert(s.frames === sceneJson.frames.length && s.size[0] === W && s.size[1] === H,
      `the page's scene is ${s.frames} frames of ${s.size}, the command line's ${sceneJson.frames.length} of ${W}x${H}`);
    assert(s.classes === sceneJson.classes.length, `${s.classes} classes, the command line's ${sceneJson.classes.length}`);
    reportEstimate(await packResult(page));
  });
  await page.screenshot({ path: join(outDir, "pack-opened.png") });

  await checks.check("scribbles on the packed scene train the field until it shows a mask", async () => {
    assert(strokes.length >= 2, `the ground truth of frame 0 gives ${strokes.length} strokes`);
    await waitForStatus(page, (t) => {
      if (t.training === "failed") throw new Error(`training failed: ${t.failure}`);
      return t.training === "running";
    }, "training to start", TRAIN_TIMEOUT_MS);
    await page.focus("#scribblefield");
    // Paused while drawing: on SwiftShader a step holds the GPU, and the strokes must not wait.
    await page.keyboard.press("Space");
    await waitForStatus(page, (t) => t.training === "paused", "the pause", 120_000);
    for (const stroke of strokes) await drawFrameStroke(page, stroke, W, H);
    await waitForStatus(page, (t) => t.strokes === strokes.length, "the strokes", 60_000);
    await page.keyboard.press("Space");
    const startSteps = (await status(page)).steps;
    s = await waitForStatus(page, (t) => t.steps >= startSteps + 5 && t.mask === "full" && t.rendered > startSteps,
      "a full mask rendered after training with the strokes", TRAIN_TIMEOUT_MS);
    console.log(`     ${strokes.length} strokes; mask at step ${s.rendered}; trains on ${JSON.stringify(s.spread)} (${elapsed()})`);
  });
  await page.screenshot({ path: join(outDir, "pack-mask.png") });

  await checks.check("the masks of the packed scene download", async () => {
    const downloadPromise = page.waitForEvent("download", { timeout: EXPORT_TIMEOUT_MS });
    let downloaded = false;
    downloadPromise.then(() => { downloaded = true; }, () => {});
    // A key press can be lost while the page is busy (annotate.mjs): press again.
    for (let attempt = 1; attempt <= 3; attempt++) {
      await page.keyboard.press("d");
      const started = await waitForStatus(page, (t) => downloaded || t.training === "exporting",
        "the export to start", 20_000).then(() => true, () => false);
      if (started) break;
    }
    const download = await downloadPromise;
    const zipPath = join(outDir, download.suggestedFilename());
    await download.saveAs(zipPath);
    console.log(`     ${download.suggestedFilename()} (${elapsed()})`);
    assert(download.suggestedFilename().startsWith("alexander-colmap"),
      `the masks are named ${download.suggestedFilename()}`);
    const files = readZip(readFileSync(zipPath));
    const manifest = JSON.parse(files.get("classes.json").toString("utf8"));
    assert(manifest.frames === sceneJson.frames.length, `the manifest lists ${manifest.frames} frames`);
    const masks = manifest.files.map((name) => decodePng(files.get(name)));
    assert(masks.every((m) => m.width === W && m.height === H && m.channels === 1), "masks have the wrong format");
    // Pixel accuracy against the command line's ground truth, for the record: a few steps of
    // the tiny model are far from converged.
    let right = 0, counted = 0;
    sceneJson.frames.forEach((f, i) => {
      const g = decodePng(reference.get(f.gt)).data;
      for (let p = 0; p < g.length; p++) if (g[p] !== 255) { counted += 1; right += g[p] === masks[i].data[p] ? 1 : 0; }
    });
    const classesSeen = new Set(masks.flatMap((m) => [...new Set(m.data)]));
    console.log(`     ${masks.length} masks of ${W}x${H}; classes ${[...classesSeen].sort()}; pixel accuracy ` +
      `${(right / counted).toFixed(3)} against the ground truth`);
    assert(classesSeen.size >= 2, `the masks hold one class only (${[...classesSeen]})`);
  });

  await checks.check("save scene archive downloads the packed archive", async () => {
    const downloadPromise = page.waitForEvent("download", { timeout: 60_000 });
    await page.keyboard.press("a");
    const download = await downloadPromise;
    const zipPath = join(outDir, download.suggestedFilename());
    await download.saveAs(zipPath);
    assert(download.suggestedFilename() === "alexander-colmap.scene.zip", `named ${download.suggestedFilename()}`);
    const packed = readZip(readFileSync(zipPath));
    const packedJson = JSON.parse(packed.get("scene.json").toString("utf8"));
    assert(packedJson.frames.length === sceneJson.frames.length && packedJson.width === W && packedJson.height === H,
      `the archive has ${packedJson.frames.length} frames of ${packedJson.width}x${packedJson.height}`);
    assert(packedJson.features, "the archive has no feature codes");
    pickedSceneJson = packedJson;
    console.log(`     ${download.suggestedFilename()}: ${readFileSync(zipPath).length} bytes, ` +
      `features ${packedJson.features.width} x ${packedJson.features.height} x ${packedJson.features.dim}`);
  });

  await checks.check("a zip of the capture folder dropped on the page packs and opens", async () => {
    // The same page options, on a page of its own (it reads them once, when it opens).
    await page.close();
    const dropPage = await openPage(context, pageUrl.href, "drop", consoleLog);
    await settledStatus(dropPage, PACK_TIMEOUT_MS);
    const zip = await dropZip(dropPage, capturePath);
    await startPack(dropPage, PACK_TIMEOUT_MS);
    s = await waitForPacked(dropPage, "the dropped capture to open", PACK_TIMEOUT_MS);
    assert(s.frames === sceneJson.frames.length && s.size[0] === W && s.size[1] === H,
      `the dropped zip gave ${s.frames} frames of ${s.size}, the command line ${sceneJson.frames.length} of ${W}x${H}`);
    console.log(`     ${(zip.length / 1e6).toFixed(1)} MB zip dropped; ${s.frames} frames of ${s.size} (${elapsed()})`);
    await dropPage.close();
  });

  await checks.check("a capture folder dropped on the page packs to the same scene", async () => {
    const dropPage = await openPage(context, pageUrl.href, "drop-folder", consoleLog);
    await settledStatus(dropPage, PACK_TIMEOUT_MS);
    await dropFolder(context, dropPage, capturePath);
    const setup = await startPack(dropPage, PACK_TIMEOUT_MS);
    assert(setup.name === basename(capturePath) && setup.images === 52,
      `the dropped folder is ${setup.name} with ${setup.images} images`);
    s = await waitForPacked(dropPage, "the dropped folder to open", PACK_TIMEOUT_MS);
    assert(s.frames === sceneJson.frames.length && s.size[0] === W && s.size[1] === H,
      `the dropped folder gave ${s.frames} frames of ${s.size}, the command line ${sceneJson.frames.length} of ${W}x${H}`);
    // The very archive the folder picked with the input gave.
    const downloadPromise = dropPage.waitForEvent("download", { timeout: 60_000 });
    await dropPage.focus("#scribblefield");
    await dropPage.keyboard.press("a");
    const download = await downloadPromise;
    const zipPath = join(outDir, `dropped-${download.suggestedFilename()}`);
    await download.saveAs(zipPath);
    const droppedJson = JSON.parse(readZip(readFileSync(zipPath)).get("scene.json").toString("utf8"));
    assert(pickedSceneJson, "no archive of the picked folder to compare with (an earlier check failed)");
    assert(JSON.stringify(droppedJson) === JSON.stringify(pickedSceneJson),
      "the dropped folder's scene.json differs from the picked folder's");
    console.log(`     ${setup.images} images dropped as a folder; ${s.frames} frames of ${s.size}, the same ` +
      `scene.json as the picked folder (${elapsed()})`);
    await dropPage.close();
  });

  await checks.check("without pack options a photo capture starts at the photo captures' size, one with depth at 640",
    async () => {
      const bare = new URL(url);
      bare.hash = "model=tiny";
      const defaultsPage = await openPage(context, bare.href, "defaults", consoleLog);
      await settledStatus(defaultsPage, PACK_TIMEOUT_MS);
      const startsAs = async (folder) => {
        await defaultsPage.setInputFiles("#capture-folder", folder);
        const t = await waitForPackSetup(defaultsPage, (t) => t && t.estimate, "the pack settings", PACK_TIMEOUT_MS);
        await cancelPackSetup(defaultsPage);
        return t;
      };
      const photos = await startsAs(capturePath);
      assert(photos.values.max_size === "200" && photos.values.stride === "2" &&
        photos.caption.includes("No depth images"),
        `the COLMAP capture's settings start as ${JSON.stringify(photos.values)}: ${photos.caption}`);
      console.log(`     ${photos.caption}`);
      if (depthCapturePath) {
        const depth = await startsAs(depthCapturePath);
        assert(depth.values.max_size === "640" && depth.values.stride === "8" && !depth.caption.includes("No depth"),
          `the RGB-D capture's settings start as ${JSON.stringify(depth.values)}: ${depth.caption}`);
      }
      await defaultsPage.close();
    });

  await checks.check("the pack settings estimate, refuse bad values, cancel, and pack with what was changed",
    async () => {
      const setPage = await openPage(context, pageUrl.href, "settings", consoleLog);
      const before = await settledStatus(setPage, PACK_TIMEOUT_MS);
      // Cancel leaves the scene open as it was.
      await setPage.setInputFiles("#capture-folder", capturePath);
      await waitForPackSetup(setPage, (t) => t && t.estimate, "the pack settings", PACK_TIMEOUT_MS);
      await cancelPackSetup(setPage);
      s = await status(setPage);
      assert(s.state === "ready" && s.frames === before.frames, `after Cancel the page says ${show(s)}`);

      await setPage.setInputFiles("#capture-folder", capturePath);
      const first = await waitForPackSetup(setPage, (t) => t && t.estimate, "the pack settings", PACK_TIMEOUT_MS);
      // A bad value is named and keeps packing from starting.
      let t = await setPackField(setPage, "max_size", "4");
      assert(t.errors.max_size && t.errors.max_size.includes("is not a longest side from 8 to 8192 pixels") &&
        t.estimate === null, `with a longest side of 4 the form says ${JSON.stringify(t.errors)}`);
      await clickPackControl(setPage, "start");
      await new Promise((r) => setTimeout(r, 3000));
      t = await packSetup(setPage);
      s = await status(setPage);
      assert(t !== null && s.state === "ready" && s.frames === before.frames,
        `Start with a bad value: settings ${t ? "shown" : "gone"}, page ${show(s)}`);
      t = await setPackField(setPage, "max_frames", "0");
      assert(t.errors.max_frames, `at most 0 frames is accepted: ${JSON.stringify(t.errors)}`);
      // Smaller frames and fewer of them: the estimate follows.
      await setPackField(setPage, "max_size", "64");
      t = await setPackField(setPage, "max_frames", "4");
      const size = [64, Math.round(64 * H / W)];
      assert(Object.keys(t.errors).length === 0 && t.estimate, `the form says ${JSON.stringify(t.errors)}`);
      assert(t.estimate.frames === 4 && t.estimate.size[0] === size[0] && t.estimate.size[1] === size[1],
        `the estimate is ${t.estimate.frames} frames of ${t.estimate.size}, not 4 of ${size}`);
      assert(t.estimate.archive_bytes < first.estimate.archive_bytes &&
        t.estimate.memory_bytes < first.estimate.memory_bytes && t.estimate.seconds < first.estimate.seconds,
        `the estimate did not shrink: ${JSON.stringify(first.estimate)} -> ${JSON.stringify(t.estimate)}`);
      console.log(`     estimate ${first.estimate.frames} frames of ${first.estimate.size}, ` +
        `${first.estimate.archive_bytes} bytes -> ${t.estimate.frames} of ${t.estimate.size}, ` +
        `${t.estimate.archive_bytes} bytes`);
      // No features: no grid.
      await clickPackControl(setPage, "features");
      t = await waitForPackSetup(setPage, (x) => x && !x.values.features, "features off", 60_000);
      assert(t.estimate && t.estimate.grid === null, `without features the estimate has ${JSON.stringify(t.estimate)}`);
      await startPack(setPage, PACK_TIMEOUT_MS);
      s = await waitForPacked(setPage, "the capture packed with the changed settings", PACK_TIMEOUT_MS);
      assert(s.frames === 4 && s.size[0] === size[0] && s.size[1] === size[1],
        `packed ${s.frames} frames of ${s.size}, the settings asked for 4 of ${size}`);
      const result = await packResult(setPage);
      reportEstimate(result);
      assert(result.stages.features === 0 || result.stages.features < 0.5,
        `features took ${result.stages.features} s though they were off`);
      await setPage.close();
    });

  await checks.check("packing can be cancelled", async () => {
    // A fit far longer than the test waits.
    const slow = new URL(url);
    // (The first occurrence of a key counts.)
    slow.hash = `pack-steps=100000&${PAGE_OPTIONS}`;
    // A page of its own: the page reads its options once, when it opens.
    const slowPage = await openPage(context, slow.href, "cancel", consoleLog);
    await settledStatus(slowPage, PACK_TIMEOUT_MS);
    await slowPage.setInputFiles("#capture-folder", capturePath);
    await startPack(slowPage, PACK_TIMEOUT_MS);
    await waitForStatus(slowPage, (t) => t.state === "packing" && t.stage === "autoencoder", "the autoencoder",
      PACK_TIMEOUT_MS);
    await slowPage.focus("#scribblefield");
    await slowPage.keyboard.press("Escape");
    s = await waitForStatus(slowPage, (t) => t.state === "cancelled", "the cancel", 60_000);
    console.log(`     cancelled during the autoencoder fit (${elapsed()})`);
  });
});
