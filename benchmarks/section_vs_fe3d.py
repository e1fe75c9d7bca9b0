"""Section rung against fe3d in R_C = l / theta, from committed fe3d sweeps (no fe3d run here).

Reads the fe3d rows of ``fe3d_sweep.py`` or ``fe3d_stability.py`` results (default: the 20 and 40
mm sweeps with lumen contact), evaluates the section rung of the same design and length at the same
pressures, and reports per pressure:
- ``section_vs_fe3d``: the section rung as shipped (its arc over the channelled part, the tip cap
  straight beyond it; core/prediction.arc_and_cap);
- ``no_cap_vs_fe3d``: the same curvature laid over the whole length (the cap bent like the body),
  what the rung reported before the cap was straight;
- ``unbent_length_mm`` = l (1 - theta_fe3d / theta_long), theta_long the long-body angle over the
  whole length: the length of body that does not bend as the long-body section predicts, and
  ``base_share_mm``, what is left of it beyond the cap (the clamped base's boundary layer, which a
  2.5D rung cannot have).

    .venv/bin/python benchmarks/section_vs_fe3d.py [--fe3d NAME ...] [--name section_vs_fe3d]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import RESULTS, save_figure, write_results  # noqa: E402

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.models import make_model, rung_class  # noqa: E402
from softcath_ros.core.prediction import KINEMATICS_VERSION, angle_per_length  # noqa: E402
from softcath_ros.core.units import PA_PER_BAR  # noqa: E402

DEFAULT = ("fe3d_sweep_20mm_contact", "fe3d_sweep_40mm_contact")
TARGET = {0.02: 0.08, 0.04: 0.05}   # |section / fe3d - 1| in R_C over 0-0.35 bar (issue 12)
DESIGN_TARGET = {"three_sector_5mm": 0.05, "optimised_1dof_5mm": 0.05}   # issue 36, at any length
DESIGNS = Path(__file__).resolve().parent / "designs"   # designs kept with the benchmarks


def _design(name: str):
    """A sweep's design by name: the shipped ones, else benchmarks/designs/<name>.yaml."""
    from softcath_ros.core.errors import DesignError

    try:
        return load_design(name)
    except DesignError:
        if (DESIGNS / f"{name}.yaml").is_file():
            return load_design(DESIGNS / f"{name}.yaml")
        raise


def _commands(meta: dict, design, pressures: np.ndarray) -> np.ndarray:
    """The sweep's commands: its pressure on the channel(s) in meta (fe3d_sweep --channel)."""
    channels = meta.get("channel", 0)
    out = np.zeros((len(pressures), design.n_channels))
    out[:, np.atleast_1d(channels)] = pressures[:, None]
    return out


def _fe3d_row(row: dict) -> dict | None:
    """A converged fe3d row as {pressure_bar, radius_l_over_theta_mm}: fe3d_sweep.py's rows carry a
    converged flag, fe3d_stability.py's (R_C_mm) hold accepted states only."""
    rc = row.get("radius_l_over_theta_mm") if "converged" in row else row.get("R_C_mm")
    if ("converged" in row and not row["converged"]) or not rc or not math.isfinite(rc) or row.get("pressure_bar", 0.0) <= 0.0:
        return None
    return {"pressure_bar": row["pressure_bar"], "radius_l_over_theta_mm": rc}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fe3d", nargs="+", default=list(DEFAULT), metavar="NAME",
                    help="fe3d_sweep or fe3d_stability result names in benchmarks/results/ (without .json)")
    ap.add_argument("--name", default="section_vs_fe3d")
    args = ap.parse_args(argv)
    rows, sources = [], {}
    for name in args.fe3d:
        path = RESULTS / f"{name}.json"
        try:
            doc = json.loads(path.read_text())
            meta = doc["meta"]
            length = float(meta["length_m"])
            design = _design(meta.get("design", "implemented_5mm")).with_length(length)
        except (OSError, ValueError, KeyError) as exc:
            print(f"section_vs_fe3d: {path}: not an fe3d_sweep or fe3d_stability result ({exc})", file=sys.stderr)
            return 2
        sources[name] = {"git_commit": meta.get("git_commit"), "date": meta.get("date"), "length_m": length,
                         "design": design.name, "channel": meta.get("channel", 0),
                         "stop": meta.get("message", "")[:200]}
        target = DESIGN_TARGET.get(design.name, TARGET.get(round(length, 4)) if design.name == "implemented_5mm" else None)
        fe = [_fe3d_row(r) for r in doc["results"]]
        fe = [r for r in fe if r is not None]
        if not fe:
            continue
        p = np.array([r["pressure_bar"] for r in fe]) * PA_PER_BAR
        section = make_model("section", design)
        state = section.evaluate(_commands(meta, design, p))
        with np.errstate(divide="ignore"):
            rc = 1e3 / angle_per_length(state, section)                               # mm, the cap straight
            rc_long = 1e3 / (np.hypot(*np.asarray(state.curvature).T) * state.axial_stretch)   # mm, cap bent too
        for r, ok, a, b in zip(fe, state.converged, rc, rc_long):
            f = r["radius_l_over_theta_mm"]
            unbent = length * 1e3 * (1.0 - b / f) if ok else None   # theta_fe3d / theta_long = R_long / R_fe3d
            rows.append({"case": name, "length_mm": length * 1e3, "pressure_bar": r["pressure_bar"], "fe3d_rc_mm": f,
                         "section_rc_mm": float(a) if ok else None,
                         "fe3d_angle_deg": math.degrees(length * 1e3 / f),
                         "section_angle_deg": math.degrees(length * 1e3 / a) if ok else None,
                         "section_vs_fe3d": float(a / f - 1.0) if ok else None,
                         "section_no_cap_rc_mm": float(b) if ok else None,
                         "no_cap_vs_fe3d": float(b / f - 1.0) if ok else None,
                         "unbent_length_mm": unbent,
                         "base_share_mm": None if unbent is None else unbent - design.cap_thickness * 1e3,
                         "target": target,
                         "within_target": bool(abs(a / f - 1.0) <= target) if ok and target else None})
    if not rows:
        print("section_vs_fe3d: no converged fe3d rows in the inputs", file=sys.stderr)
        return 2
    meta = {"fe3d_sources": sources, "section_solver": rung_class("section").solver_version,
            "kinematics": KINEMATICS_VERSION, "targets": {f"{k * 1e3:g} mm": v for k, v in TARGET.items()},
            "note": "R_C = l / theta; fe3d rows as committed (their own commits in fe3d_sources); section rung at "
                    "its default mesh at the same pressures"}
    stem = write_results(args.name, meta, rows)
    for case in dict.fromkeys(r["case"] for r in rows):
        mine = [r for r in rows if r["case"] == case and r["section_vs_fe3d"] is not None]
        length = mine[0]["length_mm"]
        worst = max(mine, key=lambda r: abs(r["section_vs_fe3d"]))
        print(f"{case}, {length:g} mm: {len(mine)} pressures to {max(r['pressure_bar'] for r in mine):.4g} bar; section vs fe3d "
              f"{min(r['section_vs_fe3d'] for r in mine):+.2%} .. {max(r['section_vs_fe3d'] for r in mine):+.2%} "
              f"(worst {worst['section_vs_fe3d']:+.2%} at {worst['pressure_bar']:.4g} bar; before the straight cap "
              f"{worst['no_cap_vs_fe3d']:+.2%}); unbent length {min(r['unbent_length_mm'] for r in mine):.2f}.."
              f"{max(r['unbent_length_mm'] for r in mine):.2f} mm")
    _plot(rows, args.name)
    print(f"wrote {stem}.json, .csv, .png")
    return 0


def _plot(rows, name) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for case, colour in zip(dict.fromkeys(r["case"] for r in rows), ("C0", "C1", "C2", "C3", "C4", "C5")):
        mine = [r for r in rows if r["case"] == case and r["section_vs_fe3d"] is not None]
        if not mine:
            continue
        p, label = [r["pressure_bar"] for r in mine], f"{case} ({mine[0]['length_mm']:g} mm)"
        ax1.plot(p, [100 * r["section_vs_fe3d"] for r in mine], "o-", color=colour, label=f"{label}, cap straight")
        ax1.plot(p, [100 * r["no_cap_vs_fe3d"] for r in mine], "x:", color=colour, label=f"{label}, cap bent")
        target = mine[0]["target"]
        if target:
            ax1.axhspan(-100 * target, 100 * target, color=colour, alpha=0.08)
        ax2.plot(p, [r["unbent_length_mm"] for r in mine], "o-", color=colour, label=label)
    ax1.axhline(0, color="k", lw=0.5)
    ax1.set(xlabel="pressure [bar]", ylabel="section / fe3d - 1 in R_C = l / theta [%]",
            title="section rung against fe3d (bands: targets)")
    ax1.legend(fontsize=7)
    ax2.axhline(1.0, color="grey", ls="--", lw=0.8, label="tip cap (1 mm)")
    ax2.set(xlabel="pressure [bar]", ylabel="length not bent as the long body [mm]",
            title="l (1 - theta_fe3d / theta_long body)")
    ax2.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, name)


if __name__ == "__main__":
    sys.exit(main())
