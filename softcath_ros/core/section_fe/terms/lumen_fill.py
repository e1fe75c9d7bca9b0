"""Optional soft lumen fill: a compressible neo-Hookean solid in the lumen (a self-contact proxy).

Without contact the empty lumen of a strongly bent section collapses until its walls pass
through each other. The fill, W = mu/2 (I1 - 3 - 2 ln J) + lambda/2 (ln J)^2 with lambda = mu
(Poisson 0.25), bends and stretches with the section and grows without bound as J -> 0; J at or
below ``FILL_MIN_JACOBIAN`` at any sample point counts as inverted. Its elements are integrated
with the 7-point rule on the vertices, midsides and centroid, not the 6 interior points: det F
of a P2 element is quadratic, fixed by its values at the six nodes, so sampling the barrier
there keeps the squeezed corner elements at the lumen's shoulders from folding between
interior points (with the 6-point rule they do, from 0.225 bar at D/20). It is compressible,
so it has no element pressure.
"""
from __future__ import annotations

import numpy as np

from ...energy import neo_hookean, neo_hookean_derivatives
from ..kinematics import ElementRule, add_f33_hessian, jacobian_derivatives, kinematics, strain_rows
from . import INADMISSIBLE, Contribution

# Smallest admissible det F in the lumen fill (it is meant to be squeezed; fe3d uses the same).
FILL_MIN_JACOBIAN = 1e-4


class LumenFill:
    def __init__(self, rule: ElementRule, mu: float, dofs: np.ndarray, n_u: int):
        """``rule``: the nodal 7-point rule on the fill's elements; ``mu``: its shear modulus
        (units of c_ref); ``dofs`` (f,15) of those elements."""
        self.rule, self.mu, self.dofs, self.n_u = rule, mu, dofs, n_u

    def min_jacobian(self, x) -> float:
        kin = kinematics(self.rule, x, self.n_u)
        return float(np.min(kin.det2 * kin.f33))

    def _admissible(self, x):
        kin = kinematics(self.rule, x, self.n_u)
        J = kin.det2 * kin.f33
        return kin, J, not (np.any(J <= FILL_MIN_JACOBIAN) or np.any(kin.f33 <= 0))

    def energy(self, x, pressures) -> float:
        kin, J, ok = self._admissible(x)
        if not ok:
            return np.inf
        a = kin.entries()
        I1 = np.einsum("eqk,eqk->eq", a, a)
        return float(np.sum(self.rule.dA * neo_hookean(I1, np.log(J), self.mu, self.mu)))

    def assemble(self, x, pressures) -> Contribution:
        kin, J, ok = self._admissible(x)
        if not ok:
            return INADMISSIBLE
        rule, mu = self.rule, self.mu
        a = kin.entries()
        I1 = np.einsum("eqk,eqk->eq", a, a)
        Ja, Jaa = jacobian_derivatives(a, kin.det2, kin.f33)
        lnj = np.log(J)
        W = neo_hookean(I1, lnj, mu, mu)
        W_i1, W_l, W_ll = neo_hookean_derivatives(lnj, mu, mu)
        # chain rule to a: dI1/da = 2 a, d ln J/da = Ja / J
        g = Ja / J[..., None]
        Wa = 2 * W_i1 * a + W_l[..., None] * g
        gg = g[..., :, None] * g[..., None, :]
        Waa = 2 * W_i1 * np.eye(5) + W_l[..., None, None] * (Jaa / J[..., None, None] - gg) + W_ll * gg
        D = strain_rows(rule, kin)
        Pa = rule.dA[..., None] * Wa
        grad = np.einsum("eqk,eqkl->el", Pa, D)
        nf, nq = J.shape
        H = np.matmul(D.reshape(nf, nq * 5, 15).transpose(0, 2, 1),
                      np.matmul(rule.dA[..., None, None] * Waa, D).reshape(nf, nq * 5, 15))
        add_f33_hessian(H, Pa[..., 4], rule.N, kin.xq, *kin.globals)
        return Contribution(float(np.sum(rule.dA * W)), grad, H)
