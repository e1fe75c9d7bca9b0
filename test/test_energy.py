"""The shared strain-energy densities (core/energy.py): values, derivatives, rest state, and that
the same functions build NGSolve CoefficientFunctions."""
import numpy as np
import pytest

from softcath_ros.core.energy import isochoric_i1, neo_hookean, neo_hookean_derivatives, yeoh, yeoh_derivatives
from softcath_ros.core.materials import PRESETS, material_from_spec

YEOH = (12.7e3, 423.0, -1.46)     # Pa, the Ecoflex 00-30 set
MU = LAM = 500.0                  # Pa


def _yeoh_of_f(F):
    return yeoh(isochoric_i1(np.sum(F * F), np.linalg.det(F)), *YEOH)


def _neo_hookean_of_f(F):
    return neo_hookean(np.sum(F * F), np.log(np.linalg.det(F)), MU, LAM)


def _fd_gradient(fun, F, eps=1e-6):
    g = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            dF = np.zeros((3, 3))
            dF[i, j] = eps
            g[i, j] = (fun(F + dF) - fun(F - dF)) / (2 * eps)
    return g


def test_yeoh_value():
    d = 0.7
    assert yeoh(3.0 + d, *YEOH) == pytest.approx(YEOH[0] * d + YEOH[1] * d**2 + YEOH[2] * d**3, rel=1e-15)
    assert material_from_spec("ecoflex_0030_kulkarni").strain_energy(3.0 + d) == yeoh(3.0 + d, *YEOH)
    assert PRESETS["ecoflex_0030_kulkarni"]["c1"] == YEOH[0]


@pytest.mark.parametrize("i1_bar", [3.0, 3.2, 4.5, 9.0])
def test_yeoh_derivatives_match_finite_differences(i1_bar):
    W, W1, W2 = yeoh_derivatives(i1_bar, *YEOH)
    h = 1e-5
    assert W == yeoh(i1_bar, *YEOH)
    assert W1 == pytest.approx((yeoh(i1_bar + h, *YEOH) - yeoh(i1_bar - h, *YEOH)) / (2 * h), rel=1e-9)
    w1 = lambda s: yeoh_derivatives(s, *YEOH)[1]  # noqa: E731
    assert W2 == pytest.approx((w1(i1_bar + h) - w1(i1_bar - h)) / (2 * h), rel=1e-7)


@pytest.mark.parametrize("i1, log_j", [(3.0, 0.0), (3.4, -0.2), (5.0, 0.3)])
def test_neo_hookean_derivatives_match_finite_differences(i1, log_j):
    W_i1, W_l, W_ll = neo_hookean_derivatives(log_j, MU, LAM)
    h = 1e-6
    assert W_i1 == pytest.approx((neo_hookean(i1 + h, log_j, MU, LAM) - neo_hookean(i1 - h, log_j, MU, LAM)) / (2 * h),
                                 rel=1e-8)
    assert W_l == pytest.approx((neo_hookean(i1, log_j + h, MU, LAM) - neo_hookean(i1, log_j - h, MU, LAM)) / (2 * h),
                                rel=1e-7, abs=1e-6)
    dl = lambda s: neo_hookean_derivatives(s, MU, LAM)[1]  # noqa: E731
    assert W_ll == pytest.approx((dl(log_j + h) - dl(log_j - h)) / (2 * h), rel=1e-8)


@pytest.mark.parametrize("energy_of_f", [_yeoh_of_f, _neo_hookean_of_f])
def test_zero_energy_and_stress_at_identity(energy_of_f):
    F = np.eye(3)
    assert energy_of_f(F) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(_fd_gradient(energy_of_f, F), 0.0, atol=1e-5)   # P = dW/dF, Pa


def test_yeoh_is_isochoric_and_stresses_a_stretch():
    # a pure volume change leaves the isochoric energy at zero; a uniaxial stretch does not
    assert _yeoh_of_f(1.1 * np.eye(3)) == pytest.approx(0.0, abs=1e-9)
    F = np.diag([1.2, 1 / np.sqrt(1.2), 1 / np.sqrt(1.2)])
    P = _fd_gradient(_yeoh_of_f, F)
    assert P[0, 0] > 0
    assert _yeoh_of_f(F) > 0


def test_neo_hookean_is_a_barrier_against_collapse():
    w = [_neo_hookean_of_f(np.diag([1.0, 1.0, s])) for s in (0.5, 1e-3, 1e-6)]
    assert w[0] < w[1] < w[2] and w[2] > 100 * w[0]


def test_the_same_functions_build_ngsolve_coefficient_functions():
    ng = pytest.importorskip("ngsolve")
    from netgen.geom2d import unit_square

    mesh = ng.Mesh(unit_square.GenerateMesh(maxh=0.5))
    i1, j = 4.1, 1.05
    w_cf = yeoh(isochoric_i1(ng.CF(i1), ng.CF(j)), *YEOH)
    assert ng.Integrate(w_cf, mesh) == pytest.approx(yeoh(isochoric_i1(i1, j), *YEOH), rel=1e-12)
    n_cf = neo_hookean(ng.CF(i1), ng.log(ng.CF(j)), MU, LAM)
    assert ng.Integrate(n_cf, mesh) == pytest.approx(neo_hookean(i1, np.log(j), MU, LAM), rel=1e-12)
