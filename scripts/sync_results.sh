#!/usr/bin/env bash
# Copies every comparison run's progress.csv from runs/ to docs/results/comparison/ (same layout), and
# every learning check's (benchmarks/learning.py, runs/learning/) to docs/results/learning/collectors/,
# the Sim2Real training's (runs/franka_pick_place-*) to docs/results/sim2real/training/,
# and commits them, so that finished epochs survive the session. A shorter CSV never replaces a longer one.
# Usage: bash scripts/sync_results.sh [--every SECONDS]
set -uo pipefail
cd "$(dirname "$0")/.."
usage() { sed -n '2,6p' "$0" | cut -c3-; }
every=0
case "${1:-}" in
  "") ;;
  -h|--help) usage; exit 0 ;;
  --every)
    every=${2:-}
    if ! [[ "$every" =~ ^[1-9][0-9]*$ ]]; then echo "--every needs a number of seconds, got '${every}'" >&2; exit 2; fi ;;
  *) echo "unknown option ${1}: the only option is --every SECONDS" >&2; exit 2 ;;
esac
sync_once() {
  local copied=()
  while IFS= read -r csv; do
    case "$csv" in
      runs/learning/*) dest="docs/results/learning/collectors/${csv#runs/learning/}" ;;
      runs/franka_pick_place-*) dest="docs/results/sim2real/training/${csv#runs/}" ;;
      *) dest="docs/results/comparison/${csv#runs/}" ;;
    esac
    # A run restarted from epoch 0 (its checkpoint lost with an earlier machine) repeats the committed rows, bit for
    # bit on the same CPU and within float noise on another: it replaces them only once it has caught up, so no
    # committed epoch is ever withdrawn.
    if [ -f "$dest" ] && [ "$(wc -l < "$csv")" -lt "$(wc -l < "$dest")" ]; then
      continue
    fi
    if ! cmp -s "$csv" "$dest"; then
      mkdir -p "$(dirname "$dest")" && cp "$csv" "$dest" && copied+=("$dest")
    fi
  done < <(find -H runs -path runs/quick -prune -o -name progress.csv -print 2>/dev/null | sort)
  # -H: runs/ may be a link to a folder outside the checkout, which a new checkout keeps.
  # Only the copied CSVs: other edits under docs/results/ (a figure being redrawn) are not this script's to commit.
  if [ "${#copied[@]}" -gt 0 ]; then
    git add -- "${copied[@]}"
    git commit -q -m "Results: finished epochs" -- "${copied[@]}" \
      && echo "[sync] $(date -u +%TZ) committed"
  fi
}
sync_once
while [ "$every" -gt 0 ]; do sleep "$every"; sync_once; done
