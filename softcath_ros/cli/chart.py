"""`softcath chart`: the ladder chart from benchmarks/ladder_chart.py's CSV: speed against accuracy
(log time per evaluation vs R_C error, one point per rung and setting), error against pressure per
rung, and each rung's failure boundary (the last pressure it reached on a ramp)."""
from __future__ import annotations

import csv
from pathlib import Path

from ..core.errors import SoftcathError
from ..core.units import PA_PER_BAR

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "results"


def register(sub) -> None:
    p = sub.add_parser("chart", help="draw the model ladder chart (speed against accuracy) from its CSV")
    p.add_argument("--csv", default=str(RESULTS / "ladder_chart.csv"),
                   help="results of benchmarks/ladder_chart.py (default: the committed ones)")
    p.add_argument("--out", default=None, help="PNG to write (default: beside the CSV, same stem)")
    p.set_defaults(func=run)


def _float(v: str):
    return None if v in ("", "None") else float(v)


def load_rows(path: str) -> list[dict]:
    if not Path(path).is_file():
        raise SoftcathError(f"--csv {path}: no such file; run benchmarks/ladder_chart.py first")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k in ("pressure_pa", "s_per_eval", "boundary_pa", "rc_rel_error", "tip_error_mm"):
            r[k] = _float(r[k])
        r["converged"] = r["converged"] == "True"
        r["fails_beyond"] = r["fails_beyond"] == "True"
    if not rows:
        raise SoftcathError(f"--csv {path}: no rows")
    return rows


def run(args) -> int:
    rows = load_rows(args.csv)
    out = args.out or str(Path(args.csv).with_suffix(".png"))
    draw(rows, out)
    print(f"wrote {out}")
    return 0


def draw(rows: list[dict], path: str) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    settings = list(dict.fromkeys(r["setting"] for r in rows))
    ref = rows[0]["reference"]
    colours = {s: f"C{i}" for i, s in enumerate(settings)}
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(16, 4.8))
    for s in settings:
        rs = [r for r in rows if r["setting"] == s]
        errs = [r["rc_rel_error"] for r in rs if r["rc_rel_error"] is not None]
        if s != ref and errs:
            a1.scatter([rs[0]["s_per_eval"]], [max(errs) * 100], color=colours[s], s=50, label=s)
            a1.annotate(s, (rs[0]["s_per_eval"], max(errs) * 100), fontsize=7, xytext=(4, 4),
                        textcoords="offset points")
            pts = [(r["pressure_pa"] / PA_PER_BAR, r["rc_rel_error"] * 100) for r in rs if r["rc_rel_error"] is not None]
            a2.plot(*zip(*pts), "o-", color=colours[s], label=s)
        a3.barh(s, rs[0]["boundary_pa"] / PA_PER_BAR, color=colours[s])
        a3.annotate("fails beyond" if rs[0]["fails_beyond"] else "reached the end", (rs[0]["boundary_pa"] / PA_PER_BAR, s),
                    fontsize=7, xytext=(3, 0), textcoords="offset points", va="center")
    a1.set_xscale("log")
    a1.set_yscale("log")
    a1.set_xlabel("time per evaluation [s] (shared 2-core machine)")
    a1.set_ylabel(f"max R_C error vs {ref} [%]")
    a1.set_title("speed against accuracy")
    a2.set_yscale("log")
    a2.set_xlabel("pressure [bar]")
    a2.set_ylabel("R_C error [%]")
    a2.set_title(f"error against pressure (reference: {ref})")
    a2.legend(fontsize=7)
    a3.set_xlabel("last pressure reached on a ramp [bar]")
    a3.set_title("failure boundary")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
