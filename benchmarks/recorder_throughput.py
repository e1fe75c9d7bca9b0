"""Recorder throughput: messages/s from DDS into a rosbag2-style MCAP with zero loss, and the
writer's overhead against a bare mcap writer.

1. Writer only (no DDS): the same CDR payloads through mcap.Writer directly vs BagWriter.write
   (rosbag2 records, counts, flush checks), median over repeats -> per-message overhead.
2. From DDS: a publisher process sends N std_msgs/Float64 at a target rate (reliable, depth
   large); the recorder (TopicRecorder + BagWriter, as in bench_node) runs in another process.
   Reported: achieved publish rate, messages recorded, lost, recorded rate.

Run:  .venv/bin/python benchmarks/recorder_throughput.py [--quick]
Writes benchmarks/results/recorder_throughput.{json,csv} and recorder_throughput.png.
"""
from __future__ import annotations

import argparse
import io
import os
import struct
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_io import RESULTS, write_results  # noqa: E402

PAYLOADS = [b"\x00\x01\x00\x00" + struct.pack("<d", float(i)) for i in range(1000)]


def writer_only(n: int, repeats: int) -> dict:
    from mcap.writer import CompressionType, Writer

    from softcath_ros.recording import BagWriter

    bare, ours = [], []
    for _ in range(repeats):
        w = Writer(io.BytesIO(), compression=CompressionType.ZSTD)
        w.start(profile="ros2")
        sid = w.register_schema("std_msgs/msg/Float64", "ros2msg", b"float64 data\n")
        cid = w.register_channel("/x", "cdr", sid, {})
        t = time.perf_counter()
        for i in range(n):
            w.add_message(cid, i, PAYLOADS[i % 1000], i)
        w.finish()
        bare.append(time.perf_counter() - t)
        with tempfile.TemporaryDirectory() as d:
            b = BagWriter(Path(d) / "bag", fsync=False)
            b.add_topic("/x", "std_msgs/msg/Float64")
            t = time.perf_counter()
            for i in range(n):
                b.write("/x", PAYLOADS[i % 1000], i + 1)
            b.close()
            ours.append(time.perf_counter() - t)
    tb, to = float(np.median(bare)), float(np.median(ours))
    return {"case": "writer_only", "messages": n, "bare_mcap_msgs_per_s": n / tb, "bagwriter_msgs_per_s": n / to,
            "overhead_us_per_msg": (to - tb) / n * 1e6, "overhead_ratio": to / tb}


PUBLISHER = textwrap.dedent("""
    import sys, time, rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
    from std_msgs.msg import Float64
    n, rate = int(sys.argv[1]), float(sys.argv[2])
    rclpy.init()
    node = rclpy.create_node("bench_pub")
    pub = node.create_publisher(Float64, "/throughput", QoSProfile(depth=10000, history=HistoryPolicy.KEEP_LAST,
                                reliability=ReliabilityPolicy.RELIABLE))
    while node.count_subscribers("/throughput") == 0:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(1.0)
    msg = Float64()
    t0 = time.perf_counter()
    for i in range(n):
        msg.data = float(i)
        pub.publish(msg)
        target = t0 + (i + 1) / rate
        while time.perf_counter() < target:
            pass
    dt = time.perf_counter() - t0
    print(f"published {n} {dt}", flush=True)
    time.sleep(2.0)
""")

RECORDER = textwrap.dedent("""
    import sys, time, rclpy
    from softcath_ros.recording import BagWriter
    from softcath_ros.nodes.recorder import TopicRecorder
    n, path = int(sys.argv[1]), sys.argv[2]
    rclpy.init()
    node = rclpy.create_node("bench_rec")
    w = BagWriter(path)
    rec = TopicRecorder(node, w, ["/throughput"], depth=10000, poll_period=0.05)
    t_first = t_last = None
    deadline = time.time() + 120
    while time.time() < deadline:
        rclpy.spin_once(node, timeout_sec=0.2)
        got = rec.received.get("/throughput", 0)
        if got and t_first is None:
            t_first = time.perf_counter()
        if got >= n:
            break
        if t_first and time.perf_counter() - t_first > n / 1000 + 15:
            break
    t_last = time.perf_counter()
    w.close()
    print(f"recorded {rec.received.get('/throughput', 0)} lost {rec.lost} span {t_last - (t_first or t_last)}", flush=True)
""")


def from_dds(n: int, rate: float, domain: int) -> dict:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    with tempfile.TemporaryDirectory() as d:
        rec = subprocess.Popen([sys.executable, "-c", RECORDER, str(n), str(Path(d) / "bag")], env=env,
                               stdout=subprocess.PIPE, text=True)
        pub = subprocess.Popen([sys.executable, "-c", PUBLISHER, str(n), str(rate)], env=env,
                               stdout=subprocess.PIPE, text=True)
        try:
            pub_out, _ = pub.communicate(timeout=180)
            rec_out, _ = rec.communicate(timeout=180)
        finally:
            for p in (pub, rec):
                if p.poll() is None:
                    p.kill()
        _, sent, pub_dt = pub_out.split()[:3]
        words = rec_out.split()
        recorded, lost = int(words[1]), int(words[3])
        from mcap.reader import make_reader
        with open(Path(d) / "bag" / "bag_0.mcap", "rb") as f:
            in_file = make_reader(f).get_summary().statistics.message_count
    return {"case": "from_dds", "messages": n, "target_rate": rate, "published_rate": int(sent) / float(pub_dt),
            "recorded": recorded, "in_file": in_file, "lost": n - in_file, "middleware_lost": lost}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer messages (smoke run)")
    args = ap.parse_args()
    n = 20000 if args.quick else 100000
    rows = [writer_only(n, 3)]
    print(rows[-1], flush=True)
    for k, rate in enumerate((5000.0, 10000.0, 20000.0, 40000.0)):
        rows.append(from_dds(int(min(n, rate * 5)), rate, 150 + k))
        print(rows[-1], flush=True)
    keys = sorted({k for r in rows for k in r})
    rows = [{k: r.get(k, "") for k in keys} for r in rows]
    write_results("recorder_throughput", {"note": "2 shared cores, other engineers' jobs running (numbers under load)",
                                          "quick": args.quick}, rows)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    dds = [r for r in rows if r["case"] == "from_dds"]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot([r["published_rate"] for r in dds], [r["in_file"] / r["messages"] * 100 for r in dds], "o-")
    ax.set_xlabel("achieved publish rate [msg/s]")
    ax.set_ylabel("messages in the recording [%]")
    ax.set_title("recorder: Float64 from DDS into MCAP")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(RESULTS / "recorder_throughput.png", dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
