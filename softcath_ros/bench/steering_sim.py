"""Steering on the simulated rig without DDS: trajectories, the loop, and how well it tracked.

``SteeringScenario`` says which design, rungs, rig and tracker; ``simulate`` runs the steering
controller (core/steering.py) against the simulated rig (sim_rig: regulator, actuator lag,
truth with pressure shift and material scale, tip tracker with noise, latency and drops) in
simulated time, and returns the time series. ``targets_for`` builds the target paths on the
*true* workspace (what the real actuator can reach), ``metrics`` scores a run. The DDS
command (`softcath steer-sim`) uses the same trajectories and metrics.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..core.allocation import Allocator
from ..core.design import load_design
from ..core.steering import SteeringController, SteeringParams
from ..core.steering_range import steering_allocator, steering_design, steering_model, steering_range
from .sim_rig import RigParams, SimulatedRig, TipTracker, TrackerParams, truth_model

TRAJECTORIES = ("step", "circle")
SETTLE_TOLERANCE = 5e-4      # m: settled = within 0.5 mm
CIRCLE_HZ = 0.2
# Step targets: (direction deg, fraction of the true reach in that direction), one per hold.
STEP_TARGETS = ((-90.0, 0.85), (90.0, 0.85), (0.0, 0.7))
CIRCLE_FRACTION = 0.9        # of the smallest true reach over all directions


def steering_rig_params(**overrides) -> RigParams:
    """The rig the steering benchmarks use: the published 25% pressure shift, material scale 1.2,
    a 10 Hz actuator behind the regulator."""
    values = {"pressure_shift": 0.25, "material_scale": 1.2, "actuator_time_constant": 1.0 / (2 * math.pi * 10)}
    values.update(overrides)
    return RigParams(**values)


@dataclass
class SteeringScenario:
    design: str = "three_sector_5mm"
    model: str = "closed_form"           # the controller's rung
    truth: str = "closed_form"           # the rig's rung
    max_pressure: float | None = None    # Pa, the controller's limit; None: the design's steering range
    rig: RigParams = field(default_factory=steering_rig_params)
    tracker: TrackerParams = field(default_factory=TrackerParams)
    controller: SteeringParams = field(default_factory=SteeringParams)
    output_hz: float = 200.0


class TargetPath:
    """Target tip positions over time for one trajectory (m, softcath_base)."""

    def __init__(self, kind: str, duration: float, tips: np.ndarray, switch_times: np.ndarray):
        self.kind, self.duration = kind, duration
        self._tips, self.switch_times = tips, switch_times

    def __call__(self, t: float) -> np.ndarray:
        if self.kind == "step":
            i = int(np.searchsorted(self.switch_times, t, side="right")) - 1
            return self._tips[max(i, 0)]
        n = len(self._tips)
        x = (t * CIRCLE_HZ % 1.0) * n
        i = int(x)
        w = x - i
        return (1 - w) * self._tips[i % n] + w * self._tips[(i + 1) % n]


def _true_tip(truth_alloc: Allocator, direction: float, fraction: float) -> np.ndarray:
    res = truth_alloc.allocate_bend(direction, 1e3)          # saturates: the reach in that direction
    res = truth_alloc.allocate_bend(direction, fraction * res.extras["max_angle_rad"])
    return truth_alloc.tip_position(res)


def targets_for(kind: str, duration: float, truth_model_, truth_max_pressure: float) -> TargetPath:
    """Targets on the true workspace: the truth allocated within its effective pressure range."""
    if kind not in TRAJECTORIES:
        raise ValueError(f"trajectory {kind!r} is not one of {TRAJECTORIES}")
    alloc = Allocator(truth_model_, max_pressure=truth_max_pressure)
    if kind == "step":
        tips = np.array([_true_tip(alloc, math.radians(d), f) for d, f in STEP_TARGETS])
        return TargetPath(kind, duration, tips, np.arange(len(tips)) * duration / len(tips))
    directions = np.linspace(0.0, 2 * math.pi, 120, endpoint=False)
    reach = min(alloc.allocate_bend(float(d), 1e3).extras["max_angle_rad"] for d in directions)
    tips = []
    for d in np.linspace(0.0, 2 * math.pi, 360, endpoint=False):
        res = alloc.allocate_bend(float(d), CIRCLE_FRACTION * reach)
        tips.append(alloc.tip_position(res))
    return TargetPath(kind, duration, np.array(tips), np.array([0.0]))


@dataclass
class SteeringRun:
    t: np.ndarray            # (N,) s
    target: np.ndarray       # (N, 3) m
    tip: np.ndarray          # (N, 3) m, true
    pressures: np.ndarray    # (N, C) Pa, commanded
    closed: np.ndarray       # (N,) bool, loop closed at that step
    gain: np.ndarray         # (N,) adapted gain
    controller_s: float      # CPU seconds spent in the controller
    measurements: int        # delivered to the controller
    path: TargetPath = None


def build(scenario: SteeringScenario):
    """(controller's allocator, truth model, design with the steering limit) for ``scenario``; both
    rungs on the design as shipped (a surrogate reads its shipped table). No ``max_pressure``: the
    steering range on the controller's rung (core/steering_range.steering_range)."""
    shipped = load_design(scenario.design)
    model = steering_model(scenario.model, shipped)
    limit = steering_range(model) if scenario.max_pressure is None else scenario.max_pressure
    allocator = steering_allocator(model, shipped, limit)
    return allocator, truth_model(scenario.truth, shipped, scenario.rig), steering_design(shipped, limit)


def simulate(scenario: SteeringScenario, trajectory: str, duration: float, built=None) -> SteeringRun:
    """Run the loop for ``duration`` s of simulated time."""
    allocator, truth, design = built or build(scenario)
    path = targets_for(trajectory, duration, truth, (1.0 - scenario.rig.pressure_shift) * design.max_pressure)
    ctrl = SteeringController(allocator, scenario.controller)
    rig = SimulatedRig(truth, scenario.rig)
    tracker = TipTracker(scenario.tracker)
    dt = 1.0 / scenario.output_hz
    sample_dt = 1.0 / scenario.tracker.rate_hz
    n = int(round(duration / dt))
    rows_t, rows_target, rows_tip, rows_p, rows_closed, rows_gain = [], [], [], [], [], []
    next_sample, cpu, delivered = 0.0, 0.0, 0
    command = np.zeros(design.n_channels)
    clock = time.thread_time   # CPU time of this thread: waits for a shared core do not count
    for i in range(n):
        t = i * dt
        rig.advance(dt, command)
        true = rig.true_tip()   # None: the truth's free body has no answer (the tracker sees nothing)
        tip = np.full(3, np.nan) if true is None else true[0]
        if t + 1e-12 >= next_sample:
            if true is not None:
                tracker.capture(t, tip)
            next_sample += sample_dt
        target = path(t)
        t0 = clock()
        ctrl.set_target(target, t)
        for stamp, pos in tracker.due(t):
            ctrl.on_measurement(pos, stamp, t)
            delivered += 1
        out = ctrl.step(t)
        cpu += clock() - t0
        command = out.pressures
        rows_t.append(t)
        rows_target.append(target)
        rows_tip.append(tip)
        rows_p.append(command)
        rows_closed.append(out.state == "closed_loop")
        rows_gain.append(out.gain)
    return SteeringRun(np.array(rows_t), np.array(rows_target), np.array(rows_tip), np.array(rows_p),
                       np.array(rows_closed), np.array(rows_gain), cpu, delivered, path)


def metrics(t, target, tip, kind: str, duration: float, switch_times=None) -> dict:
    """Tip error RMS, steady-state error and settling time (m, s) of one run.

    Steps: steady state = the largest over the holds of the mean error in each hold's last
    quarter; settling = the largest over the steps of the time until the error stays within
    0.5 mm for the rest of the hold (inf if it never does). Circle: steady state = RMS error
    over the second half of the run (after the start-up transient); settling is not defined;
    that error split about the target's direction from the axis (in the base's x-y plane):
    radial (RMS), tangential (RMS, and its mean: positive = ahead of the target, negative =
    lagging it) and axial (z, RMS).
    """
    t = np.asarray(t, dtype=float)
    diff = np.asarray(tip, dtype=float) - np.asarray(target, dtype=float)
    err = np.linalg.norm(diff, axis=1)
    out = {"tip_error_rms_m": float(np.sqrt(np.mean(err ** 2))), "tip_error_max_m": float(err.max())}
    if kind == "circle":
        late = t >= 0.5 * duration
        d, tg = diff[late], np.asarray(target, dtype=float)[late]
        u = tg[:, :2] / np.maximum(np.linalg.norm(tg[:, :2], axis=1), 1e-300)[:, None]
        radial = d[:, 0] * u[:, 0] + d[:, 1] * u[:, 1]
        tangential = d[:, 1] * u[:, 0] - d[:, 0] * u[:, 1]   # along the path's sense (counter-clockwise)

        def rms(x):
            return float(np.sqrt(np.mean(x ** 2)))

        out.update(steady_state_error_m=rms(err[late]), settling_time_s=None, radial_error_rms_m=rms(radial),
                   tangential_error_rms_m=rms(tangential), tangential_error_mean_m=float(tangential.mean()),
                   axial_error_rms_m=rms(d[:, 2]))
        return out
    edges = list(switch_times) + [duration]
    steady, settling = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        hold = (t >= a) & (t < b)
        if not hold.any():
            continue
        th, eh = t[hold], err[hold]
        steady.append(float(eh[th >= a + 0.75 * (b - a)].mean()))
        outside = np.nonzero(eh > SETTLE_TOLERANCE)[0]
        if outside.size == 0:
            settling.append(0.0)
        elif outside[-1] == eh.size - 1:
            settling.append(math.inf)
        else:
            settling.append(float(th[outside[-1] + 1] - a))
    out.update(steady_state_error_m=max(steady), settling_time_s=max(settling),
               steady_state_per_step_m=steady, settling_per_step_s=settling)
    return out


def run_metrics(run: SteeringRun, duration: float) -> dict:
    m = metrics(run.t, run.target, run.tip, run.path.kind, duration, run.path.switch_times)
    m.update(controller_cpu_s=run.controller_s, controller_core_fraction=run.controller_s / duration,
             measurements=run.measurements, final_gain=float(run.gain[-1]))
    return m


__all__ = ["CIRCLE_HZ", "SETTLE_TOLERANCE", "SteeringRun", "SteeringScenario", "TRAJECTORIES", "TargetPath",
           "build", "metrics", "run_metrics", "simulate", "steering_rig_params", "targets_for"]
