"""Sizing of N equal circular channels placed symmetrically around a central lumen.

For the 2-DOF design (docs/actuator.md "Optimised designs"): outer radius R, a lumen of
radius r_l at the centre, N channels of radius r at distance d from the centre,
spaced 360/N degrees apart. Every silicone wall must be at least w thick:

    outer wall          R - d - r          >= w
    channel to lumen    d - r - r_l        >= w
    channel to channel  2 d sin(pi/N) - 2 r >= w

Maximise the channel area N pi r^2, i.e. r. The problem is solved numerically
(scipy SLSQP) so that the constraints are checked as written, and against the
closed-form optimum: for the 5 mm body the first two constraints meet first,
giving r = (R - r_l - 2 w) / 2 and d = r_l + w + r.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize


@dataclass(frozen=True)
class ChannelLayout:
    channel_radius: float       # m
    center_radius: float        # m, distance of each channel centre from the body axis
    outer_wall: float           # m
    lumen_wall: float           # m
    channel_wall: float         # m, between neighbouring channels
    area_ratio: float           # total channel area / body cross-section area

    @property
    def channel_diameter(self) -> float:
        return 2.0 * self.channel_radius

    def centers(self, n_channels: int, first_angle_deg: float = 90.0) -> list[tuple[float, float]]:
        """Channel centres (m), the first at ``first_angle_deg`` and the rest counter-clockwise."""
        out = []
        for i in range(n_channels):
            a = math.radians(first_angle_deg + 360.0 * i / n_channels)
            out.append((self.center_radius * math.cos(a), self.center_radius * math.sin(a)))
        return out


def _walls(r: float, d: float, outer_radius: float, lumen_radius: float, n: int) -> tuple[float, float, float]:
    return (outer_radius - d - r, d - r - lumen_radius, 2.0 * d * math.sin(math.pi / n) - 2.0 * r)


def max_channel_layout(outer_diameter: float, lumen_diameter: float, min_wall: float,
                       n_channels: int = 3) -> ChannelLayout:
    """Largest equal circular channels that keep every wall >= ``min_wall`` (all in m)."""
    if n_channels < 2:
        raise ValueError("a symmetric layout needs at least two channels")
    big_r, r_l, w, n = 0.5 * outer_diameter, 0.5 * lumen_diameter, min_wall, n_channels
    scale = big_r  # solve in units of the outer radius so SLSQP's tolerances are meaningful

    def walls(x):
        return np.array(_walls(x[0] * scale, x[1] * scale, big_r, r_l, n)) / scale - w / scale

    x0 = np.array([0.05, (r_l + w) / scale + 0.05 + 0.01])
    res = minimize(lambda x: -x[0], x0, method="SLSQP",
                   constraints=[{"type": "ineq", "fun": walls}],
                   bounds=[(1e-6, 1.0), (0.0, 1.0)], options={"ftol": 1e-14, "maxiter": 200})
    if not res.success or res.x[0] <= 1e-6 * 1.0001:
        raise ValueError(f"no channel fits: outer {outer_diameter} m, lumen {lumen_diameter} m, "
                         f"walls {min_wall} m ({res.message})")
    r, d = res.x[0] * scale, res.x[1] * scale
    outer_wall, lumen_wall, channel_wall = _walls(r, d, big_r, r_l, n)
    return ChannelLayout(channel_radius=r, center_radius=d, outer_wall=outer_wall, lumen_wall=lumen_wall,
                         channel_wall=channel_wall, area_ratio=n * r * r / (big_r * big_r))
