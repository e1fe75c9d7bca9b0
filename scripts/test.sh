#!/usr/bin/env bash
# Sets up .venv with the ROS, test, fe (NGSolve) and cluster (Dask) extras and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh "ros,test,fe,cluster"
# Each pytest run gets its own DDS domain and stays on loopback, so parallel runs do not see each other.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 100) + 100 ))}"
exec .venv/bin/python -m pytest "$@"
