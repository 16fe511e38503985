#!/usr/bin/env bash
# The open comparison on per-worker replay (issues 27 and 28), in priority order, JOBS runs at a time (default 1;
# the Sim2Real policy has shipped, so JOBS=2 uses both cores). Every stage is resumable: rerunning this script
# continues each run after its last finished epoch, and finished runs return at once. Commit epochs as they finish
# with bash scripts/sync_results.sh --every 600. Usage: [JOBS=2] bash scripts/run_comparison.sh [Hydra overrides]
set -uo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then sed -n '2,5p' "$0" | cut -c3-; exit 0; fi
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 MUJOCO_GL=osmesa
python=${PYTHON:-.venv/bin/python}
stage() { echo "[comparison] $(date -u +%FT%TZ) $*"; "$python" train.py -m "hydra.launcher.n_jobs=${JOBS:-1}" "$@" || echo "[comparison] stage failed: $*" >&2; }
# Seed 0's 12 epochs are complete in docs/results/comparison/ (its checkpoint went with an earlier machine).
stage +comparison=push_standard seed=1,2 sampler=cebp_initial "$@"            # 27.1 A: the figure's CEBP, per worker
stage +comparison=push_released seed=0,1,2 sampler=cebp_released "$@"         # 27.2 B: the released CEBP, per worker
stage +comparison=pick_place_standard seed=0,1,2 sampler=cebp_initial "$@"    # 28.1 A PickAndPlace, per worker
# CPER with its published draw (HindsightRelabel strategy "past"; docs/results.md); run folders end in -her_past.
stage +comparison=pick_place_standard seed=0,1,2 sampler=cper replay.strategy=past "$@"
# 28.1 A PickAndPlace HER: started on the merged buffer before per-worker replay landed (uniform HER draws the
# same distribution either way, tests/replay/test_per_worker.py), so it continues merged, in its own folders.
stage +comparison=pick_place_standard seed=0,1,2 sampler=her replay.per_worker=false "$@"
stage +comparison=push_standard seed=0,1,2 sampler=cper replay.strategy=past "$@"  # 28.2 A Push: CPER
stage +comparison=slide_standard seed=0,1,2 sampler=her,cebp_initial "$@"     # 28.3 A Slide, 70-step episodes
stage +comparison=push_standard seed=0,1,2 sampler=per,ebp,mep "$@"           # 28.4 A Push: the other baselines
