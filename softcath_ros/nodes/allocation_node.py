"""allocation_node (softcath_allocation): desired bending -> channel pressures.

Subscribes /softcath/bend_cmd (geometry_msgs/Vector3Stamped, curvature x, y in 1/m in
softcath_base, z ignored) and /softcath/tip_target (geometry_msgs/PointStamped, m);
publishes /softcath/pressure_cmd (std_msgs/Float64MultiArray, Pa, one per channel) at
``publish_rate`` and /diagnostics. The physics is the core Allocator on the chosen rung;
this node parses, checks, rate-limits, watches the command stream and reports.

Parameters: design, model, max_pressure_rate (Pa/s), command_timeout (s), frame_id,
publish_rate (Hz), max_request_curvature (1/m), max_tip_distance (m), hysteresis_deg,
diagnostics_period (s); max_pressure (Pa) is read-only: it may only be lowered below the
design's limit (at start-up), never raised, and it is enforced again on every message.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import replace

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, Vector3Stamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from ..core.allocation import Allocator
from ..core.errors import SoftcathError
from ..core.command_shaping import CommandWatchdog, RateLimiter, check_frame, check_vector
from ..core.design import load_design
from ..core.models import make_model
from ..core.pressure_command import check_pressure_command

NODE_NAME = "softcath_allocation"


class AllocationNode(Node):
    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        p = self._declare
        design_name = p("design", "three_channel_5mm", "design file or shipped design name")
        model_name = p("model", "closed_form", "model rung used for the inverse")
        self.max_rate = p("max_pressure_rate", 2.0e5, "largest change of any channel's pressure, Pa/s")
        self.timeout = p("command_timeout", 0.5, "no command for this long (s): vent, ramped")
        self.frame_id = p("frame_id", "softcath_base", "frame commands must be expressed in")
        publish_rate = p("publish_rate", 200.0, "pressure_cmd publishing rate, Hz")
        self.max_request_curvature = p("max_request_curvature", 1000.0,
                                       "bend_cmd above this |k| (1/m) is a fault and rejected (below it saturates)")
        hysteresis = p("hysteresis_deg", 0.2, "angular hysteresis of the active channel pair, degrees")
        diag_period = p("diagnostics_period", 1.0, "period of /diagnostics, s")

        design = load_design(design_name)
        requested_max = self._declare("max_pressure", design.max_pressure,
                                      "safety limit on every published pressure, Pa (read-only)", read_only=True)
        if not requested_max > 0:
            raise SoftcathError(f"max_pressure {requested_max} Pa must be positive")
        if requested_max > design.max_pressure:
            self.get_logger().warning(f"max_pressure {requested_max} Pa exceeds design '{design.name}' limit "
                                      f"{design.max_pressure} Pa: using the design's")
        # A lowered limit goes into the design the allocator sees, so saturation stays along the
        # requested direction instead of clipping channels one by one at the wire.
        self.design = replace(design, max_pressure=min(float(requested_max), design.max_pressure))
        self.max_pressure = self.design.max_pressure
        self.allocator = Allocator(make_model(model_name, self.design), hysteresis_deg=hysteresis)
        self.max_tip_distance = p("max_tip_distance", 10.0 * self.design.length,
                                  "tip_target farther than this from the base (m) is a fault and rejected")
        if not (publish_rate > 0 and math.isfinite(publish_rate)):
            raise SoftcathError(f"publish_rate {publish_rate} Hz must be positive")

        n = self.design.n_channels
        self.limiter = RateLimiter(n, self.max_rate)
        self.watchdog = CommandWatchdog(self.timeout)
        self.target = np.zeros(n)
        self.last = None            # last Allocation
        self.vented = True          # no command yet counts as vented
        self.received = 0
        self.rejected = 0
        self.last_rejection = ""
        self.published = 0
        self._last_publish = time.monotonic()

        self.pub = self.create_publisher(Float64MultiArray, "/softcath/pressure_cmd", 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(Vector3Stamped, "/softcath/bend_cmd", self._on_bend, 10)
        self.create_subscription(PointStamped, "/softcath/tip_target", self._on_tip, 10)
        self.period = 1.0 / publish_rate
        self.create_timer(self.period, self._tick)
        self.create_timer(diag_period, self._publish_diagnostics)
        self.get_logger().info(
            f"design {self.design.name} ({n} channels), model {model_name}, max_pressure {self.max_pressure:g} Pa, "
            f"rate limit {self.max_rate:g} Pa/s, timeout {self.timeout:g} s, publishing at {publish_rate:g} Hz")

    def _declare(self, name, default, description, read_only=False):
        # Numbers accept an integer too (``-p max_pressure:=40000``), then count as float.
        numeric = isinstance(default, float)
        desc = ParameterDescriptor(description=description, read_only=read_only, dynamic_typing=numeric)
        value = self.declare_parameter(name, default, desc).value
        if numeric:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise SoftcathError(f"parameter {name} = {value!r}: must be a number")
            return float(value)
        return value

    # ------------------------------------------------------------------ inputs

    def _reject(self, reason: str) -> None:
        self.rejected += 1
        self.last_rejection = reason
        self.get_logger().warning(f"rejected command ({self.rejected} so far): {reason}", throttle_duration_sec=1.0)

    def _on_bend(self, msg: Vector3Stamped) -> None:
        self.received += 1
        k = (msg.vector.x, msg.vector.y)
        for check in (check_frame(msg.header.frame_id, self.frame_id),
                      check_vector(k, self.max_request_curvature, "bend_cmd curvature", "1/m")):
            if not check.ok:
                return self._reject(check.reason)
        self._apply(lambda: self.allocator.allocate(k))

    def _on_tip(self, msg: PointStamped) -> None:
        self.received += 1
        tip = (msg.point.x, msg.point.y, msg.point.z)
        for check in (check_frame(msg.header.frame_id, self.frame_id),
                      check_vector(tip, self.max_tip_distance, "tip_target", "m")):
            if not check.ok:
                return self._reject(check.reason)
        self._apply(lambda: self.allocator.allocate_tip(tip))

    def _apply(self, allocate) -> None:
        try:
            result = allocate()
        except SoftcathError as exc:
            return self._reject(str(exc))
        if not result.reachable or not result.converged:
            return self._reject(result.message)
        self.last = result
        self.target = result.pressures
        self.watchdog.feed(time.monotonic())
        if self.vented:
            self.vented = False
            self.get_logger().info("command stream resumed")
            self._publish_diagnostics()
        # A new target goes out at once (rate limited): a fast command stream sets the output rate
        # and costs one callback per command instead of two.
        self._publish_step(time.monotonic())

    # ------------------------------------------------------------------ output

    def _tick(self) -> None:
        """Timer: the output never falls below publish_rate, and the watchdog is checked."""
        now = time.monotonic()
        if self.watchdog.expired(now) and not self.vented:
            self.vented = True
            self.get_logger().warning(f"no command for {self.timeout:g} s: venting (ramping all pressures to zero)")
            self._publish_diagnostics()
        if now - self._last_publish >= 0.9 * self.period or self.vented:
            self._publish_step(now)

    def _publish_step(self, now: float) -> None:
        dt, self._last_publish = now - self._last_publish, now
        target = np.zeros_like(self.target) if self.vented else self.target
        out = self.limiter.step(target, dt)
        # Last guard before the wire: the limit is enforced here whatever happened upstream.
        check = check_pressure_command(out, self.design.n_channels, self.max_pressure, out_of_range="clamp")
        if check.status == "rejected":  # non-finite: nothing safe to send but zero
            self.get_logger().error(f"refusing to publish {out.tolist()}: {check.reason}; sending zeros")
            self.limiter.output = np.zeros_like(out)
            values = self.limiter.output
        else:
            values = check.pressures
        self.pub.publish(Float64MultiArray(data=[float(v) for v in values]))
        self.published += 1

    def _publish_diagnostics(self) -> None:
        level, words = DiagnosticStatus.OK, []
        if self.vented:
            level = DiagnosticStatus.WARN
            words.append("vented: no command within the timeout" if self.received else "waiting for commands")
        if self.last is not None and self.last.saturated and not self.vented:
            level = DiagnosticStatus.WARN
            words.append("saturated: request beyond the reachable set")
        if self.rejected:
            words.append(f"{self.rejected} command(s) rejected")
            level = max(level, DiagnosticStatus.WARN)
        last = self.last
        values = {
            "design": self.design.name, "model": self.allocator.model.name,
            "max_pressure_pa": f"{self.max_pressure:g}",
            "watchdog": "vented" if self.vented else "ok",
            "commands_received": str(self.received), "commands_rejected": str(self.rejected),
            "last_rejection": self.last_rejection,
            "saturated": str(bool(last is not None and last.saturated)).lower(),
            "active_channels": "" if last is None else ",".join(map(str, last.active_channels)),
            "target_pa": ",".join(f"{v:.1f}" for v in self.target),
            "output_pa": ",".join(f"{v:.1f}" for v in self.limiter.output),
            "messages_published": str(self.published),
        }
        status = DiagnosticStatus(level=level, name=f"{NODE_NAME}: allocation", hardware_id=self.design.name,
                                  message="; ".join(words) or "ok",
                                  values=[KeyValue(key=k, value=v) for k, v in values.items()])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)


def main(args=None) -> int:
    rclpy.init(args=args)
    # The executor exists before the (slower) node set-up, so a SIGTERM during set-up does not
    # leave rclpy half-building one (its __del__ then prints spurious tracebacks).
    # (rclpy 9.1's experimental EventsExecutor was tried: it ignored SIGTERM here.)
    executor = SingleThreadedExecutor()
    node = None
    try:
        node = AllocationNode()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (SoftcathError, ValueError) as exc:  # bad parameters: one line, non-zero exit
        print(f"{NODE_NAME}: error: {exc}", file=sys.stderr)
        return 2
    except Exception:  # noqa: BLE001
        # SIGTERM shuts the context down under the executor, which may then fail to build its
        # wait set: that is the requested shutdown, not a fault. Anything else is re-raised.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
