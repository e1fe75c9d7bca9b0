"""Every way a section ramp can stop has a name (core/continuation.py), and each is produced here:
a physical limit point (a channel without rings balloons), the material leaving its fitted range
(a Yeoh set with c3 < 0 past its convexity limit), walls touching with contact off, and a
numerical failure (fixed steps too large). Non-converged commands are NaN and marked."""
import copy

import numpy as np
import pytest

from softcath_ros.core.continuation import LIMIT_POINT, MATERIAL_RANGE, NUMERICAL_FAILURE, OUTSIDE_MODEL
from softcath_ros.core.design import design_from_dict
from softcath_ros.core.energy import yeoh_convexity_limit, yeoh_derivatives
from softcath_ros.core.models import make_model

BAR = 1e5


def _coarse(design_dict, **options):
    d = design_from_dict(design_dict)
    return make_model("section", d, mesh_size=d.outer_diameter / 12, **options)


def _stopped(state, reason):
    assert not state.converged.any() and np.isnan(state.curvature).all()
    assert f"[stop: {reason}]" in state.message, state.message
    for other in (LIMIT_POINT, MATERIAL_RANGE, NUMERICAL_FAILURE, OUTSIDE_MODEL):
        if other != reason:
            assert f"[stop: {other}]" not in state.message


def test_yeoh_convexity_limit_of_the_fitted_set():
    i1, stretch = yeoh_convexity_limit(12.7e3, 423.0, -1.46)       # the implemented silicone
    assert i1 == pytest.approx(3 + 423.0 / (3 * 1.46))              # I1b = 99.6
    assert stretch**2 + 2 / stretch == pytest.approx(i1) and stretch == pytest.approx(9.97, abs=0.01)
    _, _, w2 = yeoh_derivatives(np.array([i1 - 1e-6, i1 + 1e-6]), 12.7e3, 423.0, -1.46)
    assert w2[0] > 0 > w2[1]
    assert yeoh_convexity_limit(1.0, 0.5, 0.0) is None


def test_a_channel_without_rings_balloons_to_a_limit_point(design_dict):
    design_dict["reinforcement"] = None
    design_dict["material"] = dict(design_dict["material"], c2=0.0, c3=0.0)     # neo-Hookean
    state = _coarse(design_dict).evaluate([0.2 * BAR])
    _stopped(state, LIMIT_POINT)
    # measured (D/12): the tangent's smallest eigenvalue falls to 15 % of its value at rest at 0.133 bar
    assert "physical limit point at p = 0.13" in state.message
    assert 0.125 * BAR < state.last_converged["pressure"][0] < 0.14 * BAR


def test_a_yeoh_set_with_strongly_negative_c3_leaves_its_range(design_dict):
    design_dict["material"] = dict(design_dict["material"], c3=-100.0)   # convex only up to I1b = 4.41
    state = _coarse(design_dict).evaluate([0.4 * BAR])
    _stopped(state, MATERIAL_RANGE)
    assert "past I1b = 4.41 (uniaxial stretch 1.82)" in state.message
    # the fitted set stays convex over the whole working range (measured at D/20: max I1b 11.2 at
    # 0.35 bar, 35 at 0.5 bar, at the folded lumen shoulders)
    assert make_model("section", design_from_dict(_implemented(design_dict)),
                      mesh_size=0.005 / 12).evaluate([0.5 * BAR]).converged


def _implemented(design_dict):
    d = copy.deepcopy(design_dict)
    d["material"] = dict(d["material"], c3=-1.46)
    return d


def test_walls_touching_without_contact_are_outside_the_model(design_dict):
    _stopped(_coarse(design_dict, contact_distance=None).evaluate([0.35 * BAR]), OUTSIDE_MODEL)


def test_too_large_fixed_steps_are_a_numerical_failure(design_dict):
    state = _coarse(design_dict, adaptive=False, initial_step=0.25 * BAR).evaluate([0.25 * BAR])
    _stopped(state, NUMERICAL_FAILURE)
    assert state.last_converged["pressure"] == [0.0]


def test_a_snap_of_a_stiffening_channel_is_passed_by_arc_length(design_dict):
    """Without rings a channel of a Yeoh silicone with a small c2 balloons at a limit point and
    stiffens again further out: the pressure-controlled path snaps. Arc length follows the path
    over the limit point and back up (the pressure falls, then rises past it), and the ramp goes
    on from there on the ballooned branch."""
    design_dict["reinforcement"] = None
    design_dict["material"] = dict(design_dict["material"], c2=200.0, c3=0.0)
    model = _coarse(design_dict)
    state = model.evaluate([0.15 * BAR])
    assert state.converged and state.message == ""
    (event,) = model.passed_limit_points
    assert event["by"] == "arc length"
    # measured (D/12): the path turns back at 0.1425 bar, falls to 0.1297 bar and rises again
    assert 0.13 * BAR < event["pressure"][0] < 0.15 * BAR
    assert event["lowest_pressure"][0] < 0.95 * event["pressure"][0]
    # on the ballooned branch: the channel's cross-section is many times the body's
    area = float(state.diagnostics.channel_area[0])
    assert area > 5 * np.pi * (0.0025 ** 2)
    assert make_model("section", design_from_dict(design_dict), mesh_size=0.005 / 12).evaluate([0.12 * BAR]).converged
