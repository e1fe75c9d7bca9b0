"""Unit conversions for human-facing input and output (code and wire are SI).

A pressure a user types carries its unit (docs/units rule in README "Pressures"): a suffix
(``0.15bar``, ``15kPa``, ``15000Pa``) or the tool's ``--unit`` for bare numbers. A bare number
without either is refused (0 excepted: the same in every unit), never read as Pa silently.
"""
from __future__ import annotations

import math
import re
from decimal import Decimal

from .errors import SoftcathError, shown

PA_PER_BAR = 1.0e5
PRESSURE_UNITS = {"Pa": 1.0, "kPa": 1.0e3, "bar": PA_PER_BAR}   # Pa per unit; names as typed (any case)
_PRESSURE = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z]*)\s*")


def describe_pressure(pa: float) -> str:
    """A pressure (Pa) as ramps and failure messages state it: "p = 0.2518 bar"."""
    return f"p = {pa / PA_PER_BAR:.4f} bar"


def pressure_unit(name: str) -> str:
    """The unit's canonical name (Pa, kPa, bar) for ``name`` in any case; SoftcathError otherwise."""
    for unit in PRESSURE_UNITS:
        if name.lower() == unit.lower():
            return unit
    raise SoftcathError(f"unknown pressure unit {shown(name)}: Pa, kPa or bar")


def parse_pressure(text: str, option: str, unit: str | None = None) -> float:
    """The pressure ``text`` (what the user typed for ``option``) in Pa: a number with a unit suffix,
    or a bare number in ``unit``. A bare non-zero number without ``unit`` is a one-line error naming
    ``option``; so are non-numbers and non-finite values."""
    m = _PRESSURE.fullmatch(str(text))
    if m is None or not math.isfinite(float(m.group(1))):
        raise SoftcathError(f"{option} {shown(text)}: not a pressure (a number with its unit, e.g. 0.15bar, "
                            "15kPa, 15000Pa)")
    number, suffix = m.groups()
    if suffix:
        try:
            unit = pressure_unit(suffix)
        except SoftcathError:
            raise SoftcathError(f"{option} {shown(text)}: unknown pressure unit '{suffix}' (Pa, kPa or bar)") from None
    elif unit is not None:
        unit = pressure_unit(unit)
    if unit is not None:   # in decimal, so 0.15bar is 15000 Pa exactly, as 15kPa is
        return float(Decimal(number) * Decimal(repr(PRESSURE_UNITS[unit])))
    if float(number) == 0.0:
        return 0.0
    raise SoftcathError(f"{option} {number}: which unit? write {number}bar, {number}kPa or {number}Pa "
                        "(or give --unit Pa|kPa|bar)")


def parse_pressure_list(text: str, option: str, unit: str | None = None) -> list[float]:
    """A comma list of pressures (one per channel), each as ``parse_pressure``, in Pa."""
    return [parse_pressure(item, option, unit) for item in str(text).split(",")]
