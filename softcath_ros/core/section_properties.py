"""Transformed (modulus-weighted) cross-section of the actuator for beam theory.

Everything is expressed in silicone-equivalent area: a part of Young's modulus E
counts as (E / E_silicone) times its area. The fibre replaces silicone where it
sits, so it adds (n - 1) of its area. A device in the lumen slides freely, so it
adds its own bending stiffness (N m^2) but no axial stiffness and does not move
the neutral axis. Holes of any shape: a circle by its formulas, other outlines by exact
integrals over their lines and arcs (core/geometry; exact where a meshed integral, e.g.
sectionproperties', would carry its mesh's error, and with no extra dependency).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .design import Design, Hole


@dataclass(frozen=True)
class TransformedSection:
    youngs_modulus: float          # Pa, silicone reference modulus (small strain)
    axial_stiffness: float         # EA, N
    neutral_axis: np.ndarray       # (2,) m, modulus-weighted centroid
    bending_stiffness: np.ndarray  # (2, 2) N m^2 about the neutral axis, device included
    silicone_area: float           # m^2, body minus holes
    pressure_areas: np.ndarray     # (C,) m^2, each channel's end-cap area (its hole's area)
    pressure_centroids: np.ndarray  # (C, 2) m, where each channel's end-cap force acts

    @property
    def pressure_offsets(self) -> np.ndarray:
        """(C, 2) m: each channel's centroid from the neutral axis (the pressure force's lever arm)."""
        return self.pressure_centroids - self.neutral_axis


def _disk_second_moment(radius: float) -> float:
    """Second moment of area of a disk about a centroidal axis, m^4."""
    return math.pi * radius**4 / 4.0


def hole_properties(hole) -> tuple[float, np.ndarray, np.ndarray]:
    """(area, centroid (2,), centroidal second-moment tensor (2, 2)) of a hole, exact: a circle
    by its formulas, any other outline by exact integrals over its lines and arcs (core/geometry)."""
    if isinstance(hole, Hole):
        return hole.area, np.asarray(hole.center, dtype=float), _disk_second_moment(hole.radius) * np.eye(2)
    integrals = hole.outline.integrals
    return integrals.area, integrals.centroid, integrals.centroidal_second


def transformed_section(design: Design) -> TransformedSection:
    e_sil = design.material.youngs_modulus
    # (weight, area, centre, centroidal second-moment tensor) of each part; holes have weight -1.
    parts = [(1.0, math.pi * design.outer_radius**2, np.zeros(2), _disk_second_moment(design.outer_radius) * np.eye(2))]
    holes = list(design.channels) + ([design.lumen] if design.lumen is not None else [])
    for h in holes:
        parts.append((-1.0, *hole_properties(h)))
    silicone_area = sum(w * a for w, a, _, _ in parts)
    f = design.limiting_fibre
    if f is not None:
        n = f.material.youngs_modulus / e_sil
        parts.append((n - 1.0, f.area, np.asarray(f.center, dtype=float),
                      _disk_second_moment(0.5 * f.diameter) * np.eye(2)))

    weighted_area = sum(w * a for w, a, _, _ in parts)
    centroid = sum(w * a * c for w, a, c, _ in parts) / weighted_area
    inertia = np.zeros((2, 2))
    for w, a, c, j0 in parts:
        d = c - centroid
        # J_ab = int (r - r0)_a (r - r0)_b dA about the neutral axis (parallel axes), which is what
        # the curvature law needs.
        inertia += w * (j0 + a * np.outer(d, d))
    stiffness = e_sil * inertia
    if design.device is not None:
        stiffness = stiffness + design.device.bending_stiffness * np.eye(2)
    channel_parts = [hole_properties(c) for c in design.channels]
    return TransformedSection(youngs_modulus=e_sil, axial_stiffness=e_sil * weighted_area,
                              neutral_axis=centroid, bending_stiffness=stiffness,
                              silicone_area=silicone_area,
                              pressure_areas=np.array([a for a, _, _ in channel_parts]),
                              pressure_centroids=np.array([c for _, c, _ in channel_parts]))
