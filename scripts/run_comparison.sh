#!/usr/bin/env bash
# The open comparison on per-worker replay (issue 28: the rest of robot A's Fig. 2), in priority order, JOBS runs at
# a time (default 1; JOBS=2 uses both cores). Every stage is resumable: rerunning this script continues each run
# after its last finished epoch, and finished runs return at once. Commit epochs as they finish with
# bash scripts/sync_results.sh --every 600. Usage: [JOBS=2] bash scripts/run_comparison.sh [Hydra overrides]
set -uo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then sed -n '2,5p' "$0" | cut -c3-; exit 0; fi
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 MUJOCO_GL=osmesa
python=${PYTHON:-.venv/bin/python}
stage() { echo "[comparison] $(date -u +%FT%TZ) $*"; "$python" train.py -m "hydra.launcher.n_jobs=${JOBS:-1}" "$@" || echo "[comparison] stage failed: $*" >&2; }
# Issue 27's reruns are complete in docs/results/comparison/ (docs/results.md, twelfth sitting); their commands:
#   train.py -m +comparison=push_standard seed=0,1,2 sampler=cebp_initial     (robot A, per worker)
#   train.py -m +comparison=push_released seed=0,1,2 sampler=cebp_released    (robot B, per worker)
stage +comparison=pick_place_standard seed=0,1,2 sampler=cebp_initial "$@"    # 28.1 A PickAndPlace, per worker
# 28.1 A PickAndPlace HER on the merged buffer, as robot A's Push HER rows: uniform HER draws the same
# distribution either way (tests/replay/test_per_worker.py).
stage +comparison=pick_place_standard seed=0,1,2 sampler=her replay.per_worker=false "$@"
# CPER with its published draw (HindsightRelabel strategy "past"; docs/results.md); run folders end in -her_past.
stage +comparison=pick_place_standard seed=0,1,2 sampler=cper replay.strategy=past "$@"
stage +comparison=push_standard seed=0,1,2 sampler=cper replay.strategy=past "$@"  # 28.2 A Push: CPER
stage +comparison=slide_standard seed=0,1,2 sampler=her,cebp_initial "$@"     # 28.3 A Slide, 70-step episodes
stage +comparison=push_standard seed=0,1,2 sampler=per,ebp,mep "$@"           # 28.4 A Push: the other baselines
