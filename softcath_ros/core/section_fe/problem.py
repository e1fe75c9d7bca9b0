"""Total potential of the 2.5D section problem as a sum of terms, its gradient and Hessian.

Kinematics (the long-actuator limit, ``kinematics.py``). The body is a prism along Z; every
section deforms in its own plane by the same map X -> x(X) = X + u(X), and the backbone (the
line through the section-frame origin) is a circular arc of uniform curvature k = (kx, ky) per
unit deformed arc length and axial stretch lambda. With r(X, Z) = c(s) + x d1(s) + y d2(s),
s = lambda Z, and the frame turning as d3' = kx d1 + ky d2 (so the backbone bends *towards* k,
base.py's convention), dr/dZ = lambda (1 - kx x - ky y) d3: the side at +k is shortened. The
in-plane rigid motions are removed by a gauge (``SectionProblem._place_gauge``), so the origin
stays on the body axis and k is in the body frame.

Potential per unit reference length (all terms SI, J/m), one module per term in ``terms/``:
    Pi = int_A W_iso(F) dA + sum_e A_e U(theta_e)    silicone.py: decoupled Yeoh, P2 displacement /
                                                     P0 pressure (theta_e the element's mean J)
       + int_fill W_fill(F) dA                       lumen_fill.py: optional soft lumen fill
       + A_f W_fibre(lambda_f)                       fibre.py: strain-limiting point fibre
       + oint 1/2 k_h (ds/dS - 1)^2 dS               hoop.py: hoop rings on the outer boundary
       - sum_i p_i V_i                               pressure_volume.py: channel volumes
       + 1/2 EI_dev |k|^2                            device.py: device in the lumen
       + kappa sum l_i b(gap_ij^2)                    contact.py: self-contact of each empty hole's wall

Internally everything is non-dimensional: lengths in units of the outer radius R,
energy densities in units of the silicone's c1 (so curvature k R, energy Pi / (c1 R^2)).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..design import Design
from ..energy import isochoric_i1
from ..errors import ModelError
from .kinematics import N_GLOBAL, ElementRule, block_dofs, kinematics
from .mesh import SectionMesh
from .quadrature import NODAL_POINTS, NODAL_WEIGHTS, TRIANGLE_POINTS, TRIANGLE_WEIGHTS
from .shape import p2_triangle
from .terms import Contribution, SparseContribution, Term
from .terms.contact import DeviceContact, WallContact, segments_cross
from .terms.device import DeviceBending
from .terms.fibre import Fibre
from .terms.hoop import HoopRings
from .terms.lumen_fill import FILL_MIN_JACOBIAN, LumenFill
from .terms.pressure_volume import ChannelPressure
from .terms.ring_bending import RingBending
from .terms.silicone import SiliconeBody

__all__ = ["SectionProblem", "N_GLOBAL", "FILL_MIN_JACOBIAN"]


class SectionProblem:
    """Discrete potential for one design and mesh; ``x`` = [u (2n, in units of R), lambda, kx R,
    ky R, element pressures / c1]. ``terms`` lists the potential's terms (``terms/``)."""

    def __init__(self, design: Design, mesh: SectionMesh, hoop_tension_only: bool = False,
                 end_cap_only: bool = False, lumen_fill: float | None = None,
                 contact_distance: float | None = None, ring_bending: bool = False):
        """``lumen_fill``: the fill's shear modulus as a fraction of the silicone's (2 c1); the
        mesh must then have a fill region (``mesh_section(..., filled=...)``), and vice versa.
        ``contact_distance``: self-contact of every empty hole's wall (channels and lumen) with this
        barrier distance, as a fraction of the hole's diameter (of the circle of its area if not
        round; ``terms/contact.py``); None: no contact. ``ring_bending``: the rings' own bending stiffness.
        ``end_cap_only``: the pressure acts only through the end caps (the closed form's load)."""
        self.design = design
        self.end_cap_only = end_cap_only
        self.mesh = mesh
        self.R = design.outer_radius
        self.c_ref = design.material.c1
        has_fill = not mesh.silicone.all()
        if has_fill != (lumen_fill is not None):
            raise ValueError("section problem: lumen_fill must be given exactly when the mesh has a fill region")
        self.fill = None if not has_fill else np.flatnonzero(~mesh.silicone)   # fill element indices
        self.filled_holes = np.isin(np.arange(len(mesh.hole_edges)), mesh.filled)
        self._number_unknowns(contact_distance)
        self._list_terms(hoop_tension_only, ring_bending, lumen_fill, contact_distance)
        self._place_gauge()
        # terms in order of assembly: the silicone (the costly one) last, so an inadmissible state
        # (crossed walls) is found before it is assembled
        self._assembly_order = [i for i in range(len(self.terms)) if self.terms[i] is not self.body] + \
            [self.terms.index(self.body)]
        self._build_pattern()

    @property
    def area_e(self) -> np.ndarray:
        """Reference element areas (/ R^2), silicone and fill."""
        return self.body.area_e

    # ------------------------------------------------------------------ set-up helpers
    def _number_unknowns(self, contact_distance: float | None) -> None:
        """Reference nodes ``X`` (/ R) and the numbering of the unknowns: 2 per node, then the
        globals (lambda, k R), then one pressure per element."""
        design, mesh, R = self.design, self.mesh, self.R
        X = mesh.nodes / R
        # a device in an empty lumen with wall contact lies free in it: its centre is one more node
        # (in no element), at the lumen's centre at rest
        self.device_node = None
        if (contact_distance is not None and design.device is not None and design.lumen is not None
                and not self.filled_holes[design.n_channels]):
            self.device_node = len(X)
            X = np.vstack([X, np.asarray(design.lumen.center) / R])
        self.X = X
        self.n_u = 2 * len(X)
        self.n = self.n_u + N_GLOBAL                       # unknowns of the Newton system
        self.n_state = self.n + len(mesh.triangles)        # + element pressures p_e / c1
        self.i_glob = self.n_u + np.arange(N_GLOBAL)
        self.elem_dofs = block_dofs(mesh.triangles, self.i_glob)

    def _list_terms(self, hoop_tension_only: bool, ring_bending: bool, lumen_fill: float | None,
                    contact_distance: float | None) -> None:
        """The terms of the potential (adding one: write a module in terms/ and list it here)."""
        design, mesh, X, R, c_ref = self.design, self.mesh, self.X, self.R, self.c_ref
        mat = design.material
        tri = mesh.triangles
        self.rule = ElementRule(X, tri, TRIANGLE_POINTS, TRIANGLE_WEIGHTS)
        self.body = SiliconeBody(self.rule, mesh.silicone, (mat.c1 / c_ref, mat.c2 / c_ref, mat.c3 / c_ref),
                                 mat.bulk_modulus / c_ref, self.elem_dofs, self.n_u, self.n)
        self.terms: list[Term] = [self.body]
        self.lumen_fill = None
        if self.fill is not None:
            self.lumen_fill = LumenFill(ElementRule(X, tri[self.fill], NODAL_POINTS, NODAL_WEIGHTS),
                                        2.0 * float(lumen_fill) * mat.c1 / c_ref, self.elem_dofs[self.fill], self.n_u)
            self.terms.append(self.lumen_fill)
        f = design.limiting_fibre
        if f is not None:
            e, xi = self._locate(np.asarray(f.center) / R)
            Nf, _ = p2_triangle(np.array(xi[0]), np.array(xi[1]))
            fm = f.material
            self.terms.append(Fibre(X, tri, e, Nf, f.area / R**2, (fm.c1 / c_ref, fm.c2 / c_ref, fm.c3 / c_ref),
                                    self.elem_dofs[[e]], self.n_u))
        if design.reinforcement is not None:
            self.terms.append(HoopRings(X, mesh.outer_edges,
                                        design.reinforcement.hoop_stiffness_per_length / (c_ref * R),
                                        hoop_tension_only, block_dofs(mesh.outer_edges, self.i_glob), self.n_u))
            if ring_bending:
                self.terms.append(RingBending(X, mesh.outer_edges,
                                              design.reinforcement.hoop_bending_stiffness_per_length / (c_ref * R**3),
                                              lambda nodes: block_dofs(nodes, self.i_glob), self.n_u))
        self.channels = [ChannelPressure(X, edges, i, self.end_cap_only, block_dofs(edges, self.i_glob), self.n_u)
                         for i, edges in enumerate(mesh.hole_edges[:design.n_channels])]
        self.terms += self.channels
        self._list_contact(contact_distance)
        if design.device is not None:
            self.terms.append(DeviceBending(design.device.bending_stiffness / (c_ref * R**4), self.i_glob))

    def _list_contact(self, contact_distance: float | None) -> None:
        """Each empty hole's wall contact (``contact``), and the lumen wall's with a free device."""
        design, mesh, X, R = self.design, self.mesh, self.X, self.R
        self.contact: list[tuple[int, WallContact]] = []   # (hole index, its wall contact)
        self.device = None                                  # the lumen wall's contact with the device
        holes = design.section.holes
        for i in range(len(holes) if contact_distance is not None else 0):
            if self.filled_holes[i]:
                continue
            # a hole's size: the diameter of the circle of its area (its diameter if round)
            size = 2.0 * np.sqrt(holes[i].area / np.pi)
            wall = WallContact(X, mesh.hole_edges[i], contact_distance * size / R, self.n_u)
            self.contact.append((i, wall))
            self.terms.append(wall)
            if self.device_node is not None and holes[i].role == "lumen":
                room = design.section.largest_inscribed_diameter(holes[i])
                if design.device.diameter >= room:
                    raise ModelError(f"design '{design.name}': the device ({design.device.diameter} m) does "
                                     f"not fit in the lumen (largest circle in it {room:.6g} m)")
                self.device = DeviceContact(X, mesh.hole_edges[i], 0.5 * design.device.diameter / R,
                                            wall.d_hat, self.device_node, self.n_u)
                self.terms.append(self.device)

    def _place_gauge(self) -> None:
        """Gauge: in-plane rigid motions are removed by pinning node A (both components) and the x
        component of a node B above or below it (their rows become identity rows, which keeps the
        tangent symmetric positive definite at stable states, so LDL^T needs no pivoting). Results
        are reported in the frame where the silicone's mean displacement and mean rotation vanish
        (``frame_state``), which does not depend on the choice of A and B."""
        X, nn = self.X, len(self.X)
        w = np.einsum("eq,qa->ea", self.body.dA_silicone, self.rule.N)   # int N_a dA per node, silicone only
        self._w_node = np.bincount(self.mesh.triangles.ravel(), weights=w.ravel(), minlength=nn)
        area = self._w_node.sum()
        self._centroid = self._w_node @ X / area
        r2 = np.sum(self._w_node * np.sum((X - self._centroid) ** 2, 1))
        self._rot_weights = self._w_node / r2
        # on a mirror-symmetric mesh both pins sit on the axis, so the gauge keeps the symmetry
        off_axis = 0.0 if not self.mesh.symmetric else np.where(X[:, 0] == 0.0, 0.0, np.inf)
        if self.device_node is not None:        # the free device is no gauge node
            off_axis = off_axis + np.where(np.arange(nn) == self.device_node, np.inf, 0.0)
        a = int(np.argmin(np.sum((X - self._centroid) ** 2, 1) + off_axis))
        b = int(np.argmax(np.abs(X[:, 1] - X[a, 1]) - 10 * np.abs(X[:, 0] - X[a, 0]) - off_axis))
        self.pinned = np.array([2 * a, 2 * a + 1, 2 * b])

    def _locate(self, point):
        """Element containing ``point`` and its reference coordinates (straight-sided inverse map)."""
        p = self.X[self.mesh.triangles[:, :3]]
        v0, v1, v2 = p[:, 0], p[:, 1], p[:, 2]
        m = np.stack([v1 - v0, v2 - v0], -1)               # (e,2,2)
        xi = np.linalg.solve(m, (point - v0)[..., None])[..., 0]
        inside = (xi[:, 0] >= -1e-12) & (xi[:, 1] >= -1e-12) & (xi.sum(1) <= 1 + 1e-12) & self.mesh.silicone
        if not inside.any():
            raise ValueError("fibre centre is not inside the meshed silicone")
        e = int(np.flatnonzero(inside)[0])
        return e, xi[e]

    def _build_pattern(self):
        """Sparsity of the tangent from the terms' blocks and the scatter map into its CSR data."""
        blocks_r, blocks_c = [], []
        for term in self.terms:
            d = term.dofs
            blocks_r.append(np.repeat(d, d.shape[1], axis=1).ravel())
            blocks_c.append(np.tile(d, (1, d.shape[1])).ravel())
        self._grad_dofs = np.concatenate([term.dofs.ravel() for term in self.terms])
        rows = np.concatenate(blocks_r)
        cols = np.concatenate(blocks_c)
        size = self.n
        key = rows * size + cols
        uniq, inv = np.unique(key, return_inverse=True)
        self._csr_shape = (size, size)
        m = sp.csr_matrix((np.arange(1, len(uniq) + 1, dtype=float), (uniq // size, uniq % size)), shape=(size, size))
        # position in m.data of each unique key
        order = np.asarray(m.data, dtype=np.int64) - 1
        pos = np.empty(len(uniq), dtype=np.int64)
        pos[order] = np.arange(len(uniq))
        self._pos = pos[inv.ravel()]
        ends = np.cumsum([term.dofs.size * term.dofs.shape[1] for term in self.terms])
        self._term_pos = np.split(self._pos, ends[:-1])        # each term's blocks' entries
        self._csr_indices = m.indices.copy()
        self._csr_indptr = m.indptr.copy()
        self._nnz = len(uniq)
        r_of = np.repeat(np.arange(size), np.diff(self._csr_indptr))
        is_pinned = np.zeros(size, dtype=bool)
        is_pinned[self.pinned] = True
        pinned_entries = is_pinned[r_of] | is_pinned[self._csr_indices]
        self._pinned_entries = np.flatnonzero(pinned_entries)
        self._pinned_diag = np.flatnonzero(pinned_entries & (r_of == self._csr_indices) & is_pinned[r_of])

    def frame_state(self, x) -> tuple[float, np.ndarray]:
        """(lambda, k R) in the frame that follows the silicone's mean displacement and rotation.

        Moving the frame origin by o and turning it by w re-describes the same body with
        lambda' = lambda (1 - k.o) and k' = rot(-w) k / (1 - k.o) (F33 = lambda (1 - k.x)).
        w is the best-fit (least-squares, weighted by the silicone's area) rotation of the
        reference section onto the deformed one: exact for any finite rigid turn, so states that
        differ by one (another gauge) report the same k."""
        lam, kx, ky = x[self.n_u:self.n]
        o, w = self.frame_motion(x)
        s = 1 - kx * o[0] - ky * o[1]
        c, si = np.cos(w), np.sin(w)
        k = np.array([c * kx + si * ky, -si * kx + c * ky]) / s
        return lam * s, k

    def frame_motion(self, x) -> tuple[np.ndarray, float]:
        """The silicone's mean displacement (/ R) and its best-fit (least-squares, area-weighted)
        rotation (rad) from the reference section to the deformed one."""
        u = x[:self.n_u].reshape(-1, 2)
        o = self._w_node @ u / self._w_node.sum()
        d = self.X - self._centroid
        v = u - o
        w = float(np.arctan2(np.sum(self._rot_weights * (d[:, 0] * v[:, 1] - d[:, 1] * v[:, 0])),
                             1.0 + np.sum(self._rot_weights * (d[:, 0] * v[:, 0] + d[:, 1] * v[:, 1]))))
        return o, w

    def initial_state(self) -> np.ndarray:
        x = np.zeros(self.n_state)
        x[self.n_u] = 1.0
        return x

    def _element_kinematics(self, x):
        """In-plane F (e,q,2,2), F33 (e,q), deformed points (e,q,2) and the globals at the
        silicone rule's points on every element."""
        kin = kinematics(self.rule, x, self.n_u)
        return kin.F2, kin.f33, kin.xq, kin.globals

    # ------------------------------------------------------------------ energy only (line search)
    def energy(self, x, pressures) -> float:
        """Total potential; +inf for an inadmissible state (an inverted element or negative stretch)."""
        E = 0.0
        for term in (self.terms[i] for i in self._assembly_order):
            e = term.energy(x, pressures)
            if not np.isfinite(e):
                return np.inf
            E += e
        return float(E)

    def channel_volumes(self, x) -> np.ndarray:
        """Channel volume per unit reference length, lambda int (1 - k.x) dA (non-dimensional).

        With ``end_cap_only`` the channel keeps its reference cross-section in this term."""
        return np.array([c.volume(x) for c in self.channels])

    def load_vector(self, x, direction) -> tuple[float, np.ndarray]:
        """(d . V, its gradient (n,)) for channel pressures p = mu d: the load's conjugate and
        -dg/dmu, the derivative of the potential's gradient with respect to the load factor mu
        (pinned entries zero)."""
        d = np.asarray(direction, dtype=float)
        b = np.zeros(self.n)
        for c in self.channels:
            if d[c.channel] != 0.0:
                grad = c.assemble(x, np.eye(len(d))[c.channel]).gradient   # -dV_i per block
                b -= d[c.channel] * np.bincount(c.dofs.ravel(), weights=grad.ravel(), minlength=self.n)
        b[self.pinned] = 0.0
        return float(d @ self.channel_volumes(x)), b

    def channel_areas(self, x) -> np.ndarray:
        """Deformed channel cross-sections (/ R^2)."""
        return np.array([c.area(x) for c in self.channels])

    def fill_min_jacobian(self, x) -> float:
        """The smallest det F in the lumen fill (inf without a fill): how squeezed the lumen is."""
        return np.inf if self.lumen_fill is None else self.lumen_fill.min_jacobian(x)

    def open_hole_gaps(self, x) -> np.ndarray:
        """``hole_gaps`` with the filled holes and the holes with wall contact at inf: their fill
        or contact resists closing, so they are no reason to stop (a collapsing fill shows up as
        an inverted fill element instead)."""
        resisted = self.filled_holes.copy()
        for i, _ in self.contact:
            resisted[i] = True
        return self.hole_gaps(x, ~resisted)

    def max_isochoric_i1(self, x) -> float:
        """The largest isochoric first invariant I1b in the silicone (at the quadrature points)."""
        kin = kinematics(self.rule, x, self.n_u)
        J = kin.det2 * kin.f33
        I1 = np.einsum("eqij,eqij->eq", kin.F2, kin.F2) + kin.f33**2
        return float(np.max(np.where(self.body.dA_silicone > 0, isochoric_i1(I1, J), 3.0)))

    def smallest_tangent_eigenvalue(self, x, pressures) -> float:
        """The tangent's eigenvalue nearest zero at ``x`` (pressures / c1): it goes to zero at a limit
        point or a bifurcation of the pressure-controlled path."""
        import scipy.sparse.linalg as spla

        K = self.assemble(x, pressures)[2]
        return float(spla.eigsh(K.tocsc(), k=1, sigma=-1e-9, which="LM", return_eigenvectors=False)[0])

    def crossed_walls(self, x) -> list[int]:
        """Holes without contact or fill whose wall polygon (corner and midside nodes) crosses
        itself at ``x``: walls that have passed through each other, which ``hole_gaps`` (opposite
        walls only) does not see when a folded shoulder crosses locally."""
        u = x[:self.n_u].reshape(-1, 2)
        resisted = {i for i, _ in self.contact} | set(np.flatnonzero(self.filled_holes).tolist())
        out = []
        for i, edges in enumerate(self.mesh.hole_edges):
            if i in resisted:
                continue
            ids = edges[:, :2].ravel()
            m = len(ids)
            a, b = np.triu_indices(m, k=2)
            keep = (b - a) <= m - 2
            if np.any(segments_cross(self.X[ids] + u[ids], a[keep], b[keep])):
                out.append(i)
        return out

    def contact_min_gap(self, x) -> float:
        """The smallest wall-to-wall distance (m) of the holes with contact (inf without contact;
        negative if a wall polygon crosses itself)."""
        return min((w.min_gap(x) * self.R for _, w in self.contact), default=np.inf)

    def contact_active(self, x) -> bool:
        """Some wall point is within the contact barrier's distance of the wall (or the device's)."""
        return (any(w.energy(x, None) > 0 for _, w in self.contact)
                or (self.device is not None and bool(np.any(self.device.gaps(x) < self.device.d_hat))))

    def device_min_gap(self, x) -> float:
        """The smallest distance (m) between the lumen wall and the device (inf without one)."""
        return np.inf if self.device is None else float(self.device.gaps(x).min() * self.R)

    def hole_gaps(self, x, holes=None) -> np.ndarray:
        """Per hole (channels, then lumen): the smallest distance between its deformed wall points
        that are at least a quarter of the perimeter apart along it, relative to the hole's size
        (twice its wall's mean distance from its centroid: the diameter of a circle); only where
        ``holes`` (bool per hole) is True if given, inf elsewhere.

        Near zero the opposite walls touch; the model has no self-contact, so it must stop there."""
        u = x[:self.n_u].reshape(-1, 2)
        out = []
        for k, edges in enumerate(self.mesh.hole_edges):
            if holes is not None and not holes[k]:
                out.append(np.inf)
                continue
            ids = edges[:, :2].ravel()                     # corner and midside nodes, in order
            pts = self.X[ids] + u[ids]
            m = len(ids)
            # separation along the reference wall (its spacing is graded): a quarter of the perimeter
            step = np.linalg.norm(np.diff(self.X[ids], axis=0, append=self.X[ids[:1]]), axis=1)
            s = np.concatenate([[0.0], np.cumsum(step)])
            perimeter, s = s[-1], s[:-1]
            i, j = np.triu_indices(m, k=1)
            sep = np.minimum(s[j] - s[i], perimeter - (s[j] - s[i]))
            far = sep >= 0.25 * perimeter * (1 - 1e-9)
            d = np.linalg.norm(pts[i[far]] - pts[j[far]], axis=1)
            ref = np.linalg.norm(self.X[ids] - self.X[ids].mean(0), axis=1).mean() * 2
            out.append(d.min() / ref)
        return np.array(out)

    # ------------------------------------------------------------------ full assembly
    def assemble(self, x, pressures):
        """(energy, gradient (n,), tangent (n, n) CSR, aux for the pressure update) at ``x``.

        Pinned rows/columns are identity and their gradient entries zero; energy inf (and the
        rest None) if the state is inadmissible."""
        parts: list[Contribution | None] = [None] * len(self.terms)
        for i in self._assembly_order:          # the cheap admissibility tests (contact) first
            c = self.terms[i].assemble(x, pressures)
            if not np.isfinite(c.energy):
                return np.inf, None, None, None
            parts[i] = c
        E = 0.0
        for c in parts:
            E += c.energy
        grad = np.bincount(self._grad_dofs, weights=np.concatenate([c.gradient.ravel() for c in parts]),
                           minlength=self.n)
        if any(isinstance(c, SparseContribution) for c in parts):
            # only the non-zero entries of the mostly-zero blocks (the same sums: a zero adds nothing)
            sparse = [isinstance(c, SparseContribution) for c in parts]
            data = np.bincount(
                np.concatenate([pos[c.keys] if s else pos for c, pos, s in zip(parts, self._term_pos, sparse)]),
                weights=np.concatenate([c.values if s else c.hessian.ravel() for c, s in zip(parts, sparse)]),
                minlength=self._nnz)
        else:
            data = np.bincount(self._pos, weights=np.concatenate([c.hessian.ravel() for c in parts]),
                               minlength=self._nnz)
        data[self._pinned_entries] = 0.0
        data[self._pinned_diag] = 1.0
        grad[self.pinned] = 0.0
        K = sp.csr_matrix((data, self._csr_indices, self._csr_indptr), shape=self._csr_shape)
        return float(E), grad, K, parts[0].condensation

    def pressure_update(self, dx, aux) -> np.ndarray:
        """Linearised change of the element pressures for a Newton step ``dx`` (condensed out)."""
        return self.body.pressure_update(dx, aux)

    def consistent_pressures(self, x) -> np.ndarray:
        """x with p_e = K (theta_e - 1) (the value at a solution)."""
        out = x.copy()
        out[self.n:] = self.body.consistent_pressures(x)
        return out
