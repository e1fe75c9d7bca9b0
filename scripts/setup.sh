#!/usr/bin/env bash
# Creates .venv (Python 3.11) and installs softcath_ros with the given extras, e.g. "ros,test";
# a lab PC with hardware: "ros,vision,hardware" (docs/lab.md).
# Re-running is cheap: the install is skipped while setup.py and the extras are unchanged.
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-ros}"
python="${PYTHON:-python3.11}"
command -v "$python" >/dev/null 2>&1 || python=python3
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv with $($python --version)"
  "$python" -m venv .venv
fi
stamp=".venv/.softcath-installed-$(cat setup.py setup.cfg pyproject.toml package.xml | sha256sum | cut -c1-12)-${extras//,/_}"
if [ ! -f "$stamp" ]; then
  echo "[setup] installing softcath_ros[$extras] into .venv (first run takes a minute)"
  # pip's output goes to a log (the machine's extra indexes make it chatty); shown on failure.
  log=.venv/pip-install.log
  if ! .venv/bin/python -m pip install -e ".[$extras]" >"$log" 2>&1; then
    tail -n 40 "$log"; echo "[setup] pip install failed; full log in $log" >&2; exit 1
  fi
  touch "$stamp"
fi
