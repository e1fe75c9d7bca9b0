"""Does allocation_node sustain 1 kHz? (issue 4 target)

Starts the installed ``allocation_node`` as its own process (publish_rate 1000 Hz), sends
/softcath/bend_cmd at 1 kHz from this process (a sweep of directions, so every command
is a fresh allocation) and records /softcath/pressure_cmd. Reports the received rate,
the inter-arrival intervals (median, 99th percentile), how many commands the node
counted (its /diagnostics), and the node's CPU share (psutil).

    .venv/bin/python benchmarks/allocation_node_rate.py [--seconds 10] [--rate 1000] [--model surrogate]
        [--name allocation_node_rate]

``--model``: the node's rung (default: the node's default, the section rung's surrogate table).
Writes benchmarks/results/<name>.{json,csv,png}.
"""
from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from harness import RESULTS, save_figure, write_results  # benchmarks/ is the script's directory
from softcath_ros import topics  # noqa: E402
from softcath_ros.graph import graph_env, lease_domain  # noqa: E402


SENDER = """
import math, sys, time, rclpy
from geometry_msgs.msg import Vector3Stamped
from softcath_ros import topics
rate, seconds = float(sys.argv[1]), float(sys.argv[2])
rclpy.init()
node = rclpy.create_node("alloc_rate_sender")
pub = node.create_publisher(Vector3Stamped, topics.BEND_CMD, 100)
m = Vector3Stamped()
m.header.frame_id = topics.FRAME_ID
period, n = 1.0 / rate, 0
t0 = time.perf_counter()
while time.perf_counter() - t0 < seconds:
    phi = 2 * math.pi * (n % 3600) / 3600   # a sweep: every command is a fresh allocation
    m.vector.x, m.vector.y = 5.0 * math.cos(phi), 5.0 * math.sin(phi)
    pub.publish(m)
    n += 1
    delay = t0 + n * period - time.perf_counter()
    if delay > 0:
        time.sleep(delay)
print(n / (time.perf_counter() - t0))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=1000.0, help="command and publish rate, Hz")
    ap.add_argument("--model", default="surrogate", help="allocation_node's rung (parameter 'model')")
    ap.add_argument("--name", default="allocation_node_rate", help="results stem under benchmarks/results/")
    args = ap.parse_args()

    import psutil
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64MultiArray

    lease = lease_domain()   # a private domain (softcath_ros.graph), held until exit
    args.domain = lease.domain
    env = graph_env(args.domain)
    exe = Path(sys.executable).parent / "allocation_node"
    node_proc = subprocess.Popen([str(exe), "--ros-args", "-p", f"publish_rate:={args.rate}",
                                  "-p", "max_pressure_rate:=1.0e7", "-p", "command_timeout:=0.5",
                                  "-p", "diagnostics_period:=0.5", "-p", f"model:={args.model}"],
                                 env=env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=args.domain)
    node = rclpy.create_node("alloc_rate_bench", context=ctx)
    executor = rclpy.executors.SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    arrivals = []
    accepted, published = [], []  # (arrival time, counter) from the node's /diagnostics

    def on_diag(msg):
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            if st.name == f"{topics.ALLOCATION_NODE}: commands":
                accepted.append((time.perf_counter(), int(values["accepted"])))
            elif st.name == f"{topics.ALLOCATION_NODE}: output":
                published.append((time.perf_counter(), int(values["messages_published"])))

    node.create_subscription(Float64MultiArray, topics.PRESSURE_CMD,
                             lambda m: arrivals.append(time.perf_counter()), 100)
    node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diag, 10)
    sender = None

    try:
        t_end = time.monotonic() + 30
        while len(arrivals) < 20 and time.monotonic() < t_end:  # discovery
            executor.spin_once(timeout_sec=0.05)
        if len(arrivals) < 20:
            raise SystemExit("allocation_node did not start publishing")
        ps = psutil.Process(node_proc.pid)
        # The operator sending commands is a third process, paced on absolute deadlines.
        sender = subprocess.Popen([sys.executable, "-c", SENDER, str(args.rate), str(args.seconds + 3.0)],
                                  env=env, stdout=subprocess.PIPE, text=True)
        t_warm = time.monotonic() + 2.0
        while time.monotonic() < t_warm:  # sender discovery and warm-up
            executor.spin_once(timeout_sec=0.01)

        def rate(series, t_start, t_end):
            inside = [(t, v) for t, v in series if t_start <= t <= t_end]
            (ta, va), (tb, vb) = inside[0], inside[-1]
            return (vb - va) / (tb - ta)

        arrivals.clear()
        ps.cpu_percent(None)
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < args.seconds - 1.0:
            executor.spin_once(timeout_sec=0.01)
        t1 = time.perf_counter()
        elapsed = t1 - t0
        n_recv = len(arrivals)
        cpu = ps.cpu_percent(None)
        counted, published_rate = rate(accepted, t0, t1), rate(published, t0, t1)
        sent_rate = float(sender.communicate(timeout=30)[0].split()[-1])
    except KeyboardInterrupt:
        print("interrupted")
        return
    finally:
        if sender is not None and sender.poll() is None:
            sender.kill()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
        node_proc.send_signal(signal.SIGINT)
        try:
            node_proc.wait(10)
        except subprocess.TimeoutExpired:
            node_proc.kill()

    callback_us = callback_cost_us(args.domain, args.model)
    gaps = np.diff(arrivals) * 1e3
    row = {"model": args.model, "target_rate_hz": args.rate, "seconds": elapsed,
           "commands_sent_per_s": sent_rate, "node_counted_commands_per_s": counted,
           "node_published_per_s": published_rate, "pressure_cmd_received_per_s": n_recv / elapsed,
           "interval_median_ms": float(np.median(gaps)), "interval_p99_ms": float(np.percentile(gaps, 99)),
           "interval_max_ms": float(gaps.max()), "node_cpu_percent": cpu,
           "callback_median_us": callback_us,
           "sustains_target": bool(published_rate >= 0.95 * args.rate and counted >= 0.95 * sent_rate)}
    for k, v in row.items():
        print(f"{k:32s} {v:.3f}" if isinstance(v, float) else f"{k:32s} {v}")
    write_results(args.name, {"note": "shared 2-core machine under load; sender and receiver "
                                                   "share this process"}, [row])
    plot(gaps, row, args.name)
    print(f"results in {RESULTS}/{args.name}.{{json,csv,png}}")


def callback_cost_us(domain: int, model: str, calls: int = 20000) -> float:
    """Median time of the node's own work per bend_cmd (check, allocate, rate limit, publish),
    measured in this process by calling the subscription callback directly: the part of the
    budget that is ours, apart from rclpy's executor and DDS."""
    import rclpy
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.parameter import Parameter

    from softcath_ros.nodes.allocation_node import AllocationNode

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = AllocationNode(context=ctx, parameter_overrides=[Parameter("model", value=model)])
    try:
        msgs = []
        for i in range(calls):
            m = Vector3Stamped()
            m.header.frame_id = topics.FRAME_ID
            m.vector.x, m.vector.y = 5.0 * np.cos(i * 1e-3), 5.0 * np.sin(i * 1e-3)
            msgs.append(m)
        out = np.empty(calls)
        for i, m in enumerate(msgs):
            t0 = time.perf_counter_ns()
            node._on_bend(m)
            out[i] = (time.perf_counter_ns() - t0) * 1e-3
        return float(np.median(out))
    finally:
        node.destroy_node()
        rclpy.shutdown(context=ctx)


def plot(gaps_ms, row, name):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    ax.hist(np.clip(gaps_ms, 0, 5), bins=100)
    ax.set_yscale("log")
    ax.axvline(1e3 / row["target_rate_hz"], color="r", ls="--", label=f"{row['target_rate_hz']:g} Hz period")
    ax.set_xlabel("interval between /softcath/pressure_cmd messages, ms (clipped at 5)")
    ax.set_ylabel("count")
    ax.set_title(f"allocation_node ({row['model']}) at {row['target_rate_hz']:g} Hz: published {row['node_published_per_s']:.0f}/s, "
                 f"allocated {row['node_counted_commands_per_s']:.0f} cmd/s", fontsize=10)
    ax.legend()
    fig.tight_layout()
    save_figure(fig, name, dpi=120)


if __name__ == "__main__":
    main()
