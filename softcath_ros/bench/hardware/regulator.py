"""The pressure regulator's run logic on an injected clock (no ROS; regulator_node adapts it).

States: ``unconfigured`` -> configure (open the device, vent, and every channel must answer within
``check_timeout``) -> ``inactive`` -> activate -> ``active`` -> deactivate (vent) -> ``inactive``;
cleanup/shutdown vent and close. While active, each ``tick()``:

- sends the commanded pressures, every value clamped to [0, max_pressure] (a command with the wrong
  channel count or a non-finite value is refused, core/pressure_command.py), rate limited, re-sent
  every ``keep_alive`` (the firmware's own watchdog), and vents (at once) when no command arrived
  for ``command_timeout`` (the silence counts from a command's arrival: core/command_shaping.py);
- returns the new valid readings (the newest per channel; refused lines are counted, never returned);
- when no valid reading came for ``silence_timeout`` (0.4 s) the device is declared silent: vent and
  go to ``error`` (ticks at 50 Hz: within 0.5 s of the last reading) (latched: it keeps venting until deactivated or cleaned up).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...core.command_shaping import PressureStream
from ...core.pressure_command import check_pressure_command
from .devices import DeviceFault
from .protocol import DeviceError, Reading, Refused

# s without a valid reading: the device is silent. ERROR must come within 0.5 s of the device going
# silent: this, plus a tick (20 ms at 50 Hz) and a Modbus request's timeout (50 ms), stays below it.
SILENCE_TIMEOUT = 0.4
MAX_SILENCE_TIMEOUT = 0.45


@dataclass
class Counters:
    readings: int = 0          # valid readings taken
    superseded: int = 0        # valid readings replaced by a newer one of the same channel before a tick
    refused: int = 0           # device lines / registers refused (malformed, NaN, out of range)
    device_errors: int = 0     # ERR lines
    commands: int = 0          # commands applied
    clamped: int = 0
    rejected: int = 0          # wrong channel count / non-finite
    stale: int = 0             # older than command_timeout when handled
    timeouts: int = 0          # vented: no command for command_timeout
    last_refused: str = ""
    last_device_error: str = ""
    last_command_problem: str = ""
    extra: dict = field(default_factory=dict)


class Regulator:
    def __init__(self, device, n_channels: int, max_pressure: float, clock, *, command_timeout: float = 0.5,
                 silence_timeout: float = SILENCE_TIMEOUT, check_timeout: float = 2.0,
                 max_rate: float = 1e9, keep_alive: float = 0.1):
        if not (max_pressure > 0 and math.isfinite(max_pressure)):
            raise ValueError(f"max_pressure {max_pressure} Pa must be positive and finite")
        self.device, self.n, self.max_pressure, self.clock = device, int(n_channels), float(max_pressure), clock
        self.command_timeout, self.silence_timeout, self.check_timeout = command_timeout, silence_timeout, check_timeout
        self.max_rate, self.keep_alive = max_rate, keep_alive
        self.stream = self._new_stream()
        self.state = "unconfigured"
        self.reason = ""             # why configure failed or why the state is error
        self.counters = Counters()
        self.last_answer = -math.inf # clock time of the last valid reading
        self.last_sent = np.zeros(self.n)
        self._t_vent = -math.inf

    def _new_stream(self) -> PressureStream:
        return PressureStream(self.n, self.max_rate, self.command_timeout, self.clock, keep_alive=self.keep_alive)

    # -- transitions ---------------------------------------------------------------------------------
    def configure(self, sleep) -> bool:
        """Open the device, vent it and wait (``sleep(s)``) until every channel answered within
        ``check_timeout``; False (with ``reason``) when it cannot be opened or stays silent."""
        try:
            self.device.open()
        except DeviceFault as exc:
            self.reason = str(exc)
            return False
        self.device.vent()
        deadline = self.clock() + self.check_timeout
        heard: set[int] = set()
        while True:
            heard |= {r.channel for r in self._take()}
            if len(heard) == self.n:
                break
            if self.clock() >= deadline:
                self.device.vent()
                self.device.close()
                missing = sorted(set(range(self.n)) - heard)
                extra = f"; last refused line: {self.counters.last_refused}" if self.counters.last_refused else ""
                self.reason = (f"{self.device.name}: no valid reading of channel(s) {missing} within "
                               f"{self.check_timeout:g} s{extra}")
                return False
            sleep(0.01)
        self.state, self.reason = "inactive", ""
        return True

    def activate(self) -> None:
        self.stream = self._new_stream()     # a command from before activation is not applied
        self.stream.output()                 # (the rate limit counts from here, not from the first tick)
        self.last_answer = self.clock()      # silence counts from here
        self.state = "active"

    def deactivate(self) -> None:
        self.vent()
        self.state = "inactive"

    def close(self) -> None:
        """Cleanup or shutdown: vent, then close the device."""
        if self.state != "unconfigured":
            self.vent()
            self.device.close()
        self.state = "unconfigured"

    def vent(self) -> None:
        self.stream = self._new_stream()
        self.last_sent = np.zeros(self.n)
        self._t_vent = self.clock()
        self.device.vent()

    # -- while active ----------------------------------------------------------------------------------
    def command(self, values, arrived: float) -> str:
        """A pressure command (Pa per channel) that arrived at ``arrived``: 'ok', 'clamped',
        'rejected' or 'stale' (the last two are not applied)."""
        check = check_pressure_command(values, self.n, self.max_pressure, out_of_range="clamp")
        c = self.counters
        if check.pressures is None:
            c.rejected += 1
            c.last_command_problem = check.reason
            return "rejected"
        if not self.stream.command(check.pressures, arrived):
            c.stale += 1
            return "stale"
        c.commands += 1
        if check.status == "clamped":
            c.clamped += 1
            c.last_command_problem = check.reason
        return check.status

    def tick(self) -> list[Reading]:
        """Send what is due, take what the device said; the new readings (newest per channel)."""
        if self.state not in ("active", "error"):
            return []
        readings = self._take()
        now = self.clock()
        if readings:
            self.last_answer = now
        if self.state == "active" and now - self.last_answer > self.silence_timeout:
            self.state = "error"
            fault = getattr(self.device, "fault", "")
            self.reason = (f"{self.device.name}: no valid reading for {now - self.last_answer:.2f} s: vented"
                           + (f" ({fault})" if fault else ""))
            self.vent()
        if self.state == "error":
            if now - self._t_vent >= self.keep_alive:   # keep telling it to vent
                self._t_vent = now
                self.device.vent()
            return []
        if self.stream.check_watchdog():       # command timeout: vent at once, not at the rate limit
            self.counters.timeouts += 1
            self.stream.sent(np.zeros(self.n))
            self.last_sent = np.zeros(self.n)
            self.device.vent()
        out = self.stream.output()
        if out is not None:
            out = np.clip(out, 0.0, self.max_pressure)       # the last guard before the wire
            self.stream.sent(out)
            self.last_sent = out
            self.device.send(out)
        newest = {}
        for r in readings:
            if r.channel in newest:
                self.counters.superseded += 1
            newest[r.channel] = r
        return [newest[c] for c in sorted(newest)]

    def _take(self) -> list[Reading]:
        return take_readings(self.device, self.counters)


def take_readings(device, counters: Counters) -> list[Reading]:
    """The device's valid readings since the last call; refused lines and ERR lines counted."""
    c = counters
    good = []
    for item in device.poll():
        if isinstance(item, Reading):
            good.append(item)
            c.readings += 1
        elif isinstance(item, DeviceError):
            c.device_errors += 1
            c.last_device_error = item.text
        elif isinstance(item, Refused):
            c.refused += 1
            c.last_refused = f"{item.line!r}: {item.reason}"
    lines = getattr(device, "lines", None)
    if lines is not None and lines.overlong:
        c.refused += lines.overlong
        c.last_refused = "a line longer than the protocol allows"
        lines.overlong = 0
    return good
