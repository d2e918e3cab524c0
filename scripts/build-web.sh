#!/usr/bin/env bash
# Builds the web app into www/: the wasm module and its JS glue in www/pkg/, and the demo scene
# archive www/demo.scene.zip. The result is a static folder that any web server can host.
# Installs what is missing (the wasm32 target, wasm-bindgen-cli at the crate's exact version).
set -euo pipefail
cd "$(dirname "$0")/.."

TARGET=wasm32-unknown-unknown
OUT=www/pkg

if ! rustup target list --installed 2>/dev/null | grep -qx "$TARGET"; then
  echo "==> rustup target add $TARGET"
  rustup target add "$TARGET"
fi

# The CLI must match the wasm-bindgen crate in Cargo.lock exactly, or the glue it writes does not
# fit the module.
WANT=$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/"/, "", $3); print $3; exit }' Cargo.lock)
if [ -z "$WANT" ]; then
  echo "error: no wasm-bindgen version in Cargo.lock" >&2
  exit 1
fi
HAVE=$(wasm-bindgen --version 2>/dev/null | awk '{ print $2 }' || true)
if [ "$HAVE" != "$WANT" ]; then
  echo "==> cargo install wasm-bindgen-cli --version $WANT (found: ${HAVE:-none})"
  cargo install wasm-bindgen-cli --version "$WANT"
fi

echo "==> cargo build --release --lib --target $TARGET"
CARGO_PROFILE_RELEASE_LTO=thin cargo build --release --lib --target "$TARGET"

echo "==> wasm-bindgen --target web --out-dir $OUT"
rm -rf "$OUT"
wasm-bindgen --target web --no-typescript --out-dir "$OUT" "target/$TARGET/release/scribblefield.wasm"

WASM="$OUT/scribblefield_bg.wasm"
# Debian 12's binaryen 108 mangles the externref table wasm-bindgen emits (the page then fails
# with "WebAssembly.Table.set(): Argument 1 is invalid"). Releases from 116 on are used; that
# bound is an assumption, only 108 has been tried. -Oz took the module from 8.3 MiB to 6.6 MiB
# (gzip: 2.9 to 2.6 MiB).
OPT_VERSION=$(wasm-opt --version 2>/dev/null | awk '{ print $3 }' || true)
if [ -n "$OPT_VERSION" ] && [ "$OPT_VERSION" -ge 116 ] 2>/dev/null; then
  echo "==> wasm-opt -Oz (binaryen $OPT_VERSION; takes a minute or two)"
  # Allow the features rustc enables by default for wasm32, or wasm-opt rejects the module.
  if wasm-opt -Oz --enable-bulk-memory --enable-nontrapping-float-to-int --enable-sign-ext \
    --enable-mutable-globals --enable-reference-types --enable-multivalue \
    "$WASM" -o "$WASM.opt"; then
    mv "$WASM.opt" "$WASM"
  else
    rm -f "$WASM.opt"
    echo "warning: wasm-opt failed; keeping the unoptimised build" >&2
  fi
elif [ -n "$OPT_VERSION" ]; then
  echo "(wasm-opt $OPT_VERSION is older than 116 and breaks this module: skipping size optimisation)"
else
  echo "(wasm-opt not found: skipping size optimisation; binaryen 116+ makes the download smaller)"
fi

echo "==> demo scene"
# With weight-free baseline feature codes on a 40 x 30 grid (stride 4 of 160 x 120), so the demo
# trains with feature supervision as the paper does: +3.1 MB (1.3 to 4.4 MB), and mean IoU 0.58 ->
# 0.96 on it with scribbles on frames 0 and 12 (`segment --preset budget`).
cargo run --release --quiet -- demo-scene -o www/demo.scene.zip --features baseline --feature-stride 4

RAW=$(wc -c < "$WASM")
GZ=$(gzip -9 -c "$WASM" | wc -c)
echo "built www/: $WASM is $((RAW / 1024)) KiB ($((GZ / 1024)) KiB gzipped)"
