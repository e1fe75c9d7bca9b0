"""Quadrature rules on the reference triangle and edge, and a rule mapped onto P2 elements."""
from __future__ import annotations

import numpy as np

from .shape import p2_triangle

# 6-point, degree-4 rule on the reference triangle (Dunavant); weights sum to 1/2.
_A, _B = 0.445948490915965, 0.091576213509771
TRIANGLE_POINTS = np.array([[_A, _A], [1 - 2 * _A, _A], [_A, 1 - 2 * _A],
                            [_B, _B], [1 - 2 * _B, _B], [_B, 1 - 2 * _B]])
TRIANGLE_WEIGHTS = 0.5 * np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)
# 7-point, degree-3 rule on the vertices, midsides and centroid: it samples det F of a P2 element
# (quadratic, fixed by its six nodal values) where a barrier energy must keep it positive.
NODAL_POINTS = np.array([[0, 0], [1, 0], [0, 1], [0.5, 0], [0.5, 0.5], [0, 0.5], [1 / 3, 1 / 3]])
NODAL_WEIGHTS = np.array([3.0] * 3 + [8.0] * 3 + [27.0]) / 120.0
# 3-point Gauss on [-1, 1] for boundary edges (exact for the degree-5 volume integrands).
EDGE_POINTS = np.array([-np.sqrt(0.6), 0.0, np.sqrt(0.6)])
EDGE_WEIGHTS = np.array([5 / 9, 8 / 9, 5 / 9])


def map_rule(X, triangles, points, weights):
    """A reference rule on the P2 elements ``triangles`` (e,6) with nodes ``X``: shape values
    (q,6), physical gradients (e,q,6,2), weights dA (e,q) and reference positions (e,q,2)."""
    N, dN = p2_triangle(points[:, 0], points[:, 1])   # (q,6), (q,6,2)
    xe = X[triangles]                                  # (e,6,2)
    Jac = np.einsum("eai,qaj->eqij", xe, dN)           # dX/dxi
    detJ = Jac[..., 0, 0] * Jac[..., 1, 1] - Jac[..., 0, 1] * Jac[..., 1, 0]
    if np.any(detJ <= 0):
        raise ValueError("inverted reference element")
    invJ = np.stack([np.stack([Jac[..., 1, 1], -Jac[..., 0, 1]], -1),
                     np.stack([-Jac[..., 1, 0], Jac[..., 0, 0]], -1)], -2) / detJ[..., None, None]
    dNdX = np.einsum("qaj,eqji->eqai", dN, invJ)       # (e,q,6,2)
    return N, dNdX, detJ * weights, np.einsum("qa,eai->eqi", N, xe)
