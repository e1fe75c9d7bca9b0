#!/usr/bin/env bash
# Main job: set up .venv, then run the whole characterisation on the embedded default (the
# simulated rig): sim_bench_node, model_node and bench_node as separate processes run the
# default protocol (0 -> 0.35 -> 0 bar, 3 trials, angle and blocking-force benches), record
# everything to MCAP and write the report. It prints where the recording and report are.
# Extra arguments go to `softcath characterise` (e.g. --protocol three_channel_directions).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh ros
# DDS on loopback; unless ROS_DOMAIN_ID is set, characterise picks a domain no other graph uses.
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
exec .venv/bin/softcath characterise "$@"
