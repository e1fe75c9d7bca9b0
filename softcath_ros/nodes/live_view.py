"""model_node's live 3D view: the body as a Marker, the backbone as a Path, R_C, the tip on TF.

At ``display_rate`` (a timer, independent of the pose stream) the latest accepted prediction
is published, if there is a new one (a repeat of the shown command only once a second: a
bench dwelling on a step does not fill its recording with identical 55 kB markers): ``/softcath/body_marker`` (visualization_msgs/Marker,
TRIANGLE_LIST: a tube of the outer diameter along the backbone, channel surfaces coloured by
pressure, core.body_mesh), ``/softcath/backbone_path`` (nav_msgs/Path) and
``/softcath/radius_l_over_theta`` (std_msgs/Float64, R_C = l / theta of the design length and the
rung's own bending angle, m, also past 180 degrees; not published while straight), all in ``softcath_base`` and stamped with the prediction's
stamp. The pose callback only stores a reference to its result (no copy, no work).

The Marker (about 1400 vertices) and the Path are preallocated CDR templates
(nodes/cdr.MessageTemplate) rewritten through numpy views; benchmarks/node_latency.py
measures what the view costs the node.

TF: where tf2_ros is importable (a sourced ROS workspace) the tip is broadcast as frame
``tip_frame`` under ``softcath_base`` at the display rate. The PyPI wheels have no tf2_ros:
then no TF is broadcast, and the node says so once at start-up.
"""
from __future__ import annotations

import struct
import time

import numpy as np
from nav_msgs.msg import Path
from geometry_msgs.msg import Point, PoseStamped
from rclpy.serialization import serialize_message
from std_msgs.msg import ColorRGBA, Float64
from visualization_msgs.msg import Marker

from .. import topics
from ..core.body_mesh import BodyMesh
from ..core.kinematics import radius_l_over_theta
from .cdr import MessageTemplate

_S_FIRST, _S_LAST = 1.2345678901234567e-200, 7.654321098765432e-201   # sentinels (f8)
_S_RGBA_FIRST, _S_RGBA_LAST = np.float32(0.1234567), np.float32(0.7654321)


def marker_template(frame_id: str, n_vertices: int) -> tuple[MessageTemplate, np.ndarray, np.ndarray]:
    """The body Marker as a template: (template, points view (N, 3) f8, colours view (N, 4) f4)."""
    m = Marker()
    m.header.frame_id = frame_id
    m.ns, m.id, m.type, m.action = "softcath_body", 0, Marker.TRIANGLE_LIST, Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = 1.0
    m.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
    m.points = [Point() for _ in range(n_vertices)]
    m.colors = [ColorRGBA() for _ in range(n_vertices)]
    m.points[0].x, m.points[-1].x = _S_FIRST, _S_LAST
    m.colors[0].r, m.colors[-1].r = float(_S_RGBA_FIRST), float(_S_RGBA_LAST)
    t = MessageTemplate(serialize_message(m))
    p0 = t.find(struct.pack("<d", _S_FIRST))
    c0 = t.find(_S_RGBA_FIRST.astype("<f4").tobytes())
    if t.find(struct.pack("<d", _S_LAST)) != p0 + 24 * (n_vertices - 1) or \
            t.find(_S_RGBA_LAST.astype("<f4").tobytes()) != c0 + 16 * (n_vertices - 1):
        raise ValueError("Marker points/colors are not contiguous in its CDR")
    points, colours = t.view(p0, "<f8", (n_vertices, 3)), t.view(c0, "<f4", (n_vertices, 4))
    points[:] = 0.0
    colours[:] = 0.0
    return t, points, colours


def path_template(frame_id: str, n_poses: int) -> tuple[MessageTemplate, list[np.ndarray], list[np.ndarray]]:
    """The backbone Path as a template: (template, per pose a (7,) f8 view x y z qx qy qz qw,
    per pose its header stamp (2,) u4 view)."""
    msg = Path()
    msg.header.frame_id = frame_id
    msg.poses = [PoseStamped() for _ in range(n_poses)]
    for i, ps in enumerate(msg.poses):
        ps.header.frame_id = frame_id
        ps.header.stamp.sec, ps.header.stamp.nanosec = 0x5AC00000 + i, 0x0ACE0000 + i
        ps.pose.position.x = _S_FIRST * (i + 2)
    t = MessageTemplate(serialize_message(msg))
    poses, stamps = [], []
    for i in range(n_poses):
        off = t.find(struct.pack("<d", _S_FIRST * (i + 2)))
        poses.append(t.view(off, "<f8", (7,)))
        # the pose's stamp lies before its position: its header (stamp, frame_id, padding) apart
        stamp = t.find(struct.pack("<II", 0x5AC00000 + i, 0x0ACE0000 + i), max(0, off - 32 - len(frame_id)), off)
        stamps.append(t.view(stamp, "<u4", (2,)))
        poses[-1][:] = 0.0
        stamps[-1][:] = 0
    return t, poses, stamps


class LiveView:
    """Owned by model_node: publishers, templates and the display timer."""

    def __init__(self, node, design, n_points: int, rate_hz: float, sides: int, tip_frame: str, qos):
        self.node = node
        self.length = design.length
        self.mesh = BodyMesh(design, n_points, sides)
        frame = topics.FRAME_ID
        self._marker, self._points, self._colours = marker_template(frame, self.mesh.n_vertices)
        self._path, self._path_poses, self._path_stamps = path_template(frame, n_points)
        self._poses = np.empty((n_points, 7))
        self.pub_marker = node.create_publisher(Marker, topics.BODY_MARKER, qos)
        self.pub_path = node.create_publisher(Path, topics.BACKBONE_PATH, qos)
        self.pub_radius = node.create_publisher(Float64, topics.RADIUS_L_OVER_THETA, qos)
        self.latest = None        # (stamp ns, positions (n, 3), quats (n, 4), pressures (C,), bending angle rad)
        self._shown = None
        self._shown_pressures = None
        self._t_published = 0.0
        self.keepalive_s = 1.0
        self.published = 0
        self.tip_frame = tip_frame
        self.tf = None
        try:
            from tf2_ros import TransformBroadcaster
        except ImportError:
            node.get_logger().info("tf2_ros is not importable (the pip install has no tf2 wheel): the tip "
                                   "frame is not broadcast on /tf; /softcath/tip_pose carries it")
        except Exception as exc:  # noqa: BLE001 - a broken tf2 install must not take the model down
            node.get_logger().warning(f"tf2_ros failed to load ({type(exc).__name__}: {exc}): no TF broadcast")
        else:
            self.tf = TransformBroadcaster(node)
        self.timer = node.create_timer(1.0 / rate_hz, self.show)

    def show(self) -> None:
        latest = self.latest
        if latest is None or latest is self._shown:
            return
        self._shown = latest
        stamp_ns, positions, quats, pressures, angle = latest
        # The same command again (a bench dwelling on a step): nothing new to draw; once a second
        # anyway, so a viewer that joins late gets the body.
        now = time.monotonic()
        if self._shown_pressures is not None and np.array_equal(pressures, self._shown_pressures) and \
                now - self._t_published < self.keepalive_s:
            return
        self._shown_pressures = np.array(pressures, copy=True)
        self._t_published = now
        self.mesh.triangle_list(positions, quats, pressures, out_points=self._points, out_colours=self._colours)
        self._marker.set_stamp(stamp_ns)
        self.pub_marker.publish(self._marker.to_bytes())
        poses = self._poses
        poses[:, :3], poses[:, 3:] = positions, quats
        sec_nsec = divmod(stamp_ns, 1_000_000_000)
        for view, stamp, row in zip(self._path_poses, self._path_stamps, poses):
            view[:] = row
            stamp[:] = sec_nsec
        self._path.set_stamp(stamp_ns)
        self.pub_path.publish(self._path.to_bytes())
        r = radius_l_over_theta(self.length, angle)
        if np.isfinite(r):
            self.pub_radius.publish(Float64(data=r))
        if self.tf is not None:
            self._broadcast_tip(stamp_ns, positions[-1], quats[-1])
        self.published += 1

    def _broadcast_tip(self, stamp_ns: int, position, quat) -> None:
        from geometry_msgs.msg import TransformStamped

        t = TransformStamped()
        t.header.stamp.sec, t.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        t.header.frame_id, t.child_frame_id = topics.FRAME_ID, self.tip_frame
        tr, ro = t.transform.translation, t.transform.rotation
        tr.x, tr.y, tr.z = (float(v) for v in position)
        ro.x, ro.y, ro.z, ro.w = (float(v) for v in quat)
        self.tf.sendTransform(t)
