#!/usr/bin/env bash
# Redraws every figure of docs/results.md from the committed CSVs (docs/results/comparison/, and the Franka training
# in docs/results/sim2real/), prints each question's table (IQM [95% CI] and P(> HER), rliable's conventions), and
# writes robot A's tables, one per task, to docs/results/comparison/robot_a_fig2.md.
# Usage: bash scripts/redraw_results.sh [-h]
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then sed -n '2,5p' "$0" | cut -c3-; exit 0; fi
python=${PYTHON:-.venv/bin/python}
results=docs/results/comparison
paper=docs/results/paper_fig2.csv
robot_a=(pick_place-standard push-standard slide-standard-T70)
plot() { "$python" -m torchrl_cebp.plot "$@" 2> >(grep -v AdroitHand >&2); }
question() { printf '\n## %s\n' "$1"; }
# The run folders of the methods as the figure's setup runs them (robot A, per-worker replay, baselines' loss).
current=('her/paper' 'her/paper-per_worker' 'cebp_initial/paper-per_worker' 'cper/paper-per_worker-her_past'
  'per/paper-per_worker' 'ebp/paper-per_worker' 'mep/paper-per_worker')

# The paper's Fig. 2 on its own setup: current runs only, the paper's values as markers.
question "Robot A, the paper's Fig. 2 setup, every current method"
plot "$results" --panels "${robot_a[@]}" --configurations "${current[@]}" --reference "$paper" \
  --out "$results/robot_a_fig2.png" \
  --title "The paper's Fig. 2 setup (robot A: mocap Fetch, standard goals, 8 workers), 3 seeds" \
  --table 5 10 12 15 20 --improvement-at 10 12 15 20 --tables-out "$results/robot_a_fig2.md"
question "Does our HER match the paper's, task by task?"
plot "$results" --panels "${robot_a[@]}" --configurations 'her/*' --reference "$paper" \
  --out "$results/her_vs_paper.png" --title "Our HER against the paper's, robot A, 3 seeds" --table 10 12 15 20
question "Does CEBP beat HER on the figure's setup, task by task and form by form?"
plot "$results" --panels "${robot_a[@]}" --configurations 'her/*' 'cebp_initial/paper-per_worker' 'cebp/paper-wnorm' \
  --reference "$paper" --out "$results/cebp_vs_her.png" \
  --title "CEBP's forms against HER on the paper's Fig. 2 setup (robot A), 3 seeds" \
  --table 10 12 15 20 --improvement-at 10 12 15 20
question "CPER"
plot "$results" --panels pick_place-standard push-standard --configurations 'her/*' 'cper/*' --reference "$paper" \
  --out "$results/cper.png" --title "CPER (its published draw) against HER, robot A, 3 seeds" \
  --table 10 12 15 20 --improvement-at 10 12 20
question "PER, EBP and MEP"
plot "$results" --panels push-standard --configurations 'her/*' 'cebp_initial/paper-per_worker' 'per/*' 'ebp/*' 'mep/*' \
  --reference "$paper" --out "$results/push_baselines.png" \
  --title "Push, robot A: PER, EBP and MEP against HER and CEBP, 3 seeds" \
  --table 10 12 --improvement-at 10 12
question "Which robot reproduces the paper?"
plot "$results" --panels push-standard push-extended push-extended-joint-tableblind \
  --configurations 'her/paper' 'cebp/paper' 'cebp/paper-wnorm' 'cebp_initial/paper-per_worker' \
  'cebp_released/paper-per_worker' \
  --reference "$paper" --reference-panel push-standard --out "$results/robots.png" \
  --title "Push on each robot and goal space, with the paper's Push values" \
  --table 10 12 15 --improvement-at 10 12 15
question "What does faithful per-worker replay change?"
plot "$results" --panels push-standard push-extended-joint-tableblind \
  --configurations 'her/paper' 'cebp_initial/paper-wnorm' 'cebp_initial/paper-per_worker-wnorm' 'cebp_released/paper' \
  'cebp_released/paper-per_worker' --out "$results/per_worker.png" \
  --title "One merged buffer against each worker's own replay (both with the superseded normalised loss), Push" \
  --table 10 12 15 --improvement-at 10 12 15
question "What do the IS weights do (-beta0)?"
plot "$results" --panels push-standard \
  --configurations 'her/*' 'cebp_initial/paper-per_worker' 'cebp_initial/paper-per_worker-beta0' 'per/*' 'ebp/*' \
  --reference "$paper" --out "$results/is_weights.png" \
  --title "Push, robot A: the Initial commit's CEBP with and without its IS weights, 3 seeds" \
  --table 10 12 --improvement-at 10 12
question "Does the sigmoid temperature matter, as the paper's ablation says?"
plot "$results" --panels push-standard-temperature --against 'cebp_T(.+)/paper-per_worker' --at 10 12 \
  --parameter-values 0.001 0.01 0.1 1 5 \
  --against-references push-standard/her/paper push-standard/cper/paper-per_worker-her_past \
  push-standard/cebp_initial/paper-per_worker --out "$results/push_temperature.png" \
  --title "The paper-form CEBP's sigmoid temperature on robot A's Push, with HER, CPER and the Initial commit's CEBP" \
  --table 5 10 12 --improvement-at 10 12 --parameter-baseline 0.01
question "The normalised critic loss (superseded), robot A"
plot "$results" --panels "${robot_a[@]}" \
  --configurations 'her/*' 'cebp_initial/paper-per_worker' 'cebp_initial/paper-per_worker-wnorm' \
  --out "$results/normalised_loss.png" \
  --title "The Initial commit's CEBP with baselines' critic loss and with the superseded normalised loss, 3 seeds" \
  --table 10 12 15 20 --improvement-at 10 12 15 20
question "The extended goal space"
plot "$results" --panels pick_place-extended push-extended --out "$results/extended_goals.png" \
  --title "The mocap Fetch on the extended goal spaces (merged buffer, normalised loss)" \
  --table 5 10 15 20 --mean-over 6 10 --improvement-at 10
question "How the samplers draw, merged and per worker"
for metric in is_weight_mean priority_ess_fraction; do
  plot "$results" --panels push-standard push-extended-joint-tableblind --metric "$metric" --log-y \
    --configurations 'cebp_initial/paper-wnorm' 'cebp_initial/paper-per_worker-wnorm' 'cebp_released/paper' \
    'cebp_released/paper-per_worker' --out "$results/$metric.png" \
    --title "Merged buffer against per-worker replay, Push (both with the superseded normalised loss)"
done
# The Franka training: cebp/paper is the first shipped run (before the env fixes of
# docs/results/sim2real/diagnosis.md), cebp/paper-per_worker the retrains, with 100- and 50-step episodes, and
# 50-step episodes with half the training episodes begun grasped (-grasped50).
question "The Sim2Real policy"
plot docs/results/sim2real/training \
  --panels franka_pick_place-standard franka_pick_place-standard-T50 franka_pick_place-standard-T50-grasped50 \
  --out docs/results/sim2real/test_success.png \
  --title "Franka pick-and-place in simulation, test success over 80 episodes" \
  --table 5 8 10 12 15 18 20 24
