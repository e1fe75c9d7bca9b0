#!/usr/bin/env bash
# Main job: set up .venv, then run the whole characterisation on the embedded default (the
# simulated rig): sim_bench_node, model_node and bench_node as separate processes run the
# default protocol (0 -> 0.35 -> 0 bar, 3 trials, angle and blocking-force benches), record
# everything to MCAP and write the report. It prints where the recording and report are.
# Extra arguments go to `softcath characterise` (e.g. --protocol three_channel_directions).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh ros
# Own DDS domain on loopback, so the demo neither sees nor disturbs other ROS graphs.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 50) + 50 ))}"
exec .venv/bin/softcath characterise "$@"
