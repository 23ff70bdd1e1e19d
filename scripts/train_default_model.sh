#!/usr/bin/env bash
# Train the CNN shipped for the default grid (33x33x65 nodes): the one documented sequence.
#
#   scripts/train_default_model.sh [WORKDIR]      (default WORKDIR: runs/default_model)
#
# 1. Algorithm 1 data (random pressure walks, FEM + level set): scripts/default_model/datagen.yaml
# 2. engine samples: FEM engine runs of random electrode scenes (random power 30-70 W, start,
#    direction, speed 0-20 mm/s), every 2nd mechanics step recorded; the built-in fixed- and
#    moving-electrode scenes are never generated (they are benchmarks/hybrid.py's held-out test)
# 3. merge, train (width 8, scenario-wise validation split), evaluate
# 4. copy the model and its validation metrics into the package
# About 40 min of one core on an idle machine; the shipped model was made on 2 shared cores.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
WORK="${1:-$ROOT/runs/default_model}"
MODELS="$ROOT/server/diathermy/surrogates/models"
mkdir -p "$WORK"
export PYTHONPATH="$ROOT/server${PYTHONPATH:+:$PYTHONPATH}"
export MALLOC_MMAP_MAX_=0 MALLOC_TRIM_THRESHOLD_=68719476736  # benchmarks/results/cnn.md
# one torch thread: on shared 2-core machines two threads ran the training 7x slower (measured)
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"

python -m diathermy datagen "$ROOT/scripts/default_model/datagen.yaml" --out "$WORK/alg1.h5" --resume --quiet
python -m diathermy.datagen.engine_samples --out "$WORK/engine.h5" --runs 3 --steps 80 --every 2 --seed 7
python -m diathermy.datagen.engine_samples --merge "$WORK/alg1.h5" "$WORK/engine.h5" --out "$WORK/train.h5"
python -m diathermy train "$WORK/train.h5" --out "$WORK/model.pt" --width 8 --depth 5 \
    --epochs 20 --patience 6 --lr 2e-3 --batch-size 4 --val-fraction 0.2 --seed 0 --device cpu --quiet
python -m diathermy evaluate "$WORK/model.pt" "$WORK/train.h5" --subset validation \
    --json "$WORK/metrics_validation.json"
python -m diathermy evaluate "$WORK/model.pt" "$WORK/train.h5" --json "$WORK/metrics_all.json"
python - "$WORK" "$MODELS/cnn_33x33x65" <<'PY'
import json, sys
from pathlib import Path
import torch
work, dest = Path(sys.argv[1]), sys.argv[2]
ckpt = torch.load(work / "model.pt", map_location="cpu", weights_only=True)
ckpt.pop("training_state", None)  # ship the weights only (no optimizer state): a smaller file
torch.save(ckpt, dest + ".pt")
val = json.loads((work / "metrics_validation.json").read_text())["summary"]
every = json.loads((work / "metrics_all.json").read_text())["summary"]
meta = {"validation": val, "all_samples": every, "training": ckpt.get("training_config", {}),
        "data": ckpt.get("data", {}), "trained_by": "scripts/train_default_model.sh"}
Path(dest + ".json").write_text(json.dumps(meta, indent=2) + "\n")
print(f"shipped {dest}.pt and {dest}.json")
PY
