"""Why does fe3d bend ~13% more than the published FE? One modelling choice at a time, 40 mm.

Each variant changes one thing the published description leaves open or that our model
simplifies (docs/actuator.md), never the material constants of the silicone:

* where the strain-limiting fibre sits ("just below the lumen": touching it, or mid-wall as
  in the design file), how stiff it is, or no fibre;
* the cap thickness (not measured; 1 mm assumed);
* the reinforcement: none, or its hoop stiffness halved / x10 (bounds on how much the
  ring model can matter: discrete rings constrain less than the homogenised membrane);
* the bulk modulus (how incompressible);
* the element formulation: P2 displacement only (locks for nearly incompressible solids)
  instead of our mixed displacement-pressure elements;
* a very soft fill in the lumen (the contact proxy used to pass lumen collapse at 20 mm).

    .venv/bin/python benchmarks/fe3d_sensitivity.py                 # every variant (cached per variant)
    .venv/bin/python benchmarks/fe3d_sensitivity.py --only baseline,cap_2mm
    .venv/bin/python benchmarks/fe3d_sensitivity.py --plot-only

Every run is 0 -> 0.20 bar at the default mesh through `Fe3dModel` (cached by a hash of the
design and settings in the project cache, so an interrupted study resumes). Writes
benchmarks/results/fe3d_sensitivity.{json,csv,png}.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import RESULTS, save_figure, write_results  # noqa: E402

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.experimental.fe3d_variants import Fe3dVariantModel  # noqa: E402
from softcath_ros.core.units import PA_PER_BAR  # noqa: E402

NAME = "fe3d_sensitivity"
PRESSURES_BAR = [0.05, 0.10, 0.15, 0.20]
PUBLISHED_MM = {0.15: 31.13, 0.20: 16.86}   # docs/actuator.md, 40 mm


def _fibre_at(y: float):
    def change(d):
        return dataclasses.replace(d, limiting_fibre=dataclasses.replace(d.limiting_fibre, center=(0.0, y)))
    return change


def _hoop_scaled(factor: float):
    def change(d):
        r = d.reinforcement
        return dataclasses.replace(d, reinforcement=dataclasses.replace(r, youngs_modulus=r.youngs_modulus * factor))
    return change


def _material(**kw):
    def change(d):
        return dataclasses.replace(d, material=dataclasses.replace(d.material, **kw))
    return change


# name -> (what changes, design change, Fe3dModel options)
VARIANTS = {
    "baseline": ("design file as is: fibre centre y = -2.2 mm (mid-wall), cap 1 mm, hoop membrane 874 N/m",
                 lambda d: d, {}),
    "fibre_touching_lumen": ("fibre centre y = -2.05 mm: touching the lumen (\"just below\")",
                             _fibre_at(-2.05e-3), {}),
    "fibre_none": ("no strain-limiting fibre", lambda d: dataclasses.replace(d, limiting_fibre=None), {}),
    "fibre_c1_x0.1": ("fibre 10x softer (c1 = 0.79 MPa): is it its stiffness or its presence that counts",
                      lambda d: dataclasses.replace(d, limiting_fibre=dataclasses.replace(
                          d.limiting_fibre, material=dataclasses.replace(d.limiting_fibre.material,
                                                                         c1=d.limiting_fibre.material.c1 * 0.1))),
                      {}),
    "cap_0.5mm": ("cap 0.5 mm", lambda d: dataclasses.replace(d, cap_thickness=0.5e-3), {}),
    "cap_2mm": ("cap 2 mm", lambda d: dataclasses.replace(d, cap_thickness=2.0e-3), {}),
    "rings_none": ("no reinforcement", lambda d: dataclasses.replace(d, reinforcement=None), {}),
    "hoop_x0.5": ("hoop stiffness halved (437 N/m)", _hoop_scaled(0.5), {}),
    "hoop_x10": ("hoop stiffness x10 (8740 N/m): nearly inextensible rings", _hoop_scaled(10.0), {}),
    "bulk_x10": ("bulk modulus 1 GPa instead of 100 MPa", _material(bulk_modulus=1.0e9), {}),
    "displacement_p2": ("P2 displacement-only elements (no mixed pressure): volumetric locking",
                        lambda d: d, {"formulation": "displacement"}),
    "lumen_fill": ("lumen filled with a compressible solid of shear modulus 1% of the silicone's",
                   lambda d: d, {"lumen_fill": 0.01}),
}


def run_variant(name: str, length: float, threads: int) -> dict:
    what, change, options = VARIANTS[name]
    design = change(load_design("implemented_5mm").with_length(length))
    model = Fe3dVariantModel(design, cache=True, progress=True, threads=threads, **options)
    pressures = np.array(PRESSURES_BAR)[:, None] * PA_PER_BAR
    t0 = time.perf_counter()
    state = model.evaluate(pressures)
    elapsed = time.perf_counter() - t0
    rows = []
    for i, p in enumerate(PRESSURES_BAR):
        ok = bool(state.converged[i])
        rc = float(state.radius_l_over_theta[i]) if ok else None
        rows.append({"variant": name, "change": what, "pressure_bar": p, "converged": ok,
                     "radius_l_over_theta_mm": rc * 1e3 if rc else None,
                     "bending_angle_deg": float(np.degrees(state.tip.angle[i])) if ok else None,
                     "wall_s": elapsed})
    if not bool(np.all(state.converged)):
        print(f"{name}: {state.message}")
    return {"rows": rows, "message": state.message}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", default="", help="comma-separated variant names (default: all)")
    ap.add_argument("--length", type=float, default=0.040, help="m")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--plot-only", action="store_true")
    args = ap.parse_args(argv)
    if args.plot_only:
        print(plot())
        return 0
    names = [n for n in args.only.split(",") if n] or list(VARIANTS)
    unknown = set(names) - set(VARIANTS)
    if unknown:
        ap.error(f"unknown variant(s) {sorted(unknown)}; known: {', '.join(VARIANTS)}")
    messages = {}
    try:
        for name in names:
            print(f"--- {name}: {VARIANTS[name][0]}", flush=True)
            out = run_variant(name, args.length, args.threads)
            # merge into what is on disk now (another run may have added variants meanwhile)
            rows = [r for r in _load_doc()["results"] if r["variant"] != name] + out["rows"]
            messages[name] = out["message"]
            _write(rows, messages, args)   # after each variant: a long study keeps what finished
    except KeyboardInterrupt:
        print("interrupted: the variants that finished are written (the interrupted one resumes from the cache)")
    print(f"wrote {RESULTS / NAME}.json/.csv, {plot()}")
    return 0


def _write(rows: list[dict], messages: dict, args) -> None:
    _add_deltas(rows)
    order = {n: i for i, n in enumerate(VARIANTS)}
    rows.sort(key=lambda r: (order.get(r["variant"], 99), r["pressure_bar"]))
    previous = _load_doc()["meta"].get("messages", {})
    meta = {"design": "implemented_5mm", "length_m": args.length, "mesh_size": 1.0, "threads": args.threads,
            "published_radius_mm": PUBLISHED_MM, "messages": {**previous, **messages},
            "note": "wall_s is the variant's whole ramp on a shared 2-core machine (see load_average)"}
    write_results(NAME, meta, rows)


def _load_doc() -> dict:
    """The committed results (meta and rows), empty before the first run."""
    path = RESULTS / f"{NAME}.json"
    return json.loads(path.read_text()) if path.is_file() else {"meta": {}, "results": []}


def _add_deltas(rows: list[dict]) -> None:
    """Per row: change of R_C against the baseline and error against the published FE."""
    base = {r["pressure_bar"]: r["radius_l_over_theta_mm"] for r in rows if r["variant"] == "baseline"}
    for r in rows:
        rc = r["radius_l_over_theta_mm"]
        b = base.get(r["pressure_bar"])
        r["change_vs_baseline"] = (rc - b) / b if (rc and b) else None
        pub = PUBLISHED_MM.get(r["pressure_bar"])
        r["error_vs_published"] = (rc - pub) / pub if (rc and pub) else None


def plot() -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    doc = _load_doc()
    rows = doc["results"]
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    fig, ax = plt.subplots(figsize=(9, 4.5))
    width = 0.38
    for j, p in enumerate((0.15, 0.20)):
        vals = []
        for v in variants:
            r = next((r for r in rows if r["variant"] == v and r["pressure_bar"] == p), None)
            vals.append(100 * r["error_vs_published"] if r and r["error_vs_published"] is not None else np.nan)
        x = np.arange(len(variants)) + (j - 0.5) * width
        ax.bar(x, vals, width, label=f"{p:.2f} bar")
        for xi, v in zip(x, vals):   # a variant that stopped before this pressure says so
            if np.isnan(v):
                ax.text(xi, 0.5, "did not converge", rotation=90, ha="center", va="bottom", fontsize=6)
    ax.axhspan(-5, 5, color="g", alpha=0.12, label="target +-5%")
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xticks(np.arange(len(variants)), variants, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("R_C error vs published FE [%]\n(negative: bends more)")
    ax.legend(fontsize=8)
    ax.set_title(f"fe3d sensitivity, 40 mm, default mesh (load avg {doc['meta']['load_average'][0]:.1f})",
                 fontsize=9)
    fig.tight_layout()
    return save_figure(fig, NAME)


if __name__ == "__main__":
    sys.exit(main())
