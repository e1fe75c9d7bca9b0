"""sim_bench_node (node ``softcath_sim_bench``): the simulated bench, embedded default when no rig
is attached. All physics is in ``softcath_ros.bench.sim_rig``; this node only wires it to topics,
as the rig contract (docs/rig.md) says a rig must.

Subscribes: /softcath/pressure_cmd (Float64MultiArray, Pa), /softcath/bench/step (String, JSON
markers from bench_node: which bench and sample are mounted).
Publishes at ``rate_hz``, every reading stamped with the time it was taken:
/softcath/pressure_measured/ch<i> (sensor_msgs/FluidPressure, gauge Pa, variance = gauge noise^2),
/softcath/bench/bend_angle (geometry_msgs/Vector3Stamped, vector.x in rad), /softcath/bench/wrench
(geometry_msgs/WrenchStamped, force.z in N, frame softcath_scale); with ``legacy_topics`` (off by
default; for one release) also the deprecated unstamped /softcath/pressure_measured, /softcath/bench/angle and
/softcath/bench/force; /diagnostics; and once (transient local) /softcath/bench/rig: JSON saying
this rig is simulated, with its parameters.
"""
from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict
from functools import partial

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Vector3Stamped, WrenchStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64, Float64MultiArray, String

from .. import topics
from ..bench.sim_rig import FRESH_SEED, RigParams, SimulatedRig, TipTracker, TrackerParams, truth_model
from ..core.command_shaping import CommandWatchdog
from ..core.design import load_design
from ..core.model_selection import require_live_rung
from ..core.errors import SoftcathError
from .diagnostics import ThrottledLog, diagnostic_status, publish_statuses
from .parameters import declare, refuse_unknown_parameters
from .executors import take_waiting
from .runtime import run_node

# Ranges of the rig's parameters (RigParams fields): a time constant of 0 or a negative noise
# would make the simulated readings meaningless.
# Upper bounds keep every reading finite (a finite but huge noise would overflow to inf).
RIG_RANGES = {"regulator_time_constant": (1e-4, 10.0), "pressure_shift": (0.0, 0.99),
              "friction_underread": (0.0, 0.99), "out_of_plane_tilt": (0.0, 1.5),
              "gauge_error": (0.0, 1e6), "gauge_noise": (0.0, 1e6), "hysteresis_pressure": (0.0, 1e6),   # Pa
              "angle_noise": (0.0, 10.0),                                                             # rad
              "force_noise": (0.0, 10.0), "scale_offset": (0.0, 10.0),                                # N
              "seed": (FRESH_SEED, 2**32 - 1), "material_scale": (0.05, 20.0)}


class SimBenchNode(Node):
    # timers at rate_hz and two subscriptions: the events executor takes half the CPU of rclpy's
    # default one (13 % of a core at 100 Hz against 26 %), and a node test runs several of these
    executor_name = "events"

    def __init__(self, **node_options):
        super().__init__(topics.SIM_BENCH_NODE, **node_options)
        self._log = ThrottledLog(self.get_logger(), 2.0)
        p = partial(declare, self)
        design_name = p("design", "implemented_5mm", "design file or shipped design name")
        model_name = p("model", "surrogate", "model rung that stands for the true actuator (default: the section rung's table)")
        rate_hz = p("rate_hz", 100.0, "publishing rate of the readings, Hz", minimum=1.0, maximum=10000.0)
        self.command_timeout = p("command_timeout", 0.5, "no pressure command for this long (s): vent "
                                 "(the rig contract's watchdog)", minimum=0.01, maximum=60.0)
        legacy = p("legacy_topics", False, "also publish the deprecated unstamped reading topics (one release)")
        values = {}
        # every run its own noise unless a seed is given (-1: drawn, and published with the parameters)
        for name, default in {**asdict(RigParams()), "seed": FRESH_SEED}.items():
            lo, hi = RIG_RANGES.get(name, (0, None))
            values[name] = p(name, default, f"simulated rig: {name} (bench/sim_rig.py RigParams)",
                             minimum=lo, maximum=hi)
        params = RigParams(**values)
        refuse_unknown_parameters(self, later=tuple(f"tracker_{n}" for n in asdict(TrackerParams())))
        design = load_design(design_name)
        require_live_rung(model_name, design.name)
        model = truth_model(model_name, design, params)
        self.rig = SimulatedRig(model, params)
        self._start_tracker(p)
        self.rejected = 0
        self.unanswered = 0   # readings not published: the truth rung refused the pressures (outside its table)
        self.command = np.zeros(design.n_channels)
        self.watchdog = CommandWatchdog(self.command_timeout)   # fed from each command's arrival
        self.silent = False
        self.stale = 0        # commands dropped: older than command_timeout when handled
        self.pub_pc = [self.create_publisher(FluidPressure, topics.pressure_measured_topic(c), 10)
                       for c in range(design.n_channels)]
        self.pub_angle = self.create_publisher(Vector3Stamped, topics.BENCH_BEND_ANGLE, 10)
        self.pub_wrench = self.create_publisher(WrenchStamped, topics.BENCH_WRENCH, 10)
        self.pressure_variance = float(params.gauge_noise) ** 2  # Pa^2: the gauge's white noise
        self.legacy = None
        if legacy:
            self.legacy = (self.create_publisher(Float64MultiArray, topics.PRESSURE_MEASURED, 10),
                           self.create_publisher(Float64, topics.BENCH_ANGLE, 10),
                           self.create_publisher(Float64, topics.BENCH_FORCE, 10))
        self.pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_rig = self.create_publisher(String, topics.BENCH_RIG, latched)
        self.pub_rig.publish(String(data=json.dumps({
            "simulated": True, "node": self.get_name(), "design": design.name,
            "design_hash": design.content_hash(), "model": model.name, "rate_hz": rate_hz,
            "rig": asdict(self.rig.params)})))
        self._command_sub = self.create_subscription(Float64MultiArray, topics.PRESSURE_CMD, self.on_command, 10)
        self.create_subscription(String, topics.BENCH_STEP, self.on_step, 100)
        self.dt = 1.0 / rate_hz
        self.t_last = time.monotonic()
        self.create_timer(self.dt, self.tick)
        self.create_timer(1.0, self.diagnostics)
        self.get_logger().info(f"simulated bench: design {design.name}, rung {model.name}, "
                               f"pressure shift {params.pressure_shift:g}, seed {self.rig.params.seed}, {1 / self.dt:g} Hz")
        if self.legacy is not None:
            self.get_logger().warning(
                f"also publishing the deprecated unstamped {', '.join(topics.DEPRECATED_RIG_TOPICS)} "
                "(removed in the next release; legacy_topics is off by default): read the stamped "
                "topics of docs/rig.md instead")

    def _start_tracker(self, p) -> None:
        """The tip tracker: /softcath/tip_measured (noisy, late, lossy) and the truth on /softcath/bench/tip_true."""
        from geometry_msgs.msg import PoseStamped

        values = {name: p(f"tracker_{name}", default, f"tip tracker: {name} (bench/sim_rig.py TrackerParams)",
                          minimum=0.0, maximum=0.99 if name == "drop_fraction" else None)
                  for name, default in asdict(TrackerParams()).items()}
        self.tracker = TipTracker(TrackerParams(**values))
        self._tip_quat = (0.0, 0.0, 0.0, 1.0)   # the last true tip orientation (tracked samples carry it)
        if values["rate_hz"] <= 0:   # no tracker
            return
        self._pose_type = PoseStamped
        self.pub_tip = self.create_publisher(PoseStamped, topics.TIP_MEASURED, 100)
        self.pub_tip_true = self.create_publisher(PoseStamped, topics.TIP_TRUE, 100)
        self.create_timer(1.0 / values["rate_hz"], self.tick_tracker)

    def _pose(self, stamp_ns: int, position, quat):
        msg = self._pose_type()
        msg.header.frame_id = topics.FRAME_ID
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in position)
        q = msg.pose.orientation
        q.x, q.y, q.z, q.w = (float(v) for v in quat)
        return msg

    def tick_tracker(self):
        now = self.get_clock().now().nanoseconds
        true = self.rig.true_tip()
        if true is not None:   # (None: the truth has no answer there, so there is nothing to track)
            position, self._tip_quat = true
            self.pub_tip_true.publish(self._pose(now, position, self._tip_quat))
            self.tracker.capture(now * 1e-9, position)
        for stamp, pos in self.tracker.due(now * 1e-9):   # (the tracker reads positions: the last true orientation)
            self.pub_tip.publish(self._pose(round(stamp * 1e9), pos, self._tip_quat))

    def on_command(self, msg):
        """The regulator's input: the newest command waiting, unless stale (command_shaping's
        freshness rule: the watchdog counts from arrival, so a backlog never holds pressure)."""
        arrived = time.monotonic()
        waiting = take_waiting(self._command_sub)
        if waiting:
            msg, arrived = waiting[-1]
        if not self.watchdog.fresh(arrived, time.monotonic()):
            self.stale += 1
            return
        p = np.asarray(msg.data, dtype=float)
        if p.shape != self.command.shape or not np.all(np.isfinite(p)):
            self.rejected += 1
            self._log.warning("rejected", f"rejected pressure command {list(msg.data)} (need "
                                          f"{self.command.size} finite values)")
            return
        self.command = p  # the regulator clamps to [0, max_pressure]
        self.watchdog.feed(arrived)
        self.silent = False

    def on_step(self, msg):
        try:
            ev = json.loads(msg.data)
        except ValueError:
            return
        if isinstance(ev, dict) and ev.get("event") == "step_start":
            try:
                self.rig.mount(ev["bench"], float(ev["sample_length_m"]))
            except (KeyError, ValueError, TypeError) as exc:
                self.get_logger().warning(f"cannot mount sample from marker: {exc}")

    def tick(self):
        # The regulator advances by the time that really passed: on a loaded machine the
        # timer fires late, and a fixed dt would slow the simulated rig down.
        now = time.monotonic()
        dt, self.t_last = min(now - self.t_last, 0.5), now
        if self.watchdog.expired(now) and not self.silent:
            self.silent = True  # the commander went silent: vent (said once per silence)
            self.command = np.zeros_like(self.command)
            if self.watchdog.last_feed is not None:
                self.get_logger().warning(f"no pressure command for {self.command_timeout:g} s: venting")
        self.rig.advance(dt, self.command)
        r = self.rig.read()
        stamp = self.get_clock().now().to_msg()  # when the reading was taken
        for c, pub in enumerate(self.pub_pc):
            m = FluidPressure(fluid_pressure=float(r.pressures[c]), variance=self.pressure_variance)
            m.header.stamp, m.header.frame_id = stamp, topics.FRAME_ID
            pub.publish(m)
        if not (math.isfinite(r.angle) and math.isfinite(r.force)):
            self.unanswered += 1     # never a made-up reading
            if self.legacy is not None:
                self.legacy[0].publish(Float64MultiArray(data=[float(x) for x in r.pressures]))
            return
        a = Vector3Stamped()
        a.header.stamp, a.header.frame_id = stamp, topics.FRAME_ID
        a.vector.x = float(r.angle)
        self.pub_angle.publish(a)
        w = WrenchStamped()
        w.header.stamp, w.header.frame_id = stamp, topics.SCALE_FRAME_ID
        w.wrench.force.z = float(r.force)
        self.pub_wrench.publish(w)
        if self.legacy is not None:
            pub_p, pub_a, pub_f = self.legacy
            pub_p.publish(Float64MultiArray(data=[float(x) for x in r.pressures]))
            pub_a.publish(Float64(data=r.angle))
            pub_f.publish(Float64(data=r.force))

    def diagnostics(self):
        level = DiagnosticStatus.OK if self.rejected == self.unanswered == 0 else DiagnosticStatus.WARN
        message = ("simulated rig running" + (f", {self.rejected} commands rejected" if self.rejected else "")
                   + (f", {self.unanswered} readings withheld (the truth rung refused the pressures)"
                      if self.unanswered else ""))
        publish_statuses(self, self.pub_diag, diagnostic_status(level, topics.SIM_BENCH_NODE, message, [
            ("rejected_commands", self.rejected), ("stale_commands", self.stale), ("withheld_readings", self.unanswered), ("bench", self.rig.bench),
            ("sample_length_m", f"{self.rig.length:g}")], hardware_id="simulated"))

def main(args=None) -> int:
    return run_node(SimBenchNode, args, startup_errors=(SoftcathError, ValueError))


if __name__ == "__main__":
    sys.exit(main())
