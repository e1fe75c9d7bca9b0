"""How stable a converged 3D state is: the smallest eigenvalues of the condensed tangent.

The condensed tangent K (Fe3dProblem.a.mat after AssembleLinearization: the displacement
unknowns, the element pressure eliminated) is compared with the H1 seminorm's form M on the
displacement, m(v, v) = int |grad v|^2 dX, over the free unknowns:

    K v = lam M v,        lam / (2 c1)  (dimensionless; 2 c1 the silicone's shear modulus)

lam is a stiffness in Pa: the energy's second variation per |grad v|^2, so it does not scale
with the mesh (a mass form would give Pa / m^2 and a nodal norm a mesh-dependent number), and
it is the shift at which NewtonSettings(shifted_tangent=True)'s shifted tangent K + sigma M turns
singular: sigma = -lam. lam -> 0 along a ramp at a limit point or a bifurcation; lam < 0 is a
saddle. The eigenvalues nearest zero come from ARPACK in shift-invert mode on NGSolve's sparse
Cholesky factorisation of K (its LDL^T also factorises an indefinite K), so they are the
smallest in magnitude. A negative eigenvalue farther from zero than those is missed by them (a
saddle would read as a stable state), so the smallest algebraically comes from a second
shift-invert solve at -LOWEST_SHIFT x 2 c1, where K + LOWEST_SHIFT 2 c1 M is positive definite
unless the state is far past a saddle (``lowest_and_nearest_zero``); the first eigenvalue
reported is that one. Opt-in: two factorisations and a few dozen solves, not part of the Newton
loop.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .holes import is_circle


# the second solve's shift, in 2 c1 (module docstring): negative eigenvalues seen at stops are -0.003 to -0.13
LOWEST_SHIFT = 1.0


@dataclass
class Stability:
    eigenvalues: np.ndarray      # (k,) lam / (2 c1), ascending: the smallest algebraically, then the nearest zero
    modes: np.ndarray            # (k, ndof) eigenvectors in the state's layout (u and q), unit in M (J-free: m)
    max_displacement_m: np.ndarray   # (k,) the largest displacement of each unit mode at the mesh vertices
    where: str                   # the element where the first mode's |grad v|^2 is largest, and its nearest surface
    at_m: np.ndarray             # that element's centre (reference, m)
    lumen_share: float           # the first mode's share of M within ``near`` of the lumen wall (nan: no lumen)
    load_share: float            # |f . v| / (|f|_M* |v|_M) of the first mode: ~1 a limit point, ~0 a bifurcation
    extent: dict                 # the fewest elements holding ``share`` of the first mode's M: their count and
                                 # the range of their centres' reference radius r_m, angle_deg (about the axis,
                                 # from +x) and z_m, each (min, max)

    @property
    def smallest(self) -> float:
        return float(self.eigenvalues[0])


def _reference_form(problem):
    """M: the H1 seminorm's form on the displacement (q has none), assembled once per problem."""
    m = getattr(problem, "_h1_form", None)
    if m is None:
        import ngsolve as ng

        (u, _), (v, _) = problem.fes.TnT()
        m = ng.BilinearForm(problem.fes, symmetric=False)
        m += ng.InnerProduct(ng.Grad(u), ng.Grad(v)) * ng.dx
        m.Assemble()
        problem._h1_form = m
    return m


def _reference_factor(problem, M):
    """M's sparse LU over the free unknowns, computed once per problem (M and the free set are fixed)."""
    lu = getattr(problem, "_h1_factor", None)
    if lu is None:
        from scipy.sparse.linalg import splu

        lu = problem._h1_factor = splu(M.tocsc())
    return lu


def _csr(mat, idx):
    import scipy.sparse as sp

    data, cols, rows = mat.CSR()
    full = sp.csr_matrix((np.array(data), np.array(cols), np.array(rows)), shape=(mat.height, mat.width))
    if sp.triu(full, 1).nnz == 0:   # a symmetric NGSolve matrix stores its lower triangle only
        full = full + sp.tril(full, -1).T
    return full[idx][:, idx].tocsr()


def condensed_matrices(problem):
    """(K, M, idx): the condensed tangent at the current state and the reference form, as scipy CSR
    matrices over the free coupling unknowns ``idx`` (the displacement's; q and any interior bubbles
    are condensed, and M is the H1 form of the coupling unknowns alone: with bubbles the eigenvalues'
    sign and zeros are exact, their scale is not the H1 one). Factorises K
    (problem.inverse then holds it; ``Fe3dProblem.tangent`` reuses it at a converged state)."""
    import ngsolve as ng

    with ng.TaskManager():
        problem.a.AssembleLinearization(problem.gf.vec)
        problem.inverse = problem.a.mat.Inverse(problem.free, inverse="sparsecholesky")
    idx = np.nonzero(np.array(list(problem.free), dtype=bool))[0]
    return _csr(problem.a.mat, idx), _csr(_reference_form(problem).mat, idx), idx


def stability(problem, k: int = 3, near: float = 0.5e-3, tol: float = 1e-10) -> Stability:
    """``k`` eigenvalues of K v = lam M v at the current state, over 2 c1: the smallest algebraically
    and those nearest zero (module docstring, ``lowest_and_nearest_zero``), their modes, and where
    the first mode lives."""
    import ngsolve as ng
    from scipy.sparse.linalg import LinearOperator

    K, M, idx = condensed_matrices(problem)
    n = len(idx)
    inv = problem.inverse
    rhs = problem.a.mat.CreateColVector()
    out = problem.a.mat.CreateColVector()

    def solve(x):
        v = rhs.FV().NumPy()
        v[:] = 0.0
        v[idx] = np.ravel(x)
        out.data = inv * rhs
        return np.array(out.FV().NumPy()[idx], copy=True)

    mu = 2.0 * problem.design.material.c1
    lam, vec = lowest_and_nearest_zero(K, M, k, LinearOperator((n, n), matvec=solve, dtype=float),
                                       LOWEST_SHIFT * mu, tol)
    for j in range(k):   # unit in M (ARPACK's are, to its tolerance), sign: largest entry positive
        vec[:, j] /= math.sqrt(vec[:, j] @ (M @ vec[:, j]))
        if vec[np.argmax(np.abs(vec[:, j])), j] < 0:
            vec[:, j] *= -1.0
    modes = np.zeros((k, problem.fes.ndof))
    full = problem.gf.vec.CreateVector()
    with ng.TaskManager():
        for j in range(k):
            fv = full.FV().NumPy()
            fv[:] = 0.0
            fv[idx] = vec[:, j]
            full.data += problem.a.harmonic_extension * full   # the condensed unknowns' response (q)
            modes[j] = full.FV().NumPy()
    where, at, share, peak, extent = _locate(problem, modes, near)
    f = problem._load_vector().FV().NumPy()[idx]
    # the load's dual norm in M: sqrt(f . M^-1 f) (M's factorisation kept with M: it does not change)
    f_dual = math.sqrt(abs(f @ _reference_factor(problem, M).solve(f))) if f.any() else 0.0   # 0: no direction set
    load_share = abs(f @ vec[:, 0]) / f_dual if f_dual > 0 else 0.0
    return Stability(eigenvalues=lam / mu, modes=modes, max_displacement_m=peak, where=where, at_m=at,
                     lumen_share=share, load_share=float(load_share), extent=extent)


@dataclass
class ContactSplit:
    """What the lumen contact's term adds to a state's stability (``contact_split``)."""
    without_contact: float       # the smallest eigenvalue / 2 c1 of the condensed tangent less the contact term's
    past_log_range_m2: float     # wall area of the held pairs past the barrier's log range (gap < XI_MIN d_hat)


def contact_split(problem, tol: float = 1e-10) -> ContactSplit | None:
    """At the current state on the held contact pairs: the smallest eigenvalue (algebraically, shift-invert
    at -LOWEST_SHIFT x 2 c1 as in ``lowest_and_nearest_zero``) of K less the contact term's own tangent
    (the silicone and the pressures alone; the contact acts on the wall's coupling unknowns only, so
    the condensation is unchanged), and the wall area of the pairs past the barrier's log range.
    None without contact or with no pair held (the walls far apart: the term adds nothing)."""
    from scipy.sparse.linalg import eigsh

    contact = problem.contact
    if contact is None or contact.pairs_idle:
        return None
    K, M, idx = condensed_matrices(problem)
    Kc = _csr(contact.tangent_matrix(), idx)
    mu = 2.0 * problem.design.material.c1
    v0 = np.random.default_rng(0).standard_normal(len(idx))
    low = eigsh((K - Kc).tocsc(), k=1, M=M, sigma=-LOWEST_SHIFT * mu, which="LM", tol=tol, v0=v0,
                return_eigenvectors=False)
    return ContactSplit(without_contact=float(low[0]) / mu, past_log_range_m2=contact.past_log_range_area())


def lowest_and_nearest_zero(K, M, k: int, inverse_k, shift: float, tol: float = 1e-10):
    """(lam, vec) of K v = lam M v (scipy sparse K symmetric, M positive definite): the ``k``
    eigenpairs nearest zero (shift-invert with ``inverse_k``, K's inverse as a LinearOperator),
    ascending, with the smallest algebraically first where it is none of them (then the one of
    them farthest from zero is dropped). The smallest comes from shift-invert at -``shift`` (same
    units as lam), exact while lam_min > -shift and a negative eigenvalue in any case."""
    from scipy.sparse.linalg import eigsh

    n = K.shape[0]
    v0 = np.random.default_rng(0).standard_normal(n)
    lam, vec = eigsh(K, k=k, M=M, sigma=0.0, which="LM", OPinv=inverse_k, tol=tol, v0=v0)
    low, low_vec = eigsh(K, k=1, M=M, sigma=-shift, which="LM", tol=tol, v0=v0)
    if low[0] < lam.min() - 1e-6 * max(abs(low[0]), abs(lam.min()), 1e-300):
        keep = np.argsort(np.abs(lam))[:k - 1]
        lam, vec = np.concatenate([low, lam[keep]]), np.concatenate([low_vec, vec[:, keep]], axis=1)
    order = np.argsort(lam)
    return lam[order], vec[:, order]


def _locate(problem, modes, near, share: float = 0.9):
    """Where the first mode's |grad v|^2 (its density in M) is largest: that element's centre and
    nearest surface (as Fe3dProblem.worst_element names it); the share of the mode's M within ``near``
    of the lumen wall (element centres); each mode's largest displacement at the mesh vertices; the
    mode's extent (``Stability.extent``: the elements of largest M that together hold ``share`` of it)."""
    import ngsolve as ng

    mesh = problem.mesh
    gf = ng.GridFunction(problem.fes)
    dens = ng.GridFunction(ng.L2(mesh, order=0))
    gf.vec.FV().NumPy()[:] = modes[0]
    v = gf.components[0]
    dens.Set(ng.InnerProduct(ng.Grad(v), ng.Grad(v)), bonus_intorder=2)
    d = dens.vec.FV().NumPy()
    volumes = np.array(ng.Integrate(ng.CF(1.0), mesh, element_wise=True))
    centres = np.array([np.mean([mesh[p].point for p in el.vertices], axis=0) for el in mesh.Elements(ng.VOL)])
    i = int(np.argmax(d))
    w = d * volumes
    lumen = problem.design.lumen
    if lumen is not None:
        if is_circle(lumen):
            dist = np.abs(np.hypot(centres[:, 0] - lumen.center[0], centres[:, 1] - lumen.center[1]) - lumen.radius)
        else:
            dist = np.array([lumen.outline.distance_to_point(c[:2]) for c in centres])
        lumen_share = float(w[dist < near].sum() / w.sum())
    else:
        lumen_share = float("nan")
    by_m = np.argsort(w)[::-1]
    held = by_m[:int(np.searchsorted(np.cumsum(w[by_m]), share * w.sum())) + 1]
    c = centres[held]

    def span(v):
        return (float(v.min()), float(v.max()))

    extent = {"share": share, "elements": len(held), "of_elements": len(w), "r_m": span(np.hypot(c[:, 0], c[:, 1])),
              "angle_deg": span(np.degrees(np.arctan2(c[:, 1], c[:, 0]))), "z_m": span(c[:, 2])}
    where = problem.describe_element(i, f"mode density {d[i] / max(np.mean(d), 1e-300):.3g} x its mean")
    # H1's vertex unknowns are the field's values there (NGSolve's basis is hierarchical)
    dofs = np.array([problem.fes.GetDofNrs(ng.NodeId(ng.VERTEX, j))[:3] for j in range(mesh.nv)])
    peak = np.array([float(np.max(np.linalg.norm(m[dofs], axis=1))) for m in modes])
    return where, centres[i], lumen_share, peak, extent
