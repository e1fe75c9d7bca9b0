"""`softcath report [RECORDING]`: per-step statistics, hysteresis, model overlay (Markdown + PNG)."""
from __future__ import annotations

import math
import sys
from pathlib import Path

DEFAULT_RUNS = "runs"   # where `softcath characterise` puts recordings (its --output-dir default)

from ..core import json_output


def register(sub) -> None:
    p = sub.add_parser("report", help="analyse a bench recording: table + plots, model overlaid")
    p.add_argument("file", nargs="*", help="the bench recording (.mcap or its bag directory); several: the newest "
                                           f"(default: the newest under {DEFAULT_RUNS}/)")
    p.add_argument("--design", default=None, help="design to overlay (default: the one attached to the recording)")
    add_overlay_arguments(p)
    p.add_argument("--calibration", default=None,
                   help="calibration file from `softcath calibrate`: each rung is overlaid calibrated too, with its band")
    p.add_argument("--out", default=None, help="output directory (default: beside the recording)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def add_overlay_arguments(p, note: str = "") -> None:
    """``--model`` (the rungs a report overlays) and ``--no-cache``: one default for every command that
    writes a report (report, import, characterise)."""
    from ..bench.report import DEFAULT_OVERLAY
    from ..core.models import available_models

    p.add_argument("--model", nargs="+", default=list(DEFAULT_OVERLAY),
                   help=f"rung(s) overlaid in the report{note} (default: {' '.join(DEFAULT_OVERLAY)}, the section "
                        f"rung's table and the fast, rough closed form): {', '.join(available_models())}")
    p.add_argument("--no-cache", action="store_true", help="the report's rungs do not read their cache")


def pick_recording(paths: list[str], command: str) -> Path:
    """The recording a command works on: the one given, the newest of several (a shell glob such as
    ``runs/bench_default_*/``), or the newest bench recording under runs/. Says which on stderr."""
    from ..core.errors import SoftcathError

    if not paths:
        root = Path(DEFAULT_RUNS)
        candidates = [d for d in root.glob("*/") if any(d.glob("*.mcap"))] if root.is_dir() else []
        if not candidates:
            raise SoftcathError(f"no recording given and none under {root}/: pass RECORDING "
                                "(run `softcath characterise` to make one)")
    else:
        candidates = [Path(p) for p in paths]
        missing = [str(p) for p in candidates if not p.exists()]
        if missing:
            raise SoftcathError(f"{missing[0]}: no such recording")
        if len(candidates) == 1:
            return candidates[0]
        # a folder without a recording (logs of runs made before they moved to runs/logs/) is no candidate
        candidates = [p for p in candidates if p.is_file() or any(p.glob("*.mcap"))]
        if not candidates:
            raise SoftcathError(f"none of the {len(paths)} paths given holds a recording (.mcap)")
    newest = max(candidates, key=lambda p: p.stat().st_mtime)
    print(f"softcath {command}: using the newest of {len(candidates)} recording(s): {newest}", file=sys.stderr)
    return newest


def stats_json(stats) -> list[dict]:
    def clean(x):
        return None if isinstance(x, float) and not math.isfinite(x) else x

    return [{"bench": s.bench, "drive": s.drive, "phase": s.phase, "level": s.level, "n": s.n,
             "pressure_mean_pa": s.pressure_mean.tolist(), "pressure_std_pa": s.pressure_std.tolist(),
             "curvature_mean_per_m": clean(s.curvature_mean), "curvature_std_per_m": clean(s.curvature_std),
             "radius_of_curvature_mean_m": clean(s.radius_mean), "radius_of_curvature_std_m": clean(s.radius_std),
             "force_mean_n": clean(s.force_mean), "force_std_n": clean(s.force_std), "unsettled": s.unsettled,
             "model": {k: {q: clean(v) for q, v in d.items()} for k, d in s.model.items()}} for s in stats]


def run(args) -> int:
    from ..bench.report import write_report
    from ..core.calibration_file import load_calibration
    from ..core.design import load_design

    design = load_design(args.design) if args.design else None
    calibration = load_calibration(args.calibration) if args.calibration else None
    result = write_report(pick_recording(args.file, "report"), design, args.model, calibration, args.out,
                          cache=not args.no_cache)
    if args.json:
        json_output.dump({"report": result["report"], "plots": result["plots"], "steps": stats_json(result["stats"]),
                   "hysteresis": [h.__dict__ for h in result["hysteresis"]]}, sys.stdout, indent=2, default=float)
        print()
    else:
        print(f"report: {result['report']}")
        for p in result["plots"]:
            print(f"plot:   {p}")
    return 0
