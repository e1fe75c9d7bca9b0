"""3D finite-element rung (fe3d): geometry, physics direction, symmetry, failure reporting,
cache and command line. Coarse meshes and short bodies keep these fast; the accuracy
validation against the published FE (40 mm, 0.15/0.20 bar) and the mesh study live in
benchmarks/fe3d_sweep.py and docs/validation.md, with one slow check here."""
from __future__ import annotations

import dataclasses
import json
import math
import re
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("ngsolve", reason="fe3d needs the 'fe' extra (scripts/test.sh installs it)")

from softcath_ros.core.fe3d.mesh import MeshSettings  # noqa: E402
from softcath_ros.core.fe3d.ramp import default_step_control  # noqa: E402
from softcath_ros.core.fe3d.newton_settings import NewtonSettings  # noqa: E402
from softcath_ros.core.models import make_model  # noqa: E402
from softcath_ros.core.errors import ModelError  # noqa: E402
from softcath_ros.core.models.fe3d import Fe3dModel  # noqa: E402
from softcath_ros.experimental.fe3d_variants import Fe3dVariantModel  # noqa: E402

COARSE = MeshSettings(section_h=1.0e-3, wall_h=0.7e-3, layer_h=4.5e-3, cap_layers=1)
# Plain P2 / P0, for the tests that impose a displacement field by GridFunction.Set or read a mode's
# seminorm back: Set interpolates into the default element's prism bubbles only approximately, and the
# condensed modes carry no bubble part.
PLAIN_P2 = {"pressure_order": 0, "interior_order": None}


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SOFTCATH_CACHE", str(tmp_path / "cache"))


@pytest.fixture
def short_design(implemented_design):
    return implemented_design.with_length(0.010)


# Steps as large as Newton takes from the straight state on the coarse 10 mm body, for the tests about
# an equilibrium state, not the ramp to it (an elastic body without contact: the state does not depend
# on the path).
BIG_STEPS = dataclasses.replace(default_step_control(step=5000.0), max_step=5000.0)
BASE_LOADS = (0.0, 5000.0, 8000.0, 10000.0)


@pytest.fixture(scope="module")
def base_ramp():
    """The coarse 10 mm body of the implemented design (half model, default settings) at BASE_LOADS
    (Pa, the rows of the returned BendState), solved once for the tests that use or compare with it."""
    from softcath_ros.core.design import load_design

    design = load_design("implemented_5mm").with_length(0.010)
    state = Fe3dModel(design, mesh=COARSE, cache=False, step_control=BIG_STEPS).evaluate(
        np.array(BASE_LOADS)[:, None])
    assert state.converged.all(), state.message
    return state


def test_mesh_volumes_are_exact(short_design):
    """Body and channel volumes of the (half) mesh equal the design's, so the pressure's
    work is not biased by the polygonal circles."""
    model = Fe3dModel(short_design, mesh=COARSE, cache=False)
    pb = model.problem
    d = short_design
    holes = sum(h.area for h in d.channels) + d.lumen.area
    body = math.pi * d.outer_radius**2 * d.length - holes * d.length + d.channels[0].area * d.cap_thickness
    assert pb.half
    assert pb.reference_volume == pytest.approx(body, rel=1e-9)
    v_channel = d.channels[0].area * (d.length - d.cap_thickness)
    assert pb.channel_volumes()[0] == pytest.approx(v_channel, rel=1e-9)


def test_bends_away_from_the_channel_and_inflates(short_design, base_ramp):
    state = base_ramp        # rows 0, 1 and 3: 0, 0.05 and 0.10 bar
    k = state.curvature[[0, 1, 3]]
    assert k[0] == pytest.approx([0.0, 0.0], abs=1e-12)
    # channel at +y lengthens the +y side: the backbone bends towards -y, more with pressure
    assert k[1, 1] < 0 and k[2, 1] < 1.5 * k[1, 1]
    assert abs(k[2, 0]) < 1e-6 * abs(k[2, 1])
    vol = state.diagnostics.channel_volume
    assert vol[3][0] > vol[1][0] > short_design.channels[0].area * (short_design.length - short_design.cap_thickness)
    assert state.diagnostics.channel_area[3][0] > short_design.channels[0].area
    angle = state.tip.angle[3]
    assert state.radius_l_over_theta[3] == pytest.approx(short_design.length / angle)
    assert state.diagnostics.newton_iterations[3] >= 1


def test_half_model_matches_full_model(short_design, base_ramp):
    """The symmetry cut must not change the answer."""
    p = np.array([[8000.0]])
    half_k = base_ramp.curvature[BASE_LOADS.index(8000.0)]
    full = Fe3dModel(short_design, mesh=COARSE, cache=False, half=False, step_control=BIG_STEPS)
    assert not full.problem.half
    full_state = full.evaluate(p)
    assert full_state.converged.all(), full_state.message
    # the two meshes differ (netgen meshes the full disk differently), so agree to mesh error
    assert full_state.curvature[0, 1] == pytest.approx(half_k[1], rel=0.03)
    # netgen does not mesh the full disk mirror-symmetrically: a small sideways bend is mesh error
    assert abs(full_state.curvature[0, 0]) < 1e-2 * abs(full_state.curvature[0, 1])


def test_rings_stop_the_channel_ballooning(short_design, base_ramp):
    """Without the hoop membrane (reinforcement: null) the channel inflates much more."""
    p = np.array([[8000.0]])
    no_rings = Fe3dModel(dataclasses.replace(short_design, reinforcement=None), mesh=COARSE,
                         cache=False, step_control=BIG_STEPS).evaluate(p)
    assert no_rings.converged.all(), no_rings.message
    # without rings the channel balloons: much more volume
    assert no_rings.diagnostics.channel_volume[0][0] > \
        1.05 * base_ramp.diagnostics.channel_volume[BASE_LOADS.index(8000.0)][0]


def test_non_convergence_is_reported_not_hidden(short_design):
    """A deliberately tiny iteration budget: the rung says so and returns no numbers."""
    model = Fe3dModel(short_design, mesh=COARSE, cache=False, newton=NewtonSettings(max_iterations=1))
    state = model.evaluate(np.array([[2000.0], [4000.0]]))
    assert not state.converged.any()
    assert "did not converge at p = " in state.message
    assert np.isnan(state.curvature).all()


def test_fixed_large_steps_fail_and_report_the_last_converged_pressure(short_design):
    """Step control off: plain load stepping with a huge step fails (no cutting), and the
    message names the pressure it failed at and the last one that converged."""
    control = dataclasses.replace(default_step_control(adaptive=False), initial_step=30000.0)
    model = Fe3dModel(short_design, mesh=COARSE, cache=False, step_control=control,
                      newton=NewtonSettings(max_iterations=8))
    state = model.evaluate(np.array([[30000.0]]))
    assert not state.converged[0]
    assert "did not converge at p = 0.3000 bar" in state.message
    assert "last converged p = 0.0000 bar" in state.message
    # an inverted element is located, so the report says what collapsed
    if "inverts an element" in state.message:
        assert re.search(r"most compressed: \w+ element at x = .* next to the (channel0 wall|lumen wall|outer "
                         r"surface), mean det F", state.message), state.message


def test_lumen_fill_is_a_soft_contact_proxy(short_design, base_ramp):
    """The soft lumen fill (self-contact proxy) barely changes bending while the lumen is open
    (< 1% in R_C at 0.10 bar), and a fraction outside (0, 1) is refused."""
    p = np.array([[10000.0]])
    filled = Fe3dModel(short_design, mesh=COARSE, cache=False, lumen_fill=0.01, step_control=BIG_STEPS)
    assert "fill" in filled.problem.mesh.GetMaterials()
    state = filled.evaluate(p)
    assert state.converged[0], state.message
    rc_empty = base_ramp.radius_l_over_theta[BASE_LOADS.index(10000.0)]
    rc_filled = state.radius_l_over_theta[0]
    assert rc_filled == pytest.approx(rc_empty, rel=0.01)
    assert rc_filled != rc_empty   # the fill is really in the model
    with pytest.raises(ModelError, match="lumen_fill"):
        Fe3dModel(short_design, mesh=COARSE, lumen_fill=1.5)
    with pytest.raises(ModelError, match="formulation"):
        Fe3dVariantModel(short_design, mesh=COARSE, formulation="reduced")
    with pytest.raises(TypeError, match="formulation"):   # comparison-only: not an option of the rung
        Fe3dModel(short_design, mesh=COARSE, formulation="displacement")


def test_results_are_cached_by_design_mesh_and_settings(short_design):
    p = np.array([[3000.0]])
    first = Fe3dModel(short_design, mesh=COARSE).evaluate(p)
    again = Fe3dModel(short_design, mesh=COARSE)
    second = again.evaluate(p)
    assert not again._problems  # answered from the cache, nothing was built
    np.testing.assert_allclose(second.curvature, first.curvature)
    finer = Fe3dModel(short_design, mesh=COARSE.scaled(0.8))
    assert finer.cache_key != again.cache_key
    other = Fe3dModel(short_design.with_length(0.012), mesh=COARSE)
    assert other.cache_key != again.cache_key


def test_make_model_and_predict_cli(short_design, tmp_path):
    model = make_model("fe3d", short_design, mesh_size=2.0)
    assert model.name == "fe3d"
    out = subprocess.run([sys.executable, "-m", "softcath_ros.cli", "predict", "--design", "implemented_5mm",
                          "--model", "fe3d", "--length", "0.01", "--pressure", "0.01", "--unit", "bar", "--json"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout)["results"][0]
    assert res["converged"] is True
    assert res["curvature_per_m"][1] < 0


def test_sweep_cli_writes_csv_json_png(tmp_path):
    prefix = tmp_path / "s"
    out = subprocess.run([sys.executable, "-m", "softcath_ros.cli", "sweep", "--design", "implemented_5mm",
                          "--model", "closed_form", "--from", "0", "--to", "0.2", "--steps", "5", "--unit", "bar",
                          "--out", str(prefix)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    doc = json.loads((tmp_path / "s.json").read_text())
    assert len(doc["results"]) == 5 and doc["results"][0]["pressure_pa"] == 0.0
    angles = [r["bending_angle_deg"] for r in doc["results"]]
    assert all(b > a for a, b in zip(angles, angles[1:]))
    assert (tmp_path / "s.csv").read_text().count("\n") == 6
    assert (tmp_path / "s.png").stat().st_size > 1000


def test_bending_angle_beyond_half_circle_from_tip():
    """The tip rotation alone is ambiguous past 180 degrees; the tip position decides."""
    from scipy.spatial.transform import Rotation

    from softcath_ros.core.fe3d.measure import bending_from_tip
    from softcath_ros.core.kinematics import tip_pose

    length = 0.02
    for deg, direction in ((30.0, -90.0), (170.0, -90.0), (200.0, -90.0), (250.0, 45.0), (0.0, 0.0)):
        theta = math.radians(deg)
        u = np.array([math.cos(math.radians(direction)), math.sin(math.radians(direction))])
        pos, quat = tip_pose(theta / length * u, length)
        rot = Rotation.from_quat(quat).as_matrix()
        got_theta, got_u = bending_from_tip(rot, pos)
        assert got_theta == pytest.approx(theta, abs=1e-9)
        if deg > 0:
            np.testing.assert_allclose(got_u, u, atol=1e-9)


def test_bending_angle_past_a_full_turn_from_the_section_at_mid_length():
    """Past a full turn the tip's rotation repeats, and near one the tip is back near the axis, where
    its position cannot tell theta from 2 pi - theta; the section at mid-length decides (the tip's
    position is not used), also when the two halves bend unequally (40 / 60 %)."""
    from scipy.spatial.transform import Rotation

    from softcath_ros.core.fe3d.measure import bending_with_mid
    from softcath_ros.core.kinematics import tip_pose

    length = 0.04
    for direction in (-90.0, 30.0):
        u = np.array([math.cos(math.radians(direction)), math.sin(math.radians(direction))])
        for deg in (0.0, 30.0, 170.0, 200.0, 340.0, 355.0, 359.0, 361.0, 370.0, 500.0, 580.0):
            theta = math.radians(deg)
            for first_half_share in (0.5, 0.4, 0.6):
                mid, q_mid = tip_pose(first_half_share * theta / (0.5 * length) * u, 0.5 * length)
                _, q_tip = tip_pose(theta / length * u, length)   # the tip's rotation: the total angle
                got, got_u = bending_with_mid(Rotation.from_quat(q_tip).as_matrix(),
                                              Rotation.from_quat(q_mid).as_matrix(), mid)
                assert got == pytest.approx(theta, abs=1e-9), (direction, deg, first_half_share)
                if 0 < deg % 360:
                    np.testing.assert_allclose(got_u, u, atol=1e-9)


def test_three_channel_design_with_a_central_lumen_bends_away_from_its_channel():
    """The 3-channel design's lumen is on the body axis, so the tip is carried by the tip face's
    rigid fit (there is no material at the axis to sample). One channel at +y bends to -y."""
    from softcath_ros.core.design import load_design

    design = load_design("three_channel_5mm").with_length(0.010)
    state = Fe3dModel(design, mesh=COARSE, cache=False, step_control=BIG_STEPS).evaluate(np.array([10000.0, 0.0, 0.0]))
    assert state.converged, state.message
    kx, ky = state.curvature
    assert ky < 0 and abs(math.degrees(math.atan2(kx, -ky))) < 2.0
    tip = np.asarray(state.tip.position)   # one command: no leading axis
    assert tip[1] < 0 and 0.009 < tip[2] < 0.0105


def test_discrete_rings_are_resolved_bands_on_the_outer_surface(short_design):
    """reinforcement='rings': one band per ring (floor(L / pitch) of them), each thread_diameter
    wide, on the outer surface; the membrane option keeps one 'outer' surface; bad names refused."""
    import ngsolve as ng

    rings = Fe3dVariantModel(short_design, mesh=COARSE, cache=False, reinforcement="rings").problem
    r = short_design.reinforcement
    n = int(short_design.length / r.pitch + 1e-9)
    band_area = ng.Integrate(ng.CF(1.0), rings.mesh, definedon=rings.mesh.Boundaries("ring")) * rings.mirror
    assert band_area == pytest.approx(n * r.thread_diameter * math.pi * short_design.outer_diameter, rel=0.01)
    membrane = Fe3dModel(short_design, mesh=COARSE, cache=False).problem
    assert "ring" not in membrane.mesh.GetBoundaries()
    with pytest.raises(ModelError, match="reinforcement"):
        Fe3dVariantModel(short_design, mesh=COARSE, reinforcement="helix")


def test_contact_barrier_is_c2_and_zero_beyond_its_distance():
    """The lumen contact's barrier beta(xi) (the section rung's b(s) on s = xi^2): zero with zero
    slope and curvature at xi = 1, its quadratic continuation below XI_MIN joins it C2, and it
    repels (beta' < 0) everywhere below xi = 1."""
    import ngsolve as ng

    from softcath_ros.core.fe3d.contact import XI_MIN, _barrier_parts, barrier_cf

    mesh = ng.Mesh(ng.unit_square.GenerateMesh(maxh=0.5))
    xi_param = ng.Parameter(0.5)
    cf = barrier_cf(xi_param)

    def beta(v):
        xi_param.Set(v)
        return cf(mesh(0.5, 0.5))

    for xi in (0.999999, 0.5, 0.1, XI_MIN * 1.0001, XI_MIN * 0.9999, 0.0, -0.05):
        h = 1e-6 * max(abs(xi), XI_MIN)
        slope = (beta(xi + h) - beta(xi - h)) / (2 * h)
        assert slope < 0, xi
    b, b1, b2 = _barrier_parts(1.0 - 1e-9)
    assert abs(b) < 1e-15 and abs(b1) < 1e-6 and abs(b2) < 1e-3
    assert beta(1.2) == 0.0
    for f in (lambda v: beta(v), lambda v: (beta(v + 1e-5) - beta(v - 1e-5)) / 2e-5):
        assert f(XI_MIN * (1 + 1e-7)) == pytest.approx(f(XI_MIN * (1 - 1e-7)), rel=1e-4)


def _polygon_gap_all_pairs(P, skip):
    """The lumen gap check's definition, every vertex against every segment: the reference for polygon_gap."""
    from softcath_ros.core.section_fe.terms.contact import point_segment_distance, segments_cross

    m = len(P)
    si, sk = np.triu_indices(m, k=2)
    far = (sk - si) <= m - 2
    crossing = segments_cross(P, si[far], sk[far])
    if np.any(crossing):
        i, k = si[far][crossing], sk[far][crossing]
        a, b, c, e = P[i], P[(i + 1) % m], P[k], P[(k + 1) % m]
        depth = np.min(np.stack([point_segment_distance(a, c, e), point_segment_distance(b, c, e),
                                 point_segment_distance(c, a, b), point_segment_distance(e, a, b)]), axis=0)
        return -max(float(np.max(depth)), 1e-15)
    vi, sj = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    off = (sj - vi) % m
    keep = (off >= skip) & (off <= m - skip - 1)
    return float(np.min(point_segment_distance(P[vi[keep]], P[sj[keep]], P[(sj[keep] + 1) % m])))


@given(seed=st.integers(0, 2**32 - 1), squeeze=st.floats(0.0, 1.08), m=st.integers(40, 400),
       skip=st.integers(1, 8))
@settings(max_examples=60, deadline=None)
def test_polygon_gap_equals_the_all_pairs_check(seed, squeeze, m, skip):
    """The lumen wall's gap check (a k-d tree on the segments) gives exactly the all-pairs answer on
    wiggly rings squeezed towards a slit (squeeze 1) and past it, where the two walls cross."""
    from softcath_ros.core.fe3d.wall_gap import polygon_gap

    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 2 * np.pi, m))
    r = 1.0 + 0.05 * rng.standard_normal(m)
    noise = 0.001 + 0.02 * max(0.0, squeeze - 0.95)   # the squeezed walls cross where they wiggle
    P = np.column_stack([r * np.cos(t), (1.0 - squeeze) * r * np.sin(t) + noise * rng.standard_normal(m)])
    assert polygon_gap(P, skip) == _polygon_gap_all_pairs(P, skip)


def test_lumen_gap_check_reads_each_state_once_and_as_located_point_by_point(short_design):
    """The gap check's wall points, located in the mesh once, deform as the displacement evaluated
    ring by ring at freshly located points; min_gap answers for the state it is asked at (the
    memo of the last state is dropped when the state changes: bending narrows the lumen)."""
    from softcath_ros.core.fe3d.wall_gap import min_wall_gap
    from softcath_ros.core.fe3d.measure import _evaluate

    from softcath_ros.core.fe3d.ramp import run_ramp

    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1).problem
    lc = pb.contact
    gap0 = lc.min_gap()
    ramp = run_ramp(pb, [1.0], [20000.0])   # bent: the lumen narrows
    assert ramp.converged, ramp.message
    sampling = lc._sampling
    batch = sampling.deformed(pb)
    ring = sampling.ring
    for k, zk in enumerate(sampling.levels):
        ref = np.column_stack([ring, np.full(len(ring), zk)])
        np.testing.assert_allclose(batch[k, 0], ref + _evaluate(pb, ref), rtol=0, atol=1e-15)
    gap1 = lc.min_gap()
    assert gap1 == min_wall_gap(pb, sampling)
    assert 0.0 < gap1 < gap0
    pb.set_state(np.zeros(pb.fes.ndof))
    assert lc.min_gap() == gap0


def test_lumen_wall_stretch_reads_a_homogeneous_deformation(short_design):
    """lumen_wall_stretch (the creasing diagnostic): under u = ((s - 1) x, (s - 1)(y - y_c), (a - 1) z)
    the lumen wall's hoop stretch is s and its axial stretch a everywhere; the smaller is the
    smallest principal surface stretch, and the normal stretch is 1 / (s a)."""
    import ngsolve as ng

    from softcath_ros.core.fe3d.measure import lumen_wall_stretch

    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, **PLAIN_P2).problem
    yc = short_design.lumen.center[1]
    for s, a in ((0.8, 1.1), (1.2, 0.9)):
        pb.u.Set(ng.CF(((s - 1) * ng.x, (s - 1) * (ng.y - yc), (a - 1) * ng.z)))
        w = lumen_wall_stretch(pb)
        assert w["min_hoop_stretch"] == pytest.approx(s, rel=1e-9)
        assert w["axial_stretch_there"] == pytest.approx(a, rel=1e-9)
        assert w["min_principal_stretch"] == pytest.approx(min(s, a), rel=1e-9)
        assert w["other_principal_there"] == pytest.approx(max(s, a), rel=1e-9)
        assert w["normal_stretch_there"] == pytest.approx(s, rel=1e-9)   # det F = s^2 a over s a
        assert w["min_det_f"] == pytest.approx(s * s * a, rel=1e-9)


@pytest.mark.parametrize("half", [True, False])
def test_outer_surface_stretch_reads_a_homogeneous_deformation(short_design, half):
    """outer_surface_stretch (the outer surface's creasing diagnostic): unloaded every stretch is 1;
    under u = ((s - 1) x, (s - 1) y, (a - 1) z) the hoop stretch is s and the axial one a all round,
    the smaller the smallest principal surface stretch, the normal stretch 1 / (s a) x det F = s.
    Its samples lie just inside the outer surface and go round it (the half model's half)."""
    import ngsolve as ng

    from softcath_ros.core.fe3d.measure import outer_surface_stretch

    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, half=half, **PLAIN_P2).problem
    w = outer_surface_stretch(pb, samples=True)
    for key in ("min_hoop_stretch", "axial_stretch_there", "min_principal_stretch", "other_principal_there",
                "normal_stretch_there", "min_det_f"):
        assert w[key] == pytest.approx(1.0, abs=1e-12), key
    r = np.hypot(w["points_m"][:, 0], w["points_m"][:, 1])
    big_r = short_design.outer_radius
    assert np.all(r < big_r * 1.01) and np.all(r > 0.97 * big_r)   # a hair inside the (snapped) polygon
    angle = np.degrees(np.arctan2(w["points_m"][:, 1], w["points_m"][:, 0]))
    assert np.ptp(angle) > (170.0 if half else 340.0)
    assert (np.all(w["points_m"][:, 0] > 0.0) if half else np.any(w["points_m"][:, 0] < 0.0))
    for s, a in ((0.8, 1.1), (1.2, 0.9)):
        pb.u.Set(ng.CF(((s - 1) * ng.x, (s - 1) * ng.y, (a - 1) * ng.z)))
        w = outer_surface_stretch(pb)
        assert w["min_hoop_stretch"] == pytest.approx(s, rel=1e-9)
        assert w["axial_stretch_there"] == pytest.approx(a, rel=1e-9)
        assert w["min_principal_stretch"] == pytest.approx(min(s, a), rel=1e-9)
        assert w["other_principal_there"] == pytest.approx(max(s, a), rel=1e-9)
        assert w["normal_stretch_there"] == pytest.approx(s, rel=1e-9)
        assert w["min_det_f"] == pytest.approx(s * s * a, rel=1e-9)


def test_pair_census_counts_the_walls_of_a_lumen_pressed_to_a_slit(short_design):
    """pair_census (the contact diagnosis): an open lumen has no pair in the barrier's range; squeezed
    to a slit narrower than d_hat (u_y = -(1 - eps)(y - y_c)), most of its wall is in range with a mean
    gap below d_hat, and no partner lies behind the primary."""
    import ngsolve as ng

    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02, **PLAIN_P2).problem
    wall_area = ng.Integrate(ng.CF(1.0), pb.mesh, ng.BND, definedon=pb.mesh.Boundaries("lumen"))
    census = pb.contact.pair_census()
    assert census["in_range"]["area_m2"] == 0.0 and census["behind"]["area_m2"] == 0.0
    yc = short_design.lumen.center[1]
    pb.u.Set(ng.CF((0.0, -(1.0 - 0.005) * (ng.y - yc), 0.0)))   # slit 1 % of the radius wide: d_hat / 4
    census = pb.contact.pair_census()
    assert 0.5 * wall_area < census["in_range"]["area_m2"] <= 1.001 * wall_area
    assert 0.0 < census["in_range"]["gap"] < pb.contact.d_hat
    assert census["behind"]["area_m2"] < 1e-3 * wall_area


def test_contact_option_checked(short_design):
    assert Fe3dModel(short_design, mesh=COARSE).contact_distance == 0.02   # on by default with a lumen
    assert Fe3dModel(short_design, mesh=COARSE, contact_distance=None).contact_distance is None
    assert Fe3dModel(short_design, mesh=COARSE, lumen_fill=0.01).contact_distance is None
    for bad in (0.0, -0.01, 0.5, True):
        with pytest.raises(ModelError, match="contact_distance"):
            Fe3dModel(short_design, mesh=COARSE, contact_distance=bad)
    a = Fe3dModel(short_design, mesh=COARSE)
    b = Fe3dModel(short_design, mesh=COARSE, contact_distance=0.03)
    assert a.cache_key != b.cache_key
    for bad in (1, 13, 6.0, True):
        with pytest.raises(ModelError, match="contact_intorder"):
            Fe3dModel(short_design, mesh=COARSE, contact_intorder=bad)
    c = Fe3dModel(short_design, mesh=COARSE, contact_intorder=4)
    assert c.problem.contact.intorder == 4 and a.problem.contact.intorder == 6
    assert c.cache_key != a.cache_key


CONTACT_LOADS = [10000.0, 20000.0, 25500.0]


@pytest.fixture(scope="module")
def contact_ramp():
    """The coarse 10 mm body ramped into lumen contact (CONTACT_LOADS, Pa) with the default Newton
    and the default barrier; (problem, ramp, its counters right after the ramp), solved once for
    the tests about contact and the solver's shortcuts."""
    from softcath_ros.core.design import load_design
    from softcath_ros.core.fe3d.ramp import run_ramp

    design = load_design("implemented_5mm").with_length(0.010)
    pb = Fe3dModel(design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02,
                   newton=NewtonSettings(threads=1)).problem
    ramp = run_ramp(pb, [1.0], CONTACT_LOADS)
    return pb, ramp, (pb.factorizations, pb.iterations_total, pb.contact.searches, pb.contact.skipped)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_lumen_contact_keeps_the_walls_apart_at_every_step(short_design, contact_ramp):
    """Coarse 10 mm body ramped past the lumen's closing (about 0.23 bar on this mesh) to
    0.255 bar, beyond the 0.252 bar where the ramp stops without contact: the contact barrier is
    active (the wall's smallest gap below the barrier distance, here 0.02 of the lumen diameter,
    30 um) and at every accepted step the wall never crosses itself beyond the tolerance (min gap
    >= -0.5 d_hat)."""
    pb, ramp, _ = contact_ramp
    assert pb.contact is not None
    d_hat = pb.contact.d_hat
    assert d_hat == pytest.approx(0.02 * short_design.lumen.diameter)
    assert ramp.converged, ramp.message
    loads = [t for t, _ in ramp.min_gap_m]
    gaps = np.array([g for _, g in ramp.min_gap_m])
    assert len(gaps) == ramp.steps and loads[-1] == pytest.approx(25500.0)
    assert np.all(gaps >= -pb.contact.tolerance), gaps
    assert gaps[-1] < d_hat            # the walls are within the barrier's range: contact is active
    assert gaps[0] > 5 * d_hat         # and were far apart at the start


def test_mirror_planes_of_the_three_channel_design():
    """One channel (or channels 1 and 2 equal) lies on the y-z plane; channels 0 and 1 equal on the
    plane through channel 2 (-30 deg), which the section is turned by 120 deg to put on x = 0; a 2:1
    pair lies on none. In the turned half model the unmeshed channel takes its partner's volume."""
    from softcath_ros.core.design import load_design
    from softcath_ros.core.fe3d.symmetry import channel_shares, mirror_plane, rotated_section

    design = load_design("three_channel_5mm")
    assert math.degrees(mirror_plane(design, (1.0, 0.0, 0.0))) == pytest.approx(90.0)
    assert math.degrees(mirror_plane(design, (0.0, 1.0, 1.0))) == pytest.approx(90.0)
    assert math.degrees(mirror_plane(design, (1.0, 1.0, 0.0))) == pytest.approx(-30.0)
    assert mirror_plane(design, (1.0, 0.5, 0.0)) is None
    turned = rotated_section(design, math.radians(120.0))
    assert turned.channels[2].center == (0.0, pytest.approx(design.channels[0].center[1]))
    assert channel_shares(turned, True) == [(1, 1.0), (1, 1.0), (2, 2.0)]
    assert channel_shares(design, True) == [(0, 2.0), (2, 1.0), (2, 1.0)]
    assert channel_shares(design, False) == [(0, 1.0), (1, 1.0), (2, 1.0)]


def test_half_model_on_a_mirror_plane_equals_the_mirrored_full_model():
    """Channels 0 and 1 equal (the plane through channel 2, turned onto x = 0): the half body with
    the symmetry condition gives the full body's answer on the same (mirrored) mesh, R_C and tip
    angle within 0.2 % (the displacements agree to solver tolerance), and reports the whole
    body's channel volumes; the bend points away from the pair (-30 deg)."""
    from softcath_ros.core.design import load_design

    design = load_design("three_channel_5mm").with_length(0.010)
    p = np.array([[8000.0, 8000.0, 0.0]])
    steps = default_step_control(step=4000.0)   # two steps: the test is about the symmetry, not the ramp
    half_model = Fe3dModel(design, mesh=COARSE, cache=False, threads=1, half=True, step_control=steps,
                           contact_distance=None)   # far from closing: the barrier is zero
    problem = half_model.problem_for(p[0] / p[0].max())
    assert problem.half and math.degrees(problem.rotation) == pytest.approx(120.0)
    half = half_model.evaluate(p)
    full_model = Fe3dVariantModel(design, mesh=COARSE, cache=False, threads=1, half=False, mirror_mesh=True,
                           contact_distance=None,
                           step_control=steps)
    assert not full_model.problem_for(p[0] / p[0].max()).half
    full = full_model.evaluate(p)
    assert half.converged.all() and full.converged.all(), (half.message, full.message)
    assert half.radius_l_over_theta[0] == pytest.approx(full.radius_l_over_theta[0], rel=2e-3)
    assert half.tip.angle[0] == pytest.approx(full.tip.angle[0], rel=2e-3)
    np.testing.assert_allclose(half.tip.position, full.tip.position, atol=1e-3 * design.length)
    np.testing.assert_allclose(half.diagnostics.channel_volume, full.diagnostics.channel_volume, rtol=1e-6)
    v_open = design.channels[0].area * (design.length - design.cap_thickness)
    vol = half.diagnostics.channel_volume[0]
    assert vol[0] == pytest.approx(vol[1]) and vol[0] > vol[2] > 0.9 * v_open
    kx, ky = half.curvature[0]
    assert math.degrees(math.atan2(ky, kx)) == pytest.approx(-30.0, abs=0.5)


def test_shifted_tangent_step_descends_and_newton_ends_on_the_plain_state(short_design):
    """The Newton safeguard (NewtonSettings.shifted_tangent): its term 0.5 sigma |grad(u - u_k)|^2
    adds nothing at sigma = 0 (the same solve with and without it); a shifted step from a state
    short of equilibrium lowers the condensed energy and stays admissible, and Newton then converges,
    on a plain step, to the state it had found (coarse 10 mm body, 0.05 bar, no contact)."""
    runs = {}
    for shifted in (False, True):
        model = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=None,
                          newton=NewtonSettings(threads=1, shifted_tangent=shifted, reuse_ratio=None))
        pb = model.problem
        pb.set_direction([1.0])
        pb.set_state(np.zeros(pb.fes.ndof))
        pb.load.Set(5000.0)
        pb.newton()
        runs[shifted] = (pb, pb.get_state())
    pb, solved = runs[True]
    nu = pb.fes.components[0].ndof
    np.testing.assert_allclose(solved[:nu], runs[False][1][:nu], rtol=0, atol=1e-12)
    assert pb.shifted_total == 0             # a plain solve never needed it
    pb.set_state(0.9 * solved)               # a smooth, admissible state away from equilibrium
    e0 = pb._condensed_energy()
    slope = pb._shifted_step(pb.get_state(), 1)
    assert slope > 0 and pb.sigma > 0 and pb.shift.Get() == 0.0
    assert pb._condensed_energy() < e0 and pb._rejection() == ""
    pb.newton()                              # starts plain (sigma 0 at a new solve)
    np.testing.assert_allclose(pb.get_state()[:nu], solved[:nu], rtol=0, atol=1e-8 * short_design.length)
    # inside Newton: when every plain step length is rejected, the iteration is a shifted step (outside
    # the plain steps' budget; shifted ones follow until the full plain step descends), and Newton then
    # converges to the same state
    rejection, shifted_step, blocked = pb._rejection, pb._shifted_step, [True]
    pb._rejection = lambda locate=True: "rejected by the test" if blocked[0] and not locate else rejection(locate)

    def shifted_once(base, it):
        blocked[0] = False
        return shifted_step(base, it)

    pb._shifted_step = shifted_once
    pb.set_state(0.9 * solved)
    before = pb.shifted_total
    pb.newton()
    assert pb.shifted_total > before and not blocked[0] and pb.sigma == 0.0
    np.testing.assert_allclose(pb.get_state()[:nu], solved[:nu], rtol=0, atol=1e-8 * short_design.length)


def test_stability_eigenpairs_of_the_condensed_tangent(short_design):
    """Fe3dProblem.stability at 0.05 bar on the coarse 10 mm body: the smallest eigenvalue is
    positive (a stable state), each mode is an eigenvector of K v = lam M v (residual) of unit H1
    seminorm, the modes are M-orthogonal, and the eigenvalues are the smallest: a random M-unit
    vector's Rayleigh quotient lies above the first."""
    import ngsolve as ng

    from softcath_ros.core.fe3d.ramp import run_ramp
    from softcath_ros.core.fe3d.stability import condensed_matrices

    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02, **PLAIN_P2).problem
    r = run_ramp(pb, [1.0], [5000.0])
    assert r.converged, r.message
    s = pb.stability(k=2)
    mu = 2.0 * short_design.material.c1
    assert 0.0 < s.eigenvalues[0] < s.eigenvalues[1]
    K, M, idx = condensed_matrices(pb)
    for j in range(2):
        v = s.modes[j][idx]
        assert v @ (M @ v) == pytest.approx(1.0, rel=1e-9)
        res = K @ v - s.eigenvalues[j] * mu * (M @ v)
        assert np.linalg.norm(res) < 1e-6 * np.linalg.norm(K @ v)
        # the H1 seminorm of the mode's displacement, integrated anew
        gf = ng.GridFunction(pb.fes)
        gf.vec.FV().NumPy()[:] = s.modes[j]
        g = ng.Grad(gf.components[0])
        assert ng.Integrate(ng.InnerProduct(g, g), pb.mesh) == pytest.approx(1.0, rel=1e-9)
    assert abs(s.modes[0][idx] @ (M @ s.modes[1][idx])) < 1e-8
    x = np.random.default_rng(1).standard_normal(len(idx))
    assert (x @ (K @ x)) / (x @ (M @ x)) > s.eigenvalues[0] * mu
    assert s.max_displacement_m[0] > 0.0 and "element at" in s.where


def test_an_interrupted_ramp_names_its_last_accepted_state(short_design):
    """Ctrl-C (KeyboardInterrupt from the progress bar's update) between checkpoints: the ramp stops
    cleanly, flagged interrupted, and names the last accepted load, not the last checkpoint."""
    from softcath_ros.core.fe3d.ramp import run_ramp
    from softcath_ros.core.units import PA_PER_BAR

    class StopAtThird:
        def __init__(self):
            self.loads = [0.0]

        def update(self, n):
            self.loads.append(self.loads[-1] + n)
            if len(self.loads) == 4:
                raise KeyboardInterrupt

        def set_postfix_str(self, _):
            pass

    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1).problem
    bar = StopAtThird()
    r = run_ramp(pb, [1.0], [0.0, 20000.0], progress=bar)
    assert r.interrupted and not r.converged
    assert 0.0 < bar.loads[-1] < 20000.0
    assert r.message.startswith(f"interrupted after p = {bar.loads[-1] / PA_PER_BAR:.4f} bar (the last accepted state")


def test_interior_bubbles_add_condensed_unknowns_and_soften_p2_p1_slightly(short_design):
    """interior_order=3 adds 2 condensed bubbles per component and prism (none coupled: the factorised
    system keeps its size) and, with a P1 pressure on the coarse 10 mm body at 0.1 bar, gives an R_C a
    little below plain P2's (the enriched element locks less), by well under the mesh's own error."""
    from softcath_ros.core.fe3d.measure import measure
    from softcath_ros.core.fe3d.ramp import run_ramp
    from softcath_ros.core.fe3d.solver import Fe3dProblem

    plain = Fe3dProblem(short_design, COARSE, NewtonSettings(threads=1), None, contact_distance=0.02,
                        pressure_order=1)
    # the model builds the same problem from its options, and keys its cache on them
    model = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02,
                      pressure_order=1, interior_order=3)
    bubbled = model.problem
    assert model.cache_key != Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02,
                                        pressure_order=1, interior_order=None).cache_key
    assert bubbled.fes.ndof - plain.fes.ndof == 6 * plain.mesh.ne
    assert sum(bubbled.free) == sum(plain.free)
    rc = []
    for pb in (plain, bubbled):
        r = run_ramp(pb, [1.0], [10000.0])
        assert r.converged, r.message
        rc.append(short_design.length / measure(pb)["bending_angle_rad"])
    assert 0.0 < (rc[0] - rc[1]) / rc[0] < 0.03
    for bad in (2, 0, 3.0, True):
        with pytest.raises(ValueError, match="interior_order"):
            Fe3dProblem(short_design, COARSE, interior_order=bad)
        with pytest.raises(ModelError, match=r"^fe3d: interior_order must be an integer >= 3 or None, not"):
            Fe3dModel(short_design, mesh=COARSE, cache=False, interior_order=bad)
    for bad in (2, -1, 0.5, False):
        with pytest.raises(ModelError, match=r"^fe3d: pressure_order must be 0 \(P2/P0\) or 1"):
            Fe3dModel(short_design, mesh=COARSE, cache=False, pressure_order=bad)


def test_stability_matches_an_independent_eigensolve(implemented_design):
    """On a 4 mm body with a very coarse section (4,200 free unknowns) the eigenvalues from NGSolve's
    factorisation equal scipy's own shift-invert (SuperLU of the same condensed tangent, H1 form) at a
    stressed state (0.05 bar). A dense eigensolve of it took 53 s, too slow for the suite (it agreed)."""
    from scipy.sparse.linalg import eigsh

    from softcath_ros.core.fe3d.ramp import run_ramp
    from softcath_ros.core.fe3d.stability import condensed_matrices

    tiny = MeshSettings(section_h=2.5e-3, wall_h=2.0e-3, layer_h=4.5e-3, cap_layers=1)
    pb = Fe3dModel(implemented_design.with_length(0.004), mesh=tiny, cache=False, threads=1,
                   contact_distance=0.02).problem
    assert run_ramp(pb, [1.0], [5000.0]).converged
    s = pb.stability(k=3)
    K, M, _ = condensed_matrices(pb)
    other = np.sort(eigsh(K.tocsc(), k=3, M=M.tocsc(), sigma=0.0, which="LM", return_eigenvectors=False))
    mu = 2.0 * implemented_design.material.c1
    assert s.eigenvalues == pytest.approx(other / mu, rel=1e-7)


@pytest.mark.parametrize("diagonal, k", [
    ([-0.5, 0.01, 0.02, 0.3, 0.7, 1.5], 1),    # a saddle whose eigenvalue is farther from 0 than one above 0
    ([-0.5, 0.01, 0.02, 0.3, 0.7, 1.5], 3),
    ([-0.004, 0.01, 0.02, 0.3, 0.7, 1.5], 2),  # the negative one is also the nearest zero
    ([0.05, 0.08, 0.3, 0.7, 1.5, 2.0], 2),     # stable: the nearest zero only
])
def test_the_smallest_eigenvalue_is_found_beside_those_nearest_zero(diagonal, k):
    """lowest_and_nearest_zero on K v = lam M v with a known spectrum (K and M sparse, 60 unknowns):
    the first eigenvalue is the smallest algebraically even where the k nearest zero miss it, the
    rest are the nearest zero, and each pair is an eigenpair."""
    import scipy.sparse as sp
    from scipy.linalg import eigh
    from scipy.sparse.linalg import LinearOperator, eigsh, splu

    from softcath_ros.core.fe3d.stability import lowest_and_nearest_zero

    n = 60
    d = np.concatenate([diagonal, np.linspace(3.0, 9.0, n - len(diagonal))])
    M = sp.diags([np.full(n - 1, 0.2), np.full(n, 1.0), np.full(n - 1, 0.2)], [-1, 0, 1], format="csr")
    L = np.linalg.cholesky(M.toarray())
    K = sp.csr_matrix(L @ np.diag(d) @ L.T)   # K v = lam M v has the spectrum d
    lu = splu(K.tocsc())
    lam, vec = lowest_and_nearest_zero(K, M, k, LinearOperator((n, n), matvec=lu.solve, dtype=float), 1.0)
    exact = eigh(K.toarray(), M.toarray(), eigvals_only=True)
    nearest = exact[np.argsort(np.abs(exact))][:k]
    expected = np.sort(nearest if exact[0] in nearest else np.concatenate([[exact[0]], nearest[:k - 1]]))
    assert lam == pytest.approx(expected, rel=1e-8, abs=1e-10)
    assert lam[0] == pytest.approx(min(diagonal), rel=1e-8)
    for j in range(k):
        assert np.linalg.norm(K @ vec[:, j] - lam[j] * (M @ vec[:, j])) < 1e-7 * np.linalg.norm(K @ vec[:, j])
    if k == 1 and min(diagonal) == -0.5:   # what the nearest-zero solve alone reports there
        only = eigsh(K, k=1, M=M, sigma=0.0, which="LM", return_eigenvectors=False)
        assert only[0] == pytest.approx(0.01, rel=1e-8)


@pytest.mark.parametrize("lam_before, lam_last, reason", [
    (0.030, 0.0133, "physical limit point"),      # falling fast: zero 0.2 % of the load past the last state
    (0.0140, 0.0133, "numerical failure"),        # falling slowly: zero 4.9 % past it
    (0.0100, 0.0133, "numerical failure"),        # rising
    (0.0050, 5e-4, "physical limit point"),       # below SINGULAR_BELOW
    (0.0050, -2e-3, "unstable equilibrium"),      # a saddle
])
def test_a_failed_ramp_names_its_stop_by_the_smallest_eigenvalue(lam_before, lam_last, reason):
    """_name_the_stop classifies the last two converged states' smallest eigenvalues (the fe3d
    problem replaced by one whose stability() returns them, by state): a singular or falling-to-zero
    tangent is a limit point, a negative one a saddle, else the numerical failure stays."""
    from types import SimpleNamespace

    from softcath_ros.core.continuation import RampResult
    from softcath_ros.core.fe3d.ramp import _name_the_stop

    class Problem:
        contact = None
        load = SimpleNamespace(Set=lambda v: None)

        def set_state(self, s):
            self.state = s

        def stability(self, k=1):
            lam = {1: lam_before, 2: lam_last}[int(self.state[0])]
            return SimpleNamespace(smallest=lam, load_share=0.01, where="silicone element at x = 1.87")

    result = RampResult(points=[], converged=False, message="", last_load=25190.0,
                        last_state=np.array([2.0]), previous=(25125.0, np.array([1.0])))
    s, why, text = _name_the_stop(Problem(), result, 1e-3)
    assert why == reason
    assert f"{lam_last:.3g} x 2 c1" in text and "x = 1.87" in text
    if why == "physical limit point":   # the eigenvalues cannot tell a physical fold from a mesh's mode
        assert "only a mesh study tells" in text


@pytest.mark.parametrize("stall_lam, tolerances, indefinite, without, reason", [
    (0.0055, 1.6, 1.7, -0.05, "physical limit point"),   # the 1-DOF optimum at 0.1124 bar: indefinite at 1.7 x tol
    (0.0055, 1.6, 1.7, 0.022, "numerical failure"),      # ... but of the contact's making (pairs past the log range)
    (7e-4, 1.6, math.inf, -0.05, "physical limit point"),  # singular at the stalled iterate
    (-2e-3, 1.6, math.inf, -0.05, "physical limit point"),  # negative there: not an equilibrium to call a saddle
    (0.02, 1.6, math.inf, -0.05, "numerical failure"),   # neither
    (0.02, 1.6, 40.0, -0.05, "numerical failure"),       # indefinite only far from equilibrium
    (7e-4, 50.0, 1.7, -0.05, "numerical failure"),       # stalled far from equilibrium: its iterate names nothing
    (None, None, None, -0.05, "numerical failure"),      # the solve did not stall
])
def test_a_stall_next_to_a_singular_tangent_is_named_a_limit_point(stall_lam, tolerances, indefinite, without, reason):
    """_name_the_stop where the last converged states read not singular (0.00697 / 0.0224 x 2 c1, the 1-DOF
    optimum's at 0.1089 / 0.1121 bar, accepted microns along a mode whose energy is quartic there) but the
    failed solve stalled within STALL_NEAR x its tolerance of equilibrium (Fe3dProblem.stalled): a singular
    eigenvalue at its last iterate, or an indefinite tangent that near equilibrium, names a limit point."""
    from types import SimpleNamespace

    from softcath_ros.core.continuation import RampResult
    from softcath_ros.core.fe3d.newton import Stall
    from softcath_ros.core.fe3d.ramp import _name_the_stop
    from softcath_ros.core.fe3d.stability import ContactSplit

    class Problem:
        contact = SimpleNamespace(update=lambda: True, mirror_crossing=lambda: 0.0, d_hat=3e-5)
        load = SimpleNamespace(Set=lambda v: None)
        stalled = None if stall_lam is None else Stall(11239.5, np.array([3.0]), 1.6 * 2.9e-12, tolerances, indefinite)

        def set_state(self, s):
            self.state = s

        def stability(self, k=1):
            lam = {1: 0.00697, 2: 0.0224, 3: stall_lam}[int(self.state[0])]
            return SimpleNamespace(smallest=lam, load_share=0.01, where="silicone element at x = 0.50")

        def contact_split(self):
            assert self.state[0] == 3.0   # only where Newton stalled: the converged states read not singular
            return ContactSplit(without_contact=without, past_log_range_m2=5.9e-8)

    problem = Problem()
    result = RampResult(points=[], converged=False, message="", last_load=11207.5,
                        last_state=np.array([2.0]), previous=(10887.5, np.array([1.0])))
    s, why, text = _name_the_stop(problem, result, 1e-3)
    assert why == reason, text
    assert problem.state[0] == 2.0   # left at the last converged state
    assert ("Newton stalled at p = 0.1124 bar" in text) == (stall_lam is not None and tolerances < 10)
    if why == "physical limit point":
        assert f"smallest eigenvalue {stall_lam:.3g} x 2 c1 (singular" in text and "only a mesh study tells" in text
        assert ("the tangent indefinite at 1.7 x its tolerance" in text) == (indefinite == 1.7)
    if indefinite == 1.7 and tolerances < 10:   # the contact's share checked where only the sign said singular
        assert f"without the lumen contact's term {without:.3g}" in text


@pytest.mark.parametrize("without, past, reason", [
    (0.022, 5.9e-8, "numerical failure"),      # the contact's making: the silicone positive, pairs past the log range
    (0.022, 0.0, "unstable equilibrium"),      # every pair within the barrier's log range: the saddle stands
    (-0.010, 5.9e-8, "unstable equilibrium"),  # a saddle of the silicone itself
])
def test_a_saddle_of_the_contact_term_alone_is_not_named_an_unstable_equilibrium(without, past, reason):
    """_name_the_stop on a state in contact whose smallest eigenvalue is negative (-0.269 x 2 c1, the
    1-DOF optimum's at 0.1041 bar): when the tangent without the contact term is positive definite and
    some pairs are past the barrier's log range, the saddle is the contact's continuation's, and the
    stop stays a numerical failure that says so; otherwise it is an unstable equilibrium."""
    from types import SimpleNamespace

    from softcath_ros.core.continuation import RampResult
    from softcath_ros.core.fe3d.ramp import _name_the_stop
    from softcath_ros.core.fe3d.stability import ContactSplit

    class Problem:
        contact = SimpleNamespace(update=lambda: True, mirror_crossing=lambda: 0.0, d_hat=3e-5)
        load = SimpleNamespace(Set=lambda v: None)

        def set_state(self, s):
            self.state = s

        def stability(self, k=1):
            lam = {1: 0.0242, 2: -0.269}[int(self.state[0])]
            return SimpleNamespace(smallest=lam, load_share=0.01, where="silicone element at x = 0.84")

        def contact_split(self):
            return ContactSplit(without_contact=without, past_log_range_m2=past)

    result = RampResult(points=[], converged=False, message="", last_load=10406.25,
                        last_state=np.array([2.0]), previous=(10156.25, np.array([1.0])))
    s, why, text = _name_the_stop(Problem(), result, 1e-3)
    assert why == reason
    assert "-0.269 x 2 c1" in text and f"without the lumen contact's term {without:.3g}" in text
    assert ("of the lumen contact's making" in text) == (reason == "numerical failure")


def test_a_half_wall_past_its_mirror_plane_is_measured_and_named_at_a_stop(short_design):
    """LumenContact.mirror_crossing: how far the half model's lumen wall lies past its mirror plane x = 0
    (through its mirror image; at fe3d-11, without the mirror term, the fan design's equal pair stopped so
    with no contact pair held): 0 at rest and on the full body; with every point moved to
    -x / 2, half the wall's largest x. A failed ramp's stop message says so when it is past by more than
    MIRROR_SAID d_hat (here a stand-in problem at 38 um, the equal pair's at 0.05 bar), and not at 0."""
    from types import SimpleNamespace

    import ngsolve as ng

    from softcath_ros.core.continuation import RampResult
    from softcath_ros.core.fe3d.measure import lumen_wall_nodes
    from softcath_ros.core.fe3d.ramp import _name_the_stop

    half = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02, **PLAIN_P2).problem
    full = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02, half=False,
                     **PLAIN_P2).problem
    assert half.half and not full.half
    assert half.contact.mirror_crossing() < 1e-12
    x_max = float(np.max(lumen_wall_nodes(half)[0][:, 0]))
    for pb in (half, full):
        pb.u.Set(ng.CF((-1.5 * ng.x, 0.0, 0.0)))
    assert half.contact.mirror_crossing() == pytest.approx(0.5 * x_max, rel=1e-6)
    assert full.contact.mirror_crossing() == 0.0   # (no mirror plane)

    for past in (38e-6, 0.0):
        class Problem:
            contact = SimpleNamespace(update=lambda: True, mirror_crossing=lambda: past, d_hat=3e-5)
            load = SimpleNamespace(Set=lambda v: None)

            def set_state(self, s):
                self.state = s

            def stability(self, k=1):
                return SimpleNamespace(smallest=0.018, load_share=0.02, where="silicone element at x = 0.31")

        result = RampResult(points=[], converged=False, message="", last_load=6015.0,
                            last_state=np.array([2.0]), previous=(5970.0, np.array([1.0])))
        _, why, text = _name_the_stop(Problem(), result, 1e-3)
        assert why == "numerical failure"
        said = "its lumen wall lies 38.0 um past the half body's mirror plane, through its mirror image"
        assert (said in text) == (past > 0.0), text


def test_the_half_wall_is_held_off_its_mirror_image_but_not_where_it_meets_the_plane(short_design):
    """The mirror term (mirror_energy_cf) on the coarse 10 mm half body: nothing at rest (the wall far
    from its image); with the wall pulled to within d_hat of the plane, and past it, a positive energy
    whose gradient (checked by finite differences) pushes the wall back to x > 0, rising as the wall
    closes on its image; nothing from wall points that start on or beside the plane (held there by the
    symmetry condition, gap 0 by construction) however close to it they are. It is in the problem's
    energy; the full body has none."""
    import ngsolve as ng

    from softcath_ros.core.fe3d.contact import NEAR_LOW
    from softcath_ros.core.fe3d.holes import hole_size

    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02, **PLAIN_P2).problem
    full = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02, half=False,
                     **PLAIN_P2).problem
    assert pb.half and pb.contact.mirror_form is not None and full.contact.mirror_form is None
    assert full.contact.mirror_energy() == 0.0
    d_hat, r = pb.contact.d_hat, hole_size(short_design.lumen)
    wall = pb.mesh.Boundaries("lumen")
    back = ng.GridFunction(pb.fes)
    back.components[0].Set(ng.CF((ng.x, 0.0, 0.0)))   # a motion back to the body's side
    bare = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=None, **PLAIN_P2).problem

    def gradient_along_back():
        g = pb.gf.vec.CreateVector()
        pb.contact.mirror_form.Apply(pb.gf.vec, g)
        return float(np.dot(g.FV().NumPy(), back.vec.FV().NumPy()))

    def energy_at(shift):
        saved = pb.gf.vec.CreateVector()
        saved.data = pb.gf.vec
        pb.gf.vec.data += shift * back.vec
        e = pb.contact.mirror_energy()
        pb.gf.vec.data = saved
        return e

    assert pb.contact.mirror_energy() == 0.0 and gradient_along_back() == 0.0   # at rest
    energies = []
    for pulled in (0.995, 1.2):   # u_x = -pulled x: the wall at 0.01 x from its image, then past the plane
        pb.u.Set(ng.CF((-pulled * ng.x, 0.0, 0.0)))
        e, slope = pb.contact.mirror_energy(), gradient_along_back()
        assert e > 0.0 and slope < 0.0   # held off: moving back to x > 0 lowers it
        h = 1e-4
        assert (energy_at(h) - energy_at(-h)) / (2 * h) == pytest.approx(slope, rel=1e-3)
        energies.append(e)
    assert energies[1] > energies[0]
    # the problem's energy holds it (no pair searched yet: the pair term adds nothing): the body moved
    # rigidly by 0.3 lumen radii to -x, so the silicone stores nothing
    for p in (pb, bare):
        p.u.Set(ng.CF((-0.3 * r, 0.0, 0.0)))
    e = pb.contact.mirror_energy()
    assert e > 0.0 and pb.a.Energy(pb.gf.vec) - bare.a.Energy(bare.gf.vec) == pytest.approx(e, rel=1e-9)

    # the wall beside the plane (starting within NEAR_LOW / 2 lumen radii of it) pulled onto it, the rest
    # left where it is: area within d_hat of its image, and no energy
    c = 0.5 * NEAR_LOW * r
    pb.u.Set(ng.CF((ng.IfPos(c - ng.x, -ng.x * (1.0 - ng.x / c) ** 2, 0.0), 0.0, 0.0)))
    near = ng.Integrate(ng.IfPos(d_hat - 2.0 * (ng.x + pb.u[0]), 1.0, 0.0), pb.mesh, ng.BND, definedon=wall,
                        order=6)
    assert near > 0.0
    assert pb.contact.mirror_energy() == 0.0 and gradient_along_back() == 0.0


def test_contact_split_removes_exactly_the_contact_terms_tangent(short_design):
    """contact_split on the coarse 10 mm body with its lumen squeezed to a slit (det F = eps): the tangent
    less the contact term's is the tangent of the same state without contact (so its smallest eigenvalue
    is that problem's), and pairs count as past the barrier's log range only below XI_MIN d_hat."""
    import ngsolve as ng
    from scipy.sparse.linalg import eigsh

    from softcath_ros.core.fe3d.stability import _csr, condensed_matrices

    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02, **PLAIN_P2).problem
    bare = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=None, **PLAIN_P2).problem
    assert pb.contact_split() is None and bare.contact_split() is None   # no pair held / no contact
    yc = short_design.lumen.center[1]
    squeeze = {0.005: False, 0.0001: True}   # slit d_hat / 4 wide: within the log range; d_hat / 200: past it
    for eps, past in squeeze.items():
        for p in (pb, bare):
            p.u.Set(ng.CF((0.0, -(1.0 - eps) * (ng.y - yc), 0.0)))
        pb.contact.update()
        split = pb.contact_split()
        assert (split.past_log_range_m2 > 0.0) is past
        K, M, idx = condensed_matrices(pb)
        Kc = _csr(pb.contact.tangent_matrix(), idx)
        K0, _, idx0 = condensed_matrices(bare)
        assert np.array_equal(idx, idx0) and abs(Kc).max() > 0.0
        assert abs(K - Kc - K0).max() <= 1e-12 * abs(K0).max()   # (roundoff of K's entries)
        mu = 2.0 * short_design.material.c1
        low = eigsh(K0.tocsc(), k=1, M=M, sigma=-mu, which="LM", return_eigenvectors=False)[0] / mu
        assert split.without_contact == pytest.approx(low, rel=1e-6, abs=1e-9)


def test_a_partner_far_off_the_normal_line_raises_the_barriers_argument():
    """lateral_xi: a partner within OFF_LOW d_hat of the primary's normal line leaves xi as it is; farther
    off, xi rises (C2 at OFF_LOW) until from OFF_HIGH on a pair at most d_hat behind the primary is beyond
    the barrier's range. So a pair found nearly in the primary's tangent plane, 4.8 d_hat off its normal
    line with a gap of -0.01 d_hat (where the 1-DOF optimum's wall turns round a fold), adds no energy and
    does not count as past the log range; as a window weighing the barrier it kept 0.5 % of the
    barrier's continuation there, which made the tangent indefinite."""
    import ngsolve as ng

    from softcath_ros.core.fe3d.contact import OFF_HIGH, OFF_LOW, XI_MIN, barrier_cf, lateral_xi

    mesh = ng.Mesh(ng.unit_square.GenerateMesh(maxh=0.5))
    xi_p, off_p = ng.Parameter(0.0), ng.Parameter(0.0)
    arg, energy = lateral_xi(xi_p, off_p), barrier_cf(lateral_xi(xi_p, off_p))

    def at(cf, xi, offset):
        xi_p.Set(xi)
        off_p.Set(offset * offset)
        return cf(mesh(0.5, 0.5))

    for xi in (-0.5, 0.01, 0.3):
        for offset in (0.0, 1.0, OFF_LOW):
            assert at(arg, xi, offset) == xi
        assert at(arg, xi, 0.5 * (OFF_LOW + OFF_HIGH)) > xi
    for xi in (-1.0, -0.5, 0.0, 0.5):
        for offset in (OFF_HIGH, 6.0, 10.0):
            assert at(arg, xi, offset) >= 1.0 and at(energy, xi, offset) == 0.0
    # C2 where the offset starts to count: the argument's slope and curvature in the offset vanish there
    h = 1e-4
    f = [at(arg, 0.2, OFF_LOW + k * h) for k in (-1, 0, 1)]
    assert abs(f[2] - f[0]) / (2 * h) < 1e-6 and abs(f[2] - 2 * f[1] + f[0]) / h ** 2 < 1e-3
    assert at(arg, -0.01, 4.8) > 1.0 and at(energy, -0.01, 4.8) == 0.0 and at(arg, -0.01, 4.8) > XI_MIN


def _slit(pb, design, eps):
    """The lumen of ``pb`` squeezed to a slit (u_y = -(1 - eps)(y - y_c)), its pairs searched."""
    import ngsolve as ng

    yc = design.lumen.center[1]
    pb.u.Set(ng.CF((0.0, -(1.0 - eps) * (ng.y - yc), 0.0)))
    pb.contact.update()


def test_held_contact_pairs_stay_current_while_the_wall_sections_keep_their_shape(short_design):
    """LumenContact.pairs_current: no pairs held, none are current; after a search they are, and stay so
    when the body moves as a rigid body (a turn about x, the bending plane's normal, and a shift: the
    bending carries the wall far but leaves its sections' shape); the sections deformed by more than
    settle_move (SETTLE_MOVE d_hat) make them stale. Newton searches the pairs again only then, so held
    pairs are not swapped for a neighbouring state's at every iteration (which kept the 1-DOF optimum's
    Newton from converging at 0.108 bar)."""
    import ngsolve as ng

    from softcath_ros.core.fe3d.contact import SETTLE_MOVE

    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02, **PLAIN_P2).problem
    c = pb.contact
    assert not c.pairs_current()
    yc, eps = short_design.lumen.center[1], 0.005
    _slit(pb, short_design, eps)
    assert c.settle_move == SETTLE_MOVE * c.d_hat and c.pairs_current()
    a = 0.05   # rad
    y1, z1 = -(1.0 - eps) * (ng.y - yc) + ng.y, ng.z     # the slit's deformed y, z; then turned about x, shifted
    pb.u.Set(ng.CF((0.0, math.cos(a) * y1 - math.sin(a) * z1 + 2e-4 - ng.y,
                    math.sin(a) * y1 + math.cos(a) * z1 - 3e-4 - ng.z)))
    assert c.pairs_current()
    # the slit opened by more than settle_move at its widest
    radius = 0.5 * short_design.lumen.diameter
    extra = 3.0 * c.settle_move / radius
    pb.u.Set(ng.CF((0.0, -(1.0 - eps - extra) * (ng.y - yc), 0.0)))
    assert not c.pairs_current()
    c.update()
    assert c.pairs_current()


def test_in_contact_a_step_that_raises_the_energy_is_shortened_not_counted_as_an_overshoot(short_design):
    """NewtonSettings.descent_in_contact: with the lumen walls in contact, a descent step far from
    convergence is halved while it raises the condensed energy, and such a cut is named for that (the
    Newton loop does not count it toward cut_iterations). Here the full step turns the squeezed lumen
    into one stretched twice as far the other way (higher energy), half of it leaves the lumen half
    open (lower). Without the setting the full step is taken."""
    from softcath_ros.core.fe3d.newton import RAISES_ENERGY

    for on in (True, False):
        pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02,
                       newton=NewtonSettings(threads=1, descent_in_contact=on), **PLAIN_P2).problem
        pb.set_direction(np.array([1.0]))
        _slit(pb, short_design, 0.005)
        assert not pb.contact.pairs_idle
        base = pb.get_state()
        pb.du.FV().NumPy()[:] = 3.0 * base    # base - du = -2 x the squeeze
        alpha, cut = pb._step_length(base, 1, slope=1.0)
        assert (alpha, cut) == ((0.5, RAISES_ENERGY) if on else (1.0, ""))
        if on:   # the state is the shortened step's, with Newton's own q
            assert np.allclose(pb.get_state(), base - 0.5 * 3.0 * base)


def test_a_failed_predicted_step_is_retried_from_the_last_state_unless_switched_off():
    """continuation.ramp: a corrector failing on the predicted guess gets a second try from the last
    converged state (it may rescue a step the predictor overshot); retry_from_last=False cuts at once."""
    from softcath_ros.core.continuation import Correction, StepControl, ramp

    for retry in (True, False):
        calls = []

        def corrector(guess, t, previous):
            calls.append((t, bool(np.array_equal(guess, previous))))
            ok = t <= 2.0 or (retry and np.array_equal(guess, previous))   # the guess beyond 2 always fails
            return Correction(state=np.array([t]) if ok else previous, converged=ok, iterations=1)

        control = StepControl(initial_step=1.0, max_step=1.0, min_step=0.5, adaptive=True, retry_from_last=retry)
        r = ramp(corrector, np.array([0.0]), [3.0], control)
        assert r.converged is retry
        assert calls[2] == (3.0, False)                       # the predicted guess at t = 3
        if retry:
            assert calls[3] == (3.0, True) and r.cuts == 0    # retried from the state at t = 2, converged
        else:
            assert (3.0, True) not in calls and r.cuts > 0    # never retried: cut to the smallest step, stopped
            assert r.last_load == 2.0


def test_a_stalled_newton_solve_fails_early_and_says_so(short_design):
    """NewtonSettings.stall_iterations: a solve whose |du.r| does not fall tenfold over that many
    iterations fails then, named "stalled", instead of using its whole budget; without it the same
    solve runs to its budget. NewtonSettings.cut_iterations fails it once that many steps in a row
    were cut short, naming what the full step does."""
    from softcath_ros.core.fe3d.newton import NewtonFailure
    from softcath_ros.core.fe3d.solver import Fe3dProblem

    outcomes = {}
    for stall, cuts in ((None, None), (3, None), (None, 3)):
        pb = Fe3dProblem(short_design, COARSE, NewtonSettings(threads=1, max_iterations=12, stall_iterations=stall,
                                                              cut_iterations=cuts))
        pb.set_direction(np.array([1.0]))
        pb.load.Set(20000.0)   # from the straight state in one step: Newton wanders (0.1 bar converges in 5)
        with pytest.raises(NewtonFailure) as exc:
            pb.newton()
        outcomes[stall, cuts] = exc.value
        if stall is not None:
            stall_problem = pb
    assert outcomes[3, None].reason.startswith("stalled: |du.r|") and outcomes[3, None].iterations < 12, \
        outcomes[3, None].reason
    # the stalled solve keeps its last iterate and how far from equilibrium it is, for the ramp's stop naming
    stall = outcomes[3, None].stall
    assert stall is stall_problem.stalled and stall.load == 20000.0 and stall.state.shape == (stall_problem.fes.ndof,)
    assert stall.tolerances == pytest.approx(stall.work / (1e-9 * stall_problem.energy_scale)) and stall.tolerances > 1
    assert outcomes[None, None].stall is None
    assert outcomes[None, None].reason.startswith("no convergence in 12 Newton iterations"), outcomes[None, None].reason
    # NewtonSettings.cut_iterations: so many cut steps in a row fail the solve, saying where the full step fails
    cut = outcomes[None, 3]
    assert re.match(r"3 Newton steps in a row cut short \(the last full step inverts an element \(det F <= 0.02; "
                    r"most compressed: silicone element at x = ", cut.reason), cut.reason
    assert cut.iterations < 12


def test_the_tangent_after_a_failed_solve_is_the_converged_states_own(short_design):
    """A failed Newton solve leaves no factorisation of its last iterate behind: the tangent du/ds at
    the converged state restored afterwards (a ramp's predictor after a cut) equals the one computed
    there before the failure."""
    from softcath_ros.core.fe3d.newton import NewtonFailure
    from softcath_ros.core.fe3d.solver import Fe3dProblem

    pb = Fe3dProblem(short_design, COARSE, NewtonSettings(threads=1, max_iterations=6), contact_distance=0.02)
    pb.set_direction(np.array([1.0]))
    pb.load.Set(10000.0)
    pb.newton()
    converged = pb.get_state()
    pb._factorize()   # (Newton's last factorisation may be an earlier iterate's: reused while it contracted)
    before = pb.tangent()
    pb.load.Set(30000.0)
    with pytest.raises(NewtonFailure):
        pb.newton()
    assert pb.inverse is None
    pb.set_state(converged)
    pb.load.Set(10000.0)
    after = pb.tangent()
    assert np.linalg.norm(after - before) < 1e-9 * np.linalg.norm(before)


def test_the_deformed_backbone_of_an_imposed_arc_reaches_the_shaft_past_the_onset(implemented_design):
    """The displacement of a pure bend (every section rigid, the axis an arc of radius rho towards
    -y) set on a 30 mm body: deformed_backbone follows the arc, and body_contact finds the tip in the
    shaft at 330 deg (onset 290 deg at rho = 5.2 mm) and nothing at 250 deg."""
    import ngsolve as ng

    from softcath_ros.core.body_contact import body_contact
    from softcath_ros.core.fe3d.measure import deformed_backbone

    design = implemented_design.with_length(0.030)
    pb = Fe3dModel(design, mesh=COARSE, cache=False, threads=1, **PLAIN_P2).problem
    radius = 0.5 * design.outer_diameter
    for deg, reaches in ((250.0, False), (330.0, True)):
        rho = design.length / math.radians(deg)
        phi = ng.z / rho
        pb.u.Set(ng.CF((0.0, -rho * (1 - ng.cos(phi)) + ng.y * ng.cos(phi) - ng.y,
                        rho * ng.sin(phi) + ng.y * ng.sin(phi) - ng.z)))
        axis = deformed_backbone(pb, 0.5 * radius)
        z = np.linspace(0.0, design.length, len(axis))
        expect = np.column_stack([0 * z, -rho * (1 - np.cos(z / rho)), rho * np.sin(z / rho)])
        np.testing.assert_allclose(axis, expect, atol=0.02 * rho)
        hit = body_contact(axis, radius)
        assert (hit is not None and hit.what == "shaft") if reaches else hit is None, (deg, hit)


def test_a_ramp_whose_body_reaches_its_shaft_stops_outside_the_model(short_design, monkeypatch):
    """The ramp's check after every converged solve: from its third call on, the (stand-in) geometry
    says the body reaches its shaft; the ramp cuts its step, keeps the states before, and stops
    named outside the model's validity with what the body reached."""
    from softcath_ros.core.body_contact import BodyContact
    from softcath_ros.core.continuation import OUTSIDE_MODEL, tagged_stop
    from softcath_ros.core.fe3d import ramp as ramp_module

    calls = []

    def reaches_from_the_third(points, radius):
        calls.append(len(points))
        return BodyContact("shaft", 0.01, 1e-4, True) if len(calls) >= 3 else None

    monkeypatch.setattr(ramp_module, "body_contact", reaches_from_the_third)
    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1).problem
    r = ramp_module.run_ramp(pb, [1.0], [0.0, 1000.0, 2000.0, 10000.0])
    assert not r.converged and r.stop_reason == OUTSIDE_MODEL and tagged_stop(r.message) == OUTSIDE_MODEL
    assert "the tip" in r.message and "shaft" in r.message
    assert [p.load for p in r.points] == [0.0, 1000.0, 2000.0] and r.cuts >= 3
    assert calls[0] >= math.ceil(short_design.length / (0.25 * short_design.outer_diameter)) + 1


def test_the_default_mesh_and_element_are_the_converged_set(short_design):
    """Defaults (fe3d-8, the element and mesh kept by fe3d-9): P2 + order-3 bubbles / P1, barrier
    0.02 D, the base mesh x 1.4 in the section with 1.2 mm prisms; layer_h None scales the prisms
    with mesh_size; bad values are one ModelError each, and the cache key follows the prism height.
    fe3d-9's ramp: reused factorisations, the stall and cut rules, steps up to 0.025 bar, no retry
    from the last state, body-reach stops located to 250 Pa."""
    model = Fe3dModel(short_design, cache=False)
    assert model.newton_settings.reuse_ratio == 0.25 and model.newton_settings.stall_iterations == 4
    assert model.newton_settings.cut_iterations == 3
    steps = model.step_control
    assert (steps.max_step, steps.domain_step, steps.retry_from_last) == (2500.0, 250.0, False)
    base = MeshSettings()
    assert (model.pressure_order, model.interior_order, model.contact_distance) == (1, 3, 0.02)
    assert model.mesh_settings.section_h == pytest.approx(1.4 * base.section_h)
    assert model.mesh_settings.wall_h == pytest.approx(1.4 * base.wall_h)
    assert model.mesh_settings.layer_h == 1.2e-3
    scaled = Fe3dModel(short_design, cache=False, mesh_size=2.0, layer_h=None)
    assert scaled.mesh_settings.layer_h == pytest.approx(2.0 * base.layer_h)
    assert Fe3dModel(short_design, cache=False, layer_h=2e-3).cache_key != model.cache_key
    for bad in ({"layer_h": 5.0}, {"layer_h": True}, {"mesh_size": 0.0}, {"mesh_size": 50.0}):
        with pytest.raises(ModelError, match=next(iter(bad))):
            Fe3dModel(short_design, cache=False, **bad)


@pytest.mark.slow
@pytest.mark.timeout(400)
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_reused_factorisations_and_skipped_pair_searches_leave_the_ramp_unchanged(short_design, contact_ramp):
    """The coarse 10 mm body ramped into lumen contact (0.255 bar) with the default Newton (a
    factorisation reused while Newton contracts with it; the pair search skipped while the walls
    are far apart) and with a factorisation and a search at every iteration: the same bending at
    every checkpoint to well within Newton's tolerance, with fewer factorisations than iterations,
    searches skipped before the walls close and made once they are near."""
    from softcath_ros.core.fe3d.ramp import run_ramp

    _, fast, (f_fact, f_its, f_search, f_skip) = contact_ramp     # the default Newton
    assert fast.converged, fast.message
    pb = Fe3dModel(short_design, mesh=COARSE, cache=False, threads=1, contact_distance=0.02,
                   newton=NewtonSettings(threads=1, reuse_ratio=None)).problem
    pb.contact.far = math.inf     # search at every chance
    full = run_ramp(pb, [1.0], CONTACT_LOADS)
    assert full.converged, full.message
    u_fact, u_its, u_skip = pb.factorizations, pb.iterations_total, pb.contact.skipped
    for a, b in zip(fast.points, full.points):
        assert a.load == b.load
        assert a.measured["bending_angle_rad"] == pytest.approx(b.measured["bending_angle_rad"], rel=1e-5)
        assert a.measured["arc_length_m"] == pytest.approx(b.measured["arc_length_m"], rel=1e-6)
    assert f_fact < f_its and u_fact >= u_its
    assert u_skip == 0 and f_skip > 0 and f_search > 0
    assert fast.min_gap_m[-1][1] < 0.02 * short_design.lumen.diameter   # the walls closed: contact active


def test_a_channel_wall_through_the_body_axis_is_measured_not_a_netgen_traceback(implemented_design):
    """The implemented design with its channel 0.2 mm lower: the channel's wall touches the body axis,
    where the backbone used to be read (netgen's "Meshpoint 0 not in mesh!" as a traceback). The
    axis point is carried with the section's rigid fit instead; a point in no element is a ModelError
    of one line."""
    from softcath_ros.core.fe3d.measure import _axis_in_solid, _evaluate, deformed_backbone, measure

    ch = implemented_design.channels[0]
    low = dataclasses.replace(implemented_design.with_length(0.010), min_wall_thickness=0.2e-3,
                              channels=(dataclasses.replace(ch, center=(0.0, ch.center[1] - 0.2e-3)),))
    problem = Fe3dModel(low, mesh=COARSE, cache=False, threads=1).problem
    assert not _axis_in_solid(problem)
    out = measure(problem)   # the unloaded body
    assert out["bending_angle_rad"] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(out["tip_position_m"], [0.0, 0.0, low.length], atol=1e-12)
    backbone = deformed_backbone(problem, 2e-3)
    np.testing.assert_allclose(backbone[:, :2], 0.0, atol=1e-12)
    assert _axis_in_solid(Fe3dModel(implemented_design.with_length(0.010), mesh=COARSE, cache=False).problem)
    with pytest.raises(ModelError, match=r"cannot read the displacement at x = 9\.000") as err:
        _evaluate(problem, np.array([[9e-3, 0.0, 1e-3]]))
    assert "\n" not in str(err.value)


@pytest.fixture
def sector_design():
    """docs/examples/sectors.yaml (three 96 deg sectors round a central lumen), 10 mm, no device."""
    from pathlib import Path

    from softcath_ros.core.design import load_design

    path = Path(__file__).resolve().parents[1] / "docs" / "examples" / "sectors.yaml"
    return dataclasses.replace(load_design(path).with_length(0.010), device=None)


def test_sector_channels_are_meshed_from_their_outlines_and_bend_the_body_away(sector_design):
    """A sector design through fe3d: the section face built from the outlines (its arcs' mesh points
    moved so the polygons enclose the exact areas, as the circles'), the half body on the mirror
    plane of channel 0 found from the geometry, channels 1 and 2 mirror partners; pressurising
    channel 0 (at +y) bends the body towards -y, inflates the channel and reports the whole body's
    channel volumes."""
    from softcath_ros.core.fe3d.measure import channel_area
    from softcath_ros.core.fe3d.symmetry import can_use_half_model, mirror_plane
    from softcath_ros.core.geometry import symmetry

    d = sector_design
    assert not can_use_half_model(d)   # channels 1 and 2 lie off x = 0
    assert mirror_plane(d, (1.0, 0.0, 0.0)) == pytest.approx(math.pi / 2)
    assert mirror_plane(d, (1.0, 1.0, 0.0)) is not None and mirror_plane(d, (1.0, 0.5, 0.0)) is None
    found = symmetry(d.section)   # the geometry layer's mirrors: every plane fe3d turns to is one
    assert all(found.has_mirror(mirror_plane(d, p)) for p in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (0, 1, 1)))
    model = Fe3dModel(d, mesh=COARSE, cache=False, threads=1, half=True, contact_distance=None,
                      step_control=default_step_control(step=3000.0))
    problem = model.problem_for(np.array([1.0, 0.0, 0.0]))
    assert problem.half and problem.rotation == 0.0
    v_open = np.array([h.area for h in d.channels]) * (d.length - d.cap_thickness)
    rest = problem.channel_volumes()
    np.testing.assert_allclose(rest, v_open, rtol=1e-9)   # the arcs snapped like the circles
    rest_area = channel_area(problem, 0)
    assert rest_area == pytest.approx(d.channels[0].area, rel=1e-9)
    state = model.evaluate(np.array([[6000.0, 0.0, 0.0]]))
    assert state.converged.all(), state.message
    kx, ky = state.curvature[0]
    assert ky < 0 and abs(kx) < 1e-6 * abs(ky)
    vol = state.diagnostics.channel_volume[0]
    assert vol[0] > rest[0] and vol[1] == pytest.approx(vol[2], rel=1e-9)
    assert state.diagnostics.channel_area[0][0] > rest_area


def _scaled_design(design, s: float):
    """``design`` with every length scaled by ``s`` (section, body, cap, reinforcement, walls)."""
    def hole(h):
        return dataclasses.replace(h, diameter=h.diameter * s, center=tuple(c * s for c in h.center))

    r = design.reinforcement
    return dataclasses.replace(
        design, name=f"{design.name}_x{s:g}", length=design.length * s, outer_diameter=design.outer_diameter * s,
        channels=tuple(hole(h) for h in design.channels), lumen=hole(design.lumen),
        limiting_fibre=hole(design.limiting_fibre), cap_thickness=design.cap_thickness * s,
        min_wall_thickness=design.min_wall_thickness * s,
        reinforcement=dataclasses.replace(r, pitch=r.pitch * s, thread_diameter=r.thread_diameter * s))


def test_a_design_scaled_as_a_whole_is_meshed_alike_and_bends_alike(implemented_design):
    """The solid's equations have no length scale: the implemented design scaled to a 2 mm body
    bends by the same angle at the same pressure when its mesh scales with it (the rung's mesh
    lengths are for a 5 mm body, scaled by the outer diameter; they used to be absolute, so a
    2 mm body got 2.5x longer prisms relative to its size)."""
    p = np.array([[5000.0]])
    big = implemented_design.with_length(0.010)
    small = _scaled_design(big, 0.4)
    models = [Fe3dModel(d, cache=False, threads=1, mesh_size=3.0, layer_h=4e-3, contact_distance=None)
              for d in (big, small)]
    assert models[1].mesh_settings.layer_h == pytest.approx(0.4 * models[0].mesh_settings.layer_h)
    states = [m.evaluate(p) for m in models]
    assert all(s.converged.all() for s in states), [s.message for s in states]
    assert models[0].problem.fes.ndof == models[1].problem.fes.ndof
    assert states[1].tip.angle[0] == pytest.approx(states[0].tip.angle[0], rel=1e-5)
    assert states[1].curvature[0, 1] * 0.4 == pytest.approx(states[0].curvature[0, 1], rel=1e-5)


def test_a_shaped_lumen_wall_is_chained_edge_to_edge_for_its_contact(implemented_design):
    """A U-shaped lumen (its centroid in the notch: not star-shaped about it, so its wall cannot be
    ordered by angle): its wall points are ordered by the section's edges (each next point shares a
    wall edge), the half wall from the plane to the plane, and its contact's barrier is scaled by
    the equal-area radius."""
    from softcath_ros.core.design import ShapedHole
    from softcath_ros.core.fe3d.measure import _edge_owners, lumen_wall_nodes
    from softcath_ros.core.geometry import PolygonShape, shape_outline

    shape = PolygonShape(((-0.0007, -0.0016), (0.0007, -0.0016), (0.0007, -0.0006), (0.00035, -0.0006),
                          (0.00035, -0.0012), (-0.00035, -0.0012), (-0.00035, -0.0006), (-0.0007, -0.0006)),
                         fillet=0.0001)
    outline = shape_outline(shape, "lumen")
    assert not outline.contains(outline.centroid)
    d = dataclasses.replace(implemented_design.with_length(0.010),
                            lumen=ShapedHole(shape, tuple(outline.centroid), "lumen", outline))
    problem = Fe3dModel(d, mesh=COARSE, cache=False, threads=1).problem
    assert problem.half and problem.contact is not None
    assert problem.contact.d_hat == pytest.approx(0.02 * 2.0 * math.sqrt(outline.area / math.pi))
    pts, _ = lumen_wall_nodes(problem)
    sec = problem.prism.section
    index = {tuple(p): i for i, p in enumerate(sec.points)}
    chain = [index[tuple(p)] for p in pts]
    owners = _edge_owners(sec)
    assert all((min(a, b), max(a, b)) in owners for a, b in zip(chain[:-1], chain[1:]))
    assert abs(pts[0][0]) < 1e-12 and abs(pts[-1][0]) < 1e-12 and len(set(chain)) == len(chain)


def test_a_section_netgen_cannot_mesh_is_one_line(short_design, monkeypatch):
    """netgen's own failure while meshing the section (its NgException) reaches the user as one
    ModelError line naming the design, never as netgen's traceback."""
    import netgen.occ

    from softcath_ros.core.fe3d.mesh import MeshSettings as Settings, mesh_section

    class Refuses:
        def __init__(self, *args, **kwargs):
            raise RuntimeError("Meshing failed!\n  surface 3: bad edge")

    monkeypatch.setattr(netgen.occ, "OCCGeometry", Refuses)
    with pytest.raises(ModelError, match=r"could not mesh implemented_5mm's section: Meshing failed! surface 3") as err:
        mesh_section(short_design, Settings(), True)
    assert "\n" not in str(err.value)


def test_shaped_holes_are_meshed_without_clusters_at_their_fillets(sector_design, implemented_design):
    """netgen's curvature safety: 0.5 where a hole is shaped (2 fills a 0.1 mm fillet with 50 um
    elements graded into the walls: 1.5x the DOF for 1 % in R_C, docs/validation.md), each arc still
    in two segments (its exact area); its own 2 where every hole is a circle (those designs' meshes
    as validated), or as MeshSettings says."""
    from softcath_ros.core.fe3d.mesh import MeshSettings, curvature_safety, mesh_section
    from softcath_ros.core.models.fe3d import mesh_settings

    base = mesh_settings()
    assert curvature_safety(sector_design, base) == 0.5 and curvature_safety(implemented_design, base) == 2.0
    fine = dataclasses.replace(base, curvature_safety=2.0)
    assert MeshSettings().scaled(2.0).curvature_safety is None and fine.scaled(2.0).curvature_safety == 2.0
    shaped, clustered = (mesh_section(sector_design, m, True) for m in (base, fine))
    assert len(shaped.triangles) < 0.7 * len(clustered.triangles)
    circles, as_before = (mesh_section(implemented_design, m, True) for m in (base, fine))
    np.testing.assert_array_equal(circles.points, as_before.points)
