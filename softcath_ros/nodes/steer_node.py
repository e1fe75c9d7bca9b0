"""steer_node (softcath_steer): closed-loop steering on a measured tip.

Subscribes /softcath/tip_target (geometry_msgs/PointStamped, m, softcath_base) and
/softcath/tip_measured (geometry_msgs/PoseStamped, from a camera or an electromagnetic
tracker, stamped when the sample was taken); publishes /softcath/pressure_cmd
(std_msgs/Float64MultiArray, Pa) at ``publish_rate`` and /diagnostics. All of the control,
the safety logic and its fallback are the core SteeringController (core/steering.py); this
node parses, checks frames and sizes, keeps the clock and reports.

A node of its own rather than a mode of allocation_node: it has state allocation_node does
not (the integral, the adapted gain, the measurement's health) and stricter rules (it falls
back to open loop on a stale or jumping measurement), and allocation_node's contract stays as
characterise uses it. The two both publish /softcath/pressure_cmd: run one or the other.

Targets waiting behind a busy controller: each callback takes every target waiting and uses the
newest; the watchdog counts from its arrival, and one older than ``command_timeout`` is dropped
(core.command_shaping's freshness rule), so no backlog holds pressure past timeout + ramp.

Parameters: design, model (default surrogate: the shipped table), mode (integral | adaptive | open_loop), the SteeringParams fields,
publish_rate (Hz), frame_id, max_tip_distance (m), diagnostics_period (s), executor;
max_pressure (Pa, read-only, default the design's steering range on the rung, core.steering_range.steering_range:
0.3 bar, lower where one channel alone would turn the tip past 90 degrees; never above the design's).
Time is the node's ROS clock, which the tracker's stamps are compared with.
"""
from __future__ import annotations

import sys
import time
from dataclasses import asdict, fields
from functools import partial

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped, PoseStamped
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from .. import topics
from ..core.command_shaping import check_frame, check_vector
from ..core.design import load_design
from ..core.model_selection import require_live_rung
from ..core.errors import SoftcathError
from ..core.pressure_command import check_pressure_command
from ..core.steering import MODES, SteeringController, SteeringError, SteeringParams
from ..core.steering_range import steering_allocator, steering_design, steering_model, steering_range
from .diagnostics import DiagnosticsReporter, InputCounters, ThrottledLog, diagnostic_status, publish_statuses
from .parameters import declare, refuse_unknown_parameters
from .qos import stream_qos
from .executors import EXECUTORS, take_waiting
from .runtime import run_node

NODE_NAME = topics.STEER_NODE
_DESCRIPTIONS = {
    "integral_gain": "integral gain on the bend error, 1/s",
    "forgetting": "adaptive mode: RLS forgetting factor per measurement",
    "lead_time": "lag cancelled on the feed-forward pressures, s",
    "plant_time_constant": "first-order estimate of the actuator's lag, s (adaptive regressor)",
    "max_pressure_rate": "largest change of any channel's pressure, Pa/s",
    "command_timeout": "no tip_target for this long (s): vent, ramped",
    "measurement_timeout": "older measurements are rejected; none accepted this long (s): open loop",
    "max_tip_speed": "apparent tip speed above this (m/s) is a jump: rejected",
    "jump_margin": "added to the speed allowance, m",
    "resume_samples": "consistent measurements before the loop closes (again)",
    "max_integral": "bound on the integral, rad",
    "allocation_period": "at most one inverse through the model per this period, s",
    "max_lead_step": "a pressure change above this between allocations (Pa) is a step: no lead",
}


class SteerNode(Node):
    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._log = ThrottledLog(self.get_logger(), 1.0)
        p = partial(declare, self)
        design_name = p("design", "three_sector_5mm", "design file or shipped design name")
        model_name = p("model", "surrogate", "model rung of the feed-forward (surrogate: the shipped table)")
        mode = p("mode", SteeringParams.mode, f"feedback: {' | '.join(MODES)}", choices=MODES)
        values = {"mode": mode}
        for f in fields(SteeringParams):
            if f.name in _DESCRIPTIONS:
                default = getattr(SteeringParams, f.name)
                values[f.name] = p(f.name, default, _DESCRIPTIONS[f.name], minimum=0 if isinstance(default, int)
                                   else 0.0)
        self.frame_id = p("frame_id", topics.FRAME_ID, "frame targets and measurements must be expressed in")
        publish_rate = p("publish_rate", 200.0, "pressure_cmd publishing rate, Hz", minimum=1.0, maximum=5000.0)
        diag_period = p("diagnostics_period", 1.0, "period of /diagnostics, s", minimum=1e-3, maximum=3600.0)
        self.executor_name = p("executor", "events", f"executor: {' | '.join(EXECUTORS)}", choices=EXECUTORS)
        refuse_unknown_parameters(self, later=("max_pressure", "max_tip_distance"))   # before the rung is built
        design = load_design(design_name)
        require_live_rung(model_name, design.name)
        model = steering_model(model_name, design)   # the rung on the shipped design
        requested_max = p("max_pressure", steering_range(model), "safety limit on every published pressure, Pa "
                          "(default the design's steering range; never above the design's)", minimum=1.0)
        if requested_max > design.max_pressure:
            self.get_logger().warning(f"max_pressure {requested_max:g} Pa exceeds design '{design.name}' limit "
                                      f"{design.max_pressure:g} Pa: using the design's")
        self.design = steering_design(design, requested_max)
        self.max_pressure = self.design.max_pressure
        allocator = steering_allocator(model, design, self.max_pressure)
        for said in (allocator.limited_by_rung, allocator.limited_by_peak):
            if said:
                self.get_logger().warning(said)
        self.max_tip_distance = p("max_tip_distance", 10.0 * self.design.length,
                                  "tip_target farther than this from the base (m) is a fault and rejected", minimum=0.0)
        self.params = SteeringParams(**values)
        self.ctrl = SteeringController(allocator, self.params)
        self.counters = InputCounters(extra={"design": self.design.name, "model": model_name, "mode": mode,
                                             "max_pressure_pa": f"{self.max_pressure:g}"})
        self.published = 0
        self.failed = 0
        self._last_state = None

        qos = stream_qos(100)
        self.pub = self.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, qos)
        self._target_sub = self.create_subscription(PointStamped, topics.TIP_TARGET, self._on_target, qos)
        self.create_subscription(PoseStamped, topics.TIP_MEASURED, self._on_measured, qos)
        self.create_timer(1.0 / publish_rate, self._tick)
        self._inputs_report = DiagnosticsReporter(self, self.counters, f"{NODE_NAME}: targets", self.design.name,
                                                  diag_period)
        self.diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.create_timer(diag_period, self._publish_diagnostics)
        self.get_logger().info(
            f"design {self.design.name}, model {model_name}"
            + (f" ({allocator.model.origin} table)" if getattr(allocator.model, "origin", "") else "")
            + f", mode {mode}, max_pressure {self.max_pressure:g} Pa, "
            f"measurement timeout {self.params.measurement_timeout:g} s, publishing at {publish_rate:g} Hz")

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_target(self, msg: PointStamped) -> None:
        now, arrived = self._now(), time.monotonic()
        waiting = take_waiting(self._target_sub)
        if waiting:                        # only the newest target matters
            self.counters.superseded += len(waiting)
            msg, arrived = waiting[-1]
        arrived = now - (time.monotonic() - arrived)   # on the node's clock
        tip = (msg.point.x, msg.point.y, msg.point.z)
        for check in (check_frame(msg.header.frame_id, self.frame_id),
                      check_vector(tip, self.max_tip_distance, "tip_target", "m")):
            if not check.ok:
                return self._reject(check.reason)
        try:
            self.ctrl.set_target(tip, now, arrived)
        except SteeringError as exc:
            return self._reject(str(exc))
        self.counters.accepted += 1

    def _reject(self, reason: str) -> None:
        self.counters.rejected += 1
        self.counters.last_reason = reason
        self._log.warning("rejected", f"rejected target ({self.counters.rejected} so far): {reason}")

    def _on_measured(self, msg: PoseStamped) -> None:
        if msg.header.frame_id != self.frame_id:
            self.ctrl.counters.invalid += 1
            return
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        pos = msg.pose.position
        self.ctrl.on_measurement((pos.x, pos.y, pos.z), stamp, self._now())

    def _tick(self) -> None:
        try:
            out = self.ctrl.step(self._now())
            values, state, reason = out.pressures, out.state, out.reason
        except SteeringError as exc:   # the model's inverse failed: ramp down, say so
            self.failed += 1
            self.counters.model_failed += 1
            self.counters.last_reason = str(exc)
            self._log.error("model_failed", f"{exc}; ramping to zero")
            values = self.ctrl.limiter.step(np.zeros_like(self.ctrl.limiter.output), 1.0 / 200.0)
            state, reason = "vented", str(exc)
        check = check_pressure_command(values, self.design.n_channels, self.max_pressure, out_of_range="clamp")
        if check.status == "rejected":
            self.get_logger().error(f"refusing to publish {list(values)}: {check.reason}; sending zeros")
            self.ctrl.limiter.output = np.zeros(self.design.n_channels)
            values = self.ctrl.limiter.output
        else:
            values = check.pressures
        if self.context.ok():
            self.pub.publish(Float64MultiArray(data=[float(v) for v in values]))
            self.published += 1
        if state != self._last_state:
            self._last_state = state
            text = f"loop {state.replace('_', ' ')}" + (f": {reason}" if reason else "")
            if state in ("closed_loop", "waiting"):   # rclpy: one severity per call site
                self.get_logger().info(text)
            else:
                self.get_logger().warning(text)
            self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        c, m = self.ctrl, self.ctrl.counters
        if c.state == "closed_loop":
            level, message = DiagnosticStatus.OK, "closed loop on the measured tip"
        elif c.state == "waiting":
            level, message = DiagnosticStatus.OK, "waiting for a tip target"
        else:
            level, message = DiagnosticStatus.WARN, f"{c.state.replace('_', ' ')}: {c.reason}"
        if c.saturated and c.state != "vented":
            level, message = DiagnosticStatus.WARN, message + "; saturated along the target's direction"
        values = {"state": c.state, "reason": c.reason, "mode": self.params.mode,
                  "saturated": str(bool(c.saturated)).lower(), "gain": f"{c.gain:.4f}",
                  "integral_rad": ",".join(f"{v:.5f}" for v in c.integral),
                  "output_pa": ",".join(f"{v:.1f}" for v in c.limiter.output),
                  "max_pressure_pa": f"{self.max_pressure:g}", "messages_published": str(self.published),
                  **{f"measurements_{k}": str(v) for k, v in asdict(m).items()}}
        publish_statuses(self, self.diag_pub,
                         diagnostic_status(level, f"{NODE_NAME}: loop", message, values, self.design.name))


def main(args=None) -> int:
    return run_node(SteerNode, args, startup_errors=(SoftcathError, ValueError, ParameterException))


if __name__ == "__main__":
    sys.exit(main())
