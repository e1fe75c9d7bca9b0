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
