"""Convergence rate of the section rung under mesh refinement (in the manner of scikit-fem's tests).

R_C = L / theta (the radius of the arc through base and tip) at a fixed pressure is computed on a
sequence of mesh spacings h; with the finest mesh as the reference, the slope of log |error|
against log h is the observed order. The 3-channel design is used because its error is smooth
in h from D/12 on; the implemented design's point fibre (a concentrated load inside one
element) makes its error small but erratic on coarse meshes, which a rate fit cannot use.
"""
import numpy as np

from softcath_ros.core.design import load_design
from softcath_ros.core.models.section import SectionModel
from softcath_ros.core.units import PA_PER_BAR

DIVISIONS = (12, 16, 20, 24, 32)     # h = D / division (D/20 is the rung's default)
REFERENCE_DIVISION = 64
# Measured slope 2.5 on the 3-fold symmetric mesh (errors 1.8 / 0.78 / 0.58 / 0.31 / 0.14 %;
# 3.2 on the former mirror-only mesh, whose D/12 error was larger, 2.9 %, and the later ones
# alike), P2 displacement, quadratic boundaries; a P1-like loss of accuracy (order 2 or less),
# a quadrature or geometry error that stalls convergence, or a non-converging term falls outside.
SLOPE_BAND = (2.3, 4.0)


def _radius_l_over_theta(design, division, pressure_pa):
    model = SectionModel(design, mesh_size=design.outer_diameter / division)
    ps = np.zeros((1, design.n_channels))
    ps[0, 0] = pressure_pa
    state = model.evaluate(ps)
    assert state.converged.all(), state.message
    kappa = np.hypot(*state.curvature[0]) * state.axial_stretch[0]   # tip angle per unit reference length
    return model.mesh.h, 1.0 / kappa


def test_section_radius_of_curvature_converges_at_the_expected_rate():
    design = load_design("three_channel_5mm")
    p = 0.15 * PA_PER_BAR
    _, reference = _radius_l_over_theta(design, REFERENCE_DIVISION, p)
    h, radius = np.array([_radius_l_over_theta(design, n, p) for n in DIVISIONS]).T
    error = np.abs(radius - reference) / reference
    slope = np.polyfit(np.log(h), np.log(error), 1)[0]
    assert SLOPE_BAND[0] <= slope <= SLOPE_BAND[1], f"observed order {slope:.2f}, errors {error}"
    assert np.all(np.diff(error) < 0), f"the error does not fall with h: {error}"
    assert error[DIVISIONS.index(20)] < 0.01     # the default mesh: within 1 % of the reference
