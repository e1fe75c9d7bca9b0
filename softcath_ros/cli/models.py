"""`softcath models`: the rungs of the model ladder, what each declares it models and the options
it takes (from each rung's ``RungInfo``; nothing is built)."""
from __future__ import annotations

from ..core import json_output



def register(sub) -> None:
    p = sub.add_parser("models", help="list the model rungs: what each models and the options it takes")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..core.models import available_models, rung_info

    doc = {}
    for name in available_models():
        info = rung_info(name)
        doc[name] = {"summary": info.summary, "models": list(info.models), "linear_gain": info.linear_gain,
                     "solves_backbone": info.solves_backbone, "depends_on_length": info.depends_on_length,
                     "needs": info.needs, "live": info.live,
                     "options": {o.name: {"kind": o.kind, "description": o.description} for o in info.options},
                     "more_options": info.more_options}
    if args.json:
        print(json_output.dumps(doc, indent=2))
        return 0
    for name, d in doc.items():
        flags = [f for f in ("linear_gain", "solves_backbone", "depends_on_length") if d[f]]
        flags += [] if d["live"] else ["offline only (no node serves it)"]
        print(f"{name}: {d['summary']}")
        print(f"  models: {', '.join(d['models'])}" + (f"; {', '.join(flags)}" if flags else "")
              + (f"; needs the '{d['needs']}' extra" if d["needs"] else ""))
        for opt, o in d["options"].items():
            print(f"  --option {opt}=<{o['kind']}>  {o['description']}")
        if d["more_options"]:
            print(f"  other options: {d['more_options']}")
    return 0
