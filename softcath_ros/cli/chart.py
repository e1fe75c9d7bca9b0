"""`softcath chart`: the ladder charts from benchmarks/ladder_chart.py's CSV.

- ``<stem>.png``: speed against accuracy (log time per evaluation vs worst R_C error, one point per
  rung setting and case family, against that family's reference), error against pressure per rung
  on the first case, and each rung's failure boundary per case (the last pressure reached on a ramp).
- ``<stem>_lengths.png`` (+ CSV): the 1-channel cases, R_C and tip error against pressure per length.
- ``<stem>_directions.png`` (+ CSV): the 3-channel cases, R_C, tip and bending-direction error
  against the bending direction (worst over each case's pressures).
"""
from __future__ import annotations

import csv
from pathlib import Path

from ..core.errors import SoftcathError
from ..core.units import PA_PER_BAR
from ..resources import checkout_root

NUMBERS = ("pressure_pa", "s_per_eval", "boundary_pa", "rc_rel_error", "tip_error_mm", "direction_error_deg",
           "length_m", "rc_m")
# numbers written by later versions of the ladder (read when present)
OPTIONAL_NUMBERS = ("centreline_radius_m", "contact_boundary_pa", "accurate_to_pa_2pct", "accurate_to_pa_5pct",
                    "accurate_to_pa_10pct")
MARKERS = {"length": "o", "direction": "^"}
# the marker of a point by its reference (the row's column reference)
REFERENCE_MARKERS = {"fe3d": "o", "section": "D"}


def _reference_marker(reference: str) -> str:
    return REFERENCE_MARKERS.get((reference or "").split(" ")[0], "x")


def register(sub) -> None:
    p = sub.add_parser("chart", help="draw the model ladder charts (speed against accuracy, errors per case family)")
    root = checkout_root()
    p.add_argument("--csv", default=str(root / "benchmarks/results/ladder_chart.csv") if root else None,
                   help="rows written by `softcath envelope --results STEM` (STEM.csv) or benchmarks/ladder_chart.py "
                        "(default in a source checkout: the committed ones)")
    p.add_argument("--out", default=None, help="main PNG to write (default: beside the CSV, same stem); the "
                   "family charts go beside it as <stem>_lengths.png and <stem>_directions.png")
    p.set_defaults(func=run)


def _float(v: str):
    return None if v in ("", "None") else float(v)


def load_rows(path: str | None) -> list[dict]:
    if path is None:
        raise SoftcathError("--csv: no committed results outside a source checkout; give --csv FILE "
                            "(written by `softcath envelope --results STEM`)")
    if not Path(path).is_file():
        raise SoftcathError(f"--csv {path}: no such file; run benchmarks/ladder_chart.py first")
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except UnicodeDecodeError as exc:
        raise SoftcathError(f"--csv {path}: not a CSV text file (not UTF-8 at byte {exc.start})") from None
    if not rows:
        raise SoftcathError(f"--csv {path}: no rows")
    missing = [k for k in ("case", "family", "setting", "reference", "converged", "fails_beyond", *NUMBERS)
               if k not in rows[0]]
    if missing:
        raise SoftcathError(f"--csv {path}: columns {missing} missing; re-run benchmarks/ladder_chart.py")
    for i, r in enumerate(rows, start=2):
        for k in NUMBERS + tuple(k for k in OPTIONAL_NUMBERS if k in r):
            try:
                r[k] = _float(r[k])
            except (TypeError, ValueError):
                raise SoftcathError(f"--csv {path} row {i}: {k} = {r[k]!r} is not a number") from None
        r["converged"] = r["converged"] == "True"
        r["fails_beyond"] = r["fails_beyond"] == "True"
    return rows


def run(args) -> int:
    rows = load_rows(args.csv)
    out = Path(args.out or Path(args.csv).with_suffix(".png"))
    for path in draw_all(rows, out):
        print(f"wrote {path}")
    return 0


def draw_all(rows: list[dict], out: Path) -> list[Path]:
    """The main chart and one chart (+ its rows as CSV) per case family present."""
    written = [Path(draw(rows, str(out)))]
    for family, drawer in (("length", draw_lengths), ("direction", draw_directions)):
        rs = [r for r in rows if r["family"] == family]
        if not rs:
            continue
        stem = out.with_name(f"{out.stem}_{family}s")
        drawer(rs, str(stem.with_suffix(".png")))
        with open(stem.with_suffix(".csv"), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rs[0]))
            w.writeheader()
            w.writerows(rs)
        written += [stem.with_suffix(".png"), stem.with_suffix(".csv")]
    return written


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(plt, fig, path: str) -> str:
    fig.tight_layout()
    # bbox "tight" grows the image to hold the legends placed outside the axes
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def _legend_below(ax, *args, fontsize: int = 6, ncol: int = 1) -> None:
    """A legend under the axes (beneath a one-line x label), so it never covers the plotted points."""
    ax.legend(*args, fontsize=fontsize, ncol=ncol, loc="upper center", bbox_to_anchor=(0.5, -0.2),
              borderaxespad=0.0)


def _legend_right(ax, *args, fontsize: int = 6) -> None:
    """A legend right of the (last) axes, beside them, for axes whose x labels take several lines."""
    ax.legend(*args, fontsize=fontsize, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)


def _colours(rows: list[dict]) -> dict:
    return {s: f"C{i % 10}" for i, s in enumerate(dict.fromkeys(r["setting"] for r in rows))}


def _style(setting: str) -> str:
    """Line style: the surrogate dashed, so it shows over its source it tracks closely."""
    return "x--" if setting.startswith("surrogate") else "o-"


def _worst(rs: list[dict], key: str):
    vals = [r[key] for r in rs if r[key] is not None]
    return max(vals) if vals else None


def _plot_by_reference(ax, rs: list[dict], key: str, scale: float, colour: str, label: str) -> None:
    """A setting's line over pressure, each point marked by the reference it was measured against
    (filled circle: fe3d; open diamond: the section rung with contact)."""
    pts = [(r["pressure_pa"] / PA_PER_BAR, r[key] * scale, r["reference"]) for r in rs if r[key]]
    if not pts:
        return
    ax.plot([p[0] for p in pts], [p[1] for p in pts], "--" if label.startswith("surrogate") else "-",
            color=colour, label=label)
    for ref in dict.fromkeys(p[2] for p in pts):
        mine = [p for p in pts if p[2] == ref]
        filled = _reference_marker(ref) == "o"
        ax.scatter([p[0] for p in mine], [p[1] for p in mine], marker=_reference_marker(ref), s=22,
                   color=colour, facecolors=colour if filled else "none")


def _reference_legend(rows: list[dict]) -> str:
    refs = dict.fromkeys(r["reference"] for r in rows if r["reference"])
    names = {"o": "filled circle", "D": "open diamond", "x": "x"}
    return ", ".join(f"{names[_reference_marker(r)]}: {r}" for r in refs)


def draw(rows: list[dict], path: str) -> str:
    plt = _pyplot()
    colours = _colours(rows)
    cases = list(dict.fromkeys(r["case"] for r in rows))
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(18, 6))
    # speed against accuracy: per setting and family, the worst error over the family's cases
    for family in dict.fromkeys(r["family"] for r in rows):
        fam = [r for r in rows if r["family"] == family]
        refs = sorted({r["reference"] for r in fam if r["reference"]})
        for s in dict.fromkeys(r["setting"] for r in fam):
            rs = [r for r in fam if r["setting"] == s]
            err = _worst(rs, "rc_rel_error")
            if all(r["setting"] == r["reference"] for r in rs) or not err:
                continue
            cost = max(r["s_per_eval"] for r in rs)
            a1.scatter([cost], [err * 100], color=colours[s], marker=MARKERS.get(family, "s"), s=50,
                       label=f"{s} ({family} cases vs {'/'.join(refs)})")
            a1.annotate(s, (cost, err * 100), fontsize=7, xytext=(4, 4), textcoords="offset points")
    a1.set_xscale("log")
    a1.set_yscale("log")
    a1.set_xlabel("time per evaluation [s] (shared 2-core machine)")
    a1.set_ylabel("worst R_C error against the reference [%]")
    a1.set_title("speed against accuracy (o: 1 channel, lengths; ^: 3 channels, directions)", fontsize=9)
    _legend_below(a1)
    # error against pressure on the first case
    first = [r for r in rows if r["case"] == cases[0]]
    for s in dict.fromkeys(r["setting"] for r in first):
        mine = [r for r in first if r["setting"] == s and r["rc_rel_error"] and r["setting"] != r["reference"]]
        _plot_by_reference(a2, mine, "rc_rel_error", 100, colours[s], s)
    a2.set_yscale("log")
    a2.set_xlabel("pressure [bar]")
    a2.set_ylabel("R_C = l / theta error [%]")
    a2.set_title(f"error against pressure: {cases[0]}\n(marker: the point's reference, "
                 f"{_reference_legend(first)})", fontsize=9)
    _legend_below(a2, fontsize=7, ncol=2)
    # failure boundary per setting and case
    settings = list(dict.fromkeys(r["setting"] for r in rows))
    for j, case in enumerate(cases):
        for i, s in enumerate(settings):
            rs = [r for r in rows if r["case"] == case and r["setting"] == s]
            if not rs:
                continue
            y = i + (j - (len(cases) - 1) / 2) * 0.8 / max(len(cases), 1)
            a3.scatter([rs[0]["boundary_pa"] / PA_PER_BAR], [y], color=f"C{j % 10}",
                       marker="x" if rs[0]["fails_beyond"] else ">", label=case if i == 0 or s == settings[0] else None)
            within = rs[0].get("accurate_to_pa_5pct")
            if within is not None:   # the accuracy boundary: a bar from 0 to where the error leaves 5 %
                a3.plot([0.0, within / PA_PER_BAR], [y, y], "-", color=f"C{j % 10}", lw=2.5, alpha=0.5)
            if rs[0].get("contact_boundary_pa") is not None:
                a3.scatter([rs[0]["contact_boundary_pa"] / PA_PER_BAR], [y], color=f"C{j % 10}", marker="s",
                           facecolors="none")
    a3.set_yticks(range(len(settings)), settings, fontsize=7)
    a3.set_xlabel("pressure [bar]\nx: stops beyond it on a ramp to max_pressure; >: reaches max_pressure\n"
                  "(fe3d: the case's top); bar: R_C error within 5 % up to there;\n"
                  "square: stops with the tip on the bench's scale", fontsize=7)
    a3.set_title("failure boundaries per case:\nwhere each rung stops, where its error leaves 5 %", fontsize=9)
    handles, labels = a3.get_legend_handles_labels()
    uniq = dict(zip(labels, handles))
    _legend_right(a3, uniq.values(), uniq.keys())
    return _save(plt, fig, path)


def draw_lengths(rows: list[dict], path: str) -> str:
    """R_C and tip error against pressure, one column per length (1-channel cases)."""
    plt = _pyplot()
    colours = _colours(rows)
    cases = sorted(dict.fromkeys(r["case"] for r in rows), key=lambda c: -next(
        r["length_m"] for r in rows if r["case"] == c))
    fig, axes = plt.subplots(3, len(cases), figsize=(5 * len(cases), 11), squeeze=False)
    for j, case in enumerate(cases):
        rs = [r for r in rows if r["case"] == case]
        for s in dict.fromkeys(r["setting"] for r in rs):
            mine = [r for r in rs if r["setting"] == s and r["setting"] != r["reference"]]
            _plot_by_reference(axes[0, j], mine, "rc_rel_error", 100, colours[s], s)
            _plot_by_reference(axes[1, j], mine, "tip_error_mm", 1, colours[s], s)
            _plot_by_reference(axes[2, j], [r for r in rs if r["setting"] == s], "rc_m", 1e3, colours[s], s)
            failed = [r["pressure_pa"] / PA_PER_BAR for r in rs if r["setting"] == s and not r["converged"]]
            if failed:
                axes[0, j].scatter(failed, [100.0] * len(failed), marker="x", color=colours[s])
        axes[0, j].set_title(f"{case}: {rs[0]['length_m'] * 1e3:g} mm\n(marker: the point's reference, "
                             f"{_reference_legend(rs)})", fontsize=8)
        axes[0, j].set_yscale("log")
        axes[1, j].set_yscale("log")
        axes[2, j].set_yscale("log")
        axes[0, j].set_ylabel("R_C = l / theta error [%] (x at 100: did not converge)")
        axes[1, j].set_ylabel("tip position error [mm]")
        axes[2, j].set_ylabel("R_C = l / theta [mm]")
        axes[2, j].set_xlabel("pressure [bar]")
    _legend_below(axes[-1, 0], *axes[0, 0].get_legend_handles_labels(), fontsize=7, ncol=2)
    fig.suptitle("1-channel design: error against pressure per length, 0-0.5 bar, with lumen contact", fontsize=10)
    return _save(plt, fig, path)


def _case_design(rows: list[dict], case: str) -> str:
    r = next(r for r in rows if r["case"] == case)
    return f"{r['design']}, {float(r['length_m']) * 1e3:g} mm"


def draw_directions(rows: list[dict], path: str) -> str:
    """R_C, tip and bending-direction error (worst over pressures) against the commanded direction."""
    plt = _pyplot()
    colours = _colours(rows)
    cases = list(dict.fromkeys(r["case"] for r in rows))
    fig, axes = plt.subplots(3, 1, figsize=(max(12, 2.4 * len(cases)), 13), sharex=True)
    keys = (("rc_rel_error", 100, "R_C error [%]"), ("tip_error_mm", 1, "tip position error [mm]"),
            ("direction_error_deg", 1, "bending-direction error [deg]"))
    for s in dict.fromkeys(r["setting"] for r in rows):
        for ax, (key, scale, _) in zip(axes, keys):
            xs, ys = [], []
            for i, case in enumerate(cases):
                rs = [r for r in rows if r["case"] == case and r["setting"] == s and r["setting"] != r["reference"]]
                w = _worst(rs, key)
                if w:
                    xs.append(i)
                    ys.append(w * scale)
            if xs:
                ax.plot(xs, ys, _style(s), color=colours[s], label=s)
    labels = [f"{c}\n{_case_design(rows, c)}\n(p = {next(r['direction'] for r in rows if r['case'] == c)})\nref. "
              + "\n+ ".join(dict.fromkeys(r["reference"] for r in rows if r["case"] == c and r["reference"]))
              for c in cases]
    axes[-1].set_xticks(range(len(cases)), labels, fontsize=7)
    for ax, (_, _, name) in zip(axes, keys):
        ax.set_yscale("log")
        ax.set_ylabel(f"worst {name}\nover the case's pressures")
    axes[2].set_ylim(bottom=1e-3)   # the one-channel direction is exact to ~1e-13 deg for every rung
    refs = sorted({r["reference"] for r in rows if r["reference"]})
    pressures = sorted({r["pressure_pa"] / PA_PER_BAR for r in rows})
    _legend_right(axes[0], *axes[0].get_legend_handles_labels(), fontsize=7)
    designs = ", ".join(dict.fromkeys(r["design"] for r in rows))
    fig.suptitle(f"3-channel designs ({designs}): error against bending direction,\n"
                 f"{', '.join(f'{p:g}' for p in pressures)} bar "
                 f"(largest channel); reference: {'/'.join(refs)}", fontsize=10)
    return _save(plt, fig, path)
