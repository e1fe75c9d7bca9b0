"""The 3D hyperelastic problem on a prism mesh, solved with NGSolve (imported lazily).

Unknowns: P2 displacement u and an element-wise constant pressure q (perturbed
Lagrangian, statically condensed). Total potential, stationary at equilibrium:

    Pi(u, q) = int W_iso(F) + q (J - 1) - q^2 / (2 K) dX        (body, fibre, device)
             + int W_fill(F) dX                                   (optional soft lumen fill)
             + int k_hoop / 2 (lambda_theta - 1)^2 dA             (reinforcement: outer surface)     
             - s sum_i d_i V_i(u)                                 (follower pressure on channel i)

with s the load factor and d_i the pressure per unit s of channel i. V_i, the enclosed
channel volume, is a surface integral over the channel's walls and cap:
V = int x_z n_z da = int x_z (cof F N)_z dA (the base, z = 0, and the symmetry plane,
n_z = 0, add nothing), so -p V is exactly the potential of a follower pressure.
All energies are differentiated by NGSolve (``Variation``).

The optional lumen fill is a contact proxy: without self-contact the empty lumen of a
strongly bent body collapses until its elements invert. The fill is a compressible
neo-Hookean solid, W = mu/2 (I1 - 3 - 2 ln J) + lambda/2 (ln J)^2, whose energy grows
without bound as its volume goes to zero, so the lumen walls cannot pass through each other.
Its shear modulus is a small fraction of the silicone's so that it barely stiffens bending
before the walls come close (measured: benchmarks/fe3d_sensitivity.py, variant lumen_fill).

Because q is element-wise constant, its optimum for a given u is the element mean of
K (J - 1); with q reset to it Pi becomes the condensed, minimised energy: the merit of
the shifted-tangent steps.

Comparison-only variants (a displacement-only element, resolved rings) live in
softcath_ros/experimental/fe3d_variants.py, which overrides ``_build_prism``,
``_body_energy`` and ``_reinforcement_energy``.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..design import Design
from ..energy import isochoric_i1, neo_hookean, yeoh
from .contact import INTORDER, LumenContact
from .mesh import MeshSettings, PrismMesh, build_mesh, hole_size

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class NewtonSettings:
    max_iterations: int = 12
    rtol: float = 1e-8          # residual norm relative to the load's norm
    energy_tol: float = 1e-9    # |du . r| relative to c1 * volume (displacement error ~ sqrt of it)
    min_step: float = 1.0 / 64  # smallest step factor (halved from 1 while a step is rejected) before the solve fails
    threads: int = 2
    # where the Newton step is no descent direction of the energy, or every step length is
    # rejected (an indefinite tangent: past a saddle), step with the tangent shifted by
    # sigma x (the H1 seminorm's form), sigma growing until the step descends the condensed energy
    # and stays admissible (Fe3dProblem._shifted_step); converged only on an unshifted step.
    # Off: on the 20 mm ramp the stop is the wall crossing itself, which it cannot pass, and it
    # made that ramp 5x slower (docs/models/fe3d.md, "Where it fails")
    shifted_tangent: bool = False
    shifted_steps: int = 12     # shifted steps per solve, on top of max_iterations
    # give up on a solve whose |du.r| has not fallen tenfold over this many iterations (None: never;
    # with contact, solves that fail wander with |du.r| flat for their whole budget, those that
    # converge fall from the start), so a step that will fail is cut early
    stall_iterations: int | None = 4
    # give up on a solve once this many iterations in a row had their full step rejected and cut
    # (an inverted element, the wall through itself): a step overshot past recovery. None: never.
    # On the 20 mm default ramp no solve that converged cut a step at all; those that failed cut
    # up to 10 in a row before their budget ran out
    cut_iterations: int | None = 3
    # reuse a solve's factorisation while Newton contracts with it: after its first iteration
    # (always factorised), an iteration solves with the tangent of an earlier iterate of the same
    # solve (at most reuse_age iterations old) and keeps that increment while its |du.r| is at
    # most reuse_ratio of the last step's; else it takes Newton's own step (a fresh factorisation),
    # from the start of the last step when that step was the reused one, and at once when the
    # reused step is no descent or not admissible (an inverted element, crossing walls). A solve
    # ends on a reused factorisation only at REUSED_TOLERANCE of the tolerance. None: a
    # factorisation at every iteration.
    reuse_ratio: float | None = 0.25
    reuse_age: int = 8


# a Newton iteration on a reused factorisation costs about a quarter of one that factorises (the
# 20 mm default body: 0.16-0.21 s against 0.76-0.86 s): the weight of such iterations in a solve's
# effort, by which the ramp sizes its steps
REUSED_ITERATION_COST = 0.25
# on a reused factorisation |du.r| only estimates the energy error: a solve ends there at this
# fraction of the tolerance
REUSED_TOLERANCE = 0.1


def check_element(pressure_order, interior_order) -> None:
    """Raise ValueError (one line) unless the element orders are ones Fe3dProblem builds:
    ``pressure_order`` 0 or 1, ``interior_order`` None or an integer >= 3."""
    if isinstance(pressure_order, bool) or pressure_order not in (0, 1):
        raise ValueError(f"pressure_order must be 0 (P2/P0) or 1 (P2/P1), not {pressure_order!r}")
    if interior_order is not None and (isinstance(interior_order, bool) or not isinstance(interior_order, int)
                                       or interior_order < 3):
        raise ValueError(f"interior_order must be an integer >= 3 or None, not {interior_order!r}")


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


class NewtonFailure(Exception):
    """One Newton solve failed; ``reason`` says how (diverged, inverted, max iterations)."""

    def __init__(self, reason: str, iterations: int):
        super().__init__(reason)
        self.reason = reason
        self.iterations = iterations


def _ng():
    import ngsolve

    return ngsolve


class Fe3dProblem:
    """Everything NGSolve needs for one design and mesh; holds the current state."""

    # rad: how far the model turned the design's section to put a mirror plane at x = 0 (the half
    # body about it); measure() turns its results back by it
    rotation: float = 0.0

    def __init__(self, design: Design, mesh_settings: MeshSettings = MeshSettings(),
                 newton: NewtonSettings = NewtonSettings(), half: bool | None = None,
                 lumen_fill: float | None = None, contact_distance: float | None = None, pressure_order: int = 0, interior_order: int | None = None,
                 contact_intorder: int = INTORDER):
        """``lumen_fill``: shear modulus of a soft fill in an empty lumen as a fraction of the
        silicone's (2 c1); None leaves the lumen empty. The reinforcement is a homogenised hoop
        layer (stiffness E A / pitch) on the whole outer surface. ``pressure_order``: the element pressure q's
        order (0: P2/P0, 1: a discontinuous linear q). ``interior_order``: order (>= 3) of the
        displacement's element-interior bubbles added to P2, condensed with q (order 3: two per
        component and prism, the triangle's cubic bubble times the axial quadratic and cubic ones):
        more divergence for a P1 q to act on, against the P2/P1 pair's spurious soft modes (the pair
        is not inf-sup stable; on tetrahedra the full cure also needs face bubbles); None: plain P2.
        ``contact_intorder``: the lumen contact's quadrature order on the wall (LumenContact)."""
        check_element(pressure_order, interior_order)
        ng = _ng()
        ng.SetNumThreads(newton.threads)
        self.design = design
        self.newton_settings = newton
        self.prism: PrismMesh = self._build_prism(design, mesh_settings, half, bool(lumen_fill))
        self.half = self.prism.half
        self.mirror = 2.0 if self.half else 1.0
        mesh = self.mesh = ng.Mesh(self.prism.ngmesh)
        v = ng.VectorH1(mesh, order=2, dirichlet="base", dirichletx="sym" if self.half else "")
        if interior_order is not None:
            v.SetOrder(ng.PRISM, interior_order)
            v.Update()
        q = ng.L2(mesh, order=pressure_order)
        self.fes = fes = v * q
        self.gf = ng.GridFunction(fes)
        self.u, self.q = self.gf.components
        self.load = ng.Parameter(0.0)   # load factor s; pressure of channel i is s * d_i
        self.direction = [ng.Parameter(0.0) for _ in design.channels]

        u, mats = self._assemble(lumen_fill)

        self.shift = None
        if newton.shifted_tangent:
            # 0.5 sigma |grad (u - u_k)|^2 with sigma a Parameter (0 but in a shifted step) and
            # u_k the step's start: at u = u_k it adds sigma x the H1 seminorm's form to the
            # tangent and nothing to the residual or energy
            self.shift = ng.Parameter(0.0)
            self.shift_origin = ng.GridFunction(fes)
            g = ng.Grad(u) - ng.Grad(self.shift_origin.components[0])
            self.a += ng.Variation((0.5 * self.shift * ng.InnerProduct(g, g)).Compile() * ng.dx)
        self.sigma = 0.0             # the last shifted step's shift, Pa (0: plain Newton)
        self.shifted_total = 0

        self.contact = None
        if contact_distance is not None and "lumen" in mesh.GetBoundaries():
            self.contact = LumenContact(self, float(contact_distance) * 2.0 * hole_size(design.lumen),
                                        intorder=contact_intorder)
        self.J = ng.Det(ng.Id(3) + ng.Grad(self.u))
        self.bulk_cf = mesh.MaterialCF({k: m[3] for k, m in mats.items()}, default=0.0)
        self.reference_volume = ng.Integrate(ng.CF(1.0), mesh) * self.mirror
        self.energy_scale = design.material.c1 * self.reference_volume
        free = fes.FreeDofs(True)
        self.free = free
        self.free_mask = np.array(list(fes.FreeDofs(False)), dtype=bool)   # every free unknown, q too
        self.res = self.gf.vec.CreateVector()
        self.du = self.gf.vec.CreateVector()
        self.inverse = None
        self.factor_age = 0          # Newton iterations solved with the current factorisation
        self.last_effort = 0.0       # the last solve's iterations, those on a reused factorisation weighted
        self.factorizations = 0
        self.iterations_total = 0

    # ------------------------------------------------------------------ energies
    def _assemble(self, lumen_fill):
        """The bilinear form ``self.a`` of the total potential (module docstring) and the channels'
        volume forms; returns the trial displacement and the materials."""
        ng = _ng()
        fes, mesh, design = self.fes, self.mesh, self.design
        (u, qq) = fes.TrialFunction()
        F = ng.Id(3) + ng.Grad(u)
        mats = self._materials()
        energy = self._body_energy(F, qq, mats)
        self.a = a = ng.BilinearForm(fes, symmetric=True, condense=True)
        a += ng.Variation(energy.Compile() * ng.dx)
        self.has_fill = "fill" in mesh.GetMaterials()
        if self.has_fill:
            mu = 2.0 * design.material.c1 * float(lumen_fill)
            a += ng.Variation(self._fill_energy(F, mu).Compile() * ng.dx(definedon=mesh.Materials("fill")))
        if design.reinforcement is not None:
            a += self._reinforcement_energy(u)
        self.volume_forms = []
        for i, _ in enumerate(design.channels):
            vol_i = self._volume_density(u)
            # The model's share of the volume (half of it in the half model, like every energy).
            a += ng.Variation(-self.load * self.direction[i] * vol_i * ng.ds(f"channel{i}"))
            # The same volume alone: its value (Energy) and derivative (Apply) for the tangent.
            bv = ng.BilinearForm(fes, symmetric=True)
            bv += ng.Variation(vol_i * ng.ds(f"channel{i}"))
            self.volume_forms.append(bv)
        return u, mats

    def _build_prism(self, design: Design, mesh_settings: MeshSettings, half, lumen_fill: bool) -> PrismMesh:
        return build_mesh(design, mesh_settings, half, lumen_fill=lumen_fill)

    def _reinforcement_energy(self, u):
        """The rings homogenised: a hoop membrane of stiffness E A / pitch on the outer surface."""
        ng = _ng()
        stiffness = self.design.reinforcement.hoop_stiffness_per_length
        return ng.Variation(self._hoop_energy(u, stiffness) * ng.ds("outer"))

    def _materials(self):
        d = self.design
        mats = {"silicone": (d.material.c1, d.material.c2, d.material.c3, d.material.bulk_modulus)}
        if d.limiting_fibre is not None:
            f = d.limiting_fibre.material
            mats["fibre"] = (f.c1, f.c2, f.c3, f.bulk_modulus)
        if d.device is not None:
            mats["device"] = self._device_material()
        return mats

    def _device_material(self):
        """A device in the lumen as a bonded neo-Hookean cylinder filling the lumen, with the
        modulus that adds the device's bending stiffness EI to the section about its neutral
        axis (own second moment plus the parallel-axis term of the transformed section)."""
        from ..section_properties import transformed_section

        d = self.design
        na = transformed_section(d.with_length(d.length)).neutral_axis
        r = d.lumen.radius
        area = math.pi * r * r
        dy = d.lumen.center[1] - na[1]
        inertia = math.pi * r**4 / 4 + area * dy * dy
        youngs = d.device.bending_stiffness / inertia
        return (youngs / 6.0, 0.0, 0.0, max(d.material.bulk_modulus, 1e3 * youngs))

    def _body_energy(self, F, q, mats):
        ng = _ng()
        mesh = self.mesh
        C = F.trans * F
        J = ng.Det(F)
        c1 = mesh.MaterialCF({k: m[0] for k, m in mats.items()}, default=0.0)
        c2 = mesh.MaterialCF({k: m[1] for k, m in mats.items()}, default=0.0)
        c3 = mesh.MaterialCF({k: m[2] for k, m in mats.items()}, default=0.0)
        bulk = mesh.MaterialCF({k: m[3] for k, m in mats.items()}, default=1.0)
        # 0 in the fill (its own energy handles volume), where q then stays 0
        mixed = mesh.MaterialCF({k: 1.0 for k in mats}, default=0.0)
        iso = yeoh(isochoric_i1(ng.Trace(C), J), c1, c2, c3)
        return iso + mixed * q * (J - 1.0) - q * q / (2.0 * bulk)

    @staticmethod
    def _fill_energy(F, mu: float):
        """Compressible neo-Hookean (Poisson ratio 0.25: lambda = mu); a barrier as J -> 0."""
        ng = _ng()
        return neo_hookean(ng.Trace(F.trans * F), ng.log(ng.Det(F)), mu, mu)

    def _hoop_energy(self, u, stiffness_per_length):
        """A membrane that resists only hoop stretch (per unit reference area, N/m)."""
        ng = _ng()
        rad = ng.sqrt(ng.x * ng.x + ng.y * ng.y)
        e_theta = ng.CF((-ng.y / rad, ng.x / rad, 0.0))
        fs = ng.Id(3) + ng.Grad(u).Trace()   # surface gradient: exact on tangent vectors
        stretch = ng.Norm(fs * e_theta)
        return 0.5 * stiffness_per_length * (stretch - 1.0) ** 2

    def _volume_density(self, u):
        """x_z (cof F N)_z per reference area; N is the mesh normal (into the channel), so the
        enclosed volume, whose outward normal is -N, gets a minus sign."""
        ng = _ng()
        n = ng.specialcf.normal(3)
        fs = ng.Id(3) + ng.Grad(u).Trace()
        cof_n = ng.Cof(fs) * n
        return -(ng.z + u.Trace()[2]) * cof_n[2]

    # ------------------------------------------------------------------ state
    def set_direction(self, pressures_per_unit) -> None:
        for p, d in zip(self.direction, pressures_per_unit):
            p.Set(float(d))
        self.inverse = None   # the tangent holds the pressures' follower terms: not reused across directions

    def get_state(self) -> np.ndarray:
        return np.array(self.gf.vec.FV().NumPy(), copy=True)

    def set_state(self, values: np.ndarray) -> None:
        self.gf.vec.FV().NumPy()[:] = values

    def _update_pressure_field(self) -> None:
        """Element-wise optimum of q for the current u (L2 projection onto constants), with the
        energy's quadrature: the default one of ``Set`` (exact for constants only) put the
        condensed energy of a bent 20 mm body 10x off (-1.03e-2 J instead of -1.01e-3 J at 0.24 bar)."""
        self.q.Set(self.bulk_cf * (self.J - 1.0), bonus_intorder=4)

    def channel_volumes(self) -> np.ndarray:
        """Enclosed volume of each channel (whole body: in the half model a cut channel's doubled,
        an unmeshed one's its mirror partner's), m^3."""
        v = [bv.Energy(self.gf.vec) for bv in self.volume_forms]
        return np.array([factor * v[j] for j, factor in self.prism.channel_shares])

    def min_jacobian_ok(self) -> bool:
        """No element inverted or degenerate: det F > 0.02 at every integration point tested
        (nearly incompressible solids never legitimately get there), det F > 1e-4 in the
        compressible lumen fill, whose job is to be squeezed."""
        ng = _ng()
        bad = ng.Integrate(ng.IfPos(self._jacobian_floor() - self.J, 1.0, 0.0) * ng.dx(bonus_intorder=2),
                           self.mesh)
        return bad == 0.0

    def _jacobian_floor(self):
        return self.mesh.MaterialCF({"fill": 1e-4}, default=0.02) if self.has_fill else 0.02

    def max_isochoric_i1(self) -> float:
        """The largest isochoric first invariant I1b of the silicone over its elements' means
        (the Yeoh set's fitted range ends at its convexity limit, core/energy.py)."""
        ng = _ng()
        F = ng.Id(3) + ng.Grad(self.u)
        i1 = isochoric_i1(ng.Trace(F.trans * F), ng.Det(F))
        mean = ng.GridFunction(ng.L2(self.mesh, order=0, definedon=self.mesh.Materials("silicone")))
        mean.Set(i1)
        return float(np.max(mean.vec.FV().NumPy()))

    def worst_element(self) -> str:
        """Where the current state is most compressed: the element with the lowest mean det F,
        its region, centre (mm) and the nearest surface (which hole's wall, or the outside), so
        a failure says what collapsed."""
        ng = _ng()
        mean_j = ng.GridFunction(ng.L2(self.mesh, order=0))
        mean_j.Set(self.J - self._jacobian_floor())   # lowest margin over the region's floor
        values = mean_j.vec.FV().NumPy()
        i = int(np.argmin(values))
        floor = 1e-4 if self.mesh[ng.ElementId(ng.VOL, i)].mat == "fill" else 0.02
        return f"most compressed: {self.describe_element(i, f'mean det F {values[i] + floor:.3f}')}"

    def describe_element(self, i: int, what: str) -> str:
        """Volume element i as a failure names it: region, centre (mm), the nearest surface (which
        hole's wall, or the outside), then ``what``."""
        ng = _ng()
        el = self.mesh[ng.ElementId(ng.VOL, i)]
        centre = np.mean([self.mesh[v].point for v in el.vertices], axis=0)
        d = self.design
        surfaces = {f"channel{k} wall": c.outline for k, c in enumerate(d.channels)}
        if d.lumen is not None:
            surfaces["lumen wall"] = d.lumen.outline
        near = min(surfaces, key=lambda n: surfaces[n].distance_to_point(centre[:2]))
        if d.outer_radius - math.hypot(centre[0], centre[1]) < surfaces[near].distance_to_point(centre[:2]):
            near = "outer surface"
        return (f"{el.mat} element at x = {centre[0] * 1e3:.2f}, y = {centre[1] * 1e3:.2f}, "
                f"z = {centre[2] * 1e3:.1f} mm, next to the {near}, {what}")

    def energy(self) -> float:
        return self.a.Energy(self.gf.vec)

    def stability(self, k: int = 3):
        """The k eigenvalues nearest 0 of the condensed tangent relative to the H1 seminorm, over
        2 c1, with their modes and where the first lives (core/fe3d/stability.py). Opt-in: not
        part of Newton or the ramp's accepted steps."""
        from .stability import stability

        return stability(self, k)

    # ------------------------------------------------------------------ Newton
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
        ng = _ng()
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
        gives non-finite values is halved; below ``min_step`` the solve fails."""
        try:
            return self._newton()
        except NewtonFailure:
            # the factorisation is a failed iterate's: the tangent at the converged state the
            # caller restores must not use it (a ramp's predictor after a cut did, and stepped off)
            self.inverse = None
            raise

    def _newton(self) -> int:
        """Newton's loop: each iteration an increment (``_increment``), the shifted tangent's step
        where the plain one is no descent, a step length halved while the step is rejected
        (``_step_length``), then the convergence test (``_converged``)."""
        ng = _ng()
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
                        s.work >= self.contact.search_above * s.tol:
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
                if not math.isfinite(s.work):
                    raise NewtonFailure("Newton increment is not finite", it)
                if self.shift is not None and (self.sigma > 0.0 or slope < -s.tol):
                    # past a saddle: the plain step only once it descends the energy again
                    if not (slope > 0.0 and self._plain_step_descends(base, slope)):
                        s.work, s.budget = self._shifted_iteration(base, it, s.budget)
                        continue
                    self.sigma = 0.0   # Newton recovered
                alpha, full_cut = self._step_length(base, it)
                if alpha is None:   # every length rejected: the shifted tangent's step instead
                    s.work, s.budget = self._shifted_iteration(base, it, s.budget)
                    continue
                s.cuts_in_row = s.cuts_in_row + 1 if alpha < 1.0 else 0
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
                                f"{s.works[-1 - n]:.2e} J {n} iterations before", it - 1)

    def _increment(self, s: "_Solve", it: int) -> tuple[np.ndarray, float, bool]:
        """The iteration's increment self.du for the residual self.res: with the held factorisation
        while the last step contracted (NewtonSettings.reuse_ratio), else with a fresh one (from the
        start of the last step when that step was the reused one). Returns (the state the step
        starts from, du . r, whether the factorisation is fresh)."""
        ng = _ng()
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

    def _step_length(self, base: np.ndarray, it: int) -> tuple[float | None, str]:
        """Take base - alpha du with alpha halved from 1 while the state is not admissible: an
        inverted element, a step through the other wall, which jumps over the barrier (it acts only
        at the pairs' points), or (``contact.backtrack_on_overlap``) a growing overlap of the walls.
        Returns (alpha, why the full step was cut, "" if not); alpha None below ``min_step`` with the
        shifted tangent on; without it that raises NewtonFailure."""
        st = self.newton_settings
        backtrack = self.contact is not None and self.contact.backtrack_on_overlap
        overlap0 = self.contact.overlap_area() if backtrack else 0.0
        alpha, full_cut = 1.0, ""
        while True:
            self.gf.vec.data = base
            self.gf.vec.data -= alpha * self.du
            cut = self._rejection(locate=False)
            if not cut and backtrack and self.contact.overlap_area() > overlap0 * (1.0 + 1e-9):
                # no step into the barrier's continuation (the walls' overlap must not grow)
                cut = "pushes paired walls past the barrier's log range"
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
        """At a converged iterate: with contact, search the pairs again (``_contact_pairs_settled``);
        when they move, iterate on with the new ones (a fresh budget; False), and check the wall
        does not pass through itself (NewtonFailure). True: the solve is done."""
        if self.contact is None:
            return True
        if self.contact.settle and not self._contact_pairs_settled():
            # converged for the old pairs: iterate on with the new ones
            s.searches += 1
            if s.searches > self.contact.max_searches:
                raise NewtonFailure(f"the contact pairs did not settle in {s.searches} searches", it)
            s.budget = it + self.newton_settings.max_iterations
            s.works, s.chord = [], None
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
        ng = _ng()
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
        ng = _ng()
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
        ng = _ng()
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
        ng = _ng()
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
        ng = _ng()
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
