"""Constant-curvature kinematics against hand-computed arcs."""
import math

import numpy as np
import pytest

from softcath_ros.core.kinematics import (backbone_poses, bending_angle, curvature_for_tip, tip_pose,
                                          tip_pose_single)

L = 0.04


def rotate(q, v):
    """Rotate vector v by unit quaternion q (x, y, z, w)."""
    x, y, z, w = q
    u = np.array([x, y, z])
    return 2 * np.dot(u, v) * u + (w * w - np.dot(u, u)) * np.asarray(v) + 2 * w * np.cross(u, v)


def test_straight_backbone():
    pos, q = tip_pose(np.zeros(2), L)
    np.testing.assert_allclose(pos, [0, 0, L], atol=1e-15)
    np.testing.assert_allclose(q, [0, 0, 0, 1], atol=1e-15)


def test_quarter_circle_towards_minus_y():
    r = 2 * L / math.pi                       # quarter circle: L = R pi / 2
    pos, q = tip_pose(np.array([0.0, -1.0 / r]), L)
    np.testing.assert_allclose(pos, [0, -r, r], atol=1e-12)
    # The tip tangent points along -y after a 90 degree bend.
    np.testing.assert_allclose(rotate(q, [0, 0, 1]), [0, -1, 0], atol=1e-12)


def test_half_circle_towards_plus_x():
    r = L / math.pi
    pos, q = tip_pose(np.array([1.0 / r, 0.0]), L)
    np.testing.assert_allclose(pos, [2 * r, 0, 0], atol=1e-12)
    np.testing.assert_allclose(rotate(q, [0, 0, 1]), [0, 0, -1], atol=1e-12)


@pytest.mark.parametrize("direction_deg", [0, 37, 90, 135, 180, 251, 300, 359.9])
def test_any_direction_matches_planar_arc(direction_deg):
    kappa = 30.0
    u = np.array([math.cos(math.radians(direction_deg)), math.sin(math.radians(direction_deg))])
    pos, q = tip_pose(kappa * u, L)
    theta = kappa * L
    radial = (1 - math.cos(theta)) / kappa
    np.testing.assert_allclose(pos, [radial * u[0], radial * u[1], math.sin(theta) / kappa], atol=1e-12)
    tangent = [math.sin(theta) * u[0], math.sin(theta) * u[1], math.cos(theta)]
    np.testing.assert_allclose(rotate(q, [0, 0, 1]), tangent, atol=1e-12)


def test_tiny_curvature_is_smooth_and_keeps_direction():
    for kappa in (1e-3, 1e-8, 1e-12, 1e-200):
        k = np.array([-kappa, 0.0])
        pos, q = tip_pose(k, L)
        assert np.all(np.isfinite(pos)) and np.all(np.isfinite(q))
        # first-order arc: deflection kappa L^2 / 2 towards -x, never flipped
        assert pos[0] < 0
        assert pos[0] == pytest.approx(-kappa * L * L / 2, rel=1e-6)
        assert pos[2] == pytest.approx(L, rel=1e-9)


def test_quaternions_unit_and_tangent_consistent_along_backbone():
    rng = np.random.default_rng(1)
    ks = rng.normal(scale=40.0, size=(50, 2))
    lengths = rng.uniform(0.01, 0.05, size=50)
    pos, quat = backbone_poses(ks, lengths, 41)
    assert pos.shape == (50, 41, 3) and quat.shape == (50, 41, 4)
    np.testing.assert_allclose(np.linalg.norm(quat, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(pos[:, 0], 0.0, atol=1e-15)
    for i in range(0, 50, 7):
        # finite-difference tangent of the positions equals the quaternion's z axis
        ds = lengths[i] / 40
        fd = (pos[i, 2:] - pos[i, :-2]) / (2 * ds)
        z_axes = np.array([rotate(q, [0, 0, 1]) for q in quat[i, 1:-1]])
        np.testing.assert_allclose(fd, z_axes, atol=(np.hypot(*ks[i]) * ds) ** 2 + 1e-9)  # O(ds^2) FD error


def test_backbone_ends_at_tip():
    k = np.array([12.0, -5.0])
    pos, quat = backbone_poses(k, L, 10)
    tpos, tq = tip_pose(k, L)
    np.testing.assert_allclose(pos[-1], tpos)
    np.testing.assert_allclose(quat[-1], tq)
    with pytest.raises(ValueError):
        backbone_poses(k, L, 1)


def test_bending_angle():
    assert bending_angle(np.array([3.0, 4.0]), 0.1) == pytest.approx(0.5)


@pytest.mark.parametrize("k", [[0.0, -39.27], [25.0, 10.0], [1e-9, 0.0], [0.0, 0.0], [-70.0, 50.0]])
def test_inverse_recovers_curvature(k):
    k = np.array(k)
    pos, _ = tip_pose(k, L)
    inv = curvature_for_tip(pos, L)
    assert inv.reachable
    np.testing.assert_allclose(inv.curvature, k, rtol=1e-9, atol=1e-9)
    assert inv.arc_length == pytest.approx(L, rel=1e-9)


def test_inverse_reports_unreachable_points():
    inv = curvature_for_tip(np.array([0.0, 0.0, 2 * L]), L)   # straight ahead but too far
    assert not inv.reachable and inv.arc_length == pytest.approx(2 * L)
    inv = curvature_for_tip(np.array([0.0, 0.0, 0.0]), L)
    assert not inv.reachable
    inv = curvature_for_tip(np.array([0.0, 0.0, -0.01]), L)   # straight behind the base
    assert not inv.reachable


def test_scalar_tip_pose_matches_vectorised():
    from softcath_ros.core.kinematics import tip_pose_single

    for k in ([0.0, 0.0], [1e-9, -2e-9], [3e-5, 0.0], [25.0, -40.0], [0.0, -78.5]):
        pos, q = tip_pose(np.array(k), L)
        spos, sq = tip_pose_single(k[0], k[1], L)
        np.testing.assert_allclose(spos, pos, rtol=1e-13, atol=1e-18)
        np.testing.assert_allclose(sq, q, rtol=1e-13, atol=1e-18)


def test_planar_backbone_poses_reproduce_an_arc():
    """Resampling a solved backbone (as the rod gives) returns the arc's own poses for an arc."""
    from softcath_ros.core.kinematics import backbone_poses, planar_backbone_poses

    k = np.array([0.0, -40.0])
    dense, _ = backbone_poses(k, 0.03, 2001)
    pos, quat = planar_backbone_poses(dense, 11)
    ref_pos, ref_quat = backbone_poses(k, 0.03, 11)
    np.testing.assert_allclose(pos, ref_pos, atol=1e-8)
    np.testing.assert_allclose(quat, ref_quat, atol=1e-5)
    straight, q0 = planar_backbone_poses(np.column_stack([np.zeros(5), np.zeros(5), np.linspace(0, 0.02, 5)]), 3)
    np.testing.assert_allclose(q0, [[0, 0, 0, 1]] * 3, atol=1e-12)


CAP = 0.001


@pytest.mark.parametrize("k", [[0.0, 0.0], [1e-9, 0.0], [0.0, -40.0], [30.0, 55.0], [-120.0, 10.0]])
def test_straight_cap_continues_the_arc_along_its_end_tangent(k):
    """The tip is the arc's end plus the cap along the end tangent (the arc's end orientation turns z
    onto it); the orientation is the arc's; the backbone's last pose is the tip, its points in the cap
    on that line; the scalar tip is the vectorised one; the inverse with the cap returns the arc."""
    from softcath_ros.core.kinematics import arc_tangent, tip_pose_single

    from scipy.spatial.transform import Rotation

    k = np.array(k, dtype=float)
    arc = L - CAP
    end, q_end = tip_pose(k, arc)
    tip, q_tip = tip_pose(k, arc, CAP)
    t = arc_tangent(k, arc)
    assert np.linalg.norm(t) == pytest.approx(1.0, rel=1e-12)
    np.testing.assert_allclose(t, Rotation.from_quat(q_end).apply([0.0, 0.0, 1.0]), atol=1e-12)
    np.testing.assert_allclose(tip, end + CAP * t, atol=1e-15)
    np.testing.assert_allclose(q_tip, q_end, atol=0)
    np.testing.assert_allclose(tip_pose_single(k[0], k[1], arc, CAP)[0], tip, rtol=1e-13, atol=1e-17)
    pos, quats = backbone_poses(k, arc, 41, CAP)
    np.testing.assert_allclose(pos[-1], tip, atol=1e-15)
    in_cap = np.linspace(0.0, L, 41) > arc
    np.testing.assert_allclose(np.cross(pos[in_cap] - end, t), 0.0, atol=1e-15)
    np.testing.assert_allclose(quats[in_cap], np.broadcast_to(q_end, quats[in_cap].shape), atol=1e-15)
    inv = curvature_for_tip(tip, arc, cap=CAP)
    assert inv.reachable and inv.arc_length == pytest.approx(arc, rel=1e-10)
    np.testing.assert_allclose(inv.curvature, k, rtol=1e-9, atol=1e-9)


def test_inverse_with_a_cap_on_a_batch_and_off_the_workspace():
    ks = np.array([[0.0, 0.0], [20.0, 0.0], [0.0, -150.0]])
    arcs = np.array([0.02, 0.039, 0.016])
    caps = np.full(3, CAP)
    tips, _ = tip_pose(ks, arcs, caps)
    inv = curvature_for_tip(tips, arcs, cap=caps)
    assert inv.reachable.all()
    np.testing.assert_allclose(inv.curvature, ks, rtol=1e-9, atol=1e-9)
    # a point behind the base has no arc; one too close to it needs a shorter arc than the body has
    assert not curvature_for_tip(np.array([0.0, 0.0, -0.01]), L, cap=CAP).reachable
    short = curvature_for_tip(np.array([0.002, 0.0, 0.01]), L - CAP, cap=CAP)
    assert not short.reachable and short.arc_length < L - CAP


@pytest.mark.parametrize("cap", [0.0, 0.001, 0.005])
def test_one_tip_inverse_is_the_batch_inverse(cap):
    """One tip (the steering controller's, per target and sample: plain floats) gives what the array
    form gives for it as a batch of one and among others: bends up to 4.5 rad (past the base plane),
    noisy tips, and no arc at all."""
    rng = np.random.default_rng(4)
    tips = []
    for i in range(300):
        theta, phi = rng.uniform(0.0, 4.5), rng.uniform(-np.pi, np.pi)
        k = theta / 0.039
        tip = np.array(tip_pose_single(k * np.cos(phi), k * np.sin(phi), 0.039, cap)[0])
        tips.append(tip + rng.normal(0.0, 1e-4, 3) * (i % 2))
    tips += [np.array(t) for t in ([0.0, 0.0, 0.04], [0.0, 0.0, -0.01], [0.0, 0.0, 0.0])]
    whole = curvature_for_tip(np.array(tips), 0.039, cap=cap)

    def row(inv, j):   # (kx, ky, arc length, reachable) of tip j
        return [*np.reshape(inv.curvature, (-1, 2))[j], np.ravel(inv.arc_length)[j], bool(np.ravel(inv.reachable)[j])]

    for i, tip in enumerate(tips):
        one = curvature_for_tip(tip, 0.039, cap=cap)
        assert one.curvature.shape == (2,) and np.ndim(one.arc_length) == 0 and np.ndim(one.reachable) == 0
        for batch, j in ((curvature_for_tip(tip[None], 0.039, cap=cap), 0), (whole, i)):
            assert row(one, 0)[3] == row(batch, j)[3]
            if np.isfinite(row(batch, j)[2]):
                assert np.allclose(row(one, 0)[:3], row(batch, j)[:3], rtol=1e-12, atol=0)
            else:
                assert row(one, 0)[:3] == row(batch, j)[:3]
    assert 0 < whole.reachable.sum() < len(tips)
    # without a length, reachable says only that an arc ends there
    assert curvature_for_tip(tips[0], cap=cap).reachable and not curvature_for_tip(tips[-2], cap=cap).reachable
    np.testing.assert_array_equal(curvature_for_tip(np.array(tips), cap=cap).reachable, np.isfinite(whole.arc_length))


@pytest.mark.parametrize("cap", [0.0, 0.001])
def test_one_curvatures_backbone_is_the_batch_paths(cap):
    """``backbone_poses`` of one curvature (the model node's path, its own 1-D formulas) equals the
    batch path's, to round-off, from straight and tiny curvatures to a body bent past a full turn."""
    rng = np.random.default_rng(5)
    ks = [np.zeros(2), np.array([1e-12, 0.0]), np.array([0.0, -3e-9])]
    ks += [rng.normal(size=2) * 10 ** rng.uniform(-3, 2.7) for _ in range(100)]
    for k in ks:
        p1, q1 = backbone_poses(k, 0.04, 20, cap)
        p2, q2 = backbone_poses(k[None], np.array([0.04]), 20, np.array([cap]))
        np.testing.assert_allclose(p1, p2[0], rtol=0, atol=1e-15)
        np.testing.assert_allclose(q1, q2[0], rtol=0, atol=1e-14)
