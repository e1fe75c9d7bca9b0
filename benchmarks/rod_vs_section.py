"""Free bending of the rod rung against its source, the section rung (D/20, lumen contact): R_C =
l / theta per pressure and length. The rod's law is the section's held at prescribed curvatures and
its tip cap is rigid and straight like the arc rungs' (rod-3), so unloaded the two should agree to
the law's interpolation (between its grid pressures and near its curvature table's end).

    SOFTCATH_CACHE=... .venv/bin/python benchmarks/rod_vs_section.py

Writes benchmarks/results/rod_vs_section.{json,csv}.
"""
from __future__ import annotations

import time

import numpy as np

from harness import write_results
from softcath_ros.core.design import load_design
from softcath_ros.core.models import make_model
from softcath_ros.core.prediction import predict
from softcath_ros.core.units import PA_PER_BAR

LENGTHS = (0.017, 0.020, 0.040)
PRESSURES_BAR = tuple(np.round(np.arange(0.05, 0.35 + 1e-9, 0.0125), 4))   # the law's grid (0.025) and between


def main():
    design = load_design("implemented_5mm")
    p = np.array(PRESSURES_BAR)[:, None] * PA_PER_BAR
    t0 = time.perf_counter()
    section = make_model("section", design)
    rod = make_model("rod", design)
    rows = []
    for length in LENGTHS:
        sec = predict(section, p, length)
        rd = predict(rod, p, length)
        for bar, a, b in zip(PRESSURES_BAR, rd, sec):
            ok = a.converged and b.converged and a.radius_of_curvature_m and b.radius_of_curvature_m
            rows.append({"length_mm": length * 1e3, "pressure_bar": bar,
                         "rc_rod_mm": a.radius_of_curvature_m * 1e3 if ok else None,
                         "rc_section_mm": b.radius_of_curvature_m * 1e3 if ok else None,
                         "rc_rod_vs_section": a.radius_of_curvature_m / b.radius_of_curvature_m - 1 if ok else None,
                         "tip_distance_mm": float(np.linalg.norm(np.subtract(a.tip_position_m, b.tip_position_m))) * 1e3
                         if ok else None,
                         "message": "" if ok else (a.message or b.message)})
    diffs = [abs(r["rc_rod_vs_section"]) for r in rows if r["rc_rod_vs_section"] is not None]
    per_length = {f"{length * 1e3:g}": max(abs(r["rc_rod_vs_section"]) for r in rows
                                          if r["length_mm"] == length * 1e3 and r["rc_rod_vs_section"] is not None)
                  for length in LENGTHS}
    meta = {"design": design.name, "rod": rod.solver_version, "section": section.solver_version,
            "law": rod.law.source, "lengths_m": list(LENGTHS), "pressures_bar": [float(v) for v in PRESSURES_BAR],
            "max_abs_rc_rod_vs_section": max(diffs),
            "max_abs_rc_rod_vs_section_per_length_mm": per_length, "seconds": time.perf_counter() - t0}
    write_results("rod_vs_section", meta, rows)
    print(f"rod {rod.solver_version} vs section {section.solver_version} ({rod.law.source})")
    print(" l [mm]  p [bar]  R_C rod [mm]  R_C section [mm]  rod/section - 1  tip distance [mm]")
    for r in rows:
        if r["rc_rod_mm"] is None:
            print(f"  {r['length_mm']:5.1f}  {r['pressure_bar']:.4f}  refused: {r['message'][:120]}")
        else:
            print(f"  {r['length_mm']:5.1f}  {r['pressure_bar']:.4f}  {r['rc_rod_mm']:11.3f}  {r['rc_section_mm']:15.3f}"
                  f"  {r['rc_rod_vs_section']:+14.2e}  {r['tip_distance_mm']:16.4f}")
    print(f"max |R_C rod / section - 1| = {max(diffs):.2e}; per length [mm]: "
          + ", ".join(f"{k}: {v:.2e}" for k, v in per_length.items()))


if __name__ == "__main__":
    main()
