"""Every section answer is a stable state (the tangent's LDL^T has no negative pivot), or it is
refused by name. At 0.35 bar on the D/17 mesh with the rings as strings (ring_bending off) plain
Newton's answer is a saddle (two directions of negative stiffness at the lumen wall's creased
shoulders); the rung leaves it for the stable state next to it. Figures: docs/models/section.md ("Stable states only")."""
import numpy as np
import pytest

import softcath_ros.core.models.section as section_module
import softcath_ros.core.section_fe.solver as solver_module
from softcath_ros.core.continuation import UNSTABLE
from softcath_ros.core.models import make_model
from softcath_ros.core.section_fe.solver import leave_saddle, unstable_directions

BAR = 1e5


def _radius(k, stretch):
    return 1.0 / (float(np.hypot(*k)) * float(stretch))


@pytest.fixture
def saddles_kept(monkeypatch):
    """The rung with saddles kept where it would leave them (plain Newton's answers); the saddles
    it met, as (problem, state, pressures / c1)."""
    met = []

    def keep(self, corr, pressures, where):
        met.append((self.problem, corr.state.copy(), pressures.copy()))
        return corr

    monkeypatch.setattr(section_module.SectionModel, "_leave_saddle", keep)
    return met


@pytest.fixture
def newton_first(monkeypatch):
    """The rung with plain Newton first everywhere (no stable-only minimiser where the walls touch),
    so that it reaches the saddles a ramp can meet and must leave them."""
    monkeypatch.setattr(section_module.SectionModel, "_saddles_likely", lambda self, x: False)


def _coarse(design, n=17):
    """D/17 (Triangle mesh) with the rings as strings (ring_bending off): this ramp meets saddles at
    the lumen's creased shoulders. With the rings' own bending (the default) it meets none: the
    saddle machinery is exercised where saddles exist."""
    return make_model("section", design, mesh_size=design.outer_diameter / n, ring_bending=False)


def test_a_saddle_that_cannot_be_left_is_refused_by_name(implemented_design, monkeypatch, newton_first):
    """With leaving saddles made to fail, the D/17 ramp to 0.35 bar stops at the saddle it meets
    (measured at 0.29 bar, two directions of negative stiffness): a named stop, no numbers, and the
    last stable state before it reported."""
    met = []

    def cannot_leave(problem, x, pressures, **kwargs):
        met.append(unstable_directions(problem, x, pressures))
        return None, met[-1]

    monkeypatch.setattr(solver_module, "leave_saddle", cannot_leave)   # (imported where it is used)
    state = _coarse(implemented_design).evaluate([0.35 * BAR])
    assert not state.converged and np.isnan(state.curvature).all()
    assert f"[stop: {UNSTABLE}]" in state.message and "saddle" in state.message, state.message
    assert met and met[0] == 2
    assert state.diagnostics.negative_directions == -1       # no answer reached
    assert 0.25 * BAR < state.last_converged["pressure"][0] < 0.35 * BAR


def test_the_rung_leaves_a_saddle_for_the_stable_state_next_to_it(implemented_design, saddles_kept):
    model = _coarse(implemented_design)
    model.evaluate([0.35 * BAR])
    problem, saddle, p = saddles_kept[-1]
    assert unstable_directions(problem, saddle, p) == 2
    stable, count = leave_saddle(problem, saddle, p, tol=model.settings.tol)
    assert count == 2 and stable is not None
    assert unstable_directions(problem, stable.state, p) == 0
    assert problem.energy(stable.state, p) < problem.energy(saddle, p)
    assert stable.info["energy_drop"] > 0
    assert problem.contact_min_gap(stable.state) > 0


def test_answers_past_the_saddle_are_stable_states(implemented_design):
    model = _coarse(implemented_design)
    state = model.evaluate([0.35 * BAR])
    assert state.converged, state.message
    assert state.diagnostics.negative_directions == 0
    x = model._states[(0.35 * BAR,)]
    assert unstable_directions(model.problem, x, np.array([0.35 * BAR]) / model.problem.c_ref) == 0
    # the ramp met a saddle on its way (measured at 0.29 bar, two negative directions), left it
    # and went on from the stable state
    assert model.left_saddles and model.left_saddles[0]["negative_directions"] == 2
    assert model.left_saddles[0]["energy_drop"] > 0
    # measured (D/17, section-7): 3.5208 mm
    assert _radius(state.curvature, state.axial_stretch) == pytest.approx(3.5208e-3, rel=2e-4)
    # asked again (answered from the solved state: its inertia is measured there) and as predict's JSON
    from softcath_ros.core.prediction import predict

    # (at 17 mm: the 40 mm body bent so far would reach the shaft below its base, core/body_contact.py)
    out = predict(model, np.array([[0.35 * BAR]]), length=0.017)[0].to_json()
    assert out["converged"] and out["negative_directions"] == 0


def test_a_stable_answer_is_untouched(implemented_design, monkeypatch):
    """D/16 at 0.35 bar is stable all the way: the same answer with the saddle check and without it."""
    ps = [0.35 * BAR]
    model = _coarse(implemented_design, 16)
    checked = model.evaluate(ps)
    assert checked.converged and checked.diagnostics.negative_directions == 0 and not model.left_saddles
    monkeypatch.setattr(section_module.SectionModel, "_leave_saddle", lambda self, corr, p, where: corr)
    plain = _coarse(implemented_design, 16).evaluate(ps)
    np.testing.assert_array_equal(checked.curvature, plain.curvature)
    assert checked.axial_stretch == plain.axial_stretch
    # measured: 3.5277 mm (section-7, stable-only minimiser once the lumen wall's contact is active;
    # 3.5262 mm by plain Newton there, 3.5271 mm on the former mesher)
    assert _radius(checked.curvature, checked.axial_stretch) == pytest.approx(3.5277e-3, rel=2e-4)
