"""The body's reach of itself and of its shaft (core/body_contact.py), and every path that refuses it."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from softcath_ros.core.body_contact import body_contact, may_reach
from softcath_ros.core.continuation import OUTSIDE_MODEL, tagged_stop
from softcath_ros.core.design import load_design
from softcath_ros.core.kinematics import backbone_poses
from softcath_ros.core.models import make_model
from softcath_ros.core.prediction import predict

R = 0.0025   # the 5 mm body's radius


def arc(rho, theta, cap=0.0, n=None):
    length = rho * theta
    n = n or max(3, math.ceil((length + cap) / (0.4 * R)) + 1)
    return backbone_poses(np.array([1.0 / rho, 0.0]), length, n, cap)[0]


def shaft_onset(rho):
    """The angle at which the tip face's outer corner of a planar arc (no cap) enters the body's
    straight continuation below the base: rho - (rho + r) cos(theta) = r."""
    return 2.0 * math.pi - math.acos((rho - R) / (rho + R))


@settings(max_examples=40, deadline=None)
@given(rho=st.floats(1.05 * R, 0.2), fraction=st.floats(0.01, 0.999), cap=st.floats(0.0, 0.002))
def test_within_half_a_turn_an_arc_reaches_nothing(rho, fraction, cap):
    theta = fraction * math.pi
    assert not may_reach(theta)
    assert body_contact(arc(rho, theta, cap), R) is None


@settings(max_examples=25, deadline=None)
@given(rho=st.floats(0.004, 0.03))
def test_an_arc_reaches_its_shaft_where_the_tip_corner_crosses_the_base_axis(rho):
    onset = shaft_onset(rho)
    assert body_contact(arc(rho, onset - math.radians(3.0)), R) is None
    hit = body_contact(arc(rho, onset + math.radians(3.0)), R)
    assert hit is not None and hit.what == "shaft" and hit.depth_m > 0 and "shaft" in hit.describe()
    assert hit.at_m > rho * (onset - math.radians(3.0))   # a cross-section near the tip


def _crossing_path(offset):
    """Up the z axis 30 mm, over a 6 mm half circle, down to z = 12 mm, a quarter circle to heading
    -x at z = 6 mm, then straight across the first part's axis, ``offset`` (m) beside it in y."""
    h = 0.0002
    pts = [np.array([0.0, 0.0, z]) for z in np.arange(0.0, 0.030, h)]
    for a in np.arange(0.0, math.pi, h / 0.006):
        pts.append(np.array([0.006 - 0.006 * math.cos(a), 0.0, 0.030 + 0.006 * math.sin(a)]))
    down = np.arange(0.030, 0.012, -h)
    for j, z in enumerate(down):   # the sideways offset grows smoothly on the way down
        w = j / (len(down) - 1)
        pts.append(np.array([0.012, offset * w * w * (3 - 2 * w), z]))
    for a in np.arange(0.0, 0.5 * math.pi, h / 0.006):
        pts.append(np.array([0.006 + 0.006 * math.cos(a), offset, 0.012 - 0.006 * math.sin(a)]))
    pts += [np.array([x, offset, 0.006]) for x in np.arange(0.006, -0.010, -h)]
    return np.array(pts)


def test_a_body_crossing_its_own_earlier_part_reaches_itself_only_when_closer_than_its_diameter():
    near = body_contact(_crossing_path(0.003), R)
    assert near is not None and near.what == "itself" and not near.at_tip
    assert 0.0 < near.depth_m < R
    assert body_contact(_crossing_path(0.0055), R) is None


def test_a_bend_tighter_than_the_body_radius_folds():
    hit = body_contact(arc(0.8 * R, 0.5 * math.pi, n=60), R)
    assert hit is not None and hit.what == "fold"


@pytest.mark.parametrize("points,radius,says", [
    (np.zeros((2, 3)), R, r"needs \(M >= 3, 3\)"),
    (np.zeros((5, 2)), R, r"needs \(M >= 3, 3\)"),
    (np.column_stack([np.zeros(4), np.zeros(4), np.linspace(0, 0.04, 4)]), R, "apart; needs under"),
    (np.column_stack([np.zeros(4), np.zeros(4), np.linspace(0, 0.001, 4)]), 0.0, "needs > 0"),
])
def test_bad_backbones_get_one_line(points, radius, says):
    with pytest.raises(ValueError, match=says):
        body_contact(points, radius)


def test_predict_refuses_a_body_through_its_shaft_and_keeps_the_answers_before():
    """The shipped surrogate of the 40 mm design: 0.20 bar bends it 158 deg (an answer); at 0.27 bar
    it would turn about 350 deg, the tip through its own shaft: refused as outside the model, no numbers."""
    model = make_model("surrogate", load_design("implemented_5mm"), build=False)
    ok, coiled = predict(model, np.array([[20000.0], [27000.0]]))
    assert ok.converged and 2.0 < ok.bending_angle_rad < math.pi
    assert not coiled.converged and "shaft" in coiled.reason
    assert tagged_stop(coiled.reason) == OUTSIDE_MODEL
    doc = coiled.to_json()
    assert doc["tip_position_m"] is None and doc["radius_of_curvature_m"] is None
    # the same rung at 17 mm turns about 187 deg at 0.30 bar: past a half turn (so sampled) and clear
    short = predict(model, np.array([[30000.0]]), length=0.017)[0]
    assert short.converged and math.pi < short.bending_angle_rad < math.radians(250)
