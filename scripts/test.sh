#!/usr/bin/env bash
# Sets up .venv with the ROS, test, fe (NGSolve) and cluster (Dask) extras and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh "ros,test,fe,cluster,hardware"
# DDS stays on loopback; test/conftest.py leases each test process its own domain and every node
# test another (softcath_ros.graph), so parallel runs do not see each other. One process by
# default: with two pytest-xdist workers (SOFTCATH_TEST_WORKERS=2, a test file per worker) the suite
# takes 8 min instead of about 15, but three signal and full-disk tests of characterise still fail
# there (they pass alone), so parallel runs are not the default yet.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
exec .venv/bin/python -m pytest -n "${SOFTCATH_TEST_WORKERS:-0}" --dist loadfile "$@"
