"""Several pressures of a ramped rung in one batch (one ramp through them) against one command at
a time (a ramp from 0 for each, what a batch of the rod with its tip on the scale cost before it
shared one ramp).

- rod, the blocking-force bench (scene blocking_force_bench: 17 mm, tip on the scale, gravity),
  28 pressures 0.0125..0.35 bar: ``evaluate`` of the batch vs each command alone.
- section (D/20, implemented_5mm at 40 mm), 7 pressures 0.05..0.35 bar: the batch in increasing
  order vs shuffled (solved per ray by increasing pressure: the same ramp) vs each alone (a fresh
  model per command, no states to start from).
Per variant the median wall time over repeats and the largest relative difference of its answers
(contact force for the rod, R_C = l / theta for the section) from the increasing batch's.

    .venv/bin/python benchmarks/batch_ramp.py [--repeats 3]

Writes benchmarks/results/batch_ramp.{json,csv}.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from harness import write_results
from softcath_ros.core.design import load_design
from softcath_ros.core.models import make_model
from softcath_ros.core.prediction import angle_per_length
from softcath_ros.core.scene import load_scene
from softcath_ros.core.units import PA_PER_BAR


def timed(fn, repeats):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def largest_difference(a, b):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    both = np.isfinite(a) & np.isfinite(b)
    if not np.array_equal(np.isfinite(a), np.isfinite(b)):
        return float("inf")       # one answered where the other did not
    return float(np.max(np.abs(a[both] / b[both] - 1.0))) if both.any() else 0.0


def rod_rows(repeats):
    scene = load_scene("blocking_force_bench")
    design = scene.design                 # at the scene's length, 17 mm
    rod = make_model("rod", design, loads=scene.loads)
    p = (np.arange(1, 29) * 0.0125 * PA_PER_BAR)[:, None]
    t_batch, batch = timed(lambda: rod.evaluate(p), repeats)
    t_each, each = timed(lambda: [rod.evaluate(row) for row in p], repeats)
    ref = batch.contact_force
    return [
        {"rung": "rod", "case": "blocking_force_bench 17 mm", "commands": len(p), "variant": "batch, increasing",
         "wall_s": t_batch, "converged": int(batch.converged.sum()), "max_rel_difference": 0.0},
        {"rung": "rod", "case": "blocking_force_bench 17 mm", "commands": len(p), "variant": "one command at a time",
         "wall_s": t_each, "converged": int(sum(bool(s.converged) for s in each)),
         "max_rel_difference": largest_difference([float(s.contact_force) for s in each], ref)}]


def section_rows(repeats):
    design = load_design("implemented_5mm")
    p = (np.arange(1, 8) * 0.05 * PA_PER_BAR)[:, None]
    shuffled = np.array([6, 0, 5, 1, 4, 2, 3])

    def rc(state):
        per_length = angle_per_length(state, make_model("closed_form", design))   # theta / l, the cap straight
        return np.where(np.asarray(state.converged).reshape(-1), 1.0 / per_length, np.nan)

    t_batch, batch = timed(lambda: make_model("section", design).evaluate(p), repeats)
    t_mixed, mixed = timed(lambda: make_model("section", design).evaluate(p[shuffled]), repeats)
    t_each, each = timed(lambda: [make_model("section", design).evaluate(row) for row in p], repeats)
    ref = rc(batch)
    out_of_order = np.empty(len(p))
    out_of_order[shuffled] = rc(mixed)
    rows = [("batch, increasing", t_batch, batch.converged, ref),
            ("batch, shuffled (solved per ray by increasing pressure)", t_mixed, mixed.converged, out_of_order),
            ("one command at a time (fresh model)", t_each, [s.converged for s in each],
             np.concatenate([rc(s) for s in each]))]
    return [{"rung": "section", "case": "implemented_5mm 40 mm D/20", "commands": len(p), "variant": v,
             "wall_s": t, "converged": int(np.sum(c)), "max_rel_difference": largest_difference(r, ref)}
            for v, t, c, r in rows]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    rows = rod_rows(args.repeats) + section_rows(args.repeats)
    for r in rows:
        print(f"{r['rung']:8s} {r['variant']:58s} {r['wall_s']:7.2f} s  {r['converged']}/{r['commands']} converged  "
              f"max rel. difference {r['max_rel_difference']:.1e}")
    write_results("batch_ramp", {"repeats": args.repeats, "load_average_after": list(os.getloadavg()),
                                 "note": "wall_s: median over repeats on a shared 2-core machine"}, rows)


if __name__ == "__main__":
    main()
