"""Design-study speed: the full sensitivity study on the section rung, from an empty cache.

Target (issue 7): the full sensitivity study (every parameter and value of
core/studies/sensitivity.py, 24 rows, 19 distinct solves) on the section rung at its default mesh
(D/20) in under 5 minutes on this 2-core machine. Each repeat uses a fresh, empty case cache
and the default executor (one local process per CPU), so the time includes process start-up,
meshing and every solve. The machine's load average is recorded with every time (the cores
are shared). Also times every other study once (from an empty cache) for reference, and a
second sensitivity run on the warm cache (all cases cached: the resume path).

    .venv/bin/python benchmarks/study_speed.py [--design implemented_5mm] [--repeats 3]

Writes benchmarks/results/study_speed.{json,csv}.
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

from harness import write_results
from softcath_ros.core.design import load_design
from softcath_ros.core.studies import STUDIES, study_module
from softcath_ros.core.studies.context import StudyContext
from softcath_ros.core.studies.runner import CaseCache

TARGET_S = 300.0


def timed(name: str, design, cache: CaseCache, workers: int | None) -> dict:
    ctx = StudyContext(cache=cache, workers=workers, progress=False)
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    result = study_module(name).run(design, ctx)
    wall = time.perf_counter() - t0
    return {"study": name, "design": design.name, "rung": ctx.rung, "workers": workers or os.cpu_count(),
            "wall_s": wall, "rows": len(result.rows), "solved": ctx.stats.solved, "cached": ctx.stats.cached,
            "failed": ctx.stats.errors, "load_1min_before": load0[0], "load_1min_after": os.getloadavg()[0]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--design", default="implemented_5mm")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workers", type=int, default=None, help="default: one process per CPU")
    args = ap.parse_args()
    design = load_design(args.design)
    rows = []
    for i in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            cache = CaseCache(tmp)
            r = timed("sensitivity", design, cache, args.workers)
            rows.append({**r, "run": f"cold {i + 1}"})
            print(rows[-1])
            if i == 0:
                rows.append({**timed("sensitivity", design, cache, args.workers), "run": "warm cache"})
                print(rows[-1])
    with tempfile.TemporaryDirectory() as tmp:
        for name in STUDIES:
            if name != "sensitivity":
                rows.append({**timed(name, design, CaseCache(tmp), args.workers), "run": "cold"})
                print(rows[-1])
    cold = [r["wall_s"] for r in rows if r["study"] == "sensitivity" and r["run"].startswith("cold")]
    meta = {"benchmark": "study_speed", "target_s": TARGET_S, "sensitivity_median_s": statistics.median(cold),
            "sensitivity_max_s": max(cold), "meets_target": max(cold) < TARGET_S,
            "note": "cold = empty case cache; wall time includes pool start-up, meshing and every solve"}
    path = write_results("study_speed", meta, rows)
    print(f"sensitivity (cold): median {meta['sensitivity_median_s']:.1f} s, max {max(cold):.1f} s "
          f"(target < {TARGET_S:.0f} s); wrote {path}.json/.csv")


if __name__ == "__main__":
    main()
