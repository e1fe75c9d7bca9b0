"""Bending of the shipped designs as a ratio to implemented_5mm on the same rung (issue 36): the
published FE's figures at 0.14 bar, 40 mm are 2.66x (1-DOF optimum) and 1.58x (2-DOF optimum) the
implemented design's curvature, and two equal channels of the 2-DOF design bend +5 % over one.
Comparing ratios removes the offset between our rung and the published FE.

Each design is solved on the section rung (one ramp from 0 to the pressure): channel 0 alone and,
for a multi-channel design, channels 0 and 1 at the same pressure. The ratio is |k| over
implemented_5mm's |k| (1/|k| is the centreline radius); R_C = l / theta is recorded beside it.

    .venv/bin/python benchmarks/design_ratios.py [--pressure 0.14bar] [--designs a,b,...]

Writes benchmarks/results/design_ratios.{json,csv}.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import pressure_option, write_results  # noqa: E402

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.studies.cases import CaseSpec, solve_case  # noqa: E402

DESIGNS = "implemented_5mm,optimised_1dof_5mm,optimised_2dof_5mm,three_sector_5mm,three_channel_5mm"
PUBLISHED = {"optimised_1dof_5mm": 2.66, "optimised_2dof_5mm": 1.58, "three_sector_5mm": 1.58}


def commands(n: int, p: float) -> list[tuple[str, tuple]]:
    one = ("one channel", tuple([p] + [0.0] * (n - 1)))
    return [one] if n == 1 else [one, ("equal pair", tuple([p, p] + [0.0] * (n - 2)))]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pressure", type=pressure_option("--pressure"), default=14000.0, help="with its unit (default 0.14bar)")
    ap.add_argument("--designs", default=DESIGNS)
    args = ap.parse_args()
    rows, reference = [], None
    for given in args.designs.split(","):
        design = load_design(given)
        name = design.name
        cmds = commands(design.n_channels, args.pressure)
        t0 = time.perf_counter()
        # one ramp per command (a pair is not reached through channel 0 alone)
        for what, cmd in cmds:
            r = solve_case(CaseSpec(design.to_dict(), "section", (cmd,)))["results"][0]
            k = math.hypot(*r["curvature_per_m"]) if r["converged"] else float("nan")
            if name == "implemented_5mm" and what == "one channel":
                reference = k
            rows.append({"design": name, "command": what, "pressure_pa": args.pressure, "length_m": design.length,
                         "converged": r["converged"], "curvature_per_m": k,
                         "centreline_radius_mm": 1e3 / k if k > 0 else None,
                         "radius_of_curvature_mm": None if r["radius_of_curvature_m"] is None
                         else r["radius_of_curvature_m"] * 1e3,
                         "max_principal_stretch": r["max_principal_stretch"],
                         "area_ratio": design.section.area_ratio,
                         "thinnest_wall_mm": design.section.thinnest_wall().thickness * 1e3,
                         "message": r["message"]})
        print(f"{name}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    for row in rows:
        row["curvature_ratio"] = row["curvature_per_m"] / reference if reference else None
        row["published_ratio"] = PUBLISHED.get(row["design"]) if row["command"] == "one channel" else None
    for name in {r["design"] for r in rows}:
        mine = {r["command"]: r for r in rows if r["design"] == name}
        if "equal pair" in mine:
            mine["equal pair"]["pair_over_one"] = mine["equal pair"]["curvature_per_m"] / mine["one channel"]["curvature_per_m"]
    for row in rows:
        row.setdefault("pair_over_one", None)
        print(f"{row['design']:20s} {row['command']:12s} |k| {row['curvature_per_m']:8.2f} 1/m  ratio "
              f"{row['curvature_ratio']:.3f}" + (f"  pair/one {row['pair_over_one']:.3f}" if row["pair_over_one"] else ""))
    write_results("design_ratios", {"rung": "section", "pressure_pa": args.pressure,
                                    "reference": "implemented_5mm, channel 0 alone",
                                    "published": {"optimised_1dof_5mm": 2.66, "optimised_2dof_5mm": 1.58,
                                                  "pair_over_one": 1.05}}, rows)


if __name__ == "__main__":
    main()
