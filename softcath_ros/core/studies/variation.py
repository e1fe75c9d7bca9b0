"""Design variants for the studies: every variant goes through the design-file validation.

A variant is built from the baseline's design-file mapping with some fields changed and then
validated (``design_from_dict``), so a study never runs a design a user could not load.
A variant that breaks a rule (a wall thinner than the minimum, a hole outside the body, a
thread wider than its pitch) is kept as *infeasible* with the ``DesignError``'s reason, so the
study reports it instead of crashing or silently dropping it.

Studies that move walls below the baseline's own ``min_wall_thickness`` (channel shift,
area ratio, miniaturisation) pass ``min_wall``: the variant is validated against that
fabrication limit instead, and the row says whether the baseline's own minimum holds.
"""
from __future__ import annotations

import copy
import itertools
import math
from dataclasses import dataclass

from ..design import Design, design_from_dict
from ..errors import DesignError


@dataclass(frozen=True)
class Variant:
    """One case of a study: the design (None if infeasible) and what was changed."""

    label: str                  # human-readable, e.g. "pitch = 0.6 mm"
    parameter: str              # which parameter the study varies
    value: object               # its value in the study's units (SI unless the name says so)
    design: Design | None
    reason: str = ""            # why infeasible (the DesignError text), empty when feasible
    baseline: bool = False
    info: tuple = ()            # extra (name, value) pairs for the study's table

    @property
    def feasible(self) -> bool:
        return self.design is not None


def make_variant(base: Design, label: str, parameter: str, value, edit, *, baseline: bool = False,
                 min_wall: float | None = None, info: dict | None = None) -> Variant:
    """Apply ``edit(mapping)`` (changes the design-file mapping in place) and validate.

    ``min_wall`` (m) replaces the baseline's minimum wall for the validation."""
    data = copy.deepcopy(base.to_dict())
    if min_wall is not None:
        data["min_wall_thickness"] = min_wall
    try:
        edit(data)
        design = design_from_dict(data, source=base.source)
    except DesignError as exc:
        return Variant(label, parameter, value, None, str(exc), baseline, tuple((info or {}).items()))
    return Variant(label, parameter, value, design, "", baseline, tuple((info or {}).items()))


def min_wall_of(design: Design) -> float:
    """The thinnest silicone wall of a design (m): the true minimum distance between its real
    outlines, holes to the outer surface and to each other (core/geometry)."""
    return design.section.thinnest_wall().thickness


def channel_wall_of(design: Design) -> float:
    """The thinnest silicone wall between two of a design's channels (m; inf with one channel):
    the true minimum distance between their outlines, as the design validation measures it."""
    section = design.section
    return min((section.wall_between(a, b, locate=False).thickness
                for a, b in itertools.combinations(section.channels, 2)), default=math.inf)


def stacked_layout(outer_diameter: float, lumen_diameter: float, outer_wall: float, middle_wall: float,
                   bottom_wall: float) -> dict:
    """The implemented design's 1-DOF layout along the y axis, bottom to top:
    bottom wall (holding the fibre) / lumen / middle wall / channel / outer wall.

    The channel fills what is left: diameter D - d_l - the three walls (m). Returns the
    ``channels``, ``lumen`` and fibre centre of the design-file mapping (the fibre sits in the
    middle of the bottom wall, where the implemented design has it)."""
    big_r = 0.5 * outer_diameter
    d_c = outer_diameter - lumen_diameter - outer_wall - middle_wall - bottom_wall
    if d_c <= 0:
        raise DesignError("channels[0].diameter", d_c,
                          f"no room for the channel: {outer_diameter * 1e3:.2f} mm body minus lumen and walls")
    return {"channels": [{"diameter": tidy(d_c), "center": [0.0, tidy(big_r - outer_wall - 0.5 * d_c)]}],
            "lumen": {"diameter": lumen_diameter, "center": [0.0, tidy(-big_r + bottom_wall + 0.5 * lumen_diameter)]},
            "fibre_center": [0.0, tidy(-big_r + 0.5 * bottom_wall)]}


def tidy(x: float) -> float:
    """Round a length to 1e-12 m: far below any tolerance, keeps written design files readable."""
    return round(x, 12) + 0.0


def apply_stacked(data: dict, layout: dict) -> None:
    """Write a ``stacked_layout`` into a design-file mapping (the fibre follows the bottom wall)."""
    data["channels"] = layout["channels"]
    data["lumen"] = layout["lumen"]
    if data.get("limiting_fibre") is not None:
        data["limiting_fibre"]["center"] = layout["fibre_center"]


def scale_design_dict(data: dict, s: float) -> None:
    """Scale every length of a design-file mapping by ``s`` in place (geometric similarity):
    body, holes, fibre, reinforcement pitch and thread, cap, length and the minimum wall.
    Materials, pressures and the device's stiffness are not lengths and stay."""
    for key in ("length", "outer_diameter", "cap_thickness", "min_wall_thickness"):
        data[key] *= s
    for hole in data["channels"] + ([data["lumen"]] if data.get("lumen") else []):
        hole["diameter"] *= s
        hole["center"] = [c * s for c in hole["center"]]
    if data.get("limiting_fibre"):
        data["limiting_fibre"]["diameter"] *= s
        data["limiting_fibre"]["center"] = [c * s for c in data["limiting_fibre"]["center"]]
    if data.get("reinforcement"):
        data["reinforcement"]["pitch"] *= s
        data["reinforcement"]["thread_diameter"] *= s
    if data.get("device"):
        data["device"]["diameter"] *= s


def area_ratio(design: Design) -> float:
    """Total pressurised channel area over the body's cross-section area (docs/actuator.md's key
    parameter), from the real outlines' exact areas (core/geometry)."""
    return design.section.area_ratio
