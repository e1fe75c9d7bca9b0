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

import math

import numpy as np

from ..design import Design
from ..energy import isochoric_i1, neo_hookean, yeoh
from .contact import INTORDER, LumenContact
from .holes import hole_size
from .mesh import MeshSettings, PrismMesh, build_mesh
from .newton import Fe3dNewton
from .newton_settings import NewtonSettings


def check_element(pressure_order, interior_order) -> None:
    """Raise ValueError (one line) unless the element orders are ones Fe3dProblem builds:
    ``pressure_order`` 0 or 1, ``interior_order`` None or an integer >= 3."""
    if isinstance(pressure_order, bool) or pressure_order not in (0, 1):
        raise ValueError(f"pressure_order must be 0 (P2/P0) or 1 (P2/P1), not {pressure_order!r}")
    if interior_order is not None and (isinstance(interior_order, bool) or not isinstance(interior_order, int)
                                       or interior_order < 3):
        raise ValueError(f"interior_order must be an integer >= 3 or None, not {interior_order!r}")


def _ng():
    import ngsolve

    return ngsolve


class Fe3dProblem(Fe3dNewton):
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
        self.stalled = None          # the last Newton solve's stalled iterate (newton.Stall), if it stalled

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

    def contact_split(self):
        """The smallest eigenvalue without the lumen contact's term and the pairs past the barrier's
        log range, at the current state (core/fe3d/stability.py ``contact_split``); None without pairs."""
        from .stability import contact_split

        return contact_split(self)
