"""Requests in other terms than a curvature: a bending angle towards a direction, or a tip position.
Each becomes curvature requests to the ``Allocator`` (core/allocation.py), into which it is mixed."""
from __future__ import annotations

import math

import numpy as np

from .allocation_result import Allocation
from .errors import AllocationError
from .kinematics import curvature_for_tip, tip_pose_single
from .prediction import arc_and_cap


class BendTargets:
    """``allocate_bend`` and ``allocate_tip`` on top of the allocator's ``allocate`` (a mixin of ``Allocator``)."""

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
            if not slope > 0.0:   # the tip no longer turns with the angle (the bend is held at a limit)
                break
            previous = (angle, miss)
            angle = max(angle - miss / slope, 0.0)   # an arc's tip bearing is half its angle
            miss, result, pos = off_bearing(angle)
        error = float(np.linalg.norm(pos - p))
        result.extras.update({"target_tip_m": p.tolist(), "achieved_tip_m": pos.tolist(), "tip_error_m": error,
                              "tip_reachable": bool(result.reachable and error <= rtol * length)})
        return result
