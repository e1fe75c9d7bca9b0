"""`softcath report FILE.mcap`: per-step statistics, hysteresis, model overlay (Markdown + PNG)."""
from __future__ import annotations

import math
import sys

from ..core import json_output


def register(sub) -> None:
    from ..core.models import available_models

    p = sub.add_parser("report", help="analyse a bench recording: table + plots, model overlaid")
    p.add_argument("file", help="the bench recording (.mcap or its bag directory)")
    p.add_argument("--design", default=None, help="design to overlay (default: the one attached to the recording)")
    p.add_argument("--model", nargs="+", default=["closed_form"],
                   help=f"rung(s) to overlay: {', '.join(available_models())}")
    p.add_argument("--calibration", default=None, help="calibration YAML from `softcath calibrate` to overlay")
    p.add_argument("--out", default=None, help="output directory (default: beside the recording)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def stats_json(stats) -> list[dict]:
    def clean(x):
        return None if isinstance(x, float) and not math.isfinite(x) else x

    return [{"bench": s.bench, "drive": s.drive, "phase": s.phase, "level": s.level, "n": s.n,
             "pressure_mean_pa": s.pressure_mean.tolist(), "pressure_std_pa": s.pressure_std.tolist(),
             "curvature_mean_per_m": clean(s.curvature_mean), "curvature_std_per_m": clean(s.curvature_std),
             "radius_mean_m": clean(s.radius_mean), "radius_std_m": clean(s.radius_std),
             "force_mean_n": clean(s.force_mean), "force_std_n": clean(s.force_std), "unsettled": s.unsettled,
             "model": {k: {q: clean(v) for q, v in d.items()} for k, d in s.model.items()}} for s in stats]


def run(args) -> int:
    from ..bench.calibration import load_calibration
    from ..bench.report import write_report
    from ..core.design import load_design

    design = load_design(args.design) if args.design else None
    calibration = load_calibration(args.calibration) if args.calibration else None
    result = write_report(args.file, design, args.model, calibration, args.out)
    if args.json:
        json_output.dump({"report": result["report"], "plots": result["plots"], "steps": stats_json(result["stats"]),
                   "hysteresis": [h.__dict__ for h in result["hysteresis"]]}, sys.stdout, indent=2, default=float)
        print()
    else:
        print(f"report: {result['report']}")
        for p in result["plots"]:
            print(f"plot:   {p}")
    return 0
