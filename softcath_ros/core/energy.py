"""Strain-energy densities shared by the FE rungs: one Yeoh, one compressible neo-Hookean.

Each density is a function of invariants written with + - * and powers only, so the same
function evaluates numpy arrays (the section rung, which differentiates by hand for Newton)
and NGSolve CoefficientFunctions (the fe3d rung, which differentiates symbolically). The
logarithm is the one operation the two libraries spell differently, so the neo-Hookean
density takes ln J as its argument instead of J.

The derivatives are those of the densities with respect to their own arguments; the
section rung chains them to the entries of F.
"""
from __future__ import annotations


def isochoric_i1(i1, j):
    """The isochoric first invariant J^(-2/3) I1 (3 at any pure volume change)."""
    return j ** (-2.0 / 3.0) * i1


def yeoh(i1_bar, c1, c2, c3):
    """Yeoh density W = c1 (I1b - 3) + c2 (I1b - 3)^2 + c3 (I1b - 3)^3 (units of the c_i).

    ``i1_bar``: the isochoric first invariant (``isochoric_i1``) for the decoupled form, or
    I1 of an incompressible deformation."""
    d = i1_bar - 3.0
    return c1 * d + c2 * d * d + c3 * d * d * d


def yeoh_derivatives(i1_bar, c1, c2, c3):
    """(W, dW/dI1b, d2W/dI1b^2) of ``yeoh``."""
    d = i1_bar - 3.0
    return (c1 * d + c2 * d * d + c3 * d * d * d,
            c1 + 2 * c2 * d + 3 * c3 * d * d,
            2 * c2 + 6 * c3 * d)


def neo_hookean(i1, log_j, mu, lam):
    """Compressible neo-Hookean W = mu/2 (I1 - 3 - 2 ln J) + lam/2 (ln J)^2 (units of mu, lam).

    It grows without bound as J -> 0 (ln J -> -inf), which makes it a barrier against
    collapse (the lumen fill of both FE rungs)."""
    return 0.5 * mu * (i1 - 3.0 - 2.0 * log_j) + 0.5 * lam * log_j * log_j


def neo_hookean_derivatives(log_j, mu, lam):
    """(dW/dI1, dW/d(ln J), d2W/d(ln J)^2) of ``neo_hookean`` (the mixed derivative is zero)."""
    return 0.5 * mu, lam * log_j - mu, lam


def yeoh_convexity_limit(c1, c2, c3) -> tuple[float, float] | None:
    """Where a Yeoh density stops being convex in I1b (d2W/dI1b^2 = 2 c2 + 6 c3 (I1b - 3) < 0):
    (I1b there, the uniaxial stretch lambda with lambda^2 + 2 / lambda = I1b), or None if it never
    does (c3 >= 0 and c2 >= 0). Fitted coefficients with c3 < 0 (Kulkarni's set, fitted on
    uniaxial data) say nothing beyond it: a solution that reaches it has left their range."""
    if c3 >= 0 and c2 >= 0:
        return None
    i1 = 3.0 + (max(-c2 / (3.0 * c3), 0.0) if c3 < 0 else 0.0)
    lo, hi = 1.0, 2.0
    while hi * hi + 2.0 / hi < i1:
        hi *= 2.0
    for _ in range(200):                      # lambda^2 + 2/lambda increases for lambda > 1
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mid * mid + 2.0 / mid < i1 else (lo, mid)
    return i1, 0.5 * (lo + hi)
