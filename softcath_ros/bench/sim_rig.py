"""The simulated rig (sim_bench_node's core): what the bench would read for a command.

- Regulator: each channel's pressure follows the command as a first-order lag
  (time constant ``regulator_time_constant``), never below zero.
- Gauge: reads the true pressure with a fixed per-channel error drawn once in
  +-``gauge_error`` (0.02 bar, docs/actuator.md) plus white noise.
- Hysteresis (off by default): the actuator bends with a pressure that lags the true one
  through a play of width ``hysteresis_pressure`` (rate-independent backlash: up to half
  the width below it while loading, above it while unloading), so at equal pressure the
  unloading branch bends more.
- Actuator (off by default): the body follows the regulated pressure through a further
  first-order lag (``actuator_time_constant``; 16 ms is a 10 Hz bandwidth).
- Truth: a model rung (closed form by default), built by ``truth_model`` for the design with
  its material scaled by ``material_scale`` (1.2: the body 20% stiffer than the model says). ``pressure_shift`` mimics the published
  gap between model and experiment (the model's curve lies on the experiment's when its
  input pressure is shifted by about 25%): the rig bends as the model does at
  (1 - pressure_shift) times the true pressure.
- No reading where the truth has none: where it does not converge, and on the angle bench where
  its free body would pass through itself or the holder below its base (``free_body_answers``).
- Angle bench: bending angle theta = |k| lambda l of the mounted sample (its arc is stretched by
  the axial stretch lambda), read low by the known
  biases: friction on the paper (a fractional under-read) and out-of-plane bending
  (the paper sees the projection, cos of the tilt); plus reading noise.
- Force bench: blocking force (bench.blocking), read low by the same friction, plus a
  scale offset (tared by the analysis with the p = 0 reading) and noise. With the tip
  blocked the angle reads zero (plus noise); on the angle bench the scale reads its offset.
- Noise: drawn from ``seed``; a negative seed (``FRESH_SEED``, sim_bench_node's default) draws a fresh
  one, kept in ``SimulatedRig.params.seed`` so the run says which it was and a rerun with it
  reproduces the noise.
- Tip tracker (``TipTracker``, a camera or an electromagnetic tracker): the true tip position
  at ``rate_hz`` plus white noise, delivered ``latency`` seconds after it was taken, with a
  fraction ``drop_fraction`` of the samples lost.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import replace, dataclass, fields

import numpy as np

from .blocking import BlockingForce
from ..core.prediction import angle_per_length, arc_and_cap, body_reach
from ..core.kinematics import tip_pose_single
from ..core.models import make_model
from ..core.units import PA_PER_BAR

FRESH_SEED = -1   # RigParams.seed: draw a fresh seed (recorded in the rig's parameters)


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
    actuator_time_constant: float = 0.0     # s, body's lag behind the regulated pressure (0: none)
    material_scale: float = 1.0             # truth's moduli = the design's x this (scaled_design)
    seed: int = 0                           # of the noise; FRESH_SEED: a fresh one (module docstring)

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


def truth_model(rung: str, design, params: RigParams, **options):
    """The rung that plays the true actuator: ``design`` with its material scaled by
    ``params.material_scale`` (``options`` go to the rung; a surrogate also answers commands with
    all three channels pressurised beyond its measured common-mode limit, and pair commands where
    its build could not refine the table, as a rig would). A rung
    that answers for pressures alone reads the design's own answers at p / m (exact: every modulus
    scales by m), so no table is built for the scaled design; one that takes loads is built on the
    scaled design."""
    from ..core.calibration_file import CalibratedModel, pressure_only, scaled_design

    if rung == "surrogate":   # a rig answers every pressure: all three channels pressurised too (approximately)
        options = {"answer_common": True, "answer_unresolved": True, **options}
    m = params.material_scale
    if m != 1.0 and pressure_only(rung):
        return CalibratedModel(make_model(rung, design, **options), 0.0, material_scale=m)
    if m != 1.0:
        design = scaled_design(design, m)
    return make_model(rung, design, **options)


class SimulatedRig:
    def __init__(self, model, params: RigParams | None = None):
        """``model``: the truth (``truth_model`` applies the material scale)."""
        self.model = model
        self.params = params or RigParams()
        if self.params.seed < 0:
            self.params = replace(self.params, seed=int(np.random.SeedSequence().entropy % 2**32))
        self.rng = np.random.default_rng(self.params.seed)
        n = model.n_channels
        self.true_pressures = np.zeros(n)
        self.actuated_pressures = np.zeros(n)  # after the actuator's lag
        self.bending_pressures = np.zeros(n)  # after the hysteresis play
        self._state_key, self._state = None, None
        self._free_key, self._free = None, False   # free_body_answers' verdict and what it was for
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
        tau = self.params.actuator_time_constant
        b = 1.0 if tau <= 0 else 1.0 - math.exp(-max(dt, 0.0) / tau)
        self.actuated_pressures = self.actuated_pressures + b * (self.true_pressures - self.actuated_pressures)
        half = 0.5 * self.params.hysteresis_pressure
        self.bending_pressures = np.clip(self.bending_pressures, self.actuated_pressures - half,
                                         self.actuated_pressures + half)

    def true_state(self):
        # read() and the tip tracker both ask for it between two advances: evaluate the truth once
        key = self.bending_pressures.tobytes()
        if key != self._state_key:
            self._state = self.model.evaluate(np.clip(self.bending_pressures, 0.0, None)
                                              * (1.0 - self.params.pressure_shift))
            self._state_key = key
        return self._state

    def true_curvature(self) -> np.ndarray:
        return np.asarray(self.true_state().curvature, dtype=float)

    def free_body_answers(self, state) -> bool:
        """Whether the truth answered and its free body of the mounted length clears itself and the
        holder below its base (core/body_contact.py): beyond that the truth would be a body passing
        through itself, which no rig reads."""
        # asked by every reading and tracker tick: once per truth state (its pressures) and mount
        key = (self._state_key, self.length) if state is self._state else None
        if key is None or self._free_key != key:
            ok = bool(np.all(state.converged))
            if ok:
                arc, cap = arc_and_cap(self.model, self.length)
                ok = body_reach(np.asarray(state.curvature, dtype=float), arc * float(state.axial_stretch), cap,
                                self.model.design.outer_radius) is None
            self._free_key, self._free = key, ok
        return self._free

    def true_tip(self):
        """True tip position (m) and quaternion (x, y, z, w) in softcath_base, for the mounted length;
        None where the free body has no answer (``free_body_answers``)."""
        state = self.true_state()
        if not self.free_body_answers(state):
            return None
        kx, ky = (float(v) for v in state.curvature)
        arc, cap = arc_and_cap(self.model, self.length)
        position, quat = tip_pose_single(kx, ky, arc * float(state.axial_stretch), cap)
        return np.array(position), np.array(quat)

    def read(self) -> RigReading:
        p = self.params
        gauge = self.true_pressures + self.gauge_bias + self.rng.normal(0.0, p.gauge_noise, self.true_pressures.shape)
        state = self.true_state()
        k = np.asarray(state.curvature, dtype=float)
        keep = (1.0 - p.friction_underread)
        # the truth did not answer, or its free body on the angle bench would pass through itself or
        # its holder: no reading, never a made-up one
        if not bool(np.all(state.converged)) or (self.bench == "angle" and not self.free_body_answers(state)):
            k = np.full(2, np.nan)
            state = replace(state, curvature=k, axial_stretch=np.nan)
        if self.bench == "angle":
            angle = float(angle_per_length(state, self.model, self.length)[0]) * self.length * keep * math.cos(p.out_of_plane_tilt)
            force = 0.0
        else:
            angle = 0.0
            force = float(self.force_model.from_curvature(k, self.length)) * keep
        return RigReading(pressures=gauge,
                          angle=angle + float(self.rng.normal(0.0, p.angle_noise)),
                          force=force + p.scale_offset + float(self.rng.normal(0.0, p.force_noise)))


@dataclass
class TrackerParams:
    rate_hz: float = 100.0      # samples per second
    noise: float = 1.0e-4       # m, std per axis
    latency: float = 0.05       # s from taking a sample to delivering it
    drop_fraction: float = 0.2  # fraction of samples lost
    seed: int = 1


class TipTracker:
    """Noisy, late, lossy samples of the true tip position (module docstring)."""

    def __init__(self, params: TrackerParams | None = None):
        self.params = params or TrackerParams()
        if not 0.0 <= self.params.drop_fraction < 1.0:
            raise ValueError(f"drop_fraction {self.params.drop_fraction} must lie in [0, 1)")
        self.rng = np.random.default_rng(self.params.seed)
        self.queue: deque = deque()   # (delivery time, stamp, position)
        self.taken = 0
        self.dropped = 0

    def capture(self, now: float, tip) -> None:
        """Take a sample of the true ``tip`` (m) at ``now`` (s)."""
        self.taken += 1
        if self.rng.random() < self.params.drop_fraction:
            self.dropped += 1
            return
        noisy = np.asarray(tip, dtype=float) + self.rng.normal(0.0, self.params.noise, 3)
        self.queue.append((now + self.params.latency, now, noisy))

    def due(self, now: float) -> list[tuple[float, np.ndarray]]:
        """Samples delivered by ``now``: (stamp, position) in the order taken."""
        out = []
        while self.queue and self.queue[0][0] <= now + 1e-12:
            _, stamp, pos = self.queue.popleft()
            out.append((stamp, pos))
        return out
