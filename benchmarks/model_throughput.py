"""Closed-form rung throughput: single calls and batches.

Targets (issue 2): >= 1e6 evaluations per second batched, <= 20 us per single call.
Each figure is the median over repeated runs (the machine is shared and noisy).

    .venv/bin/python benchmarks/model_throughput.py [--model closed_form] [--design implemented_5mm]

Writes benchmarks/results/model_throughput.{json,csv,png}.
"""
from __future__ import annotations

import argparse
import statistics

import numpy as np
from harness import RESULTS, save_figure, time_loops, write_results

from softcath_ros.core.design import load_design
from softcath_ros.core.kinematics import tip_pose, tip_pose_single
from softcath_ros.core.models import make_model
from softcath_ros.core.prediction import arc_and_cap


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="closed_form")
    ap.add_argument("--design", default="implemented_5mm")
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()

    design = load_design(args.design)
    model = make_model(args.model, design)
    arc, cap = arc_and_cap(model, design.length)
    rng = np.random.default_rng(0)
    p1 = rng.uniform(0, design.max_pressure, design.n_channels)
    rows = []

    def record(case, batch, seconds_per_call):
        med = statistics.median(seconds_per_call)
        rows.append({"case": case, "batch_size": batch, "median_s_per_call": med,
                     "evaluations_per_s": batch / med,
                     "us_per_evaluation": med / batch * 1e6,
                     "min_s_per_call": min(seconds_per_call), "max_s_per_call": max(seconds_per_call)})
        print(f"{case:38s} batch {batch:>8d}: {med / batch * 1e6:9.3f} us/eval, "
              f"{batch / med:12.3e} eval/s")

    record("evaluate (single, BendState)", 1, time_loops(lambda: model.evaluate(p1), args.repeats, 20000))
    if model.info.linear_gain:
        record("curvature_single (fast path)", 1,
               time_loops(lambda: model.curvature_single(p1), args.repeats, 20000))
    record("evaluate + tip_pose (single)", 1,
           time_loops(lambda: tip_pose(model.evaluate(p1).curvature, arc, cap), args.repeats, 5000))
    if model.info.linear_gain:
        def fast_pose():
            k, stretch = model.curvature_single(p1)
            return tip_pose_single(k[0], k[1], arc * stretch, cap)
        record("curvature_single + tip_pose_single", 1, time_loops(fast_pose, args.repeats, 20000))
    for n in (1_000, 100_000, 1_000_000):
        batch = rng.uniform(0, design.max_pressure, (n, design.n_channels))
        calls = max(1, 200_000 // n)
        record("evaluate (batched)", n, time_loops(lambda: model.evaluate(batch), args.repeats, calls))
        record("evaluate + tip_pose (batched)", n, time_loops(
            lambda: tip_pose(model.evaluate(batch).curvature, design.length), args.repeats, calls))

    stem = write_results("model_throughput", {"model": args.model, "design": args.design,
                                              "repeats": args.repeats}, rows)
    plot(rows, stem.name, args.model)
    print(f"results in {RESULTS}/model_throughput.{{json,csv,png}}")


def plot(rows, name, model_name):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for case in dict.fromkeys(r["case"] for r in rows if r["batch_size"] > 1):
        pts = [r for r in rows if r["case"] == case]
        ax.loglog([r["batch_size"] for r in pts], [r["evaluations_per_s"] for r in pts], "o-", label=case)
    for r in rows:
        if r["batch_size"] == 1:
            ax.scatter([1], [r["evaluations_per_s"]], label=f"{r['case']}: {r['us_per_evaluation']:.1f} us")
    ax.axhline(1e6, color="k", ls="--", lw=1, label="target 1e6 eval/s (batched)")
    ax.axhline(5e4, color="grey", ls=":", lw=1, label="target 20 us (single call)")
    ax.set_xlabel("batch size")
    ax.set_ylabel("evaluations per second")
    ax.set_title(f"{model_name} rung throughput (median of repeats)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, name, dpi=120)


if __name__ == "__main__":
    main()
