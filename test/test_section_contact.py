"""Self-contact of the lumen wall in the section rung (core/section_fe/terms/contact.py).

Fast cases on coarse meshes: the term's derivatives, a flat wall pressed on a rigid flat wall
(hand solution), no interpenetration at any converged step of a 0 -> 0.5 bar sweep, and R_C at
0.35 bar independent of the barrier distance. Figures they were set against:
docs/models/section.md (contact)."""
import numpy as np
import pytest

import softcath_ros.core.section_fe.solver as solver_module
from softcath_ros.core.models import make_model
from softcath_ros.core.section_fe.terms.contact import WallContact, barrier, line_distance2, window

BAR = 1e5


def _radius(k, stretch):
    return 1.0 / (float(np.hypot(*k)) * float(stretch))


def test_line_distance_and_window_derivatives_match_finite_differences():
    rng = np.random.default_rng(5)
    z = rng.standard_normal((4, 6))
    s, t, ds, dt, d2s, d2t = line_distance2(z[:, 0:2], z[:, 2:4], z[:, 4:6])
    eps = 1e-6
    for i in range(6):
        zp, zm = z.copy(), z.copy()
        zp[:, i] += eps
        zm[:, i] -= eps
        fp, fm = line_distance2(zp[:, 0:2], zp[:, 2:4], zp[:, 4:6]), line_distance2(zm[:, 0:2], zm[:, 2:4], zm[:, 4:6])
        np.testing.assert_allclose(ds[:, i], (fp[0] - fm[0]) / (2 * eps), rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(dt[:, i], (fp[1] - fm[1]) / (2 * eps), rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(d2s[:, :, i], (fp[2] - fm[2]) / (2 * eps), rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(d2t[:, :, i], (fp[3] - fm[3]) / (2 * eps), rtol=1e-5, atol=1e-7)
    # the windows of two collinear neighbours sum to one; C2 steps; the barrier is C2 at s_hat
    t = np.linspace(0.6, 1.4, 33)
    np.testing.assert_allclose(window(t)[0] + window(t - 1)[0], 1.0, atol=1e-12)
    assert window(np.array([-0.26, 1.26]))[0].max() == 0.0
    b = barrier(np.array([1.0 - 1e-9]), 1.0)
    assert max(abs(v[0]) for v in b) < 1e-7


def _squeezed(problem, squeeze):
    """The lumen wall flattened towards its centre line (the rest of the body untouched)."""
    _, wall = problem.contact[0]
    x = problem.initial_state()
    u = x[:problem.n_u].reshape(-1, 2)
    P = problem.X[wall.ids]
    yc = P[:, 1].mean()
    u[wall.ids, 1] = (yc + squeeze * (P[:, 1] - yc)) - P[:, 1]
    return x, wall


def test_contact_term_gradient_and_hessian_match_finite_differences(implemented_design):
    problem = make_model("section", implemented_design, mesh_size=implemented_design.outer_diameter / 12).problem
    x, wall = _squeezed(problem, 0.012)
    c = wall.assemble(x, None)
    assert c.energy > 0 and c.energy == pytest.approx(wall.energy(x, None), rel=1e-12)
    g = np.zeros(problem.n)
    np.add.at(g, wall.dofs[0], c.gradient[0])
    eps = 1e-8
    rng = np.random.default_rng(0)
    for i in rng.choice(wall.dofs[0], 8, replace=False):
        xp, xm = x.copy(), x.copy()
        xp[i] += eps
        xm[i] -= eps
        assert g[i] == pytest.approx((wall.energy(xp, None) - wall.energy(xm, None)) / (2 * eps), rel=1e-5, abs=1e-6)
        k = int(np.flatnonzero(wall.dofs[0] == i)[0])
        h_fd = (wall.assemble(xp, None).gradient[0] - wall.assemble(xm, None).gradient[0]) / (2 * eps)
        np.testing.assert_allclose(c.hessian[0][:, k], h_fd, rtol=1e-4, atol=1e-6 * np.abs(h_fd).max())
    # walls passed through each other: inadmissible, so Newton backtracks instead of tunnelling
    crossed = problem.initial_state()
    P = problem.X[wall.ids]
    upper = wall.ids[P[:, 1] > P[:, 1].mean()]
    crossed[2 * upper + 1] = -1.6 * implemented_design.lumen.radius / problem.R   # the upper half pushed through
    assert wall.energy(crossed, None) == np.inf and wall.min_gap(crossed) < 0


def _brute_force_active(wall, x):
    """What ``WallContact._active`` stands for, over every pair: the pairs within the barrier's range,
    or None where the wall polygon crosses itself."""
    from softcath_ros.core.section_fe.terms.contact import WINDOW, segments_cross

    P = wall._points(x)
    if np.any(segments_cross(P, wall.cross_i, wall.cross_j)):
        return None
    s, t = line_distance2(*wall._pair_points(P), derivatives=False)
    return np.flatnonzero((s < wall.s_hat) & (t > -WINDOW) & (t < 1 + WINDOW))


@pytest.mark.parametrize("squeeze", [1.0, 0.2, 0.03, 0.012, 0.005, -0.3])
def test_the_contact_broad_phase_finds_exactly_the_pairs_every_pair_would(implemented_design, squeeze):
    """The broad phase (segment midpoints in a k-d tree) keeps the same pairs, in the same order, as
    testing every vertex against every segment, from a round lumen to one squeezed flat within the
    barrier's range and one whose halves have passed through each other (inadmissible)."""
    problem = make_model("section", implemented_design, mesh_size=implemented_design.outer_diameter / 12).problem
    x, wall = _squeezed(problem, squeeze)
    got, want = wall._active(x), _brute_force_active(wall, x)
    if want is None:
        assert squeeze < 0 and got is None
        return
    np.testing.assert_array_equal(got[1], want)
    if squeeze in (1.0, 0.2):
        assert len(want) == 0             # open: nothing within range
    if squeeze in (0.012, 0.005):
        assert len(want) > 0              # squeezed flat: the walls within the barrier's range


def test_the_broad_phase_shortcut_for_a_clear_wall_changes_no_answer(implemented_design, monkeypatch):
    """Where no pair was a candidate, ``_active`` skips the search while the wall has moved by less
    than a ninth of the margin it found (but for a common translation): along a lumen squeezed from
    round to flat and through itself, in steps from 1e-7 to 0.3 of its height, and moved as a whole,
    every answer is the search over every pair, and the shortcut was taken."""
    problem = make_model("section", implemented_design, mesh_size=implemented_design.outer_diameter / 12).problem
    wall = problem.contact[0][1]
    searches = []
    search = wall._candidates
    monkeypatch.setattr(wall, "_candidates", lambda P: searches.append(1) or search(P))
    squeezes = np.concatenate([1 - np.geomspace(1e-7, 0.3, 25), np.linspace(0.6, 0.005, 25), [-0.3]])
    for i, squeeze in enumerate(squeezes):
        x = _squeezed(problem, squeeze)[0]
        got, want = wall._active(x), _brute_force_active(wall, x)
        assert (got is None) == (want is None), squeeze
        if want is not None:
            np.testing.assert_array_equal(got[1], want)
    assert 0 < len(searches) < len(squeezes)         # searched where it had to, not every time
    # a wall moved as a whole changes no distance: no search, the same (empty) answer
    x = _squeezed(problem, 1.0)[0]
    wall._active(x)
    before = len(searches)
    x.reshape(-1)[2 * wall.ids] += 0.1
    x.reshape(-1)[2 * wall.ids + 1] -= 0.05
    np.testing.assert_array_equal(wall._active(x)[1], _brute_force_active(wall, x))
    assert len(searches) == before


def test_flat_wall_pressed_on_a_rigid_wall_balances_the_load_at_the_hand_solution_gap():
    """A long slit: its bottom wall is rigid, its top wall (free vertically) carries a line load
    q per unit length. Far from the ends the gap d is uniform and solves
    q = -4 kappa d b'(d^2) (each wall's vertices see a partition of unity of the other's
    segments), and the rigid wall's reaction equals the load."""
    n, length, d_hat, q = 60, 2.0, 0.01, 0.5
    xs = np.linspace(-length / 2, length / 2, n + 1)
    bottom = np.column_stack([xs, np.zeros_like(xs)])
    top = np.column_stack([xs[::-1], np.full_like(xs, 0.8 * d_hat)])
    X = np.concatenate([bottom, top])                    # counter-clockwise about the slit
    m = len(X)
    edges = np.column_stack([np.arange(0, m, 2), np.arange(1, m, 2), (np.arange(2, m + 2, 2)) % m])
    wall = WallContact(X, edges, d_hat, 2 * m)
    free = np.arange(n + 1, 2 * n + 2)                  # the top wall's vertices
    load = q * wall.weight[free]
    x = np.zeros(2 * m)
    for _ in range(60):
        c = wall.assemble(x, None)
        g = c.gradient[0][2 * free + 1] + load           # d(Pi_c + q sum l_i u_y)/du_y: load downwards
        H = c.hessian[0][np.ix_(2 * free + 1, 2 * free + 1)]
        dy = np.linalg.solve(H, -g)
        a = min(1.0, 0.2 * d_hat / np.abs(dy).max())      # stay within the barrier's reach
        while True:
            trial = x.copy()
            trial[2 * free + 1] += a * dy
            if np.isfinite(wall.energy(trial, None)):
                break
            a *= 0.5
        x = trial
        if np.abs(dy).max() < 1e-13:
            break
    c = wall.assemble(x, None)
    np.testing.assert_allclose(-c.gradient[0][2 * free + 1], load, rtol=1e-8)    # equilibrium
    # the rigid wall's reaction (the contact force on it, -dPi_c/du_y) carries the whole load
    assert -c.gradient[0][1:2 * (n + 1):2].sum() == pytest.approx(-load.sum(), rel=1e-9)
    gap = 0.8 * d_hat + x[2 * free + 1]
    mid = gap[len(gap) // 3: 2 * len(gap) // 3]
    # hand solution: bisection on q = -4 kappa d b'(d^2)
    lo, hi = 1e-9, d_hat
    for _ in range(200):
        d = 0.5 * (lo + hi)
        f = -4 * wall.kappa * d * barrier(np.array([d * d]), d_hat**2)[1][0] - q
        lo, hi = (d, hi) if f > 0 else (lo, d)
    assert mid.min() > 0
    np.testing.assert_allclose(mid, d, rtol=1e-3)


@pytest.fixture
def converged_states(monkeypatch):
    """Every converged Newton state of the section rung during a test."""
    states = []
    original = solver_module.newton

    def recording(problem, *args, **kwargs):
        corr = original(problem, *args, **kwargs)
        if corr.converged:
            states.append((problem, corr.state))
        return corr

    monkeypatch.setattr(solver_module, "newton", recording)   # (the rung imports it where it is used)
    return states


def test_lumen_walls_never_interpenetrate_up_to_the_design_limit(implemented_design, converged_states):
    d = implemented_design
    model = make_model("section", d, mesh_size=d.outer_diameter / 12)
    ps = np.linspace(0.0, 0.5 * BAR, 11)[:, None]
    state = model.evaluate(ps)
    assert state.converged.all(), state.message
    r = [_radius(k, s) for k, s in zip(state.curvature[1:], state.axial_stretch[1:])]
    assert np.all(np.diff(r) < 0)
    gaps = [problem.contact_min_gap(x) for problem, x in converged_states]
    assert len(gaps) >= 10
    assert min(gaps) > 0                                # strictly apart: the barrier keeps them so
    x = model._states[(0.5 * BAR,)]
    problem = model.problem
    # the walls are in contact there (within the barrier's reach), not merely close
    assert problem.contact_min_gap(x) < problem.contact[0][1].d_hat * problem.R
    assert problem.hole_gaps(x)[-1] < model.settings.min_hole_gap   # the empty rung would have stopped


def test_radius_at_035_bar_does_not_depend_on_the_barrier_distance(implemented_design):
    d = implemented_design
    radii = []
    for distance in (0.005, 0.02):
        s = make_model("section", d, mesh_size=d.outer_diameter / 12, contact_distance=distance).evaluate([0.35 * BAR])
        assert s.converged, s.message
        radii.append(_radius(s.curvature, s.axial_stretch))
    # measured: 3.526 and 3.534 mm (D/12), 3.516 and 3.523 mm (D/20)
    assert abs(radii[1] / radii[0] - 1) < 0.005


def test_without_contact_the_empty_lumen_stops_where_its_walls_touch(implemented_design):
    d = implemented_design
    state = make_model("section", d, mesh_size=d.outer_diameter / 12, contact_distance=None).evaluate([0.35 * BAR])
    assert not state.converged and "lumen" in state.message


def test_a_device_in_the_lumen_is_never_entered_by_the_wall(implemented_design, converged_states):
    import dataclasses

    from softcath_ros.core.design import Device

    d = dataclasses.replace(implemented_design, device=Device(diameter=1.0e-3, bending_stiffness=2e-6))
    model = make_model("section", d, mesh_size=d.outer_diameter / 12)
    problem, term = model.problem, model.problem.device
    assert term is not None and problem.device_node == problem.n_u // 2 - 1
    # derivatives against finite differences with the device 5 um from the wall
    x = problem.initial_state()
    x[2 * problem.device_node + 1] = -(d.lumen.radius - 0.5e-3 - 5e-6) / problem.R
    c = term.assemble(x, None)
    assert c.energy > 0 and c.energy == pytest.approx(term.energy(x, None), rel=1e-12)
    eps = 1e-7
    for i in list(term.dofs[0][-2:]) + [2 * term.ids[term.m * 3 // 4] + 1]:
        xp, xm = x.copy(), x.copy()
        xp[i] += eps
        xm[i] -= eps
        k = int(np.flatnonzero(term.dofs[0] == i)[0])
        assert c.gradient[0][k] == pytest.approx((term.energy(xp, None) - term.energy(xm, None)) / (2 * eps),
                                                 rel=1e-5, abs=1e-9)
        h_fd = (term.assemble(xp, None).gradient[0] - term.assemble(xm, None).gradient[0]) / (2 * eps)
        np.testing.assert_allclose(c.hessian[0][:, k], h_fd, rtol=1e-4, atol=1e-5 * np.abs(h_fd).max())
    # 0 -> 0.5 bar: the wall closes onto the device and never enters it
    ps = np.linspace(0.0, 0.5 * BAR, 6)[:, None]
    state = model.evaluate(ps)
    assert state.converged.all(), state.message
    gaps = [pr.device_min_gap(xs) for pr, xs in converged_states if pr is problem]
    assert min(gaps) > 0
    last = model._states[(0.5 * BAR,)]
    assert problem.device_min_gap(last) < term.d_hat * problem.R       # in contact there
    # measured (D/12): R_C 4.88 mm at 0.35 bar with the device against 3.53 mm without
    bare = make_model("section", implemented_design, mesh_size=d.outer_diameter / 12).evaluate([0.5 * BAR])
    assert _radius(state.curvature[-1], state.axial_stretch[-1]) > _radius(bare.curvature, bare.axial_stretch)


def test_every_channel_of_the_three_channel_design_reaches_the_design_limit_alike():
    """The 3-channel design on its default (3-fold symmetric) mesh: each channel alone reaches
    0.5 bar with lumen contact and bends the same, turned by 120 degrees (channel 0 used to stop
    at 0.481 bar: the secant predictor pushed the lumen walls through each other, and the ramp
    then cut its steps down to a numerical failure). Alike in magnitude to 2 % and in direction to
    0.2 deg, not to round-off and not to issue 36's 0.1 % / 0.1 deg: the mesh is 3-fold symmetric to
    round-off, but near 0.5 bar the folding lumen has neighbouring stable states and the two ramps
    end in different ones (section-8: 182.48 and 183.54 1/m, 0.6 % apart, turned by 120.10 deg)."""
    from softcath_ros.core.design import load_design

    d = load_design("three_channel_5mm")
    k = []
    for i in (0, 1):
        p = np.zeros(3)
        p[i] = 0.5 * BAR
        state = make_model("section", d).evaluate(p)
        assert state.converged, state.message
        k.append(state.curvature)
    assert np.hypot(*k[1]) == pytest.approx(np.hypot(*k[0]), rel=0.02)
    assert np.degrees(np.arctan2(k[1][1], k[1][0]) - np.arctan2(k[0][1], k[0][0])) % 360 == pytest.approx(120.0, abs=0.2)
