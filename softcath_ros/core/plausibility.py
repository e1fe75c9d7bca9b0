"""Plausible magnitudes of a design: outside them a value is almost always a unit slip (millimetres
for metres, bar for pascals), refused naming the field, the value and the likely intended value."""
from __future__ import annotations

from .errors import DesignError

# Magnitudes a catheter-scale soft actuator can have.
PLAUSIBLE_LENGTH = (1.0e-3, 2.0)          # m: body length
PLAUSIBLE_SIZE = 0.1                      # m: largest diameter, offset, thickness or pitch on the section
PLAUSIBLE_PRESSURE = (1.0e3, 2.0e6)       # Pa: max_pressure (0.01 to 20 bar)
PLAUSIBLE_MODULUS = (100.0, 1.0e12)       # Pa: Yeoh c1, thread Young's modulus


def _plausible_size(value: float, field_name: str, upper: float = PLAUSIBLE_SIZE) -> float:
    if abs(value) > upper:
        raise DesignError(field_name, value, f"{value:g} m {field_name} is implausible: design files are in "
                                             f"metres; {value * 1e-3:g}?")
    return value


def _plausible_pascals(value: float, field_name: str, bounds: tuple[float, float], guess) -> float:
    """``value`` (Pa) within ``bounds``; below them ``guess(value)`` names the likely intended value."""
    lo, hi = bounds
    if value < lo:
        raise DesignError(field_name, value, f"{value:g} Pa {field_name} is implausible: design files are in "
                                             f"pascals; {guess(value)}?")
    if value > hi:
        raise DesignError(field_name, value, f"{value:g} Pa ({value / 1e5:g} bar) {field_name} is implausible "
                                             f"(above {hi:g} Pa): design files are in pascals")
    return value


def pressure_guess(v: float) -> str:
    return f"{v * 1e5:g} ({v:g} bar)" if v <= 20 else f"{v * 1e3:g} ({v:g} kPa)"


def _modulus_guess(v: float) -> str:
    return f"{v * 1e3:g} ({v:g} kPa)" if v >= 1 else f"{v * 1e6:g} ({v:g} MPa)"


def plausible_length(value: float) -> float:
    """A body length (m) a catheter-scale actuator can have, else the slip named (mm for m)."""
    if value < PLAUSIBLE_LENGTH[0]:
        raise DesignError("length", value, f"{value:g} m length is implausible (below "
                                           f"{PLAUSIBLE_LENGTH[0] * 1e3:g} mm): lengths are in metres")
    return _plausible_size(value, "length", PLAUSIBLE_LENGTH[1])


def check_plausible(design) -> None:
    """Refuse magnitudes no catheter-scale actuator has, naming field, value and the likely slip."""
    plausible_length(design.length)
    sizes = [("outer_diameter", design.outer_diameter), ("cap_thickness", design.cap_thickness),
             ("min_wall_thickness", design.min_wall_thickness)]
    for i, c in enumerate(design.channels):
        sizes += c.sizes(f"channels[{i}]")
    sizes += design.lumen.sizes("lumen") if design.lumen is not None else []
    fibre = design.limiting_fibre
    if fibre is not None:
        sizes += [("limiting_fibre.diameter", fibre.diameter), ("limiting_fibre.center[0]", fibre.center[0]),
                  ("limiting_fibre.center[1]", fibre.center[1])]
    if design.reinforcement is not None:
        sizes += [("reinforcement.pitch", design.reinforcement.pitch),
                  ("reinforcement.thread_diameter", design.reinforcement.thread_diameter)]
    if design.device is not None:
        sizes += [("device.diameter", design.device.diameter)]
    for name, v in sizes:
        _plausible_size(v, name)
    _plausible_pascals(design.max_pressure, "limits.max_pressure", PLAUSIBLE_PRESSURE, pressure_guess)
    moduli = [("material.c1", design.material.c1)]
    if design.limiting_fibre is not None:
        moduli.append(("limiting_fibre.material.c1", design.limiting_fibre.material.c1))
    if design.reinforcement is not None:
        moduli.append(("reinforcement.youngs_modulus", design.reinforcement.youngs_modulus))
    for name, v in moduli:
        _plausible_pascals(v, name, PLAUSIBLE_MODULUS, _modulus_guess)
