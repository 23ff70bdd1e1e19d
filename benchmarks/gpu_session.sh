#!/usr/bin/env bash
# Issue #22's GPU measurements in one go, on a machine with CUDA and at least 8 cores:
#
#   bash benchmarks/gpu_session.sh OUTDIR [TRAIN_RUNS]
#
# 1. benchmarks/gpu.py (the networks' inference and whole steps, the CPU beside the GPU) runs on
#    cores 0-3 while benchmarks/incremental_network.py generates its training data (FEM runs, one
#    process each) on the other cores and the GPU stays the timing's alone;
# 2. then benchmarks/incremental_network.py trains the direct and incremental networks, the
#    paper's pooled layout and a U-Net, on the GPU and scores them on the held-out runs.
# Each part has a time limit (DATA_TIMEOUT, GPU_TIMEOUT, INC_TIMEOUT seconds) so that a slow part
# cannot take the other's time; logs and reports go to OUTDIR. STEPS, EPOCHS, GRIDS and
# STEP_GRIDS change the runs' size (a dry run: STEPS=5 EPOCHS=1 GRIDS="default 17x17x33").
# A whole step at 64x64x128 does not fit the default limits (2026-12-04 on an H200 machine: its
# warm-up alone took 80 s, and four engines stepping in lockstep, the full solve among them, did
# not finish in 160-220 s more): give it a run of its own, e.g. `python3 benchmarks/gpu.py
# --grids 64x64x128 --modes incremental hybrid auto --steps 3` (without the full solve: no errors).
set -uo pipefail
out=${1:?usage: bash benchmarks/gpu_session.sh OUTDIR [TRAIN_RUNS]}
runs=${2:-22}
cd "$(dirname "$0")/.."
mkdir -p "$out"
n=$(nproc)
if [ "$n" -lt 8 ]; then
    echo "gpu_session: needs at least 8 cores (has $n)" >&2
    exit 2
fi
pin() {  # pin() CPUS CMD...: run CMD on those CPUs (unpinned where taskset cannot)
    local cpus=$1
    shift
    if taskset -c "$cpus" true 2>/dev/null; then taskset -c "$cpus" "$@"; else "$@"; fi
}
work=${WORK:-runs/gpu_session}
inc=(--train-runs "$runs" --steps "${STEPS:-60}" --epochs "${EPOCHS:-20}" --width 12 --batch 8
     --archs pooled unet --jobs $((n - 4)) --work "$work")
pin "4-$((n - 1))" timeout "${DATA_TIMEOUT:-300}" \
    python3 benchmarks/incremental_network.py "${inc[@]}" --data-only \
    >"$out/incremental_data.log" 2>&1 &
data=$!
pin 0-3 timeout "${GPU_TIMEOUT:-300}" \
    python3 benchmarks/gpu.py --grids ${GRIDS:-default 33x33x65 64x64x128} \
    --step-grids ${STEP_GRIDS:-default 33x33x65} --steps 4 --warmup-s 60 --out "$out/gpu.md" \
    >"$out/gpu.log" 2>&1
echo "gpu.py exit $?" >>"$out/gpu.log"
wait "$data"
echo "data exit $?" >>"$out/incremental_data.log"
timeout "${INC_TIMEOUT:-240}" python3 benchmarks/incremental_network.py "${inc[@]}" \
    --out "$out/incremental_network.md" >"$out/incremental_network.log" 2>&1
echo "incremental_network.py exit $?" >>"$out/incremental_network.log"
