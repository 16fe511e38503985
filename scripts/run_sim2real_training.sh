#!/usr/bin/env bash
# The Franka pick-and-place training (docs/results/sim2real/diagnosis.md): CEBP at the paper's 8-worker scale,
# 800 env steps per cycle (Fetch's 0.05 updates per env step), 50 epochs, one core. EPISODE_STEPS=50 (default:
# Fetch PickAndPlace's, two episodes per worker per cycle) or 100 (the paper's Franka episodes, one per worker);
# GRASPED_START=0.5 (default: half the training episodes begin with the cube grasped, the HER paper's aid) or 0.
# Resumable: rerunning continues after the last finished epoch. The 8 workers share 1e6 transitions, as the shipped
# policy's run did (replay.capacity_per=total; it began before each worker could hold its own).
# Usage: [EPISODE_STEPS=50|100] [GRASPED_START=0.5] bash scripts/run_sim2real_training.sh [overrides]
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then sed -n '2,8p' "$0" | cut -c3-; exit 0; fi
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 MUJOCO_GL=osmesa
steps=${EPISODE_STEPS:-50}
case "$steps" in
  100) length=() ;;  # the task's own length: the config (and the run folder) name none
  50) length=(env.episode_steps=50) ;;
  *) echo "EPISODE_STEPS=$steps: must be 100 or 50" >&2; exit 2 ;;
esac
exec "${PYTHON:-.venv/bin/python}" train.py env=franka_pick_place sampler=cebp preset=paper \
  rollouts_per_cycle=$((100 / steps)) "${length[@]}" env.grasped_start="${GRASPED_START:-0.5}" \
  replay.capacity_per=total epochs=50 seed=0 resume=true "$@"
