"""`softcath import FILE.csv`: tabular bench data into a bench recording (columns: bench/importer.py)."""
from __future__ import annotations

import json
import sys
from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("import", help="turn a CSV of bench readings into a bench recording (then report, calibrate)")
    p.add_argument("file", help="CSV file, one reading per row (docs/bench.md, 'Imported data')")
    p.add_argument("--design", default="implemented_5mm", help="design the samples are of (name or path)")
    p.add_argument("--name", default=None, help="recording name (default bench_imported_<file stem>)")
    p.add_argument("--output-dir", default="runs", help="where the recording directory goes (default runs/)")
    p.add_argument("--model", nargs="+", default=["closed_form"], help="rung(s) overlaid in the report")
    p.add_argument("--no-report", action="store_true", help="write the recording only")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..bench.importer import import_csv
    from ..bench.report import write_report
    from ..core.design import load_design

    design = load_design(args.design)
    result = import_csv(args.file, design, Path(args.output_dir).resolve(), args.name)
    report = None if args.no_report else write_report(result["recording"], design, args.model)
    out = {"recording": result["recording"], "readings": result["readings"], "steps": result["steps"],
           "report": report and report["report"], "plots": report["plots"] if report else []}
    if args.json:
        json.dump(out, sys.stdout, indent=2)
        print()
    else:
        print(f"[import] {out['readings']} readings in {out['steps']} steps")
        print(f"recording: {out['recording']}")
        if report:
            print(f"report:    {out['report']}")
    return 0
