"""Closed-loop steering: a tip target and a measured tip pose -> channel pressures.

The loop works in *bend space*: a tip position p = (x, y, z) in softcath_base is written as
the bend vector b = theta (cos phi, sin phi), with the bending angle theta = 2 atan2(rho, z)
and direction phi = atan2(y, x) of the one constant-curvature arc through p (the inverse of
core/kinematics, independent of the arc's length, so of the axial stretch). A tip error maps
into a bend error through that inverse, which is the model's kinematic Jacobian inverted
exactly instead of linearised.

    command = target_bend + integral               (bend vector, rad)
    pressures = Allocator(command) / gain          (the model's minimum-pressure inverse, then
                                                    the adapted pressure gain; 1 unless adaptive)

- Feed-forward: the Allocator on the model rung (core/allocation.py), with a lead of
  ``lead_time`` seconds on its pressures (p + lead_time dp/dt) that cancels the known
  first-order lag of regulator and actuator, so a moving target is not followed one lag
  behind. Steps
  (a change above ``max_lead_step`` between two allocations) get no lead.
- Feedback, mode ``integral``: integral action on the measured bend error (gain fixed at 1).
  Its gain is capped by the delay the loop sees (the measurements' age on arrival plus the
  actuator's lag): gain <= delay_margin / delay, so a slower tracker slows the loop instead of
  making it ring.
- Mode ``adaptive``: the same integral, plus a recursive least-squares estimate (with
  forgetting; Gauss-Newton, the model being nonlinear) of the pressure gain: measured bend =
  the model's bend at gain x the pressures the actuator had when the sample was taken (the
  controller's own first-order estimate of them, looked up at the sample's stamp, so latency
  is accounted for). A pressure shift s and a material scale m are exactly that one gain
  (1 - s) / m on every rung that answers for pressures alone, so the feed-forward is right in
  every direction and the integral only takes what is left. The allocator's limit is lowered
  to gain x max_pressure (gain < 1), so the pressures sent stay within max_pressure and a
  saturated command keeps its direction. docs/steering.md compares the modes.
- Mode ``open_loop``: feed-forward only (measurements are checked and counted, never used).

Safety (stricter than allocation_node, same pieces): every pressure within [0, max_pressure]
(the allocator's limit, by default the design's steering range: ``steering_range.steering_range``; clamped
again at the end), rate limited (RateLimiter), the command
watchdog vents (ramped) when no target comes within ``command_timeout``. A measurement older
than ``measurement_timeout`` on arrival, out of order, non-finite, or farther from the last
accepted one than ``max_tip_speed`` allows (+ ``jump_margin``) is rejected; when none was
accepted for ``measurement_timeout`` the loop falls back to open loop (the integral is
dropped; an adapted gain is kept: it is a calibration, not a correction of the moment) and
says why (``state``/``reason``); it closes again after ``resume_samples`` consistent samples.
Anti-windup: when the command saturates, the integral is recomputed so the command sits on
the reachable set's edge *along the target's direction* (back-calculation), and its
magnitude is bounded by ``max_integral``. Times are seconds of one clock chosen by the caller
(the node: ROS time, which also stamps the measurements; the simulation: simulated time).
"""
from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from dataclasses import dataclass, fields

import numpy as np

from .allocation import Allocator
from .command_shaping import CommandWatchdog, RateLimiter
from .errors import SoftcathError
from .kinematics import curvature_for_tip
from .prediction import arc_and_cap
from .steering_range import SteeringError

MODES = ("integral", "adaptive", "open_loop")
STATES = ("waiting", "closed_loop", "open_loop", "vented")


@dataclass
class SteeringParams:
    mode: str = "adaptive"
    integral_gain: float = 10.0         # 1/s, on the bend error (upper bound: see delay_margin)
    delay_margin: float = 1.0           # integral gain <= this / (measurement age + plant_time_constant)
    forgetting: float = 0.98            # RLS forgetting factor per accepted measurement
    gain_bounds: tuple = (0.2, 5.0)     # the adapted pressure gain stays within these
    gain_resolution: float = 0.01       # relative change of the adapted gain that re-limits the allocator
    lead_time: float = 0.096            # s, lag cancelled on the feed-forward (regulator 80 ms + actuator 16 ms)
    max_lead_step: float = 2000.0       # Pa: a larger change between two allocations is a step (no lead)
    plant_time_constant: float = 0.096  # s, first-order estimate of the actuator's pressure (adaptive regressor)
    max_pressure_rate: float = 2.0e5    # Pa/s
    command_timeout: float = 0.5        # s without a target: vent
    measurement_timeout: float = 0.25   # s: older samples are rejected; none accepted this long: open loop
    max_tip_speed: float = 0.5          # m/s, faster apparent motion is a jump
    jump_margin: float = 0.002          # m, added to the speed allowance (noise)
    resume_samples: int = 3             # consistent samples before the loop closes (again)
    max_integral: float = 1.0           # rad, bound on the integral's magnitude
    allocation_period: float = 0.01     # s, at most one inverse through the model per period

    def __post_init__(self):
        if self.mode not in MODES:
            raise SteeringError(f"steering mode {self.mode!r} is not one of {MODES}")
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and not (math.isfinite(v) and v >= 0):
                raise SteeringError(f"steering {f.name} = {v!r} must be finite and not negative")
        if not 0 < self.forgetting <= 1:
            raise SteeringError(f"steering forgetting {self.forgetting} must lie in (0, 1]")
        if self.measurement_timeout <= 0 or self.command_timeout <= 0 or self.max_pressure_rate <= 0:
            raise SteeringError("steering timeouts and max_pressure_rate must be positive")
        lo, hi = self.gain_bounds
        if not 0 < lo <= 1 <= hi:
            raise SteeringError(f"steering gain_bounds {self.gain_bounds} must satisfy 0 < low <= 1 <= high")


def bend_of_tip(tip, cap: float = 0.0) -> np.ndarray:
    """Bend vector theta (cos phi, sin phi), rad, of the body whose arc from the base, continued by a
    straight ``cap`` (m) along its end tangent, ends at ``tip`` (m)."""
    p = np.asarray(tip, dtype=float).ravel()
    if p[0] == 0.0 and p[1] == 0.0:
        return np.zeros(2)
    inv = curvature_for_tip(p, cap=float(cap))
    return inv.curvature * inv.arc_length


@dataclass
class SteeringStep:
    """One output of the controller."""

    pressures: np.ndarray   # (C,) Pa, rate limited and within [0, max_pressure]
    state: str              # one of STATES
    reason: str             # why open loop / vented / waiting ("" when closed loop)
    saturated: bool         # the command lay beyond the reachable set
    gain: float             # adapted pressure gain (1 unless adaptive)
    integral: np.ndarray    # (2,) rad


@dataclass
class MeasurementCounters:
    accepted: int = 0
    stale: int = 0          # older than measurement_timeout on arrival (or out of order)
    jumps: int = 0          # implausible jump
    invalid: int = 0        # non-finite
    fallbacks: int = 0      # closed loop -> open loop transitions


class SteeringController:
    """Feed-forward through ``allocator`` plus feedback on the measured tip (module docstring)."""

    def __init__(self, allocator: Allocator, params: SteeringParams | None = None):
        self.allocator = allocator
        self.params = params or SteeringParams()
        self.max_pressure = allocator.max_pressure
        self._alloc = allocator           # the inverse in use: limited to gain x max_pressure (gain < 1)
        self._alloc_gain = 1.0            # the pressure gain that inverse and the pressures sent use
        # the arc's reference length (the channelled part) and the straight cap beyond it
        self.arc_length, self.cap = arc_and_cap(allocator.model, allocator.design.length)
        n = allocator.n_channels
        self.limiter = RateLimiter(n, self.params.max_pressure_rate)
        self.watchdog = CommandWatchdog(self.params.command_timeout)
        self.counters = MeasurementCounters()
        self.target_tip: np.ndarray | None = None
        self.target_bend = np.zeros(2)
        self._frame = (1.0, 0.0)           # (cos, sin) of the target's direction
        self.integral_local = np.zeros(2)  # rad, the integral in the target's frame (radial, tangential)
        self.gain = 1.0     # adapted pressure gain: the actuator bends as the model at gain x pressure
        self._info = 1e-6   # RLS information (rad^2 per unit gain^2); a tiny prior avoids 0/0
        self.state = "waiting"
        self.reason = "no target yet"
        self.closed = False               # feedback in use
        self._last_stamp: float | None = None   # stamp of the last accepted measurement
        self._last_tip: np.ndarray | None = None
        self._consistent = 0
        self.measured_bend: np.ndarray | None = None
        self.latency: float | None = None   # s, smoothed age of the accepted measurements on arrival
        self._p_est = np.zeros(n)
        self._history: deque = deque()    # (time, estimated actuator pressures)
        self._targets: deque = deque()    # (time taken up, target bend): the target in force at a stamp
        self._t_prev: float | None = None
        self._pressures = np.zeros(n)       # last allocation, Pa
        self._alloc_time: float | None = None
        self._stretch = 1.0
        self._lead = np.zeros(n)            # lead term on the last allocation, Pa
        self.saturated = False
        self._rest_curvature = np.asarray(allocator.model.evaluate(np.zeros(n)).curvature, dtype=float)

    # ------------------------------------------------------------------ inputs

    def set_target(self, tip, now: float, arrived: float | None = None) -> None:
        """A new tip target (m, softcath_base) that arrived at ``arrived`` (default ``now``); feeds
        the command watchdog from its arrival. One older than ``command_timeout`` is stale:
        SteeringError (command_shaping's freshness rule)."""
        arrived = now if arrived is None else arrived
        if not self.watchdog.fresh(arrived, now):
            raise SteeringError(f"stale tip target dropped: it arrived {now - arrived:.3f} s ago, more than "
                                f"command_timeout {self.params.command_timeout:g} s")
        p = np.asarray(tip, dtype=float).ravel()
        if p.size != 3 or not np.all(np.isfinite(p)):
            raise SteeringError(f"tip target {p.tolist()} m must be three finite numbers")
        if p[2] <= 0 and math.hypot(p[0], p[1]) == 0:
            raise SteeringError(f"tip target {p.tolist()} m: no bending arc ends there (on or behind the base)")
        self.target_tip = p
        self.target_bend = bend_of_tip(p, self.cap)
        theta = math.hypot(*self.target_bend)
        if theta > 1e-4:   # below, the direction is noise: keep the frame
            self._frame = (self.target_bend[0] / theta, self.target_bend[1] / theta)
        self.watchdog.feed(arrived)
        h = self._targets
        while h and h[-1][0] >= now:      # a target replaced within one instant (or a clock step back)
            h.pop()
        h.append((now, self.target_bend))
        while len(h) > 1 and now - h[1][0] > self.params.measurement_timeout:
            h.popleft()                   # keep the one in force at the oldest acceptable stamp

    def target_bend_at(self, stamp: float) -> np.ndarray:
        """The target bend (rad) in force at ``stamp``: a measurement taken then is compared with it,
        not with the newest target, or a target moving at v would read as a lead of v x latency."""
        h = self._targets
        if not h:
            return self.target_bend
        i = bisect_right(h, stamp, key=lambda e: e[0]) - 1
        return h[max(i, 0)][1]

    def on_measurement(self, tip, stamp: float, now: float) -> str:
        """A measured tip position (m) taken at ``stamp``; returns "accepted" or why it was rejected."""
        prm, c = self.params, self.counters
        p = np.asarray(tip, dtype=float).ravel()
        if p.size != 3 or not np.all(np.isfinite(p)) or not math.isfinite(stamp):
            c.invalid += 1
            return "invalid"
        if now - stamp > prm.measurement_timeout or (self._last_stamp is not None and stamp <= self._last_stamp):
            c.stale += 1
            return "stale"
        fresh_reference = self._last_stamp is not None and stamp - self._last_stamp <= prm.measurement_timeout
        if fresh_reference:
            allowed = prm.max_tip_speed * (stamp - self._last_stamp) + prm.jump_margin
            if float(np.linalg.norm(p - self._last_tip)) > allowed:
                c.jumps += 1
                self._consistent = 0
                return "jump"
        else:
            self._consistent = 0     # re-acquiring: this sample is the new reference
        dt = stamp - self._last_stamp if fresh_reference else 0.0
        self._last_stamp, self._last_tip = stamp, p
        self._consistent += 1
        c.accepted += 1
        bend = bend_of_tip(p, self.cap)
        self.measured_bend = bend
        if prm.mode == "open_loop":
            return "accepted"
        if not self.closed and self._consistent >= prm.resume_samples and self.target_tip is not None:
            self.closed = True
        if prm.mode == "adaptive":
            self._adapt(bend, stamp)
        age = now - stamp
        self.latency = age if self.latency is None else 0.9 * self.latency + 0.1 * age
        if self.closed and not self.saturated:
            local = self.integral_local + self.integral_gain() * dt * self._to_local(self.target_bend_at(stamp) - bend)
            norm = math.hypot(*local)
            self.integral_local = local * (prm.max_integral / norm) if norm > prm.max_integral else local
        return "accepted"

    @property
    def integral(self) -> np.ndarray:
        """The integral (rad) in softcath_base: kept in the target's frame, so on a target moving
        round the axis the correction turns with it (the lag on a circle is a constant
        tangential error there) instead of being integrated up anew at each direction."""
        c, s = self._frame
        r, t = self.integral_local
        return np.array([c * r - s * t, s * r + c * t])

    @integral.setter
    def integral(self, world) -> None:
        self.integral_local = self._to_local(np.asarray(world, dtype=float))

    def _to_local(self, v: np.ndarray) -> np.ndarray:
        c, s = self._frame
        return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1]])

    def integral_gain(self) -> float:
        """The integral gain in use (1/s): the set gain, lowered as the measurement's age grows so
        the loop keeps its phase margin (crossover x total delay <= delay_margin rad)."""
        prm = self.params
        delay = (self.latency or 0.0) + prm.plant_time_constant
        return min(prm.integral_gain, prm.delay_margin / delay) if delay > 0 else prm.integral_gain

    def _adapt(self, measured_bend: np.ndarray, stamp: float) -> None:
        """One recursive Gauss-Newton step (RLS on the model linearised in the gain) on
        measured = model bend at gain x the estimated actuator pressures at ``stamp``."""
        h = self._history
        if not h:
            return
        i = bisect_right(h, stamp, key=lambda e: e[0]) - 1
        pressures = h[max(i, 0)][1]
        if not np.any(pressures > 0):
            return                                   # at rest the bend says nothing about the gain
        g, dg = self.gain, 1e-3 * self.gain
        predicted = self.model_bend(g * pressures)
        slope = (self.model_bend((g + dg) * pressures) - predicted) / dg   # rad per unit gain
        if not (np.all(np.isfinite(predicted)) and np.all(np.isfinite(slope))):
            return
        self._info = self.params.forgetting * self._info + float(slope @ slope)
        lo, hi = self.params.gain_bounds
        self.gain = min(max(g + float(slope @ (measured_bend - predicted)) / self._info, lo), hi)

    # ------------------------------------------------------------------ output

    def step(self, now: float) -> SteeringStep:
        """Pressures to send now (call at the output rate)."""
        prm = self.params
        dt = 0.0 if self._t_prev is None else max(now - self._t_prev, 0.0)
        self._t_prev = now
        if self.target_tip is None or self.watchdog.expired(now):
            self._set_state("waiting" if self.target_tip is None else "vented",
                            "no target yet" if self.target_tip is None
                            else f"no target for {prm.command_timeout:g} s: venting")
            self.closed = False
            self.integral = np.zeros(2)
            self.saturated = False
            self._alloc_time = None
            self._lead = np.zeros_like(self._lead)
            return self._emit(np.zeros_like(self.limiter.output), dt, now)
        if self.closed and (self._last_stamp is None or now - self._last_stamp > prm.measurement_timeout):
            self.closed = False
            self.integral = np.zeros(2)
            self.counters.fallbacks += 1
        if prm.mode == "open_loop":
            self._set_state("open_loop", "open-loop mode")
        elif self.closed:
            self._set_state("closed_loop", "")
        elif self._last_stamp is None:
            self._set_state("open_loop", "no measurement yet")
        else:
            age = now - self._last_stamp
            self._set_state("open_loop", f"no valid measurement for {age:.3f} s (timeout "
                                         f"{prm.measurement_timeout:g} s)" if age > prm.measurement_timeout
                            else "re-acquiring the measurement")

        # The pressure gain maps the whole command (target and integral) onto the actuator: the
        # loop's bandwidth is then integral_gain whatever the plant's gain (in adaptive mode).
        command = self.target_bend + self.integral
        if self._alloc_time is None or now - self._alloc_time >= prm.allocation_period - 1e-9:
            self._reallocate(command, now)
        return self._emit(np.clip(self._pressures + self._lead, 0.0, self.max_pressure), dt, now)

    def _reallocate(self, command: np.ndarray, now: float) -> None:
        """New pressures for the bend ``command`` (one inverse through the model, then the gain)."""
        prm = self.params
        self._follow_gain()
        result = self._allocate(command)
        u = self.target_bend / max(math.hypot(*self.target_bend), 1e-300)
        self.saturated = bool(result.saturated)
        if result.saturated:
            # Saturate along the target's direction; back-calculate the integral to that edge.
            result = self._allocate(u * math.hypot(*command))
            edge = np.asarray(result.achieved_curvature, dtype=float) * self.arc_length * result.axial_stretch
            if self.closed:
                self.integral = edge - self.target_bend
        # the allocator's limit is _alloc_gain x max_pressure when that gain is below 1: within max_pressure
        pressures = np.minimum(np.asarray(result.pressures, dtype=float) / self._alloc_gain, self.max_pressure)
        self._stretch = float(result.axial_stretch)
        step = pressures - self._pressures
        if prm.lead_time > 0 and self._alloc_time is not None and now > self._alloc_time and \
                float(np.abs(step).max()) <= prm.max_lead_step:
            self._lead = prm.lead_time * step / (now - self._alloc_time)
        else:
            self._lead = np.zeros_like(pressures)   # a step: the rate limiter shapes it, no lead
        self._pressures, self._alloc_time = pressures, now

    def _follow_gain(self) -> None:
        """Take up the adapted gain once it moved by ``gain_resolution``: the pressures sent are the
        model's divided by it, so below 1 the model's inverse is limited to gain x max_pressure
        (a new allocator: about a millisecond, only while the gain moves)."""
        g = self.gain
        if abs(g - self._alloc_gain) <= self.params.gain_resolution * self._alloc_gain:
            return
        if g >= 1.0:
            alloc = self.allocator
        else:
            try:
                alloc = Allocator(self.allocator.model, max_pressure=g * self.max_pressure)
            except SoftcathError:    # a limit too low to allocate at: keep the last one (the pressures
                return               # sent are clamped to max_pressure all the same)
        self._alloc, self._alloc_gain = alloc, g

    def _allocate(self, bend):
        """Pressures for a bend vector (rad): its curvature on the last axial stretch (the integral
        absorbs the small change of stretch), one allocator call."""
        b = np.asarray(bend, dtype=float)
        res = self._alloc.allocate(b / (self.arc_length * self._stretch))
        if not res.converged or not res.reachable:
            raise SteeringError(f"allocation failed for bend {b.tolist()} rad: {res.message}")
        return res

    def _emit(self, target: np.ndarray, dt: float, now: float) -> SteeringStep:
        out = np.clip(self.limiter.step(target, dt), 0.0, self.max_pressure)
        self.limiter.output = out
        # the controller's estimate of the actuator's pressures, for the adaptive regressor
        tau = self.params.plant_time_constant
        a = 1.0 if tau <= 0 else 1.0 - math.exp(-dt / tau)
        self._p_est = self._p_est + a * (out - self._p_est)
        if self.params.mode == "adaptive":
            self._history.append((now, self._p_est.copy()))
            while self._history and now - self._history[0][0] > 2.0 * self.params.measurement_timeout:
                self._history.popleft()
        return SteeringStep(pressures=out.copy(), state=self.state, reason=self.reason,
                            saturated=self.saturated and self.state != "vented", gain=self.gain,
                            integral=self.integral.copy())

    def model_bend(self, pressures) -> np.ndarray:
        """The model's bend vector (rad) at ``pressures`` (Pa)."""
        state = self.allocator.model.evaluate(np.asarray(pressures, dtype=float))
        k = np.asarray(state.curvature, dtype=float) - self._rest_curvature
        return k * self.arc_length * float(state.axial_stretch)

    def _set_state(self, state: str, reason: str) -> None:
        self.state, self.reason = state, reason


__all__ = ["MODES", "STATES", "MeasurementCounters", "SteeringController", "SteeringError", "SteeringParams",
           "SteeringStep", "bend_of_tip"]
