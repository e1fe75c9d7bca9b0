"""CPU of an idle allocation_node + model_node graph (issue 34 item 11: <= 5 % of a core).

Starts allocation_node and model_node (both on ``--design``, their default rung and parameters
otherwise) as separate processes on a private domain, sends no command, waits until model_node
answers allocation_node's keep-alive zeros (a tip_pose is seen), lets them settle, then measures
the two processes' CPU (psutil user + system time) over ``--seconds``. Repeats with fresh
processes; reports the median and spread over repeats, per node and for the graph, and the
idle pressure_cmd rate (the keep-alive that satisfies the rig's 0.5 s command watchdog).

    .venv/bin/python benchmarks/idle_graph.py                  # 3 repeats of 20 s
    .venv/bin/python benchmarks/idle_graph.py --repeats 1 --seconds 5

Writes benchmarks/results/idle_graph.{json,csv}. Ctrl-C stops cleanly (nothing written).
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
import psutil

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from harness import write_results  # noqa: E402
from softcath_ros import topics  # noqa: E402
from softcath_ros.graph import NodeGraph  # noqa: E402

TARGET_CORE_FRACTION = 0.05


def run_once(design: str, settle_s: float, seconds: float, logs: Path) -> dict:
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import Float64MultiArray

    with NodeGraph() as graph:
        started = {name: graph.start(name, {"design": design}, ("--log-level", "warn"),
                                     stdout=open(logs / f"{name}.log", "w"), stderr=subprocess.STDOUT)
                   for name in ("allocation_node", "model_node")}
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=graph.domain)
        node = rclpy.create_node("idle_graph_probe", context=context)
        commands, tips = [], []
        node.create_subscription(Float64MultiArray, topics.PRESSURE_CMD, lambda m: commands.append(time.monotonic()), 100)
        node.create_subscription(PoseStamped, topics.TIP_POSE, lambda m: tips.append(m.pose.position.z), 100)
        from rclpy.executors import SingleThreadedExecutor

        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)

        def spin(duration):
            end = time.monotonic() + duration
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)

        try:
            end = time.monotonic() + 120.0
            while not tips and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
            if not tips:
                raise SystemExit(f"model_node never answered allocation_node; node logs in {logs}")
            commands.clear()
            t_settle = time.monotonic()
            spin(settle_s)       # the idle stream's rate, while settling
            idle_hz = len(commands) / (time.monotonic() - t_settle)
            procs = {name: psutil.Process(proc.pid) for name, proc in started.items()}
            before = {k: p.cpu_times() for k, p in procs.items()}
            t0 = time.monotonic()
            # the probe sleeps rather than spins while measuring: its own CPU is not counted anyway
            time.sleep(seconds)
            after = {k: p.cpu_times() for k, p in procs.items()}
            elapsed = time.monotonic() - t0
            ended = [name for name, proc in started.items() if proc.poll() is not None]
            if ended:
                raise SystemExit(f"{', '.join(ended)} ended during the measurement; node logs in {logs}")
        finally:
            node.destroy_node()
            rclpy.try_shutdown(context=context)
    cpu = {k: ((after[k].user - before[k].user) + (after[k].system - before[k].system)) / elapsed for k in procs}
    return {**{f"{k}_core_fraction": v for k, v in cpu.items()}, "graph_core_fraction": sum(cpu.values()),
            "idle_pressure_cmd_hz": idle_hz, "seconds": elapsed, "loadavg_1min": os.getloadavg()[0]}


def main() -> int:
    ap = argparse.ArgumentParser(description="CPU of an idle allocation_node + model_node graph")
    ap.add_argument("--design", default="three_channel_5mm", help="both nodes' design")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=20.0, help="measured seconds per repeat")
    ap.add_argument("--settle", type=float, default=3.0, help="seconds after the first pose before measuring "
                    "(the idle pressure_cmd rate is counted then)")
    ap.add_argument("--name", default="idle_graph")
    args = ap.parse_args()
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    runs = []
    logs = Path(tempfile.mkdtemp(prefix="idle_graph_"))
    try:
        for i in range(args.repeats):
            r = run_once(args.design, args.settle, args.seconds, logs)
            runs.append(r)
            print(f"repeat {i + 1}/{args.repeats}: graph {r['graph_core_fraction']:.1%} of a core "
                  f"(allocation_node {r['allocation_node_core_fraction']:.1%}, model_node "
                  f"{r['model_node_core_fraction']:.1%}), idle pressure_cmd {r['idle_pressure_cmd_hz']:.1f} Hz",
                  flush=True)
    except KeyboardInterrupt:
        print("interrupted: nothing written", file=sys.stderr)
        return 130
    keys = [k for k in runs[0] if k not in ("seconds", "loadavg_1min")]
    row = {"design": args.design, "repeats": len(runs), "seconds_each": args.seconds}
    for k in keys:
        v = np.array([r[k] for r in runs])
        row[f"{k}_median"] = float(np.median(v))
        row[f"{k}_min"], row[f"{k}_max"] = float(v.min()), float(v.max())
    row["target_core_fraction"] = TARGET_CORE_FRACTION
    row["meets_target"] = bool(row["graph_core_fraction_median"] <= TARGET_CORE_FRACTION)
    meta = {"command": " ".join(["python"] + [Path(sys.argv[0]).as_posix()] + sys.argv[1:]),
            "what": "CPU of the two processes while no command is sent (psutil user+system time / wall time)",
            "keep_alive": "allocation_node re-sends an unchanged output every 0.1 s; the rig vents after 0.5 s "
                          "without a command (docs/rig.md)",
            "note": "2 cores shared with other engineers' jobs; medians over repeats", "runs": runs}
    write_results(args.name, meta, [row])
    print(f"median over {len(runs)}: graph {row['graph_core_fraction_median']:.1%} of a core "
          f"(target <= {TARGET_CORE_FRACTION:.0%}); idle pressure_cmd {row['idle_pressure_cmd_hz_median']:.1f} Hz; "
          f"wrote benchmarks/results/{args.name}.{{json,csv}}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
