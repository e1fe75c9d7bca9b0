#!/usr/bin/env bash
# Sets up .venv with the ROS, test, fe (NGSolve) and cluster (Dask) extras and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh "ros,test,fe,cluster,hardware"
# DDS stays on loopback, over UDP only (test/conftest.py: config/dds/loopback_udp.xml); conftest
# leases each test process its own domain and every node test another (softcath_ros.graph), so
# parallel runs do not see each other. Three pytest-xdist workers by default, a test file per
# worker: on two cores the node tests spend much of their time waiting on a protocol's real time,
# and a third worker fills it (6 min 10 s of pytest against 6 min 37 s with two, quiet machine);
# SOFTCATH_TEST_WORKERS=0 runs the suite in this process, N in N workers.
exec .venv/bin/python -m pytest -n "${SOFTCATH_TEST_WORKERS:-3}" --dist loadfile "$@"
