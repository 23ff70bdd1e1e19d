#!/usr/bin/env bash
# Set-up: install diathermy with everything it needs, then run the main job (the default scene).
# On this project's machines torch comes from the local CPU build (constraints/local.txt pins it);
# elsewhere pip resolves torch from pyproject's range (CPU or CUDA, as the user's index serves).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
extra=()
if [ -d /opt/wheels ]; then extra+=(--find-links /opt/wheels); fi
"$PY" -m pip install --quiet "${extra[@]}" -c constraints/local.txt -e ".[dev,cluster]"
"$PY" -m diathermy simulate --out runs/default.h5 ${DIATHERMY_SETUP_ARGS:-}
