#!/usr/bin/env bash
# Build the docs site into docs/_build/html, every warning an error (a broken reference or a missing page fails).
# Needs the docs extra: .venv/bin/python -m pip install -e ".[docs]"
# Usage: bash scripts/build_docs.sh [sphinx-build options]
set -euo pipefail
cd "$(dirname "$0")/.."
case "${1:-}" in -h|--help) sed -n '2,4p' "$0" | cut -c3-; exit 0 ;; esac
export MUJOCO_GL="${MUJOCO_GL:-osmesa}"
# -E: read every page afresh, so a warning of an unchanged page fails every build, not only the first.
exec .venv/bin/python -m sphinx -E -W --keep-going -b html docs docs/_build/html "$@"
