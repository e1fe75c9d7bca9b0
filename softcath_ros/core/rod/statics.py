"""Planar Kirchhoff rod statics: a clamped body with a moment-curvature law, dead loads and tip contact.

Coordinates in the bending plane: a along the unbent axis (softcath_base z), b along the bending
direction e. The body (reference length L) is cut into N segments of reference length h; the
unknowns are the section angles theta_j at the joints Z_j = j h (theta_0 = 0: clamped base).
Segment i is a circular arc of curvature kappa_i = (theta_i - theta_{i-1}) / h (per reference
length), arc length lambda(kappa_i) h (the law's stretch at zero axial force) and mid angle
phi_i; its chord is Delta r_i = lambda h sinc(kappa_i h / 2) t(phi_i), so an unloaded body is
exactly the source rung's arc.

Moment balance about joint j, with m_i = M(kappa_i, p) the moment in segment i and G_i the force
the distal part exerts on segment i's middle (tip force + contact reaction + distal weight):
    m_j - m_{j+1} = (Delta r_j x G_j + Delta r_{j+1} x G_{j+1}) / 2,        m_{N+1} = 0.
Tip contact with a plane (frictionless, the tip free to rotate): n . (r_tip - c) >= 0, with the
reaction R n, R >= 0, and R (n . (r_tip - c)) = 0 (solved as: free first; if the tip would cross
the plane, with the constraint active, R as an unknown). Newton with the exact Jacobian on the
N (+1) unknowns (dense, N ~ 40: tens of microseconds per solve of the linear system); why not
shooting: the law is a table, and a clamped-free problem with a contact is a two-point problem
whose shooting would integrate the table many times per evaluation.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .law import LawRangeError, LawSlice


@dataclass(frozen=True)
class PlaneContact:
    """A plane the tip may touch: ``normal`` (a, b) unit, pointing to the side the tip stays on;
    ``point`` (a, b) on the plane (m)."""

    normal: tuple[float, float]
    point: tuple[float, float]


@dataclass(frozen=True)
class PlanarLoads:
    tip_force: tuple[float, float] = (0.0, 0.0)          # N, (a, b)
    weight_per_length: tuple[float, float] = (0.0, 0.0)  # N per m of reference length, (a, b)
    contact: PlaneContact | None = None


@dataclass
class RodSolution:
    theta: np.ndarray        # (N+1,) rad, section angles at the joints (theta_0 = 0)
    positions: np.ndarray    # (N+1, 2) m, joints in (a, b)
    kappa: np.ndarray        # (N,) 1/m per reference length, per segment
    arc_length: float        # m, deformed
    contact_force: float     # N, normal reaction of the plane (0 without contact)
    converged: bool
    message: str = ""
    iterations: int = 0


def _sinc_and_slope(x):
    s = np.sinc(x / np.pi)
    small = np.abs(x) < 1e-4
    xs = np.where(small, 1.0, x)
    ds = np.where(small, -x / 3.0, (np.cos(xs) - s) / xs)
    return s, ds


class _Rod:
    def __init__(self, law: LawSlice, length: float, loads: PlanarLoads, n: int):
        self.law, self.L, self.n = law, float(length), int(n)
        self.h = self.L / self.n
        z_mid = (np.arange(self.n) + 0.5) * self.h
        self.G0 = np.asarray(loads.tip_force, float)[None, :] + np.outer(self.L - z_mid,
                                                                         np.asarray(loads.weight_per_length, float))
        self.contact = loads.contact
        B = np.eye(self.n) - np.eye(self.n, k=-1)
        A = 0.5 * (np.eye(self.n) + np.eye(self.n, k=-1))
        self.A, self.B = A, B

    def geometry(self, theta):
        h = self.h
        th = np.concatenate([[0.0], theta])
        kap = np.diff(th) / h
        phi = 0.5 * (th[:-1] + th[1:])
        lam = np.asarray(self.law.stretch(kap), float)
        dlam = np.asarray(self.law.stretch_slope(kap), float)
        s, ds = _sinc_and_slope(0.5 * h * kap)
        ell = h * lam * s
        dell = h * (dlam * s + lam * ds * 0.5 * h)
        t = np.stack([np.cos(phi), np.sin(phi)], -1)
        tp = np.stack([-np.sin(phi), np.cos(phi)], -1)
        return kap, ell, dell, t, tp, lam

    def residual(self, theta, R, with_contact: bool, load_scale: float = 1.0):
        kap, ell, dell, t, tp, _ = self.geometry(theta)
        G = load_scale * self.G0
        if with_contact:
            nrm = np.asarray(self.contact.normal, float)
            G = G + R * nrm
        m = np.asarray(self.law.moment(kap), float)
        S = np.asarray(self.law.slope(kap), float)
        tpG = np.einsum("ij,ij->i", tp, G)
        tG = np.einsum("ij,ij->i", t, G)
        q = ell * tpG
        F1 = self.B.T @ m - self.A.T @ q
        J = (self.B.T * (S / self.h)) @ self.B + (self.A.T * (ell * tG)) @ self.A \
            - (self.A.T * (dell * tpG / self.h)) @ self.B
        if not with_contact:
            return F1, J, None
        c = np.asarray(self.contact.point, float)
        tip = ell @ t
        g = float(nrm @ (tip - c))
        dF1_dR = -self.A.T @ (ell * (tp @ nrm))
        dg = self.A.T @ (ell * (tp @ nrm)) + self.B.T @ (dell * (t @ nrm) / self.h)
        Jf = np.zeros((self.n + 1, self.n + 1))
        Jf[:self.n, :self.n] = J
        Jf[:self.n, self.n] = dF1_dR
        Jf[self.n, :self.n] = dg
        return np.concatenate([F1, [g]]), Jf, g

    def newton(self, theta0, R0, with_contact: bool, load_scale: float = 1.0, tol: float = 1e-11,
               max_iterations: int = 40):
        theta, R = theta0.copy(), float(R0)
        f_scale = max(abs(float(self.law.slope(0.0))) / self.L, 1e-30)   # N m per rad: moments -> radians
        for it in range(1, max_iterations + 1):
            F, J, _ = self.residual(theta, R, with_contact, load_scale)
            try:
                dz = np.linalg.solve(J, -F)
            except np.linalg.LinAlgError:
                return theta, R, False, it, "singular rod Jacobian"
            if not np.all(np.isfinite(dz)):
                return theta, R, False, it, "non-finite rod Newton step"
            dth = dz[:self.n]
            big = float(np.max(np.abs(dth)))
            alpha = min(1.0, 0.3 / big) if big > 0 else 1.0   # at most 0.3 rad per step
            theta = theta + alpha * dth
            if with_contact:
                R += alpha * float(dz[self.n])
            if alpha == 1.0 and big < tol:
                F, _, _ = self.residual(theta, R, with_contact, load_scale)
                if np.max(np.abs(F[:self.n])) / f_scale < 1e-8:
                    return theta, R, True, it, ""
        return theta, R, False, max_iterations, f"rod Newton did not converge in {max_iterations} iterations"

    def solution(self, theta, R, converged, message, iterations) -> RodSolution:
        kap, ell, _, t, _, lam = self.geometry(theta)
        pos = np.vstack([[0.0, 0.0], np.cumsum(ell[:, None] * t, 0)])
        return RodSolution(theta=np.concatenate([[0.0], theta]), positions=pos, kappa=kap,
                           arc_length=float(np.sum(lam) * self.h), contact_force=float(R),
                           converged=converged, message=message, iterations=iterations)


def solve_rod(law: LawSlice, length: float, loads: PlanarLoads = PlanarLoads(), n_segments: int = 40,
              guess: np.ndarray | None = None) -> RodSolution:
    """Static equilibrium of the clamped rod; raises ``LawRangeError`` when the solution needs
    curvatures outside the law's table (``converged=False`` for a solve that failed otherwise)."""
    rod = _Rod(law, length, loads, n_segments)
    z = (np.arange(n_segments) + 1) * rod.h
    k_free = law.free_curvature()
    free = k_free * z if k_free is not None else np.zeros(n_segments)
    start = free if guess is None else np.asarray(guess, float)[1:]
    theta, _, ok, its, msg = rod.newton(start, 0.0, False)
    if not ok:
        # load continuation from the unloaded body
        theta, scale, ok = free.copy(), 0.0, True
        step = 0.25
        while ok and scale < 1.0:
            trial = min(1.0, scale + step)
            th, _, good, n_it, msg = rod.newton(theta, 0.0, False, load_scale=trial)
            its += n_it
            if good:
                theta, scale = th, trial
            elif step > 1 / 64:
                step /= 2
            else:
                ok = False
    if loads.contact is not None:
        free_ok = ok
        gap = rod.residual(theta, 0.0, True)[2] if free_ok else -1.0
        if not free_ok or gap < -1e-12 * rod.L:
            th_c, R, ok_c, n_it, msg_c = rod.newton(np.zeros(n_segments), 0.0, True)
            its += n_it
            if not ok_c:
                th_c, R, ok_c, n_it, msg_c = rod.newton(theta, 0.0, True)
                its += n_it
            if ok_c and R >= 0:
                law.check(rod.geometry(th_c)[0])
                return rod.solution(th_c, R, True, "", its)
            why = (f"the contact solve found a pulling reaction ({R:.3g} N), no admissible contact state"
                   if ok_c else (msg_c or "contact did not converge"))
            return rod.solution(th_c, max(R, 0.0), False, why, its)
    if ok:
        law.check(rod.geometry(theta)[0])
    return rod.solution(theta, 0.0, ok, "" if ok else msg, its)


__all__ = ["LawRangeError", "PlaneContact", "PlanarLoads", "RodSolution", "solve_rod"]
