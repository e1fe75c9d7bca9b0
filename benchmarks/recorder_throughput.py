"""Recorder throughput: messages/s from DDS into a rosbag2-style MCAP with zero loss, and the
writer's overhead against a bare mcap writer.

1. Writer only (no DDS): the same CDR payloads through mcap.Writer directly vs BagWriter.write
   (rosbag2 records, counts, flush checks), synchronous and with the background writer thread
   (there ``write`` only queues; the time until ``close`` returns is what counts), median over
   repeats -> per-message overhead.
2. From DDS: ``--publishers`` processes each send their share of N std_msgs/Float64 as
   pre-serialized bytes, in batches every millisecond (a Python publisher calling publish() once
   per busy-wait tops out near 10k msg/s); reliable, keep-last 10000. The recorder runs in
   another process with the recorder configuration under test:
     - ``single_sync``: the previous recorder (SingleThreadedExecutor, MessageInfo timestamps,
       writes in the callback);
     - ``events_queue``: the current one (EventsExecutor, writer thread).
   Both use TopicRecorder + BagWriter exactly as bench_node does, subscription reliable,
   keep-last 10000. Reported per target rate, median over repeats: offered rate (messages sent
   / span of the publishers), received rate (messages in the file / span from first to last
   message), loss (sent - in file; a publish that fails because the publisher's reliable history
   is full of unacknowledged samples is counted apart, as publish_failed), and CPU seconds per message of the recorder and the
   publishers (process time), which says which side runs out of CPU first.

The machine has 2 cores shared with other jobs: the load average before each run is recorded.

Run:  .venv/bin/python benchmarks/recorder_throughput.py [--quick] [--repeats N] [--publishers P] [--nice -10]
Writes benchmarks/results/recorder_throughput.{json,csv} and recorder_throughput.png (with --nice:
recorder_throughput_nice<N>.*).
"""
from __future__ import annotations

import argparse
import io
import json
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
from harness import save_figure, write_results  # noqa: E402
from softcath_ros.graph import graph_env, lease_domain  # noqa: E402

PAYLOADS = [b"\x00\x01\x00\x00" + struct.pack("<d", float(i)) for i in range(1000)]
CONFIGS = ("single_sync", "events_queue")


def writer_only(n: int, repeats: int) -> dict:
    from mcap.writer import CompressionType, Writer

    from softcath_ros.recording import BagWriter

    bare, ours, ours_bg, bg_enqueue = [], [], [], []
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
        for background, out in ((False, ours), (True, ours_bg)):
            with tempfile.TemporaryDirectory() as d:
                b = BagWriter(Path(d) / "bag", fsync=False, background=background)
                b.add_topic("/x", "std_msgs/msg/Float64")
                t = time.perf_counter()
                for i in range(n):
                    b.write("/x", PAYLOADS[i % 1000], i + 1)
                if background:
                    bg_enqueue.append(time.perf_counter() - t)
                b.close()
                out.append(time.perf_counter() - t)
                assert b.message_count == n
    tb, to, tq, te = (float(np.median(x)) for x in (bare, ours, ours_bg, bg_enqueue))
    return {"case": "writer_only", "messages": n, "bare_mcap_msgs_per_s": n / tb, "bagwriter_msgs_per_s": n / to,
            "bagwriter_background_msgs_per_s": n / tq, "background_enqueue_us_per_msg": te / n * 1e6,
            "overhead_us_per_msg": (to - tb) / n * 1e6, "overhead_ratio": to / tb}


PUBLISHER = textwrap.dedent("""
    import json, sys, time, rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64
    n, rate, expected_subs = int(sys.argv[1]), float(sys.argv[2]), 1
    rclpy.init()
    node = rclpy.create_node("bench_pub")
    pub = node.create_publisher(Float64, "/throughput", QoSProfile(depth=10000, history=HistoryPolicy.KEEP_LAST,
                                reliability=ReliabilityPolicy.RELIABLE))
    payloads = [serialize_message(Float64(data=float(i))) for i in range(1000)]
    while node.count_subscribers("/throughput") < expected_subs:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(1.5)  # the subscription's matching settles
    batch = max(1, int(round(rate / 1000.0)))  # one batch per millisecond
    publish = pub.publish
    failed = 0
    c0, w0, t0 = time.process_time(), time.time(), time.perf_counter()
    i = 0
    while i < n:
        k = min(batch, n - i)
        for j in range(i, i + k):
            try:
                publish(payloads[j % 1000])
            except Exception:  # reliable history full of unacknowledged samples: the write times out
                failed += 1
        i += k
        d = t0 + i / rate - time.perf_counter()
        if d > 0:
            time.sleep(d)
    print(json.dumps({"sent": n - failed, "failed": failed, "start": w0, "end": time.time(), "cpu": time.process_time() - c0}), flush=True)
    time.sleep(3.0)  # stay for reliable repairs
""")

RECORDER = textwrap.dedent("""
    import json, sys, time, rclpy
    from softcath_ros.recording import BagWriter
    from softcath_ros.nodes.recorder import TopicRecorder
    from softcath_ros.nodes.executors import make_executor
    n, path, config = int(sys.argv[1]), sys.argv[2], sys.argv[3]
    events = config == "events_queue"
    rclpy.init()
    node = rclpy.create_node("bench_rec")
    w = BagWriter(path, background=events)
    rec = TopicRecorder(node, w, ["/throughput"], depth=10000, poll_period=0.05, message_info=not events)
    ex = make_executor("events" if events else "single")
    ex.add_node(node)
    last, first, t_last, cpu_first, cpu_last = 0, None, None, None, None
    deadline = time.time() + 120
    while time.time() < deadline:
        ex.spin_once(timeout_sec=0.05)
        got = rec.received.get("/throughput", 0)
        if got != last:
            now = time.time()
            if first is None:
                first, cpu_first = now, time.process_time()
            last, t_last, cpu_last = got, now, time.process_time()
        if got >= n or (t_last is not None and time.time() - t_last > 4.0):
            break
    w.close()  # drains the writer thread: its CPU counts too
    cpu_end = time.process_time()
    print(json.dumps({"received": last, "first": first, "last": t_last, "lost_events": rec.lost,
                      "write_failures": rec.write_failures + w.write_failures,
                      "cpu": (cpu_end - cpu_first) if cpu_first is not None else 0.0}), flush=True)
""")


def from_dds(n: int, rate: float, config: str, publishers: int, domain: int, nice: int = 0) -> dict:
    from mcap.reader import make_reader

    env = graph_env(domain)
    load = os.getloadavg()[0]
    shares = [n // publishers + (1 if k < n % publishers else 0) for k in range(publishers)]
    with tempfile.TemporaryDirectory() as d:
        pre = (lambda: os.nice(nice)) if nice else None  # every thread (DDS ones too) inherits it
        rec = subprocess.Popen([sys.executable, "-c", RECORDER, str(n), str(Path(d) / "bag"), config], env=env,
                               stdout=subprocess.PIPE, text=True, preexec_fn=pre)
        pubs = [subprocess.Popen([sys.executable, "-c", PUBLISHER, str(s), str(rate / publishers)], env=env,
                                 stdout=subprocess.PIPE, text=True, preexec_fn=pre) for s in shares]
        try:
            pub_out = [json.loads(p.communicate(timeout=240)[0].splitlines()[0]) for p in pubs]
            rec_out = json.loads(rec.communicate(timeout=150)[0].splitlines()[-1])
        finally:
            for p in (*pubs, rec):
                if p.poll() is None:
                    p.kill()
                    p.wait()
        with open(Path(d) / "bag" / "bag_0.mcap", "rb") as f:
            in_file = make_reader(f).get_summary().statistics.message_count
    sent = sum(p["sent"] for p in pub_out)
    failed = sum(p["failed"] for p in pub_out)
    span_pub = max(p["end"] for p in pub_out) - min(p["start"] for p in pub_out)
    span_rec = (rec_out["last"] - rec_out["first"]) if rec_out["first"] else float("nan")
    return {"case": "from_dds", "config": config, "publishers": publishers, "messages": n, "target_rate": rate,
            "offered_rate": sent / span_pub, "received_rate": in_file / span_rec if span_rec > 0 else 0.0,
            "in_file": in_file, "publish_failed": failed, "lost": sent - in_file, "loss_fraction": (sent - in_file) / sent,
            "middleware_lost_events": rec_out["lost_events"], "write_failures": rec_out["write_failures"],
            "recorder_cpu_us_per_msg": rec_out["cpu"] / max(in_file, 1) * 1e6,
            "publisher_cpu_us_per_msg": sum(p["cpu"] for p in pub_out) / sent * 1e6, "load_avg_1min": load,
            "nice": nice}


def median_row(rows: list[dict]) -> dict:
    out = dict(rows[0])
    for k, v in rows[0].items():
        if isinstance(v, float) and k != "target_rate":
            out[k] = float(np.median([r[k] for r in rows]))
    for k in ("lost", "publish_failed"):
        out[k] = int(np.median([r[k] for r in rows]))
    out["lost_max"] = max(r["lost"] for r in rows)
    out["repeats"] = len(rows)
    out["zero_loss_runs"] = sum(r["lost"] == 0 for r in rows)
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer messages and rates (smoke run)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--publishers", type=int, default=2, help="publisher processes sharing the offered rate")
    ap.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=CONFIGS)
    ap.add_argument("--rates", nargs="+", type=float, default=None)
    ap.add_argument("--seconds", type=float, default=None, help="publishing time per run")
    ap.add_argument("--nice", type=int, default=0,
                    help="run publishers and recorder at this nice value (e.g. -10: a larger CPU share on a "
                         "shared machine); results then go to recorder_throughput_nice*")
    ap.add_argument("--max-rate-single", type=float, default=20000.0,
                    help="highest rate tried on single_sync (it is saturated well below; runs above are slow)")
    args = ap.parse_args()
    n_writer = 20000 if args.quick else 100000
    seconds = args.seconds or (2.0 if args.quick else 4.0)
    rates = args.rates or ([10000.0, 20000.0] if args.quick else [5000.0, 10000.0, 20000.0, 30000.0])
    rows = [writer_only(n_writer, args.repeats)]
    print(rows[-1], flush=True)
    try:
        from tqdm import tqdm
    except ImportError:  # progress is a nicety
        tqdm = None
    plan = [(c, r) for c in args.configs for r in rates if c != "single_sync" or r <= args.max_rate_single]
    bar = tqdm(total=len(plan) * args.repeats, desc="from DDS") if tqdm else None
    for config, rate in plan:
        runs = []
        for _ in range(args.repeats):
            with lease_domain() as lease:   # a private domain per run (softcath_ros.graph)
                runs.append(from_dds(int(rate * seconds), rate, config, args.publishers, lease.domain, args.nice))
            if bar:
                bar.update()
        rows.append(median_row(runs))
        print({k: rows[-1][k] for k in ("config", "target_rate", "offered_rate", "received_rate", "lost",
                                        "lost_max", "recorder_cpu_us_per_msg", "publisher_cpu_us_per_msg")},
              flush=True)
    if bar:
        bar.close()
    keys = list(dict.fromkeys(k for r in rows for k in r))
    rows = [{k: r.get(k, "") for k in keys} for r in rows]
    name = "recorder_throughput" + (f"_nice{args.nice}" if args.nice else "")
    write_results(name, {
        "note": "2 cores shared with other engineers' jobs (numbers under load; see load_avg_1min per row); "
                "from_dds rows are medians over repeats",
        "quick": args.quick, "repeats": args.repeats, "publishers": args.publishers, "seconds_per_run": seconds,
        "nice": args.nice},
        rows)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for config in args.configs:
        dds = [r for r in rows if r["case"] == "from_dds" and r["config"] == config]
        ax1.plot([r["offered_rate"] for r in dds], [r["received_rate"] for r in dds], "o-", label=config)
        ax2.plot([r["offered_rate"] for r in dds], [100 * r["loss_fraction"] for r in dds], "o-", label=config)
    hi = max([r["offered_rate"] for r in rows if r["case"] == "from_dds"] + [1.0])
    ax1.plot([0, hi], [0, hi], "k:", lw=0.8, label="received = offered")
    ax1.axhline(20000, color="r", ls="--", lw=0.8, label="target 20k msg/s")
    ax1.set_xlabel("offered rate [msg/s]")
    ax1.set_ylabel("received rate [msg/s]")
    ax2.set_xlabel("offered rate [msg/s]")
    ax2.set_ylabel("lost [% of sent] (median)")
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("recorder: Float64 from DDS into MCAP (2 shared cores, under load"
                 + (f", processes at nice {args.nice})" if args.nice else ")"))
    fig.tight_layout()
    save_figure(fig, name, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
