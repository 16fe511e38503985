#!/usr/bin/env bash
# Issue 17's Push matrix, in its order (most informative first), two runs at a time, one thread each.
# Every stage is resumable: rerunning this script continues each run after its last finished epoch,
# and finished runs return at once. Usage: bash scripts/run_comparison.sh [extra Hydra overrides]
set -uo pipefail
cd "$(dirname "$0")/.."
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
python=${PYTHON:-.venv/bin/python}
stage() { echo "[comparison] $(date -u +%FT%TZ) $*"; "$python" train.py -m "$@" || echo "[comparison] stage failed: $*" >&2; }
stage +comparison=push_released seed=0,1,2 sampler=her,cebp_released "$@"   # 1. B: her, released CEBP
stage +comparison=push_standard seed=0,1,2 sampler=cebp_initial "$@"        # 2. A: the Initial commit's CEBP
stage +comparison=push_standard seed=1,2 sampler=her,cebp "$@"              # 3. A: seeds 1-2 (seed 0: docs/results/learning)
stage +comparison=push_released seed=0,1,2 sampler=cebp,cper "$@"           # 4. B: the paper's CEBP, CPER
