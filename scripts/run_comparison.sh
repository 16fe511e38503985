#!/usr/bin/env bash
# The open comparison on per-worker replay (issue 28: the rest of robot A's Fig. 2), one run per stage and seed, in
# priority order, JOBS runs at a time (default 1; JOBS=2 uses both cores). Each run is resumable: rerunning this
# script continues each run after its last finished epoch, and finished runs return at once; a run whose CSV in
# docs/results/comparison/ already holds all its epochs is skipped (scripts/pending_runs.py; SKIP_COMMITTED=0 runs it).
# Commit epochs as they finish with bash scripts/sync_results.sh --every 600. --plan runs nothing: it prints each
# queued run's epochs done and left, and the hours the rest takes at JOBS runs at a time.
# Usage: [JOBS=2] bash scripts/run_comparison.sh [--plan, first] [Hydra overrides]
set -uo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then sed -n '2,8p' "$0" | cut -c3-; exit 0; fi
plan=0
if [ "${1:-}" = "--plan" ]; then plan=1; shift; fi
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 MUJOCO_GL=osmesa
export python=${PYTHON:-.venv/bin/python}
run() { echo "[comparison] $(date -u +%FT%TZ) $*"; "$python" train.py "$@" || echo "[comparison] run failed: $*" >&2; }
export -f run
extra="$*"
# One line per run. Runs of a stage's seeds are queued, not swept, so a free slot takes the next stage's first run
# instead of waiting for the stage's slowest seed.
seeds() { local seed; for seed in ${SEED_ORDER:-0 1 2}; do echo "$* seed=$seed${extra:+ $extra}"; done; }
# Issue 27's reruns are complete in docs/results/comparison/ (docs/results.md, twelfth sitting); their commands:
#   train.py -m +comparison=push_standard seed=0,1,2 sampler=cebp_initial     (robot A, per worker)
#   train.py -m +comparison=push_released seed=0,1,2 sampler=cebp_released    (robot B, per worker)
queue() {
  # 28.1 A PickAndPlace HER on the merged buffer, as robot A's Push HER rows: uniform HER draws the same
  # distribution either way (tests/replay/test_per_worker.py).
  seeds +comparison=pick_place_standard sampler=her replay.per_worker=false
  # CPER with its published draw (HindsightRelabel strategy "past"; docs/results.md); run folders end in -her_past.
  SEED_ORDER="1 2 0" seeds +comparison=pick_place_standard sampler=cper replay.strategy=past
  seeds +comparison=push_standard sampler=cper replay.strategy=past          # 28.2 A Push: CPER
  SEED_ORDER="2 0 1" seeds +comparison=slide_standard sampler=her            # 28.3 A Slide, 70-step episodes
  # The figure's CEBP again with baselines' weighted critic loss, mean(w * delta^2) (2026-12-06): its runs before
  # are in -wnorm folders. Push first, the panel where the paper's C-Energy leads HER most.
  seeds +comparison=push_standard sampler=cebp_initial
  # 28.4 A Push: the other baselines. EBP and MEP take no IS weights, so the loss fix of 2026-12-06 leaves them as
  # they were; PER's first runs fed no TD errors back to the per-worker shards, and were discarded.
  seeds +comparison=push_standard sampler=ebp
  seeds +comparison=push_standard sampler=mep
  seeds +comparison=push_standard sampler=per
  seeds +comparison=pick_place_standard sampler=cebp_initial
  seeds +comparison=slide_standard sampler=cebp_initial
  # Beyond the matrix (2026-12-06): the figure's CEBP on Push with its IS weights off (beta 0). EBP, which weights
  # nothing, leads HER by 2.4x where cebp_initial is level with it: is it the priorities or the weights?
  seeds +comparison=push_standard sampler=cebp_initial sampler.beta=0 \
    'hydra.run.dir=runs/push-standard/cebp_initial/paper-per_worker-beta0/seed${seed}'
}
filter=${FILTER_PYTHON:-.venv/bin/python}
if [ "$plan" = 1 ]; then queue | "$filter" scripts/pending_runs.py --plan --jobs "${JOBS:-1}"; exit; fi
queue | if [ "${SKIP_COMMITTED:-1}" = 1 ]; then "$filter" scripts/pending_runs.py; else cat; fi \
  | xargs -r -P "${JOBS:-1}" -L 1 bash -c 'run "$@"' run   # -r: an empty queue runs nothing, not a default train.py
