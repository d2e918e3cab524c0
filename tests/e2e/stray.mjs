// End-to-end test of a Stray Scanner phone capture packed in the page: a zip of the YCB clip
// written in the app's layout (tests/import_stray.rs `write_browser_fixture`: an H.264 rgb.mp4
// whose frames carry their number in a corner block of colour, depth at 256x192, confidence maps,
// ARKit odometry) is dropped on the page, whose settings count its frames and read the video's
// size from its MP4 index; the page decodes the kept frames with the browser's own decoder, and
// the archive it saves must be the one `pack` writes with ffmpeg: the same frames (by number),
// poses and camera, colours close, and each frame's corner block the colour of its number. Then
// the same capture as the app records it (HEVC, which this Chromium does not decode) is refused
// with a message that names the video. Starts no server: run.sh does.
//
//   E2E_URL              page to open (required)
//   E2E_STRAY            the capture folder (H.264) (required)
//   E2E_STRAY_HEVC       the same with an HEVC video (required)
//   E2E_STRAY_REFERENCE  the capture packed by the command line: `pack E2E_STRAY --max-size 160
//                        --every 3 --no-features` (required)
//   E2E_OUT              folder for screenshots and the saved archive (default /tmp/e2e)
//   CHROMIUM             browser binary (default /usr/bin/chromium)
import { mkdirSync, readFileSync } from "node:fs";
import { join } from "node:path";
import {
  assert, Checks, decodePng, dropZip, openPage, readZip, runBrowserTest, settledStatus, show, startPack, waitForError,
  waitForPacked,
} from "./lib.mjs";

const url = process.env.E2E_URL;
const capturePath = process.env.E2E_STRAY;
const hevcPath = process.env.E2E_STRAY_HEVC;
const referencePath = process.env.E2E_STRAY_REFERENCE;
if (!url || !capturePath || !hevcPath || !referencePath) {
  console.error("E2E_URL, E2E_STRAY, E2E_STRAY_HEVC and E2E_STRAY_REFERENCE must be set (tests/e2e/run.sh sets them)");
  process.exit(2);
}
const outDir = process.env.E2E_OUT || "/tmp/e2e";
mkdirSync(outDir, { recursive: true });
// As `pack --max-size 160 --every 3 --no-features`: frames 0, 3, 6 and 9 of 10.
const PAGE_OPTIONS = "pack-size=160&pack-every=3&pack-stride=0&model=tiny&rays=256";
const TIMEOUT_MS = 300_000;
/// The corner block of frame `n` (tests/import_stray.rs `marker`).
const marker = (n) => [n * 25, 255 - n * 25, 128];
/// A channel of the corner block may move this far through H.264 and two different decoders.
const MARKER_TOLERANCE = 16;
/// Mean difference of a channel between the browser's and ffmpeg's decoding of one frame.
const COLOUR_TOLERANCE = 6;

const checks = new Checks();
const consoleLog = [];
const reference = readZip(readFileSync(referencePath));
const referenceJson = JSON.parse(reference.get("scene.json").toString("utf8"));

await runBrowserTest("stray", { checks, consoleLog }, async (context) => {
  const pageUrl = new URL(url);
  pageUrl.hash = PAGE_OPTIONS;

  await checks.check("a Stray Scanner capture dropped as a zip packs in the page as on the command line", async () => {
    const page = await openPage(context, pageUrl.href, "stray", consoleLog);
    await settledStatus(page, TIMEOUT_MS);
    await dropZip(page, capturePath);
    const setup = await startPack(page, TIMEOUT_MS);
    assert(setup.images === 10 && setup.estimate.frames === 4 && setup.estimate.size[0] === 160,
      `the pack settings saw ${setup.images} frames and estimated ${JSON.stringify(setup.estimate)}`);
    const s = await waitForPacked(page, "the Stray Scanner capture to open", TIMEOUT_MS);
    assert(s.frames === 4 && s.size[0] === 160 && s.size[1] === 120, `the page packed ${show(s)}`);
    await page.screenshot({ path: join(outDir, "stray-packed.png") });

    const downloadPromise = page.waitForEvent("download", { timeout: 60_000 });
    await page.keyboard.press("a");
    const download = await downloadPromise;
    const zipPath = join(outDir, download.suggestedFilename());
    await download.saveAs(zipPath);
    const packed = readZip(readFileSync(zipPath));
    const json = JSON.parse(packed.get("scene.json").toString("utf8"));
    assert(JSON.stringify(json.intrinsics) === JSON.stringify(referenceJson.intrinsics),
      `intrinsics ${JSON.stringify(json.intrinsics)}, the command line's ${JSON.stringify(referenceJson.intrinsics)}`);
    assert(JSON.stringify(json.bounds) === JSON.stringify(referenceJson.bounds),
      `bounds ${JSON.stringify(json.bounds)}, the command line's ${JSON.stringify(referenceJson.bounds)}`);
    assert(json.frames.length === referenceJson.frames.length, `${json.frames.length} frames`);
    json.frames.forEach((f, i) => {
      const r = referenceJson.frames[i];
      assert(f.source === r.source, `frame ${i} is ${f.source}, the command line's ${r.source}`);
      assert(JSON.stringify(f.pose) === JSON.stringify(r.pose), `frame ${i}'s pose differs`);
      const mine = decodePng(packed.get(f.rgb));
      const theirs = decodePng(reference.get(r.rgb));
      let sum = 0;
      for (let p = 0; p < mine.data.length; p++) sum += Math.abs(mine.data[p] - theirs.data[p]);
      const mean = sum / mine.data.length;
      // The corner block's middle: 48 px of 640 is 12 px of 160.
      const at = (5 * mine.width + 5) * 3;
      const got = [...mine.data.slice(at, at + 3)];
      const want = marker(Number(f.source));
      console.log(`     frame ${f.source}: corner ${got}, expected ${want}; mean difference from ffmpeg's ` +
        `${mean.toFixed(2)}`);
      assert(got.every((c, k) => Math.abs(c - want[k]) <= MARKER_TOLERANCE),
        `frame ${f.source}'s corner is ${got}, the colour of frame ${want} expected: another frame was decoded`);
      assert(mean <= COLOUR_TOLERANCE, `frame ${f.source}'s colours differ from ffmpeg's by ${mean.toFixed(2)} on average`);
    });
    await page.close();
  });

  await checks.check("a video the browser cannot decode is refused naming it", async () => {
    const page = await openPage(context, pageUrl.href, "stray-hevc", consoleLog);
    await settledStatus(page, TIMEOUT_MS);
    await dropZip(page, hevcPath);
    await startPack(page, TIMEOUT_MS);
    const s = await waitForError(page, TIMEOUT_MS);
    assert(s.state === "error" && s.message.includes("rgb.mp4") && s.message.includes("could not decode"),
      `the page says ${show(s)}`);
    console.log(`     ${s.message}`);
    await page.close();
  });
});
