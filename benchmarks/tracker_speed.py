"""Frames per second of the camera tracker (softcath_ros.bench.tracker) at 1280x720 on one core.

Frames rendered with known truth (bench/tracker_render: our body at 0-180 deg on plain and graph
paper, uneven light, blur, noise) are measured in memory, as tracker_node measures a camera's
decoded frames; OpenCV runs on one thread and the process is pinned to one CPU. Per frame: wall
time and CPU time of this process; the accuracy against the truth is recorded beside (target issue
37: >= 30 frames/s, angle within 1 deg, tip within 0.3 mm).

    .venv/bin/python benchmarks/tracker_speed.py                 # 10 angles x 2 backgrounds x 20 repeats

Writes benchmarks/results/tracker_speed.{csv,json} (harness.write_results).
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from harness import summary, write_results  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description="camera tracker frames/s at 1280x720 on one core")
    ap.add_argument("--repeats", type=int, default=20, help="times each frame is measured")
    ap.add_argument("--angles", type=int, default=10, help="bend angles from 0 to 180 deg")
    args = ap.parse_args()

    import cv2

    from softcath_ros.bench.tracker import Tracker
    from softcath_ros.bench.tracker_scene import Scene
    from softcath_ros.bench.tracker_render import SceneLook, render
    from softcath_ros.core.design import load_design

    cv2.setNumThreads(1)
    cpu = sorted(os.sched_getaffinity(0))[0]
    os.sched_setaffinity(0, {cpu})
    design = load_design("implemented_5mm")
    rows, wall, cpu_time = [], [], []
    for background in ("plain", "graph"):
        look = SceneLook(background=background, base_px=(500.0, 560.0), noise=6.0, blur_px=1.5, light=0.4)
        scene = Scene(mm_per_px=look.mm_per_px, base_px=look.base_px, toward_px=(500.0, 100.0),
                      length_m=design.length, cap_mm=design.cap_thickness * 1e3)
        tracker = Tracker(scene)
        for deg in np.linspace(0.0, 180.0, args.angles):
            frame, truth = render(math.radians(deg), design.length, design.outer_diameter, design.cap_thickness,
                                  SceneLook(**{**look.__dict__, "seed": int(deg)}))
            tracker.measure(frame)                      # warm (the first frame also finds width and contrast)
            w, c = [], []
            for _ in range(args.repeats):
                t0, p0 = time.perf_counter(), time.process_time()
                m = tracker.measure(frame)
                w.append(time.perf_counter() - t0)
                c.append(time.process_time() - p0)
            wall += w
            cpu_time += c
            rows.append({"background": background, "angle_deg": round(float(deg), 2), "ok": m.ok,
                         "angle_error_deg": m.bend_angle_deg - truth["bend_angle_deg"] if m.ok else None,
                         "tip_error_mm": math.dist(m.tip_mm, truth["tip_mm"]) if m.ok else None,
                         "median_ms": float(np.median(w)) * 1e3, "cpu_median_ms": float(np.median(c)) * 1e3})
            print(f"{background:5s} {deg:6.1f} deg: {rows[-1]['median_ms']:6.2f} ms, angle error "
                  f"{rows[-1]['angle_error_deg']:+.3f} deg, tip error {rows[-1]['tip_error_mm']:.3f} mm", flush=True)
    s = summary(wall)
    meta = {"frame_size": [1280, 720], "threads": 1, "cpu": cpu, "repeats": args.repeats,
            "frames_per_s_median": 1.0 / s["median_s"], "frames_per_s_p99": 1.0 / s["p99_s"],
            "wall": s, "cpu_median_s": float(np.median(cpu_time)),
            "worst_angle_error_deg": max(abs(r["angle_error_deg"]) for r in rows if r["ok"]),
            "worst_tip_error_mm": max(r["tip_error_mm"] for r in rows if r["ok"]),
            "all_measured": all(r["ok"] for r in rows),
            "command": "benchmarks/tracker_speed.py " + " ".join(sys.argv[1:])}
    stem = write_results("tracker_speed", meta, rows)
    print(f"{meta['frames_per_s_median']:.0f} frames/s (median {s['median_s'] * 1e3:.2f} ms, p99 "
          f"{s['p99_s'] * 1e3:.2f} ms) on one core; worst angle error {meta['worst_angle_error_deg']:.3f} deg, "
          f"tip {meta['worst_tip_error_mm']:.3f} mm; {stem}.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
