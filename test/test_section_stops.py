"""Every way a section ramp can stop has a name (core/continuation.py), and each is produced here:
a physical limit point (a channel without rings balloons), the material leaving its fitted range
(a Yeoh set with c3 < 0 past its convexity limit), walls touching with contact off, and a
numerical failure (fixed steps too large). Non-converged commands are NaN and marked."""
import copy

import numpy as np
import pytest

from softcath_ros.core.continuation import LIMIT_POINT, MATERIAL_RANGE, NUMERICAL_FAILURE, OUTSIDE_MODEL, UNSTABLE
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
    for other in (LIMIT_POINT, MATERIAL_RANGE, NUMERICAL_FAILURE, OUTSIDE_MODEL, UNSTABLE):
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
    # one step from rest (section-8, D/12): 0.3 bar converges, 0.35 bar and beyond do not
    state = _coarse(design_dict, adaptive=False, initial_step=0.4 * BAR).evaluate([0.4 * BAR])
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


def _arc_corrector(p, dp):
    """Pseudo-arc-length corrector on the 1-D path p(x) (the load p, the state x)."""
    memory = {}

    def corrector(x0, load0, previous, ds):
        from softcath_ros.core.continuation import Correction

        t = np.array([1.0, dp(x0)])
        t /= np.linalg.norm(t)
        if "t" in memory and t @ memory["t"] < 0:
            t = -t
        elif "t" not in memory and t[1] < 0:
            t = -t
        x, q = x0 + ds * t[0], load0 + ds * t[1]
        for it in range(1, 30):
            # residuals: equilibrium p(x) - q = 0 and the arc constraint
            r = np.array([p(x) - q, t @ [x - x0, q - load0] - ds])
            J = np.array([[dp(x), -1.0], t])
            dx, dq = np.linalg.solve(J, -r)
            x, q = x + dx, q + dq
            if abs(dx) + abs(dq) < 1e-13:
                memory["t"] = t
                return Correction(x, True, it, info={"load": q})
        return Correction(x0, False, 30, "no convergence")

    return corrector


def test_arc_length_passes_a_snap_and_names_the_end_of_a_branch():
    from softcath_ros.core.continuation import ArcControl, arc_length

    control = ArcControl(initial_step=0.01, min_step=1e-5, max_step=0.05)
    # an S-shaped path: the load turns back at x1 = 0.2764 (p 0.0723) and rises again from x2 = 0.7236 (p 0.0277)
    p = lambda x: x**3 - 1.5 * x**2 + 0.6 * x         # noqa: E731
    dp = lambda x: 3 * x**2 - 3 * x + 0.6             # noqa: E731
    x1, x2 = (3 - np.sqrt(1.8)) / 6, (3 + np.sqrt(1.8)) / 6
    arc = arc_length(_arc_corrector(p, dp), 0.25, p(0.25), control, floor=0.0)
    assert arc.passed and not arc.below_floor
    assert arc.limit_load == pytest.approx(p(x1), abs=2e-4) and arc.lowest_load == pytest.approx(p(x2), abs=2e-4)
    assert arc.load > p(x1) and arc.state > x2                  # on the rising branch beyond the snap
    # a path whose load falls for ever after its maximum (p = x exp(-x), limit point at x = 1)
    arc = arc_length(_arc_corrector(lambda x: x * np.exp(-x), lambda x: (1 - x) * np.exp(-x)), 0.9,
                     0.9 * np.exp(-0.9), control, floor=0.5 / np.e)
    assert not arc.passed and arc.below_floor
    assert arc.limit_load == pytest.approx(1 / np.e, abs=1e-4)
