// The page's training bench (`#bench=PRESET`, src/app/bench.rs) in headless Chromium (WebGPU on
// SwiftShader): it trains the preset on the built-in demo scene as the page trains and reports
// the figures of `scribblefield bench --json` on <body data-bench>. The checks are that the
// report is complete and its numbers are consistent, never how fast they are: timings are
// measurements (docs/results/bench.md), not test thresholds. Starts no server: run.sh does
// (`tests/e2e/run.sh bench` runs this test alone), or point E2E_URL at one.
//
//   E2E_URL            page to open (required)
//   E2E_BENCH          preset to train (default tiny: the quickest)
//   E2E_BENCH_STEPS    timed steps (default 3)
//   E2E_BENCH_OPTIONS  more page options, e.g. `bench-inflight=1&rays=512`
//   E2E_BENCH_JSON     write the report to this file too
//   E2E_CHROMIUM_ARGS  more Chromium flags, space-separated (e.g. Dawn toggles, to find out
//                      where time goes)
//   CHROMIUM           browser binary (default /usr/bin/chromium)
import { writeFileSync } from "node:fs";
import { assert, CHROMIUM_ARGS, Checks, openPage, runBrowserTest, status, show } from "./lib.mjs";

const url = process.env.E2E_URL;
if (!url) {
  console.error("E2E_URL is not set: give the URL of the served page, e.g. E2E_URL=http://127.0.0.1:8080/");
  process.exit(2);
}
const preset = process.env.E2E_BENCH || "tiny";
const steps = Number(process.env.E2E_BENCH_STEPS || 3);
const extra = process.env.E2E_BENCH_OPTIONS ? `&${process.env.E2E_BENCH_OPTIONS}` : "";
// Compiling the wasm and the kernels on a CPU rasterizer, rendering the demo scene, the steps
// and the plain matmul: minutes on a small, busy machine for the larger presets.
const TIMEOUT_MS = Number(process.env.E2E_BENCH_TIMEOUT_MS || 900_000);

CHROMIUM_ARGS.push(...(process.env.E2E_CHROMIUM_ARGS || "").split(" ").filter((a) => a));
const consoleLog = [];
const checks = new Checks();
const check = (name, body) => checks.check(name, body);

function bench(page) {
  return page.evaluate(() => {
    try {
      return JSON.parse(document.body.dataset.bench || "null");
    } catch {
      return { state: "unreadable", text: document.body.dataset.bench };
    }
  });
}

const positive = (x) => typeof x === "number" && Number.isFinite(x) && x > 0;
const close = (a, b) => Math.abs(a - b) <= 1e-9 * Math.max(Math.abs(a), Math.abs(b), 1);

await runBrowserTest("bench", { checks, consoleLog }, async (context) => {
  const page = await openPage(context, new URL(`#bench=${preset}&bench-steps=${steps}${extra}`, url).href, "bench", consoleLog);
  const started = Date.now();
  let report = null;
  let stage = "";
  while (Date.now() - started < TIMEOUT_MS) {
    report = await bench(page);
    if (report && report.stage !== stage) {
      stage = report.stage;
      if (stage) console.log(`  ${((Date.now() - started) / 1000).toFixed(0)} s: ${stage}`);
    }
    if (report && ["done", "error", "unreadable"].includes(report.state)) break;
    const s = await status(page);
    if (s.state === "crashed" || s.state === "error") {
      report = { state: "error", message: `the page says ${show(s)}` };
      break;
    }
    await new Promise((r) => setTimeout(r, 500));
  }
  console.log(`bench report after ${((Date.now() - started) / 1000).toFixed(0)} s: ${JSON.stringify(report)}`);
  if (report && process.env.E2E_BENCH_JSON) writeFileSync(process.env.E2E_BENCH_JSON, `${JSON.stringify(report)}\n`);

  await check("the bench finishes with a report", async () => {
    assert(report && report.state === "done", `data-bench is ${JSON.stringify(report)}`);
  });
  if (!report || report.state !== "done") return;
  await check("it names the adapter, the preset, the kernels and the atomics", async () => {
    assert(typeof report.adapter === "string" && report.adapter.length > 0, `adapter ${report.adapter}`);
    assert(report.config === preset, `config ${report.config}, asked for ${preset}`);
    assert(["uniform", "tiled"].includes(report.kernels), `kernels ${report.kernels}`);
    // Browsers have no float atomics: the hash backward adds in fixed point on a GPU and with
    // one invocation per level, without atomics, on a CPU rasterizer (AtomicAdd::best_for;
    // kernels=tiled makes the page treat SwiftShader as a GPU).
    const atomics = report.kernels === "tiled" ? "fixed_point" : "per_level";
    assert(report.hash_atomics === atomics, `hash_atomics ${report.hash_atomics} with kernels ${report.kernels}`);
  });
  await check("it timed the steps asked for, at a positive finite rate", async () => {
    assert(report.steps_timed === steps, `steps_timed ${report.steps_timed}, asked for ${steps}`);
    for (const key of ["step_s", "steps_per_s", "rays_per_s", "samples_per_s", "mlp_gflop_per_step", "mlp_gflops", "matmul_gflops", "ratio_to_matmul"]) {
      assert(positive(report[key]), `${key} is ${report[key]}`);
    }
  });
  await check("the rates agree with each other and with the batch", async () => {
    assert(positive(report.rays) && positive(report.samples_per_ray), `batch ${report.rays} x ${report.samples_per_ray}`);
    assert(close(report.steps_per_s * report.step_s, 1), `steps/s ${report.steps_per_s} x step ${report.step_s}`);
    assert(close(report.rays_per_s, report.steps_per_s * report.rays), `rays/s ${report.rays_per_s}`);
    assert(close(report.samples_per_s, report.rays_per_s * report.samples_per_ray), `samples/s ${report.samples_per_s}`);
    // The keep stage's mean over the timed steps: some, at most every sample of the batch.
    assert(positive(report.samples_to_heads_per_step) && report.samples_to_heads_per_step <= report.rays * report.samples_per_ray, `samples to the heads ${report.samples_to_heads_per_step}`);
  });
  await check("the stages add up to the step's dispatches and bytes", async () => {
    assert(Array.isArray(report.stages) && report.stages.length > 0, "no stages");
    const dispatches = report.stages.reduce((a, s) => a + s.dispatches, 0);
    const bytes = report.stages.reduce((a, s) => a + s.bytes, 0);
    assert(Number.isInteger(report.dispatches_per_step) && report.dispatches_per_step > 0, `dispatches ${report.dispatches_per_step}`);
    assert(dispatches === report.dispatches_per_step, `stages ${dispatches} dispatches, step ${report.dispatches_per_step}`);
    assert(bytes === report.bytes_per_step, `stages ${bytes} bytes, step ${report.bytes_per_step}`);
    // No timestamp queries in the page: no GPU times per stage.
    assert(report.stages.every((s) => s.gpu_ms === null || positive(s.gpu_ms)), "a stage's gpu_ms is neither null nor positive");
  });
  await check("the field trained: a finite loss, the page's batches counted", async () => {
    assert(typeof report.loss_per_ray === "number" && Number.isFinite(report.loss_per_ray), `loss per ray ${report.loss_per_ray}`);
    const p = report.page;
    assert(p && p.batches >= 1 && p.largest_batch >= 1 && p.in_flight >= 1, `page ${JSON.stringify(p)}`);
    for (const key of ["record_ms_per_step", "wait_ms_per_step", "yield_ms_per_step", "paint_cpu_ms_per_step"]) {
      assert(typeof p[key] === "number" && p[key] >= 0, `page.${key} is ${p[key]}`);
    }
  });
});
