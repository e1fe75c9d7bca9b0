#!/usr/bin/env bash
# Sets up .venv with the ROS, test, fe (NGSolve) and cluster (Dask) extras and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh "ros,test,fe,cluster,hardware"
# DDS stays on loopback; test/conftest.py leases the run its own domain and every node test
# another (softcath_ros.graph), so parallel runs do not see each other.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
exec .venv/bin/python -m pytest "$@"
