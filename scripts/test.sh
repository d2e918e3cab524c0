#!/usr/bin/env bash
# Runs every check CI runs: formatting, clippy (native and wasm32), the native test suite (GPU
# tests on whatever Vulkan adapter there is: lavapipe on CPU-only machines) and the browser
# end-to-end tests in headless Chromium.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

# setup.sh installed a Vulkan device (lavapipe at least): GPU tests must run, never skip.
export SCRIBBLEFIELD_REQUIRE_GPU=1
# The Vulkan loader complains on every start without it.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"

step() { echo; echo "=== $* ($(date +%T))"; }

step "cargo fmt --check"
cargo fmt --check

step "clippy native"
cargo clippy --all-targets --release -- -D warnings
step "clippy wasm32"
cargo clippy --lib --release --target wasm32-unknown-unknown -- -D warnings

# Release: the GPU tests run kernels on lavapipe and the quality tests train fields; debug
# builds would make them many times slower.
step "native tests"
cargo test --release --all-targets

step "browser end-to-end tests"
bash tests/e2e/run.sh
