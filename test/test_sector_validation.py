"""The section rung against the committed fe3d sweeps of the fan designs (issue 36 item 7: within 5 %
in R_C = l / theta, 20 mm; docs/validation.md). fe3d is not run here: the committed sweeps
(benchmarks/fe3d_sweep.py, their rows with the section rung's D/20 answer beside them) hold the
reference; this test checks (1) that they stay within the target, 5 %, where fe3d converged from
0.05 bar, and (2)
that the section rung today, solved coarse (D/12), still gives the committed D/20 answers within
3 % (D/12 was measured up to 2.8 % from D/20 on these designs at 0.05-0.25 bar), so the comparison
holds for the rung as it is now."""
import json
from pathlib import Path

import numpy as np
import pytest

from softcath_ros.core.design import load_design
from softcath_ros.core.models import make_model
from softcath_ros.core.prediction import angle_per_length
from sector_designs import THREE_SECTOR_5MM

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
DESIGNS = {"three_sector_5mm": THREE_SECTOR_5MM, "optimised_1dof_5mm": "optimised_1dof_5mm"}
TARGET = 0.05      # |section / fe3d - 1| in R_C, issue 36
COARSE_SHIFT = 0.03   # |section D/12 / section D/20 - 1| allowed
CASES = ("fe3d_sector_ch0_20mm", "fe3d_sector_pair_20mm_fe3d13", "fe3d_optimised_1dof_20mm_fe3d13")


def _committed(name):
    doc = json.loads((RESULTS / f"{name}.json").read_text())
    rows = [r for r in doc["results"] if r["converged"] and r["pressure_bar"] >= 0.05 - 1e-9]
    return doc["meta"], rows


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_the_section_rung_is_within_its_band_of_the_committed_fe3d_sweep(name):
    meta, rows = _committed(name)
    assert rows, f"{name}: no converged fe3d row from 0.05 bar"
    fe3d = np.array([r["radius_l_over_theta_mm"] for r in rows])
    committed = np.array([r["section_radius_l_over_theta_mm"] for r in rows])
    assert np.all(np.abs(committed / fe3d - 1.0) <= TARGET), list(zip([r["pressure_bar"] for r in rows],
                                                                      committed / fe3d - 1.0))
    design = load_design(DESIGNS[meta["design"]]).with_length(meta["length_m"])
    p = np.array([r["pressure_bar"] for r in rows]) * 1e5
    commands = np.zeros((len(p), design.n_channels))
    commands[:, np.atleast_1d(meta["channel"])] = p[:, None]
    model = make_model("section", design, mesh_size=design.outer_diameter / 12)
    state = model.evaluate(commands)
    assert state.converged.all(), state.message
    coarse = 1e3 / angle_per_length(state, model)
    np.testing.assert_allclose(coarse, committed, rtol=COARSE_SHIFT)
