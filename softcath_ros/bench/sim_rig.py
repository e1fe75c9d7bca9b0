"""The simulated rig (sim_bench_node's core): what the bench would read for a command.

- Regulator: each channel's pressure follows the command as a first-order lag
  (time constant ``regulator_time_constant``), never below zero.
- Gauge: reads the true pressure with a fixed per-channel error drawn once in
  +-``gauge_error`` (0.02 bar, docs/actuator.md) plus white noise.
- Hysteresis (off by default): the actuator bends with a pressure that lags the true one
  through a play of width ``hysteresis_pressure`` (rate-independent backlash: up to half
  the width below it while loading, above it while unloading), so at equal pressure the
  unloading branch bends more.
- Truth: a model rung (closed form by default). ``pressure_shift`` mimics the published
  gap between model and experiment (the model's curve lies on the experiment's when its
  input pressure is shifted by about 25%): the rig bends as the model does at
  (1 - pressure_shift) times the true pressure.
- Angle bench: bending angle theta = |k| l of the mounted sample, read low by the known
  biases: friction on the paper (a fractional under-read) and out-of-plane bending
  (the paper sees the projection, cos of the tilt); plus reading noise.
- Force bench: blocking force (bench.blocking), read low by the same friction, plus a
  scale offset (tared by the analysis with the p = 0 reading) and noise. With the tip
  blocked the angle reads zero (plus noise); on the angle bench the scale reads its offset.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from .blocking import BlockingForce
from ..core.units import PA_PER_BAR


@dataclass
class RigParams:
    regulator_time_constant: float = 0.08   # s
    gauge_error: float = 0.02 * PA_PER_BAR  # Pa, bound of the fixed gauge error
    gauge_noise: float = 200.0              # Pa, std
    pressure_shift: float = 0.25            # truth = model at (1 - shift) p
    friction_underread: float = 0.05        # fraction of angle/force lost to friction
    out_of_plane_tilt: float = 0.15         # rad
    angle_noise: float = math.radians(0.5)  # rad, std of reading the graph paper
    force_noise: float = 0.2e-3             # N, std of the scale
    scale_offset: float = 3.0e-3            # N, scale reading with nothing on it
    hysteresis_pressure: float = 0.0        # Pa, width of the play between true and bending pressure
    seed: int = 0

    @classmethod
    def from_dict(cls, d: dict) -> "RigParams":
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown rig parameters {sorted(unknown)}; known: {sorted(known)}")
        return cls(**d)


@dataclass
class RigReading:
    pressures: np.ndarray  # Pa, gauge
    angle: float           # rad
    force: float           # N


class SimulatedRig:
    def __init__(self, model, params: RigParams | None = None):
        self.model = model
        self.params = params or RigParams()
        self.rng = np.random.default_rng(self.params.seed)
        n = model.n_channels
        self.true_pressures = np.zeros(n)
        self.bending_pressures = np.zeros(n)  # after the hysteresis play
        self.gauge_bias = self.rng.uniform(-self.params.gauge_error, self.params.gauge_error, n)
        self.force_model = BlockingForce(model)
        self.bench = "angle"
        self.length = model.design.length
        self.max_pressure = model.design.max_pressure

    def mount(self, bench: str, length: float) -> None:
        """Put a sample of ``length`` (m) on the ``bench`` ('angle' or 'force')."""
        if bench not in ("angle", "force"):
            raise ValueError(f"bench {bench!r}: expected 'angle' or 'force'")
        if not (isinstance(length, (int, float)) and 0 < length <= 10.0):   # 10 m: a protocol's bound
            raise ValueError(f"sample length {length!r} m must be positive and finite (at most 10 m)")
        self.bench, self.length = bench, float(length)

    def advance(self, dt: float, command) -> None:
        """Regulator: exact first-order step over ``dt`` s towards the (clamped) command."""
        cmd = np.clip(np.asarray(command, dtype=float), 0.0, self.max_pressure)
        a = 1.0 - math.exp(-max(dt, 0.0) / self.params.regulator_time_constant)
        self.true_pressures = self.true_pressures + a * (cmd - self.true_pressures)
        half = 0.5 * self.params.hysteresis_pressure
        self.bending_pressures = np.clip(self.bending_pressures, self.true_pressures - half,
                                         self.true_pressures + half)

    def true_curvature(self) -> np.ndarray:
        state = self.model.evaluate(np.clip(self.bending_pressures, 0.0, None) * (1.0 - self.params.pressure_shift))
        return np.asarray(state.curvature, dtype=float)

    def read(self) -> RigReading:
        p = self.params
        gauge = self.true_pressures + self.gauge_bias + self.rng.normal(0.0, p.gauge_noise, self.true_pressures.shape)
        k = self.true_curvature()
        keep = (1.0 - p.friction_underread)
        if self.bench == "angle":
            angle = float(np.hypot(*k)) * self.length * keep * math.cos(p.out_of_plane_tilt)
            force = 0.0
        else:
            angle = 0.0
            force = float(self.force_model.from_curvature(k, self.length)) * keep
        return RigReading(pressures=gauge,
                          angle=angle + float(self.rng.normal(0.0, p.angle_noise)),
                          force=force + p.scale_offset + float(self.rng.normal(0.0, p.force_noise)))
