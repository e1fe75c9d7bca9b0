"""The surrogate's table settings (part of a table's key, see ``surrogate.py``) and the test for
a 3-fold symmetric section, whose pair 0-1 half-rays then serve every pair."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..design import Design

# Bump when the table layout or the way it is built changes.
SURROGATE_VERSION = "surrogate-6"
ROTATION_COS = np.cos(np.array([0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0]))   # channel r's pair turned by r * 120 deg
ROTATION_SIN = np.sin(np.array([0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0]))


@dataclass(frozen=True)
class SurrogateSettings:
    source: str = "section"             # the rung the table is built from
    source_options: dict = field(default_factory=dict)  # its options (mesh_size, ...): part of the key
    pressure_step: float = 2000.0       # Pa between table points along a ray (3 channels: in a + b)
    initial_rays: int = 5               # 3 channels: rays over half a pair (t in [0, 1/2]) before refinement
    max_rays: int = 21                  # 3 channels: most rays over half a pair (the worst misses refined first)
    ray_tolerance: float = 0.005        # split between rays where the table misses the middle ray by more
                                        # than this in R_C (relative) ...
    ray_direction_tolerance: float = 0.2    # ... or by more than this in direction (degrees)
    answer_tolerance: float = 0.02      # pair commands are refused where a middle ray the build could not
                                        # refine further missed the table by more than this in R_C ...
    answer_direction_tolerance: float = 0.5   # ... or this in direction (degrees), from the sum it first did
    held_out_rays: int = 3              # 3 channels: rays used only to measure the error, one per pair
                                        # in turn (1 channel: always one)
    fine_points: int = 321              # 3 channels: resampled points per axis (bilinear read-out)
    common_rays: int = 3                # rays with all three pressures > 0 that measure the common-mode error
    common_tolerance: float = 0.01      # such commands are answered while within this in R_C (relative) ...
    common_direction_tolerance: float = 0.5   # ... and this in direction (degrees), refused beyond
    pairs: str = "auto"                 # 3 channels: "auto" uses the section's 3-fold symmetry when it
                                        # has it, "rotated" requires it, "each" solves every pair


def pair_mirror_angle(design: Design) -> float | None:
    """The mirror line (rad from +x) that swaps channels 0 and 1 when the section, as found from its
    outlines (core/geometry ``symmetry``, never from the channel count), maps onto itself turned by
    120 degrees with channel i -> i + 1; None otherwise. Then one half of pair 0-1 gives the other
    half and the two other pairs."""
    if design.n_channels != 3:
        return None
    from ..geometry import symmetry

    sym = symmetry(design.section)
    if sym.rotation_order != 3 or tuple(sym.rotation_permutation[:3]) != (1, 2, 0):
        return None
    mirror = next((m for m in sym.mirrors if m.permutation[:2] == (1, 0)), None)
    return None if mirror is None else mirror.angle


def symmetric_three(design: Design) -> bool:
    """A 3-channel section that turns channel i onto i + 1 and mirrors channel 0 onto 1."""
    return pair_mirror_angle(design) is not None


__all__ = ["SURROGATE_VERSION", "SurrogateSettings", "pair_mirror_angle", "symmetric_three"]
