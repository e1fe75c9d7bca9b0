"""Frictionless self-contact of the lumen wall in the 3D problem: NGSolve's ``ContactBoundary``
with the section rung's clamped log-barrier on the normal gap.

NGSolve pairs every integration point of the lumen wall (primary) with the closest point of
the lumen wall (secondary) whose normal faces it (its own and its neighbours' do not while
the wall is smooth; the wall across a closing slit, or across a fold at its shoulders, does),
within ``maxdist``. The pairs are searched again (``ContactBoundary.Update``) before every
Newton iteration until Newton is close to convergence, then fixed, and searched again at
convergence (Fe3dProblem.newton). Between searches the energy is differentiated exactly by
NGSolve, so the tangent is the consistent one of the fixed pairing (checked by finite
differences of the residual). Pairs kept from a distant iterate are stale: the walls slide, a
fixed partner drifts off the closest point, and that energy is so nonconvex that full Newton
steps cycle (fe3d-4's stall, docs/models/fe3d.md "Where it fails"). The gap is the normal one,

    g = ((X' + u') - (X + u)) . n,      n the primary's deformed normal (into the lumen),

and the energy per reference area of the wall is

    W_c = c1 kappa d_hat beta(g / d_hat),   beta(xi) = -(xi^2 - 1)^2 ln(xi^2) for 0 < xi < 1, 0 beyond,

(times windows, and with xi raised for a partner far off the primary's normal line: lateral_xi),

the section rung's barrier b(s) = -(s - s_hat)^2 ln(s / s_hat) on s = g^2
(core/section_fe/terms/contact.py), C2 at xi = 1. Its traction is about 2 kappa c1 / xi, so
at a contact pressure p_c the gap is about 2 kappa d_hat c1 / p_c: a fixed fraction of d_hat,
and results depend on d_hat only through that gap. Below xi = XI_MIN beta is continued by its
second-order Taylor polynomial, so an overshooting Newton iterate has a finite (steep) energy
and is pushed back instead of producing NaNs; a converged state whose wall crosses itself
(``min_gap`` < 0) is rejected by the solver, so no accepted state has interpenetrating walls.
Each pair is seen from both walls (every wall point is a primary), so the wall's contact
traction is the sum of both sides' terms.
"""
from __future__ import annotations

import logging

import numpy as np

from ..section_fe.terms.contact import KAPPA_SCALE, barrier
from .holes import hole_size
from .wall_gap import min_wall_gap, section_rings, wall_sampling

log = logging.getLogger(__name__)

# energy scale (units c1 d_hat per reference area): gap ~ 2 KAPPA d_hat c1 / p_c, the section rung's
KAPPA = KAPPA_SCALE
# below xi = g / d_hat = XI_MIN the barrier is continued quadratically (C2)
XI_MIN = 0.02
# a pair counts fully when its partner lies within OFF_LOW d_hat of the primary's normal line (its
# offset o along the wall, |sep - g n|); beyond, LATERAL t^3, t = (o^2 - OFF_LOW^2) / (OFF_HIGH^2 -
# OFF_LOW^2), is added to xi (C2), so from OFF_HIGH d_hat on a pair at most d_hat behind the
# primary lies beyond the barrier's range (lateral_xi)
OFF_LOW, OFF_HIGH = 2.0, 5.0
LATERAL = 2.0
# the held pairs are the state's own while the wall's sections have moved by at most SETTLE_MOVE d_hat
# in their planes since the pairs were searched (LumenContact.pairs_current): half the crossing the
# gap check tolerates; on the 1-DOF optimum a fresh search at a converged state in contact moved the
# wall by 2-4.5 um (0.07-0.15 d_hat) and its tip angle by 4e-5 of itself, however often repeated
SETTLE_MOVE = 0.25
# and when it lies in front of the primary or at most BEHIND_HIGH d_hat behind it, not at all
# beyond BEHIND_LOW d_hat behind it (through the silicone, where the wall creases)
BEHIND_LOW, BEHIND_HIGH = -2.0, -1.0
# and when its two points lie at least NEAR_HIGH lumen radii apart in the reference state, not at
# all below NEAR_LOW (neighbours along the wall, found at a sharply curved shoulder)
NEAR_LOW, NEAR_HIGH = 0.25, 0.5
# a converged state may cross by at most TOLERANCE d_hat between the barrier's quadrature points
TOLERANCE = 0.5
# the pair search is skipped while every section's wall keeps at least FAR d_hat between points two
# edges apart along it (min_gap): a pair weighs in only with its partner within d_hat along the normal
# and OFF_HIGH d_hat beside it, so no search there can find a pair the energy counts
FAR = 6.0
# the contact's quadrature order on the lumen wall: the barrier is integrated, and the pairs searched,
# at these points. 6 since fe3d-10 (8 before): the same R_C to a small fraction of a percent for a
# cheaper pair search (the measurements: docs/models/fe3d.md, "Newton and the ramp")
INTORDER = 6


def _barrier_parts(xi: float):
    """beta, beta', beta'' at xi (floats): the section rung's b(s) with s_hat = 1 on s = xi^2."""
    s = xi * xi
    b, b1, b2 = (float(v) for v in barrier(s, 1.0))
    return b, 2 * xi * b1, 4 * s * b2 + 2 * b1


def barrier_cf(xi):
    """beta(xi) as an NGSolve CoefficientFunction: the clamped log-barrier, 0 for xi >= 1,
    continued by its Taylor polynomial at XI_MIN below XI_MIN (C2 at both joints)."""
    import ngsolve as ng

    inside = ng.IfPos(xi - 1.0, 1.0, ng.IfPos(xi - XI_MIN, xi, XI_MIN))   # log never sees xi <= 0
    s = inside * inside
    log_part = -(s - 1.0) * (s - 1.0) * ng.log(s)
    b0, b1, b2 = _barrier_parts(XI_MIN)
    d = xi - XI_MIN
    taylor = b0 + b1 * d + 0.5 * b2 * d * d
    return ng.IfPos(xi - 1.0, 0.0, ng.IfPos(xi - XI_MIN, log_part, taylor))


def lateral_xi(xi, offset2):
    """The barrier's argument for a pair of normal gap xi d_hat whose partner lies sqrt(offset2) d_hat
    off the primary's normal line: xi while that offset is at most OFF_LOW, then xi + LATERAL t^3
    (C2; t as at LATERAL), as a CoefficientFunction."""
    import ngsolve as ng

    t = ng.IfPos(offset2 - OFF_LOW ** 2, (offset2 - OFF_LOW ** 2) / (OFF_HIGH ** 2 - OFF_LOW ** 2), 0.0)
    return xi + LATERAL * t * t * t


def smooth_step_cf(t):
    """S(t) = 6t^5 - 15t^4 + 10t^3 on [0, 1], 0 below, 1 above (C2), as a CoefficientFunction."""
    import ngsolve as ng

    c = ng.IfPos(t - 1.0, 1.0, ng.IfPos(t, t, 0.0))
    return c * c * c * (10.0 - 15.0 * c + 6.0 * c * c)


def near_window(ref):
    """0 for two wall points within NEAR_LOW lumen radii of each other in the reference state (``ref``,
    in lumen radii: neighbours along the wall, or a point and its image on the mirror plane), 1 from
    NEAR_HIGH on (C2 between), as a CoefficientFunction."""
    return smooth_step_cf((ref - NEAR_LOW) / (NEAR_HIGH - NEAR_LOW))


def mirror_energy_cf(problem, u, d_hat: float):
    """The half body's lumen wall against its mirror image across x = 0, per reference area of the wall:
    the pair term's barrier on the gap g = 2 (X + u)_x from a wall point to its own image (the body lies
    at x > 0), c1 KAPPA d_hat beta(g / d_hat). The wall meets the plane, where the symmetry condition
    holds it with g = 0 by construction: like a neighbour along the wall, a point within NEAR_LOW lumen
    radii of its image in the reference state is no partner of it (NEAR_HIGH on: fully)."""
    import ngsolve as ng

    gap = 2.0 * (ng.x + u[0])
    ref = 2.0 * ng.x / hole_size(problem.design.lumen)
    weight = near_window(ref)
    return problem.design.material.c1 * KAPPA * d_hat * weight * barrier_cf(gap / d_hat)


def pair_energy_cf(problem, u, d_hat: float):
    """The lumen wall's pair term per reference area of the primary, for ``ContactBoundary``: (its
    compiled energy c1 KAPPA d_hat beta(xi) times the windows, the windows' weight, the normal gap
    (m), the barrier's argument xi, the two points' reference distance in lumen radii), as
    CoefficientFunctions of the trial function ``u`` and its value at the partner (``Other``)."""
    import ngsolve as ng

    X = ng.CF((ng.x, ng.y, ng.z))
    sep = X.Other() + u.Other() - X - u
    # the primary's deformed normal from the trial function (so it is differentiated too):
    # Nanson, n ~ cof(F) N, N the reference normal (out of the silicone, into the lumen)
    fs = ng.Id(3) + ng.Grad(u).Trace()
    cof_n = ng.Cof(fs) * ng.specialcf.normal(3)
    normal = cof_n / ng.Norm(cof_n)
    gap = sep * normal
    # a pair across the lumen has its partner near the primary's normal line, in front of it.
    # Windows in lengths (d_hat), not in the angle: with the pairs fixed between searches the
    # walls slide by microns, and a window on the angle (fe3d-4: cos 0.3 -> 0.7) switched a
    # pair off once it had slid by about its gap, a few microns, which made the fixed
    # pairing's energy so nonconvex that full Newton steps cycled (docs/models/fe3d.md,
    # "Where it fails"). The offset window drops a neighbour on a sharply curved wall (a
    # shoulder), found at the shared edge nearly in the tangent plane; the behind window a wall
    # point behind the primary (through the silicone, found where the wall creases): such pairs,
    # counted with their negative gap, made the energy jump by orders of magnitude when the
    # search added or dropped them (fe3d-3). Walls that really pass through each other are
    # caught by the geometric check instead (min_gap)
    # The offset does not weigh the barrier but adds to its argument (lateral_xi): a weight let a
    # pair found nearly in the primary's tangent plane (offset 4.8 d_hat, gap -0.01 d_hat: the
    # wall turning round a fold) keep a sliver of the barrier's large value there, which moved
    # with the offset: 0.059 mm^2 of such pairs past the log range made the tangent indefinite
    # on the 1-DOF optimum at 0.1041 bar (docs/models/fe3d.md, "Where it fails")
    offset2 = (sep * sep - gap * gap) / (d_hat * d_hat)
    xi = lateral_xi(gap / d_hat, offset2)
    weight = smooth_step_cf((gap / d_hat - BEHIND_LOW) / (BEHIND_HIGH - BEHIND_LOW))
    # and the two points must be apart on the reference wall: a neighbour along the wall
    # is not a contact partner (the section rung's exclusion of incident segments)
    ref = ng.Norm(X.Other() - X) / hole_size(problem.design.lumen)
    weight = weight * near_window(ref)
    scale = problem.design.material.c1 * KAPPA * d_hat
    # compiled: the same values, several times faster to assemble
    energy = (scale * weight * barrier_cf(xi)).Compile()
    return energy, weight, gap, xi, ref


# the mirror term's quadrature order on the lumen wall above the default (2 x the element order, 4):
# INTORDER, the pair term's
MIRROR_BONUS_ORDER = INTORDER - 4


class LumenContact:
    """The lumen wall's self-contact term added to a problem's BilinearForm."""

    def __init__(self, problem, distance: float, intorder: int = INTORDER):
        """``distance``: the barrier distance d_hat, m."""
        import ngsolve as ng

        mesh = problem.mesh
        self.problem = problem
        self.d_hat = float(distance)
        lumen = problem.design.lumen
        # pairs are searched up to maxdist: far more than d_hat, so a wall closing by more than
        # d_hat in one Newton step is still paired at the next search, and well below the
        # lumen's radius, so the smooth wall never pairs with itself
        self.maxdist = max(20.0 * self.d_hat, 0.15 * hole_size(lumen))
        self.intorder = intorder
        self.tolerance = TOLERANCE * self.d_hat
        # search the pairs again at convergence and iterate on until they no longer change
        # (False: the pairs of the step's start hold for the whole step)
        self.settle = True
        # at most this many searches at convergence per solve (each with max_iterations of its own)
        self.max_searches = 6
        # the pairs are searched again before every Newton iteration while |du.r| is at least this
        # many times Newton's tolerance, then fixed (Newton quadratic on them) until convergence
        self.search_above = 1e3
        # the pairs count as settled when a search at convergence leaves a residual force below
        # this fraction of the pressure load (Fe3dProblem._contact_pairs_settled)
        self.settle_force = 1e-3
        # the held pairs count as the current state's (no search before a Newton iteration or at
        # convergence) while no sampled point of the wall's sections has moved by more than this (m)
        # in its section's plane since they were searched (pairs_current)
        self.settle_move = SETTLE_MOVE * self.d_hat
        # backtrack from a Newton step that adds to overlap_area(): off, since on the coarse
        # 10 mm body it stopped the ramp at the same pressure (0.2439 bar) and cost time
        self.backtrack_on_overlap = False
        wall = mesh.Boundaries("lumen")
        self.boundary = ng.ContactBoundary(wall, wall, volume=False)
        u, _ = problem.fes.TrialFunction()
        energy, weight, gap, xi, ref = pair_energy_cf(problem, u, self.d_hat)
        self.boundary.AddEnergy(energy)
        paired = ng.IfPos(weight - 1e-12, 1.0, 0.0)   # the pairs the energy counts at all
        # the same pairs measuring the wall area (m^2) past the barrier's log range (xi < XI_MIN);
        # Newton can backtrack from a step that adds to it (backtrack_on_overlap)
        self.check = ng.ContactBoundary(wall, wall, volume=False)
        self.check.AddEnergy(paired * ng.IfPos(XI_MIN - xi, 1.0, 0.0))
        self.check_form = ng.BilinearForm(problem.fes)
        # the contact energy alone on the same pairs: its gradient is the wall's contact force
        self.force_boundary = ng.ContactBoundary(wall, wall, volume=False)
        self.force_boundary.AddEnergy(energy)
        self.force_form = ng.BilinearForm(problem.fes)
        # the half body's wall against its own mirror image (mirror_energy_cf), in the problem's energy
        # and in the contact's own forms (force_norm, tangent_matrix); mirror_form holds it alone
        self.mirror_form = None
        if problem.half:
            mirror = ng.Variation(mirror_energy_cf(problem, u, self.d_hat).Compile()
                                  * ng.ds(definedon=wall, bonus_intorder=MIRROR_BONUS_ORDER))
            problem.a += mirror
            self.force_form += mirror
            self.mirror_form = ng.BilinearForm(problem.fes)
            self.mirror_form += mirror
        self._sampling = wall_sampling(problem)
        self._gap_of = None   # (state, min_gap there): the last state asked about
        self.far = FAR * self.d_hat
        # True while the pairs held count nothing: none searched yet, or the last search was made
        # with the walls far apart (then skipping a search changes no energy, gradient or tangent)
        self.pairs_idle = True
        self._searched_wall = None   # the wall's sampled points (wall_points) at the last search
        self.searches = self.skipped = 0
        self._wall, self._gap, self._xi, self._ref, self._paired = wall, gap, xi, ref, paired
        self._census = None   # pair_census's forms, built on its first call (diagnosis only)

    def _census_forms(self) -> list:
        """The census's forms: for "in_range" (counted by the energy: in its windows, the barrier's
        argument below 1) and "behind" (partner beyond BEHIND_LOW d_hat behind the primary, apart on
        the wall: the energy ignores them) the area (m^2) and area-weighted x, y, z and gap."""
        if self._census is None:
            import ngsolve as ng

            one = ng.IfPos(self._ref - NEAR_HIGH, 1.0, 0.0)
            kinds = {"in_range": self._paired * ng.IfPos(1.0 - self._xi, 1.0, 0.0),
                     "behind": one * ng.IfPos(BEHIND_LOW * self.d_hat - self._gap, 1.0, 0.0)}
            self._census = []
            for kind, mask in kinds.items():
                for what, f in (("area", mask), ("x", mask * ng.x), ("y", mask * ng.y), ("z", mask * ng.z),
                                ("gap", mask * self._gap)):
                    cb = ng.ContactBoundary(self._wall, self._wall, volume=False)
                    cb.AddEnergy(f)
                    self._census.append((kind, what, cb, ng.BilinearForm(self.problem.fes)))
        return self._census

    def update(self) -> bool:
        """Search the contact pairs for the current displacement (before each Newton iteration),
        unless the walls are far apart (``min_gap`` above ``far``) and the pairs held count
        nothing, where a search cannot change the problem (it costs about as much as a
        factorisation). Returns whether it searched."""
        far = self.min_gap() > self.far
        if far and self.pairs_idle:
            self.skipped += 1
            return False
        self.boundary.Update(self.problem.u, self.problem.a, self.intorder, self.maxdist, keep_pairs=True)
        if self.backtrack_on_overlap:
            self._held_pairs_to(self.check, self.check_form)
        self.pairs_idle = far
        self.searches += 1
        self._searched_wall = self.wall_points()
        return True

    def pairs_current(self) -> bool:
        """Whether the held pairs were searched where every sampled point of the lumen wall lay within
        ``settle_move`` of where it is now: the current state's pairs to within that motion."""
        if self._searched_wall is None:
            return False
        moved = float(np.max(np.linalg.norm(self.wall_points() - self._searched_wall, axis=-1)))
        log.debug("the lumen wall moved %.3g um since the pairs were searched", moved * 1e6)
        return moved <= self.settle_move

    def force_norm(self, free) -> float:
        """Euclidean norm over the ``free`` unknowns of the contact's nodal forces (N) on the pairs of
        the last update."""
        self._held_pairs_to(self.force_boundary, self.force_form)
        out = self.problem.gf.vec.CreateVector()
        self.force_form.Apply(self.problem.gf.vec, out)
        return float(np.linalg.norm(out.FV().NumPy()[free]))

    def tangent_matrix(self):
        """The contact term's own tangent (NGSolve matrix over all unknowns) at the current state on
        the pairs of the last update: the part of the problem's tangent the contact adds."""
        self._held_pairs_to(self.force_boundary, self.force_form)
        self.force_form.AssembleLinearization(self.problem.gf.vec)
        return self.force_form.mat

    def past_log_range_area(self) -> float:
        """Wall area (m^2, of the model) of the pairs of the last update whose gap is below XI_MIN
        d_hat, where the barrier is its Taylor continuation (a device to push an overshooting
        iterate back), not the log-barrier it models contact with."""
        self._held_pairs_to(self.check, self.check_form)
        return self.overlap_area()

    def _held_pairs_to(self, boundary, form) -> None:
        """Give ``boundary`` (a ContactBoundary on the wall, its energy in ``form``) the pairs of the
        last update, without a search of its own."""
        boundary.Update(self.problem.u, form, self.intorder, self.maxdist, other=self.boundary)

    def overlap_area(self) -> float:
        """Wall area (m^2, of the model) of the current pairs whose gap is below XI_MIN d_hat
        (the pairs of the last update with backtrack_on_overlap on)."""
        return self.check_form.Energy(self.problem.gf.vec)

    def pair_census(self) -> dict:
        """The pairs of a fresh search at the current state: for "in_range" (counted by the energy:
        in its windows, the barrier's argument below 1) and "behind" (partner more than 2 d_hat
        behind the primary, ignored by the energy) the model's wall area (m^2), its centroid (m)
        and mean gap (m)."""
        self.boundary.Update(self.problem.u, self.problem.a, self.intorder, self.maxdist, keep_pairs=True)
        self.pairs_idle = False   # (not known: the next update searches)
        self._searched_wall = None
        raw: dict = {}
        for kind, what, cb, form in self._census_forms():
            self._held_pairs_to(cb, form)
            raw.setdefault(kind, {})[what] = form.Energy(self.problem.gf.vec)
        out = {}
        for kind, v in raw.items():
            a = v["area"]
            out[kind] = {"area_m2": a, **({k: v[k] / a for k in ("x", "y", "z", "gap")} if a > 0 else {})}
        return out

    def wall_points(self) -> np.ndarray:
        """The lumen wall's sampled section rings in their own planes (m), (levels, m, 2): ``section_rings``."""
        return np.asarray(section_rings(self.problem, self._sampling))

    def mirror_energy(self) -> float:
        """The mirror term's energy (J, of the model) at the current state (mirror_energy_cf); 0 on the full body."""
        return 0.0 if self.mirror_form is None else self.mirror_form.Energy(self.problem.gf.vec)

    def mirror_crossing(self) -> float:
        """How far (m) the half model's lumen wall lies past its mirror plane x = 0 at its deepest sampled
        point: there it passes its mirror image (through the mirror term's barrier; at fe3d-11, without it,
        the fan design's equal pair lay 38 um past at 0.05 bar, where min_gap read -6.6 um). 0 on the full body."""
        if not self.problem.half:
            return 0.0
        return max(0.0, max(float(-np.min(rings[0][:, 0])) for rings in self._sampling.deformed(self.problem)))

    def min_gap(self) -> float:
        """The smallest distance (m) between two wall points of one section that are not
        neighbours along the wall, over every section of the mesh; negative (minus the
        depth of the deepest crossing point) when a section's wall crosses itself."""
        state = self.problem.gf.vec.FV().NumPy()
        if self._gap_of is None or not np.array_equal(state, self._gap_of[0]):
            # (a Newton step's admissibility check and the next iteration's search ask at one state)
            self._gap_of = (state.copy(), min_wall_gap(self.problem, self._sampling))
        return self._gap_of[1]
