"""Total potential of the 2.5D section problem, its gradient and Hessian (vectorised numpy).

Kinematics (the long-actuator limit). The body is a prism along Z; every section deforms
in its own plane by the same map X -> x(X) = X + u(X), and the backbone (the line through
the section-frame origin) is a circular arc of uniform curvature k = (kx, ky) per unit
deformed arc length and axial stretch lambda. With r(X, Z) = c(s) + x d1(s) + y d2(s),
s = lambda Z, and the frame turning as d3' = kx d1 + ky d2 (so the backbone bends
*towards* k, base.py's convention), dr/dZ = lambda (1 - kx x - ky y) d3, and

    F = [[dx/dX, dx/dY, 0], [dy/dX, dy/dY, 0], [0, 0, lambda (1 - k . x)]]

with x the deformed in-plane position: the side at +k is shortened. The in-plane rigid
motions are removed by three gauge conditions (mean displacement and mean rotation of
the silicone zero), so the origin stays on the body axis and k is in the body frame.

Potential per unit reference length (all terms SI, J/m):
    Pi = int_A W_iso(F) dA + sum_e A_e U(theta_e)          silicone: decoupled Yeoh, P2
                                                           displacement / P0 pressure
                                                           (theta_e the element's mean J)
       + A_f W_fibre(lambda_f)                             strain-limiting fibre, a point
                                                           fibre under uniaxial stretch
       + oint 1/2 k_h (ds/dS - 1)^2 dS                      hoop rings on the outer boundary
       + 1/2 EI_dev |k|^2                                   device in the lumen
       + int_fill W_fill(F) dA                              optional soft lumen fill
       - sum_i p_i lambda int_{channel_i, deformed} (1 - k . x) dA
The last term is the channel volume per unit length: its variation gives the follower
pressure on the walls, the axial end force p A and its moment p A lambda (lever arm).
Volumes use Green's theorem on the quadratic hole boundary.

The optional lumen fill is a self-contact proxy (as in the fe3d rung): without contact the
empty lumen of a strongly bent section collapses until its walls pass through each other.
The lumen is meshed as its own region of a compressible neo-Hookean solid,
W_fill = mu/2 (I1 - 3 - 2 ln J) + lambda/2 (ln J)^2 with lambda = mu (Poisson 0.25), with
the same out-of-plane kinematics as the silicone (it bends and stretches with the section);
W_fill grows without bound as J -> 0, and J <= 1e-4 at any of its sample points counts as
inverted. Its elements are integrated with the 7-point rule on the vertices, midsides and
centroid (degree 3), not the 6 interior points: det F of a P2 element is quadratic, fixed by
its values at the six nodes, so sampling the barrier there keeps the squeezed corner elements
at the lumen's shoulders from folding between interior points (with the 6-point rule they do,
from 0.225 bar at D/20). It is compressible, so it has no element pressure: its p_e slots stay
zero (K = 0 there).

The volumetric part is solved in mixed form: the element pressures p_e (P0) are unknowns,
statically condensed in each Newton step and updated linearly. At a solution p_e = K
(theta_e - 1) and the potential is the one above; on the way, the tangent uses p_e instead
of K (theta_e - 1), which keeps Newton's convergence radius independent of the bulk
modulus (with K / mu = 4000 a displacement-only Newton crawls).

Internally everything is non-dimensional: lengths in units of the outer radius R,
energy densities in units of the silicone's c1 (so curvature k R, energy Pi / (c1 R^2)).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..design import Design
from .mesh import SectionMesh

# 6-point, degree-4 rule on the reference triangle (Dunavant); weights sum to 1/2.
_A, _B = 0.445948490915965, 0.091576213509771
_QP = np.array([[_A, _A], [1 - 2 * _A, _A], [_A, 1 - 2 * _A], [_B, _B], [1 - 2 * _B, _B], [_B, 1 - 2 * _B]])
_QW = 0.5 * np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)
# 3-point Gauss on [-1, 1] for boundary edges (exact for the degree-5 volume integrands).
_GT = np.array([-np.sqrt(0.6), 0.0, np.sqrt(0.6)])
# 7-point, degree-3 rule on the vertices, midsides and centroid (the lumen fill's rule, see above).
_QP_FILL = np.array([[0, 0], [1, 0], [0, 1], [0.5, 0], [0.5, 0.5], [0, 0.5], [1 / 3, 1 / 3]])
_QW_FILL = np.array([3.0] * 3 + [8.0] * 3 + [27.0]) / 120.0
_GW = np.array([5 / 9, 8 / 9, 5 / 9])

N_GLOBAL = 3  # lambda, kx R, ky R
# Smallest admissible det F in the lumen fill (it is meant to be squeezed; fe3d uses the same).
FILL_MIN_JACOBIAN = 1e-4


def _p2_shape(xi, eta):
    """P2 shape functions (..., 6) and their reference gradients (..., 6, 2)."""
    l0, l1, l2 = 1 - xi - eta, xi, eta
    n = np.stack([l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1), 4 * l0 * l1, 4 * l1 * l2, 4 * l2 * l0], -1)
    dl = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])  # d(l0,l1,l2)/d(xi,eta)
    ls = [l0, l1, l2]
    parts = [(4 * ls[i] - 1)[..., None] * dl[i] for i in range(3)]
    for a, b in ((0, 1), (1, 2), (2, 0)):
        parts.append(4 * (ls[a][..., None] * dl[b] + ls[b][..., None] * dl[a]))
    return n, np.stack(parts, -2)


def _edge_shape(t):
    return (np.stack([0.5 * t * (t - 1), 1 - t * t, 0.5 * t * (t + 1)], -1),
            np.stack([t - 0.5, -2 * t, t + 0.5], -1))


def _quadrature(X, tri, points, weights):
    """Shape values (q,6), physical gradients (e,q,6,2), weights dA (e,q), reference positions
    (e,q,2) and the constant rows of da/d(dofs) (e,q,5,15) of a rule on the elements ``tri``."""
    N, dN = _p2_shape(points[:, 0], points[:, 1])       # (q,6), (q,6,2)
    xe = X[tri]                                        # (e,6,2)
    Jac = np.einsum("eai,qaj->eqij", xe, dN)           # dX/dxi
    detJ = Jac[..., 0, 0] * Jac[..., 1, 1] - Jac[..., 0, 1] * Jac[..., 1, 0]
    if np.any(detJ <= 0):
        raise ValueError("inverted reference element")
    invJ = np.stack([np.stack([Jac[..., 1, 1], -Jac[..., 0, 1]], -1),
                     np.stack([-Jac[..., 1, 0], Jac[..., 0, 0]], -1)], -2) / detJ[..., None, None]
    dNdX = np.einsum("qaj,eqji->eqai", dN, invJ)       # (e,q,6,2)
    D0 = np.zeros((len(tri), len(weights), 5, 15))
    D0[..., 0, 0:12:2] = dNdX[..., 0]
    D0[..., 1, 0:12:2] = dNdX[..., 1]
    D0[..., 2, 1:12:2] = dNdX[..., 0]
    D0[..., 3, 1:12:2] = dNdX[..., 1]
    return N, dNdX, detJ * weights, np.einsum("qa,eai->eqi", N, xe), D0


def _jacobian_derivs(a, det2, f33):
    """dJ/da (..., 5) and d2J/da2 (..., 5, 5) for a = (F11, F12, F21, F22, F33), J = det2 f33."""
    Ja = np.stack([a[..., 3] * f33, -a[..., 2] * f33, -a[..., 1] * f33, a[..., 0] * f33, det2], -1)
    Jaa = np.zeros(a.shape + (5,))
    Jaa[..., 0, 3] = Jaa[..., 3, 0] = f33
    Jaa[..., 1, 2] = Jaa[..., 2, 1] = -f33
    Jaa[..., 0, 4] = Jaa[..., 4, 0] = a[..., 3]
    Jaa[..., 3, 4] = Jaa[..., 4, 3] = a[..., 0]
    Jaa[..., 1, 4] = Jaa[..., 4, 1] = -a[..., 2]
    Jaa[..., 2, 4] = Jaa[..., 4, 2] = -a[..., 1]
    return Ja, Jaa


@dataclass
class Loads:
    pressures: np.ndarray  # (C,) non-dimensional p / c1


class SectionProblem:
    """Discrete potential for one design and mesh; ``x`` = [u (2n, in units of R), lambda, kx R, ky R]."""

    def __init__(self, design: Design, mesh: SectionMesh, hoop_tension_only: bool = False,
                 end_cap_only: bool = False, lumen_fill: float | None = None):
        """``lumen_fill``: the fill's shear modulus as a fraction of the silicone's (2 c1); the
        mesh must then have a fill region (``mesh_section(..., filled=...)``), and vice versa."""
        self.design = design
        # end_cap_only: the pressure acts only through the end caps (axial force p A at the
        # reference channel centre), as the closed form assumes; no load on the channel walls.
        self.end_cap_only = end_cap_only
        self.mesh = mesh
        R = design.outer_radius
        self.R = R
        c_ref = design.material.c1
        self.c_ref = c_ref
        mat = design.material
        self.yeoh = np.array([mat.c1, mat.c2, mat.c3]) / c_ref
        self.bulk = mat.bulk_modulus / c_ref
        silicone = mesh.silicone
        has_fill = not silicone.all()
        if has_fill != (lumen_fill is not None):
            raise ValueError("section problem: lumen_fill must be given exactly when the mesh has a fill region")
        self.fill = None if not has_fill else np.flatnonzero(~silicone)   # fill element indices
        self.fill_mu = 0.0 if lumen_fill is None else 2.0 * float(lumen_fill) * mat.c1 / c_ref
        self.bulk_e = np.where(silicone, self.bulk, 0.0)       # no volumetric term in the fill
        self.filled_holes = np.isin(np.arange(len(mesh.hole_edges)), mesh.filled)
        X = mesh.nodes / R
        self.X = X
        nn = len(X)
        self.n_u = 2 * nn
        self.n = self.n_u + N_GLOBAL                       # unknowns of the Newton system
        self.n_state = self.n + len(mesh.triangles)        # + element pressures p_e / c1
        self.i_glob = self.n_u + np.arange(N_GLOBAL)
        tri = mesh.triangles
        ne = len(tri)

        # --- element quadrature: shape values, physical gradients, weights
        self.N, self.dNdX, self.dA, self.Xq, self._D0 = _quadrature(X, tri, _QP, _QW)
        self.area_e = self.dA.sum(1)
        # the silicone's energy density is integrated over the silicone only (the fill has its own rule)
        self.dA_silicone = self.dA * silicone[:, None]
        if self.fill is not None:
            self._fill_quad = _quadrature(X, tri[self.fill], _QP_FILL, _QW_FILL)
        # element dofs: 12 displacement + 3 global
        dofs = np.empty((ne, 12 + N_GLOBAL), dtype=np.int64)
        dofs[:, 0:12:2] = 2 * tri
        dofs[:, 1:12:2] = 2 * tri + 1
        dofs[:, 12:] = self.i_glob
        self.elem_dofs = dofs

        # --- strain-limiting fibre as a point fibre inside its element
        self.fibre = None
        f = design.limiting_fibre
        if f is not None:
            e, xi = self._locate(np.asarray(f.center) / R)
            Nf, _ = _p2_shape(np.array(xi[0]), np.array(xi[1]))
            fm = f.material
            self.fibre = dict(elem=e, N=Nf, area=f.area / R**2,
                              yeoh=np.array([fm.c1, fm.c2, fm.c3]) / c_ref)

        # --- boundary edges
        Ne, dNe = _edge_shape(_GT)
        self.Ne, self.dNe = Ne, dNe
        self.hoop = None
        if design.reinforcement is not None:
            self.hoop = dict(edges=mesh.outer_edges, k=design.reinforcement.hoop_stiffness_per_length / (c_ref * R),
                             tension_only=hoop_tension_only)
            T0 = np.einsum("ga,bai->bgi", dNe, X[mesh.outer_edges])
            self.hoop["L0"] = np.linalg.norm(T0, axis=-1)   # (b,g)
        self.channel_edges = mesh.hole_edges[:design.n_channels]
        self.device_ei = 0.0 if design.device is None else design.device.bending_stiffness / (c_ref * R**4)

        # --- gauge: in-plane rigid motions are removed by pinning node A (both components) and
        # the x component of a node B above or below it (their rows become identity rows, which
        # keeps the tangent symmetric positive definite at stable states, so LDL^T needs no pivoting). Results
        # are reported in the frame where the silicone's mean displacement and mean rotation vanish
        # (``frame_state``), which does not depend on the choice of A and B.
        w = np.einsum("eq,qa->ea", self.dA_silicone, self.N)   # int N_a dA per node, silicone only
        self._w_node = np.bincount(tri.ravel(), weights=w.ravel(), minlength=nn)
        area = self._w_node.sum()
        self._centroid = self._w_node @ X / area
        r2 = np.sum(self._w_node * np.sum((X - self._centroid) ** 2, 1))
        self._rot_weights = self._w_node / r2
        # on a mirror-symmetric mesh both pins sit on the axis, so the gauge keeps the symmetry
        off_axis = 0.0 if not mesh.symmetric else np.where(X[:, 0] == 0.0, 0.0, np.inf)
        a = int(np.argmin(np.sum((X - self._centroid) ** 2, 1) + off_axis))
        b = int(np.argmax(np.abs(X[:, 1] - X[a, 1]) - 10 * np.abs(X[:, 0] - X[a, 0]) - off_axis))
        self.pinned = np.array([2 * a, 2 * a + 1, 2 * b])
        self._build_pattern()

    # ------------------------------------------------------------------ set-up helpers
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
        """Sparsity of the KKT matrix [[H, C^T], [C, 0]] and the scatter map into its CSR data."""
        blocks_r, blocks_c = [], []
        d = self.elem_dofs
        blocks_r.append(np.repeat(d, d.shape[1], axis=1).ravel())
        blocks_c.append(np.tile(d, (1, d.shape[1])).ravel())
        self._edge_dofs = []
        for edges in ([self.hoop["edges"]] if self.hoop else []) + list(self.channel_edges):
            ed = np.empty((len(edges), 6 + N_GLOBAL), dtype=np.int64)
            ed[:, 0:6:2] = 2 * edges
            ed[:, 1:6:2] = 2 * edges + 1
            ed[:, 6:] = self.i_glob
            self._edge_dofs.append(ed)
            blocks_r.append(np.repeat(ed, ed.shape[1], axis=1).ravel())
            blocks_c.append(np.tile(ed, (1, ed.shape[1])).ravel())
        gi = self.i_glob
        blocks_r.append(np.repeat(gi, 3))
        blocks_c.append(np.tile(gi, 3))
        n = self.n
        rows = np.concatenate(blocks_r)
        cols = np.concatenate(blocks_c)
        size = n
        key = rows * size + cols
        uniq, inv = np.unique(key, return_inverse=True)
        self._scatter = inv.ravel()
        self._n_entries = len(key)
        self._csr_shape = (size, size)
        m = sp.csr_matrix((np.arange(1, len(uniq) + 1, dtype=float), (uniq // size, uniq % size)), shape=(size, size))
        # position in m.data of each unique key
        order = np.asarray(m.data, dtype=np.int64) - 1
        pos = np.empty(len(uniq), dtype=np.int64)
        pos[order] = np.arange(len(uniq))
        self._pos = pos[self._scatter]
        self._csr_indices = m.indices.copy()
        self._csr_indptr = m.indptr.copy()
        self._nnz = len(uniq)
        r_of = np.repeat(np.arange(size), np.diff(self._csr_indptr))
        is_pinned = np.zeros(size, dtype=bool)
        is_pinned[self.pinned] = True
        self._pinned_entries = is_pinned[r_of] | is_pinned[self._csr_indices]
        self._pinned_diag = self._pinned_entries & (r_of == self._csr_indices) & is_pinned[r_of]

    def frame_state(self, x) -> tuple[float, np.ndarray]:
        """(lambda, k R) in the frame that follows the silicone's mean displacement and rotation.

        Moving the frame origin by o and turning it by w re-describes the same body with
        lambda' = lambda (1 - k.o) and k' = rot(-w) k / (1 - k.o) (F33 = lambda (1 - k.x))."""
        u = x[:self.n_u].reshape(-1, 2)
        lam, kx, ky = x[self.n_u:self.n]
        o = self._w_node @ u / self._w_node.sum()
        d = self.X - self._centroid
        w = float(np.sum(self._rot_weights * (d[:, 0] * (u[:, 1] - o[1]) - d[:, 1] * (u[:, 0] - o[0]))))
        s = 1 - kx * o[0] - ky * o[1]
        c, si = np.cos(w), np.sin(w)
        k = np.array([c * kx + si * ky, -si * kx + c * ky]) / s
        return lam * s, k

    def initial_state(self) -> np.ndarray:
        x = np.zeros(self.n_state)
        x[self.n_u] = 1.0
        return x

    # ------------------------------------------------------------------ kinematics
    def _element_kinematics(self, x, fill: bool = False):
        """In-plane F (e,q,2,2), F33 (e,q), deformed points (e,q,2) and the globals; ``fill``:
        at the fill's sample points on the fill elements instead of the silicone rule on all."""
        u = x[:self.n_u].reshape(-1, 2)
        lam, kx, ky = x[self.n_u:self.n]
        if fill:
            N, dNdX, _, Xq, _ = self._fill_quad
            ue = u[self.mesh.triangles[self.fill]]
        else:
            N, dNdX, Xq = self.N, self.dNdX, self.Xq
            ue = u[self.mesh.triangles]                              # (e,6,2)
        F2 = np.eye(2) + np.einsum("eai,eqaj->eqij", ue, dNdX)       # (e,q,2,2)
        xq = Xq + np.einsum("qa,eai->eqi", N, ue)
        f33 = lam * (1 - kx * xq[..., 0] - ky * xq[..., 1])
        return F2, f33, xq, (lam, kx, ky)

    def _fill_energy(self, x, order: int):
        """The lumen fill's energy (inf if a sample point is squeezed below FILL_MIN_JACOBIAN);
        with order 2 also its element gradients (f,15) and Hessians (f,15,15)."""
        F2, f33, xq, (lam, kx, ky) = self._element_kinematics(x, fill=True)
        det2 = F2[..., 0, 0] * F2[..., 1, 1] - F2[..., 0, 1] * F2[..., 1, 0]
        J = det2 * f33
        if np.any(J <= FILL_MIN_JACOBIAN) or np.any(f33 <= 0):
            return (np.inf, None, None) if order else np.inf
        N, _, dA, _, D0 = self._fill_quad
        a = np.stack([F2[..., 0, 0], F2[..., 0, 1], F2[..., 1, 0], F2[..., 1, 1], f33], -1)
        I1 = np.einsum("eqk,eqk->eq", a, a)
        if order == 0:
            return float(np.sum(dA * self._fill_density(I1, J)))
        Ja, Jaa = _jacobian_derivs(a, det2, f33)
        W, Wa, Waa = self._fill_density(I1, J, a, Ja, Jaa)
        D = self._f33_rows(D0, N, xq, lam, kx, ky)
        Pa = dA[..., None] * Wa
        g = np.einsum("eqk,eqkl->el", Pa, D)
        nf, nq = J.shape
        H = np.matmul(D.reshape(nf, nq * 5, 15).transpose(0, 2, 1),
                      np.matmul(dA[..., None, None] * Waa, D).reshape(nf, nq * 5, 15))
        self._add_f33_hessian(H, Pa[..., 4], N, xq, lam, kx, ky)
        return float(np.sum(dA * W)), g, H

    @staticmethod
    def _f33_rows(D0, N, xq, lam, kx, ky):
        """da/d(local dofs) (e,q,5,15): the constant in-plane rows D0 plus the row of F33 = lam (1 - k.x)."""
        D = D0.copy()
        D[..., 4, 0:12:2] = -lam * kx * N
        D[..., 4, 1:12:2] = -lam * ky * N
        D[..., 4, 12] = 1 - kx * xq[..., 0] - ky * xq[..., 1]
        D[..., 4, 13] = -lam * xq[..., 0]
        D[..., 4, 14] = -lam * xq[..., 1]
        return D

    # ------------------------------------------------------------------ energy only (line search)
    def energy(self, x, pressures) -> float:
        """Total potential; +inf for an inadmissible state (an inverted element or negative stretch)."""
        F2, f33, _, g = self._element_kinematics(x)
        det2 = F2[..., 0, 0] * F2[..., 1, 1] - F2[..., 0, 1] * F2[..., 1, 0]
        if np.any(det2 <= 0) or np.any(f33 <= 0):
            return np.inf
        J = det2 * f33
        I1 = np.einsum("eqij,eqij->eq", F2, F2) + f33**2
        d = J ** (-2.0 / 3.0) * I1 - 3.0
        c1, c2, c3 = self.yeoh
        E = np.sum(self.dA_silicone * (c1 * d + c2 * d**2 + c3 * d**3))
        if self.fill is not None:
            E += self._fill_energy(x, order=0)
        theta = np.sum(self.dA * J, 1) / self.area_e
        E += np.sum(self.area_e * 0.5 * self.bulk_e * (theta - 1) ** 2)
        E += self._fibre(x, g, order=0)
        E += self._hoop(x, order=0)
        E += 0.5 * self.device_ei * (g[1] ** 2 + g[2] ** 2)
        E -= float(np.dot(pressures, self.channel_volumes(x)))
        return float(E)

    def channel_volumes(self, x) -> np.ndarray:
        """Channel volume per unit reference length, lambda int (1 - k.x) dA (non-dimensional).

        With ``end_cap_only`` the channel keeps its reference cross-section in this term."""
        u = x[:self.n_u].reshape(-1, 2) * (0.0 if self.end_cap_only else 1.0)
        lam, kx, ky = x[self.n_u:self.n]
        out = []
        for edges in self.channel_edges:
            A, Sx, Sy = self._green(self.X[edges] + u[edges], order=0)
            out.append(lam * (A.sum() - kx * Sx.sum() - ky * Sy.sum()))
        return np.array(out)

    def _fill_density(self, I1, J, a=None, Ja=None, Jaa=None):
        """Compressible neo-Hookean fill, lambda = mu: W, and with ``a`` (the five entries of F)
        also dW/da and d2W/da2 (J's derivatives Ja, Jaa given)."""
        mu = lam = self.fill_mu
        lnj = np.log(J)
        W = 0.5 * mu * (I1 - 3.0) - mu * lnj + 0.5 * lam * lnj**2
        if a is None:
            return W
        g = Ja / J[..., None]                                    # d ln J / da
        s = lam * lnj - mu
        Wa = mu * a + s[..., None] * g
        gg = g[..., :, None] * g[..., None, :]
        Waa = (mu * np.eye(5) + s[..., None, None] * (Jaa / J[..., None, None] - gg)
               + lam * gg)
        return W, Wa, Waa

    def fill_min_jacobian(self, x) -> float:
        """The smallest det F in the lumen fill (inf without a fill): how squeezed the lumen is."""
        if self.fill is None:
            return np.inf
        F2, f33, _, _ = self._element_kinematics(x, fill=True)
        det2 = F2[..., 0, 0] * F2[..., 1, 1] - F2[..., 0, 1] * F2[..., 1, 0]
        return float(np.min(det2 * f33))

    def open_hole_gaps(self, x) -> np.ndarray:
        """``hole_gaps`` with the filled holes at inf: their fill resists closing, so they are no
        reason to stop (their collapse shows up as an inverted fill element instead)."""
        return np.where(self.filled_holes, np.inf, self.hole_gaps(x))

    def hole_gaps(self, x) -> np.ndarray:
        """Per hole (channels, then lumen): the smallest distance between its deformed wall points
        that are at least a quarter of the perimeter apart, relative to the hole's diameter.

        Near zero the opposite walls touch; the model has no self-contact, so it must stop there."""
        u = x[:self.n_u].reshape(-1, 2)
        out = []
        for edges in self.mesh.hole_edges:
            ids = edges[:, :2].ravel()                     # corner and midside nodes, in order
            pts = self.X[ids] + u[ids]
            m = len(ids)
            i, j = np.triu_indices(m, k=1)
            sep = np.minimum(j - i, m - (j - i))
            far = sep >= m // 4
            d = np.linalg.norm(pts[i[far]] - pts[j[far]], axis=1)
            ref = np.linalg.norm(self.X[ids] - self.X[ids].mean(0), axis=1).mean() * 2
            out.append(d.min() / ref)
        return np.array(out)

    def channel_areas(self, x) -> np.ndarray:
        u = x[:self.n_u].reshape(-1, 2)
        return np.array([self._green(self.X[e] + u[e], order=0)[0].sum() for e in self.channel_edges])

    # ------------------------------------------------------------------ full assembly
    def assemble(self, x, pressures):
        """(energy, gradient (n,), tangent (n, n) CSR, aux for the pressure update) at ``x``.

        Pinned rows/columns are identity and their gradient entries zero; energy inf (and the
        rest None) if the state is inadmissible."""
        F2, f33, xq, (lam, kx, ky) = self._element_kinematics(x)
        det2 = F2[..., 0, 0] * F2[..., 1, 1] - F2[..., 0, 1] * F2[..., 1, 0]
        if np.any(det2 <= 0) or np.any(f33 <= 0):
            return np.inf, None, None, None
        fill_part = None
        if self.fill is not None:
            fill_part = self._fill_energy(x, order=2)
            if not np.isfinite(fill_part[0]):
                return np.inf, None, None, None
        ne, nq = det2.shape
        a = np.stack([F2[..., 0, 0], F2[..., 0, 1], F2[..., 1, 0], F2[..., 1, 1], f33], -1)  # (e,q,5)
        # D = da/d(local dofs): (e,q,5,15); rows 0-3 (in-plane F) are constant
        D = self._f33_rows(self._D0, self.N, xq, lam, kx, ky)

        # isochoric Yeoh
        J = det2 * f33
        Ja, Jaa = _jacobian_derivs(a, det2, f33)
        I1 = np.einsum("eqk,eqk->eq", a, a)
        j23 = J ** (-2.0 / 3.0)
        j53 = j23 / J
        Ib = j23 * I1
        Iba = j23[..., None] * 2 * a - (2.0 / 3.0) * (j53 * I1)[..., None] * Ja
        Ibaa = (j23[..., None, None] * 2 * np.eye(5)
                - (2.0 / 3.0) * j53[..., None, None] * 2 * (a[..., :, None] * Ja[..., None, :] + Ja[..., :, None] * a[..., None, :])
                + (10.0 / 9.0) * (j53 * I1 / J)[..., None, None] * Ja[..., :, None] * Ja[..., None, :]
                - (2.0 / 3.0) * (j53 * I1)[..., None, None] * Jaa)
        c1, c2, c3 = self.yeoh
        dd = Ib - 3.0
        W = c1 * dd + c2 * dd**2 + c3 * dd**3
        W1 = c1 + 2 * c2 * dd + 3 * c3 * dd**2
        W2 = 2 * c2 + 6 * c3 * dd
        Wa = W1[..., None] * Iba
        Waa = W1[..., None, None] * Ibaa + W2[..., None, None] * Iba[..., :, None] * Iba[..., None, :]
        E = np.sum(self.dA_silicone * W)
        # volumetric (mean dilatation): U(theta_e) = K/2 (theta-1)^2, theta_e = mean J (K = 0 in the fill)
        theta = np.sum(self.dA * J, 1) / self.area_e
        Up = self.bulk_e * (theta - 1)
        p_e = x[self.n:]
        E += np.sum(self.area_e * 0.5 * self.bulk_e * (theta - 1) ** 2)
        # gradient of the condensed potential: dPi/da = Wa + K (theta - 1) Ja
        Ga = self.dA[..., None] * Ja
        G_e = np.einsum("eqk,eqkl->el", Ga, D)                                          # A_e dtheta
        Pw = self.dA_silicone[..., None] * Wa
        g_e = np.einsum("eqk,eqkl->el", Pw, D) + Up[:, None] * G_e
        # tangent with the independent element pressure p_e in the geometric terms
        Pa = Pw + p_e[:, None, None] * Ga
        Maa = self.dA_silicone[..., None, None] * (Waa + p_e[:, None, None, None] * Jaa)   # p_e = 0 in the fill
        Dr = D.reshape(ne, nq * 5, 15)
        H_e = np.matmul(Dr.transpose(0, 2, 1), np.matmul(Maa, D).reshape(ne, nq * 5, 15))
        self._add_f33_hessian(H_e, Pa[..., 4], self.N, xq, lam, kx, ky)
        H_e += (self.bulk_e / self.area_e)[:, None, None] * G_e[:, :, None] * G_e[:, None, :]
        if fill_part is not None:
            E += fill_part[0]
            g_e[self.fill] += fill_part[1]
            H_e[self.fill] += fill_part[2]

        # fibre: a point inside one element, so it adds to that element's block
        if self.fibre is not None:
            e_f, g_f, h_f = self._fibre(x, (lam, kx, ky), order=2)
            E += e_f
            g_e[self.fibre["elem"]] += g_f
            H_e[self.fibre["elem"]] += h_f
        grad = np.bincount(self.elem_dofs.ravel(), weights=g_e.ravel(), minlength=self.n)
        vals = [H_e.ravel()]
        # edges
        u = x[:self.n_u].reshape(-1, 2)
        k = 0
        if self.hoop is not None:
            e_h, g_h, h_h = self._hoop(x, order=2)
            E += e_h
            np.add.at(grad, self._edge_dofs[k].ravel(), g_h.ravel())
            vals.append(h_h.ravel())
            k += 1
        for i, edges in enumerate(self.channel_edges):
            if self.end_cap_only:
                v, gv, hv = self._volume_derivs(self.X[edges], lam, kx, ky)
                gv[:, :6] = 0.0
                hv[:, :6, :] = 0.0
                hv[:, :, :6] = 0.0
            else:
                v, gv, hv = self._volume_derivs(self.X[edges] + u[edges], lam, kx, ky)
            p = pressures[i]
            E -= p * v
            np.add.at(grad, self._edge_dofs[k].ravel(), -p * gv.ravel())
            vals.append(-p * hv.ravel())
            k += 1
        # device bending
        E += 0.5 * self.device_ei * (kx**2 + ky**2)
        grad[self.n_u + 1] += self.device_ei * kx
        grad[self.n_u + 2] += self.device_ei * ky
        vals.append(np.diag([0.0, self.device_ei, self.device_ei]).ravel())
        data = np.bincount(self._pos, weights=np.concatenate(vals), minlength=self._nnz)
        data[self._pinned_entries] = 0.0
        data[self._pinned_diag] = 1.0
        grad[self.pinned] = 0.0
        K = sp.csr_matrix((data, self._csr_indices, self._csr_indptr), shape=self._csr_shape)
        aux = (Up - p_e, (self.bulk_e / self.area_e)[:, None] * G_e)
        return float(E), grad, K, aux

    def pressure_update(self, dx, aux) -> np.ndarray:
        """Linearised change of the element pressures for a Newton step ``dx`` (condensed out)."""
        resid, kg = aux
        return resid + np.einsum("ei,ei->e", kg, dx[self.elem_dofs])

    def consistent_pressures(self, x) -> np.ndarray:
        """x with p_e = K (theta_e - 1) (the value at a solution)."""
        F2, f33, _, _ = self._element_kinematics(x)
        J = (F2[..., 0, 0] * F2[..., 1, 1] - F2[..., 0, 1] * F2[..., 1, 0]) * f33
        out = x.copy()
        out[self.n:] = self.bulk_e * (np.sum(self.dA * J, 1) / self.area_e - 1)
        return out

    @staticmethod
    def _add_f33_hessian(H, s, N, xq, lam, kx, ky):
        """H += sum_q s_q d2F33/d(dofs)^2, F33 = lam (1 - k.x), dofs (12 element u, lam, kx, ky).

        H (e,15,15), s (e,q), N (q,6), xq (e,q,2)."""
        sn = s @ N                                   # (e,6)
        sx = np.sum(s * xq[..., 0], -1)
        sy = np.sum(s * xq[..., 1], -1)
        for (rows, col, val) in ((slice(0, 12, 2), 12, -kx * sn), (slice(1, 12, 2), 12, -ky * sn),
                                 (slice(0, 12, 2), 13, -lam * sn), (slice(1, 12, 2), 14, -lam * sn)):
            H[:, rows, col] += val
            H[:, col, rows] += val
        H[:, 12, 13] -= sx
        H[:, 13, 12] -= sx
        H[:, 12, 14] -= sy
        H[:, 14, 12] -= sy

    # ------------------------------------------------------------------ fibre
    def _fibre(self, x, g, order):
        if self.fibre is None:
            return 0.0
        lam, kx, ky = g
        f = self.fibre
        nodes = self.mesh.triangles[f["elem"]]
        u = x[:self.n_u].reshape(-1, 2)
        xf = (self.X[nodes] + u[nodes]).T @ f["N"]
        s = lam * (1 - kx * xf[0] - ky * xf[1])
        i1 = s * s + 2 / s
        dd = i1 - 3
        c1, c2, c3 = f["yeoh"]
        W = f["area"] * (c1 * dd + c2 * dd**2 + c3 * dd**3)
        if order == 0:
            return W if s > 0 else np.inf
        W1 = f["area"] * (c1 + 2 * c2 * dd + 3 * c3 * dd**2)
        W2 = f["area"] * (2 * c2 + 6 * c3 * dd)
        di = 2 * s - 2 / s**2
        ws = W1 * di
        wss = W2 * di**2 + W1 * (2 + 4 / s**3)
        ds = np.zeros(15)
        ds[0:12:2] = -lam * kx * f["N"]
        ds[1:12:2] = -lam * ky * f["N"]
        ds[12] = 1 - kx * xf[0] - ky * xf[1]
        ds[13] = -lam * xf[0]
        ds[14] = -lam * xf[1]
        H = wss * np.outer(ds, ds)[None]
        self._add_f33_hessian(H, np.array([[ws]]), f["N"][None], xf[None, None], lam, kx, ky)
        return W, ws * ds, H[0]

    # ------------------------------------------------------------------ hoop rings
    def _hoop(self, x, order):
        if self.hoop is None:
            return 0.0
        h = self.hoop
        u = x[:self.n_u].reshape(-1, 2)
        edges = h["edges"]
        T = np.einsum("ga,bai->bgi", self.dNe, self.X[edges] + u[edges])  # (b,g,2)
        L = np.linalg.norm(T, axis=-1)
        L0 = h["L0"]
        ext = L - L0
        if h["tension_only"]:
            ext = np.maximum(ext, 0.0)
        w = _GW * h["k"] / L0
        E = float(np.sum(w * 0.5 * ext**2))
        if order == 0:
            return E
        t = T / L[..., None]
        gT = (w * ext)[..., None] * t                                      # dE/dT (b,g,2)
        active = (ext != 0) | (not h["tension_only"])
        tt = t[..., :, None] * t[..., None, :]
        hT = w[..., None, None] * (active[..., None, None] * tt + (ext / L)[..., None, None] * (np.eye(2) - tt))
        # T = sum_a dNe[g,a] x_a : local dof (a, i) -> index 2a+i
        Bg = np.zeros((len(_GT), 2, 6))
        Bg[:, 0, 0::2] = self.dNe
        Bg[:, 1, 1::2] = self.dNe
        g6 = np.einsum("bgi,gid->bd", gT, Bg)
        h6 = np.einsum("gid,bgij,gje->bde", Bg, hT, Bg)
        nb = len(edges)
        g9 = np.zeros((nb, 9))
        g9[:, :6] = g6
        h9 = np.zeros((nb, 9, 9))
        h9[:, :6, :6] = h6
        return E, g9, h9

    # ------------------------------------------------------------------ channel volume
    def _green(self, xe, order=0):
        """Per-edge area and first moments of the region left of the oriented edges (Green's theorem)."""
        x = xe[..., 0] @ self.Ne.T      # (b,g)
        y = xe[..., 1] @ self.Ne.T
        xp = xe[..., 0] @ self.dNe.T
        yp = xe[..., 1] @ self.dNe.T
        A = 0.5 * (x * yp - y * xp) @ _GW
        Sx = 0.5 * (x * x * yp) @ _GW
        Sy = -0.5 * (y * y * xp) @ _GW
        return A, Sx, Sy

    def _volume_derivs(self, xe, lam, kx, ky):
        """V = lam sum_edges (A - kx Sx - ky Sy), gradient (b,9) and Hessian (b,9,9) per edge.

        Local order: (x_s, y_s, x_m, y_m, x_e, y_e, lam, kx, ky)."""
        N, dN, w = self.Ne, self.dNe, _GW
        x = xe[..., 0] @ N.T
        y = xe[..., 1] @ N.T
        xp = xe[..., 0] @ dN.T
        yp = xe[..., 1] @ dN.T
        A = 0.5 * (x * yp - y * xp) @ w
        Sx = 0.5 * (x * x * yp) @ w
        Sy = -0.5 * (y * y * xp) @ w
        # first derivatives w.r.t. nodal x (X) and y (Y): (b,3)
        A_X = 0.5 * np.einsum("g,bg,ga->ba", w, yp, N) - 0.5 * np.einsum("g,bg,ga->ba", w, y, dN)
        A_Y = 0.5 * np.einsum("g,bg,ga->ba", w, x, dN) - 0.5 * np.einsum("g,bg,ga->ba", w, xp, N)
        Sx_X = np.einsum("g,bg,ga->ba", w, x * yp, N)
        Sx_Y = 0.5 * np.einsum("g,bg,ga->ba", w, x * x, dN)
        Sy_Y = -np.einsum("g,bg,ga->ba", w, y * xp, N)
        Sy_X = -0.5 * np.einsum("g,bg,ga->ba", w, y * y, dN)
        # second derivatives (b,3,3): XY block [i,j] = d2/dX_i dY_j
        A_XY = 0.5 * np.einsum("g,ga,gc->ac", w, N, dN) - 0.5 * np.einsum("g,ga,gc->ac", w, dN, N)
        Sx_XX = np.einsum("g,bg,ga,gc->bac", w, yp, N, N)
        Sx_XY = np.einsum("g,bg,ga,gc->bac", w, x, N, dN)
        Sy_YY = -np.einsum("g,bg,ga,gc->bac", w, xp, N, N)
        Sy_XY = -np.einsum("g,bg,ga,gc->bac", w, y, dN, N)
        Q = A - kx * Sx - ky * Sy
        QX = A_X - kx * Sx_X - ky * Sy_X
        QY = A_Y - kx * Sx_Y - ky * Sy_Y
        nb = len(xe)
        g = np.zeros((nb, 9))
        g[:, 0:6:2] = lam * QX
        g[:, 1:6:2] = lam * QY
        g[:, 6] = Q
        g[:, 7] = -lam * Sx
        g[:, 8] = -lam * Sy
        H = np.zeros((nb, 9, 9))
        XY = lam * (A_XY[None] - kx * Sx_XY - ky * Sy_XY)
        H[:, 0:6:2, 0:6:2] = lam * (-kx * Sx_XX)
        H[:, 1:6:2, 1:6:2] = lam * (-ky * Sy_YY)
        H[:, 0:6:2, 1:6:2] = XY
        H[:, 1:6:2, 0:6:2] = np.swapaxes(XY, 1, 2)
        H[:, 0:6:2, 6] = H[:, 6, 0:6:2] = QX
        H[:, 1:6:2, 6] = H[:, 6, 1:6:2] = QY
        H[:, 0:6:2, 7] = H[:, 7, 0:6:2] = -lam * Sx_X
        H[:, 1:6:2, 7] = H[:, 7, 1:6:2] = -lam * Sx_Y
        H[:, 0:6:2, 8] = H[:, 8, 0:6:2] = -lam * Sy_X
        H[:, 1:6:2, 8] = H[:, 8, 1:6:2] = -lam * Sy_Y
        H[:, 6, 7] = H[:, 7, 6] = -Sx
        H[:, 6, 8] = H[:, 8, 6] = -Sy
        return lam * Q.sum(), g, H
