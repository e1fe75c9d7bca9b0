"""allocation_node (softcath_allocation): desired bending -> channel pressures.

Subscribes /softcath/bend_cmd (geometry_msgs/Vector3Stamped, curvature x, y in 1/m in
softcath_base, z ignored) and /softcath/tip_target (geometry_msgs/PointStamped, m);
publishes /softcath/pressure_cmd (std_msgs/Float64MultiArray, Pa, one per channel) and
/diagnostics. The physics is the core Allocator on the chosen rung; the stream (rate limit,
watchdog, keep-alive) is the core PressureStream; this node parses, checks and reports.

Output rate: a new command goes out at once; while the output ramps it goes out at
``publish_rate``; an unchanged output (idle, or holding a target) is re-sent every
KEEP_ALIVE_PERIOD (0.1 s, five per the rig's 0.5 s command watchdog), and an idle node (vented,
at zero) only wakes for that keep-alive, so an idle graph costs little
(benchmarks/idle_graph.py).
Backlog: each callback takes every command waiting and allocates only the newest (the others
are superseded); the watchdog counts from a command's arrival and a command older than
``command_timeout`` when handled is dropped, so no backlog holds pressure past timeout + ramp.

Parameters: design, model, max_pressure_rate (Pa/s), command_timeout (s), frame_id,
publish_rate (Hz), max_request_curvature (1/m), max_tip_distance (m), hysteresis_deg,
diagnostics_period (s); max_pressure (Pa) is read-only: it may only be lowered below the
design's limit (at start-up), never raised, and it is enforced again on every message.
"""
from __future__ import annotations

import time
from dataclasses import replace
from functools import partial

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped, Vector3Stamped
from rclpy.exceptions import ParameterException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from .. import topics
from ..core.allocation import Allocator
from ..core.errors import SoftcathError
from ..core.command_shaping import KEEP_ALIVE_PERIOD, PressureStream, check_frame, check_vector
from ..core.design import load_design
from ..core.model_selection import require_live_rung
from ..core.calibration_file import build_model, load_calibration
from ..core.pressure_command import check_pressure_command
from .diagnostics import DiagnosticsReporter, InputCounters, ThrottledLog, diagnostic_status, publish_statuses
from .parameters import declare, refuse_unknown_parameters
from .qos import RELIABILITIES, stream_qos
from .executors import EXECUTORS, take_waiting
from .runtime import run_node

NODE_NAME = topics.ALLOCATION_NODE
RCLError = _rclpy.RCLError


class AllocationNode(Node):
    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._log = ThrottledLog(self.get_logger(), 1.0)
        p = partial(declare, self)
        design_name = p("design", "three_sector_5mm", "design file or shipped design name")
        model_name = p("model", "surrogate", "model rung used for the inverse")
        calibration_file = p("calibration", "", "calibration file from `softcath calibrate`, applied to the rung ('' = none)")
        self.max_rate = p("max_pressure_rate", 2.0e5, "largest change of any channel's pressure, Pa/s",
                          minimum=1.0, maximum=1e9)
        self.timeout = p("command_timeout", 0.5, "no command for this long (s): vent, ramped",
                         minimum=1e-3, maximum=3600.0)
        self.frame_id = p("frame_id", topics.FRAME_ID, "frame commands must be expressed in")
        publish_rate = p("publish_rate", 200.0, "pressure_cmd rate while the output ramps or a target is held, Hz "
                         "(idle: the keep-alive, 10 Hz)", minimum=0.1, maximum=10000.0)
        self.max_request_curvature = p("max_request_curvature", 1000.0,
                                       "bend_cmd above this |k| (1/m) is a fault and rejected (below it saturates)",
                                       minimum=0.0)
        hysteresis = p("hysteresis_deg", 0.2, "angular hysteresis of the active channel pair, degrees",
                       minimum=0.0, maximum=30.0)
        diag_period = p("diagnostics_period", 1.0, "period of /diagnostics, s", minimum=1e-3, maximum=3600.0)
        depth = p("qos_depth", 100, "keep-last depth of the command subscriptions and pressure publisher",
                  minimum=1, maximum=100000)
        reliability = p("reliability", "reliable", f"QoS reliability: {' | '.join(RELIABILITIES)}",
                        choices=RELIABILITIES)
        self.executor_name = p("executor", "events", f"executor: {' | '.join(EXECUTORS)}", choices=EXECUTORS)
        self.realtime_priority = p("realtime_priority", 0, "SCHED_FIFO priority 1-99 for the node's threads, "
                                                           "0 = normal scheduling", minimum=0, maximum=99)
        refuse_unknown_parameters(self, later=("max_pressure", "max_tip_distance"))   # before the rung is built

        design = load_design(design_name)
        require_live_rung(model_name, design.name)
        requested_max = p("max_pressure", design.max_pressure, "safety limit on every published pressure, Pa")
        if not requested_max > 0:
            raise SoftcathError(f"max_pressure {requested_max} Pa must be positive")
        if requested_max > design.max_pressure:
            self.get_logger().warning(f"max_pressure {requested_max} Pa exceeds design '{design.name}' limit "
                                      f"{design.max_pressure} Pa: using the design's")
        # A lowered limit goes into the design the allocator sees, so saturation stays along the
        # requested direction instead of clipping channels one by one at the wire.
        self.design = replace(design, max_pressure=min(float(requested_max), design.max_pressure))
        self.max_pressure = self.design.max_pressure
        # the rung on the design as shipped (a lowered limit would change its content hash, and a
        # surrogate would build a table for it): the allocator gets the lowered limit instead
        calibration = load_calibration(calibration_file) if calibration_file else None
        self.allocator = Allocator(build_model(model_name, design, calibration), max_pressure=self.max_pressure,
                                   hysteresis_deg=hysteresis)
        for said in (self.allocator.limited_by_rung, self.allocator.limited_by_peak):
            if said:
                self.get_logger().warning(said)
        self.max_tip_distance = p("max_tip_distance", 10.0 * self.design.length,
                                  "tip_target farther than this from the base (m) is a fault and rejected",
                                  minimum=0.0)

        n = self.design.n_channels
        self.stream = PressureStream(n, self.max_rate, self.timeout, time.monotonic)
        self.last = None            # last Allocation
        self._last_request = None   # (kind, request) of self.last: an unchanged command is not re-allocated
        self.counters = InputCounters(extra={"design": self.design.name, "model": model_name,
                                             "max_pressure_pa": f"{self.max_pressure:g}"})
        self.published = 0

        qos = stream_qos(depth, reliability)
        self.pub = self.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, qos)
        self._bend_sub = self.create_subscription(Vector3Stamped, topics.BEND_CMD, self._on_bend, qos)
        self._tip_sub = self.create_subscription(PointStamped, topics.TIP_TARGET, self._on_tip, qos)
        self.period = 1.0 / publish_rate
        # Ticks at publish_rate while a target is held or the output ramps (the watchdog is checked
        # on time); idle (vented, at zero) only the keep-alive timer runs.
        self._ramp_timer = self.create_timer(self.period, self._tick)
        self.create_timer(KEEP_ALIVE_PERIOD, self._keep_alive)
        # Two statuses: the shared input counters (accepted/rejected, as every node reports them)
        # and this node's output state (watchdog, saturation), published on each change too.
        self._inputs_report = DiagnosticsReporter(self, self.counters, f"{NODE_NAME}: commands",
                                                  self.design.name, diag_period)
        self.diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.create_timer(diag_period, self._publish_diagnostics)
        self.get_logger().info(
            f"design {self.design.name} ({n} channels), model {model_name}, max_pressure {self.max_pressure:g} Pa, "
            f"rate limit {self.max_rate:g} Pa/s, timeout {self.timeout:g} s, executor {self.executor_name}, "
            f"publishing at {publish_rate:g} Hz")

    # ------------------------------------------------------------------ inputs

    def _reject(self, reason: str) -> None:
        c = self.counters
        c.rejected += 1
        c.last_reason = reason
        self._log.warning("rejected", f"rejected command ({c.rejected} so far): {reason}")

    @property
    def vented(self) -> bool:
        return self.stream.vented

    def _on_bend(self, msg: Vector3Stamped) -> None:
        self._take(msg, getattr(self, "_bend_sub", None), self._bend_request)

    def _on_tip(self, msg: PointStamped) -> None:
        self._take(msg, getattr(self, "_tip_sub", None), self._tip_request)

    def _bend_request(self, msg: Vector3Stamped):
        k = (msg.vector.x, msg.vector.y)
        for check in (check_frame(msg.header.frame_id, self.frame_id),
                      check_vector(k, self.max_request_curvature, "bend_cmd curvature", "1/m")):
            if not check.ok:
                return check.reason
        return ("bend", k), lambda: self.allocator.allocate(k)

    def _tip_request(self, msg: PointStamped):
        tip = (msg.point.x, msg.point.y, msg.point.z)
        for check in (check_frame(msg.header.frame_id, self.frame_id),
                      check_vector(tip, self.max_tip_distance, "tip_target", "m")):
            if not check.ok:
                return check.reason
        return ("tip", tip), lambda: self.allocator.allocate_tip(tip)

    def _take(self, msg, subscription, request_of) -> None:
        """``msg`` (arrived now) and every command waiting behind it: each is checked (bad ones
        rejected), the newest valid one is allocated (the others superseded) unless it is stale."""
        batch = [(msg, time.monotonic())] + (take_waiting(subscription) if subscription is not None else [])
        valid = []
        for m, arrived in batch:
            request = request_of(m)
            if isinstance(request, str):
                self._reject(request)
            else:
                valid.append((request, arrived))
        if not valid:
            return
        if len(valid) > 1:
            self.counters.superseded += len(valid) - 1
            self.counters.last_reason = "command superseded by a newer one before it was allocated"
        (request, allocate), arrived = valid[-1]
        if not self.stream.fresh(arrived):
            self.stream.dropped += 1
            return self._reject(f"stale command dropped: it arrived more than command_timeout "
                                f"{self.timeout:g} s ago")
        self._apply(request, allocate, arrived)

    def _apply(self, request, allocate, arrived: float) -> None:
        if request == self._last_request and self.last is not None:
            result = self.last       # an unchanged command: the same allocation, no model call
        else:
            try:
                result = allocate()
            except SoftcathError as exc:
                return self._reject(str(exc))
            if not result.reachable:
                return self._reject(result.message)
            if not result.converged:
                self.counters.model_failed += 1
                self.counters.last_reason = result.message
                self._log.warning("model_failed", result.message)
                return
        was_vented = self.stream.vented
        if not self.stream.command(result.pressures, arrived):   # went stale while it was allocated
            return self._reject(f"stale command dropped: it arrived more than command_timeout {self.timeout:g} s ago")
        self.counters.accepted += 1
        self.last, self._last_request = result, request
        if was_vented:
            self._ramp_timer.reset()
            self.get_logger().info("command stream resumed")
            self._publish_diagnostics()
        # A new target goes out at once (rate limited): a fast command stream sets the output rate
        # and costs one callback per command instead of two.
        self._send(self.stream.output(force=True))

    # ------------------------------------------------------------------ output

    def _keep_alive(self) -> None:
        self._tick(keep_alive=True)

    def _tick(self, keep_alive: bool = False) -> None:
        """Timers: ramps at publish_rate, re-sends an unchanged output at the keep-alive rate
        (``keep_alive``: this is that timer, so send), and vents when the watchdog expires."""
        if self.stream.check_watchdog():
            self.get_logger().warning(f"no command for {self.timeout:g} s: venting (ramping all pressures to zero)")
            self._publish_diagnostics()
        self._send(self.stream.output(force=keep_alive))
        if self.stream.vented and self.stream.settled and not self._ramp_timer.is_canceled():
            self._ramp_timer.cancel()     # idle: the keep-alive timer alone

    def _send(self, out) -> None:
        if out is None:
            return
        # Last guard before the wire: the limit is enforced here whatever happened upstream.
        check = check_pressure_command(out, self.design.n_channels, self.max_pressure, out_of_range="clamp")
        if check.status == "rejected":  # non-finite: nothing safe to send but zero
            self.get_logger().error(f"refusing to publish {out.tolist()}: {check.reason}; sending zeros")
            values = np.zeros_like(out)
        else:
            values = check.pressures
        if check.status != "ok":
            self.stream.sent(values)
        try:
            self.pub.publish(Float64MultiArray(data=[float(v) for v in values]))
        except RCLError:
            if self.context.ok():
                raise
            return  # SIGINT/SIGTERM shut the context down while this callback ran: nothing to do
        self.published += 1

    def _publish_diagnostics(self) -> None:
        """Output state: WARN while vented (after commands stopped) or saturated."""
        last = self.last
        if self.vented:
            level = DiagnosticStatus.WARN if self.counters.accepted else DiagnosticStatus.OK
            message = "vented: no command within the timeout" if self.counters.accepted else "waiting for commands"
        elif last is not None and last.saturated:
            level, message = DiagnosticStatus.WARN, "saturated: request beyond the reachable set"
        else:
            level, message = DiagnosticStatus.OK, "tracking commands"
        values = {
            "watchdog": "vented" if self.vented else "ok",
            "saturated": str(bool(last is not None and last.saturated and not self.vented)).lower(),
            "active_channels": "" if last is None else ",".join(map(str, last.active_channels)),
            "target_pa": ",".join(f"{v:.1f}" for v in self.stream.target),
            "output_pa": ",".join(f"{v:.1f}" for v in self.stream.limiter.output),
            "stale_dropped": str(self.stream.dropped),
            "max_pressure_pa": f"{self.max_pressure:g}",
            "messages_published": str(self.published),
        }
        publish_statuses(self, self.diag_pub,
                         diagnostic_status(level, f"{NODE_NAME}: output", message, values, self.design.name))


def main(args=None) -> int:
    return run_node(AllocationNode, args, startup_errors=(SoftcathError, ValueError, ParameterException))


if __name__ == "__main__":
    import sys

    sys.exit(main())
