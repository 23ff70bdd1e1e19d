#!/usr/bin/env bash
# Set-up: install diathermy with everything it needs, then run the main job (the default scene).
# On this project's machines torch comes from the local CPU build (constraints/local.txt pins it);
# elsewhere pip resolves torch from pyproject's range (CPU or CUDA, as the user's index serves).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
# The browser viewer (/viewer): its bundle is built from viewer/package-lock.json into the
# package's static files before pip installs them; tests/viewer drives it in Debian's chromium.
(cd viewer && npm ci --no-audit --no-fund --loglevel=error && npm run build --silent)
if ! command -v chromium >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
    else
        echo "setup: chromium is missing (tests/viewer needs it): apt-get install chromium" >&2
    fi
fi
extra=()
if [ -d /opt/wheels ]; then extra+=(--find-links /opt/wheels); fi
"$PY" -m pip install --quiet "${extra[@]}" -c constraints/local.txt -e ".[dev,cluster]"
"$PY" -m diathermy simulate --out runs/default.h5 ${DIATHERMY_SETUP_ARGS:-}
