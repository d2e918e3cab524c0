#!/usr/bin/env bash
# Installs what building and testing need, idempotently: Debian packages, the wasm target and the
# wasm-bindgen CLI pinned to the version in Cargo.lock. Safe to run again; it skips what is there.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
[ -e /usr/share/vulkan/icd.d/lvp_icd.x86_64.json ] || ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1 || need_apt+=(mesa-vulkan-drivers)
command -v node >/dev/null 2>&1 || need_apt+=(nodejs npm)
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "setup: installing ${need_apt[*]}"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO=sudo
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi
# Stray Scanner captures record their colour as a video: packing one decodes it with ffmpeg, and
# the tests encode the YCB clip into one. Without its recommends: they pull in video drivers whose
# newer mesa can replace the installed lavapipe, and a new lavapipe starts with a cold shader
# cache (the GPU tests then spend minutes compiling).
if ! command -v ffmpeg >/dev/null 2>&1; then
  echo "setup: installing ffmpeg"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO=sudo
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends ffmpeg >/dev/null
fi

rustup target list --installed | grep -q '^wasm32-unknown-unknown$' || rustup target add wasm32-unknown-unknown

# The CLI must match the wasm-bindgen crate exactly, or the generated glue does not fit.
[ -f Cargo.lock ] || cargo generate-lockfile
want=$(grep -A1 '^name = "wasm-bindgen"$' Cargo.lock | sed -n 's/^version = "\(.*\)"/\1/p')
have=$(wasm-bindgen --version 2>/dev/null | awk '{print $2}' || true)
if [ "$have" != "$want" ]; then
  echo "setup: installing wasm-bindgen-cli $want (about 5 minutes on 2 cores)"
  # Not --locked: one of its locked dependencies is missing from some registries.
  cargo install wasm-bindgen-cli --version "$want"
fi
