"""Rod rung: the section's moment-curvature law, the rod statics with tip force, gravity and tip
contact, and its refusals. Coarse section mesh (D/8) and a small table keep this fast; the
production numbers (D/20) are in docs/models/rod.md and benchmarks/blocking_force.py."""
import dataclasses

import numpy as np
import pytest

from softcath_ros.core.errors import ModelError
from softcath_ros.core.models import make_model
from softcath_ros.core.prediction import predict
from softcath_ros.core.rod.law import LawRangeError, LinearLaw
from softcath_ros.core.rod.statics import PlanarLoads, solve_rod
from softcath_ros.core.rod.loads import TipPlaneContact
from softcath_ros.core.rod.section_law import LawGrid
from softcath_ros.core.section_fe.moment import HeldSection
from softcath_ros.core.section_properties import transformed_section

COARSE = dict(mesh_size=0.005 / 8)

GRID = LawGrid(kappa_min=-60.0, kappa_max=80.0, kappa_step=10.0, pressure_max=15000.0, pressure_step=2500.0)
L = 0.017


@pytest.fixture(scope="module")
def design():
    from softcath_ros.core.design import load_design

    return load_design("implemented_5mm").with_length(L)


@pytest.fixture(scope="module")
def free_rod(design):
    return make_model("rod", design, grid=GRID, cache=False, **COARSE)


def _rod(design, base, **loads):
    """A rod with loads sharing ``base``'s law (a rod or a law: the table is built once per module)."""
    rod = make_model("rod", design, source="closed_form", **loads)
    rod.law = getattr(base, "law", base)
    return rod


def test_held_section_carries_no_moment_at_its_free_state_and_EI_kappa_at_rest(design):
    sec = make_model("section", design, **COARSE)
    held = HeldSection(sec.problem, (0.0, -1.0))
    for p in (5000.0, 12500.0):
        st = sec.evaluate(np.array([p]))
        kappa = float(-st.curvature[1] * st.axial_stretch)      # rotation rate per reference length
        corr = held.solve(sec._states[(p,)], kappa, np.array([p]))
        assert corr.converged
        m = held.result(corr.state, np.array([p])).moment
        assert abs(m) < 1e-6 * 9e-6 * kappa                     # vs EI kappa: zero to solver tolerance
    # without the hoop rings the section at rest is the closed form's transformed section
    bare = dataclasses.replace(design, reinforcement=None)
    sec0 = make_model("section", bare, **COARSE)
    held0 = HeldSection(sec0.problem, (0.0, -1.0))
    x0 = sec0.problem.consistent_pressures(sec0.problem.initial_state())
    corr = held0.solve(x0, 1.0, np.zeros(1))
    ei = transformed_section(bare).bending_stiffness[1, 1]
    assert held0.result(corr.state, np.zeros(1)).moment == pytest.approx(ei * 1.0, rel=0.02)


def test_the_rings_bending_stiffness_carries_the_held_section_past_the_element_scale_wrinkle(design):
    """Bent at p = 0 the held section compresses the hoop rings; as strings they wrinkle at the element
    scale: a limit point at a curvature proportional to the element size (21.8 1/m at D/8, 15.6 at
    D/12). With their own bending stiffness E I / pitch (``ring_bending``) the branch reaches 80 1/m on
    both meshes, with moments within 2 % of each other (D/8 vs D/12: 1.7 % at 80 1/m)."""
    from softcath_ros.core.section_fe.moment import moment_curvature
    from softcath_ros.core.section_fe.settings import SectionSettings, discretise

    assert SectionSettings().key()["ring_bending"]              # on by default (section-8)
    body = dataclasses.replace(design, device=None)
    ks = np.arange(0.0, 81.0, 10.0)
    moments = {}
    for n in (8, 12):
        for bending in (False, True):
            settings = SectionSettings(mesh_size=design.outer_diameter / n, ring_bending=bending)
            table = moment_curvature(discretise(body, settings).problem, settings, [0.0], ks)
            moments[n, bending] = table.moment[:, 0]
    ends = {n: ks[np.isfinite(moments[n, False])].max() for n in (8, 12)}
    assert ends[12] < ends[8] < 30.0
    assert np.isfinite(moments[8, True]).all() and np.isfinite(moments[12, True]).all()
    np.testing.assert_allclose(moments[12, True], moments[8, True], rtol=0.02)
    # at small curvature the rings' bending adds little to E I kappa
    assert moments[8, True][1] == pytest.approx(moments[8, False][1], rel=5e-3)


def test_held_law_has_only_stable_states_past_the_lumens_folding_shoulders(design):
    """From 0.2625 bar (D/8) Newton's held-straight state was a saddle (the lumen's shoulders fold:
    two negative directions) and bending from it stalled at 16 1/m: the law recorded an unstable
    state and ended early. The held section keeps only states of positive definite tangent."""
    from softcath_ros.core.continuation import StepControl, ramp
    from softcath_ros.core.section_fe.moment import moment_curvature
    from softcath_ros.core.section_fe.settings import SectionSettings, discretise

    settings = SectionSettings(**COARSE)
    problem = discretise(dataclasses.replace(design, device=None), settings).problem
    table = moment_curvature(problem, settings, [0.0, 8750.0, 17500.0, 26250.0], [-25.0, 0.0, 25.0, 50.0])
    assert np.isfinite(table.moment[:, 1:]).all(), table.messages
    # the held-straight state at 0.2625 bar: no negative eigenvalue of the held (reduced) tangent
    held = HeldSection(problem, table.direction)
    rest = problem.consistent_pressures(problem.initial_state())
    straight = ramp(lambda guess, t, prev: held.solve(guess, 0.0, np.array([t]), snap=True), rest, [26250.0],
                    StepControl(initial_step=2000.0, max_step=4000.0, min_step=50.0))
    assert straight.converged, straight.message
    x = straight.last_state
    _, g, K, _ = problem.assemble(x, np.array([26250.0]) / problem.c_ref)
    _, reduced = held.reduce(x, g, K)
    free = np.ones(problem.n, dtype=bool)
    free[problem.pinned] = False
    free[held.i_k] = False
    assert np.linalg.eigvalsh(reduced.toarray()[np.ix_(free, free)]).min() > 0


def test_unloaded_rod_is_its_source_rung(design, free_rod):
    sec = make_model("section", design, **COARSE)
    p = np.array([[2500.0], [7500.0], [12500.0]])
    a, b = free_rod.evaluate(p), sec.evaluate(p)
    assert a.converged.all()
    np.testing.assert_allclose(a.curvature, b.curvature, rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(a.axial_stretch, b.axial_stretch, rtol=1e-4)
    # the backbone is the source's arc over the channelled part and the straight cap beyond it:
    # tip angle = |k| * its arc length, the tip where the section rung's prediction puts it; it bends to -y
    cap = design.cap_thickness
    assert a.tip.angle[2] == pytest.approx(-b.curvature[2, 1] * b.axial_stretch[2] * (L - cap), rel=2e-3)
    np.testing.assert_allclose(a.tip.position[2], predict(sec, p[2:])[0].tip_position_m, rtol=0, atol=2e-3 * L)
    assert a.tip.position[2, 1] < 0 and a.contact_force is None   # nothing to touch


@pytest.mark.parametrize("length", [0.020, 0.040])
def test_unloaded_rod_has_the_section_rungs_tip_angle_and_rc_with_the_same_straight_cap(design, free_rod, length):
    """rod-3: same law, same rigid straight cap as the arc rungs, so an unloaded rod of any length has
    the section rung's tip angle theta = |k| lambda (l - cap) and R_C = l / theta: to the law's
    interpolation (1e-4) at its grid pressures (2500, 7500 Pa) and between them (11250 Pa). A cap that bent
    with the body would be cap / (l - cap) off: 5.3 % at 20 mm, 2.6 % at 40 mm."""
    sec = make_model("section", design, **COARSE)
    for p in (2500.0, 7500.0, 11250.0):
        a, b = predict(free_rod, np.array([[p]]), length)[0], predict(sec, np.array([[p]]), length)[0]
        assert a.converged and b.converged
        assert a.bending_angle_rad == pytest.approx(b.bending_angle_rad, rel=1e-4)   # coarse law: <= 1.3e-5
        assert a.radius_of_curvature_m == pytest.approx(b.radius_of_curvature_m, rel=1e-4)
        np.testing.assert_allclose(a.tip_position_m, b.tip_position_m, rtol=0, atol=1e-4 * length)


@pytest.mark.parametrize("cap_share", [0.0, 0.25, 0.5])
def test_rigid_tip_cap_matches_beam_theory(cap_share):
    """A linear rod of length L whose last c is rigid, a small tip force F: the tip deflects by
    F / EI (a^3 / 3 + a^2 c + a c^2) with a = L - c (the cantilever a, loaded at its end by F and by
    the moment F c, the cap turning with its end), not F L^3 / (3 EI) (c / L = 0.5: 12.5 % less)."""
    ei, f = 2e-6, 1e-5
    law = LinearLaw(ei, lambda p: 0.0, source="linear law")
    c = cap_share * L
    a = L - c
    sol = solve_rod(law.at(0.0), L, PlanarLoads(tip_force=(0.0, f)), n_segments=200, cap=c)
    assert sol.converged
    assert sol.positions[-1, 1] == pytest.approx(f / ei * (a ** 3 / 3 + a ** 2 * c + a * c ** 2), rel=2e-3)
    assert sol.positions[-1, 0] == pytest.approx(L, rel=1e-4)     # small deflection: the tip stays at L


def test_small_tip_force_matches_linear_beam_theory(design, free_rod):
    ei = float(free_rod.law.at(0.0).slope(0.0))                 # the law's stiffness at rest
    f = 2e-4                                                      # N, along +y: bends away from -y
    rod = _rod(design, free_rod, tip_force=[0.0, f, 0.0])
    st = rod.evaluate(np.array([0.0]))
    assert st.converged
    assert st.tip.position[1] == pytest.approx(f * L**3 / (3 * ei), rel=0.01)


def test_blocking_force_is_positive_and_grows_with_pressure(design, free_rod):
    rod = _rod(design, free_rod, contact=TipPlaneContact(normal=(0.0, 1.0, 0.0)))
    st = rod.evaluate(np.array([[0.0], [5000.0], [10000.0], [15000.0]]))
    force = st.contact_force
    assert st.converged.all() and force[0] == 0.0
    assert np.all(np.diff(force) > 0)
    # the tip stays on the scale, the body nearly straight
    assert abs(st.tip.position[3, 1]) < 1e-9


def test_no_contact_force_when_the_tip_moves_away(design, free_rod):
    away = _rod(design, free_rod, contact=TipPlaneContact(normal=(0.0, -1.0, 0.0)))
    st = away.evaluate(np.array([10000.0]))
    free = free_rod.evaluate(np.array([10000.0]))
    assert st.converged and st.contact_force == 0.0
    np.testing.assert_allclose(st.curvature, free.curvature)


def test_gravity_sags_the_right_way(design, free_rod):
    ei = float(free_rod.law.at(0.0).slope(0.0))
    for g in (-9.81, 9.81):
        rod = _rod(design, free_rod, gravity=[0.0, g, 0.0])
        st = rod.evaluate(np.array([0.0]))
        q = design.material.density * transformed_section(design).silicone_area * abs(g)
        sag = st.tip.position[1]
        assert np.sign(sag) == np.sign(g)
        assert abs(sag) == pytest.approx(q * L**4 / (8 * ei), rel=0.01)


def test_refusals_are_clear(design, free_rod):
    st = free_rod.evaluate(np.array([20000.0]))
    assert not st.converged and "outside the moment-curvature table" in st.message
    with pytest.raises(LawRangeError, match="outside the moment-curvature table"):
        free_rod.law.at(20000.0)
    with pytest.raises(LawRangeError, match="leave the moment-curvature table"):
        free_rod.law.at(5000.0).check(np.array([500.0]))
    # a tip force too large for the table: refused, not extrapolated
    big = _rod(design, free_rod, tip_force=[0.0, -0.5, 0.0])
    st = big.evaluate(np.array([0.0]))
    assert not st.converged and "leave the moment-curvature table" in st.message
    with pytest.raises(ModelError, match="out of the bending plane"):
        make_model("rod", design, source="closed_form", tip_force=[1e-3, 0.0, 0.0])
    from softcath_ros.core.design import load_design

    with pytest.raises(ModelError, match="one-channel designs"):
        make_model("rod", load_design("three_channel_5mm"), source="closed_form")


# --------------------------------------------------------------------------- the lumen fill (self-contact proxy)

FILL_GRID = LawGrid(kappa_min=-150.0, kappa_max=80.0, kappa_step=10.0, pressure_max=35000.0, pressure_step=5000.0)


@pytest.fixture(scope="module")
def filled_rod(design):
    return make_model("rod", design, grid=FILL_GRID, cache=False, lumen_fill=0.02, **COARSE)


def test_fill_carries_the_law_past_the_closing_lumen_and_keeps_the_small_pressure_law(design, free_rod, filled_rod):
    # without contact the held-straight empty section stops before 0.35 bar (the lumen closes; D/20: 0.306 bar)
    empty = make_model("rod", design, grid=FILL_GRID, cache=False, contact_distance=None, **COARSE)
    assert empty.law.pressure_range[1] < 35000.0
    assert filled_rod.law.pressure_range[1] == 35000.0
    assert "lumen fill 0.02" in filled_rod.law.source
    # below 0.15 bar the fill changes the law's moment by < 1 % (D/20: +0.2 % in the blocking force)
    for p in (5000.0, 10000.0):
        m0, m1 = free_rod.law.at(p).moment(-20.0), filled_rod.law.at(p).moment(-20.0)
        assert m1 == pytest.approx(m0, rel=0.01)
    # the straight body's blocking moment keeps growing with pressure
    assert filled_rod.law.at(35000.0).moment(0.0) < filled_rod.law.at(20000.0).moment(0.0) < 0


def test_blocking_capacity_at_035_bar_with_fill_is_positive_and_above_02_bar(design, filled_rod):
    rod = _rod(design, filled_rod, contact=TipPlaneContact(normal=(0.0, 1.0, 0.0)))
    st = rod.evaluate(np.array([[20000.0], [35000.0]]))
    f02 = st.contact_force[0]
    assert st.converged[0] and f02 > 0
    # at 0.35 bar the blocked base would need more moment than the bent-back section carries (its
    # moment saturates and falls: the section flattens), so the rod refuses instead of answering
    # (the base leaves the table, or the rod's Newton finds no state within it) ...
    assert not st.converged[1] and np.isnan(st.contact_force[1]) and "p = 35000 Pa" in st.message
    # ... and the capacity at the base, |M_lim| / l, is what the law says the bench could read at most
    m_lim, k_lim = filled_rod.law.at(35000.0).limit_moment()
    assert m_lim < 0 and k_lim <= 0
    assert abs(m_lim) / L > f02 > 0          # D/20: 54 mN at 0.35 bar vs 30.7 mN at 0.2 bar


# --------------------------------------------------------------------------- blocking to 0.35 bar: the base hinge


BLOCK_GRID = LawGrid(kappa_min=-150.0, kappa_max=300.0, kappa_step=25.0, pressure_max=35000.0, pressure_step=8750.0)


@pytest.fixture(scope="module")
def blocking_law(design):
    """A coarse lumen-contact law over the blocking bench's range (D/6, 5 pressures to 0.35 bar)."""
    return make_model("rod", design, grid=BLOCK_GRID, cache=False, mesh_size=0.005 / 6).law


def test_blocked_rod_converges_at_035_bar_with_its_base_hinged_at_the_limit_moment(design, blocking_law):
    from softcath_ros.bench.blocking import bench_contact

    rod = _rod(design, blocking_law)
    sols = {p: rod.solve(p, L, bench_contact(L)) for p in (17500.0, 26250.0, 35000.0)}
    assert all(s.converged for s in sols.values()), [s.message for s in sols.values()]
    f = {p: s.contact_force for p, s in sols.items()}
    assert np.isfinite(list(f.values())).all() and 0 < f[17500.0] < f[26250.0] < f[35000.0]
    hi = sols[35000.0]
    m_lim, k_lim = blocking_law.at(35000.0).limit_moment_if_peaked()
    # at 0.35 bar the base is a hinge at the section's limit moment, bent back (D/20: -0.82 rad) ...
    assert hi.hinge_moment == pytest.approx(m_lim) and hi.hinge_rotation < -0.1
    # ... so the force is that moment over the tip's lever arm (statics of the frictionless scale) ...
    assert hi.contact_force == pytest.approx(abs(m_lim) / hi.positions[-1, 0], rel=0.03)
    # ... the tip is on the scale and no segment is past the limit curvature
    assert abs(hi.positions[-1, 1]) < 1e-9 and hi.kappa.min() >= k_lim - 1e-9
    # below the limit the base stays clamped (D/20: to 0.2375 bar)
    assert sols[17500.0].hinge_moment is None and sols[17500.0].hinge_rotation == 0.0


def test_blocked_rod_without_a_known_capacity_stops_with_a_named_reason(design, blocking_law):
    """A table that ends before the section's moment peaks bent back cannot say what the base
    carries: the rod refuses with the reason named, never a number."""
    import dataclasses

    from softcath_ros.core.continuation import OUTSIDE_MODEL
    from softcath_ros.core.rod.law import TabulatedLaw
    from softcath_ros.core.rod.loads import TipPlaneContact

    t = blocking_law.table
    moment = t.moment.copy()
    moment[t.curvatures < -30.0] = np.nan            # the held section "stopped" at -30 1/m
    short = TabulatedLaw(dataclasses.replace(t, moment=moment), source="short law")
    rod = _rod(design, short, contact=TipPlaneContact(normal=(0.0, 1.0, 0.0)))
    st = rod.evaluate(np.array([[35000.0]]))
    assert not st.converged[0] and np.isnan(st.contact_force[0])
    assert "before the section's moment peaks" in st.message
    # the reason is tagged as every ramped rung tags it, and the ladder reads it from the tag
    from softcath_ros.core import ladder
    from softcath_ros.core.continuation import stop_tag

    assert stop_tag(OUTSIDE_MODEL) in st.message and ladder.stop_reason(st.message) == OUTSIDE_MODEL


def test_blocked_rod_ramps_on_the_shared_continuation_with_the_former_loops_answers(design, blocking_law, monkeypatch):
    """With the tip on the scale ``RodModel.solve`` ramps the pressure with core/continuation.ramp,
    one ramp per command. The forces are a regression lock to solver tolerance: recorded when the
    law last changed (section-8: the rings' own bending; the former fixed-step loop gave 25.76 /
    37.61 / 53.65 mN on the section-7 law); a ramp past the table's pressures stops, after its cuts,
    at the last pressure it reached, with the reason."""
    from softcath_ros.bench.blocking import bench_contact
    from softcath_ros.core.continuation import OUTSIDE_MODEL
    from softcath_ros.core.models import rod as rod_module

    ramps = []
    shared = rod_module.ramp

    def counted(*args, **kwargs):
        ramps.append(kwargs.get("describe"))
        return shared(*args, **kwargs)

    monkeypatch.setattr(rod_module, "ramp", counted)
    rod = _rod(design, blocking_law)
    rod.cap = 0.0   # the former loop's body had no rigid tip cap (rod-2)
    before = {17500.0: 0.026012936683294307, 26250.0: 0.04003119812673853, 35000.0: 0.05254788332790251}
    for p, force in before.items():
        sol = rod.solve(p, L, bench_contact(L))
        assert sol.converged and sol.contact_force == pytest.approx(force, rel=1e-6)
    assert len(ramps) == 3
    with pytest.raises(LawRangeError) as refused:
        rod.solve(36000.0, L, bench_contact(L))
    assert "last converged p = 0.35 bar" in str(refused.value) and "cut(s)" in str(refused.value)
    assert refused.value.stop_reason == OUTSIDE_MODEL


def test_a_batch_with_the_tip_on_the_scale_is_one_ramp_with_each_commands_answer(design, blocking_law, monkeypatch):
    """Commands in any order (repeats, 0, one past the table) are answered from one ramp through the
    sorted pressures, as each alone would be; so is the blocking force of several pressures, also
    through a calibration (the shift scales the ramp's pressures)."""
    from softcath_ros.bench.blocking import BlockingForce, bench_contact
    from softcath_ros.core.calibration_file import CalibratedModel
    from softcath_ros.core.continuation import OUTSIDE_MODEL, stop_tag
    from softcath_ros.core.models import rod as rod_module

    rod = _rod(design, blocking_law, contact=TipPlaneContact(normal=(0.0, 1.0, 0.0)))
    alone = {p: rod.solve(p).contact_force for p in (8750.0, 26250.0, 35000.0)}
    ramps = []
    shared = rod_module.ramp
    monkeypatch.setattr(rod_module, "ramp", lambda *a, **k: ramps.append(a[2]) or shared(*a, **k))
    st = rod.evaluate(np.array([[35000.0], [0.0], [8750.0], [36000.0], [26250.0], [8750.0]]))
    assert ramps == [[8750.0, 26250.0, 35000.0, 36000.0]]
    assert st.converged.tolist() == [True, True, True, False, True, True] and st.contact_force[1] == 0.0
    for i, p in ((0, 35000.0), (2, 8750.0), (4, 26250.0), (5, 8750.0)):
        assert st.contact_force[i] == pytest.approx(alone[p], rel=1e-9)
    assert np.isnan(st.contact_force[3]) and "command p = 36000 Pa" in st.message
    assert stop_tag(OUTSIDE_MODEL) in st.message and "last converged p = 0.35 bar" in st.message
    bench = [rod.solve(p, L, bench_contact(L)).contact_force for p in (8750.0, 26250.0)]
    ramps.clear()
    f = BlockingForce(rod)(np.array([[26250.0], [8750.0]]), L)
    assert len(ramps) == 1 and f.tolist() == pytest.approx(bench[::-1], rel=1e-9)
    shifted = BlockingForce(CalibratedModel(rod, 0.25))(np.array([[35000.0], [11666.666666666666]]), L)
    assert len(ramps) == 2 and shifted.tolist() == pytest.approx(bench[::-1], rel=1e-9)


# --------------------------------------------------------------------------- the lumen's snap across the dip

def _dip_law(ei=9e-6):
    """A tabulated law whose bent-back |M| = ei (kappa_free(p) + h(-kappa)) rises (h = -kappa), folds at
    -kappa ~ 40 1/m, dips (the lumen closing) to ~52 1/m, rises to its limit at ~103 1/m and falls; on
    the positive side it is linear (kappa_free = 100 1/m at 0.35 bar)."""
    from scipy.interpolate import CubicSpline

    from softcath_ros.core.rod.law import TabulatedLaw
    from softcath_ros.core.section_fe.moment import MomentTable

    h = CubicSpline([0, 10, 20, 30, 40, 50, 60, 80, 100, 120, 150], [0, 10, 20, 26, 28, 27, 27.5, 31, 33, 32, 29],
                    bc_type=((1, 1.0), (1, 0.0)))
    ks, ps = np.arange(-150.0, 300.0 + 1e-9, 5.0), np.arange(0.0, 35000.0 + 1e-9, 2500.0)
    kf = 100.0 * ps / 35000.0
    m = np.where(ks[:, None] < 0, -ei * (kf[None, :] + h(np.maximum(-ks, 0.0))[:, None]), ei * (ks[:, None] - kf[None, :]))
    return TabulatedLaw(MomentTable(curvatures=ks, pressures=ps, moment=m, stretch=np.ones_like(m), messages=[]),
                        source="dip law")


def test_a_blocked_segment_past_the_laws_fold_snaps_to_the_outer_branch(design):
    """The bent-back law folds before its limit (the lumen closing): ``snap_fold`` finds fold, dip and
    limit; a segment's snap (``statics._snap``) moves it to the outer branch with the same moment, and
    Newton from there converges to the state the blocked ramp reaches, with the base past the dip."""
    from softcath_ros.bench.blocking import bench_contact
    from softcath_ros.core.rod import statics

    law = _dip_law()
    sl = law.at(22500.0)
    k_fold, k_dip, k_lim = sl.snap_fold()
    assert -45 < k_fold < -35 and -60 < k_dip < -45 and -110 < k_lim < -95
    k_out = sl.outer_branch_curvature(sl.moment(-38.0))
    assert k_lim < k_out < k_dip and sl.moment(k_out) == pytest.approx(sl.moment(-38.0), rel=1e-4)
    assert sl.outer_branch_curvature(sl.moment(-5.0)) is None         # below the dip: one branch only
    assert law.at(0.0).snap_fold() is not None and _dip_law().at(35000.0).limit_moment_if_peaked()[1] == k_lim

    rod = _rod(design, law)
    loads = bench_contact(L)
    ps = np.arange(20000.0, 22500.0 + 1e-9, 125.0)
    sols = rod.solve(ps, L, loads)
    assert all(s.converged for s in sols)
    i = next(i for i, s in enumerate(sols) if s.kappa[0] < k_dip)   # the base segment snaps on the ramp ...
    before, after = sols[i - 1], sols[i]
    assert k_dip < before.kappa[0] < 0 and k_lim < after.kappa[0] < k_dip
    # the force grows on either side; at the snap the base softens and, the tip held, it drops a little
    f = np.array([s.contact_force for s in sols])
    assert np.all(np.diff(f[:i]) > 0) and np.all(np.diff(f[i:]) > 0) and 0.99 * f[i - 1] < f[i] < f[i - 1]
    sl = law.at(ps[i])                                              # ... and the snap predicts where to
    r = statics._Rod(sl, L, loads, rod.n_segments, rod.cap)
    start = statics._snap(r, sl, sl.snap_fold(), before.theta, set())
    assert start is not None and r.geometry(start)[0][0] < k_dip
    th, R, ok, _, _ = r.newton(start, before.contact_force, free_R=True, gap_row=True)
    assert ok and R == pytest.approx(after.contact_force, rel=1e-9)
    np.testing.assert_allclose(th, after.theta, atol=1e-9)
    # the ramp goes on to 0.35 bar with the base hinged at the limit moment
    end = rod.solve(35000.0, L, loads)
    assert end.converged and end.hinge_moment is not None and end.hinge_rotation < 0
