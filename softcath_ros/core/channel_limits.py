"""The allocator's working pressure limit, from each channel's own answers on the rung.

Two limits below the design's (or a requested) max_pressure, each said in one line:

- the rung's: the largest pressure at which it answers every channel alone (a surrogate table
  ends where its source stopped converging);
- the peak's: the smallest pressure at which one channel alone stops bending more (|k| peaks,
  e.g. a sector channel whose wall balloons): beyond it more pressure bends less, so a request
  there has two answers or none and allocating past it is never right.

And one a caller may choose (steering's range, core/steering_range.py): ``bend_limit``, the smallest
pressure at which one channel alone turns the tip a given angle away from the base's axis.
"""
from __future__ import annotations

import math

import numpy as np

from .prediction import angle_per_length

# pressures on each channel's ray (0, max_pressure] sampled to find where |k| stops growing
PEAK_SAMPLES = 64
# the peak is refined to this fraction of max_pressure
PEAK_XTOL = 1e-4


def answered_limit(model, max_pressure: float, iterations: int = 16) -> float:
    """Largest pressure (Pa, to max_pressure / 2**iterations) at which the rung answers every
    channel alone, by bisection from rest (which every rung answers)."""
    lo, hi = 0.0, max_pressure
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if np.all(model.evaluate(np.eye(model.n_channels) * mid).converged):
            lo = mid
        else:
            hi = mid
    return lo


def _alone(model, channel: int, pressures):
    """The rung's state (batched) with ``channel`` alone at each of ``pressures``."""
    batch = np.zeros((len(pressures), model.n_channels))
    batch[:, channel] = pressures
    return model.evaluate(batch)


def _bend(model, channel: int, pressures, rest) -> np.ndarray:
    """|k - k_rest| (1/m) of ``channel`` alone at each of ``pressures`` (nan where not answered)."""
    state = _alone(model, channel, pressures)
    k = np.asarray(state.curvature, dtype=float).reshape(len(pressures), 2) - rest
    return np.where(np.asarray(state.converged, dtype=bool), np.hypot(k[:, 0], k[:, 1]), np.nan)


def _peak_between(model, channel: int, lo: float, hi: float, rest, xtol: float) -> float:
    """Pressure (Pa) in [lo, hi] where ``channel`` alone bends most (|k| rises then falls there):
    scipy's bounded scalar minimiser on -|k| (an unanswered pressure counts as no bend)."""
    from scipy.optimize import minimize_scalar

    def less_bend(p):
        bend = _bend(model, channel, [p], rest)[0]
        return -bend if math.isfinite(bend) else 0.0

    return float(minimize_scalar(less_bend, bounds=(lo, hi), method="bounded", options={"xatol": xtol}).x)


def peak_limit(model, max_pressure: float, rest) -> tuple[float, int, float] | None:
    """(pressure Pa, channel, |k| 1/m) of the smallest pressure <= max_pressure at which a channel
    alone stops increasing |k|, or None when every channel's |k| grows all the way to max_pressure.
    A rung linear in pressure grows by construction and is not sampled."""
    if model.info.linear_gain:
        return None
    rest = np.asarray(rest, dtype=float)
    grid = np.linspace(0.0, max_pressure, PEAK_SAMPLES + 1)
    bends = np.array([np.concatenate([[0.0], _bend(model, c, grid[1:], rest)]) for c in range(model.n_channels)])
    steerable = np.nanmax(bends, axis=1) > 1e-9 * max(float(np.nanmax(bends)), 1e-300)
    first = {}
    for c in np.flatnonzero(steerable):
        # the first sample after which |k| no longer grows (a sample the rung leaves unanswered is no stop)
        stops = np.flatnonzero(np.diff(bends[c]) <= 0.0)
        if len(stops):
            first[int(c)] = int(stops[0])
    if not first:
        return None
    lowest = min(first.values())
    best = None
    for c, i in first.items():
        if i > lowest + 1:      # its peak lies beyond the lowest sampled one's bracket
            continue
        lo, hi = grid[max(i - 1, 0)], grid[i + 1]
        p = _peak_between(model, c, lo, hi, rest, PEAK_XTOL * max_pressure)
        if best is None or p < best[0]:
            best = (float(p), c, float(_bend(model, c, [p], rest)[0]))
    return best


def _tip_angle(model, channel: int, pressures) -> np.ndarray:
    """Angle (rad) between the tip's direction and the base's axis with ``channel`` alone at each of
    ``pressures``: the arc's bend |k| x stretch x arc length (the tip cap continues the arc's end
    tangent); nan where not answered."""
    state = _alone(model, channel, pressures)
    angle = angle_per_length(state, model) * float(model.design.length)
    return np.where(np.asarray(state.converged, dtype=bool).reshape(-1), angle, np.nan)


def bend_limit(model, max_pressure: float, angle: float, iterations: int = 40) -> tuple[float, int] | None:
    """(pressure Pa, channel) of the smallest pressure <= max_pressure at which a channel alone turns
    the tip ``angle`` rad away from the base's axis, or None when none does up to max_pressure. The
    first crossing on PEAK_SAMPLES pressures, then bisection (to max_pressure / 2**iterations) within
    it; an unanswered pressure counts as not reaching the angle."""
    grid = np.linspace(0.0, max_pressure, PEAK_SAMPLES + 1)
    best = None
    for c in range(model.n_channels):
        over = np.flatnonzero(_tip_angle(model, c, grid[1:]) >= angle)
        if not len(over):
            continue
        lo, hi = float(grid[over[0]]), float(grid[over[0] + 1])
        if best is not None and lo >= best[0]:
            continue
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            if _tip_angle(model, c, [mid])[0] >= angle:
                hi = mid
            else:
                lo = mid
        best = (hi, c)
    return best
