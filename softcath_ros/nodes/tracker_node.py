"""tracker_node (node ``softcath_tracker``): the camera half of the rig contract (docs/rig.md,
docs/tracker.md). A managed (lifecycle) node (nodes/device_node.py) around
``softcath_ros.bench.frames.TrackedInput`` and ``softcath_ros.bench.tracker``:

- configure: opens the input (camera device, video file or folder of images), reads the first
  frame and sets the scene on it (scale, base and axis: given, or from ArUco markers); any fault
  is one line and the transition fails;
- activate: reads frames at ``rate_hz`` (a camera at its own pace) and, for each frame it can
  measure, publishes /softcath/bench/bend_angle (geometry_msgs/Vector3Stamped, vector.x = theta in
  rad, signed) and /softcath/tip_measured (geometry_msgs/PoseStamped in softcath_base: z along the
  unbent axis, the across side along ``bending_direction_deg`` in the x-y plane, m; orientation the
  tip's rotation by theta, as core/kinematics), both stamped with the time the frame was read; a frame it cannot measure publishes nothing and is counted, with its
  reason, on /diagnostics;
- deactivate stops reading; cleanup closes the input.

``autostart`` (default true) configures and activates at start-up (a configure fault then ends
the node with exit code 2); with false a lifecycle manager drives it.
"""
from __future__ import annotations

import math
import sys
from functools import partial

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped, Vector3Stamped

from .. import topics
from ..core.errors import SoftcathError
from .device_node import DeviceNode
from .diagnostics import diagnostic_status, publish_statuses
from .parameters import declare
from .runtime import run_node

MAX_MARKER_ID = 49   # the 4x4_50 dictionary


class TrackerNode(DeviceNode):

    def __init__(self, **node_options):
        super().__init__(topics.TRACKER_NODE, **node_options)
        p = partial(declare, self)
        self.input = p("input", "0", "camera device index (0, 1, ...), video file or folder of images")
        self.settings = dict(
            mm_per_px=p("mm_per_px", 0.0, "image scale in the bending plane, mm/px (0: from ArUco markers, aruco_mm)",
                        minimum=0.0, maximum=1e3) or None,
            aruco_mm=p("aruco_mm", 0.0, "printed side of the ArUco markers (4x4_50), mm (0: mm_per_px gives the scale)",
                       minimum=0.0, maximum=1e4) or None,
            base_px=p("base_px", "", "X,Y: the body's centre where it leaves the clamp, px") or None,
            toward_px=p("toward_px", "", "X,Y: a point on the unbent axis beyond the base, px") or None,
            clamp_marker=p("clamp_marker", -1, "id of the ArUco marker on the clamp that gives base and axis (-1: none)",
                           minimum=-1, maximum=MAX_MARKER_ID),
            clamp_gap_mm=p("clamp_gap_mm", 0.0, "from the clamp marker's top edge to the base, mm", minimum=0.0,
                           maximum=999.0),
            length_m=p("length", 0.0, "the sample's length, m (R_C; 0: the backbone length seen)", minimum=0.0,
                       maximum=9.0) or None,
            cap_mm=p("cap_mm", 0.0, "the straight tip beyond the bending part, mm", minimum=0.0, maximum=99.0),
            diameter_mm=p("diameter_mm", 0.0, "the body's width, mm (0: measured on the first frame)", minimum=0.0,
                          maximum=1e3) or None,
            color=p("color", "", "H,S,V:H,S,V: the body's colour range ('' : darker than the background)") or None,
            mirror=p("mirror", False, "positive bending is to the left of the unbent axis as seen"))
        if self.settings["clamp_marker"] < 0:
            self.settings["clamp_marker"] = None
        bending = math.radians(p("bending_direction_deg", 0.0, "where the positive across side points in softcath_base's "
                                 "x-y plane, deg from +x (implemented_5mm bends to -y: -90)", minimum=-360.0, maximum=360.0))
        self.bending = (math.cos(bending), math.sin(bending))
        self.rate_hz = p("rate_hz", 30.0, "frames read per second (a camera: at most its own rate)",
                         minimum=0.1, maximum=1000.0)
        self.loop = p("loop", False, "replay a video or folder from its start when it ends")
        self._reported_unmeasured = 0
        self.start()

    def make_core(self):
        from ..bench.frames import TrackedInput

        return TrackedInput(self.input, self.settings, loop=self.loop)

    def make_publishers(self) -> list:
        return [self.create_lifecycle_publisher(Vector3Stamped, topics.BENCH_BEND_ANGLE, 10),
                self.create_lifecycle_publisher(PoseStamped, topics.TIP_MEASURED, 100)]

    def configured(self) -> str:
        scene = self.core.scene
        return f"{self.input}, {scene.mm_per_px:.5f} mm/px, base {scene.base_px}"

    # -- frames -------------------------------------------------------------------------------------
    def tick(self) -> None:
        frame = self.core.next_frame()
        if frame is None:
            self.get_logger().info(f"{self.input}: no more frames")
            self._stop_timer()
            return
        stamp = self.get_clock().now()          # the time the frame was read
        m = self.core.measure(frame)
        if not m.ok:                            # never a guessed reading (counted by the core)
            return
        theta = math.radians(m.bend_angle_deg)
        a = Vector3Stamped()
        a.header.stamp, a.header.frame_id = stamp.to_msg(), topics.FRAME_ID
        a.vector.x = theta
        self.pubs[0].publish(a)
        t = PoseStamped()
        t.header = a.header
        bx, by = self.bending        # the bending plane in softcath_base: (bx, by, 0) and z
        across, along = m.tip_mm[0] * 1e-3, m.tip_mm[1] * 1e-3
        t.pose.position.x, t.pose.position.y, t.pose.position.z = across * bx, across * by, along
        half = math.sin(0.5 * theta)  # rotation by theta about z x (bx, by, 0), as core/kinematics
        t.pose.orientation.x, t.pose.orientation.y, t.pose.orientation.w = -by * half, bx * half, math.cos(0.5 * theta)
        self.pubs[1].publish(t)

    def diagnostics(self) -> None:
        c = self.core
        measured, unmeasured = (c.measured, c.unmeasured) if c is not None else (0, 0)
        new = unmeasured - self._reported_unmeasured     # since the last report
        self._reported_unmeasured = unmeasured
        if c is None or not (c.state == "active" or c.ended):
            level, message = self.level_and_message([])
        elif not c.ended:
            level, message = self.level_and_message([new and f"{new} frame(s) not measured: {c.last_problem}"])
            message = "measuring" if level == DiagnosticStatus.OK else message
        elif c.live:
            level, message = DiagnosticStatus.ERROR, "the camera stopped delivering frames"
        else:
            level, message = DiagnosticStatus.WARN, "the input has no more frames"
        publish_statuses(self, self.pub_diag, diagnostic_status(level, topics.TRACKER_NODE, message, [
            ("state", self.state_name), ("input", self.input), ("frames_measured", measured),
            ("frames_not_measured", unmeasured), ("last_reason", (c and c.last_problem) or self.last_reason)],
            hardware_id=self.input))


def main(args=None) -> int:
    return run_node(TrackerNode, args, startup_errors=(SoftcathError, ValueError))


if __name__ == "__main__":
    sys.exit(main())
