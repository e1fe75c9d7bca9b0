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
Tip cap: the last ``cap`` (m) of the body has no channel; it is a rigid straight piece along the last
joint's angle theta_N (the section law is the channelled part's, and a cap of a few percent of the
length carries only the moment of the loads on it), so the tip is r_N + cap t(theta_N), the loads at
the tip act on joint N through the arm cap t, the cap's weight through cap t / 2, and an unloaded
body is the source rung's arc with the straight cap beyond it (core/prediction.arc_and_cap).
Tip contact with a plane (frictionless, the tip free to rotate): n . (r_tip - c) >= 0, with the
reaction R n, R >= 0, and R (n . (r_tip - c)) = 0 (solved as: free first; if the tip would cross
the plane, with the constraint active, R as an unknown).

Base hinge: bent back (a blocked tip), the section's moment peaks (LawSlice.limit_moment_if_peaked:
the lumen closes and the section flattens, and the held section soon stops converging). A base
asked for more cannot follow; it kinks. The kink is a hinge at the clamp carrying the limit
moment M_lim with its rotation phi = theta_0 <= 0 as an unknown and the clamp's balance as its
equation, F_0 = M_lim - m_1 - (Delta r_1 x G_1) / 2 = 0 (a plastic hinge: because |M| is flat
about its peak, the force depends on M_lim, not on how long the kink is). Admissible while phi <= 0,
R >= 0 and no segment is bent past the limit curvature; otherwise a named stop.

Snap: bent back, |M| can fold, dip (the lumen closing) and rise again to the limit
(LawSlice.snap_fold). A segment whose moment grows past the fold snaps to the outer branch; Newton
from the inner branch cycles about the fold, so a blocked solve that fails is retried with the most
loaded inner segment moved to the outer branch (``_newton_snapping``), and a hinged state with a
segment on the falling side of the flat peak from that segment on the rising side.

Newton with the exact Jacobian on the N (+2) unknowns (dense, N ~ 40: tens of microseconds per
solve of the linear system); why not
shooting: the law is a table, and a clamped-free problem with a contact is a two-point problem
whose shooting would integrate the table many times per evaluation.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..continuation import LIMIT_POINT, NUMERICAL_FAILURE
from ..units import PA_PER_BAR
from .law import LawRangeError, LawSlice
from .loads import PlanarLoads


@dataclass
class RodSolution:
    theta: np.ndarray        # (N+1,) rad, section angles at the joints (theta_0 = 0)
    positions: np.ndarray    # (N+1, 2) m, joints in (a, b), and the tip (N+2) when the body has a cap
    kappa: np.ndarray        # (N,) 1/m per reference length, per segment
    arc_length: float        # m, deformed, of the channelled part (the cap excluded)
    contact_force: float     # N, normal reaction of the plane (0 without contact)
    converged: bool
    message: str = ""
    iterations: int = 0
    hinge_rotation: float = 0.0          # rad, the base hinge's rotation (0: clamped, no hinge)
    hinge_moment: float | None = None    # N m, the limit moment the hinge carries (None: no hinge)
    stop_reason: str = ""                # continuation's stop reasons; empty when converged


def _sinc_and_slope(x):
    s = np.sinc(x / np.pi)
    small = np.abs(x) < 1e-4
    xs = np.where(small, 1.0, x)
    ds = np.where(small, -x / 3.0, (np.cos(xs) - s) / xs)
    return s, ds


class _Rod:
    """The discrete rod. A state is (th, R): th (N+1,) the joint angles with th[0] the base hinge's
    rotation phi (0 while the base is clamped), R the contact reaction (N). ``system`` gives the
    equations and Jacobian for a choice of unknowns (phi free or not, R free or not) and equations
    (the hinge's moment on joint 0 or not, the tip on the plane or not)."""

    def __init__(self, law: LawSlice, length: float, loads: PlanarLoads, n: int, cap: float = 0.0):
        """``length``: the body's reference length (m), of which the last ``cap`` is the rigid tip cap."""
        self.law, self.n, self.cap = law, int(n), float(cap)
        self.L = float(length) - self.cap            # the channelled part, cut into segments
        self.h = self.L / self.n
        z_mid = (np.arange(self.n) + 0.5) * self.h
        weight = np.asarray(loads.weight_per_length, float)
        self.tip_load = np.asarray(loads.tip_force, float)
        self.cap_weight = self.cap * weight
        self.G0 = (self.tip_load + self.cap_weight)[None, :] + np.outer(self.L - z_mid, weight)
        self.contact = loads.contact
        self.normal = np.zeros(2) if loads.contact is None else np.asarray(loads.contact.normal, float)
        # segment i joins joints i and i + 1 (joint 0 the base): kappa = B th / h, mid angle = A th
        B = np.zeros((self.n, self.n + 1))
        B[np.arange(self.n), np.arange(self.n)] = -1.0
        B[np.arange(self.n), np.arange(self.n) + 1] = 1.0
        self.B, self.A = B, 0.5 * np.abs(B)
        self.f_scale = max(abs(float(law.slope(0.0))) / self.L, 1e-30)   # N m per rad: moments -> radians

    def geometry(self, th):
        h = self.h
        kap = self.B @ th / h
        mid = self.A @ th
        lam = np.asarray(self.law.stretch(kap), float)
        dlam = np.asarray(self.law.stretch_slope(kap), float)
        s, ds = _sinc_and_slope(0.5 * h * kap)
        ell = h * lam * s
        dell = h * (dlam * s + lam * ds * 0.5 * h)
        t = np.stack([np.cos(mid), np.sin(mid)], -1)
        tp = np.stack([-np.sin(mid), np.cos(mid)], -1)
        return kap, ell, dell, t, tp, lam

    def tip(self, th, ell, t):
        """The tip (a, b): the last joint and the cap along its angle."""
        return ell @ t + self.cap * np.array([np.cos(th[-1]), np.sin(th[-1])])

    def gap(self, th) -> float:
        if self.contact is None:
            return np.inf
        _, ell, _, t, _, _ = self.geometry(th)
        return float(self.normal @ (self.tip(th, ell, t) - np.asarray(self.contact.point, float)))

    def clamp_moment(self, th, R: float = 0.0, load_scale: float = 1.0) -> float:
        """The moment the base carries (N m, the law's sign): the clamp's (or the hinge's) reaction."""
        kap, ell, _, _, tp, _ = self.geometry(th)
        G = load_scale * self.G0[0] + R * self.normal
        return float(self.law.moment(kap[:1])[0]) + 0.5 * float(ell[0] * (tp[0] @ G))

    def system(self, th, R, hinge_moment=None, free_phi=False, free_R=False, gap_row=False, load_scale=1.0):
        """(F, J): moment balance about the joints as virtual work, F = B^T m - A^T q (row j: joint j;
        row 0, the base, only with the hinge, whose moment it then carries), plus the gap
        n . (r_tip - c) when ``gap_row``; unknowns phi (if ``free_phi``), theta_1..N, R (if ``free_R``)."""
        kap, ell, dell, t, tp, _ = self.geometry(th)
        G = load_scale * self.G0 + R * self.normal
        m = np.asarray(self.law.moment(kap), float)
        S = np.asarray(self.law.slope(kap), float)
        tpG = np.einsum("ij,ij->i", tp, G)
        tG = np.einsum("ij,ij->i", t, G)
        A, B, h = self.A, self.B, self.h
        F = B.T @ m - A.T @ (ell * tpG)
        J = (B.T * (S / h)) @ B + (A.T * (ell * tG)) @ A - (A.T * (dell * tpG / h)) @ B
        if self.cap > 0:   # the tip's loads and the cap's weight on the last joint, through the rigid cap
            c, s = np.cos(th[-1]), np.sin(th[-1])
            g_cap = load_scale * (self.tip_load + 0.5 * self.cap_weight) + R * self.normal
            F[-1] -= self.cap * (-s * g_cap[0] + c * g_cap[1])
            J[-1, -1] += self.cap * (c * g_cap[0] + s * g_cap[1])
        rows = np.arange(0 if hinge_moment is not None else 1, self.n + 1)
        cols = np.arange(0 if free_phi else 1, self.n + 1)
        if hinge_moment is not None:
            F[0] += hinge_moment
        F, J = F[rows], J[np.ix_(rows, cols)]
        tp_tip = np.array([-np.sin(th[-1]), np.cos(th[-1])])
        if free_R:
            dR = -A.T @ (ell * (tp @ self.normal))
            dR[-1] -= self.cap * (tp_tip @ self.normal)
            J = np.column_stack([J, dR[rows]])
        if gap_row:
            dg = A.T @ (ell * (tp @ self.normal)) + B.T @ (dell * (t @ self.normal) / h)
            dg[-1] += self.cap * (tp_tip @ self.normal)
            dg = dg[cols]
            F = np.append(F, self.normal @ (self.tip(th, ell, t) - np.asarray(self.contact.point, float)))
            J = np.vstack([J, np.append(dg, 0.0) if free_R else dg])
        return F, J

    def newton(self, th0, R0=0.0, hinge_moment=None, free_phi=False, free_R=False, gap_row=False,
               load_scale=1.0, tol=1e-11, max_iterations=40):
        """Newton on the chosen unknowns from (th0, R0): (th, R, converged, iterations, message)."""
        th, R = np.array(th0, dtype=float), float(R0)
        first = 0 if free_phi else 1
        n_ang = self.n + 1 - first
        kw = dict(hinge_moment=hinge_moment, free_phi=free_phi, free_R=free_R, gap_row=gap_row,
                  load_scale=load_scale)
        for it in range(1, max_iterations + 1):
            F, J = self.system(th, R, **kw)
            try:
                dz = np.linalg.solve(J, -F)
            except np.linalg.LinAlgError:
                return th, R, False, it, "singular rod Jacobian"
            if not np.all(np.isfinite(dz)):
                return th, R, False, it, "non-finite rod Newton step"
            big = float(np.max(np.abs(dz[:n_ang])))
            alpha = min(1.0, 0.3 / big) if big > 0 else 1.0   # at most 0.3 rad per step
            th[first:] += alpha * dz[:n_ang]
            if free_R:
                R += alpha * float(dz[n_ang])
            if alpha == 1.0 and big < tol:
                F, _ = self.system(th, R, **kw)
                n_m = len(F) - int(gap_row)
                if np.max(np.abs(F[:n_m])) / self.f_scale < 1e-8 and (not gap_row or abs(F[-1]) < 1e-9 * self.L):
                    return th, R, True, it, ""
        return th, R, False, max_iterations, f"rod Newton did not converge in {max_iterations} iterations"

    def solution(self, th, R, converged, message, iterations, stop_reason: str = "",
                 hinge_moment: float | None = None) -> RodSolution:
        kap, ell, _, t, _, lam = self.geometry(th)
        pos = np.vstack([[0.0, 0.0], np.cumsum(ell[:, None] * t, 0)])
        if self.cap > 0:
            pos = np.vstack([pos, self.tip(th, ell, t)])
        return RodSolution(theta=np.array(th, dtype=float), positions=pos, kappa=kap,
                           arc_length=float(np.sum(lam) * self.h), contact_force=float(max(R, 0.0)),
                           converged=converged, message=message, iterations=iterations,
                           hinge_rotation=float(th[0]), hinge_moment=hinge_moment,
                           stop_reason="" if converged else (stop_reason or NUMERICAL_FAILURE))


class _Stop(Exception):
    """A solve that ends without an admissible state: its reason and the last state."""

    def __init__(self, message, reason, th, R, iterations):
        super().__init__(message)
        self.message, self.reason, self.th, self.R, self.iterations = message, reason, th, R, iterations


def solve_rod(law: LawSlice, length: float, loads: PlanarLoads = PlanarLoads(), n_segments: int = 40,
              guess: RodSolution | None = None, hinge: bool = True, cap: float = 0.0) -> RodSolution:
    """Static equilibrium of the clamped rod; raises ``LawRangeError`` when the solution needs
    curvatures outside the law's table (``converged=False`` and a ``stop_reason`` for a solve that
    failed otherwise).

    ``length``: the body's reference length (m), of which the last ``cap`` is the tip cap, rigid and
    straight (no channel). ``guess``: a converged solution at a nearby load (pressure continuation: ``RodModel.solve``
    ramps the pressure of a blocked body so that it stays on the branch the bench follows, the tip
    on the plane from p = 0). ``hinge``: when the base would have to carry more than the section's
    limit moment (bent back; ``LawSlice.limit_moment_if_peaked``) or bend past its limit curvature,
    the base becomes a hinge that carries exactly that moment and rotates back by
    ``hinge_rotation``: a plastic hinge (the section's moment is flat about its peak, so the extra
    rotation is a kink at the clamp whose moment, not its length, enters the statics;
    docs/models/rod.md)."""
    rod = _Rod(law, length, loads, n_segments, cap)
    limit = law.limit_moment_if_peaked() if hinge else None
    m_lim = None if limit is None else limit[0]
    try:
        if loads.contact is not None and guess is not None and guess.converged and guess.contact_force > 0:
            th, R, hinged, its = _continue_contact(rod, law, limit, guess)
            return rod.solution(th, R, True, "", its, hinge_moment=m_lim if hinged else None)
        z = np.arange(n_segments + 1) * rod.h
        k_free = law.free_curvature()
        if k_free is None and np.isfinite(law.kappa_hi):
            # the tip carries no moment, so its segment is at (with a cap, near) the free curvature whatever the loads
            raise LawRangeError(f"{law.source}: at p = {law.pressure / PA_PER_BAR:.4f} bar the free curvature is beyond "
                                f"the moment-curvature table ({law.kappa_lo:.4g}..{law.kappa_hi:.4g} 1/m)")
        free = k_free * z if k_free is not None else np.zeros(n_segments + 1)
        start = free if guess is None else np.concatenate([[0.0], np.asarray(guess.theta, float)[1:]])
        th, _, ok, its, msg = rod.newton(start)
        if not ok:
            # load continuation from the unloaded body
            th, scale, ok = free.copy(), 0.0, True
            step = 0.25
            while ok and scale < 1.0:
                trial = min(1.0, scale + step)
                t2, _, good, n_it, msg = rod.newton(th, load_scale=trial)
                its += n_it
                if good:
                    th, scale = t2, trial
                elif step > 1 / 64:
                    step /= 2
                else:
                    ok = False
        R = 0.0
        if loads.contact is not None and (not ok or rod.gap(th) < -1e-12 * rod.L):
            t2, R, ok_c, n_it, msg = rod.newton(np.zeros(n_segments + 1), 0.0, free_R=True, gap_row=True)
            its += n_it
            if not ok_c and ok:
                t2, R, ok_c, n_it, msg = rod.newton(th, 0.0, free_R=True, gap_row=True)
                its += n_it
            th, ok = t2, ok_c
            if ok and R < 0:
                raise _Stop(f"the contact solve found a pulling reaction ({R:.3g} N), no admissible contact state",
                            NUMERICAL_FAILURE, th, 0.0, its)
        if not ok:
            raise _Stop(msg, NUMERICAL_FAILURE, th, R, its)
        if not _over(rod, th, R, limit):
            _check(law, rod.geometry(th)[0], limit)
            return rod.solution(th, R, True, "", its)
        contact = loads.contact is not None and R > 0
        t2, R2, ok2, n_it, msg2 = rod.newton(th, R, hinge_moment=m_lim, free_phi=True, free_R=contact,
                                             gap_row=contact)
        its += n_it
        if not ok2:
            raise _Stop(f"with the base at its limit moment: {msg2}", NUMERICAL_FAILURE, t2, R2, its)
        _admissible(rod, law, limit, t2, R2, its)
        return rod.solution(t2, R2, True, "", its, hinge_moment=m_lim)
    except _Stop as stop:
        return rod.solution(stop.th, stop.R, False, stop.message, stop.iterations, stop.reason, m_lim)


def _check(law: LawSlice, kappa, limit) -> None:
    """``law.check`` (LawRangeError outside the table), saying so when the base is bent back past the
    table's end before the section's moment peaked: its capacity there is not known."""
    if limit is None and np.isfinite(law.kappa_lo) and float(np.min(kappa)) < law.kappa_lo - 1e-9:
        raise LawRangeError(
            f"{law.source}: at p = {law.pressure / PA_PER_BAR:.4f} bar the blocked base is bent back to "
            f"{float(np.min(kappa)):.4g} 1/m, past the table's end ({law.kappa_lo:.4g} 1/m) before the section's "
            "moment peaks: its capacity there is not known (a wider table, kappa_min, would say)")
    law.check(kappa)


def _over(rod: _Rod, th, R, limit) -> bool:
    """The clamped base carries more than the limit moment, or a segment is bent back past its
    limit curvature (the falling side of the section's moment)."""
    if limit is None:
        return False
    kap = rod.geometry(th)[0]
    return abs(rod.clamp_moment(th, R)) > abs(limit[0]) * (1 + 1e-9) or float(kap.min()) < limit[1] - 1e-9


def _admissible(rod: _Rod, law: LawSlice, limit, th, R, its) -> None:
    """Raise _Stop (or LawRangeError) unless a hinged state is one: the hinge bent back (phi <= 0),
    R >= 0, no segment past the limit curvature, every curvature in the table."""
    m_lim, k_lim = limit
    kap = rod.geometry(th)[0]
    if th[0] > 1e-12:
        raise _Stop(f"the base is at its limit moment ({m_lim * 1e3:.4g} mN m) but its hinge would open forwards "
                    f"({th[0]:.3g} rad): no admissible state", NUMERICAL_FAILURE, th, R, its)
    if R < 0:
        raise _Stop(f"with the base at its limit moment the contact pulls ({R:.3g} N)", NUMERICAL_FAILURE, th, R, its)
    if float(kap.min()) < k_lim - 1e-9:
        i = int(np.argmin(kap))
        raise _Stop(f"with the base hinged at its limit moment ({m_lim * 1e3:.4g} mN m) segment {i + 1} is bent "
                    f"back past the limit curvature too ({kap[i]:.4g} < {k_lim:.4g} 1/m): a second kink, "
                    "which the rod does not model", LIMIT_POINT, th, R, its)
    _check(law, kap, limit)


def _snap(rod: _Rod, law: LawSlice, fold, th, snapped: set):
    """The state ``th`` with one more segment snapped across the lumen's dip (``LawSlice.snap_fold``):
    of the segments on the inner branch whose moment also has a curvature on the outer one, the most
    loaded (the one nearest the fold), its curvature set to the outer branch's with the same moment
    and the joints beyond it turned with it. None when no segment can snap."""
    _, k_dip, k_lim = fold
    kap = rod.geometry(th)[0]
    m = np.abs(np.asarray(law.moment(kap), float))
    inner = [i for i in np.argsort(-m) if k_dip < kap[i] < 0 and i not in snapped]
    for i in inner:
        k_out = law.outer_branch_curvature(m[i], branch=(k_dip, k_lim))
        if k_out is not None:
            kap = kap.copy()
            kap[i] = k_out
            snapped.add(int(i))
            return _with_curvatures(rod, th, kap)
    return None


def _with_curvatures(rod: _Rod, th, kap):
    """The joint angles of ``th`` (its base angle kept) with the segments' curvatures ``kap``."""
    out = np.array(th, dtype=float)
    out[1:] = th[0] + rod.h * np.cumsum(kap)
    return out


def _rising_side(rod: _Rod, law: LawSlice, th, k_lim: float):
    """``th`` with every segment bent back past the limit curvature put on the rising side of the
    law with the same moment (``LawSlice.outer_branch_curvature``), the joints beyond turned with
    it; None when no segment is past the limit or one has no such curvature."""
    kap = rod.geometry(th)[0]
    past = np.flatnonzero(kap < k_lim - 1e-9)
    branch = law.outer_branch() if len(past) else None
    if branch is None:
        return None
    kap = kap.copy()
    for i in past:
        k_in = law.outer_branch_curvature(float(law.moment(kap[i])), branch=branch)
        if k_in is None:
            return None
        kap[i] = k_in
    return _with_curvatures(rod, th, kap)


def _newton_snapping(rod: _Rod, law: LawSlice, th0, R0, max_snaps: int = 3, k_lim: float | None = None, **kw):
    """``rod.newton`` from (th0, R0); if it fails, again after snapping segments across the lumen's
    dip one by one (the most loaded first, at most ``max_snaps``); if it converges with a segment
    bent back past the limit curvature ``k_lim`` (the falling side: |M| is flat about its peak, so
    a moment just under the limit has a curvature on either side), again from that segment on the
    rising side, with the same moment.

    Bent back, the section's |M| can rise to a fold, dip where the lumen closes and rise again to
    its limit (``LawSlice.snap_fold``). A segment whose moment grows past the fold has no state on
    its branch nearby: the section snaps (the lumen closes) to the outer branch with the same
    moment. Newton started on the inner branch cycles about the fold (the segment's slope changes
    sign from one iterate to the next) instead of crossing the dip; started with that segment on
    the outer branch it converges. The dip is shallow (under 1 % of the moment), so the segment
    snaps within a fraction of a pressure step of its fold. A state still past the limit is
    returned as converged: the caller names it (a second kink)."""
    th, R, ok, its, msg = rod.newton(th0, R0, **kw)
    if ok and k_lim is not None:
        start = _rising_side(rod, law, th, k_lim)
        if start is not None:
            t2, R2, ok2, n_it, _ = rod.newton(start, R, **kw)
            its += n_it
            if ok2 and float(rod.geometry(t2)[0].min()) >= k_lim - 1e-9:
                return t2, R2, True, its, ""
        return th, R, ok, its, msg
    fold = None if ok else law.snap_fold()
    start, snapped = np.array(th0, dtype=float), set()
    for _ in range(max_snaps if fold is not None else 0):
        start = _snap(rod, law, fold, start, snapped)
        if start is None:
            break
        th, R, ok, n_it, msg = rod.newton(start, R0, **kw)
        its += n_it
        if ok:
            break
    return th, R, ok, its, msg


def _continue_contact(rod: _Rod, law: LawSlice, limit, guess: RodSolution):
    """The blocked state from one at a nearby pressure: clamped or hinged, as the guess was first;
    the other when the clamped base passes the limit moment or the hinge would open forwards."""
    th0, R0 = np.array(guess.theta, dtype=float), float(guess.contact_force)
    modes = ["clamped"] if limit is None else (
        ["hinged", "clamped"] if guess.hinge_moment is not None else ["clamped", "hinged"])
    its, reasons = 0, []
    for mode in modes:
        if mode == "clamped":
            start = th0.copy()
            start[0] = 0.0
            th, R, ok, n_it, msg = _newton_snapping(rod, law, start, R0, free_R=True, gap_row=True)
            its += n_it
            if ok and R >= 0 and not _over(rod, th, R, limit):
                _check(law, rod.geometry(th)[0], limit)
                return th, R, False, its
            reasons.append("clamped: " + (msg if not ok else f"the contact pulls ({R:.3g} N)" if R < 0
                                          else "past the limit moment"))
        else:
            th, R, ok, n_it, msg = _newton_snapping(rod, law, th0, R0, k_lim=limit[1], hinge_moment=limit[0],
                                                    free_phi=True, free_R=True, gap_row=True)
            its += n_it
            if ok and th[0] <= 1e-12 and R >= 0:
                _admissible(rod, law, limit, th, R, its)
                return th, R, True, its
            reasons.append(f"hinged at {limit[0] * 1e3:.4g} mN m: " + (
                msg if not ok else f"the hinge opens forwards ({th[0]:.3g} rad)" if th[0] > 0
                else f"the contact pulls ({R:.3g} N)"))
    raise _Stop("the blocked state does not continue from the last pressure (" + "; ".join(reasons) + ")",
                NUMERICAL_FAILURE, th0, R0, its)


__all__ = ["LawRangeError", "PlanarLoads", "RodSolution", "solve_rod"]
