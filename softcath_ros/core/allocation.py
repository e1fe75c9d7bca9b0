"""Pressure allocation: a desired bend -> channel pressures, the inverse of a ``BendModel``.

Minimum-pressure strategy (docs/actuator.md "Optimised designs"): each channel alone bends
the body in one fixed direction (its *bending direction*). Neighbouring bending
directions less than 180 degrees apart span a *sector*; a request whose direction
lies in a sector is met by that sector's two channels alone, never by all three,
because a pressure common to all channels only stiffens and lengthens the body.
On a sector's edge one of the two pressures is zero, so the pressures are
continuous as the direction sweeps the circle.

The pressures come from the model's own forward map: a 2 x 2 Newton solve on the two
active channels (finite-difference Jacobian from ``model.evaluate``), so the
nonlinearity and the two-channel coupling of the higher rungs are honoured. A rung
that is linear in pressure (it exposes ``curvature_per_pa``, the 2 x C matrix, like
the closed form) is inverted exactly in one shot, in plain floats for speed.

Reachable set: for each direction, the largest curvature with every pressure in
[0, max_pressure], where max_pressure is kept where the rung answers each channel alone and
below the pressure at which a channel alone bends most (core/channel_limits.py). Where Newton
from its usual start fails near a fold of the rung's map, the answer is followed from rest along
the request's direction (the branch of least pressure). A request beyond it saturates *along the requested direction*
(the larger active pressure at max_pressure) and says so. A direction no sector
covers (a 1-channel design asked to bend sideways) is reported unreachable, never
approximated, unless it lies within ``direction_tolerance_deg`` of a channel's own
bending direction.

Near zero the direction of a request is noise: below ``deadband`` (1/m) the
pressures are zero and the active sector is kept; an angular hysteresis keeps the
current sector while the direction strays at most ``hysteresis_deg`` past its edge
(the stray part is dropped: direction error <= hysteresis_deg, by design below the
0.5 degree accuracy target).
"""
from __future__ import annotations

import math

import numpy as np

from .allocation_result import Allocation, ReachableSet
from .bend_targets import BendTargets
from .channel_limits import answered_limit, peak_limit
from .errors import AllocationError, ModelError
from .models.base import BendModel
from .pair_inverse import PairInverse, Sector, brentq
from .plausibility import PLAUSIBLE_PRESSURE, pressure_guess
from .prediction import arc_and_cap, body_reach

TWO_PI = 2.0 * math.pi
# A request counts as beyond reach only past this relative margin, so the boundary itself
# (kappa == max curvature up to rounding) is reachable and not flagged saturated.
_SATURATION_RTOL = 1e-9


# bisections of a request's scale for the largest bend that keeps the body clear of itself and its
# shaft (each one allocation; 2^-24 of the request)
CLEAR_BISECTIONS = 24


def _wrap(angle: float) -> float:
    """Angle in [0, 2 pi)."""
    return angle % TWO_PI


def lowered_max_pressure(max_pressure: float, design) -> float:
    """A pressure limit (Pa) a user lowers the design's to: positive, finite, at most the design's
    max_pressure, and not a limit in bar given as Pa; else a one-line AllocationError."""
    top = float(design.max_pressure)
    if not (math.isfinite(max_pressure) and 0 < max_pressure <= top):
        raise AllocationError(f"max_pressure {max_pressure:g} Pa must be positive and at most design "
                              f"'{design.name}''s {top:g} Pa")
    if max_pressure < PLAUSIBLE_PRESSURE[0]:
        raise AllocationError(f"max_pressure {max_pressure:g} Pa is implausible (below {PLAUSIBLE_PRESSURE[0]:g} Pa): "
                              f"it is in pascals; {pressure_guess(max_pressure)}?")
    return float(max_pressure)


class Allocator(PairInverse, BendTargets):
    """Inverse of one model for one design; keeps the active sector between calls (hysteresis)."""

    def __init__(self, model: BendModel, *, max_pressure: float | None = None, deadband: float | None = None,
                 hysteresis_deg: float = 0.2, direction_tolerance_deg: float = 0.5, rtol: float = 1e-6,
                 accept_rtol: float = 2e-3, max_iterations: int = 25, fd_step: float = 1e-4):
        """``max_pressure`` (Pa) may lower the design's limit (never raise it), e.g. to stay inside
        the pressure range where a rung converges. The limit is also kept within the rung's own
        ``pressure_range`` (a surrogate table ends where its source stopped converging)."""
        self.model = model
        self.design = model.design
        self.n_channels = model.n_channels
        self.max_pressure = float(self.design.max_pressure)
        if max_pressure is not None:
            self.max_pressure = lowered_max_pressure(max_pressure, self.design)
        self.max_pressure = min(self.max_pressure, float(model.pressure_range[1]))
        self.hysteresis = math.radians(hysteresis_deg)
        self.direction_tolerance = math.radians(direction_tolerance_deg)
        # Newton aims at rtol (relative curvature residual). A rung solved iteratively is only
        # accurate to its own tolerance, and on a sector edge a channel's direction may drift a
        # little with pressure (mesh asymmetry): there the best point found is accepted if within
        # accept_rtol (2e-3: 0.11 degree / 0.2%, inside the 0.5 degree / 1% target) and said so.
        self.rtol = rtol
        self.accept_rtol = accept_rtol
        self.max_iterations = max_iterations

        # a rung linear in pressure declares it (closed form): its gain inverts exactly
        self.linear = model.info.linear_gain
        # a rung with pair tables declares their exact local Jacobian (the surrogate): one call per step
        self._pair_jac = model.info.pair_jacobian and self.n_channels == 3
        self._stretch_per_pa = [float(v) for v in model.stretch_per_pa] if self.linear else None
        if self.linear:
            self._g = [[float(v) for v in row] for row in np.asarray(model.curvature_per_pa)]

        # Each channel alone at max_pressure: its bending direction and its reach. The limit is first
        # kept where the rung answers every channel alone (a table ends where its source failed; said in
        # ``limited_by_rung``), then below the smallest pressure at which a channel alone bends most
        # (said in ``limited_by_peak``): never a command the rung cannot answer, nor one past a peak.
        rest = model.evaluate(np.zeros(self.n_channels))
        self._rest_curvature = np.asarray(rest.curvature, dtype=float)
        self._rest_stretch = float(rest.axial_stretch)
        self.limited_by_rung = self._limit_to_the_rung(model)
        self.limited_by_peak = self._limit_to_the_peak(model)
        single = model.evaluate(np.eye(self.n_channels) * self.max_pressure)
        self.fd_step = fd_step * self.max_pressure  # Pa, finite-difference step for the Jacobian
        k1 = np.asarray(single.curvature, dtype=float) - self._rest_curvature
        mags = np.hypot(k1[:, 0], k1[:, 1])
        steerable = mags > 1e-9 * max(float(mags.max()), 1e-300)
        self.channel_directions = np.where(steerable, np.arctan2(k1[:, 1], k1[:, 0]) % TWO_PI, np.nan)
        self.channel_max_curvature = np.where(steerable, mags, 0.0)
        self._secant = k1 / self.max_pressure  # (C, 2) curvature per Pa at max_pressure, per channel
        self.deadband = 1e-3 * float(mags.max()) if deadband is None else float(deadband)

        order = [i for i in np.argsort(np.nan_to_num(self.channel_directions, nan=np.inf)) if steerable[i]]
        self._sectors: list[Sector] = []
        for j, a in enumerate(order):
            if len(order) < 2:
                break
            b = order[(j + 1) % len(order)]
            gap = _wrap(self.channel_directions[b] - self.channel_directions[a])
            if 1e-9 < gap < math.pi - 1e-9:
                m = np.column_stack([self._secant[a], self._secant[b]])
                inv = np.linalg.inv(m)
                self._sectors.append(Sector(int(a), int(b), float(self.channel_directions[a]), float(gap),
                                             tuple(float(v) for v in inv.ravel())))
        self._current: Sector | None = None
        # the last solution inside reach on the nonlinear path (sector, pair pressures, curvature
        # vector): a stream of nearby requests starts Newton there (2-3 steps instead of ~6)
        self._warm = None

    def _limit_to_the_rung(self, model) -> str:
        """Lower max_pressure to the largest pressure the rung answers every channel alone at; the
        one-line reason, or "" when it answers them at max_pressure."""
        single = model.evaluate(np.eye(self.n_channels) * self.max_pressure)
        if np.all(single.converged):
            return ""
        reach = answered_limit(model, self.max_pressure)
        if reach <= 0.05 * self.max_pressure:
            raise ModelError(f"allocation needs model '{model.name}' at max_pressure {self.max_pressure:g} Pa on "
                             f"each channel alone, but it did not converge ({single.message}); allocate with a "
                             "lower max_pressure inside the rung's range")
        said = (f"model '{model.name}' answers each channel alone only up to {reach:.0f} Pa "
                f"(not {self.max_pressure:g} Pa): allocating up to {reach:.0f} Pa")
        self.max_pressure = reach
        return said

    def _limit_to_the_peak(self, model) -> str:
        """Lower max_pressure to where a channel alone bends most, if that is below it; the one-line
        reason, or "" when every channel bends more all the way to max_pressure."""
        peak = peak_limit(model, self.max_pressure, self._rest_curvature)
        if peak is None:
            return ""
        pressure, channel, bend = peak
        said = (f"model '{model.name}': channel {channel} alone bends most at {pressure:.0f} Pa ({bend:.1f} 1/m) "
                f"and less beyond (not up to {self.max_pressure:g} Pa): allocating up to {pressure:.0f} Pa")
        self.max_pressure = pressure
        return said

    # ------------------------------------------------------------------ public API

    def reset(self) -> None:
        """Forget the active sector (hysteresis state) and the last solution."""
        self._current = None
        self._warm = None

    def allocate(self, curvature, length: float | None = None) -> Allocation:
        """Pressures for the curvature vector ``curvature`` = (kx, ky), 1/m. A bend that would take the
        body of ``length`` (m, default the design's) through itself or its shaft is not reachable
        (core/body_contact.py: no model predicts that state)."""
        result = self._allocate(curvature)
        arc, cap = arc_and_cap(self.model, self.design.length if length is None else float(length))

        def reaches(r: Allocation):
            if not (r.reachable and r.converged and r.active_channels):
                return None
            return body_reach(r.achieved_curvature, arc * r.axial_stretch, cap, self.design.outer_radius)

        reached = reaches(result)
        if reached is None:
            return result
        # saturate where the body just clears: bisect the request's scale (the achieved bend grows with it)
        requested = np.asarray(result.requested_curvature, dtype=float)
        lo, hi = 0.0, min(1.0, math.hypot(*result.achieved_curvature) / math.hypot(*requested))
        best = self._zero(tuple(requested), "")
        for _ in range(CLEAR_BISECTIONS):
            mid = 0.5 * (lo + hi)
            trial = self._allocate(mid * requested)
            if not (trial.reachable and trial.converged):
                hi = mid
            else:
                hit = reaches(trial)
                if hit is None:
                    lo, best = mid, trial
                else:
                    hi, reached = mid, hit   # what the body reaches just beyond the limit
        best.requested_curvature = requested
        best.saturated = True
        best.max_curvature = float(math.hypot(*best.achieved_curvature))
        best.message = f"limited to the largest bend this way that clears the body: beyond it {reached.describe()}"
        return best

    def _allocate(self, curvature) -> Allocation:
        kx, ky = float(curvature[0]), float(curvature[1])
        if not (math.isfinite(kx) and math.isfinite(ky)):
            raise AllocationError(f"curvature ({kx}, {ky}) 1/m is not finite")
        kappa = math.hypot(kx, ky)
        if kappa <= self.deadband:
            return self._zero((kx, ky), "inside the deadband" if kappa > 0 else "")
        phi = _wrap(math.atan2(ky, kx))
        sector, beta = self._select(phi)
        if sector is None:
            lone = self._lone_channel(phi)
            if lone is None:
                return self._unreachable((kx, ky), phi)
            return self._single(lone, (kx, ky), kappa)
        # Direction actually steered (snapped onto the sector when inside the hysteresis band).
        phi_s = sector.start + beta
        ux, uy = math.cos(phi_s), math.sin(phi_s)
        if self.linear:
            return self._pair_linear(sector, (kx, ky), kappa, ux, uy)
        return self._pair_nonlinear(sector, (kx, ky), kappa, ux, uy)

    def max_curvature(self, direction: float) -> float:
        """Reachable-set radius (1/m) in ``direction`` (rad); 0 where the direction is unreachable."""
        phi = _wrap(direction)
        sector, beta = self._select(phi, stateless=True)
        if sector is None:
            lone = self._lone_channel(phi)
            return 0.0 if lone is None else float(self.channel_max_curvature[lone])
        ux, uy = math.cos(sector.start + beta), math.sin(sector.start + beta)
        if self.linear:
            return self._linear_reach(sector, ux, uy)[0]
        return self._boundary(sector, ux, uy)[0]

    def reachable_set(self, n_directions: int = 360) -> ReachableSet:
        """Maximum curvature on ``n_directions`` equally spaced directions from 0 rad."""
        directions = np.linspace(0.0, TWO_PI, n_directions, endpoint=False)
        return ReachableSet(directions=directions,
                            max_curvature=np.array([self.max_curvature(d) for d in directions]),
                            channel_directions=self.channel_directions.copy(),
                            channel_max_curvature=self.channel_max_curvature.copy())

    # ------------------------------------------------------------------ sector choice

    def _select(self, phi: float, stateless: bool = False) -> tuple[Sector | None, float]:
        """Sector containing direction ``phi`` and the angle from its start edge (snapped into it)."""
        cur = None if stateless else self._current
        if cur is not None:
            rel = _wrap(phi - cur.start)
            if rel <= cur.gap:
                return cur, rel
            if rel <= cur.gap + self.hysteresis:
                return cur, cur.gap
            if rel >= TWO_PI - self.hysteresis:
                return cur, 0.0
        for s in self._sectors:
            rel = _wrap(phi - s.start)
            if rel <= s.gap:
                if not stateless:
                    self._current = s
                return s, rel
        return None, 0.0

    def _lone_channel(self, phi: float) -> int | None:
        """A channel whose own bending direction is within the tolerance of ``phi``."""
        for i, d in enumerate(self.channel_directions):
            if math.isfinite(d) and abs(_wrap(phi - d + math.pi) - math.pi) <= self.direction_tolerance:
                return i
        return None

    # ------------------------------------------------------------------ results

    def _zero(self, requested, message: str) -> Allocation:
        return Allocation(pressures=np.zeros(self.n_channels), requested_curvature=np.array(requested),
                          achieved_curvature=np.zeros(2), axial_stretch=self._rest_stretch,
                          max_curvature=float("nan"),
                          saturated=False, reachable=True, active_channels=(), message=message)

    def _unreachable(self, requested, phi: float) -> Allocation:
        dirs = ", ".join(f"{math.degrees(d):.1f}" for d in self.channel_directions if math.isfinite(d))
        return Allocation(pressures=np.zeros(self.n_channels), requested_curvature=np.array(requested),
                          achieved_curvature=np.zeros(2), axial_stretch=self._rest_stretch,
                          max_curvature=0.0, saturated=False, reachable=False, active_channels=(),
                          message=(f"direction {math.degrees(phi):.2f} deg is unreachable for design "
                                   f"'{self.design.name}': its channels bend only towards {dirs} deg"
                                   + (" and between neighbours less than 180 deg apart" if self._sectors else "")))

    def _result(self, pressures, requested, achieved, stretch, kmax, saturated, active, iterations=0,
                converged=True, message="") -> Allocation:
        return Allocation(pressures=pressures, requested_curvature=np.array(requested),
                          achieved_curvature=achieved, axial_stretch=stretch, max_curvature=kmax,
                          saturated=saturated, reachable=True,
                          active_channels=tuple(i for i in active if pressures[i] > 0.0),
                          converged=converged, message=message, iterations=iterations)

    # ------------------------------------------------------------------ linear rungs (exact, one shot)

    def _linear_reach(self, s: Sector, ux: float, uy: float) -> tuple[float, float, float]:
        """(max curvature, pa, pb per unit curvature) along the unit direction (ux, uy)."""
        i00, i01, i10, i11 = s.inv
        qa = max(i00 * ux + i01 * uy, 0.0)
        qb = max(i10 * ux + i11 * uy, 0.0)
        return self.max_pressure / max(qa, qb), qa, qb

    def _linear_state(self, p: list[float]) -> tuple[np.ndarray, float]:
        g = self._g
        k = np.array([sum(g[0][i] * p[i] for i in range(self.n_channels)),
                      sum(g[1][i] * p[i] for i in range(self.n_channels))])
        if self._stretch_per_pa is not None:
            stretch = 1.0 + sum(c * v for c, v in zip(self._stretch_per_pa, p))
        else:
            stretch = float(self.model.evaluate(np.asarray(p)).axial_stretch)
        return k, stretch

    def _pair_linear(self, s: Sector, requested, kappa, ux, uy) -> Allocation:
        kmax, qa, qb = self._linear_reach(s, ux, uy)
        saturated = kappa > kmax * (1.0 + _SATURATION_RTOL)
        k = kmax if saturated else kappa
        p = [0.0] * self.n_channels
        # min() guards the last ulp: the saturated larger pressure is exactly max_pressure.
        p[s.a] = min(qa * k, self.max_pressure)
        p[s.b] = min(qb * k, self.max_pressure)
        achieved, stretch = self._linear_state(p)
        return self._result(np.array(p), requested, achieved, stretch, kmax, saturated, (s.a, s.b))

    # ------------------------------------------------------------------ any rung (Newton on the model: PairInverse)

    def _pair_nonlinear(self, s: Sector, requested, kappa, ux, uy) -> Allocation:
        target = np.array([kappa * ux, kappa * uy]) + self._rest_curvature
        i00, i01, i10, i11 = s.inv
        q = np.clip([(i00 * ux + i01 * uy) * kappa, (i10 * ux + i11 * uy) * kappa], 0.0, self.max_pressure)
        warm = self._warm
        if warm is not None and warm[0] is s and float(np.hypot(*(warm[2] - target))) < 0.05 * kappa:
            q = warm[1]      # a request close to the last one: start from its answer
        try:
            q, (k, stretch), iterations, outside = self._newton(s, q, target)
        except ModelError as exc:
            self._warm = None
            return self._on_branch(s, requested, kappa, ux, uy, exc)
        self._warm = None if outside else (s, q.copy(), target)
        if not outside:  # max_curvature is not computed here: it costs a boundary solve
            return self._result(self._full(s, q), requested, k, stretch, float("nan"), False, (s.a, s.b), iterations)
        # The solution leaves the pressure box: find the boundary along the same direction.
        try:
            kmax, q_sat, (k, stretch), n_b = self._boundary(s, ux, uy)
        except ModelError as exc:
            return self._failed(requested, (s.a, s.b), str(exc))
        iterations += n_b
        if kappa > kmax * (1.0 + _SATURATION_RTOL):
            return self._result(self._full(s, q_sat), requested, k, stretch, kmax, True, (s.a, s.b), iterations)
        # Inside after all (Newton wandered out on the way): restart from the scaled boundary point.
        try:
            q, (k, stretch), n_r, _ = self._newton(s, q_sat * (kappa / kmax), target, allow_outside=False)
        except ModelError as exc:
            return self._on_branch(s, requested, kappa, ux, uy, exc, kmax, iterations)
        return self._result(self._full(s, q), requested, k, stretch, kmax, False, (s.a, s.b), iterations + n_r)

    def _on_branch(self, s: Sector, requested, kappa, ux, uy, failure, kmax=float("nan"), iterations=0):
        """Where Newton from its usual start fails (a rung whose bend folds back near the box's edge):
        the pressures on the branch of answers connected to rest, followed from it (``_follow_branch``)."""
        try:
            q, (k, stretch), n = self._follow_branch(s, kappa, ux, uy)
        except ModelError as exc:
            return self._failed(requested, (s.a, s.b), f"{failure}; followed from rest: {exc}")
        return self._result(self._full(s, q), requested, k, stretch, kmax, False, (s.a, s.b), iterations + n)

    def _full(self, s: Sector, q) -> np.ndarray:
        p = np.zeros(self.n_channels)
        p[s.a], p[s.b] = np.clip(q, 0.0, self.max_pressure)
        return p

    def _failed(self, requested, active, message) -> Allocation:
        return Allocation(pressures=np.zeros(self.n_channels), requested_curvature=np.array(requested),
                          achieved_curvature=np.zeros(2), axial_stretch=self._rest_stretch,
                          max_curvature=float("nan"), saturated=False, reachable=True, active_channels=(),
                          converged=False, message=f"inverse did not converge: {message}")

    def _single(self, i: int, requested, kappa: float) -> Allocation:
        """One channel alone (a request along its own bending direction, within the tolerance)."""
        kmax = float(self.channel_max_curvature[i])
        saturated = kappa > kmax * (1.0 + _SATURATION_RTOL)
        if self.linear:
            p = [0.0] * self.n_channels
            p[i] = self.max_pressure if saturated else min(kappa / kmax, 1.0) * self.max_pressure
            achieved, stretch = self._linear_state(p)
            return self._result(np.array(p), requested, achieved, stretch, kmax, saturated, (i,))
        count = [0]

        def reach(pi):
            p = np.zeros(self.n_channels)
            p[i] = pi
            count[0] += 1
            return self._eval(p)

        try:
            if saturated or kappa >= kmax:
                pi = self.max_pressure
            else:
                pi = brentq(lambda x: float(np.hypot(*(reach(x).curvature - self._rest_curvature))) - kappa,
                            0.0, self.max_pressure, xtol=1e-10 * self.max_pressure, rtol=1e-12)
            k, stretch = self._point(reach(pi))
        except ModelError as exc:
            return self._failed(requested, (i,), str(exc))
        p = np.zeros(self.n_channels)
        p[i] = pi
        return self._result(p, requested, k, stretch, kmax, saturated, (i,), count[0])

