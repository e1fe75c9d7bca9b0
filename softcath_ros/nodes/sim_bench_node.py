"""sim_bench_node (node ``softcath_sim_bench``): the simulated bench, embedded default when no rig
is attached. All physics is in ``softcath_ros.bench.sim_rig``; this node only wires it to topics.

Subscribes: /softcath/pressure_cmd (Float64MultiArray, Pa), /softcath/bench/step (String, JSON
markers from bench_node: which bench and sample are mounted).
Publishes at ``rate_hz``: /softcath/pressure_measured (Float64MultiArray, Pa),
/softcath/bench/angle (Float64, rad), /softcath/bench/force (Float64, N), /diagnostics, and once
(transient local) /softcath/bench/rig: JSON saying this rig is simulated, with its parameters.
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict
from functools import partial

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64, Float64MultiArray, String

from .. import topics
from ..bench.sim_rig import RigParams, SimulatedRig, TipTracker, TrackerParams, truth_model
from ..core.design import load_design
from ..core.errors import SoftcathError
from ..core.models import make_model
from .parameters import declare
from .runtime import run_node

# Ranges of the rig's parameters (RigParams fields): a time constant of 0 or a negative noise
# would make the simulated readings meaningless.
RIG_RANGES = {"regulator_time_constant": (1e-4, 10.0), "pressure_shift": (0.0, 0.99),
              "friction_underread": (0.0, 0.99), "out_of_plane_tilt": (0.0, 1.5), "material_scale": (0.05, 20.0)}


class SimBenchNode(Node):
    executor_name = "single"   # rclpy's default executor: timers at rate_hz and two subscriptions

    def __init__(self, **node_options):
        super().__init__(topics.SIM_BENCH_NODE, **node_options)
        p = partial(declare, self)
        design_name = p("design", "implemented_5mm", "design file or shipped design name")
        model_name = p("model", "closed_form", "model rung that stands for the true actuator")
        rate_hz = p("rate_hz", 100.0, "publishing rate of the readings, Hz", minimum=1.0, maximum=10000.0)
        values = {}
        for name, default in asdict(RigParams()).items():
            lo, hi = RIG_RANGES.get(name, (0, None))
            values[name] = p(name, default, f"simulated rig: {name} (bench/sim_rig.py RigParams)",
                             minimum=lo, maximum=hi)
        params = RigParams(**values)
        design = load_design(design_name)
        model = truth_model(model_name, design, params)
        self.rig = SimulatedRig(model, params)
        self._start_tracker(p)
        self.rejected = 0
        self.command = np.zeros(design.n_channels)
        self.pub_p = self.create_publisher(Float64MultiArray, topics.PRESSURE_MEASURED, 10)
        self.pub_a = self.create_publisher(Float64, topics.BENCH_ANGLE, 10)
        self.pub_f = self.create_publisher(Float64, topics.BENCH_FORCE, 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_rig = self.create_publisher(String, topics.BENCH_RIG, latched)
        self.pub_rig.publish(String(data=json.dumps({
            "simulated": True, "node": self.get_name(), "design": design.name,
            "design_hash": design.content_hash(), "model": model.name, "rig": asdict(params)})))
        self.create_subscription(Float64MultiArray, topics.PRESSURE_CMD, self.on_command, 10)
        self.create_subscription(String, topics.BENCH_STEP, self.on_step, 100)
        self.dt = 1.0 / rate_hz
        self.t_last = time.monotonic()
        self.create_timer(self.dt, self.tick)
        self.create_timer(1.0, self.diagnostics)
        self.get_logger().info(f"simulated bench: design {design.name}, rung {model.name}, "
                               f"pressure shift {params.pressure_shift:g}, {1 / self.dt:g} Hz")

    def _start_tracker(self, p) -> None:
        """The tip tracker: /softcath/tip_measured (noisy, late, lossy) and the truth on /softcath/bench/tip_true."""
        from geometry_msgs.msg import PoseStamped

        values = {name: p(f"tracker_{name}", default, f"tip tracker: {name} (bench/sim_rig.py TrackerParams)",
                          minimum=0.0, maximum=0.99 if name == "drop_fraction" else None)
                  for name, default in asdict(TrackerParams()).items()}
        self.tracker = TipTracker(TrackerParams(**values))
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
        position, quat = self.rig.true_tip()
        self.pub_tip_true.publish(self._pose(now, position, quat))
        self.tracker.capture(now * 1e-9, position)
        for stamp, pos in self.tracker.due(now * 1e-9):
            self.pub_tip.publish(self._pose(round(stamp * 1e9), pos, quat))

    def on_command(self, msg):
        p = np.asarray(msg.data, dtype=float)
        if p.shape != self.command.shape or not np.all(np.isfinite(p)):
            self.rejected += 1
            self.get_logger().warning(f"rejected pressure command {list(msg.data)} (need "
                                   f"{self.command.size} finite values)", throttle_duration_sec=2.0)
            return
        self.command = p  # the regulator clamps to [0, max_pressure]

    def on_step(self, msg):
        try:
            ev = json.loads(msg.data)
        except ValueError:
            return
        if ev.get("event") == "step_start":
            try:
                self.rig.mount(ev["bench"], float(ev["sample_length_m"]))
            except (KeyError, ValueError) as exc:
                self.get_logger().warning(f"cannot mount sample from marker: {exc}")

    def tick(self):
        # The regulator advances by the time that really passed: on a loaded machine the
        # timer fires late, and a fixed dt would slow the simulated rig down.
        now = time.monotonic()
        dt, self.t_last = min(now - self.t_last, 0.5), now
        self.rig.advance(dt, self.command)
        r = self.rig.read()
        self.pub_p.publish(Float64MultiArray(data=[float(x) for x in r.pressures]))
        self.pub_a.publish(Float64(data=r.angle))
        self.pub_f.publish(Float64(data=r.force))

    def diagnostics(self):
        st = DiagnosticStatus(level=DiagnosticStatus.OK if self.rejected == 0 else DiagnosticStatus.WARN,
                              name=topics.SIM_BENCH_NODE, hardware_id="simulated",
                              message="simulated rig running" + (f", {self.rejected} commands rejected"
                                                                 if self.rejected else ""),
                              values=[KeyValue(key="rejected_commands", value=str(self.rejected)),
                                      KeyValue(key="bench", value=self.rig.bench),
                                      KeyValue(key="sample_length_m", value=f"{self.rig.length:g}")])
        msg = DiagnosticArray(status=[st])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)

def main(args=None) -> int:
    return run_node(SimBenchNode, args, startup_errors=(SoftcathError, ValueError))


if __name__ == "__main__":
    sys.exit(main())
