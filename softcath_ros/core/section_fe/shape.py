"""Quadratic (P2) shape functions on the reference triangle and on a boundary edge."""
from __future__ import annotations

import numpy as np


def p2_triangle(xi, eta):
    """The six P2 shape functions (..., 6) (vertices, then midsides 01, 12, 20) and their
    reference gradients (..., 6, 2) at reference points (xi, eta)."""
    l0, l1, l2 = 1 - xi - eta, xi, eta
    n = np.stack([l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1), 4 * l0 * l1, 4 * l1 * l2, 4 * l2 * l0], -1)
    dl = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])  # d(l0,l1,l2)/d(xi,eta)
    ls = [l0, l1, l2]
    parts = [(4 * ls[i] - 1)[..., None] * dl[i] for i in range(3)]
    for a, b in ((0, 1), (1, 2), (2, 0)):
        parts.append(4 * (ls[a][..., None] * dl[b] + ls[b][..., None] * dl[a]))
    return n, np.stack(parts, -2)


def p2_edge(t):
    """The three quadratic shape functions (start, middle, end) on [-1, 1] and their derivatives."""
    return (np.stack([0.5 * t * (t - 1), 1 - t * t, 0.5 * t * (t + 1)], -1),
            np.stack([t - 0.5, -2 * t, t + 0.5], -1))
