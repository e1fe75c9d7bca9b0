"""`softcath envelope`: measure the model ladder (every rung on the same cases against a reference
rung; core/ladder.py) and write the envelope that `model: auto` reads, plus the rows that
`softcath chart` draws. Results are cached per rung and case, so a re-run only rewrites."""
from __future__ import annotations

import csv
import dataclasses
import os
from pathlib import Path

from ..core import json_output
from ..core.errors import SoftcathError
from ..provenance import machine_meta


def register(sub) -> None:
    from ..core.ladder import CASES

    p = sub.add_parser("envelope", help="measure the model ladder and write the envelope model selection reads")
    p.add_argument("--out", default="ladder_envelope.yaml",
                   help="envelope YAML to write (default: ./ladder_envelope.yaml; the shipped one is "
                        "config/ladder_envelope.yaml)")
    p.add_argument("--results", default=None, metavar="STEM",
                   help="also write the rows as STEM.csv (what `softcath chart` draws) and STEM.json (with metadata)")
    p.add_argument("--no-fe3d", action="store_true", help="no fe3d runs: the reference is section D/20 (the section rung with lumen contact)")
    p.add_argument("--fe3d-three-channel", action="store_true",
                   help="run fe3d on the 3-channel cases too (minutes per direction: the half body about the "
                        "direction's mirror plane, the full body off them); without it, "
                        "only cases measured before (in the cache) get fe3d")
    p.add_argument("--refresh", nargs="*", default=None, metavar="RUNG",
                   help="recompute cached results of these rungs (no names: all)")
    p.add_argument("--no-cache", action="store_true", help="recompute every cached result (= --refresh, all rungs)")
    p.add_argument("--cases", nargs="+", default=None, metavar="CASE",
                   help=f"a subset of: {', '.join(repr(c.name) for c in CASES)}")
    p.add_argument("--settings", nargs="+", default=None, metavar="LABEL",
                   help="a subset of the rung settings (labels as in the output); the reference must be among them")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..core.ladder import CASES, SETTINGS, run_case
    from ..core.ladder_envelope import report, write_envelope

    known_cases = {c.name: c for c in CASES}
    unknown = [c for c in (args.cases or []) if c not in known_cases]
    if unknown:
        raise SoftcathError(f"--cases: unknown {unknown}; known: {list(known_cases)}")
    known_settings = {s[0]: s for s in SETTINGS}
    unknown = [s for s in (args.settings or []) if s not in known_settings]
    if unknown:
        raise SoftcathError(f"--settings: unknown {unknown}; known: {list(known_settings)}")
    from ..core.models import RUNGS

    unknown = [r for r in (args.refresh or []) if r not in RUNGS and r != "all"]
    if unknown:
        raise SoftcathError(f"--refresh: unknown rung(s) {unknown}; known: {sorted(RUNGS)}")
    out = Path(args.out)
    if not out.parent.is_dir():
        raise SoftcathError(f"--out {out}: folder {out.parent} does not exist")
    if out.is_dir():
        raise SoftcathError(f"--out {out}: a folder; name the envelope file")
    if args.results and not Path(args.results).parent.is_dir():
        raise SoftcathError(f"--results {args.results}: folder {Path(args.results).parent} does not exist")
    cases = [known_cases[c] for c in args.cases] if args.cases else CASES
    settings = [known_settings[s] for s in args.settings] if args.settings else SETTINGS
    refresh = ("all",) if args.no_cache else () if args.refresh is None else tuple(args.refresh or ["all"])
    load_before = os.getloadavg()
    rows, references = [], {}
    for case in cases:
        print(f"case {case.name} ({case.design}, {case.length * 1e3:g} mm, direction {case.direction}):", flush=True)
        case_rows, references[case.name] = run_case(case, settings, fe3d=not args.no_fe3d,
                                                    fe3d_three_channel=args.fe3d_three_channel, refresh=refresh)
        print(f"  reference: {references[case.name]}")
        rows += case_rows
    write_envelope(rows, out)
    report(rows)
    if args.results:
        stem = Path(args.results)
        meta = {"cases": [dataclasses.asdict(c) for c in cases], "references": references,
                "note": "R_C = l / theta. Reference per point (column reference): fe3d where it converged, "
                        "else section D/20 (lumen contact); 3-channel cases: fe3d with --fe3d-three-channel "
                        "(half body on a mirror plane) or where cached", **machine_meta(load_before)}
        stem.with_suffix(".json").write_text(json_output.dumps({"meta": meta, "results": rows}, indent=2))
        with open(stem.with_suffix(".csv"), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        print(f"wrote {stem}.{{csv,json}}")
    print(f"wrote {out}" + ("" if len(cases) == len(CASES) else " (from a subset of the cases)"))
    return 0
