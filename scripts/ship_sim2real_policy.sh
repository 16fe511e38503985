#!/usr/bin/env bash
# Ships a trained Franka pick-and-place policy. Scores POLICY (a policy file, run directory or checkpoint)
# on 100 fresh plain-simulation episodes of the loop's length (100 steps, whatever length it trained on) and, if it
# reaches 0.8, writes its actor and normaliser as the shipped policy (torchrl_cebp/sim2real/policies/); then runs the
# 50-episode camera loop with two cameras and with one, each beside plain simulation on the same placements (logs in
# docs/results/sim2real/), and redraws the episode MP4 (docs/img/sim2real_episode.mp4). --force ships below 0.8.
# Usage: bash scripts/ship_sim2real_policy.sh POLICY [--force]   (POLICY: e.g. runs/.../seed0/best_policy.pt)
set -euo pipefail
cd "$(dirname "$0")/.."
usage() { sed -n '2,7p' "$0" | cut -c3-; }
case "${1:-}" in
  -h|--help) usage; exit 0 ;;
  "") usage >&2; exit 2 ;;
esac
case "${2:-}" in
  ""|--force) ;;
  *) echo "unknown option ${2}: the only option is --force" >&2; exit 2 ;;
esac
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} MKL_NUM_THREADS=${MKL_NUM_THREADS:-1} MUJOCO_GL=osmesa
python=${PYTHON:-.venv/bin/python}
out=docs/results/sim2real

# Fresh episodes: the trainer's test seeds picked the epoch, so they would flatter it.
"$python" - "$1" "${2:-}" <<'PYTHON'
import sys
from torchrl_cebp.envs import make_env_from_config
from torchrl_cebp.sim2real import SHIPPED_POLICY
from torchrl_cebp.training.checkpoint import policy_from_state, read_policy_state, save_policy
from torchrl_cebp.training.evaluation import evaluate_success_rate

BAR, EPISODES = 0.8, 100
source, force = sys.argv[1], sys.argv[2] == "--force"
state = read_policy_state(source)
if state["env"].get("task") != "franka_pick_place":
    sys.exit(f"[ship] {source} was trained on {state['env'].get('task')!r}, not the Franka task")
env = make_env_from_config({**state["env"], "episode_steps": None}, seed=20261203, num_envs=EPISODES)
score = evaluate_success_rate(env, policy_from_state(state), EPISODES)
print(f"[ship] {source}: plain simulation, {EPISODES} fresh 100-step episodes: {score:.3f} (bar {BAR})")
if score < BAR and not force:
    sys.exit(f"[ship] below {BAR}: not shipped (pass --force to ship it anyway)")
save_policy({**state, "plain_simulation_success": score}, SHIPPED_POLICY)
print(f"[ship] written to {SHIPPED_POLICY}")
PYTHON

loop() {  # $1: log name; the rest: options of `run`
  local log=$out/$1; shift
  echo "[ship] camera loop, 50 episodes, ${*:-one camera}: $log"
  "$python" -m torchrl_cebp.sim2real run backend=sim episodes=50 compare_sim=true "$@" | tee "$log" | tail -4
}
loop camera_loop_50_episodes_side_camera.txt side_camera=true
loop camera_loop_50_episodes_one_camera.txt
"$python" -m torchrl_cebp.sim2real debug policy=checkpoint out="${TMPDIR:-/tmp}/sim2real_debug_frames" steps=100 \
  side_camera=true video=docs/img/sim2real_episode.mp4 | tail -1
echo "[ship] done. Commit the policy, $out/camera_loop_50_episodes_*.txt and docs/img/sim2real_episode.mp4."
echo "[ship] At 0.8 the strict xfail of tests/sim2real/test_shipped_policy.py fails: remove it; update the README's Sim2Real figures."
