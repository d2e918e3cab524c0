#!/usr/bin/env bash
# Compares the page's training steps with native ones on the same software device: Chromium's
# own SwiftShader, which the page gets without a GPU and which the native `bench` runs through
# its Vulkan ICD. Alternates `scribblefield bench --json` and the page bench
# (`tests/e2e/run.sh bench`) RUNS times and prints each pair's steps/s and their ratio
# (docs/results/bench.md, "The page against native" and "Tint divides per uniform access").
#
#   scripts/bench-page-native.sh [PRESET] [RUNS] [STEPS]
#
# PRESET defaults to budget, RUNS to 2, STEPS to 10. Needs what tests/e2e/run.sh installs
# (chromium, node modules); builds the web app and the release binary first.
set -euo pipefail
case "${1:-}" in
  -h | --help)
    sed -n '2,11p' "$0" | sed 's/^# \{0,1\}//'
    exit 0
    ;;
esac
PRESET=${1:-budget}
RUNS=${2:-2}
STEPS=${3:-10}
cd "$(dirname "$0")/.."
ICD=$(dpkg -L chromium-common chromium 2>/dev/null | grep vk_swiftshader_icd.json | head -n 1 || true)
if [ -z "$ICD" ]; then
  echo "error: no vk_swiftshader_icd.json in the chromium package (apt-get install chromium)" >&2
  exit 1
fi
cargo build --release --quiet
LOG=$(mktemp)
trap 'rm -f "$LOG"' EXIT
steps_per_s() { python3 -c 'import json,sys; print("%.3f" % json.loads(sys.stdin.read())["steps_per_s"])'; }
for run in $(seq 1 "$RUNS"); do
  native=$(VK_ICD_FILENAMES="$ICD" XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp} target/release/scribblefield bench \
    --preset "$PRESET" --steps "$STEPS" --warmup 2 --json 2>/dev/null | steps_per_s)
  E2E_BENCH="$PRESET" E2E_BENCH_STEPS="$STEPS" bash tests/e2e/run.sh bench >"$LOG" 2>&1 || {
    tail -n 20 "$LOG" >&2
    exit 1
  }
  page=$(grep -m1 "bench report after" "$LOG" | sed 's/^bench report after [0-9]* s: //' | steps_per_s)
  ratio=$(python3 -c "print('%.2f' % ($page / $native))")
  echo "run $run, $PRESET, $STEPS steps: native $native steps/s, page $page steps/s, page / native $ratio"
done
