"""A regulator that goes silent (docs/lab.md): regulator_node on a serial regulator emulated on a
pseudo-terminal (test/hardware_emulators.py, its own process), holding 0.2 bar; the emulated board
stops answering, in ``--runs`` runs. Per run: from the moment it was told to stop until the
node's ERROR on /diagnostics arrived at a listener over DDS (target: 0.5 s), the silence the node
reported, and whether the board was told VENT.

Run:  .venv/bin/python benchmarks/regulator_silence.py [--runs 10]
Writes benchmarks/results/regulator_silence.{json,csv}. The machine is shared (2 cores): the load
average is in the JSON.
"""
from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "test"))
from harness import write_results  # noqa: E402

TARGET_S = 0.5


def one_run() -> dict:
    from diagnostic_msgs.msg import DiagnosticStatus
    from hardware_emulators import SerialRegulatorEmulator
    from lifecycle_listener import LifecycleListener
    from sensor_msgs.msg import FluidPressure
    from std_msgs.msg import Float64MultiArray

    from softcath_ros import topics
    from softcath_ros.graph import NodeGraph

    emu = SerialRegulatorEmulator(1).start()
    ch0 = topics.pressure_measured_topic(0)
    try:
        with NodeGraph() as graph:
            proc = graph.start("regulator_node", {"backend": "serial", "port": emu.port})
            graph.wait_ready(proc)
            listener = LifecycleListener(graph.domain, topics.REGULATOR_NODE, {ch0: FluidPressure})
            pub = listener.node.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, 100)
            error_at = []

            def on_status():
                s = listener.status
                if s is not None and s["level"] == DiagnosticStatus.ERROR and not error_at:
                    error_at.append(time.monotonic())
                return bool(error_at)
            try:
                end = time.monotonic() + 60
                while time.monotonic() < end and not (listener.got[ch0] and listener.got[ch0][-1].fluid_pressure == 20000.0):
                    pub.publish(Float64MultiArray(data=[20000.0]))
                    listener.spin(0.1)
                n = len(emu.lines)
                emu.mode = "dead"
                t0 = time.monotonic()
                end = t0 + 30
                while time.monotonic() < end and not on_status():
                    pub.publish(Float64MultiArray(data=[20000.0]))
                    listener.spin(0.05, until=on_status)
                latency = error_at[0] - t0 if error_at else None
                message = listener.status["message"] if listener.status else ""
                listener.spin(1.0)
                vented = "VENT" in emu.lines[n:]
            finally:
                listener.close()
    finally:
        emu.close()
    m = re.search(r"no valid reading for ([0-9.]+) s", message)
    return {"error_after_s": None if latency is None else round(latency, 3),
            "silence_reported_s": float(m.group(1)) if m else None, "vented": vented,
            "within_target": latency is not None and latency <= TARGET_S}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10)
    args = ap.parse_args(argv)
    rows = []
    for k in range(args.runs):
        row = {"run": k, **one_run()}
        rows.append(row)
        print(row, flush=True)
    ok = all(r["within_target"] and r["vented"] for r in rows)
    meta = {"benchmark": "regulator_silence", "runs": args.runs, "target_s": TARGET_S, "all_targets_met": ok,
            "note": "the emulated board in its own process stops at t0 (its last line up to 20 ms before); "
                    "machine shared with other jobs (2 cores)"}
    stem = write_results("regulator_silence", meta, rows)
    print(f"results: {stem}.json; all targets met: {ok}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
