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
[0, max_pressure]. A request beyond it saturates *along the requested direction*
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
from dataclasses import dataclass, field

import numpy as np

from .plausibility import PLAUSIBLE_PRESSURE, pressure_guess
from .errors import ModelError, SoftcathError
from .kinematics import curvature_for_tip, tip_pose_single
from .prediction import arc_and_cap, body_reach
from .models.base import BendModel


def brentq(*args, **kwargs):
    """scipy's brentq, imported on first use: scipy.optimize takes a second or more to import, which
    a node would otherwise pay at start-up before answering its first command."""
    from scipy.optimize import brentq as scipy_brentq

    return scipy_brentq(*args, **kwargs)

TWO_PI = 2.0 * math.pi
# A request counts as beyond reach only past this relative margin, so the boundary itself
# (kappa == max curvature up to rounding) is reachable and not flagged saturated.
_SATURATION_RTOL = 1e-9


# bisections of a request's scale for the largest bend that keeps the body clear of itself and its
# shaft (each one allocation; 2^-24 of the request)
CLEAR_BISECTIONS = 24


class AllocationError(SoftcathError):
    """A request the allocator cannot interpret (non-finite, negative angle, ...)."""


@dataclass
class Allocation:
    """One allocation. Pressures in Pa, curvatures in 1/m, angles in rad."""

    pressures: np.ndarray               # (C,) Pa, each in [0, max_pressure]
    requested_curvature: np.ndarray     # (2,) 1/m, as asked (before saturation)
    achieved_curvature: np.ndarray      # (2,) 1/m, the model's forward curvature at ``pressures``
    axial_stretch: float                # the model's axial stretch at ``pressures``
    max_curvature: float                # 1/m, reachable-set radius in the requested direction
    saturated: bool                     # the request lay beyond the reachable set
    reachable: bool                     # False: no channel combination bends this way
    active_channels: tuple[int, ...]    # channels with non-zero pressure (0, 1 or 2 of them)
    converged: bool = True              # the model's inverse converged (always for linear rungs)
    message: str = ""                   # why not reachable / not converged, or what was clipped
    iterations: int = 0                 # model evaluations batches used by the inverse
    extras: dict = field(default_factory=dict)  # mode-specific (tip error, requested angle, ...)

    @property
    def bending_angle(self) -> float:
        """Achieved bending angle, rad (needs the backbone length: see ``extras``)."""
        return float(self.extras.get("achieved_angle_rad", float("nan")))

    def to_json(self) -> dict:
        d = {"pressures_pa": [float(v) for v in self.pressures],
             "saturated": bool(self.saturated),
             "reachable": bool(self.reachable),
             "converged": bool(self.converged),
             "requested_curvature_per_m": [float(v) for v in self.requested_curvature],
             "achieved_curvature_per_m": [float(v) for v in self.achieved_curvature],
             "axial_stretch": float(self.axial_stretch),
             "max_curvature_per_m": float(self.max_curvature),
             "active_channels": list(self.active_channels),
             "iterations": int(self.iterations),
             "message": self.message}
        d.update({k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.extras.items()})
        return d


@dataclass(frozen=True)
class _Sector:
    a: int              # channel at the sector's clockwise edge
    b: int              # channel at its counter-clockwise edge
    start: float        # rad, bending direction of channel a
    gap: float          # rad, counter-clockwise angle from a's to b's direction, in (0, pi)
    inv: tuple          # secant inverse (i00, i01, i10, i11): pressures per unit curvature, Pa m


@dataclass(frozen=True)
class ReachableSet:
    directions: np.ndarray      # (N,) rad, direction of the curvature vector (atan2(ky, kx))
    max_curvature: np.ndarray   # (N,) 1/m, 0 where the direction is unreachable
    channel_directions: np.ndarray  # (C,) rad, each channel's own bending direction (nan: none)
    channel_max_curvature: np.ndarray  # (C,) 1/m, each channel alone at max_pressure


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


class Allocator:
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

        # Each channel alone at max_pressure: its bending direction and its reach. Where the rung
        # stops answering a channel alone below max_pressure (a table ends where its source failed),
        # the allocator's limit is the largest pressure every channel alone reaches (said in
        # ``limited_by_rung``), never a command the rung cannot answer.
        single = model.evaluate(np.eye(self.n_channels) * self.max_pressure)
        self.limited_by_rung = ""
        if not np.all(single.converged):
            reach = self._single_channel_reach(model)
            if reach <= 0.05 * self.max_pressure:
                raise ModelError(f"allocation needs model '{model.name}' at max_pressure {self.max_pressure:g} Pa on "
                                 f"each channel alone, but it did not converge ({single.message}); allocate with a "
                                 "lower max_pressure inside the rung's range")
            self.limited_by_rung = (f"model '{model.name}' answers each channel alone only up to {reach:.0f} Pa "
                                    f"(not {self.max_pressure:g} Pa): allocating up to {reach:.0f} Pa")
            self.max_pressure = reach
            single = model.evaluate(np.eye(self.n_channels) * self.max_pressure)
        self.fd_step = fd_step * self.max_pressure  # Pa, finite-difference step for the Jacobian
        rest = model.evaluate(np.zeros(self.n_channels))
        self._rest_curvature = np.asarray(rest.curvature, dtype=float)
        self._rest_stretch = float(rest.axial_stretch)
        k1 = np.asarray(single.curvature, dtype=float) - self._rest_curvature
        mags = np.hypot(k1[:, 0], k1[:, 1])
        steerable = mags > 1e-9 * max(float(mags.max()), 1e-300)
        self.channel_directions = np.where(steerable, np.arctan2(k1[:, 1], k1[:, 0]) % TWO_PI, np.nan)
        self.channel_max_curvature = np.where(steerable, mags, 0.0)
        self._secant = k1 / self.max_pressure  # (C, 2) curvature per Pa at max_pressure, per channel
        self.deadband = 1e-3 * float(mags.max()) if deadband is None else float(deadband)

        order = [i for i in np.argsort(np.nan_to_num(self.channel_directions, nan=np.inf)) if steerable[i]]
        self._sectors: list[_Sector] = []
        for j, a in enumerate(order):
            if len(order) < 2:
                break
            b = order[(j + 1) % len(order)]
            gap = _wrap(self.channel_directions[b] - self.channel_directions[a])
            if 1e-9 < gap < math.pi - 1e-9:
                m = np.column_stack([self._secant[a], self._secant[b]])
                inv = np.linalg.inv(m)
                self._sectors.append(_Sector(int(a), int(b), float(self.channel_directions[a]), float(gap),
                                             tuple(float(v) for v in inv.ravel())))
        self._current: _Sector | None = None
        # the last solution inside reach on the nonlinear path (sector, pair pressures, curvature
        # vector): a stream of nearby requests starts Newton there (2-3 steps instead of ~6)
        self._warm = None

    def _single_channel_reach(self, model, iterations: int = 16) -> float:
        """Largest pressure (Pa, to max_pressure / 2**iterations) at which the rung answers every
        channel alone, by bisection from rest (which every rung answers)."""
        lo, hi = 0.0, self.max_pressure
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            if np.all(model.evaluate(np.eye(self.n_channels) * mid).converged):
                lo = mid
            else:
                hi = mid
        return lo

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

    def allocate_bend(self, direction: float, angle: float, length: float | None = None) -> Allocation:
        """Pressures for bending angle ``angle`` (rad) towards ``direction`` (rad, atan2(ky, kx)).

        The angle is |k| times the *stretched* arc length of the channelled part (the tip cap
        stays straight: ``core/prediction.arc_and_cap``), so the magnitude is iterated on the
        model's own axial stretch until it settles.
        """
        if not (math.isfinite(direction) and math.isfinite(angle)):
            raise AllocationError(f"direction {direction} rad / angle {angle} rad must be finite")
        if angle < 0:
            raise AllocationError(f"bending angle {angle} rad must not be negative (turn the direction instead)")
        length = self.design.length if length is None else float(length)
        arc, _ = arc_and_cap(self.model, length)
        ux, uy = math.cos(direction), math.sin(direction)
        stretch = self._rest_stretch
        result = None
        for _ in range(8):
            kappa = angle / (arc * stretch)
            result = self.allocate((kappa * ux, kappa * uy), length)
            if abs(result.axial_stretch - stretch) <= 1e-10 * stretch:  # angle error <= 1e-10 relative
                break
            stretch = result.axial_stretch
        achieved = math.hypot(*result.achieved_curvature) * arc * result.axial_stretch
        result.extras.update({"requested_angle_rad": angle, "achieved_angle_rad": achieved,
                              "max_angle_rad": result.max_curvature * arc * result.axial_stretch})
        return result

    def tip_position(self, result: "Allocation", length: float | None = None) -> np.ndarray:
        """The tip (m, softcath_base) of the body of ``length`` (default the design's) bent as ``result``
        achieves: the arc of the channelled part and the straight cap beyond it."""
        arc, cap = arc_and_cap(self.model, self.design.length if length is None else float(length))
        ka, kb = result.achieved_curvature
        return np.array(tip_pose_single(float(ka), float(kb), arc * result.axial_stretch, cap)[0])

    def allocate_tip(self, tip, length: float | None = None, rtol: float = 1e-3) -> Allocation:
        """Pressures that put the tip at ``tip`` (m, softcath_base), through the constant-curvature inverse.

        The arc that ends, with the straight tip cap, at the target gives the direction and the
        bending angle; the bend is then allocated by angle. A target off the workspace surface is
        aimed at: the angle is corrected (secant steps) until the tip lands on the line from the
        base to the target (an arc alone would land there at once; the cap turns the tip's bearing
        a little with the arc's length), and ``tip_reachable`` says whether it was actually reached.
        """
        p = np.asarray(tip, dtype=float).ravel()
        if p.size != 3 or not np.all(np.isfinite(p)):
            raise AllocationError(f"tip {p.tolist()} m must be three finite numbers")
        length = self.design.length if length is None else float(length)
        arc = curvature_for_tip(p, length, cap=arc_and_cap(self.model, length)[1])
        arc_length = float(arc.arc_length)
        if not math.isfinite(arc_length):
            raise AllocationError(f"tip {p.tolist()} m: no bending arc ends there (on or behind the base)")
        kx, ky = float(arc.curvature[0]), float(arc.curvature[1])
        direction = math.atan2(ky, kx)
        angle = math.hypot(kx, ky) * arc_length  # the arc's angle (without a cap: 2 atan2(rho, z))

        def off_bearing(a):   # (the tip's bearing from the base minus the target's, rad; allocation; tip)
            res = self.allocate_bend(direction, a, length)
            at = self.tip_position(res, length)
            return math.atan2(math.hypot(at[0], at[1]), at[2]) - math.atan2(math.hypot(p[0], p[1]), p[2]), res, at

        miss, result, pos = off_bearing(angle)
        previous = None
        for _ in range(12):
            if abs(miss) <= 1e-12 or result.saturated or angle == 0.0:
                break
            slope = 0.5 if previous is None or previous[0] == angle else (miss - previous[1]) / (angle - previous[0])
            previous = (angle, miss)
            angle = max(angle - miss / slope, 0.0)   # an arc's tip bearing is half its angle
            miss, result, pos = off_bearing(angle)
        error = float(np.linalg.norm(pos - p))
        result.extras.update({"target_tip_m": p.tolist(), "achieved_tip_m": pos.tolist(), "tip_error_m": error,
                              "tip_reachable": bool(result.reachable and error <= rtol * length)})
        return result

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

    def _select(self, phi: float, stateless: bool = False) -> tuple[_Sector | None, float]:
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

    def _linear_reach(self, s: _Sector, ux: float, uy: float) -> tuple[float, float, float]:
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

    def _pair_linear(self, s: _Sector, requested, kappa, ux, uy) -> Allocation:
        kmax, qa, qb = self._linear_reach(s, ux, uy)
        saturated = kappa > kmax * (1.0 + _SATURATION_RTOL)
        k = kmax if saturated else kappa
        p = [0.0] * self.n_channels
        # min() guards the last ulp: the saturated larger pressure is exactly max_pressure.
        p[s.a] = min(qa * k, self.max_pressure)
        p[s.b] = min(qb * k, self.max_pressure)
        achieved, stretch = self._linear_state(p)
        return self._result(np.array(p), requested, achieved, stretch, kmax, saturated, (s.a, s.b))

    # ------------------------------------------------------------------ any rung (Newton on the model)

    def _eval(self, batch: np.ndarray):
        state = self.model.evaluate(batch)
        if not np.all(state.converged):
            raise ModelError(state.message or f"model '{self.model.name}' did not converge")
        return state

    def _pair_nonlinear(self, s: _Sector, requested, kappa, ux, uy) -> Allocation:
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
            return self._failed(requested, (s.a, s.b), str(exc))
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
            return self._failed(requested, (s.a, s.b), str(exc))
        return self._result(self._full(s, q), requested, k, stretch, kmax, False, (s.a, s.b), iterations + n_r)

    def _point(self, states, i: int | None = None) -> tuple[np.ndarray, float]:
        """(pressure-induced curvature, axial stretch) of a state, or of row ``i`` of a batch."""
        k = states.curvature if i is None else states.curvature[i]
        stretch = states.axial_stretch if i is None else states.axial_stretch[i]
        return np.asarray(k, dtype=float) - self._rest_curvature, float(stretch)

    def _full(self, s: _Sector, q) -> np.ndarray:
        p = np.zeros(self.n_channels)
        p[s.a], p[s.b] = np.clip(q, 0.0, self.max_pressure)
        return p

    def _failed(self, requested, active, message) -> Allocation:
        return Allocation(pressures=np.zeros(self.n_channels), requested_curvature=np.array(requested),
                          achieved_curvature=np.zeros(2), axial_stretch=self._rest_stretch,
                          max_curvature=float("nan"), saturated=False, reachable=True, active_channels=(),
                          converged=False, message=f"inverse did not converge: {message}")

    def _newton(self, s: _Sector, q, target, allow_outside: bool = True):
        """Damped Newton on the pair's pressures q (Pa) for curvature ``target``; projects onto the box.

        Returns (q, (curvature, stretch) at q, iterations, outside) where ``outside`` means the
        solution needs a pressure above max_pressure (the request is beyond reach).
        """
        q = np.asarray(q, dtype=float)
        pmax, h = self.max_pressure, self.fd_step
        scale = max(math.hypot(*(target - self._rest_curvature)), self.deadband)
        pushes = 0
        best = (math.inf, None, None)
        q_ok = None    # the last point the model answered
        for it in range(1, self.max_iterations + 1):
            local = self._local(s, q, h, pmax)
            if local is None:
                # the rung does not answer here (a table ends where its source failed): beyond reach,
                # or back half-way towards the last answered point
                if q_ok is None or (allow_outside and pushes >= 2):
                    if allow_outside:   # (the caller finds the boundary and its state)
                        return (q if q_ok is None else q_ok), (np.full(2, np.nan), math.nan), it, True
                    raise ModelError(f"model '{self.model.name}' does not answer near the requested bend")
                pushes += 1
                q = 0.5 * (q + q_ok)
                continue
            q_ok = q.copy()
            k, jac, point = local
            r = k - target
            residual = math.hypot(*r)
            if residual <= self.rtol * scale:
                return q, point, it, False
            if residual < best[0]:
                best = (residual, q.copy(), point)
            (j00, j01), (j10, j11) = jac.tolist()
            det = j00 * j11 - j01 * j10
            if not math.isfinite(det) or det == 0.0:
                raise ModelError("singular Jacobian of the two active channels")
            r0, r1 = float(r[0]), float(r[1])
            dq = np.array([-(j11 * r0 - j01 * r1) / det, -(j00 * r1 - j10 * r0) / det])   # -J^-1 r
            trial = q + dq
            if np.any(trial > pmax * (1.0 + 1e-12)):
                pushes += 1
                at_top = np.isclose(q, pmax, rtol=0, atol=1e-9 * pmax) & (trial > pmax)
                if allow_outside and (pushes >= 3 or np.any(at_top)):
                    return q, point, it, True
            q = np.clip(trial, 0.0, pmax)
        if best[0] <= self.accept_rtol * scale:
            return best[1], best[2], self.max_iterations, False
        raise ModelError(f"Newton did not reach rtol {self.rtol} in {self.max_iterations} iterations "
                         f"(best relative residual {best[0] / scale:.2e})")

    def _local(self, s: _Sector, q, h: float, pmax: float):
        """(curvature, 2 x 2 Jacobian over the pair's pressures, (pressure-induced curvature,
        stretch)) at pair pressures q: from the rung's declared ``pair_jacobian`` or by finite
        differences; None where the rung does not answer."""
        if self._pair_jac:
            got = self.model.pair_jacobian(s.a, s.b, float(q[0]), float(q[1]))
            if got is None:
                return None
            k, stretch, da, db = got
            k = np.array(k)
            return k, np.array([[da[0], db[0]], [da[1], db[1]]]), (k - self._rest_curvature, float(stretch))
        states, ha, hb = self._jacobian_batch(s, q, h, pmax)
        if states is None:
            return None
        k = states.curvature
        return k[0], np.column_stack([(k[1] - k[0]) / ha, (k[2] - k[0]) / hb]), self._point(states, 0)

    def _jacobian_batch(self, s: _Sector, q, h: float, pmax: float):
        """The model at q and one finite-difference step along each active channel (stepping back
        where forward is above pmax or unanswered); (states, ha, hb), or (None, .., ..) where the
        model does not answer at q."""
        ha = -h if q[0] + h > pmax else h
        hb = -h if q[1] + h > pmax else h
        for _ in range(2):
            batch = np.zeros((3, self.n_channels))
            batch[:, s.a] = [q[0], q[0] + ha, q[0]]
            batch[:, s.b] = [q[1], q[1], q[1] + hb]
            states = self.model.evaluate(batch)
            ok = np.asarray(states.converged, dtype=bool)
            if ok.all():
                return states, ha, hb
            if not ok[0]:
                break
            ha, hb = (-ha if not ok[1] else ha), (-hb if not ok[2] else hb)
        return None, ha, hb

    def _edge(self, s: _Sector, t: float) -> np.ndarray:
        """Pair pressures of the farthest command the model answers on the ray (1 - t, t) from rest,
        within the box (two batches of 64: to 1/4096 of the ray)."""
        w = np.array([1.0 - t, t]) / max(1.0 - t, t)
        lo, hi = 0.0, self.max_pressure
        for _ in range(2):
            scales = np.linspace(lo, hi, 65)[1:]
            batch = np.zeros((len(scales), self.n_channels))
            batch[:, s.a], batch[:, s.b] = scales * w[0], scales * w[1]
            ok = np.asarray(self.model.evaluate(batch).converged, dtype=bool)
            n = int(np.argmin(ok)) if not ok.all() else len(ok)
            if n == len(ok):
                return hi * w
            lo, hi = (scales[n - 1] if n else lo), scales[n]
        return lo * w

    def _boundary(self, s: _Sector, ux: float, uy: float):
        """Largest curvature along (ux, uy) in sector ``s``: the larger pressure at max_pressure.

        The other pressure t solves angle(k(t)) = direction (brentq on the signed angle).
        Returns (max curvature, pair pressures, (curvature, stretch) there, evaluations).
        """
        pmax = self.max_pressure
        count = [0]

        def curvature(qa, qb):
            p = np.zeros(self.n_channels)
            p[s.a], p[s.b] = qa, qb
            count[0] += 1
            return self._eval(p)

        def signed_angle(state):
            kx, ky = state.curvature - self._rest_curvature
            return math.atan2(ux * ky - uy * kx, ux * kx + uy * ky)

        def along_rays():
            # the rung does not answer somewhere on the box's edge: the reachable set's edge is where
            # it stops answering along each ray from rest; find the ray whose edge bends along the request
            def g(t):
                return signed_angle(curvature(*self._edge(s, t)))
            t = brentq(g, 0.0, 1.0, xtol=1e-7, rtol=1e-12) if g(0.0) * g(1.0) < 0 else (0.0 if abs(g(0.0)) < abs(
                g(1.0)) else 1.0)
            q = self._edge(s, t)
            k, stretch = self._point(curvature(*q))
            return math.hypot(*k), q, (k, stretch), count[0]

        corner = np.zeros(self.n_channels)
        corner[s.a] = corner[s.b] = pmax
        if not np.all(self.model.evaluate(corner).converged):
            return along_rays()
        both = curvature(pmax, pmax)
        f_both = signed_angle(both)
        if f_both == 0.0:
            k, stretch = self._point(both)
            return math.hypot(*k), np.array([pmax, pmax]), (k, stretch), count[0]
        # f_both > 0: the both-max direction lies counter-clockwise of the request, towards b: a is the big one.
        big_a = f_both > 0
        if big_a:
            f = lambda t: signed_angle(curvature(pmax, t))  # noqa: E731
        else:
            f = lambda t: signed_angle(curvature(t, pmax))  # noqa: E731
        try:
            t = brentq(f, 0.0, pmax, xtol=1e-10 * pmax, rtol=1e-12) if f(0.0) * f_both < 0 else 0.0
            q = np.array([pmax, t]) if big_a else np.array([t, pmax])
            k, stretch = self._point(curvature(*q))
        except ModelError:   # the corner answers but a point between it and a channel's end does not
            return along_rays()
        return math.hypot(*k), q, (k, stretch), count[0]

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

