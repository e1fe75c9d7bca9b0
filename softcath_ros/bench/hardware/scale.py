"""The load cell's run logic on an injected clock (no ROS; scale_node adapts it).

configure: open the device and one valid ``F`` reading must come within ``check_timeout``;
active: each ``tick()`` returns the newest valid force (N) since the last tick; refused lines
(malformed, NaN, beyond the cell's capacity) are counted, never returned; ``tare()`` sends ``TARE``
(the board zeroes its reading at the present load); no valid reading for ``silence_timeout``:
``error``, until valid readings come again (counted in ``silences``). A scale commands nothing, so
unlike the regulator (which vents) it need not latch: a host or board that stalls for a moment must
not end a run whose readings resume; bench_node judges each reading's freshness itself.
"""
from __future__ import annotations

import math

from .devices import DeviceFault
from .protocol import Reading
from .regulator import SILENCE_TIMEOUT, Counters, take_readings


class Scale:
    def __init__(self, device, clock, *, check_timeout: float = 2.0, silence_timeout: float = SILENCE_TIMEOUT):
        self.device, self.clock = device, clock
        self.check_timeout, self.silence_timeout = check_timeout, silence_timeout
        self.state, self.reason = "unconfigured", ""
        self.counters = Counters()
        self.last_answer = -math.inf
        self.tares = 0
        self.silences, self.last_silence = 0, ""    # how often the board fell silent, and the last time's reason

    def configure(self, sleep) -> bool:
        try:
            self.device.open()
        except DeviceFault as exc:
            self.reason = str(exc)
            return False
        deadline = self.clock() + self.check_timeout
        while not self._take():
            if self.clock() >= deadline:
                self.device.close()
                extra = f"; last refused line: {self.counters.last_refused}" if self.counters.last_refused else ""
                self.reason = f"{self.device.name}: no valid force reading within {self.check_timeout:g} s{extra}"
                return False
            sleep(0.01)
        self.state, self.reason = "inactive", ""
        return True

    def activate(self) -> None:
        self.last_answer = self.clock()
        self.state = "active"

    def deactivate(self) -> None:
        self.state = "inactive"

    def close(self) -> None:
        if self.state != "unconfigured":
            self.device.close()
        self.state = "unconfigured"

    def tare(self) -> bool:
        """Zero the scale at the present load; False unless configured."""
        if self.state == "unconfigured":
            return False
        self.device.tare()
        self.tares += 1
        return True

    def tick(self) -> Reading | None:
        if self.state not in ("active", "error"):
            return None
        readings = self._take()
        now = self.clock()
        if readings:
            self.last_answer = now
            self.counters.superseded += len(readings) - 1
            if self.state == "error":          # the board speaks again
                self.state, self.reason = "active", ""
        if self.state == "active" and now - self.last_answer > self.silence_timeout:
            fault = getattr(self.device, "fault", "")
            self.state = "error"
            self.reason = (f"{self.device.name}: no valid reading for {now - self.last_answer:.2f} s"
                           + (f" ({fault})" if fault else ""))
            self.silences, self.last_silence = self.silences + 1, self.reason
        return readings[-1] if readings and self.state == "active" else None

    def _take(self) -> list[Reading]:
        return take_readings(self.device, self.counters)
