#!/usr/bin/env bash
# The training queue: robot A's Fig. 2, the temperature ablations (Push, then PickAndPlace) and the shipped agents, one run per stage and seed, in
# priority order, JOBS runs at a time (default 1; JOBS=2 uses both cores). Each run is resumable: rerunning this
# script continues each run after its last finished epoch, and finished runs return at once; a run whose CSV in
# docs/results/comparison/ already holds all its epochs is skipped (scripts/pending_runs.py; SKIP_COMMITTED=0 runs it).
# Commit epochs as they finish with bash scripts/sync_results.sh --every 600. --plan runs nothing: it prints each
# queued run's epochs done and left, and the hours the rest takes at JOBS runs at a time. ONLY=REGEX keeps the queued
# runs whose overrides match it (e.g. ONLY=pick_place_temperature runs that stage alone).
# Usage: [JOBS=2] [ONLY=REGEX] bash scripts/run_comparison.sh [--plan, first] [Hydra overrides]
set -uo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then sed -n '2,9p' "$0" | cut -c3-; exit 0; fi
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
queue() {
  # Robot A's Fig. 2 (docs/results.md): every run is committed, so the filter below skips them on any machine.
  seeds +comparison=pick_place_standard sampler=her replay.per_worker=false  # uniform HER draws alike either way
  SEED_ORDER="1 2 0" seeds +comparison=pick_place_standard sampler=cper replay.strategy=past
  seeds +comparison=push_standard sampler=cper replay.strategy=past
  SEED_ORDER="2 0 1" seeds +comparison=slide_standard sampler=her
  local sampler
  for sampler in cebp_initial ebp mep per; do seeds +comparison=push_standard sampler=$sampler; done
  seeds +comparison=pick_place_standard sampler=cebp_initial
  seeds +comparison=slide_standard sampler=cebp_initial
  seeds +comparison=push_standard sampler=cebp_initial sampler.beta=0 \
    'hydra.run.dir=runs/push-standard/cebp_initial/paper-per_worker-beta0/seed${seed}'
  # The temperature ablation: the paper's two values first.
  local temperature
  for temperature in 5 0.01; do seeds +comparison=push_temperature sampler.temperature=$temperature; done
  # The shipped agents: seed 0 of the task's best sampler, carried on past the comparison's horizon until it clears
  # its bar (PickAndPlace: the paper's 50 epochs, then up to 80).
  echo "+comparison=pick_place_standard sampler=cper replay.strategy=past seed=0 epochs=80${extra:+ $extra}"
  echo "+comparison=push_standard sampler=ebp seed=0 epochs=20${extra:+ $extra}"
  for temperature in 1 0.1 0.001; do seeds +comparison=push_temperature sampler.temperature=$temperature; done
  # The temperature ablation on PickAndPlace with HER beside it, one seed of every arm before the next seed.
  local seed
  for seed in ${SEED_ORDER:-0 1 2}; do
    echo "+comparison=pick_place_temperature sampler=her seed=$seed${extra:+ $extra}"
    for temperature in 0.01 5 1 0.1 0.001; do
      echo "+comparison=pick_place_temperature sampler.temperature=$temperature seed=$seed${extra:+ $extra}"
    done
  done
}
only() { grep -E -- "${ONLY:-.}" || true; }   # || true: a pattern that matches nothing queues nothing
filter=${FILTER_PYTHON:-.venv/bin/python}
if [ "$plan" = 1 ]; then queue | only | "$filter" scripts/pending_runs.py --plan --jobs "${JOBS:-1}"; exit; fi
queue | only | if [ "${SKIP_COMMITTED:-1}" = 1 ]; then "$filter" scripts/pending_runs.py; else cat; fi \
  | xargs -r -P "${JOBS:-1}" -L 1 bash -c 'run "$@"' run   # -r: an empty queue runs nothing, not a default train.py
