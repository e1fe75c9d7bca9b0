"""Newton on the 3D problem (core/fe3d/solver.py ``Fe3dProblem``, into which it is mixed): a solve at
one load, with its factorisation reused while Newton contracts, a line search that keeps elements
from inverting and the lumen wall from crossing itself, the contact pairs settled at convergence,
and optionally the shifted tangent past a saddle."""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

log = logging.getLogger(__name__)


# a Newton iteration on a reused factorisation costs about a quarter of one that factorises (the
# 20 mm default body: 0.16-0.21 s against 0.76-0.86 s): the weight of such iterations in a solve's
# effort, by which the ramp sizes its steps
REUSED_ITERATION_COST = 0.25
# why a step was shortened to descend (NewtonSettings.descent_in_contact)
RAISES_ENERGY = "raises the energy"
# on a reused factorisation |du.r| only estimates the energy error: a solve ends there at this
# fraction of the tolerance
REUSED_TOLERANCE = 0.1


@dataclass
class _Solve:
    """The bookkeeping of one Newton solve (Fe3dProblem._newton)."""
    budget: float               # iterations allowed (those on a reused factorisation count less)
    tol: float                  # |du.r| (J) below which an iterate is converged
    searches: int = 0           # contact pair searches at convergence
    work: float = math.inf      # the last iteration's |du.r|
    works: list = field(default_factory=list)   # |du.r| per iteration since the last such search
    chord: np.ndarray | None = None   # where the last step, taken with a reused factorisation, began
    last_work: float = math.inf       # the last increment's |du.r|
    cuts_in_row: int = 0        # iterations in a row whose full step was rejected
    indefinite: float = math.inf   # the smallest |du.r| of a fresh increment with du.r < -tol since that search


@dataclass(frozen=True)
class Stall:
    """A stalled Newton solve (Fe3dNewton.stalled), where the ramp's stop is named (ramp.py ``_at_the_stall``):
    its load (Pa), last iterate, that iterate's |du.r| (J) and in Newton's tolerances, and the fewest
    tolerances at which its tangent was indefinite (a fresh increment with du.r < -tol; inf: never)."""
    load: float
    state: np.ndarray
    work: float
    tolerances: float
    indefinite: float = math.inf


class NewtonFailure(Exception):
    """One Newton solve failed; ``reason`` says how (diverged, inverted, max iterations); ``stall``: where
    a stalled solve stalled (None for other failures)."""

    def __init__(self, reason: str, iterations: int, stall: Stall | None = None):
        super().__init__(reason)
        self.reason = reason
        self.iterations = iterations
        self.stall = stall


class Fe3dNewton:
    """The Newton solve of ``Fe3dProblem`` (a mixin: it reads the problem's forms, state and settings)."""

    def _factorize(self):
        self.a.AssembleLinearization(self.gf.vec)
        self.inverse = self.a.mat.Inverse(self.free, inverse="sparsecholesky")
        self.factor_age = 0
        self.factorizations += 1

    def _refactor_now(self, it: int) -> bool:
        """Whether Newton iteration ``it`` of a solve factorises afresh (NewtonSettings.reuse_ratio):
        the first always (the load, and with it the pressures' follower stiffness, has changed)."""
        st = self.newton_settings
        return (it == 1 or self.inverse is None or st.reuse_ratio is None or self.shift is not None
                or self.factor_age >= st.reuse_age)

    def _full_step_admissible(self, base) -> bool:
        """Is base - du (the full Newton step) an admissible state? Leaves the state at base."""
        self.gf.vec.data -= self.du
        ok = not self._rejection(locate=False)
        self.set_state(base)
        return ok

    def _solve(self, rhs, out):
        """Solve with the last linearisation, static condensation included (rhs is modified)."""
        a = self.a
        rhs.data += a.harmonic_extension_trans * rhs
        out.data = self.inverse * rhs
        out.data += a.harmonic_extension * out
        out.data += a.inner_solve * rhs

    def _contact_pairs_settled(self) -> bool:
        """Search the contact pairs again at the converged state; True when the new pairs leave
        it in equilibrium: the Newton increment for them (with the last factorisation) below the
        tolerance, or their residual force below ``contact.settle_force`` of the pressure load
        (both as Euclidean norms over the free unknowns). The search is not a smooth function of
        the state (NGSolve's closest point is a few steps of an approximate projection, and the
        P2 wall has kinks at element edges), so once the walls touch a fresh search at a
        converged state leaves a residual of 1e-5 to 2e-4 of the load (|du.r| 1e-11 to 1e-10 J
        on the coarse 10 mm body, above the tolerance of 2e-12 J) however often it is repeated.
        Between searches the pairs are fixed, so Newton is quadratic on them."""
        import ngsolve as ng

        if not self.contact.update():
            return True   # the walls far apart: no search can change the (empty) contact term
        self.a.Apply(self.gf.vec, self.res)
        force = float(np.linalg.norm(self.res.FV().NumPy()[self.free_mask]))
        du = self.gf.vec.CreateVector()
        self._solve(self.res, du)
        self.a.Apply(self.gf.vec, self.res)
        work = abs(ng.InnerProduct(du, self.res))
        load = self._load_norm()
        if log.isEnabledFor(logging.DEBUG):
            log.debug("pair search at convergence: |du.r| %.3e J, |r| %.3e of the load, %.3e of the contact force",
                      work, force / load, force / max(self.contact.force_norm(self.free_mask), 1e-300))
        return math.isfinite(work) and (work < self.newton_settings.energy_tol * self.energy_scale
                                        or force < self.contact.settle_force * load)

    def _load_vector(self):
        """sum_i d_i dV_i/du (m^2): the channel pressures' nodal forces per unit load factor s (Pa)."""
        rhs = self.gf.vec.CreateVector()
        tmp = self.gf.vec.CreateVector()
        rhs[:] = 0.0
        for bv, d in zip(self.volume_forms, self.direction):
            if d.Get() != 0.0:
                bv.Apply(self.gf.vec, tmp)
                rhs.data += d.Get() * tmp
        return rhs

    def _load_norm(self) -> float:
        """Euclidean norm over the free unknowns of the channel pressures' nodal forces (N)."""
        return abs(self.load.Get()) * float(np.linalg.norm(self._load_vector().FV().NumPy()[self.free_mask]))

    def tangent(self) -> np.ndarray:
        """du/ds at the current (converged) state and load: K du/ds = sum_i d_i dV_i/du (the last
        Newton's factorisation, or, after a failed solve, a new one on freshly searched contact pairs)."""
        if self.inverse is None:
            if self.contact is not None:
                self.contact.update()
            self._factorize()
        rhs = self._load_vector()
        out = self.gf.vec.CreateVector()
        self._solve(rhs, out)
        return np.array(out.FV().NumPy(), copy=True)

    def newton(self) -> int:
        """Solve for the current load from the current state (Newton on u and q together).
        Returns the iterations; raises NewtonFailure (the state is then undefined: the
        caller restores a converged one). A step that inverts an element (det F <= 0) or
        gives non-finite values is halved; below ``min_step`` the solve fails. A solve that stalls
        keeps its last iterate in ``stalled`` (None otherwise): a ramp's stop is named there too."""
        self.stalled = None
        try:
            return self._newton()
        except NewtonFailure as exc:
            # the factorisation is a failed iterate's: the tangent at the converged state the
            # caller restores must not use it (a ramp's predictor after a cut did, and stepped off)
            self.inverse = None
            self.stalled = exc.stall
            raise

    def _newton(self) -> int:
        """Newton's loop: each iteration an increment (``_increment``), the shifted tangent's step
        where the plain one is no descent, a step length halved while the step is rejected
        (``_step_length``), then the convergence test (``_converged``)."""
        import ngsolve as ng

        st = self.newton_settings
        with ng.TaskManager():
            if not self.min_jacobian_ok():
                raise NewtonFailure("the predictor inverted an element (det F <= 0; "
                                    f"{self.worst_element()})", 0)
            if self.contact is not None:
                self.contact.update()
            self.sigma, self._shifted_in_solve = 0.0, 0
            self.last_effort = 0.0
            # max_iterations per pairing: a new search (at convergence) starts a fresh budget
            s = _Solve(budget=st.max_iterations, tol=st.energy_tol * self.energy_scale)
            it = 0
            while it < s.budget:
                it += 1
                self._check_stall(s, it)
                t_it = time.perf_counter()
                if self.contact is not None and it > 1 and s.searches == 0 and \
                        s.work >= self.contact.search_above * s.tol and not self.contact.pairs_current():
                    # far from convergence the pairs of an earlier iterate are stale (the walls slide):
                    # fixed, they make the energy so nonconvex that full Newton steps cycle. After a
                    # search at convergence the pairs are fresh and stay fixed: searched again at every
                    # iteration, they led back to the pairing of a neighbouring state, whose solution
                    # was the state just left (a 5-iteration cycle on the coarse body at 0.3155 bar)
                    self.contact.update()
                self.a.Apply(self.gf.vec, self.res)
                if not math.isfinite(ng.Norm(self.res)):
                    raise NewtonFailure("residual is not finite", it)
                base, slope, fresh = self._increment(s, it)
                s.work = abs(slope)
                if fresh and slope < -s.tol:   # the tangent indefinite here (the shifted tangent's test of a saddle)
                    s.indefinite = min(s.indefinite, s.work)
                if not math.isfinite(s.work):
                    raise NewtonFailure("Newton increment is not finite", it)
                if self.shift is not None and (self.sigma > 0.0 or slope < -s.tol):
                    # past a saddle: the plain step only once it descends the energy again
                    if not (slope > 0.0 and self._plain_step_descends(base, slope)):
                        s.work, s.budget = self._shifted_iteration(base, it, s.budget)
                        continue
                    self.sigma = 0.0   # Newton recovered
                alpha, full_cut = self._step_length(base, it, slope)
                if alpha is None:   # every length rejected: the shifted tangent's step instead
                    s.work, s.budget = self._shifted_iteration(base, it, s.budget)
                    continue
                # (a step shortened to descend is no overshoot past recovery)
                s.cuts_in_row = s.cuts_in_row + 1 if alpha < 1.0 and full_cut != RAISES_ENERGY else 0
                if st.cut_iterations is not None and s.cuts_in_row >= st.cut_iterations:
                    self.set_state(base)
                    self.gf.vec.data -= self.du   # the full step again, to say where it fails
                    why = self._rejection() or full_cut
                    raise NewtonFailure(f"{s.cuts_in_row} Newton steps in a row cut short (the last full step "
                                        f"{why})", it)
                self.iterations_total += 1
                self.last_work = s.work
                s.works.append(s.work)
                log.debug("load %.1f Pa it %d du.r %.3e alpha %g%s (%.2f s)", self.load.Get(), it, slope,
                          alpha, "" if self.factor_age == 1 else f" (tangent of {self.factor_age} iterations)",
                          time.perf_counter() - t_it)
                if alpha == 1.0 and s.work < (s.tol if fresh else REUSED_TOLERANCE * s.tol) and \
                        self._converged(s, it):
                    return it
            raise NewtonFailure(f"no convergence in {st.max_iterations} Newton iterations "
                                f"(last |du.r| = {s.work:.2e} J)", it)

    def _check_stall(self, s: "_Solve", it: int) -> None:
        """NewtonSettings.stall_iterations: fail a solve whose |du.r| has not fallen tenfold."""
        n = self.newton_settings.stall_iterations
        if n is not None and len(s.works) > n and s.works[-1] > 0.1 * s.works[-1 - n]:
            raise NewtonFailure(f"stalled: |du.r| {s.works[-1]:.2e} J, not a tenth of its "
                                f"{s.works[-1 - n]:.2e} J {n} iterations before", it - 1,
                                Stall(self.load.Get(), self.get_state(), s.works[-1], s.works[-1] / s.tol,
                                      s.indefinite / s.tol))

    def _increment(self, s: "_Solve", it: int) -> tuple[np.ndarray, float, bool]:
        """The iteration's increment self.du for the residual self.res: with the held factorisation
        while the last step contracted (NewtonSettings.reuse_ratio), else with a fresh one (from the
        start of the last step when that step was the reused one). Returns (the state the step
        starts from, du . r, whether the factorisation is fresh)."""
        import ngsolve as ng

        st = self.newton_settings
        fresh = self._refactor_now(it)
        base = self.get_state()
        if not fresh:
            self._solve(self.res, self.du)
            self.a.Apply(self.gf.vec, self.res)
            slope = ng.InnerProduct(self.du, self.res)
            if not abs(slope) <= st.reuse_ratio * s.last_work:
                if s.chord is not None:
                    # the step with the reused factorisation did not contract: back to its start
                    # for Newton's own step there
                    self.set_state(s.chord)
                    base = s.chord
                    self.a.Apply(self.gf.vec, self.res)
                    if s.works:
                        s.works.pop()
                    s.budget += 1
                fresh = True
            elif not (slope > 0.0 and self._full_step_admissible(base)):
                fresh = True   # no descent, or not admissible: Newton's own step instead
        s.chord = None if fresh else base
        if not fresh:
            s.budget += 1.0 - REUSED_ITERATION_COST   # max_iterations counts full iterations' worth
        if fresh:
            self._factorize()
            self._solve(self.res, self.du)
            self.a.Apply(self.gf.vec, self.res)   # (condensation overwrote it)
            slope = ng.InnerProduct(self.du, self.res)   # > 0: -du descends the energy
        s.last_work = abs(slope)
        self.factor_age += 1
        self.last_effort += 1.0 if fresh else REUSED_ITERATION_COST
        return base, slope, fresh

    def _step_length(self, base: np.ndarray, it: int, slope: float) -> tuple[float | None, str]:
        """Take base - alpha du with alpha halved from 1 while the state is not admissible: an
        inverted element, a step through the other wall, which jumps over the barrier (it acts only
        at the pairs' points), or (``contact.backtrack_on_overlap``) a growing overlap of the walls;
        with the walls in contact (NewtonSettings.descent_in_contact) also while a descent step far
        from convergence (``slope`` = du.r at least ``contact.search_above`` x the tolerance; nearer,
        round-off and Newton's q off its optimum for u outweigh the decrease) raises the condensed energy.
        Returns (alpha, why the full step was cut, "" if not); alpha None below ``min_step`` with the
        shifted tangent on; without it that raises NewtonFailure."""
        st = self.newton_settings
        backtrack = self.contact is not None and self.contact.backtrack_on_overlap
        overlap0 = self.contact.overlap_area() if backtrack else 0.0
        e0 = None
        if st.descent_in_contact and self.contact is not None and not self.contact.pairs_idle and \
                slope >= self.contact.search_above * st.energy_tol * self.energy_scale:
            self.set_state(base)
            e0 = self._condensed_energy()
        alpha, full_cut = 1.0, ""
        while True:
            self.gf.vec.data = base
            self.gf.vec.data -= alpha * self.du
            cut = self._rejection(locate=False)
            if not cut and backtrack and self.contact.overlap_area() > overlap0 * (1.0 + 1e-9):
                # no step into the barrier's continuation (the walls' overlap must not grow)
                cut = "pushes paired walls past the barrier's log range"
            if not cut and e0 is not None:
                e = self._condensed_energy()
                self.gf.vec.data = base   # Newton's own q again (the energy set q's optimum for u)
                self.gf.vec.data -= alpha * self.du
                if not (math.isfinite(e) and e <= e0 + 1e-12 * abs(e0)):
                    cut = RAISES_ENERGY
            if not cut:
                return alpha, full_cut
            if alpha == 1.0:
                full_cut = cut
            alpha *= 0.5
            if alpha < st.min_step:
                if self.shift is not None:
                    return None, full_cut
                why = self._rejection() or cut
                raise NewtonFailure(f"line search failed: every step length is rejected; the shortest {why}", it)

    def _converged(self, s: "_Solve", it: int) -> bool:
        """At a converged iterate: with contact, unless the held pairs are current
        (``LumenContact.pairs_current``), search them again (``_contact_pairs_settled``); when they
        move, iterate on with the new ones (a fresh budget; False), and check the wall does not pass
        through itself (NewtonFailure). True: the solve is done."""
        if self.contact is None:
            return True
        if self.contact.settle and not self.contact.pairs_current() and not self._contact_pairs_settled():
            # converged for the old pairs: iterate on with the new ones
            s.searches += 1
            if s.searches > self.contact.max_searches:
                raise NewtonFailure(f"the contact pairs did not settle in {s.searches} searches", it)
            s.budget = it + self.newton_settings.max_iterations
            s.works, s.chord, s.indefinite = [], None, math.inf
            return False
        gap = self.contact.min_gap()
        if gap < -self.contact.tolerance:
            raise NewtonFailure("the lumen wall passes through itself (a section's wall "
                                "polygon crosses itself)", it)
        self.last_min_gap = gap
        self.last_min_gap_state = self.get_state()   # measure() reuses the gap of this state
        return True

    # ------------------------------------------------------------------ shifted tangent
    # the first shift relative to the shear modulus 2 c1, its growth factor and its largest value
    # (beyond it the step is a crawl along the gradient: the solve fails instead)
    SHIFT_START, SHIFT_GROW, SHIFT_MAX = 1e-3, 4.0, 1e3
    ARMIJO = 1e-4

    def _shifted_iteration(self, base: np.ndarray, it: int, budget: float):
        """One Newton iteration taken by the shifted tangent (``_shifted_step``) in place of the plain
        step. A shifted step does not use up the iterations of the plain steps that follow, but at most
        ``shifted_steps`` per solve. Returns (its du . r, the iteration budget)."""
        work = self._shifted_step(base, it)
        self._shifted_in_solve += 1
        if self._shifted_in_solve > self.newton_settings.shifted_steps:
            raise NewtonFailure(f"no stable state in {self._shifted_in_solve - 1} shifted-tangent steps "
                                f"(shift {self.sigma:.3g} Pa)", it)
        return work, budget + 1

    def _condensed_energy(self) -> float:
        """The energy of the current u with q at its optimum for u (module docstring): the merit
        function of the shifted steps."""
        self._update_pressure_field()
        return self.energy()

    def _rejection(self, locate: bool = True) -> str:
        """Why the current state is not admissible ("" when it is): an inverted element (with
        ``locate``, where: the most compressed one), or the lumen wall crossing itself by more
        than the contact's tolerance (0.5 d_hat)."""
        if not self.min_jacobian_ok():
            return f"inverts an element (det F <= 0.02; {self.worst_element()})" if locate else "inverts an element"
        if self.contact is not None:
            gap = self.contact.min_gap()
            if gap < -self.contact.tolerance:
                return (f"carries the lumen wall through itself by {-gap * 1e6:.1f} um "
                        f"(tolerance {self.contact.tolerance * 1e6:.1f} um)")
        return ""

    def _plain_step_descends(self, base: np.ndarray, slope: float) -> bool:
        """After shifted steps: does the full Newton step (self.du) lower the condensed energy
        (Armijo) and stay admissible? It may head for the saddle just left, which lies higher.
        Leaves the state at ``base``."""
        self.set_state(base)
        e0 = self._condensed_energy()
        self.gf.vec.data -= self.du
        e = self._condensed_energy()
        ok = math.isfinite(e) and e <= e0 - self.ARMIJO * slope + 1e-12 * abs(e0) and not self._rejection()
        self.set_state(base)
        return ok

    def _shifted_step(self, base: np.ndarray, it: int) -> float:
        """From ``base``, the step of the tangent shifted by sigma x (the H1 seminorm's form),
        sigma growing from a quarter of the last one (or SHIFT_START x 2 c1) by SHIFT_GROW
        until the step descends the condensed energy (Armijo) and stays admissible: for sigma
        above the tangent's most negative eigenvalue the step descends, and leaves a saddle
        along its negative directions. The contact pairs stay the solve's (a search here gave
        a far more indefinite tangent). Leaves the state at the step's end, q at its optimum;
        returns the step's du . r (J). Raises NewtonFailure when no sigma up to SHIFT_MAX
        x 2 c1 works, naming what rejected the last trial."""
        import ngsolve as ng

        mu = 2.0 * self.design.material.c1
        sigma = max(0.25 * self.sigma, self.SHIFT_START * mu)
        self.set_state(base)
        e0 = self._condensed_energy()
        start = self.get_state()
        self.shift_origin.vec.data = self.gf.vec
        why = "raises the energy"
        try:
            while sigma <= self.SHIFT_MAX * mu:
                self.shift.Set(sigma)
                self.set_state(start)
                self._factorize()
                self.a.Apply(self.gf.vec, self.res)
                self._solve(self.res, self.du)
                self.a.Apply(self.gf.vec, self.res)
                slope = ng.InnerProduct(self.du, self.res)
                if math.isfinite(slope) and slope > 0.0:
                    self.gf.vec.data -= self.du
                    self.shift.Set(0.0)
                    e = self._condensed_energy()
                    why = self._rejection() if math.isfinite(e) else "gives a non-finite energy"
                    if not why and e > e0 - self.ARMIJO * slope + 1e-12 * abs(e0):
                        why = "raises the energy"
                    log.debug("   shift %.3g Pa: du.r %.3e, dE %.3e %s", sigma, slope, e - e0, why)
                    if not why:
                        self.sigma = sigma
                        self.shifted_total += 1
                        self.iterations_total += 1
                        log.debug("load %.1f Pa it %d shifted step: shift %.3g Pa, du.r %.3e, dE %.3e",
                                  self.load.Get(), it, sigma, slope, e - e0)
                        return slope
                sigma *= self.SHIFT_GROW
        finally:
            self.shift.Set(0.0)
            self.inverse = None              # the last factorisation was the shifted tangent's
        self.set_state(start)
        raise NewtonFailure(f"line search failed: every Newton step length and every shifted-tangent step "
                            f"(shift up to {self.SHIFT_MAX:g} x 2 c1) is rejected; the last {why}", it)
