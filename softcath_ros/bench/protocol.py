"""Test protocols (shipped in config/protocols/) and the engine that steps through them.

A protocol is a pressure staircase (0 -> max -> 0 by default), repeated over trials,
on one or more benches (angle, blocking force), each with its mounted samples
(actuators of given length). For a multi-channel design it drives each listed
channel alone, or bends in listed directions through the allocator, whose levels
are then fractions of the reachable curvature in that direction.

``ProtocolRunner`` is a clock-driven state machine with no I/O: each update gets the
time and the measured pressures and returns the events to publish (step start,
settled, sample, step end, protocol end). A step is settled when every channel's
measurement has stayed within ``settle.tolerance`` of the command for ``settle.hold``
seconds and at least ``dwell`` seconds have passed; after ``settle.timeout`` it is
sampled anyway and flagged unsettled. Then ``samples_per_step`` readings are taken
``sample_period`` apart.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import yaml

from ..core.errors import SoftcathError, shown
from ..core.checks import NAME_RULE, finite_number, is_file_name
from ..core.plausibility import PLAUSIBLE_PRESSURE, pressure_guess
from ..core.yaml_io import load_yaml_file

BENCHES = ("angle", "force")


class ProtocolError(SoftcathError):
    def __init__(self, field_name: str, value, reason: str):
        super().__init__(f"protocol field '{field_name}' = {shown(value)}: {reason}")


@dataclass(frozen=True)
class BenchSample:
    name: str
    length: float  # m


@dataclass(frozen=True)
class BenchSpec:
    kind: str                      # "angle" | "force"
    samples: tuple[BenchSample, ...]


@dataclass(frozen=True)
class Protocol:
    name: str
    description: str
    design: str | None
    drive: str                     # "channels" | "direction"
    channels: tuple[int, ...]      # drive: channels
    directions_deg: tuple[float, ...]  # drive: direction
    levels: tuple[float, ...]      # Pa (channels) or fraction of reach (direction), loading order
    down: bool
    trials: int
    dwell: float
    settle_tolerance: float        # Pa, peak-to-peak band of the measurement over the hold time
    settle_max_offset: float       # Pa, largest |measured - command| accepted as arrived
    settle_hold: float             # s
    settle_timeout: float          # s
    samples_per_step: int
    sample_period: float           # s
    benches: tuple[BenchSpec, ...]
    source: dict = field(default_factory=dict, compare=False)

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.source, sort_keys=False)


@dataclass(frozen=True)
class Step:
    index: int
    bench: str
    sample: BenchSample
    trial: int
    phase: str                     # "loading" | "unloading"
    drive: str                     # "channel 0" | "direction 120.0 deg"
    level: float                   # Pa or fraction
    pressures: tuple[float, ...]   # Pa, commanded per channel (by direction: the allocator's answer)
    bend: tuple[float, float] | None = None  # 1/m, curvature requested (drive 'direction' only)

    def describe(self) -> dict:
        d = {"step": self.index, "bench": self.bench, "sample_name": self.sample.name,
             "sample_length_m": self.sample.length, "trial": self.trial, "phase": self.phase,
             "drive": self.drive, "level": self.level, "pressure_cmd_pa": list(self.pressures)}
        if self.bend is not None:
            d["bend_cmd_per_m"] = list(self.bend)
        return d


# --------------------------------------------------------------------------- loading

def load_protocol(name_or_path) -> Protocol:
    """A protocol file, or the name of a shipped protocol."""
    from ..resources import ResourceNotFound, find

    try:
        p = find("protocol", name_or_path)
    except ResourceNotFound as exc:
        raise ProtocolError("protocol", str(name_or_path), f"no such file or shipped protocol; shipped: {exc.known}") from None
    return protocol_from_dict(load_yaml_file(p))


# Bounds on the size of a protocol: a run is held in memory as its list of steps and takes
# minutes per hundred steps, so a typo (a step of 0.001 bar, trials: 1e8) is refused here.
MAX_STEPS = 10_000
MAX_LEVELS = 500
MAX_TRIALS = 100
MAX_SAMPLES_PER_STEP = 1000
MAX_LIST = 64            # channels, directions, benches, samples per bench
MAX_SECONDS = 600.0      # dwell, settle hold and timeout, sample period


def _num(d: dict, key: str, default=None, *, positive=False, nonneg=False, maximum=None, where="") -> float:
    name = f"{where}{key}"
    if key not in d:
        if default is None:
            raise ProtocolError(name, None, "missing required field")
        return float(default)
    v = finite_number(d[key])
    if v is None:
        raise ProtocolError(name, d[key], "must be a finite number")
    if positive and v <= 0:
        raise ProtocolError(name, v, "must be positive")
    if nonneg and v < 0:
        raise ProtocolError(name, v, "must not be negative")
    if maximum is not None and v > maximum:
        raise ProtocolError(name, v, f"must not exceed {maximum:g}")
    return float(v)


def _int(d: dict, key: str, default: int, lo: int, hi: int) -> int:
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise ProtocolError(key, v, f"must be an integer in [{lo}, {hi}]")
    return v


def _list(d: dict, key: str, default, where: str = "") -> list:
    v = d.get(key, default)
    if not isinstance(v, list) or len(v) > MAX_LIST:
        raise ProtocolError(f"{where}{key}", v, f"must be a list of at most {MAX_LIST} entries")
    return v


def _mapping(d: dict, key: str, allowed: set, where: str = "") -> dict:
    v = d.get(key, {})
    if not isinstance(v, dict):
        raise ProtocolError(f"{where}{key}", v, f"must be a mapping with keys from {sorted(allowed)}")
    for k in v:
        if k not in allowed:
            raise ProtocolError(f"{where}{key}.{k}", v[k], f"unknown key; allowed: {sorted(allowed)}")
    return v


_KEYS = {"name", "description", "design", "drive", "channels", "directions_deg", "staircase", "trials",
         "dwell", "settle", "samples_per_step", "sample_period", "benches"}


def _benches(data: dict) -> list[BenchSpec]:
    """The protocol's ``benches``: each a kind with its samples (name, length), checked."""
    benches_raw = data.get("benches")
    if not isinstance(benches_raw, list) or not benches_raw or len(benches_raw) > MAX_LIST:
        raise ProtocolError("benches", benches_raw, f"must be a non-empty list of at most {MAX_LIST} {{kind, samples}}")
    benches = []
    for i, b in enumerate(benches_raw):
        where = f"benches[{i}]"
        if not isinstance(b, dict) or b.get("kind") not in BENCHES:
            raise ProtocolError(f"{where}.kind", b.get("kind") if isinstance(b, dict) else b,
                                f"must be one of {BENCHES}")
        for k in b:
            if k not in ("kind", "samples"):
                raise ProtocolError(f"{where}.{k}", b[k], "unknown key; allowed: ['kind', 'samples']")
        samples = b.get("samples")
        if not isinstance(samples, list) or not samples or len(samples) > MAX_LIST:
            raise ProtocolError(f"{where}.samples", samples,
                                f"must be a non-empty list of at most {MAX_LIST} {{name, length}}")
        specs = []
        for j, s in enumerate(samples):
            at = f"{where}.samples[{j}]"
            if not isinstance(s, dict) or set(s) - {"name", "length"}:
                raise ProtocolError(at, s, "must be a mapping {name, length}")
            sample_name = s.get("name", f"sample{j}")
            if not isinstance(sample_name, str) or not sample_name:
                raise ProtocolError(f"{at}.name", sample_name, "must be a non-empty string")
            specs.append(BenchSample(sample_name, _num(s, "length", positive=True, maximum=10.0, where=f"{at}.")))
        benches.append(BenchSpec(b["kind"], tuple(specs)))
    return benches


def protocol_from_dict(data) -> Protocol:
    """Validate a protocol mapping: every field's type and range (``ProtocolError`` names field,
    value and reason) and the size of the run (at most ``MAX_STEPS`` steps)."""
    if not isinstance(data, dict):
        raise ProtocolError("protocol", data, "must be a mapping")
    for k in data:
        if k not in _KEYS:
            raise ProtocolError(k, data[k], f"unknown field; known: {sorted(_KEYS)}")
    name = data.get("name")
    if not is_file_name(name):
        raise ProtocolError("name", name, NAME_RULE)
    for key in ("description", "design"):
        if data.get(key) is not None and not isinstance(data[key], str):
            raise ProtocolError(key, data[key], "must be a string")
    drive = data.get("drive", "channels")
    if drive not in ("channels", "direction"):
        raise ProtocolError("drive", drive, "must be 'channels' or 'direction'")
    channels = tuple(_list(data, "channels", [0]))
    if drive == "channels" and (not channels or not all(
            isinstance(c, int) and not isinstance(c, bool) and 0 <= c < MAX_LIST for c in channels)):
        raise ProtocolError("channels", list(channels),
                            f"must be a non-empty list of channel indices (0-{MAX_LIST - 1})")
    directions = tuple(_num({f"directions_deg[{i}]": v}, f"directions_deg[{i}]")
                       for i, v in enumerate(_list(data, "directions_deg", [])))
    if drive == "direction" and not directions:
        raise ProtocolError("directions_deg", [], "drive 'direction' needs at least one direction")

    sc = data.get("staircase")
    if not isinstance(sc, dict):
        raise ProtocolError("staircase", sc, "must be a mapping with levels, or max and step")
    _mapping(data, "staircase", {"levels", "max", "step", "down"})
    if "levels" in sc:
        levels = sc["levels"]
        if not isinstance(levels, list) or not levels or len(levels) > MAX_LEVELS:
            raise ProtocolError("staircase.levels", levels, f"must be a non-empty list of at most {MAX_LEVELS} levels")
        levels = tuple(_num({f"levels[{i}]": v}, f"levels[{i}]", where="staircase.") for i, v in enumerate(levels))
    else:
        top = _num(sc, "max", positive=True, where="staircase.")
        step = _num(sc, "step", positive=True, where="staircase.")
        if top / step > MAX_LEVELS:
            raise ProtocolError("staircase.step", step, f"gives {top / step:.3g} levels up to max {top:g}; "
                                f"at most {MAX_LEVELS}")
        n = int(round(top / step))
        if abs(n * step - top) > 1e-9 * top:
            raise ProtocolError("staircase.step", step, f"does not divide max {top}")
        levels = tuple(i * step for i in range(n + 1))
    if any(b < a for a, b in zip(levels, levels[1:])) or levels[0] < 0:
        raise ProtocolError("staircase.levels", list(levels), "must be non-negative and increasing")
    if drive == "direction" and levels[-1] > 1.0:
        raise ProtocolError("staircase.levels", list(levels),
                            "for drive 'direction' levels are fractions of the reachable curvature (<= 1)")
    if drive != "direction" and 0 < levels[-1] < PLAUSIBLE_PRESSURE[0]:   # a staircase in bar given as Pa
        raise ProtocolError("staircase.levels", list(levels), f"top level {levels[-1]:g} Pa is implausible (below "
                            f"{PLAUSIBLE_PRESSURE[0]:g} Pa): protocol pressures are in pascals; "
                            f"{pressure_guess(levels[-1])}?")
    down = sc.get("down", True)
    if not isinstance(down, bool):
        raise ProtocolError("staircase.down", down, "must be true or false")

    settle = _mapping(data, "settle", {"tolerance", "max_offset", "hold", "timeout"})
    benches = _benches(data)
    trials = _int(data, "trials", 1, 1, MAX_TRIALS)
    n_samples = _int(data, "samples_per_step", 3, 1, MAX_SAMPLES_PER_STEP)
    n_drives = len(channels) if drive == "channels" else len(directions)
    n_steps = sum(len(b.samples) for b in benches) * n_drives * trials * (2 * len(levels) - 1 if down else len(levels))
    if n_steps > MAX_STEPS:
        raise ProtocolError("protocol", name, f"expands to {n_steps} steps; at most {MAX_STEPS} (fewer levels, "
                            "trials, samples or benches)")
    return Protocol(
        name=name, description=str(data.get("description") or ""), design=data.get("design"), drive=drive,
        channels=channels, directions_deg=directions, levels=levels, down=down,
        trials=trials, dwell=_num(data, "dwell", 0.5, nonneg=True, maximum=MAX_SECONDS),
        settle_tolerance=_num(settle, "tolerance", 1000.0, positive=True, where="settle."),
        settle_max_offset=_num(settle, "max_offset", 3000.0, positive=True, where="settle."),
        settle_hold=_num(settle, "hold", 0.2, nonneg=True, maximum=MAX_SECONDS, where="settle."),
        settle_timeout=_num(settle, "timeout", 5.0, positive=True, maximum=MAX_SECONDS, where="settle."),
        samples_per_step=n_samples,
        sample_period=_num(data, "sample_period", 0.05, positive=True, maximum=MAX_SECONDS),
        benches=tuple(benches), source=data)


# --------------------------------------------------------------------------- expansion

def design_steps(protocol: Protocol, design, model_name: str = "surrogate") -> list[Step]:
    """Every step of ``protocol`` on ``design``; a protocol by direction is allocated on rung
    ``model_name``, as allocation_node allocates it (bench_node and `softcath characterise`)."""
    allocator = None
    if protocol.drive == "direction":
        from ..core.allocation import Allocator
        from ..core.models import make_model

        allocator = Allocator(make_model(model_name, design))
    return expand_steps(protocol, design.n_channels, design.max_pressure, allocator)


def expand_steps(protocol: Protocol, n_channels: int, max_pressure: float, allocator=None) -> list[Step]:
    """Every step in execution order. ``allocator`` (core.allocation.Allocator) is needed for
    drive 'direction'; pressures beyond ``max_pressure`` are refused, never clipped silently."""
    drives: list[tuple[str, callable, callable]] = []  # name, level -> pressures, level -> bend or None
    if protocol.drive == "channels":
        for c in protocol.channels:
            if c >= n_channels:
                raise ProtocolError("channels", list(protocol.channels),
                                    f"channel {c} does not exist (design has {n_channels})")

            def unit(level, c=c):
                p = np.zeros(n_channels)
                p[c] = level
                return p
            drives.append((f"channel {c}", unit, lambda level: None))
    else:
        if allocator is None:
            raise ProtocolError("drive", "direction", "needs the allocator (softcath_ros.core.allocation)")
        for deg in protocol.directions_deg:
            phi = math.radians(deg)
            kmax = allocator.max_curvature(phi)
            if kmax <= 0:
                raise ProtocolError("directions_deg", deg, "the design cannot bend in this direction")

            def bend(frac, phi=phi, kmax=kmax):
                return (frac * kmax * math.cos(phi), frac * kmax * math.sin(phi))

            def by_direction(frac, bend=bend):
                if frac == 0:
                    return np.zeros(n_channels)
                return np.asarray(allocator.allocate(bend(frac)).pressures, dtype=float)
            drives.append((f"direction {deg:g} deg", by_direction, bend))

    up = list(protocol.levels)
    sequence = [(lv, "loading") for lv in up]
    if protocol.down:
        sequence += [(lv, "unloading") for lv in reversed(up[:-1])]
    steps: list[Step] = []
    for bench in protocol.benches:
        for sample in bench.samples:
            for drive_name, to_pressures, to_bend in drives:
                for trial in range(protocol.trials):
                    for level, phase in sequence:
                        p = to_pressures(level)
                        if np.any(p > max_pressure * (1 + 1e-9)) or np.any(p < 0):
                            raise ProtocolError("staircase", level, f"needs pressures {p.tolist()} Pa outside "
                                                f"[0, max_pressure {max_pressure:g}]")
                        k = to_bend(level)
                        steps.append(Step(len(steps), bench.kind, sample, trial, phase, drive_name, float(level),
                                          tuple(float(x) for x in p),
                                          None if k is None else (float(k[0]), float(k[1]))))
    return steps


# --------------------------------------------------------------------------- engine

class ProtocolRunner:
    """Steps through ``steps`` against a clock; see the module docstring for the rules."""

    def __init__(self, protocol: Protocol, steps: list[Step]):
        if not steps:
            raise ProtocolError("steps", [], "protocol expands to no steps")
        self.protocol = protocol
        self.steps = steps
        self.i = -1
        self.state = "idle"
        self.done = False
        self._t_step = 0.0
        self._window: deque = deque()  # (t, measured) over the last hold seconds
        self._t_sampling = 0.0
        self._n_taken = 0
        self.settled_flags: list[bool] = []

    @property
    def step(self) -> Step | None:
        return self.steps[self.i] if 0 <= self.i < len(self.steps) else None

    @property
    def command(self) -> np.ndarray:
        s = self.step
        return np.zeros(len(self.steps[0].pressures)) if s is None else np.asarray(s.pressures)

    @property
    def bend_command(self) -> tuple[float, float]:
        """Curvature requested (1/m) for drive 'direction'; (0, 0) before and after the steps."""
        s = self.step
        return (0.0, 0.0) if s is None or s.bend is None else s.bend

    def _event(self, name: str, t: float, **extra) -> dict:
        ev = {"event": name, "t": t}
        if self.step is not None:
            ev.update(self.step.describe())
        ev.update(extra)
        return ev

    def start(self, t: float) -> list[dict]:
        events = [{"event": "protocol_start", "t": t, "protocol": self.protocol.name, "n_steps": len(self.steps)}]
        return events + self._begin(0, t)

    def _begin(self, i: int, t: float) -> list[dict]:
        self.i = i
        if i >= len(self.steps):
            self.done = True
            self.state = "done"
            return [{"event": "protocol_end", "t": t, "n_steps": len(self.steps),
                     "unsettled_steps": [k for k, ok in enumerate(self.settled_flags) if not ok]}]
        self.state = "settling"
        self._t_step = t
        self._window.clear()
        return [self._event("step_start", t)]

    def update(self, t: float, measured) -> list[dict]:
        """Advance to time ``t`` (s) with the latest measured pressures (Pa, or None if none yet)."""
        if self.state in ("idle", "done"):
            return []
        events: list[dict] = []
        p = self.protocol
        if self.state == "settling":
            elapsed = t - self._t_step
            settled = False
            if measured is not None:
                m = np.asarray(measured, dtype=float)
                w = self._window
                w.append((t, m))
                while len(w) > 1 and w[1][0] <= t - p.settle_hold:
                    w.popleft()
                values = np.array([x for _, x in w])
                stable = t - w[0][0] >= p.settle_hold and np.all(np.ptp(values, axis=0) <= p.settle_tolerance)
                arrived = np.all(np.abs(m - self.command) <= p.settle_max_offset)
                settled = bool(stable and arrived and elapsed >= p.dwell)
            if settled or elapsed >= p.settle_timeout:
                self.settled_flags.append(bool(settled))
                events.append(self._event("settled", t, settled=bool(settled), settle_time_s=elapsed))
                self.state = "sampling"
                self._t_sampling = t
                self._n_taken = 0
        if self.state == "sampling":
            while self._n_taken < p.samples_per_step and t >= self._t_sampling + self._n_taken * p.sample_period:
                events.append(self._event("sample", t, sample=self._n_taken))
                self._n_taken += 1
            if self._n_taken >= p.samples_per_step:
                events.append(self._event("step_end", t))
                events += self._begin(self.i + 1, t)
        return events
