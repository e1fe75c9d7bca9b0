"""Time of one pressure allocation (softcath_ros.core.allocation.Allocator).

Target (issue 4): one allocation <= 100 us with the fast rungs. Every call is timed on
its own (perf_counter_ns); the table gives the median and the 99th percentile over
many calls with random requests (directions over the full circle, magnitudes inside
the reachable set, or beyond it for the saturated cases).

Cases: the linear fast path (closed_form: exact 2 x 2 inverse in floats), the same
rung seen only through ``evaluate`` (the generic Newton path every non-linear rung
takes, so its overhead is visible apart from the rung's own cost), and any further
rungs named with --model (they take the Newton path with their real cost).

    .venv/bin/python benchmarks/allocation_speed.py [--design three_channel_5mm] [--calls 20000]
        [--model section --rung-calls 8 --rung-max-pressure 0.3bar]   (the committed results)

Writes benchmarks/results/allocation_speed.{json,csv,png}.
"""
from __future__ import annotations

import argparse
import math
import numpy as np
from tqdm import tqdm

from softcath_ros.core.allocation import Allocator
from softcath_ros.core.design import load_design
from softcath_ros.core.models import make_model
from softcath_ros.core.models.base import BendModel

from harness import RESULTS, pressure_option, save_figure, time_each, write_results  # noqa: E402  (benchmarks/ is the script's directory)

TARGET_US = 100.0


class EvaluateOnly(BendModel):
    """A rung seen only through ``evaluate``: declares no linear gain, so the allocator takes
    its generic Newton path (what every non-linear rung gets)."""

    def __init__(self, model: BendModel):
        super().__init__(model.design)
        self._inner = model
        self.name = f"{model.name} via evaluate"

    def _evaluate_batch(self, pressures):
        return self._inner._evaluate_batch(pressures)


def time_calls(fn, requests, label) -> np.ndarray:
    """Seconds of each call ``fn(request)``, with a progress bar."""
    return time_each(fn, tqdm(requests, desc=label, leave=False, mininterval=0.5))


def requests_for(allocator: Allocator, n: int, rng, saturated: bool) -> list[np.ndarray]:
    phis = rng.uniform(0, 2 * math.pi, n)
    kmax = np.array([allocator.max_curvature(p) for p in phis])
    f = rng.uniform(1.2, 3.0, n) if saturated else rng.uniform(0.01, 1.0, n)
    return [f[i] * kmax[i] * np.array([math.cos(phis[i]), math.sin(phis[i])]) for i in range(n)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--design", default="three_channel_5mm")
    ap.add_argument("--calls", type=int, default=20000, help="calls per fast case (slower cases use fewer)")
    ap.add_argument("--model", nargs="*", default=[], help="further rungs to time on the Newton path")
    ap.add_argument("--rung-calls", type=int, default=10, help="calls per further rung")
    ap.add_argument("--rung-max-pressure", type=pressure_option("--rung-max-pressure"), default=None,
                    help="with its unit: allocator limit for the further rungs (inside their convergence range)")
    args = ap.parse_args()

    design = load_design(args.design)
    rng = np.random.default_rng(0)
    rows = []

    def record(case, model_name, path, seconds):
        us = seconds * 1e6
        row = {"case": case, "model": model_name, "path": path, "calls": len(us),
               "median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
               "mean_us": float(us.mean()), "max_us": float(us.max()),
               "meets_100us_target": bool(np.median(us) <= TARGET_US)}
        rows.append(row)
        print(f"{case:44s} {model_name:28s} median {row['median_us']:9.2f} us  p99 {row['p99_us']:9.2f} us"
              f"  ({len(us)} calls)")

    try:
        cf = make_model("closed_form", design)
        fast = Allocator(cf)
        n = args.calls
        record("allocate (inside reach)", "closed_form", "linear", time_calls(
            fast.allocate, requests_for(fast, n, rng, False), "fast inside"))
        record("allocate (saturated)", "closed_form", "linear", time_calls(
            fast.allocate, requests_for(fast, n, rng, True), "fast saturated"))
        bends = [(rng.uniform(0, 2 * math.pi), rng.uniform(0, 0.3)) for _ in range(n)]
        record("allocate_bend (direction + angle)", "closed_form", "linear",
               time_calls(lambda r: fast.allocate_bend(*r), bends, "fast bend"))
        tips = []
        for r in requests_for(fast, n // 4, rng, False):
            tips.append(np.array([*(r * design.length ** 2 / 2), design.length * 0.98]))
        record("allocate_tip (tip point)", "closed_form", "linear",
               time_calls(fast.allocate_tip, tips, "fast tip"))

        generic = Allocator(EvaluateOnly(cf))
        m = max(n // 10, 200)
        record("allocate (inside reach)", "closed_form via evaluate", "newton", time_calls(
            generic.allocate, requests_for(fast, m, rng, False), "newton inside"))
        record("allocate (saturated)", "closed_form via evaluate", "newton", time_calls(
            generic.allocate, requests_for(fast, m // 4, rng, True), "newton saturated"))

        for name in args.model:
            alloc = Allocator(make_model(name, design), max_pressure=args.rung_max_pressure)
            # Requests inside the smallest single-channel reach: no boundary solves just to pick them.
            kmin = float(alloc.channel_max_curvature.min())
            reqs = [rng.uniform(0.05, 0.8) * kmin * np.array([math.cos(a), math.sin(a)])
                    for a in rng.uniform(0, 2 * math.pi, args.rung_calls)]
            record("allocate (inside reach)", name, "linear" if alloc.linear else "newton",
                   time_calls(alloc.allocate, reqs, name))
    except KeyboardInterrupt:
        print("interrupted: writing the cases timed so far")

    meta = {"design": args.design, "calls": args.calls, "target_median_us": TARGET_US,
            "note": "shared 2-core machine, other jobs running: medians, not minima"}
    write_results("allocation_speed", meta, rows)
    plot(rows, "allocation_speed", design.name)
    print(f"results in {RESULTS}/allocation_speed.{{json,csv,png}}")


def plot(rows, name, design_name):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    labels = [f"{r['case']}\n{r['model']}" for r in rows]
    y = np.arange(len(rows))
    med = [r["median_us"] for r in rows]
    p99 = [r["p99_us"] for r in rows]
    colors = ["tab:blue" if r["path"] == "linear" else "tab:orange" for r in rows]
    ax.barh(y, med, color=colors)
    ax.scatter(p99, y, marker="|", s=200, color="k", label="99th percentile")
    ax.axvline(TARGET_US, color="r", ls="--", lw=1, label="target: 100 us (fast rungs)")
    ax.set_xscale("log")
    ax.set_yticks(y, labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("time per allocation, us (median; blue: linear fast path, orange: Newton path)")
    ax.set_title(f"Pressure allocation, design {design_name}")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    save_figure(fig, name, dpi=120)


if __name__ == "__main__":
    main()
