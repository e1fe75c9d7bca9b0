"""The live 3D view: the body mesh (core), its CDR templates, and model_node publishing it."""
import math
import signal
import time

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from softcath_ros import topics
from softcath_ros.core.body_mesh import HIGH_RGBA, LOW_RGBA, SILICONE_RGBA, BodyMesh
from softcath_ros.core.design import load_design
from softcath_ros.core.kinematics import backbone_bend_angle, backbone_poses, radius_l_over_theta
from sector_designs import THREE_SECTOR_5MM

rclpy = pytest.importorskip("rclpy", reason="the ROS extra is part of the test set-up (scripts/test.sh)")


@pytest.mark.parametrize("design_name", ["implemented_5mm", "three_channel_5mm", THREE_SECTOR_5MM])
def test_body_mesh_is_a_tube_of_the_outer_diameter_coloured_by_channel_pressure(design_name):
    design = load_design(design_name)
    mesh = BodyMesh(design, 9, sides=16)
    k = np.array([40.0, -15.0])
    pos, quat = backbone_poses(k, design.length, 9)
    n_rings = 1 + design.n_channels + (design.lumen is not None)
    every = mesh.vertices(pos, quat).reshape(9, n_rings, 16, 3)
    v = every[:, 0]
    # every ring at the outer radius from its backbone point, in the plane normal to the tangent
    np.testing.assert_allclose(np.linalg.norm(v - pos[:, None], axis=-1), design.outer_radius, rtol=1e-12)
    tangent = np.gradient(pos, axis=0)   # finite differences: independent of the quaternion rotation
    tangent[1:-1] = pos[2:] - pos[:-2]    # central: parallel to the arc's tangent at the middle point
    tangent /= np.linalg.norm(tangent, axis=-1, keepdims=True)
    assert np.abs(np.einsum("rsk,rk->rs", (v - pos[:, None])[1:-1], tangent[1:-1])).max() < 1e-12
    n = design.n_channels
    pressures = np.linspace(design.max_pressure, 0.0, n)
    points, colours = mesh.triangle_list(pos, quat, pressures)
    assert points.shape == (8 * n_rings * 16 * 2 * 3, 3) and colours.shape == (len(points), 4)
    # the holes are drawn as their real outlines: at the base (no rotation) every hole ring's vertex
    # lies on its outline, channels in command order, then the lumen
    holes = list(design.section.channels) + ([design.section.lumen] if design.lumen is not None else [])
    for hole, ring in zip(holes, every[0, 1:]):
        assert max(hole.polygon.exterior.distance(Point(*p[:2])) for p in ring - pos[0]) < 2e-6
        assert Polygon((ring - pos[0])[:, :2]).area == pytest.approx(hole.area, rel=0.15)   # 16 chords
    # each channel's outer vertices lie over it (within the angle its outline spans, seen from the
    # axis), with its pressure's colour; the rest is silicone
    ring = every[0, 0] - pos[0]
    for c, hole in enumerate(design.section.channels):
        facing = ring[mesh.owner == c][:, :2]
        assert len(facing)
        centre = hole.centroid / np.linalg.norm(hole.centroid)
        pts = np.asarray(hole.polygon.exterior.coords)
        half = np.arccos(np.clip(pts @ centre / np.linalg.norm(pts, axis=1), -1, 1)).max()
        spacing = 2 * math.pi / 16
        assert np.arccos(np.clip(facing @ centre / design.outer_radius, -1, 1)).max() <= max(half, spacing / 2) + 1e-9
        f = pressures[c] / design.max_pressure
        want = (1 - f) * LOW_RGBA + f * HIGH_RGBA
        got = colours[mesh._vertex_owner == c]
        np.testing.assert_allclose(got, np.broadcast_to(want, got.shape))
        assert len(got) > 8 * 16 * 2 * 3   # its own wall inside, and its part of the outer surface
    assert (mesh.owner == -1).any()
    np.testing.assert_allclose(colours[mesh._vertex_owner == -1][0], SILICONE_RGBA)
    # over the limit is shown as the limit, never beyond
    _, over = mesh.triangle_list(pos, quat, np.full(n, 2 * design.max_pressure))
    np.testing.assert_allclose(over[mesh._vertex_owner == 0][0], HIGH_RGBA)


@pytest.mark.parametrize("degrees", [30.0, 179.0, 283.0, 340.0])
def test_the_bending_angle_of_a_backbone_counts_past_180_degrees(degrees):
    """The tangent's turning integrated along the backbone, not the tip orientation's rotation angle
    (2 acos |w|, which reads 283 degrees as 77); with a straight cap beyond the arc and in any direction."""
    theta, arc = math.radians(degrees), 0.039
    k = theta / arc * np.array([math.cos(0.7), math.sin(0.7)])
    _, quat = backbone_poses(k, arc, 20, cap=0.001)
    assert backbone_bend_angle(quat) == pytest.approx(theta, rel=1e-12)
    assert radius_l_over_theta(0.04, backbone_bend_angle(quat)) == pytest.approx(0.04 / theta, rel=1e-12)
    assert radius_l_over_theta(0.04, -theta) == pytest.approx(0.04 / theta, rel=1e-12)
    assert radius_l_over_theta(0.02, 0.0) == math.inf
    assert backbone_bend_angle(backbone_poses(np.zeros(2), arc, 5)[1]) == 0.0


def test_templates_deserialise_to_the_messages_they_stand_for():
    from nav_msgs.msg import Path
    from rclpy.serialization import deserialize_message
    from visualization_msgs.msg import Marker

    from softcath_ros.nodes.live_view import marker_template, path_template

    rng = np.random.default_rng(1)
    t, points, colours = marker_template("softcath_base", 30)
    points[:] = rng.normal(size=(30, 3))
    colours[:] = rng.uniform(size=(30, 4))
    t.set_stamp(1_700_000_000_123_456_789)
    m = deserialize_message(t.to_bytes(), Marker)
    assert (m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id) == (1_700_000_000, 123_456_789,
                                                                            "softcath_base")
    assert m.type == Marker.TRIANGLE_LIST and m.action == Marker.ADD and m.pose.orientation.w == 1.0
    np.testing.assert_array_equal([[p.x, p.y, p.z] for p in m.points], points)
    np.testing.assert_array_equal([[c.r, c.g, c.b, c.a] for c in m.colors], colours)
    t, poses, stamps = path_template("softcath_base", 5)
    rows = rng.normal(size=(5, 7))
    for view, stamp, row in zip(poses, stamps, rows):
        view[:] = row
        stamp[:] = (12, 34)
    t.set_stamp(12_000_000_034)
    msg = deserialize_message(t.to_bytes(), Path)
    assert len(msg.poses) == 5 and msg.header.frame_id == "softcath_base"
    for ps, row in zip(msg.poses, rows):
        p, q = ps.pose.position, ps.pose.orientation
        assert [p.x, p.y, p.z, q.x, q.y, q.z, q.w] == list(row)
        assert (ps.header.stamp.sec, ps.header.stamp.nanosec, ps.header.frame_id) == (12, 34, "softcath_base")


def test_path_template_finds_each_stamp_beside_its_pose_when_stray_bytes_repeat_a_sentinel(monkeypatch):
    """The serialiser leaves CDR's alignment padding unwritten: stray bytes equal to a stamp's
    sentinel elsewhere in the buffer (model_node once failed to start on "sentinel 0000c05a found
    more than one time(s)") do not move or stop the template: each stamp is found beside its pose."""
    import struct

    from rclpy.serialization import serialize_message

    from softcath_ros.nodes import live_view

    stray = struct.pack("<II", 0x5AC00000, 0x0ACE0000) * 2
    monkeypatch.setattr(live_view, "serialize_message", lambda msg: serialize_message(msg) + stray)
    t, poses, stamps = live_view.path_template("softcath_base", 3)
    for i, stamp in enumerate(stamps):
        stamp[:] = (100 + i, 7)
    data = bytes(t.to_bytes())
    assert data.endswith(stray)
    for i in range(3):
        assert data.count(struct.pack("<II", 100 + i, 7)) == 1


def test_model_node_publishes_the_view_at_its_own_rate_without_tf2(start_node):
    """Commands at ~200 Hz; the view comes at the display rate (10 Hz here), from the latest pose."""
    from nav_msgs.msg import Path
    from std_msgs.msg import Float64
    from visualization_msgs.msg import Marker

    from softcath_ros.nodes.qos import stream_qos

    pytest.importorskip("visualization_msgs")
    with pytest.raises(ImportError):
        import tf2_ros  # noqa: F401  (the pip install has none: this test is about that case)
    node = start_node("-p", "display_rate:=10.0", "-p", "backbone_points:=8")
    got = {"marker": [], "path": [], "radius": []}
    n = node.client.node
    qos = stream_qos(100)
    n.create_subscription(Marker, topics.BODY_MARKER, got["marker"].append, qos)
    n.create_subscription(Path, topics.BACKBONE_PATH, got["path"].append, qos)
    n.create_subscription(Float64, topics.RADIUS_L_OVER_THETA, got["radius"].append, qos)
    node.sync()   # the node's view publishers have matched the new subscriptions
    t0 = time.monotonic()
    sent = 0
    # ~200 Hz of new commands for at least 2 s and until a few views arrived (a loaded machine only
    # makes it last longer); then a distinct one, whose pose the last view must show.
    while time.monotonic() - t0 < 2.0 or len(got["marker"]) < 4:
        assert time.monotonic() - t0 < 60.0, f"{len(got['marker'])} views for {sent} commands in 60 s"
        node.client._pub.publish(node.client._msg_type(data=[20000.0 + sent % 100]))   # each one new
        sent += 1
        node.client.spin_until(lambda: False, 0.005)
    # The answers to the stream may still be arriving: the last command's is the backbone ending at
    # its predicted tip (closed form, as the node runs it).
    from test_model_node import expected_tip

    tip = expected_tip(30000.0)[0]
    node.client._pub.publish(node.client._msg_type(data=[30000.0]))
    bbs = node.client._backbones
    assert node.client.spin_until(lambda: bbs and np.allclose([bbs[-1].poses[-1].position.y,
                                                               bbs[-1].poses[-1].position.z], tip[1:], atol=1e-12), 30.0)
    last = [[b.position.x, b.position.y, b.position.z] for b in bbs[-1].poses]
    assert node.client.spin_until(lambda: got["path"] and got["path"][-1].poses[-1].pose.position.y == last[-1][1], 30.0)
    elapsed = time.monotonic() - t0
    n_markers, n_tips = len(got["marker"]), node.client.n_received
    # At most the display rate (10 Hz): not one per pose; a starved timer only makes fewer.
    assert n_markers <= 10 * elapsed + 2, (n_markers, elapsed)
    assert n_tips > 2 * n_markers and sent > 2 * n_markers, (n_tips, sent, n_markers)
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in got["marker"]]
    assert stamps == sorted(set(stamps)), "every view shows a newer pose than the one before"
    m = got["marker"][-1]
    assert m.header.frame_id == topics.FRAME_ID and m.type == Marker.TRIANGLE_LIST
    assert len(m.points) == 7 * 3 * 12 * 2 * 3 and len(m.colors) == len(m.points)   # outer, channel, lumen
    path = got["path"][-1]
    np.testing.assert_allclose([[p.pose.position.x, p.pose.position.y, p.pose.position.z] for p in path.poses],
                               last, atol=1e-15)
    quats = [[b.orientation.x, b.orientation.y, b.orientation.z, b.orientation.w] for b in bbs[-1].poses]
    want = radius_l_over_theta(load_design("implemented_5mm").length, backbone_bend_angle(quats))
    node.client.spin_until(lambda: got["radius"] and abs(got["radius"][-1].data - want) < 1e-9 * want, 30.0)
    assert got["radius"][-1].data == pytest.approx(want, rel=1e-9)
    code, err = node.stop(signal.SIGTERM)
    assert code == 0 and "Traceback" not in err
    assert "tf2_ros is not importable" in err


def test_r_c_past_180_degrees_is_the_rungs_own_on_the_topic_and_in_the_sweep_tool(start_node):
    """At 0.25 bar the 40 mm body bends through about 283 degrees on the default rung: the R_C topic and
    the sweep tool's table say what `softcath sweep` (core.prediction) says, not l over the tip
    orientation's folded-back angle (29.84 mm / 76.8 degrees before the fix)."""
    import io

    from std_msgs.msg import Float64

    from softcath_ros.core.models import make_model
    from softcath_ros.core.prediction import predict
    from softcath_ros.nodes.qos import stream_qos
    from softcath_ros.tools.pressure_sweep import print_table

    design = load_design("implemented_5mm")
    want = predict(make_model("surrogate", design), np.array([[25000.0]]))[0]
    assert want.converged and want.bending_angle_rad > math.pi
    node = start_node("-p", "model:=surrogate", "-p", "display_rate:=20.0")
    radius = []
    node.client.node.create_subscription(Float64, topics.RADIUS_L_OVER_THETA, radius.append, stream_qos(100))
    node.client.spin_until(lambda: False, 1.0)   # discovery of the new subscription
    point = node.client.send([25000.0])
    assert point is not None
    assert node.client.spin_until(lambda: bool(radius), 5.0)
    assert radius[-1].data == pytest.approx(want.radius_of_curvature_m, rel=1e-9)
    centreline, angle = point.radius_and_angle(design.cap_thickness)
    assert angle == pytest.approx(want.bending_angle_rad, rel=1e-9)
    out = io.StringIO()
    print_table([point], [[25000.0]], design.length, design.cap_thickness, file=out)
    cells = out.getvalue().splitlines()[1].split()
    assert float(cells[1]) == pytest.approx(want.radius_of_curvature_m * 1e3, abs=0.006)
    assert float(cells[3]) == pytest.approx(math.degrees(want.bending_angle_rad), abs=0.006)


def test_a_repeated_command_is_drawn_once_a_second(start_node):
    from visualization_msgs.msg import Marker

    from softcath_ros.nodes.qos import stream_qos

    node = start_node("-p", "display_rate:=20.0")
    got = []
    node.client.node.create_subscription(Marker, topics.BODY_MARKER, got.append, stream_qos(100))
    node.sync()
    # The same command at ~100 Hz for at least 2.5 s and until the view was redrawn once.
    t0 = time.monotonic()
    sent = 0
    while time.monotonic() - t0 < 2.5 or len(got) < 2:
        assert time.monotonic() - t0 < 60.0, f"{len(got)} views in 60 s of a repeated command"
        node.client._pub.publish(node.client._msg_type(data=[15000.0]))
        sent += 1
        node.client.spin_until(lambda: False, 0.01)
    elapsed = time.monotonic() - t0
    # first one, then about one a second (a 20 Hz view would draw 20 a second); never per command
    assert 2 <= len(got) <= 2 + elapsed, (len(got), elapsed, sent)


FAKE_TF2 = r"""
import json, os


class TransformBroadcaster:
    def __init__(self, node):
        self.out = os.environ["SOFTCATH_TEST_TF_OUT"]

    def sendTransform(self, t):
        tr, ro = t.transform.translation, t.transform.rotation
        with open(self.out, "a") as f:
            f.write(json.dumps({"parent": t.header.frame_id, "child": t.child_frame_id,
                                "stamp": [t.header.stamp.sec, t.header.stamp.nanosec],
                                "xyz": [tr.x, tr.y, tr.z], "q": [ro.x, ro.y, ro.z, ro.w]}) + "\n")
"""


def test_where_tf2_is_importable_the_tip_frame_is_broadcast(start_node, tmp_path):
    """A test double for tf2_ros's TransformBroadcaster (the pip install has no tf2): the node's
    broadcast path gives the tip pose under softcath_base, stamped like the pose."""
    import json
    import os

    (tmp_path / "tf2_ros").mkdir()
    (tmp_path / "tf2_ros" / "__init__.py").write_text(FAKE_TF2)
    out = tmp_path / "tf.jsonl"
    path = os.pathsep.join([str(tmp_path)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])
    node = start_node("-p", "tip_frame:=catheter_tip", "-p", "display_rate:=20.0",
                      env_extra={"PYTHONPATH": path, "SOFTCATH_TEST_TF_OUT": str(out)})
    from visualization_msgs.msg import Marker

    from softcath_ros.nodes.qos import stream_qos

    views = []     # whether the view was drawn, should no transform come
    node.client.node.create_subscription(Marker, topics.BODY_MARKER, views.append, stream_qos(10))
    node.sync()
    pt = node.client.send([25000.0])
    assert pt is not None
    node.client.spin_until(lambda: out.is_file() and out.read_text().strip(), 30.0)
    code, err = node.stop(signal.SIGTERM)
    assert code == 0 and "tf2_ros is not importable" not in err and "tf2_ros failed" not in err, err
    assert out.is_file(), f"no transform broadcast ({len(views)} view(s) drawn); the node said: {err[-1500:]}"
    sent = [json.loads(line) for line in out.read_text().splitlines()]
    assert sent, "no transform broadcast"
    t = sent[-1]
    assert (t["parent"], t["child"]) == (topics.FRAME_ID, "catheter_tip")
    assert t["stamp"][0] * 1_000_000_000 + t["stamp"][1] == pt.stamp_ns
    np.testing.assert_allclose(t["xyz"], pt.tip_position_m, atol=1e-15)
    np.testing.assert_allclose(t["q"], pt.tip_orientation_xyzw, atol=1e-15)


def test_display_rate_zero_turns_the_view_off(start_node):
    node = start_node("-p", "display_rate:=0.0")
    # start_node waited for a /diagnostics report: the node announces that publisher after the view's,
    # so a view publisher would be known here
    assert node.client.node.count_publishers(topics.DIAGNOSTICS) == 1
    assert node.client.node.count_publishers(topics.BODY_MARKER) == 0
    assert node.client.node.count_publishers(topics.BACKBONE_PATH) == 0
    assert node.client.send([10000.0]) is not None


def test_foxglove_layout_names_the_view_and_the_plots():
    import json

    from layout_check import LAYOUT, layout_topics

    layout = json.loads(LAYOUT.read_text())
    named = layout_topics(layout)
    assert {topics.BODY_MARKER, topics.BACKBONE_PATH, topics.TIP_POSE, topics.PRESSURE_CMD,
            topics.pressure_measured_topic(0), topics.RADIUS_L_OVER_THETA} <= named
    assert all(topics.message_type(t) for t in named)   # every one a topic of the suite
    three_d = [c for k, c in layout["configById"].items() if k.startswith("3D!")]
    assert len(three_d) == 1 and three_d[0]["followTf"] == topics.FRAME_ID
    # every panel of the layout tree is configured, and every configured panel is placed
    placed = set()

    def walk(node):
        if isinstance(node, str):
            placed.add(node)
        else:
            walk(node["first"])
            walk(node["second"])
    walk(layout["layout"])
    assert placed == set(layout["configById"])
