#!/usr/bin/env bash
# Browser end-to-end test: builds the web app, serves it on a free localhost port, and runs
# smoke.mjs, annotate.mjs, durable.mjs and (with ../shared/data beside the repository)
# spread.mjs, pack.mjs and stray.mjs in headless Chromium (WebGPU on SwiftShader), then bench.mjs (the page's
# training bench, its report checked, no timings asserted) with the kernels of a CPU device and
# with those of a GPU. Installs Chromium (apt) and the node
# modules (npm ci) when they are missing. Screenshots go to $E2E_OUT (default /tmp/e2e).
#
# With test names as arguments it runs only those: `tests/e2e/run.sh bench` (E2E_BENCH=budget
# E2E_BENCH_STEPS=20 for a measurement; bench.mjs lists its settings).
set -euo pipefail
ONLY=" $* "
# Whether the test named $1 is to run.
wanted() { [ "$ONLY" = "  " ] || [[ "$ONLY" == *" $1 "* ]]; }
HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
cd "$ROOT"

CHROMIUM=${CHROMIUM:-/usr/bin/chromium}
if [ ! -x "$CHROMIUM" ]; then
  echo "==> installing chromium"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq chromium
fi
if ! command -v node >/dev/null 2>&1; then
  echo "error: node (>= 20) is needed for the browser test" >&2
  exit 1
fi
if [ ! -d "$HERE/node_modules/playwright-core" ]; then
  echo "==> npm ci"
  (cd "$HERE" && npm ci --no-audit --no-fund)
fi

scripts/build-web.sh
cargo build --release --quiet

# A photo capture with sparse depth for spread.mjs, packed small, when the shared data is there.
SPARSE_CAPTURE="$ROOT/../shared/data/alexander-colmap"
SPARSE=""
if [ -d "$SPARSE_CAPTURE" ] && { wanted spread || wanted pack; }; then
  SPARSE="$ROOT/www/e2e-sparse.scene.zip"
  target/release/scribblefield pack "$SPARSE_CAPTURE" -o "$SPARSE" --max-size 120 --features baseline \
    --feature-stride 2 >/dev/null
  # pack.mjs packs the capture folder in the page with these options (its page options say
  # the same); this archive, packed by the command line, gives it the ground truth to plan
  # strokes from and the scene the page must arrive at.
  PACK_REFERENCE="$(mktemp -d)/alexander-colmap.scene.zip"
  target/release/scribblefield pack "$SPARSE_CAPTURE" -o "$PACK_REFERENCE" --max-size 96 --every 9 --no-features \
    >/dev/null
elif [ ! -d "$SPARSE_CAPTURE" ]; then
  echo "(no $SPARSE_CAPTURE: skipping spread.mjs and pack.mjs)"
fi

# stray.mjs: the YCB clip written as a Stray Scanner capture (H.264 and HEVC videos, encoded by
# ffmpeg), and the first packed by the command line as the page must pack it.
STRAY_DIR=""
if [ -d "$ROOT/../shared/data/ycb-video-0000" ] && command -v ffmpeg >/dev/null 2>&1 && wanted stray; then
  STRAY_DIR="$(mktemp -d)"
  STRAY_FIXTURE="$STRAY_DIR" cargo test --release --quiet --test import_stray write_browser_fixture -- --ignored \
    >/dev/null
  target/release/scribblefield pack "$STRAY_DIR/ycb-stray" -o "$STRAY_DIR/reference.scene.zip" --max-size 160 \
    --every 3 --no-features >/dev/null
elif wanted stray; then
  echo "(no ../shared/data/ycb-video-0000 or no ffmpeg: skipping stray.mjs)"
fi

# A free port: bind port 0, note what the kernel chose, release it for the server.
PORT=$(node -e 'const s=require("net").createServer().listen(0,"127.0.0.1",()=>{console.log(s.address().port);s.close()})')
LOG=$(mktemp)
target/release/scribblefield serve www --port "$PORT" >"$LOG" 2>&1 &
SERVER=$!
trap 'kill "$SERVER" 2>/dev/null || true; wait "$SERVER" 2>/dev/null || true; rm -f "$LOG" ${SPARSE:+"$SPARSE"}; [ -z "${PACK_REFERENCE:-}" ] || rm -rf "$(dirname "$PACK_REFERENCE")"; [ -z "$STRAY_DIR" ] || rm -rf "$STRAY_DIR"' EXIT

URL="http://127.0.0.1:$PORT/"
for _ in $(seq 1 100); do
  if node -e 'fetch(process.argv[1]).then(r=>process.exit(r.ok?0:1),()=>process.exit(1))' "$URL"; then
    break
  fi
  if ! kill -0 "$SERVER" 2>/dev/null; then
    echo "error: the server exited:" >&2
    cat "$LOG" >&2
    exit 1
  fi
  sleep 0.1
done

# Every test runs even when one fails, so one run shows every failure.
STATUS=0
if wanted smoke; then
  E2E_URL="$URL" CHROMIUM="$CHROMIUM" node "$HERE/smoke.mjs" || STATUS=1
fi
if wanted annotate; then
  E2E_URL="$URL" CHROMIUM="$CHROMIUM" E2E_DEMO="$ROOT/www/demo.scene.zip" node "$HERE/annotate.mjs" || STATUS=1
fi
if wanted durable; then
  E2E_URL="$URL" CHROMIUM="$CHROMIUM" E2E_DEMO="$ROOT/www/demo.scene.zip" node "$HERE/durable.mjs" || STATUS=1
fi
if [ -n "$SPARSE" ]; then
  if wanted spread; then
    E2E_URL="$URL" CHROMIUM="$CHROMIUM" E2E_SPARSE="$SPARSE" node "$HERE/spread.mjs" || STATUS=1
  fi
  if wanted pack; then
    E2E_URL="$URL" CHROMIUM="$CHROMIUM" E2E_CAPTURE="$SPARSE_CAPTURE" E2E_REFERENCE="$PACK_REFERENCE" \
      node "$HERE/pack.mjs" || STATUS=1
  fi
fi
if [ -n "$STRAY_DIR" ]; then
  E2E_URL="$URL" CHROMIUM="$CHROMIUM" E2E_STRAY="$STRAY_DIR/ycb-stray" E2E_STRAY_HEVC="$STRAY_DIR/ycb-stray-hevc" \
    E2E_STRAY_REFERENCE="$STRAY_DIR/reference.scene.zip" node "$HERE/stray.mjs" || STATUS=1
fi
if wanted bench; then
  E2E_URL="$URL" CHROMIUM="$CHROMIUM" node "$HERE/bench.mjs" || STATUS=1
  # A GPU's kernels on SwiftShader, as a browser on a GPU runs them: the workgroup-tiled dense
  # layers and the hash gradient in fixed point (the report must say `fixed_point`).
  E2E_URL="$URL" CHROMIUM="$CHROMIUM" E2E_BENCH_STEPS=1 E2E_BENCH_OPTIONS=kernels=tiled \
    node "$HERE/bench.mjs" || STATUS=1
fi
exit $STATUS
