"""Transformed (modulus-weighted) cross-section of the actuator for beam theory.

Everything is expressed in silicone-equivalent area: a part of Young's modulus E
counts as (E / E_silicone) times its area. The fibre replaces silicone where it
sits, so it adds (n - 1) of its area. A device in the lumen slides freely, so it
adds its own bending stiffness (N m^2) but no axial stiffness and does not move
the neutral axis.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .design import Design


@dataclass(frozen=True)
class TransformedSection:
    youngs_modulus: float          # Pa, silicone reference modulus (small strain)
    axial_stiffness: float         # EA, N
    neutral_axis: np.ndarray       # (2,) m, modulus-weighted centroid
    bending_stiffness: np.ndarray  # (2, 2) N m^2 about the neutral axis, device included
    silicone_area: float           # m^2, body minus holes


def _disk_second_moment(radius: float) -> float:
    """Second moment of area of a disk about a centroidal axis, m^4."""
    return math.pi * radius**4 / 4.0


def transformed_section(design: Design) -> TransformedSection:
    e_sil = design.material.youngs_modulus
    # (weight, area, centre, centroidal I) of each part; holes have weight -1.
    parts = [(1.0, math.pi * design.outer_radius**2, (0.0, 0.0), _disk_second_moment(design.outer_radius))]
    holes = list(design.channels) + ([design.lumen] if design.lumen is not None else [])
    for h in holes:
        parts.append((-1.0, h.area, h.center, _disk_second_moment(h.radius)))
    silicone_area = sum(w * a for w, a, _, _ in parts)
    f = design.limiting_fibre
    if f is not None:
        n = f.material.youngs_modulus / e_sil
        parts.append((n - 1.0, f.area, f.center, _disk_second_moment(0.5 * f.diameter)))

    weighted_area = sum(w * a for w, a, _, _ in parts)
    centroid = np.array([sum(w * a * c[k] for w, a, c, _ in parts) for k in (0, 1)]) / weighted_area
    inertia = np.zeros((2, 2))
    for w, a, c, i0 in parts:
        dx, dy = c[0] - centroid[0], c[1] - centroid[1]
        # Tensor of second moments about the centroid: [[Iyy-like, -Ixy], ...] written as
        # J_ab = int (r - r0)_a (r - r0)_b dA, which is what the curvature law needs.
        inertia += w * (np.array([[i0 + a * dx * dx, a * dx * dy], [a * dx * dy, i0 + a * dy * dy]]))
    stiffness = e_sil * inertia
    if design.device is not None:
        stiffness = stiffness + design.device.bending_stiffness * np.eye(2)
    return TransformedSection(youngs_modulus=e_sil, axial_stiffness=e_sil * weighted_area,
                              neutral_axis=centroid, bending_stiffness=stiffness,
                              silicone_area=silicone_area)
