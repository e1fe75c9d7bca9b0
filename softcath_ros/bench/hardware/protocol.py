"""The serial line protocols (docs/lab.md), one ASCII line per message, ``\\n``-terminated
(``\\r\\n`` accepted), at most ``MAX_LINE`` characters.

Regulator: host -> device ``SET <ch> <Pa>`` (gauge setpoint of channel ch = 0..n-1) and ``VENT``
(all channels to zero); device -> host ``P <ch> <Pa>`` (a gauge reading, >= 20 Hz per channel) and
``ERR <text>`` (a fault the device saw). Scale: host ``TARE``; device ``F <newtons>`` (>= 20 Hz)
and ``ERR <text>``. The firmware vents by itself when no ``SET``/``VENT`` came for 1 s.

A line that is malformed, names an unknown channel, or carries a non-finite or out-of-range number
is refused (``Refused``, counted by the caller), never taken as a reading.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

MAX_LINE = 80          # characters; a longer line is refused (a flood never grows a buffer)


@dataclass(frozen=True)
class Reading:
    channel: int       # 0.. (the scale: 0)
    value: float       # Pa (regulator) or N (scale)


@dataclass(frozen=True)
class DeviceError:
    text: str


@dataclass(frozen=True)
class Refused:
    line: str
    reason: str


def format_set(channel: int, pascal: float) -> bytes:
    """``SET <ch> <Pa>``: whole pascals (the regulators resolve far less)."""
    return f"SET {int(channel)} {int(round(pascal))}\n".encode("ascii")


VENT = b"VENT\n"
TARE = b"TARE\n"


def _number(text: str) -> float | None:
    try:
        x = float(text)
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def parse_line(line: str, tag: str, n_channels: int, low: float, high: float):
    """One device line -> ``Reading``, ``DeviceError`` or ``Refused``. ``tag``: ``P`` (regulator:
    ``P <ch> <value>``) or ``F`` (scale: ``F <value>``, channel 0); valid values lie in [low, high]."""
    line = line.strip()
    shown = line[:MAX_LINE]
    if len(line) > MAX_LINE:
        return Refused(shown, f"line longer than {MAX_LINE} characters")
    if line.startswith("ERR"):
        return DeviceError(line[3:].strip() or "(no text)")
    parts = line.split()
    want = 3 if tag == "P" else 2
    if not parts or parts[0] != tag or len(parts) != want:
        example = "P <ch> <Pa>" if tag == "P" else "F <newtons>"
        return Refused(shown, f"not '{example}' or 'ERR <text>'")
    if tag == "P" and not parts[1].isdigit():
        return Refused(shown, f"channel {parts[1]!r} is not a number")
    return check_reading(int(parts[1]) if tag == "P" else 0, _number(parts[-1]), n_channels, low, high,
                         shown, parts[-1])


def check_reading(channel: int, value: float | None, n_channels: int, low: float, high: float,
                  shown: str, text: str = ""):
    """A reading of any backend -> ``Reading`` or ``Refused`` (unknown channel, non-finite, outside
    [low, high])."""
    if not 0 <= channel < n_channels:
        return Refused(shown, f"channel {channel} is not one of 0..{n_channels - 1}")
    if value is None or not math.isfinite(value):
        return Refused(shown, f"value {text or value!r} is not a finite number")
    if not low <= value <= high:
        return Refused(shown, f"value {value:g} outside [{low:g}, {high:g}]")
    return Reading(channel, float(value))


class LineSplitter:
    """Bytes in, complete lines out; a partial line beyond ``MAX_LINE`` is dropped and counted
    (a device that floods without newlines cannot grow the buffer)."""

    def __init__(self):
        self.buffer = b""
        self.overlong = 0

    def feed(self, data: bytes) -> list[str]:
        self.buffer += data
        *lines, self.buffer = self.buffer.split(b"\n")
        if len(self.buffer) > MAX_LINE:
            self.buffer, self.overlong = b"", self.overlong + 1
        out = []
        for raw in lines:
            if len(raw) > MAX_LINE + 1:
                self.overlong += 1
                continue
            out.append(raw.decode("ascii", errors="replace"))
        return out
