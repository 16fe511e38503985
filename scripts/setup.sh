#!/usr/bin/env bash
# Installs torchrl-cebp into ./.venv (reused while pyproject.toml is unchanged) and the
# system library for offscreen MuJoCo rendering. Usage: bash scripts/setup.sh [extras]
set -euo pipefail
cd "$(dirname "$0")/.."
case "${1:-}" in
  -h|--help) sed -n '2,3p' "$0" | cut -c3-; echo "extras: comma-separated, of pyproject.toml's (default: test)"; exit 0 ;;
esac
extras="${1:-test}"
known=$(sed -n '/^\[project.optional-dependencies\]/,/^\[/s/^\([a-z0-9_-]*\) = .*/\1/p' pyproject.toml | tr '\n' ' ')
for extra in ${extras//,/ }; do
  if [[ " $known" != *" $extra "* ]]; then
    echo "[setup] unknown extra '$extra'; pyproject.toml has: ${known% }" >&2
    exit 2
  fi
done

if ! ldconfig -p 2>/dev/null | grep -q libOSMesa; then
  if command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    echo "[setup] installing libosmesa6 (offscreen rendering)"
    apt-get update -qq && apt-get install -y -qq libosmesa6 >/dev/null
  else
    echo "[setup] warning: libOSMesa not found; install Debian's libosmesa6 for offscreen rendering" >&2
  fi
fi

stamp=".venv/.installed-$(cat pyproject.toml | sha256sum | cut -c1-16)-${extras//,/_}"
if [ ! -f "$stamp" ]; then
  echo "[setup] creating .venv and installing torchrl-cebp[$extras] (a few minutes the first time)"
  python3 -m venv .venv
  .venv/bin/pip install -q --upgrade pip
  .venv/bin/pip install -q -e ".[$extras]"
  rm -f .venv/.installed-*
  touch "$stamp"
else
  echo "[setup] .venv is up to date"
fi
