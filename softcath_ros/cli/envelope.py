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
                        "direction's mirror plane, the full body off them; hours on the fan design at 40 mm, "
                        "whose 20 mm cases read the committed sweeps); without it, "
                        "only cases measured before (in the cache) get fe3d")
    p.add_argument("--refresh", nargs="*", default=None, metavar="RUNG",
                   help="recompute cached results of these rungs (no names: all)")
    p.add_argument("--no-cache", action="store_true", help="recompute every cached result (= --refresh, all rungs)")
    p.add_argument("--cases", nargs="+", default=None, metavar="CASE",
                   help=f"a subset of: {', '.join(repr(c.name) for c in CASES)}")
    p.add_argument("--keep", default=None, metavar="RESULTS.json",
                   help="the rows of the cases not run now from results written before (STEM.json of --results): "
                        "the envelope and the rows cover both, each case as it was measured (with --cases: "
                        "re-measure some cases, keep the others' fe3d hours)")
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
    kept, kept_meta = kept_rows(args.keep, known_cases, {c.name for c in cases}) if args.keep else ({}, {})
    settings = [known_settings[s] for s in args.settings] if args.settings else SETTINGS
    refresh = ("all",) if args.no_cache else () if args.refresh is None else tuple(args.refresh or ["all"])
    load_before = os.getloadavg()
    rows, references = [], {}
    for case in CASES:   # the rows in the ladder's order, whether measured now or kept
        if case.name in kept:
            rows += kept[case.name]
            references[case.name] = kept_meta["references"].get(case.name, "")
            print(f"case {case.name}: kept from {args.keep} (measured {kept_meta['measured'][case.name]['date']})")
            continue
        if case not in cases:
            continue
        print(f"case {case.name} ({case.design}, {case.length * 1e3:g} mm, direction {case.direction}):", flush=True)
        case_rows, references[case.name] = run_case(case, settings, fe3d=not args.no_fe3d,
                                                    fe3d_three_channel=args.fe3d_three_channel, refresh=refresh)
        print(f"  reference: {references[case.name]}")
        rows += case_rows
    done = [c for c in CASES if c in cases or c.name in kept]
    write_envelope(rows, out)
    report(rows)
    if args.results:
        stem = Path(args.results)
        now = {k: v for k, v in machine_meta(load_before).items() if k in ("git_commit", "date")}
        meta = {"cases": [dataclasses.asdict(c) for c in done], "references": references,
                "settings": [s[0] for s in settings],   # of the cases measured now
                "note": "R_C = l / theta. Reference per point (column reference): fe3d where it converged, "
                        "else section D/20 (lumen contact); 3-channel cases: fe3d with --fe3d-three-channel "
                        "(half body on a mirror plane) or where cached; a case naming a committed fe3d sweep "
                        "(fe3d_sweep): that sweep's points as fe3d (no tip recorded)", **machine_meta(load_before),
                # per case the commit and date it was measured at (a kept case: as its file recorded it)
                "measured": {c.name: kept_meta["measured"][c.name] if c.name in kept else now for c in done},
                **({"kept": {"from": Path(args.keep).name, "cases": list(kept)}} if kept else {})}
        stem.with_suffix(".json").write_text(json_output.dumps({"meta": meta, "results": rows}, indent=2))
        with open(stem.with_suffix(".csv"), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        print(f"wrote {stem}.{{csv,json}}")
    print(f"wrote {out}" + ("" if len(done) == len(CASES) else " (from a subset of the cases)"))
    return 0


def kept_rows(path: str, known_cases: dict, running: set) -> tuple[dict, dict]:
    """``--keep``: per case not run now, its rows from a results file written before (in its order),
    and from that file's meta its reference and when it was measured (the file's ``measured`` entry,
    else the file's commit and date); a case of the file no longer in the ladder is refused."""
    import json

    p = Path(path)
    try:
        doc = json.loads(p.read_text())
        rows, meta = doc["results"], doc["meta"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SoftcathError(f"--keep {path}: not results written by --results ({type(exc).__name__}: {exc})") from None
    unknown = sorted({r.get("case") for r in rows} - set(known_cases), key=str)
    if unknown:
        raise SoftcathError(f"--keep {path}: case(s) {unknown} are not ladder cases; known: {list(known_cases)}")
    kept = {}
    for r in rows:
        if r["case"] not in running:
            kept.setdefault(r["case"], []).append(r)
    written = {"git_commit": meta.get("git_commit", "?"), "date": meta.get("date", "?")}
    return kept, {"references": meta.get("references", {}),
                  "measured": {c: (meta.get("measured") or {}).get(c, written) for c in kept}}
