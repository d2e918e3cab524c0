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
cargo build --release --lib --target "$TARGET"

echo "==> wasm-bindgen --target web --out-dir $OUT"
rm -rf "$OUT"
wasm-bindgen --target web --no-typescript --out-dir "$OUT" "target/$TARGET/release/scribblefield.wasm"

WASM="$OUT/scribblefield_bg.wasm"
if command -v wasm-opt >/dev/null 2>&1; then
  echo "==> wasm-opt -Oz (takes a minute or two)"
  # Allow the features rustc enables by default for wasm32, or wasm-opt rejects the module.
  if wasm-opt -Oz --enable-bulk-memory --enable-nontrapping-float-to-int --enable-sign-ext \
    --enable-mutable-globals --enable-reference-types --enable-multivalue \
    "$WASM" -o "$WASM.opt"; then
    mv "$WASM.opt" "$WASM"
  else
    rm -f "$WASM.opt"
    echo "warning: wasm-opt failed (too old for this module?); keeping the unoptimised build" >&2
  fi
else
  echo "(wasm-opt not found: skipping size optimisation; binaryen's wasm-opt makes the download smaller)"
fi

echo "==> demo scene"
cargo run --release --quiet -- demo-scene -o www/demo.scene.zip

RAW=$(wc -c < "$WASM")
GZ=$(gzip -9 -c "$WASM" | wc -c)
echo "built www/: $WASM is $((RAW / 1024)) KiB ($((GZ / 1024)) KiB gzipped)"
