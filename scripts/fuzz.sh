#!/usr/bin/env bash
# Fuzzes every target (or those named) for SECONDS each, one after another, at the lowest CPU
# priority, with the memory and time limits of docs/fuzzing.md. New inputs go to a scratch
# corpus ($FUZZ_WORK/corpus/<target>), never into the repository's seed corpus; findings go to
# $FUZZ_WORK/artifacts/<target>/. Needs nightly and cargo-fuzz:
#   rustup toolchain install nightly --profile minimal && cargo install cargo-fuzz
# Usage: bash scripts/fuzz.sh [SECONDS] [TARGET...]
# FUZZ_RUNS=N also stops each target after N inputs (whichever of the two limits comes first).
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
seconds="${1:-600}"
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(archive archive_entries labels_json share_link npy safetensors transforms_json colmap_text seven_scenes_text pth pickle colmap_binary scannet_text checkpoint field_config pack_zip stray_text mp4)
fi
work="${FUZZ_WORK:-/tmp/scribblefield-fuzz}"
runs=()
if [ -n "${FUZZ_RUNS:-}" ]; then
    runs=(-runs="$FUZZ_RUNS")
fi
cargo +nightly fuzz build -O
bin=target/x86_64-unknown-linux-gnu/release
for t in "${targets[@]}"; do
    mkdir -p "$work/corpus/$t" "$work/artifacts/$t"
    echo "=== $t: ${seconds} s"
    # -rss_limit_mb: the hostile-input budget (peak memory under 1.5 GiB); -malloc_limit_mb
    # defaults to it, so one allocation over it is a finding too. -timeout: one input over 10 s
    # is a hang.
    nice -n 19 "$bin/$t" "$work/corpus/$t" "corpus/$t" \
        -rss_limit_mb=1536 -timeout=10 -max_total_time="$seconds" "${runs[@]}" -print_final_stats=1 \
        -artifact_prefix="$work/artifacts/$t/" 2>&1 | tee "$work/$t.log" | grep -E "^(#[0-9]+ +DONE|stat::number_of_executed_units|==[0-9]+==|SUMMARY)" || true
done
