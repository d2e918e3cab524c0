#!/usr/bin/env bash
# Builds the web app (scripts/build-web.sh) and serves www/ on localhost with the demo scene.
# PORT=9000 scripts/serve.sh picks another port.
set -euo pipefail
cd "$(dirname "$0")/.."

PORT=${PORT:-8080}
scripts/build-web.sh
echo
echo "==> open http://127.0.0.1:$PORT/ in a browser with WebGPU (Ctrl+C stops the server)"
echo
exec cargo run --release --quiet -- serve www --port "$PORT"
