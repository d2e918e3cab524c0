// Smoke test of the served web app in headless Chromium (WebGPU on SwiftShader): the demo scene
// loads, shows the expected frame count, the arrow keys step through frames, and a missing
// scene is reported in the page. Starts no server: run.sh does, or point E2E_URL at one.
//
//   E2E_URL      page to open, e.g. http://127.0.0.1:8080/ (required)
//   E2E_OUT      folder for screenshots (default /tmp/e2e)
//   E2E_FRAMES   frame count the loaded scene must have (default 36, the demo scene's)
//   CHROMIUM     browser binary (default /usr/bin/chromium)
import { mkdirSync } from "node:fs";
import { join } from "node:path";
import {
  assert, Checks, openPage as open, runBrowserTest, saturatedColours, settledStatus as settled, show,
} from "./lib.mjs";

const url = process.env.E2E_URL;
if (!url) {
  console.error("E2E_URL is not set: give the URL of the served page, e.g. E2E_URL=http://127.0.0.1:8080/");
  process.exit(2);
}
const outDir = process.env.E2E_OUT || "/tmp/e2e";
const expectedFrames = Number(process.env.E2E_FRAMES || 36);
// Compiling the wasm and starting WebGPU on a CPU rasterizer is slow on a small machine.
const LOAD_TIMEOUT_MS = 180_000;
const STEP_TIMEOUT_MS = 15_000;
// Measured: about 10,000 with the demo frame on screen, about 340 for the UI with an error
// message (anti-aliased red text), 0 for an empty canvas.
const MIN_FRAME_COLOURS = 2000;

mkdirSync(outDir, { recursive: true });
const consoleLog = [];
const checks = new Checks();
const check = (name, body) => checks.check(name, body);
const settledStatus = (page) => settled(page, LOAD_TIMEOUT_MS);
const openPage = (context, pageUrl, label) => open(context, pageUrl, label, consoleLog);

await runBrowserTest("smoke", {
  checks,
  consoleLog,
  viewport: { width: 1280, height: 800 },
  consoleLines: Infinity,
  summary: () => `screenshots in ${outDir}`,
}, async (context) => {
  const page = await openPage(context, url, "demo");
  const started = Date.now();
  const loaded = await settledStatus(page);
  console.log(`page status after ${((Date.now() - started) / 1000).toFixed(1)} s: ${show(loaded)}`);

  await check("the demo scene loads", async () => {
    assert(loaded.state === "ready", `status is ${show(loaded)}`);
  });
  await check(`the scene has ${expectedFrames} frames`, async () => {
    assert(loaded.frames === expectedFrames, `status is ${show(loaded)}`);
    assert(loaded.frame === 0, `the first frame shown should be 0: ${show(loaded)}`);
  });
  await check("ArrowRight shows the next frame (visible in a screenshot), ArrowLeft the previous", async () => {
    assert(loaded.state === "ready", "no scene to step through");
    await page.focus("#scribblefield");
    await page.keyboard.press("ArrowRight");
    await page.waitForFunction(() => JSON.parse(document.body.dataset.status).frame === 1, null, {
      timeout: STEP_TIMEOUT_MS,
    });
    const shot = await page.screenshot({ path: join(outDir, "smoke-frame1.png") });
    const colours = saturatedColours(shot);
    assert(colours >= MIN_FRAME_COLOURS, `the screenshot has ${colours} distinct saturated colours, ` +
      `fewer than the ${MIN_FRAME_COLOURS} of a visible frame: is the canvas blank?`);
    console.log(`     (screenshot: ${colours} distinct saturated colours)`);
    await page.keyboard.press("ArrowLeft");
    await page.waitForFunction(() => JSON.parse(document.body.dataset.status).frame === 0, null, {
      timeout: STEP_TIMEOUT_MS,
    });
  });
  await page.screenshot({ path: join(outDir, "smoke.png") });

  const missing = new URL(url);
  missing.hash = "scene=does-not-exist.scene.zip";
  const errorPage = await openPage(context, missing.href, "missing scene");
  const errorStatus = await settledStatus(errorPage);
  await check("a missing scene is reported with the URL and HTTP 404", async () => {
    assert(errorStatus.state === "error", `status is ${show(errorStatus)}`);
    assert(errorStatus.message.includes("does-not-exist.scene.zip"), `the message does not name the URL: ${show(errorStatus)}`);
    assert(errorStatus.message.includes("404"), `the message does not give the HTTP status: ${show(errorStatus)}`);
  });
  await errorPage.screenshot({ path: join(outDir, "smoke-missing-scene.png") });
});
