"""Probe process for benchmarks/node_latency.py: drives a running model_node and times it.

Publishes pressure commands on /softcath/pressure_cmd at ``--rate`` for ``--warmup`` +
``--duration`` seconds from a thread on absolute deadlines (softcath_ros.tools.pacing),
and receives /softcath/tip_pose and /softcath/backbone on an EventsExecutor in the main
thread. Writes one JSON summary (and the raw arrays as .npz next to it).

How poses are matched to commands (honest, checkable): command i carries pressure
p(i) = 0.9 p_top (i mod 997) / 997 on channel 0, so 997 consecutive commands are distinct;
p_top is the top of the rung's own valid range (``model.pressure_range``, at most the
design's max_pressure: the surrogate's table ends where its source stopped converging). The
probe predicts the tip position for each of the 997 values with the core (same design
and rung as the node), identifies every received pose's residue i mod 997 by the nearest
predicted tip, and takes the first sequence number after the previous pose's with that
residue. The match error (received vs predicted tip) is reported; it is ~1e-17 m when
every pose is the node's answer to the command it is matched with.

Latencies, all on the machine's wall clock (CLOCK_REALTIME, which ROS stamps use):
- ``node``: probe callback time - header.stamp (node clock read on entry to its command
  callback) = node compute + publish + transport + probe dispatch. This is the issue's
  "command-to-pose latency from the received PoseStamped".
- ``e2e``: probe callback time - probe send time of the matched command: adds the command's
  transport and any queueing in the node's executor before its callback runs.
CPU: psutil user+system time of the node's pid (``--node-pid``) over the measured window.
The node's own /diagnostics reports during the window are kept too: its answer load (mean
answer time, busy fraction, WARN when behind) and its model_failed counter (a rung refusing
commands would show there, not as silently missing poses).
"""
from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from pathlib import Path

import numpy as np

from softcath_ros import topics

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import pressure_option  # noqa: E402

RESIDUES = 997


def command_pressures(n_seq: int, n_channels: int, top_pressure: float) -> np.ndarray:
    """(n_seq, C) Pa: channel 0 steps through 997 distinct values in [0, 0.9 top_pressure), the
    others stay at 0."""
    p = np.zeros((n_seq, n_channels))
    p[:, 0] = 0.9 * top_pressure * (np.arange(n_seq) % RESIDUES) / RESIDUES
    return p


def top_pressure(model) -> float:
    """Pa: the highest channel pressure both the design allows and the rung answers."""
    return min(float(model.pressure_range[1]), float(model.design.max_pressure))


def diagnostics_summary(reports: list[dict]) -> dict:
    """The node's /diagnostics reports over the window: answer load and refusals."""
    load = [r for r in reports if r["name"].endswith("(answer load)")]
    counters = [r for r in reports if not r["name"].endswith("(answer load)")]

    def values(key):
        # "n/a": no answer in that report's window (no rate measured)
        return [float(r["values"][key]) for r in load if r["values"].get(key, "n/a") != "n/a"]

    out = {"reports": len(load),
           "answer_load_warn_reports": sum(r["level"] != 0 for r in load),
           "mean_answer_ms_median": float(np.median(values("mean_answer_ms"))) if load else None,
           "busy_fraction_max": max(values("busy_fraction"), default=None),
           "commands_per_s_median": float(np.median(values("commands_per_s"))) if load else None,
           "max_rate_hz_median": float(np.median(values("max_rate_hz"))) if load else None,
           "answer_load_messages": sorted({r["message"] for r in load})[:3]}
    if counters:
        last = counters[-1]["values"]
        out.update(model_failed=int(last.get("model_failed", 0)), rejected=int(last.get("rejected", 0)),
                   superseded=int(last.get("superseded", 0)),   # stale: waited over 10 ms behind a newer one
                   model=last.get("model"), last_reason=last.get("last_reason", ""))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--design", default="implemented_5mm")
    ap.add_argument("--model", default="closed_form")
    ap.add_argument("--rate", type=float, default=1000.0, help="commands per second")
    ap.add_argument("--duration", type=float, default=10.0, help="measured seconds")
    ap.add_argument("--warmup", type=float, default=1.0, help="seconds sent before measuring")
    ap.add_argument("--qos-depth", type=int, default=1000)
    ap.add_argument("--reliability", default="reliable")
    ap.add_argument("--node-pid", type=int, required=True)
    ap.add_argument("--out", required=True, help="summary JSON path")
    ap.add_argument("--realtime-priority", type=int, default=0,
                    help="SCHED_FIFO priority for the probe's threads (0: normal), as for the node")
    ap.add_argument("--discovery-timeout", type=float, default=20.0)
    ap.add_argument("--top-pressure", type=pressure_option("--top-pressure"), default=0.0,
                    help="with its unit: drive channel 0 over 0.9 x this (default 0: the rung's own valid range)")
    args = ap.parse_args()
    # The sender thread must get the GIL within ~0.1 ms of its deadline, not after the
    # default 5 ms switch interval while the receiving thread runs callbacks.
    sys.setswitchinterval(1e-4)

    import psutil
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseArray, PoseStamped
    from rclpy.experimental import EventsExecutor
    from std_msgs.msg import Float64MultiArray

    from softcath_ros.core.design import load_design
    from softcath_ros.core.kinematics import tip_pose
    from softcath_ros.core.prediction import arc_and_cap
    from softcath_ros.core.models import make_model
    from softcath_ros.nodes.qos import stream_qos
    from softcath_ros.tools.pacing import run_paced

    design = load_design(args.design)
    model = make_model(args.model, design)
    n_warm = int(round(args.warmup * args.rate))
    n_meas = int(round(args.duration * args.rate))
    n_total = n_warm + n_meas
    top = args.top_pressure or top_pressure(model)
    pressures = command_pressures(n_total, design.n_channels, top)
    state = model.evaluate(pressures[:RESIDUES])
    arc, cap = arc_and_cap(model, design.length)
    expected_tip, _ = tip_pose(state.curvature, arc * state.axial_stretch, cap)

    rclpy.init()
    node = rclpy.create_node("softcath_latency_probe")
    qos = stream_qos(args.qos_depth, args.reliability)
    recv_ns = np.zeros(n_total + 10, dtype=np.int64)
    stamp_ns = np.zeros(n_total + 10, dtype=np.int64)
    tips = np.zeros((n_total + 10, 3))
    counts = {"tip": 0, "backbone": 0, "backbone_points": 0}

    def on_tip(msg: PoseStamped) -> None:
        t = time.time_ns()
        k = counts["tip"]
        if k < len(recv_ns):
            recv_ns[k] = t
            stamp_ns[k] = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            p = msg.pose.position
            tips[k] = (p.x, p.y, p.z)
        counts["tip"] = k + 1

    def on_backbone(msg: PoseArray) -> None:
        counts["backbone"] += 1
        counts["backbone_points"] = len(msg.poses)

    diagnostics: list[dict] = []

    def on_diagnostics(msg: DiagnosticArray) -> None:
        if "wall0" not in window or done.is_set():
            return  # only reports from the measured window
        for st in msg.status:
            if st.name.startswith(topics.MODEL_NODE):
                diagnostics.append({"name": st.name, "level": int.from_bytes(st.level, "little")
                                    if isinstance(st.level, bytes) else int(st.level), "message": st.message,
                                    "values": {kv.key: kv.value for kv in st.values}})

    window = {}
    done = threading.Event()
    node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diagnostics, 10)
    tip_sub = node.create_subscription(PoseStamped, topics.TIP_POSE, on_tip, qos)
    bb_sub = node.create_subscription(PoseArray, topics.BACKBONE, on_backbone, qos)
    pub = node.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, qos)
    executor = EventsExecutor()
    executor.add_node(node)
    if args.realtime_priority:
        from softcath_ros.nodes.realtime import set_realtime_priority

        problem = set_realtime_priority(args.realtime_priority)
        if problem:
            raise SystemExit(f"latency_probe: {problem}")

    # Discovery: both directions matched before the first command.
    t0 = time.monotonic()
    while not (pub.get_subscription_count() > 0 and tip_sub.get_publisher_count() > 0
               and bb_sub.get_publisher_count() > 0):
        executor.spin_once(timeout_sec=0.05)
        if time.monotonic() - t0 > args.discovery_timeout:
            raise SystemExit("latency_probe: model_node not discovered")
    time.sleep(0.3)

    node_proc = psutil.Process(args.node_pid)
    me = psutil.Process()
    msgs = [Float64MultiArray(data=row.tolist()) for row in pressures]  # built before timing starts

    def send(i: int) -> None:
        if i == n_warm:
            window["node_cpu0"], window["probe_cpu0"] = node_proc.cpu_times(), me.cpu_times()
            window["wall0"] = time.monotonic()
        pub.publish(msgs[i])

    def sender() -> None:
        window["deadline_ns"], window["sent_ns"] = run_paced(n_total, args.rate, send)
        done.set()

    threading.Thread(target=sender, daemon=True).start()
    while not done.is_set():
        executor.spin_once(timeout_sec=0.1)
    t_end = time.monotonic() + 2.0  # stragglers
    while (counts["tip"] < n_total or counts["backbone"] < n_total) and time.monotonic() < t_end:
        executor.spin_once(timeout_sec=0.05)
    # CPU window ends with the last command sent plus the time to answer it.
    wall = time.monotonic() - window["wall0"]
    # more than one publisher: another node on this ROS_DOMAIN_ID answered too (its poses spoil the count)
    publishers = {"tip": tip_sub.get_publisher_count(), "backbone": bb_sub.get_publisher_count()}
    node_cpu = node_proc.cpu_times()
    probe_cpu = me.cpu_times()
    node.destroy_node()
    rclpy.try_shutdown()

    def busy(a, b):
        return (b.user - a.user) + (b.system - a.system)

    n_recv = min(counts["tip"], len(recv_ns))
    recv_ns, stamp_ns, tips = recv_ns[:n_recv], stamp_ns[:n_recv], tips[:n_recv]
    # Match poses to commands by content (see module docstring).
    residue = np.zeros(n_recv, dtype=np.int64)
    err = np.zeros(n_recv)
    for a in range(0, n_recv, 1000):  # blocks keep the distance matrix small
        dist = np.linalg.norm(tips[a:a + 1000, None, :] - expected_tip[None, :, :], axis=2)
        residue[a:a + 1000] = dist.argmin(axis=1)
        err[a:a + 1000] = dist.min(axis=1)
    match_err = float(err.max()) if n_recv else float("nan")
    seq = np.empty(n_recv, dtype=np.int64)
    last = -1
    for k, r in enumerate(residue):
        s = last + 1 + ((int(r) - (last + 1)) % RESIDUES)
        seq[k] = last = s
    sent_ns, deadline_ns = window["sent_ns"], window["deadline_ns"]
    valid = seq < len(sent_ns)
    meas = valid & (seq >= n_warm)
    node_lat = (recv_ns[meas] - stamp_ns[meas]) * 1e-6
    e2e_lat = (recv_ns[meas] - sent_ns[seq[meas]]) * 1e-6
    send_late = (sent_ns[n_warm:] - deadline_ns[n_warm:]) * 1e-6
    span = (sent_ns[-1] - sent_ns[n_warm]) * 1e-9

    def stats(x):
        if len(x) == 0:
            return {}
        q = np.percentile(x, [50, 90, 99, 99.9])
        return {"p50_ms": q[0], "p90_ms": q[1], "p99_ms": q[2], "p999_ms": q[3], "max_ms": float(x.max()),
                "mean_ms": float(x.mean())}

    summary = {
        "rate_hz": args.rate, "duration_s": args.duration, "sent": int(n_meas),
        "received_tip": int(meas.sum()), "lost_tip": int(n_meas - meas.sum()),
        "received_backbone_total": counts["backbone"], "sent_total": int(n_total),
        "lost_backbone_total": int(n_total - counts["backbone"]), "backbone_points": counts["backbone_points"],
        "achieved_send_rate_hz": (n_meas - 1) / span if span > 0 else float("nan"),
        "send_lateness_p99_ms": float(np.percentile(send_late, 99)),
        "match_error_max_m": match_err,
        "node_latency": stats(node_lat), "e2e_latency": stats(e2e_lat),
        "node_cpu_cores": busy(window["node_cpu0"], node_cpu) / wall,
        "probe_cpu_cores": busy(window["probe_cpu0"], probe_cpu) / wall,
        "publishers": publishers,
        "model": args.model, "design": args.design, "top_pressure_pa": top,
        "node_diagnostics": diagnostics_summary(diagnostics),
    }
    out = Path(args.out)
    out.write_text(json.dumps(summary, indent=1, default=float))
    np.savez_compressed(out.with_suffix(".npz"), node_ms=node_lat, e2e_ms=e2e_lat)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
