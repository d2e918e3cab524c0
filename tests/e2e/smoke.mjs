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

const CHROMIUM_ARGS = [
  "--headless=new",
  "--no-sandbox",
  "--enable-unsafe-webgpu",
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  "--no-first-run",
  "--disable-quic",
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
  await check("ArrowRight shows the next frame, ArrowLeft the previous", async () => {
    assert(loaded.startsWith("ready"), "no scene to step through");
    await page.focus("#scribblefield");
    await page.keyboard.press("ArrowRight");
    await page.waitForFunction(() => / frame=1\b/.test(document.body.dataset.status), null, {
      timeout: STEP_TIMEOUT_MS,
    });
    await page.screenshot({ path: join(outDir, "smoke-frame1.png") });
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
