#!/usr/bin/env bash
# Everything worth measuring on a machine with a real GPU, in one short run, for machines that
# have a GPU but no Rust toolchain (docs/results/bench.md, "A real GPU", was taken this way):
#
#   scripts/gpu-check.sh prepare KIT      # here: build, pack the captures, draw strokes, into KIT/
#   scripts/gpu-check.sh run KIT OUT [S]  # there: bench, GPU tests, segment + eval, into OUT/
#
# `prepare` needs ../shared/data (YCB, COLMAP) and writes about 25 MB: the stripped release
# binary and GPU test binaries (xz-compressed together), the YCB and demo archives, the COLMAP
# capture itself (its archive is 45 MB, so `run` packs it there), and three scribble sets per
# capture. `run` writes at most 6 files into OUT: env.log, bench.jsonl (one `bench --json` per
# preset), bench.log, tests.log (every tests/gpu_*.rs binary, SCRIBBLEFIELD_REQUIRE_GPU=1),
# quality.jsonl (one line per segment + eval run: tag, seconds, `eval --json`) and
# quality.log. It starts no segment run after S seconds (default 330) and stops waiting at
# S + 95, so a caller's time limit of S + 130 leaves room to copy OUT back.
set -uo pipefail
usage() { sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'; exit 2; }
[ $# -ge 2 ] || usage
MODE=$1
KIT=$(mkdir -p "$2" && cd "$2" && pwd)
ROOT=$(cd "$(dirname "$0")/.." && pwd)

prepare() {
  set -e
  cd "$ROOT"
  cargo build --release
  local tests
  tests=$(cargo test --release --no-run --message-format=json 2>/dev/null |
    python3 -c 'import json,sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"].startswith("gpu_"):
        print(m["target"]["name"], m["executable"])')
  local bins
  bins=$(mktemp -d)
  cp target/release/scribblefield "$bins/"
  while read -r name path; do cp "$path" "$bins/$name"; done <<< "$tests"
  strip "$bins"/* 2>/dev/null || true
  # One solid archive: the binaries share most of their code, which a large window finds.
  tar -C "$bins" -cf - . | xz -T2 -9 --lzma2=dict=192MiB > "$KIT/binaries.tar.xz"
  rm -rf "$bins"
  local b=target/release/scribblefield data=../shared/data
  $b pack "$data/ycb-video-0000" -o "$KIT/ycb.scene.zip" --max-size 160 --features baseline --feature-stride 2
  $b demo-scene -o "$KIT/demo.scene.zip" --size 80x60 --features baseline --feature-stride 2
  rm -rf "$KIT/alexander-colmap" && cp -a "$data/alexander-colmap" "$KIT/"
  # The strokes are drawn from the ground truth; `run` packs the COLMAP capture the same way.
  $b pack "$KIT/alexander-colmap" -o /tmp/gpu-check-alex.scene.zip --max-size 200 --features baseline --feature-stride 2
  for seed in 0 1 2; do
    $b scribble-from-gt "$KIT/ycb.scene.zip" --frames 0 --seed $seed -o "$KIT/ycb-l$seed.json"
    $b scribble-from-gt /tmp/gpu-check-alex.scene.zip --frames 0,26 --seed $seed -o "$KIT/alex-l$seed.json"
    $b scribble-from-gt "$KIT/demo.scene.zip" --frames 0,12 --seed $seed -o "$KIT/demo-l$seed.json"
  done
  rm -f /tmp/gpu-check-alex.scene.zip
  echo '{"feature_supervision": true}' > "$KIT/sup.json"
  du -sh "$KIT"
}

run() {
  local out=$1 limit=${2:-330}
  mkdir -p "$out"
  local t0 work
  t0=$(date +%s)
  elapsed() { echo $(($(date +%s) - t0)); }
  work=$(mktemp -d)
  export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp} SCRIBBLEFIELD_REQUIRE_GPU=1
  (cd "$work" && xz -dc "$KIT/binaries.tar.xz" | tar xf -) || { echo "cannot unpack $KIT/binaries.tar.xz" >&2; exit 1; }
  local b=$work/scribblefield
  { nvidia-smi -L 2>/dev/null; ls "$work"; } > "$out/env.log" 2>&1
  # Is there an adapter at all? The Vulkan loader says why not.
  if ! timeout 60 "$b" bench --preset tiny --steps 1 --warmup 1 >> "$out/env.log" 2>&1; then
    VK_LOADER_DEBUG=error,warn timeout 60 "$b" bench --preset tiny --steps 1 --warmup 1 >> "$out/env.log" 2>&1
    echo "no usable GPU adapter: see $out/env.log" >&2
    exit 3
  fi
  # Bench alone on the GPU first.
  for spec in tiny:60:10 budget:60:10 small:40:10 full:20:5; do
    IFS=: read -r preset steps warmup <<< "$spec"
    timeout 90 "$b" bench --preset "$preset" --json --steps "$steps" --warmup "$warmup" >> "$out/bench.jsonl" 2>> "$out/bench.log"
    echo "$preset: rc $? at $(elapsed) s" >> "$out/bench.log"
  done
  timeout 60 "$b" bench --preset full --rays 16384 --json --steps 10 --warmup 3 >> "$out/bench.jsonl" 2>> "$out/bench.log"
  echo "full, 16384 rays: rc $? at $(elapsed) s" >> "$out/bench.log"
  # The hash backward's three atomic adds (float, fixed point, compare-exchange) timed alone.
  timeout 60 "$work/gpu_field_encoding" encoding_throughput_report --ignored --nocapture 2>&1 |
    grep -E 'adapter|ms' >> "$out/bench.log"
  # The kernel tests beside the quality runs (they are short and mostly wait on the CPU).
  (
    for test in "$work"/gpu_*; do
      echo "=== $(basename "$test") at $(elapsed) s"
      timeout 150 "$test" --test-threads 6 2>&1 | grep -v '^test .* ok$' | tail -40
      echo "rc ${PIPESTATUS[0]}"
    done > "$out/tests.log" 2>&1
  ) &
  timeout 60 "$b" pack "$KIT/alexander-colmap" -o "$work/alex.scene.zip" --max-size 200 --features baseline --feature-stride 2 >> "$out/env.log" 2>&1
  cp "$KIT/ycb.scene.zip" "$KIT/demo.scene.zip" "$work/"
  one() {
    local scene=$1 strokes=$2 preset=$3 steps=$4 config=$5
    shift 5
    local tag="$scene-$strokes-$preset-$steps-$(basename "$config" .json)" start
    start=$(elapsed)
    "$b" segment "$work/$scene.scene.zip" --labels "$KIT/$scene-$strokes.json" -o "$work/m-$tag" \
      --preset "$preset" --config "$config" --warmup 100 --steps "$steps" > "$work/$tag.log" 2>&1
    local rc=$? scores
    scores=$("$b" eval "$work/$scene.scene.zip" "$work/m-$tag" "$@" --json 2>&1 | tr -d '\n')
    echo "{\"tag\":\"$tag\",\"rc\":$rc,\"start_s\":$start,\"end_s\":$(elapsed),\"eval\":$scores}" >> "$out/quality.jsonl"
    { echo "== $tag: rc $rc, $start..$(elapsed) s"; tail -4 "$work/$tag.log"; } >> "$out/quality.log"
  }
  local ycb="--frames 1,2,3,4,5,6,7,8,9" sup=$KIT/sup.json
  # The demo's full-model loss (docs/quality.md, "The full model on a real GPU") first: more
  # steps, and the budget's learning rate once labels arrive.
  echo '{"feature_supervision": true, "adam": {"lr_annotating": 5e-3}}' > "$work/sup-lr5e-3.json"
  local jobs=(
    "demo l0 full 2000 $sup"
    "demo l0 full 800 $work/sup-lr5e-3.json"
    "demo l1 full 800 $sup"
    "ycb l0 full 500 $sup $ycb"
    "ycb l1 full 500 $work/sup-lr5e-3.json $ycb"
    "alex l0 full 800 $sup"
    "demo l2 full 800 $sup"
    "ycb l0 budget 500 $sup $ycb"
    "alex l0 budget 800 $sup"
    "demo l0 budget 800 $sup"
  )
  local job
  for job in "${jobs[@]}"; do
    while [ "$(jobs -rp | wc -l)" -ge 4 ]; do sleep 1; done
    if [ "$(elapsed)" -gt "$limit" ]; then
      echo "not started (past $limit s): $job" >> "$out/quality.log"
      continue
    fi
    # shellcheck disable=SC2086 # a job is words
    one $job &
  done
  while [ "$(jobs -rp | wc -l)" -gt 0 ] && [ "$(elapsed)" -lt $((limit + 95)) ]; do sleep 2; done
  echo "end at $(elapsed) s" >> "$out/env.log"
}

case $MODE in
  prepare) prepare ;;
  run) [ $# -ge 3 ] || usage; run "$3" "${4:-330}" ;;
  *) usage ;;
esac
