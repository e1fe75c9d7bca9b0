"""`softcath import FILE.csv --design D`: tabular bench data into a bench recording (columns:
bench/importer.py); its report overlays the same rungs as `softcath report`."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from .report import add_overlay_arguments


def register(sub) -> None:
    p = sub.add_parser("import", help="turn a CSV of bench readings into a bench recording (then report, calibrate)")
    p.add_argument("file", help="CSV file, one reading per row (docs/bench.md, 'Imported data')")
    p.add_argument("--design", required=True,
                   help="design the samples are of: a shipped design name or a design file (the CSV does not say)")
    p.add_argument("--name", default=None, help="recording name (default bench_imported_<file stem>)")
    p.add_argument("--output-dir", default="runs", help="where the recording directory goes (default runs/)")
    add_overlay_arguments(p)
    p.add_argument("--no-report", action="store_true", help="write the recording only")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..bench.importer import import_csv, recording_name
    from ..bench.report import write_report
    from ..core.design import load_design
    from ..core.errors import SoftcathError
    from .common import check_rung_names

    design = load_design(args.design)
    check_rung_names(args.model)
    out_dir = Path(args.output_dir).resolve()
    target = out_dir / recording_name(args.file, args.name)
    if target.exists():   # recordings are never overwritten
        raise SoftcathError(f"recording {target} already exists: give this import another --name (or move that "
                            "recording away)")
    result = import_csv(args.file, design, out_dir, args.name)
    report = None if args.no_report else write_report(result["recording"], design, args.model,
                                                      cache=not args.no_cache)
    out = {"recording": result["recording"], "design": design.name, "readings": result["readings"],
           "steps": result["steps"], "report": report and report["report"], "models": list(args.model),
           "plots": report["plots"] if report else []}
    if args.json:
        json.dump(out, sys.stdout, indent=2)
        print()
    else:
        print(f"[import] {out['readings']} readings in {out['steps']} steps, design {design.name}")
        print(f"recording: {out['recording']}")
        if report:
            print(f"report:    {out['report']} (overlaid: {', '.join(args.model)})")
    return 0
