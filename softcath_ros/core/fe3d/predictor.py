"""The corotational predictor of the fe3d ramp: the next load's displacement from the last two
states, bent on to the predicted curvature (core/fe3d/ramp.py)."""
from __future__ import annotations

import numpy as np

from .solver import Fe3dProblem


class CorotationalPredictor:
    """Secant predictor in a bent frame: each state is split into an arc of constant
    curvature (kappa along a bending direction) and a small displacement w relative to that
    arc; kappa and w are extrapolated linearly and mapped back.

    Why: the ordinary (tangent or secant) predictor extrapolates displacements linearly, so
    a rotating section is pushed along its tangent and stretched by ~theta^2; with a bulk
    modulus 8000x the shear modulus that spurious volume change is so expensive that Newton
    overshoots. Extrapolating in the bent frame keeps rotations rotations.
    """

    def __init__(self, problem: Fe3dProblem):
        import ngsolve as ng

        self.p = problem
        mesh = problem.mesh
        self.wspace = ng.VectorH1(mesh, order=2)
        self.w0 = ng.GridFunction(self.wspace)
        self.w1 = ng.GridFunction(self.wspace)
        self.fixed = ~np.array(list(problem.fes.FreeDofs(False)), dtype=bool)
        self.nu = self.wspace.ndof

    def _frame(self, direction):
        d = np.asarray(direction, dtype=float)
        return d, np.array([-d[1], d[0]])

    def _to_straight(self, gf_target, kappa, direction):
        """gf_target <- Phi^-1(X + u) - X for the problem's current u."""
        import ngsolve as ng

        d, e = self._frame(direction)
        pos = ng.CF((ng.x, ng.y, ng.z)) + self.p.u
        a_def = d[0] * pos[0] + d[1] * pos[1]
        b = e[0] * pos[0] + e[1] * pos[1]
        radius = 1.0 / kappa
        r = ng.sqrt((radius - a_def) ** 2 + pos[2] ** 2)
        a = radius - r
        zs = ng.atan2(pos[2], radius - a_def) / kappa
        xs = a * d[0] + b * e[0]
        ys = a * d[1] + b * e[1]
        gf_target.Set(ng.CF((xs - ng.x, ys - ng.y, zs - ng.z)))

    def _from_straight(self, w, kappa, direction):
        """The problem's u <- Phi(X + w) - X."""
        import ngsolve as ng

        d, e = self._frame(direction)
        xs = ng.CF((ng.x, ng.y, ng.z)) + w
        a = d[0] * xs[0] + d[1] * xs[1]
        b = e[0] * xs[0] + e[1] * xs[1]
        radius = 1.0 / kappa
        ang = kappa * xs[2]
        a_def = radius - (radius - a) * ng.cos(ang)
        z_def = (radius - a) * ng.sin(ang)
        px = a_def * d[0] + b * e[0]
        py = a_def * d[1] + b * e[1]
        self.p.u.Set(ng.CF((px - ng.x, py - ng.y, z_def - ng.z)))

    def predict(self, t0, s0, k0, t1, s1, k1, t) -> np.ndarray | None:
        """States s0, s1 at loads t0, t1 with fitted curvature vectors k0, k1 (1/m). None when
        the bend is too small for a frame (the caller then uses the tangent)."""
        k0, k1 = np.asarray(k0), np.asarray(k1)
        f = (t - t1) / (t1 - t0)
        k = k1 + f * (k1 - k0)
        kap0, kap1, kap = (float(np.hypot(*v)) for v in (k0, k1, k))
        if min(kap0, kap1, kap) < 1e-3:   # 1/m: practically straight
            return None
        import ngsolve as ng

        with ng.TaskManager():
            self.p.set_state(s0)
            self._to_straight(self.w0, kap0, k0 / kap0)
            self.p.set_state(s1)
            self._to_straight(self.w1, kap1, k1 / kap1)
            w = ng.GridFunction(self.wspace)
            w.vec.data = (1.0 + f) * self.w1.vec - f * self.w0.vec
            self.p.set_state(s1 + f * (s1 - s0))   # q (and anything else) by the plain secant
            self._from_straight(w, kap, k / kap)
            vec = self.p.gf.vec.FV().NumPy()
            vec[self.fixed] = 0.0
        return self.p.get_state()
