"""The pressures of a pair of neighbouring channels (a sector) for a curvature on a rung solved
numerically: damped Newton on the rung's own forward map (its declared pair Jacobian, or finite
differences) and the reachable set's boundary along a direction. Mixed into the ``Allocator``
(core/allocation.py), whose model, pressure limit, tolerances and rest state it reads."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import ModelError


def brentq(*args, **kwargs):
    """scipy's brentq, imported on first use: scipy.optimize takes a second or more to import, which
    a node would otherwise pay at start-up before answering its first command."""
    from scipy.optimize import brentq as scipy_brentq

    return scipy_brentq(*args, **kwargs)


@dataclass(frozen=True)
class Sector:
    """Two neighbouring channels whose bending directions are less than 180 degrees apart."""
    a: int              # channel at the sector's clockwise edge
    b: int              # channel at its counter-clockwise edge
    start: float        # rad, bending direction of channel a
    gap: float          # rad, counter-clockwise angle from a's to b's direction, in (0, pi)
    inv: tuple          # secant inverse (i00, i01, i10, i11): pressures per unit curvature, Pa m


# curvature steps from rest when following the branch of answers connected to rest
BRANCH_STEPS = 8


class PairInverse:
    """Newton and the reachable boundary for a sector's two channels (a mixin of ``Allocator``)."""

    def _eval(self, batch: np.ndarray):
        state = self.model.evaluate(batch)
        if not np.all(state.converged):
            raise ModelError(state.message or f"model '{self.model.name}' did not converge")
        return state

    def _point(self, states, i: int | None = None) -> tuple[np.ndarray, float]:
        """(pressure-induced curvature, axial stretch) of a state, or of row ``i`` of a batch."""
        k = states.curvature if i is None else states.curvature[i]
        stretch = states.axial_stretch if i is None else states.axial_stretch[i]
        return np.asarray(k, dtype=float) - self._rest_curvature, float(stretch)

    def _newton(self, s: Sector, q, target, allow_outside: bool = True):
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

    def _follow_branch(self, s: Sector, kappa: float, ux: float, uy: float, steps: int = BRANCH_STEPS):
        """Newton along the request's direction from rest in ``steps`` equal steps of curvature, each
        started from the last answer extrapolated: it stays on the branch of answers connected to
        rest (the least pressure), where a start near a fold of the rung's map can leave it.
        Returns (q, (curvature, stretch) at q, evaluations); ModelError where a step fails."""
        q_prev, q = np.zeros(2), np.zeros(2)
        total = 0
        point = None
        for j in range(1, steps + 1):
            target = np.array([ux, uy]) * (kappa * j / steps) + self._rest_curvature
            guess = np.clip(2.0 * q - q_prev, 0.0, self.max_pressure) if j > 1 else q
            q_prev = q
            q, point, n, _ = self._newton(s, guess, target, allow_outside=False)
            total += n
        return q, point, total

    def _local(self, s: Sector, q, h: float, pmax: float):
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

    def _jacobian_batch(self, s: Sector, q, h: float, pmax: float):
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

    def _edge(self, s: Sector, t: float) -> np.ndarray:
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

    def _boundary(self, s: Sector, ux: float, uy: float):
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
