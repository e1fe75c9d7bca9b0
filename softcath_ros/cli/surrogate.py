"""`softcath surrogate build|check DESIGN`: the surrogate rung's table for a design.

``build`` solves the table from its source rung (default section) into the cache, and with
``--out`` also into a file (a model takes it as ``table=FILE``); ``--shipped`` rebuilds the
tables shipped with the package, one per shipped design (after a source rung's solver version
changed). ``check`` says whether a current table exists (shipped, cached or the ``--table``
file) without building one: exit 0 if so, 1 if it is missing or stale (and why).
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from ..core.errors import SoftcathError
from .common import add_option_argument, bounded_int, parse_model_options


def register(sub) -> None:
    p = sub.add_parser("surrogate", help="build or check the surrogate rung's table for a design")
    actions = p.add_subparsers(dest="action", required=True)
    b = actions.add_parser("build", help="build the table (into the cache; --out FILE; --shipped)")
    b.add_argument("design", nargs="?", help="design YAML file or shipped design name")
    b.add_argument("--out", default=None, help="also write the table to this file (.npz)")
    b.add_argument("--shipped", action="store_true",
                   help="rebuild every shipped design's table into the package (config/surrogate_tables)")
    b.add_argument("--workers", type=bounded_int(1, 256), default=None,
                   help="build processes (default: the machine's cores)")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    c = actions.add_parser("check", help="is a current table there (shipped, cached or --table)? exit 0/1")
    c.add_argument("design", nargs="?", help="design YAML file or shipped design name")
    c.add_argument("--table", default=None, help="check this table file instead")
    c.add_argument("--shipped", action="store_true", help="check the shipped table of every shipped design")
    for q in (b, c):
        add_option_argument(q)
        q.add_argument("--json", action="store_true", help="machine-readable output")
        q.set_defaults(func=run)


def _designs(args) -> list[str]:
    from ..resources import shipped_names

    if args.shipped == bool(args.design):
        raise SoftcathError("give a DESIGN or --shipped (not both)")
    return shipped_names("design") if args.shipped else [args.design]


def _summary(model) -> dict:
    return {"design": model.design.name, "origin": model.origin,
            "table": str(model.table_path) if model.table_path else None, "key": model.key,
            "source": model.settings.source, "source_version": model.meta.get("source_version"),
            "pressure_range_pa": list(model.pressure_range), "build_seconds": model.meta.get("build_seconds"),
            "error_bound": model.error_bound, "refused_regions": model.meta.get("refused_regions", [])}


def _line(model) -> str:
    parts = [f"{k} R_C {b['rc_rel_max']:.2%}, direction {b['direction_deg_max']:.2f} deg"
             + (f" (worst at {' / '.join(f'{p:g}' for p in b['worst_at_bar'])} bar)" if b.get("worst_at_bar") else "")
             for k, b in model.error_bound.items() if "rc_rel_max" in b and k != "common_mode"]
    cm = model.error_bound.get("common_mode", {})
    if "max_common_pressure_pa" in cm:
        parts.append(f"common pressure answered up to {cm['max_common_pressure_pa'] / 1e5:.3f} bar")
    refused = model.refused_regions() if model.kind == "three_channel" else []
    if refused:
        parts.append("refuses pair commands at " + "; ".join(refused))
    return (f"{model.design.name}: {model.origin} table {model.table_path} (0..{model.pressure_range[1] / 1e5:.3f} "
            f"bar); max error against {model.settings.source}: " + "; ".join(parts))


def run(args) -> int:
    from ..core.design import load_design
    from ..core.models import make_model

    options = parse_model_options("surrogate", args.option)
    if args.action == "build":
        if args.shipped and args.out:
            raise SoftcathError("--out names one table; --shipped writes each into the package")
        if args.out:   # a folder that cannot be made fails now, not after the build
            Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        out = []
        for name in _designs(args):
            t0 = time.perf_counter()
            model = make_model("surrogate", load_design(name), rebuild=True, progress=not args.quiet,
                               workers=args.workers, **options)
            if args.shipped:
                model.table_path = model.write(model.shipped_path())
                model.origin = "shipped"
            elif args.out:
                model.table_path = model.write(args.out)
            doc = _summary(model)
            doc["wall_seconds"] = time.perf_counter() - t0
            out.append(doc)
            if not args.json:
                print(f"built in {doc['wall_seconds']:.1f} s; " + _line(model))
        if args.json:
            json.dump(out if args.shipped else out[0], sys.stdout, indent=2)
            print()
        return 0
    # check
    status, out = 0, []
    for name in _designs(args):
        design = load_design(name)
        try:
            if args.table:
                model = make_model("surrogate", design, table=args.table, **options)
            else:
                model = make_model("surrogate", design, build=False, cache=not args.shipped, **options)
                if args.shipped and model.origin != "shipped":
                    raise SoftcathError(f"model 'surrogate': no current shipped table for '{name}'")
            doc = {"current": True, **_summary(model)}
            line = "current: " + _line(model)
        except SoftcathError as exc:
            status = 1
            doc = {"design": design.name, "current": False, "reason": str(exc)}
            line = f"not current: {exc}"
        out.append(doc)
        if not args.json:
            print(line)
    if args.json:
        json.dump(out if args.shipped else out[0], sys.stdout, indent=2)
        print()
    return status


__all__ = ["register", "run"]
