"""The shipped designs bend as issue 36 asks, as ratios of curvature to implemented_5mm on the same
rung (0.14 bar, 40 mm; published FE: 1-DOF optimum 2.66x, 2-DOF optimum 1.58x, an equal pair +5 %
over one channel). Read from the shipped surrogate tables of the section rung (fast; each table is
within its charted error of the section rung, which benchmarks/design_ratios.py solves directly:
benchmarks/results/design_ratios.json)."""
import math

import numpy as np
import pytest

from softcath_ros.core.design import load_design
from softcath_ros.core.models import make_model

P = 14000.0   # Pa, 0.14 bar


def curvature(name: str, command) -> float:
    model = make_model("surrogate", load_design(name), build=False)
    assert model.origin == "shipped"
    state = model.evaluate(np.asarray([command], dtype=float))
    assert state.converged[0]
    return float(math.hypot(*state.curvature[0]))


@pytest.fixture(scope="module")
def implemented() -> float:
    return curvature("implemented_5mm", [P])


@pytest.mark.parametrize("name, least", [("optimised_1dof_5mm", 2.66), ("optimised_2dof_5mm", 1.58),
                                         ("three_sector_5mm", 1.58)])
def test_the_shaped_designs_bend_at_least_as_the_published_optimum_relative_to_the_implemented_design(
        name, least, implemented):
    design = load_design(name)
    command = [P] + [0.0] * (design.n_channels - 1)
    assert curvature(name, command) / implemented >= least


def test_two_equal_fans_of_the_sector_design_bend_more_than_one(implemented):
    one = curvature("three_sector_5mm", [P, 0.0, 0.0])
    pair = curvature("three_sector_5mm", [P, P, 0.0])
    assert pair > one
