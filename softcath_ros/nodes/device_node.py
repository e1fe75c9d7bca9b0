"""The managed (lifecycle) node shape of the rig's drivers (regulator_node, scale_node, tracker_node)
around a pure core (bench/hardware's ``Regulator``, ``Scale``; bench/frames' ``TrackedInput``): configure builds the core and checks the
device (a fault is one line and a failed transition; at start-up with ``autostart`` exit code 2),
activate starts the ``tick`` timer at ``rate_hz``, deactivate stops it (the core vents), cleanup,
shutdown and the way out on SIGINT/SIGTERM (``finish``, runtime.run_node) close the core (which
vents first). A core that goes to ``error`` is logged and on /diagnostics at once."""
from __future__ import annotations

import time
from functools import partial

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn

from .. import topics
from ..bench.hardware.devices import DeviceFault
from ..bench.hardware.regulator import MAX_SILENCE_TIMEOUT, SILENCE_TIMEOUT
from ..core.errors import SoftcathError
from .parameters import declare, refuse_unknown_parameters


class DeviceNode(LifecycleNode):
    executor_name = "single"
    rate_hz = 50.0
    core = None

    def make_core(self):
        """The unconfigured core (Regulator or Scale) on its device."""
        raise NotImplementedError

    def make_publishers(self) -> list:
        """The lifecycle publishers of the readings (created at configure)."""
        raise NotImplementedError

    def declare_serial(self, default_port: str, note: str = "") -> None:
        """``port`` and ``baud`` of a serial device (``note``: "serial: " where it is one backend of several)."""
        p = partial(declare, self)
        self.port = p("port", default_port, f"{note}the device's serial port")
        self.baud = p("baud", 115200, f"{note}baud rate", minimum=300, maximum=4000000)

    def declare_checks(self, on_silence: str, must_answer: str) -> None:
        """``silence_timeout`` (then ``on_silence``) and ``check_timeout`` (configure: ``must_answer`` by then)."""
        p = partial(declare, self)
        self.silence_timeout = p("silence_timeout", SILENCE_TIMEOUT, f"no valid reading for this long (s): {on_silence}",
                                 minimum=0.05, maximum=MAX_SILENCE_TIMEOUT)
        self.check_timeout = p("check_timeout", 2.0, f"configure: {must_answer} within this, s", minimum=0.1,
                               maximum=60.0)

    def start(self) -> None:
        """Call at the end of __init__, once every other parameter is declared: declares ``autostart``,
        refuses parameters the node does not declare, and with ``autostart`` configures and activates."""
        autostart = declare(self, "autostart", True, "configure and activate at start (false: a lifecycle "
                            "manager drives it)")
        refuse_unknown_parameters(self)
        self.core = self.timer = None
        self.pubs = []
        self.configure_failed, self.last_reason = False, ""
        self.pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.create_timer(1.0, self.diagnostics)
        self._autostart = autostart
        if autostart:
            self.trigger_configure()
            if self.core is None:
                raise SoftcathError(f"configure failed: {self.last_reason}")
            self.trigger_activate()

    @property
    def state_name(self) -> str:
        return "unconfigured" if self.core is None else self.core.state

    def on_configure(self, state) -> TransitionCallbackReturn:
        try:
            core = self.make_core()
            ok = core.configure(time.sleep)
            reason = core.reason
        except (DeviceFault, SoftcathError, ValueError) as exc:
            core, ok, reason = None, False, str(exc)
        if not ok:
            self.last_reason, self.configure_failed = reason, True
            if not self._autostart:   # (at start-up the one line is the exit's)
                self.get_logger().error(f"configure: {reason}")
            self.diagnostics()
            return TransitionCallbackReturn.FAILURE
        self.core, self.configure_failed, self.last_reason = core, False, ""
        self.pubs = self.make_publishers()   # (self.core is set)
        self._autostart = False
        self.get_logger().info(f"configured: {self.configured()}")
        return TransitionCallbackReturn.SUCCESS

    def configured(self) -> str:
        """What configure opened, for the log line."""
        return self.core.device.name

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.core.activate()
        self.timer = self.create_timer(1.0 / self.rate_hz, self._tick)
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self._stop_timer()
        self.core.deactivate()
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def finish(self) -> int:
        """On the way out (SIGINT/SIGTERM or a fault): the core vents and closes its device."""
        self._release()
        return 0

    def _stop_timer(self) -> None:
        if self.timer is not None:
            self.destroy_timer(self.timer)
            self.timer = None

    def _release(self) -> None:
        self._stop_timer()
        if self.core is not None:
            self.core.close()
            self.core = None
            for pub in self.pubs:
                self.destroy_lifecycle_publisher(pub)
            self.pubs = []

    def _tick(self) -> None:
        was = self.core.state
        self.tick()
        if self.core.state == "error" and was != "error":
            self.get_logger().error(self.core.reason)
            self.diagnostics()                      # at once, not at the next 1 Hz report
        elif was == "error" and self.core.state == "active":   # (a core that does not latch: the scale)
            self.get_logger().warning("valid readings again")
            self.diagnostics()

    def level_and_message(self, problems: list[str]) -> tuple[int, str]:
        """/diagnostics level and message: ERROR when configure failed or the core is in error,
        WARN with ``problems`` (what the core counted), else OK with the state."""
        if self.core is None:
            if self.configure_failed:
                return DiagnosticStatus.ERROR, f"configure failed: {self.last_reason}"
            return DiagnosticStatus.OK, "unconfigured"
        if self.core.state == "error":
            return DiagnosticStatus.ERROR, self.core.reason
        problems = [p for p in problems if p]
        if problems:
            return DiagnosticStatus.WARN, "; ".join(problems)
        return DiagnosticStatus.OK, self.core.state
