#!/usr/bin/env bash
# Issue 29's Franka pick-and-place training (docs/results/sim2real/diagnosis.md): the paper's 8 workers with
# one episode each per cycle, so that updates per env step match Fetch's (0.05), CEBP, 50 epochs, one core.
# Resumable: rerunning continues after the last finished epoch. Usage: bash scripts/run_sim2real_training.sh [overrides]
set -uo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then sed -n '2,4p' "$0" | cut -c3-; exit 0; fi
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 MUJOCO_GL=osmesa
exec "${PYTHON:-.venv/bin/python}" train.py env=franka_pick_place sampler=cebp preset=paper rollouts_per_cycle=1 \
  epochs=50 seed=0 resume=true "$@"
