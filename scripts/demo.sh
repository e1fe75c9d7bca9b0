#!/usr/bin/env bash
# Main job (for now): set up .venv, start model_node, feed it a pressure sweep
# 0 -> 0.35 bar, print the predicted poses and save a plot of the backbones under runs/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh ros
# Own DDS domain on loopback, so the demo neither sees nor disturbs other ROS graphs.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 50) + 50 ))}"
run_dir="runs/demo-$(date +%Y%m%d-%H%M%S)"
mkdir -p "$run_dir"

.venv/bin/model_node --ros-args -p design:=implemented_5mm -p model:=closed_form \
  >"$run_dir/model_node.log" 2>&1 &
node_pid=$!
stop_node() {
  if kill -0 "$node_pid" 2>/dev/null; then
    kill -INT "$node_pid"
    wait "$node_pid" && echo "[demo] model_node stopped cleanly" || echo "[demo] model_node exited with $?" >&2
  fi
}
trap stop_node EXIT

echo "[demo] model_node running (pid $node_pid, ROS_DOMAIN_ID=$ROS_DOMAIN_ID); sending 0 -> 0.35 bar"
.venv/bin/python -m softcath_ros.tools.pressure_sweep --from 0 --to 0.35 --steps 8 --unit bar \
  --plot "$run_dir/backbones.png" --json "$run_dir/sweep.json"
echo "[demo] outputs in $run_dir/ (backbones.png, sweep.json, model_node.log)"
