"""model_node (node ``softcath_model``): channel pressures -> predicted tip pose and backbone.

Subscribes ``/softcath/pressure_cmd`` (std_msgs/Float64MultiArray, Pa per channel) and,
for every accepted command, publishes ``/softcath/tip_pose`` (PoseStamped) and
``/softcath/backbone`` (PoseArray, ``backbone_points`` poses from base to tip), both in
frame ``softcath_base`` and stamped with the time the command was received (clock
read on entry to the callback). Bad commands are rejected or clamped per
``out_of_range`` (core.pressure_command), counted, warned about (throttled) and
reported on /diagnostics; a model that does not converge publishes nothing.

Every command is answered while the rung keeps up. Only a stale one is superseded (counted on
/diagnostics): one that has waited longer than SUPERSEDE_AGE (10 ms, core.command_shaping) while
a newer one waits; the newest is always answered. So a scheduling pause of a few ms costs no
answers, and a rung slower than the stream answers the newest, never a growing backlog (a
steering loop wants the pose for the pressures it commands now). A rung that answers a command
in under ``INLINE_ANSWER_S`` (closed form, surrogate: ~10 us, timed at start-up) answers in the
subscription callback, where the latency is lowest; after each answer the callback takes every
command that arrived meanwhile from the subscription and answers those not stale, then returns
(so timers run between). A rung that declares itself offline only (fe3d: a minute or more per
command; ``RungInfo.live``) is refused at start, in one line. Every slower rung (rod, section)
answers on its own solve thread: the callback only queues the command (so the executor, and
with it /diagnostics, never waits for a solve). An unchanged command costs no model call: the
last answer is kept and sent again, newly stamped.

At ``display_rate`` (default 30 Hz, independent of the pose stream) it also publishes the live
3D view (nodes/live_view.py): the body as a Marker, the backbone as a Path, R_C; the tip on
TF where tf2_ros exists.

Latency: by default the two outputs are preallocated CDR buffers (nodes/cdr.py) of
which only the stamp and the doubles are rewritten per command, and the EventsExecutor
runs the callbacks; benchmarks/node_latency.py measures these and the alternatives.
"""
from __future__ import annotations

import math
import sys
import threading
import time
from collections import deque
from functools import partial
from types import SimpleNamespace

import numpy as np
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from .. import topics
from ..core.answer_load import AnswerLoad
from ..core.command_shaping import SUPERSEDE_AGE, is_superseded
from ..core.design import load_design
from ..core.errors import SoftcathError
from ..core.model_selection import require_live_rung
from ..core.models import RUNGS, rung_info, run_options
from ..core.kinematics import backbone_poses
from ..core.prediction import arc_and_cap, body_reach, state_backbone
from ..core.calibration_file import build_model, load_calibration
from ..core.pressure_command import POLICIES, check_pressure_command
from .cdr import HOST_IS_LITTLE_ENDIAN, PoseArrayBuffer, PoseStampedBuffer
from .diagnostics import DiagnosticsReporter, InputCounters, ThrottledLog
from .parameters import declare, refuse_unknown_parameters
from .qos import RELIABILITIES, stream_qos
from .executors import EXECUTORS, take_waiting
from .runtime import interruptible_start, run_node

FRAME_ID = topics.FRAME_ID
WARN_THROTTLE_S = 1.0
# Rungs faster than this per command answer in the callback; slower ones on the solve thread.
INLINE_ANSWER_S = 0.5e-3
# serialized: preallocated CDR bytes; reuse: preallocated message objects filled in place;
# fresh: new message objects per command (the plain rclpy way).
PREPARATIONS = ("serialized", "reuse", "fresh")


class ModelNode(Node):
    def __init__(self, **node_options):
        """``node_options`` go to rclpy's Node (e.g. ``context`` for in-process tests)."""
        super().__init__(topics.MODEL_NODE, **node_options)
        self._log = ThrottledLog(self.get_logger(), WARN_THROTTLE_S)
        prm = self._declare_parameters()
        self._load_model(prm.design, prm.model, prm.scene, prm.calibration, prm.n_points)
        self.counters = InputCounters(extra={"design": self.design.name, "model": self.model.name,
                                             "max_pressure_pa": f"{self.max_pressure:g}",
                                             "out_of_range": self.out_of_range})
        self._open_streams(stream_qos(int(prm.depth), prm.reliability))
        self.view = None
        if prm.display_rate > 0:
            from .live_view import LiveView

            self.view = LiveView(self, self.design, self.n_points, prm.display_rate, prm.body_sides, prm.tip_frame,
                                 stream_qos(10, prm.reliability))
        # Commands arriving faster than the rung answers show on /diagnostics, not as silent lag.
        self.answer_load = AnswerLoad(time.monotonic())
        self._diagnostics = DiagnosticsReporter(self, self.counters, "softcath_model: pressure commands",
                                                self.design.name, prm.diag_period, answer_load=self.answer_load)
        self.get_logger().info(
            f"design {self.design.name} ({self.n_channels} channel(s), max_pressure {self.max_pressure:g} Pa), "
            f"model {self.model.name}, {self.n_points} backbone points, out_of_range={self.out_of_range}, "
            f"executor={self.executor_name}, qos {prm.reliability} depth {prm.depth}, messages {self.preparation}, "
            "commands "
            + ("answered in the callback" if self._solver is None else "answered on the solve thread")
            + f" (a command waiting over {self.supersede_age * 1e3:g} ms behind a newer one is superseded)")

    def _declare_parameters(self) -> SimpleNamespace:
        """The node's parameters: those it keeps as attributes set, the others returned; unknown ones refused."""
        p = partial(declare, self)
        design_name = p("design", "implemented_5mm", "design YAML file, or the name of a shipped design")
        model_name = p("model", "surrogate", "model rung (core.models), e.g. surrogate, closed_form, or auto (needs scene)")
        scene_name = p("scene", "", "scene YAML file or shipped scene name: with model auto, picks the rung")
        calibration_file = p("calibration", "", "calibration file from `softcath calibrate`, applied to the rung "
                                                "('' = none)")
        n_points = p("backbone_points", 20, "number of poses in /softcath/backbone, base to tip",
                     minimum=2, maximum=10000)
        # 1000 = 1 s at 1 kHz: a reliable keep-last writer overwrites samples a late reader has
        # not acknowledged yet, so a shallower history loses poses whenever the node lags.
        depth = p("qos_depth", 1000, "keep-last depth of the command subscription and pose publishers",
                  minimum=1, maximum=100000)
        reliability = p("reliability", "reliable", f"QoS reliability: {' | '.join(RELIABILITIES)}",
                        choices=RELIABILITIES)
        self.out_of_range = p("out_of_range", "reject",
                              f"finite pressures outside [0, max_pressure]: {' | '.join(POLICIES)}", choices=POLICIES)
        self.executor_name = p("executor", "events", f"executor: {' | '.join(EXECUTORS)}", choices=EXECUTORS)
        self.preparation = p("message_preparation", "serialized",
                             f"how outputs are built: {' | '.join(PREPARATIONS)}", choices=PREPARATIONS)
        self.realtime_priority = p("realtime_priority", 0,
                                   "SCHED_FIFO priority 1-99 for all node threads, 0 = normal scheduling",
                                   minimum=0, maximum=99)
        diag_period = p("diagnostics_period", 1.0, "seconds between /diagnostics reports", minimum=1e-3,
                        maximum=3600.0)
        display_rate = p("display_rate", 30.0, "Hz of the live 3D view (body marker, backbone path, R_C, TF); "
                         "0 = off", minimum=0.0, maximum=1000.0)
        body_sides = p("body_sides", 12, "vertices around the body tube of the 3D view", minimum=3, maximum=64)
        tip_frame = p("tip_frame", "softcath_tip", "TF frame of the tip (broadcast where tf2_ros exists)")
        refuse_unknown_parameters(self, later=("max_pressure",))   # before a rung is built on a typo's default
        return SimpleNamespace(design=design_name, model=model_name, scene=scene_name, calibration=calibration_file,
                               n_points=n_points, depth=depth, reliability=reliability, diag_period=diag_period,
                               display_rate=display_rate, body_sides=body_sides, tip_frame=tip_frame)

    def _load_model(self, design_name: str, model_name: str, scene_name: str, calibration_file: str,
                    n_points: int) -> None:
        """The design, the rung (``auto``: chosen for the scene) and the design's pressure limit."""
        self.design = load_design(design_name)
        require_live_rung(model_name, self.design.name)   # fe3d: refused at once, not after a first solve
        self.calibration = load_calibration(calibration_file) if calibration_file else None
        if model_name == "auto":
            from ..core.scene import load_scene

            scene = load_scene(scene_name) if scene_name else None
            self.model = build_model("auto", self.design, self.calibration, scene=scene)
            self.design = self.model.design       # the scene's device included
            self.get_logger().info(self.model.selection.reason)
        else:
            self.model = self._make_model(model_name)
        self.n_channels = self.design.n_channels
        self.length = self.design.length
        self.arc_length, self.cap = arc_and_cap(self.model, self.length)   # the channelled part, the straight cap
        self.body_radius = self.design.outer_radius
        self.n_points = int(n_points)
        # The safety limit comes from the design only: an override is ignored (and said so).
        self.max_pressure = self.design.max_pressure
        declare(self, "max_pressure", self.max_pressure, "Pa, from the design file", ignore_override=True)
        if "max_pressure" in self._parameter_overrides:
            self.get_logger().warning(f"max_pressure override ignored: the limit is the design's "
                                   f"{self.max_pressure:g} Pa")
        # Rungs with a one-command fast path (closed form) skip the BendState allocation.
        self._fast = self.model.curvature_single if self.model.info.linear_gain else None

    def _open_streams(self, qos) -> None:
        """The clock, the pose publishers and their messages, and the command subscription (answered in
        the callback, or on the solve thread for a slow rung)."""
        self._clock = self.get_clock()
        # Without simulated time the ROS clock is the system clock (CLOCK_REALTIME): read it
        # directly (0.1 us instead of ~5 us for Clock.now()); decided at start-up.
        self._now_ns = (lambda: self._clock.now().nanoseconds) if self._clock.ros_time_is_active else time.time_ns
        if self.preparation == "serialized" and not HOST_IS_LITTLE_ENDIAN:
            self.get_logger().warning("big-endian host: message_preparation 'serialized' -> 'reuse'")
            self.preparation = "reuse"
        self._tip_buf = PoseStampedBuffer(FRAME_ID)
        self._bb_buf = PoseArrayBuffer(FRAME_ID, self.n_points)
        self._tip_pub = self.create_publisher(PoseStamped, topics.TIP_POSE, qos)
        self._backbone_pub = self.create_publisher(PoseArray, topics.BACKBONE, qos)
        self._tip, self._backbone = self._new_messages()
        # Rungs slower than INLINE_ANSWER_S solve on their own thread; either way the newest command
        # is answered (module docstring).
        self._pending = deque()                   # (msg, stamp_ns, arrived) waiting for the solve thread
        self.supersede_age = SUPERSEDE_AGE        # s: a command waiting longer, with a newer one behind it, is stale
        self._clock_s = time.monotonic            # ages of waiting commands (a test may drive it)
        self._answered_key = None                 # the last answered pressures (bytes) and their pose
        self._answered_pose = None
        self._wake = threading.Condition()
        self._stopping = False
        self._solver = None
        if not self._answers_inline():
            self._solver = threading.Thread(target=self._solve_newest, name="model_node_solve", daemon=True)
            self._solver.start()
        self._command_sub = self.create_subscription(
            Float64MultiArray, topics.PRESSURE_CMD, self._on_command_inline if self._solver is None else self._hand_over,
            qos)

    def _make_model(self, model_name: str):
        """The rung, saying so when start-up may wait for it: a rung that builds something when neither
        shipped nor cached (``RungInfo.builds``: the surrogate's table, the rod's law) says what and how
        long, and shows its progress bars (stderr)."""
        builds = rung_info(model_name).builds if model_name in RUNGS else ""
        if builds:
            self.get_logger().info(f"model {model_name}: loading; if neither shipped nor cached it builds {builds} "
                                   "now, with progress below (SIGINT stops it)")
        t0 = time.perf_counter()
        with interruptible_start():
            model = build_model(model_name, self.design, self.calibration,
                                **(run_options(model_name, progress=True) if builds else {}))
        took = time.perf_counter() - t0
        if model.built_now:
            self.get_logger().warning(
                f"model {model_name}: its table for design {self.design.name} was not in the cache and was built "
                f"at start-up in {took:.1f} s (now cached at {model.path}); max R_C error against its source: "
                + ", ".join(f"{part} {b.get('rc_rel_max', float('nan')):.2%}" for part, b in model.error_bound.items()))
        elif took > 1.0 or model_name == "surrogate":
            self.get_logger().info(f"model {model_name}: ready in {took:.1f} s"
                                   + (f" ({model.origin} table {model.table_path})" if model_name == "surrogate" else ""))
        return model

    def _new_messages(self):
        tip = PoseStamped()
        tip.header.frame_id = FRAME_ID
        backbone = PoseArray(poses=[Pose() for _ in range(self.n_points)])
        backbone.header.frame_id = FRAME_ID
        # Handles to the sub-messages, so filling is plain attribute stores.
        self._tip_p, self._tip_q = tip.pose.position, tip.pose.orientation
        self._bb = [(pose.position, pose.orientation) for pose in backbone.poses]
        return tip, backbone

    # -- commands faster than the rung ---------------------------------------------------------
    def _answers_inline(self) -> bool:
        """Whether the rung answers fast enough for the callback: the fast path does; others are
        timed on half the limit on channel 0 (best of three; one when the first is already slow)."""
        if self._fast is not None:
            return True
        probe = np.zeros(self.n_channels)
        probe[0] = 0.5 * self.max_pressure
        best = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            try:
                self.model.evaluate(probe)
            except Exception:  # noqa: BLE001 - a rung refusing the probe is timed as slow
                return False
            best = min(best, time.perf_counter() - t0)
            if best > INLINE_ANSWER_S:
                return False
        return True

    def _on_command_inline(self, msg: Float64MultiArray) -> None:
        """Subscription callback for a fast rung: answer ``msg``, then the commands that arrived
        meanwhile (a stale one superseded), and return."""
        self._on_command(msg)
        waiting = take_waiting(self._command_sub)
        if waiting:
            self._answer_waiting(waiting)

    def _answer_waiting(self, waiting) -> None:
        """Answer ``waiting`` ((msg, arrival s), oldest first) in order, skipping the stale ones."""
        last = len(waiting) - 1
        for i, (msg, arrived) in enumerate(waiting):
            if is_superseded(arrived, self._clock_s(), i < last, self.supersede_age):
                self._supersede()
            else:
                self._on_command(msg)

    def _supersede(self) -> None:
        self.counters.superseded += 1
        self.counters.last_reason = (f"command superseded: it waited over {self.supersede_age * 1e3:g} ms "
                                     "behind a newer one")

    def _hand_over(self, msg: Float64MultiArray) -> None:
        """Subscription callback for a solve thread: queue the command for it."""
        stamp_ns = self._now_ns()
        with self._wake:
            self._pending.append((msg, stamp_ns, self._clock_s()))
            self._wake.notify()

    def _next_pending(self):
        """The oldest waiting command that is not stale (the stale ones superseded), or None when
        stopping. Holds ``self._wake``."""
        while True:
            while not self._pending and not self._stopping:
                self._wake.wait()
            if self._stopping:
                return None
            msg, stamp_ns, arrived = self._pending.popleft()
            if is_superseded(arrived, self._clock_s(), bool(self._pending), self.supersede_age):
                self._supersede()
                continue
            return msg, stamp_ns

    def _solve_newest(self) -> None:
        while True:
            with self._wake:
                got = self._next_pending()
            if got is None:
                return
            msg, stamp_ns = got
            started = time.perf_counter()
            try:
                self._answer(msg, stamp_ns)
            except Exception as exc:  # noqa: BLE001 - the thread must outlive one bad solve
                if self._stopping:    # the node was destroyed during a long solve: nothing to report to
                    return
                self._model_failed(f"model raised {type(exc).__name__}: {exc}")
            self.answer_load.record(time.perf_counter() - started)

    def destroy_node(self):
        if self._solver is not None:
            with self._wake:
                self._stopping = True
                self._wake.notify()
            self._solver.join(timeout=5.0)
        return super().destroy_node()

    # -- the hot path ----------------------------------------------------------------------
    def _on_command(self, msg: Float64MultiArray) -> None:
        stamp_ns = self._now_ns()   # time the command was received
        started = time.perf_counter()
        self._answer(msg, stamp_ns)
        self.answer_load.record(time.perf_counter() - started)

    def _answer(self, msg: Float64MultiArray, stamp_ns: int) -> None:
        check = check_pressure_command(msg.data, self.n_channels, self.max_pressure, self.out_of_range)
        c = self.counters
        if check.status != "ok":
            c.last_reason = check.reason
            if check.status == "rejected":
                c.rejected += 1
                self._log.warning("rejected", f"command rejected: {check.reason}")
                return
            c.clamped += 1
            self._log.warning("clamped", f"command clamped into [0, {self.max_pressure:g}] Pa: {check.reason}")
        key = check.pressures.tobytes()
        if key == self._answered_key:    # an unchanged command: the same pose, no model call
            positions, quats, angle = self._answered_pose
        else:
            if self._fast is not None:
                curvature, stretch = self._fast(check.pressures)
                solved = None
            else:
                try:
                    state = self.model.evaluate(check.pressures)
                except SoftcathError as exc:  # a rung refusing this command (e.g. outside its range)
                    return self._model_failed(f"model refused {check.pressures.tolist()} Pa: {exc}")
                if not bool(state.converged):
                    return self._model_failed(f"model did not converge: {state.message or 'no reason given'}")
                curvature, stretch, solved = state.curvature, float(state.axial_stretch), state.backbone
            # a free body bent through itself or its shaft is no prediction (core/body_contact.py)
            reached = body_reach(curvature, self.arc_length * stretch, self.cap, self.body_radius, solved)
            if reached is not None:
                return self._model_failed(f"no pose for {check.pressures.tolist()} Pa: {reached.describe()}")
            if solved is None and self._fast is not None:
                positions, quats = backbone_poses(curvature, self.arc_length * stretch, self.n_points, self.cap)
            else:
                positions, quats = state_backbone(state, self.arc_length, self.cap, self.n_points)
            if not (np.isfinite(positions).all() and np.isfinite(quats).all()):
                return self._model_failed(f"model gave non-finite pose for {check.pressures.tolist()} Pa")
            # the rung's own bending angle (its solved tip's, else |k| x the deformed arc): R_C past 180 deg
            angle = float(state.tip.angle) if solved is not None and state.tip is not None else \
                math.hypot(curvature[0], curvature[1]) * self.arc_length * stretch
            self._answered_key, self._answered_pose = key, (positions, quats, angle)
        c.accepted += 1
        if self.view is not None:   # the display timer picks it up (a reference, no copy)
            self.view.latest = (stamp_ns, positions, quats, check.pressures, angle)
        if self.preparation == "serialized":
            self._publish_serialized(stamp_ns, positions, quats)
        else:
            self._publish(stamp_ns, positions.tolist(), quats.tolist())

    def _model_failed(self, reason: str) -> None:
        self.counters.model_failed += 1
        self.counters.last_reason = reason
        self._log.warning("model_failed", reason)

    def _publish_serialized(self, stamp_ns: int, positions: np.ndarray, quats: np.ndarray) -> None:
        tip, backbone = self._tip_buf, self._bb_buf
        backbone.poses[:, :3] = positions
        backbone.poses[:, 3:] = quats
        tip.poses[0] = backbone.poses[-1]   # the backbone's last pose is the tip
        tip.set_stamp(stamp_ns)
        backbone.set_stamp(stamp_ns)
        self._tip_pub.publish(tip.to_bytes())
        self._backbone_pub.publish(backbone.to_bytes())

    def _publish(self, stamp_ns: int, positions: list, quats: list) -> None:
        if self.preparation == "fresh":
            self._tip, self._backbone = self._new_messages()
        tip, backbone = self._tip, self._backbone
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        for stamp in (tip.header.stamp, backbone.header.stamp):
            stamp.sec, stamp.nanosec = sec, nanosec
        for (pos, ori), (x, y, z), (qx, qy, qz, qw) in zip(self._bb, positions, quats):
            pos.x, pos.y, pos.z = x, y, z
            ori.x, ori.y, ori.z, ori.w = qx, qy, qz, qw
        # The backbone's last pose is the tip (same arc length), so the two topics agree exactly.
        (x, y, z), (qx, qy, qz, qw) = positions[-1], quats[-1]
        p, q = self._tip_p, self._tip_q
        p.x, p.y, p.z = x, y, z
        q.x, q.y, q.z, q.w = qx, qy, qz, qw
        # publish() serialises synchronously, so refilling the same messages next time is safe.
        self._tip_pub.publish(tip)
        self._backbone_pub.publish(backbone)


def main(args=None) -> int:
    return run_node(ModelNode, args, startup_errors=(SoftcathError, ValueError, ParameterException))


if __name__ == "__main__":
    sys.exit(main())
