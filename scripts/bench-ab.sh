#!/usr/bin/env bash
# Compares the training step of two `scribblefield` binaries on this machine's GPU adapter:
# runs `bench --json` with each, alternately, RUNS times, and prints every run and the medians.
# Alternating is the point: on a shared machine the load moves the figures of one binary by more
# than most changes do (docs/results/bench.md), so back-to-back pairs are what compare.
#
#   scripts/bench-ab.sh OLD_BINARY NEW_BINARY [PRESET] [RUNS] [STEPS]
#
# PRESET defaults to small, RUNS to 4, STEPS to 6. Build an older commit's binary with
# `git worktree add /tmp/old COMMIT && cargo build --release --manifest-path /tmp/old/Cargo.toml`.
# Set VK_ICD_FILENAMES to pick a Vulkan driver (e.g. Chromium's SwiftShader).
set -euo pipefail
if [ $# -lt 2 ]; then
  sed -n '2,11p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
OLD=$1
NEW=$2
PRESET=${3:-small}
RUNS=${4:-4}
STEPS=${5:-6}
for binary in "$OLD" "$NEW"; do
  if [ ! -x "$binary" ]; then
    echo "error: $binary is not an executable scribblefield binary" >&2
    exit 1
  fi
done
OUT=$(mktemp)
trap 'rm -f "$OUT"' EXIT
for run in $(seq 1 "$RUNS"); do
  for side in old new; do
    if [ "$side" = old ]; then binary=$OLD; else binary=$NEW; fi
    "$binary" bench --preset "$PRESET" --steps "$STEPS" --warmup 1 --json 2>/dev/null |
      python3 -c '
import json, sys
d = json.load(sys.stdin)
print(sys.argv[1], sys.argv[2], d["steps_per_s"], d["bytes_per_step"], d["dispatches_per_step"], d["matmul_gflops"])
' "$side" "$run" | tee -a "$OUT"
  done
done
python3 - "$OUT" "$PRESET" <<'PY'
import statistics, sys
rows = [line.split() for line in open(sys.argv[1])]
median = {side: statistics.median(float(r[2]) for r in rows if r[0] == side) for side in ("old", "new")}
print(f"{sys.argv[2]}: median steps/s old {median['old']:.3f}, new {median['new']:.3f}, "
      f"new / old {median['new'] / median['old']:.2f}")
PY
