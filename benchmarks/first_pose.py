"""Time to the first pose after starting model_node with its defaults on a shipped design (issue 13
target: <= 3 s from a fresh install: the surrogate's tables ship, so nothing is built at start-up).

For each design and repeat: an empty cache of its own (``SOFTCATH_CACHE``), a private ROS domain,
a client in this process (rclpy already imported, as an operator's would be) that publishes one
valid pressure command every 10 ms; then ``model_node`` is started as a new process with only
``design`` set (every other parameter its default, model ``surrogate``) and the time from the
process's start to the first /softcath/tip_pose received is recorded, with where the node said its
table came from.

    .venv/bin/python benchmarks/first_pose.py [--repeats 3] [--designs implemented_5mm,three_channel_5mm]
    .venv/bin/python benchmarks/first_pose.py --node steer_node --designs three_channel_5mm [--realtime 50]

``--node steer_node`` (issue 34 target: <= 3 s, the surrogate on its shipped table): the client
publishes a reachable tip target every 10 ms and the time to the first non-zero
/softcath/pressure_cmd (the first answered target) is recorded. Writes
benchmarks/results/first_pose.{json,csv,png} (steer_node: first_command_steer.*).
"""
from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import save_figure, write_results  # noqa: E402

from softcath_ros import topics  # noqa: E402
from softcath_ros.graph import graph_env, lease_domain  # noqa: E402

COMMANDS = {1: [10000.0], 3: [12000.0, 5000.0, 0.0]}
TIP_TARGET = (0.004, 0.0, 0.0392)   # m: a bend of about 0.2 rad of the 40 mm body, within 0.3 bar


def _steer_input(node, qos):
    """steer_node's input (a tip target) and its answer (a non-zero pressure command)."""
    from geometry_msgs.msg import PointStamped
    from std_msgs.msg import Float64MultiArray

    got = []
    node.create_subscription(Float64MultiArray, topics.PRESSURE_CMD,
                             lambda m: got.append(time.perf_counter()) if max(m.data, default=0.0) > 0 else None, qos)
    pub = node.create_publisher(PointStamped, topics.TIP_TARGET, qos)
    msg = PointStamped()
    msg.header.frame_id = topics.FRAME_ID
    msg.point.x, msg.point.y, msg.point.z = TIP_TARGET
    return got, pub, msg


def one_run(design: str, n_channels: int, timeout_s: float = 60.0, node_name: str = "model_node") -> dict:
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import Float64MultiArray

    from softcath_ros.nodes.qos import stream_qos

    lease = lease_domain()
    cache = tempfile.mkdtemp(prefix="softcath-first-pose-")
    env = {**graph_env(lease.domain), "SOFTCATH_CACHE": cache}
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=lease.domain)
    node = rclpy.create_node("first_pose_probe", context=ctx)
    ex = rclpy.executors.SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    qos = stream_qos(100)
    if node_name == "steer_node":
        got, pub, msg = _steer_input(node, qos)
    else:
        got = []
        node.create_subscription(PoseStamped, topics.TIP_POSE, lambda m: got.append(time.perf_counter()), qos)
        pub = node.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, qos)
        msg = Float64MultiArray(data=COMMANDS[n_channels])
    exe = Path(sys.executable).parent / node_name
    t0 = time.perf_counter()
    proc = subprocess.Popen([str(exe), "--ros-args", "-p", f"design:={design}"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        next_send = t0
        while not got and time.perf_counter() - t0 < timeout_s and proc.poll() is None:
            if time.perf_counter() >= next_send:
                pub.publish(msg)
                next_send += 0.01
            ex.spin_once(timeout_sec=0.002)
        first = got[0] - t0 if got else float("nan")
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            out, _ = proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
        lease.release()
    ready = [ln for ln in out.splitlines() if "model surrogate: ready" in ln or "was built" in ln
             or "building one" in ln or "model surrogate (" in ln]
    return {"node": node_name, "design": design, "first_pose_s": first, "exit_code": proc.returncode,
            "table": ready[0].split("]: ", 1)[-1] if ready else "", "built_at_start": any("was built" in ln or "building one" in ln for ln in ready),
            "cache_entries_after": sum(len(f) for _, _, f in os.walk(cache))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--designs", default="implemented_5mm,three_channel_5mm")
    ap.add_argument("--node", choices=("model_node", "steer_node"), default="model_node")
    ap.add_argument("--realtime", type=int, default=0, help="SCHED_FIFO priority for this script and the node it "
                    "starts (inherited), 0 = normal: on a shared machine, the start-up without others' load")
    args = ap.parse_args()
    if args.realtime:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.realtime))
    from softcath_ros.core.design import load_design

    rows = []
    for rep in range(args.repeats):
        for name in args.designs.split(","):
            row = {"repeat": rep, **one_run(name, load_design(name).n_channels, node_name=args.node),
                   "load_average_1min": os.getloadavg()[0]}
            rows.append(row)
            print(f"{name}: first pose {row['first_pose_s']:.2f} s after start ({row['table']}); "
                  f"load {row['load_average_1min']:.1f}", flush=True)
    for name in args.designs.split(","):
        t = [r["first_pose_s"] for r in rows if r["design"] == name]
        print(f"{name}: median {np.median(t):.2f} s, max {max(t):.2f} s (target 3 s)")
    stem = "first_command_steer" if args.node == "steer_node" else "first_pose"
    write_results(stem, {"target_s": 3.0, "node": args.node, "command": " ".join(["python"] + sys.argv),
                         "realtime_priority": args.realtime,
                         "note": "fresh cache per run; shared 2-core machine"}, rows)
    plot(rows, args.node, stem)


def plot(rows, node_name: str = "model_node", stem: str = "first_pose") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5))
    names = list(dict.fromkeys(r["design"] for r in rows))
    for i, name in enumerate(names):
        t = [r["first_pose_s"] for r in rows if r["design"] == name]
        ax.plot([i] * len(t), t, "o", label=name)
    ax.axhline(3.0, color="k", ls="--", lw=1, label="target 3 s")
    ax.set_xticks(range(len(names)), names)
    ax.set_ylabel(f"start of {node_name} -> first " + ("tip_pose" if node_name == "model_node"
                                                        else "answered tip_target") + ", s")
    ax.set_ylim(bottom=0)
    ax.set_title(f"{node_name} defaults (surrogate, shipped table), empty cache")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, stem, dpi=110)


if __name__ == "__main__":
    main()
