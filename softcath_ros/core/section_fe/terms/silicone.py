"""The silicone body: decoupled Yeoh energy, P2 displacement, P0 element pressure (mixed u-p).

    int_A W_iso(F) dA + sum_e A_e K/2 (theta_e - 1)^2,   theta_e = the element's mean J

The volumetric part is solved in mixed form: the element pressures p_e are unknowns,
statically condensed in each Newton step and updated linearly (``pressure_update``). At a
solution p_e = K (theta_e - 1) and the potential is the one above; on the way the tangent uses
p_e instead of K (theta_e - 1), which keeps Newton's convergence radius independent of the bulk
modulus (with K / mu = 4000 a displacement-only Newton crawls). The term covers every element
(its blocks carry the element pattern); elements of the lumen fill get zero weight and K = 0.
"""
from __future__ import annotations

import numpy as np

from ...energy import isochoric_i1, yeoh, yeoh_derivatives
from ..kinematics import (ElementRule, add_f33_hessian, add_jacobian_hessian, jacobian_gradient, kinematics,
                          strain_rows)
from . import INADMISSIBLE, Contribution


class SiliconeBody:
    def __init__(self, rule: ElementRule, silicone: np.ndarray, yeoh_coefficients, bulk: float,
                 dofs: np.ndarray, n_u: int, n: int):
        """``rule``: the 6-point rule on all elements; ``silicone`` (e,) bool; Yeoh c1..c3 and the
        bulk modulus K in units of c_ref; ``dofs`` (e,15); the element pressures are x[n:]."""
        self.rule, self.dofs, self.n_u, self.n = rule, dofs, n_u, n
        self.yeoh = yeoh_coefficients
        self.area_e = rule.dA.sum(1)
        self.dA_silicone = rule.dA * silicone[:, None]
        self.bulk_e = np.where(silicone, bulk, 0.0)
        self._bulk_per_area = self.bulk_e / self.area_e

    def _theta(self, J):
        return np.sum(self.rule.dA * J, 1) / self.area_e

    def energy(self, x, pressures) -> float:
        kin = kinematics(self.rule, x, self.n_u)
        det2, f33 = kin.det2, kin.f33
        if np.any(det2 <= 0) or np.any(f33 <= 0):
            return np.inf
        J = det2 * f33
        I1 = np.einsum("eqij,eqij->eq", kin.F2, kin.F2) + f33**2
        E = np.sum(self.dA_silicone * yeoh(isochoric_i1(I1, J), *self.yeoh))
        theta = self._theta(J)
        return E + np.sum(self.area_e * 0.5 * self.bulk_e * (theta - 1) ** 2)

    def assemble(self, x, pressures) -> Contribution:
        rule = self.rule
        kin = kinematics(rule, x, self.n_u)
        det2, f33 = kin.det2, kin.f33
        if np.any(det2 <= 0) or np.any(f33 <= 0):
            return INADMISSIBLE
        ne, nq = det2.shape
        a = kin.entries()                                     # (e,q,5)
        D = strain_rows(rule, kin)                            # (e,q,5,15)
        J = det2 * f33
        Ja = jacobian_gradient(a, det2, f33)
        I1 = np.einsum("eqk,eqk->eq", a, a)
        # isochoric invariant Ib = J^(-2/3) I1 and its derivatives in a:
        #   dIb/da = 2 j23 a - 2/3 j53 I1 Ja,
        #   d2Ib/da2 = 2 j23 1 - 4/3 j53 (a Ja^T + Ja a^T) + 10/9 j53 I1 / J Ja Ja^T - 2/3 j53 I1 Jaa,
        # j23 = J^(-2/3), j53 = J^(-5/3); W'' dIb dIb^T expands in the same outer products, so the
        # tangent's material matrix is assembled from them with one coefficient each
        j23 = J ** (-2.0 / 3.0)
        j53 = j23 / J
        Ib = isochoric_i1(I1, J)
        ca, cj = 2 * j23, -(2.0 / 3.0) * j53 * I1          # dIb/da = ca a + cj Ja
        Iba = ca[..., None] * a + cj[..., None] * Ja
        W, W1, W2 = yeoh_derivatives(Ib, *self.yeoh)
        Wa = W1[..., None] * Iba
        E = np.sum(self.dA_silicone * W)
        # volumetric (mean dilatation): U(theta_e) = K/2 (theta-1)^2 (K = 0 in the fill)
        theta = self._theta(J)
        Up = self.bulk_e * (theta - 1)
        p_e = x[self.n:]
        E += np.sum(self.area_e * 0.5 * self.bulk_e * (theta - 1) ** 2)
        # gradient of the condensed potential: dPi/da = Wa + K (theta - 1) Ja
        Ga = rule.dA[..., None] * Ja
        G_e = np.einsum("eqk,eqkl->el", Ga, D)                                          # A_e dtheta
        Pw = self.dA_silicone[..., None] * Wa
        g_e = np.einsum("eqk,eqkl->el", Pw, D) + Up[:, None] * G_e
        # tangent with the independent element pressure p_e in the geometric terms:
        # M = dA (W1 d2Ib + W2 dIb dIb^T + p_e Jaa)   (p_e = 0 in the fill)
        dA = self.dA_silicone
        c_eye = dA * W1 * 2 * j23
        c_aa = dA * W2 * ca * ca
        c_aj = dA * (W2 * ca * cj - W1 * (4.0 / 3.0) * j53)
        c_jj = dA * (W2 * cj * cj + W1 * (10.0 / 9.0) * j53 * I1 / J)
        c_hess = dA * (W1 * cj + p_e[:, None])
        # c_aa a a^T + c_aj (a Ja^T + Ja a^T) + c_jj Ja Ja^T, as two outer products
        # (einsum's outer products: the same single products as broadcasting, in less time)
        Maa = np.einsum("...i,...j->...ij", c_aa[..., None] * a + c_aj[..., None] * Ja, a)
        Maa += np.einsum("...i,...j->...ij", c_aj[..., None] * a + c_jj[..., None] * Ja, Ja)
        add_jacobian_hessian(Maa, c_hess, a, f33)
        Maa.reshape(ne, nq, 25)[..., ::6] += c_eye[..., None]       # the diagonal
        Pa = Pw + p_e[:, None, None] * Ga
        Dr = D.reshape(ne, nq * 5, 15)
        H_e = np.matmul(Dr.transpose(0, 2, 1), np.matmul(Maa, D).reshape(ne, nq * 5, 15))
        add_f33_hessian(H_e, Pa[..., 4], rule.N, kin.xq, *kin.globals)
        H_e += np.einsum("ei,ej->eij", self._bulk_per_area[:, None] * G_e, G_e)
        return Contribution(float(E), g_e, H_e, condensation=(Up - p_e, self._bulk_per_area[:, None] * G_e))

    def pressure_update(self, dx, condensation) -> np.ndarray:
        """Linearised change of the element pressures for a Newton step ``dx`` (condensed out)."""
        resid, kg = condensation
        return resid + np.einsum("ei,ei->e", kg, dx[self.dofs])

    def consistent_pressures(self, x) -> np.ndarray:
        """The element pressures K (theta_e - 1) of the state ``x`` (their value at a solution)."""
        kin = kinematics(self.rule, x, self.n_u)
        return self.bulk_e * (self._theta(kin.det2 * kin.f33) - 1)
