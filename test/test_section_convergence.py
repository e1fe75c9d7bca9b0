"""Convergence of the section rung under mesh refinement (in the manner of scikit-fem's tests).

R_C = L / theta (the radius of the arc through base and tip) at a fixed pressure is computed on a
sequence of mesh spacings h; with a fine mesh as the reference, the observed order is measured
between two bands of meshes, h = D/10..D/16 and D/20..D/32 (the bands' geometric-mean spacings are
a factor 2 apart): order = log2(RMS error of the coarse band / RMS error of the fine band). Bands
rather than a fitted line through single meshes: the meshes are unstructured (Triangle), so the
error at one h scatters by a few tenths of a percent about its trend (three_channel_5mm: 0.36,
0.92, 0.16, 0.42 % at D/10, 12, 14, 16), which a line through five points turns into a slope of
anything from 1.7 to 4.5. A P1-like loss of accuracy, a quadrature or geometry error that stalls
convergence (a wall discretised with a fixed count: found this way), or a non-converging term
shows as an order at or below 1.
"""
import math

import numpy as np

from sector_designs import three_sector
from softcath_ros.core.design import load_design
from softcath_ros.core.models.section import SectionModel
from softcath_ros.core.units import PA_PER_BAR

COARSE = (10, 12, 14, 16)            # h = D / division (D/20 is the rung's default)
FINE = (20, 24, 28, 32)


def _radius_l_over_theta(design, division, pressure_pa):
    model = SectionModel(design, mesh_size=design.outer_diameter / division)
    ps = np.zeros((1, design.n_channels))
    ps[0, 0] = pressure_pa
    state = model.evaluate(ps)
    assert state.converged.all(), state.message
    kappa = np.hypot(*state.curvature[0]) * state.axial_stretch[0]   # tip angle per unit reference length
    return model.mesh.h, 1.0 / kappa


def _band_errors(design, pressure_pa, reference_division):
    _, reference = _radius_l_over_theta(design, reference_division, pressure_pa)
    error = {n: abs(_radius_l_over_theta(design, n, pressure_pa)[1] - reference) / reference for n in COARSE + FINE}
    rms = [math.sqrt(np.mean([error[n] ** 2 for n in band])) for band in (COARSE, FINE)]
    return error, math.log2(rms[0] / rms[1])


def test_section_radius_of_curvature_converges_at_the_expected_rate():
    """Circles (three_channel_5mm, 0.15 bar, reference D/64). Measured: order 2.36 (coarse band RMS
    0.31 %, fine band 0.06 %); D/20 within 0.094 % of the reference (the former lattice mesher: 0.58 %)."""
    error, order = _band_errors(load_design("three_channel_5mm"), 0.15 * PA_PER_BAR, 64)
    assert order >= 2.0, f"observed order {order:.2f}, errors {error}"
    assert error[20] < 0.005                   # the default mesh: within 0.5 % of the reference
    assert max(error[n] for n in FINE) < 0.0025


def test_sector_design_converges():
    """Sector channels with sharp corners (0.05 bar, reference D/48). The silicone's re-entrant
    corners make its stresses singular there, and the error meets a floor of a few tenths of a
    percent from D/20 on. Measured: coarse band RMS 0.47 %, fine band 0.26 % (order 0.83), D/20
    within 0.47 %, every mesh from D/10 within 0.87 %. So this asserts convergence (the fine band
    below the coarse one) and the level, not a rate."""
    error, order = _band_errors(three_sector(), 0.05 * PA_PER_BAR, 48)
    assert order >= 0.5, f"observed order {order:.2f}, errors {error}"
    assert error[20] < 0.01
    assert max(error.values()) < 0.015
