#!/usr/bin/env bash
# Redraws the comparison's figures in docs/results/comparison/ (and the Franka training curve in
# docs/results/sim2real/) from the committed CSVs, prints the verdict tables of docs/results.md (IQM [95% CI] and
# P(> her), rliable's conventions) and writes robot A's, one per task, to docs/results/comparison/robot_a_fig2.md.
# Usage: bash scripts/redraw_results.sh [-h]
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then sed -n '2,5p' "$0" | cut -c3-; exit 0; fi
python=${PYTHON:-.venv/bin/python}
results=docs/results/comparison
plot() { "$python" -m torchrl_cebp.plot "$@" 2> >(grep -v AdroitHand >&2); }
present() { local dir=$1; shift; for panel in "$@"; do [ -d "$dir/$panel" ] && echo "$panel"; done; return 0; }
plot "$results" --out "$results/test_success.png" --table 5 10 12 15 --improvement-at 10 12 15
plot "$results/push-extended-joint-tableblind" --out "$results/push_released_robot.png" \
  --title "Push on robot B, the released code's: joint control, extended goals, table-blind pads"
# The paper's Fig. 2 on its own setup (robot A: mocap Fetch, standard goals), its three panels, with the paper's HER,
# C-Energy and CPER values (docs/results/paper_fig2.csv, ORIGINAL_CODE.md §6) as markers; a panel without runs yet
# shows the markers alone. Its tables, one per task with the epochs some run of the task reached, go to
# robot_a_fig2.md.
plot "$results" --panels pick_place-standard push-standard slide-standard-T70 --reference docs/results/paper_fig2.csv \
  --out "$results/robot_a_fig2.png" \
  --title "The paper's Fig. 2 setup (robot A: mocap Fetch, standard goals); markers: the paper's curves" \
  --table 5 10 12 15 20 --improvement-at 5 10 12 15 20 --tables-out "$results/robot_a_fig2.md"
plot "$results" --metric priority_ess_fraction --log-y --out "$results/priority_ess_fraction.png"
plot "$results" --metric is_weight_mean --log-y --out "$results/is_weight_mean.png"
# The Franka training (issue 29): cebp/paper is the first shipped run (before the env fixes of
# docs/results/sim2real/diagnosis.md), cebp/paper-per_worker the retrains, with 100- and 50-step episodes, and
# 50-step episodes with half the training episodes started grasped (-grasped50), the panels that have runs so far.
mapfile -t franka < <(present docs/results/sim2real/training \
  franka_pick_place-standard franka_pick_place-standard-T50 franka_pick_place-standard-T50-grasped50)
plot docs/results/sim2real/training --panels "${franka[@]}" \
  --out docs/results/sim2real/test_success.png --title "Franka pick-and-place in simulation, test success over 80 episodes"
