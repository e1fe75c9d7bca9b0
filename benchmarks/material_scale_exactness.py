"""Is a material scale m a pressure scale p -> p / m? The section rung (D/20) on the design with
its moduli x m at p against the rung on the design at p / m, theta / l at 0.1, 0.2, 0.3 bar, for
m = 1.3 and 0.8: scaling every modulus (calibration's ``scaled_design``) and scaling the silicone's
Yeoh coefficients alone (the former definition: the fibre and the rings keep their stiffness).

    .venv/bin/python benchmarks/material_scale_exactness.py

Writes benchmarks/results/material_scale_exactness.{json,csv}.
"""
from __future__ import annotations

import os
from dataclasses import replace

import numpy as np
from harness import write_results

from softcath_ros.core.calibration_file import scaled_design
from softcath_ros.core.design import load_design
from softcath_ros.core.models import make_model
from softcath_ros.core.prediction import angle_per_length

PRESSURES = np.array([10000.0, 20000.0, 30000.0])


def main():
    design = load_design("implemented_5mm")
    load_before = os.getloadavg()
    base = make_model("section", design)
    rows = []
    for m in (1.3, 0.8):
        ref = angle_per_length(base.evaluate(PRESSURES[:, None] / m))
        for label, d in (("every modulus", scaled_design(design, m)),
                         ("silicone Yeoh only", replace(design, material=design.material.scaled(m)))):
            got = angle_per_length(make_model("section", d).evaluate(PRESSURES[:, None]))
            for p, a, b in zip(PRESSURES, got, ref):
                rows.append({"material_scale": m, "scaled": label, "pressure_bar": p / 1e5,
                             "theta_over_l_scaled_design": float(a), "theta_over_l_at_p_over_m": float(b),
                             "relative_difference": float(a / b - 1)})
                print(f"m = {m}, {label:18s}, {p / 1e5:.1f} bar: {a / b - 1:+.2e}")
    write_results("material_scale_exactness", {"design": design.name, "rung": "section D/20",
                                                "load_average_before": load_before,
                                                "load_average_after": os.getloadavg()}, rows)


if __name__ == "__main__":
    main()
