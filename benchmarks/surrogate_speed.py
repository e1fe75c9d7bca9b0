"""Surrogate rung throughput and its measured error against its source, for both shipped designs.

Target (issue 6): >= 1e6 evaluations per second batched. Commands are drawn inside the table's
range the way the allocator sends them (1 channel: 0..range; 3 channels: one channel at zero,
the other two uniform); the fraction the surrogate answered is recorded. Medians over repeats
(the machine is shared and noisy). Builds the tables first if they are not cached (about a
minute for the 3-channel design from the section rung).

    .venv/bin/python benchmarks/surrogate_speed.py [--repeats 7]

Writes benchmarks/results/surrogate_speed.{json,csv,png}.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import RESULTS, median_time, save_figure, write_results  # noqa: E402

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.models import make_model  # noqa: E402


def commands(model, n: int, rng) -> np.ndarray:
    hi = model.pressure_range[1]
    if model.n_channels == 1:
        return rng.uniform(0, hi, (n, 1))
    p = rng.uniform(0, hi, (n, 3))
    p[np.arange(n), rng.integers(0, 3, n)] = 0.0
    return p


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    rows = []
    for name in ("implemented_5mm", "three_channel_5mm"):
        model = make_model("surrogate", load_design(name), progress=True)
        bound = model.error_bound.get("one_channel") or model.error_bound["pair"]
        single = commands(model, 1, rng)[0]
        cases = [("single command (evaluate)", 1, lambda: model.evaluate(single), 5000)]
        for n in (1_000, 100_000, 1_000_000):
            batch = commands(model, n, rng)
            cases.append(("batched", n, (lambda b=batch: model.evaluate(b)), max(1, 300_000 // n)))
        for case, n, fn, calls in cases:
            med = median_time(fn, args.repeats, calls)
            answered = float(np.mean(fn().converged))
            rows.append({"design": name, "case": case, "batch_size": n, "median_s_per_call": med,
                         "evaluations_per_s": n / med, "us_per_evaluation": med / n * 1e6,
                         "answered_fraction": answered, "source": model.settings.source,
                         "range_max_pa": model.pressure_range[1],
                         "error_rc_rel_max": bound["rc_rel_max"], "error_rc_rel_median": bound["rc_rel_median"],
                         "error_direction_deg_max": bound["direction_deg_max"],
                         "held_out_points": bound["points"], "build_seconds": model.meta["build_seconds"]})
            print(f"{name:18s} {case:26s} batch {n:>8d}: {med / n * 1e6:9.4f} us/eval, {n / med:11.3e} eval/s, "
                  f"answered {answered:.3f}")
        print(f"{name}: R_C error vs {model.settings.source} at {bound['points']} held-out commands: "
              f"max {bound['rc_rel_max']:.3%}, median {bound['rc_rel_median']:.3%}")
    write_results("surrogate_speed", {"repeats": args.repeats, "target_evaluations_per_s": 1e6,
                                      "target_rc_rel_error": 0.005}, rows)
    plot(rows, "surrogate_speed")
    print(f"results in {RESULTS}/surrogate_speed.{{json,csv,png}}")


def plot(rows, name) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for name in dict.fromkeys(r["design"] for r in rows):
        pts = [r for r in rows if r["design"] == name]
        ax.loglog([r["batch_size"] for r in pts], [r["evaluations_per_s"] for r in pts], "o-",
                  label=f"{name} (R_C error max {pts[0]['error_rc_rel_max']:.2%})")
    ax.axhline(1e6, color="k", ls="--", lw=1, label="target 1e6 eval/s (batched)")
    ax.set_xlabel("batch size")
    ax.set_ylabel("evaluations per second")
    ax.set_title("surrogate rung throughput (median of repeats, shared machine)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, name, dpi=120)


if __name__ == "__main__":
    main()
