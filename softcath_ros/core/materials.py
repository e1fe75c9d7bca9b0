"""Hyperelastic materials: incompressible Yeoh of order 1 to 3 (neo-Hookean is Yeoh with c1 only).

Strain energy W = c1 (I1-3) + c2 (I1-3)^2 + c3 (I1-3)^3, coefficients in Pa; the density
itself is ``energy.yeoh``, the one both FE rungs use. Near-incompressibility is enforced in the
FE rungs through ``bulk_modulus`` (Pa).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

from .energy import yeoh
from .checks import finite_number
from .errors import DesignError

# Published sets for Ecoflex 00-30 differ by about 2x in c1 (docs/actuator.md); the
# Kulkarni set is the one the reference simulations use.
PRESETS: dict[str, dict] = {
    "ecoflex_0030_kulkarni": {
        "model": "yeoh", "c1": 12.7e3, "c2": 423.0, "c3": -1.46,
        "bulk_modulus": 100.0e6, "density": 1070.0,
    },
    # Polyester strain-limiting fibre as the reference simulations model it.
    "polyester_fibre": {"model": "yeoh", "c1": 7.9e6, "c2": 0.0, "c3": 0.0,
                        "bulk_modulus": 100.0e9, "density": 1380.0},
}


@dataclass(frozen=True)
class YeohMaterial:
    """Incompressible Yeoh solid. ``c1..c3`` in Pa, ``bulk_modulus`` in Pa, ``density`` in kg/m^3."""

    c1: float
    c2: float = 0.0
    c3: float = 0.0
    bulk_modulus: float = 100.0e6
    density: float = 1070.0
    name: str = "custom"

    @property
    def shear_modulus(self) -> float:
        """Initial (small-strain) shear modulus mu = 2 c1, Pa."""
        return 2.0 * self.c1

    @property
    def youngs_modulus(self) -> float:
        """Initial Young's modulus of the incompressible solid, E = 3 mu = 6 c1, Pa."""
        return 6.0 * self.c1

    def strain_energy(self, i1_bar):
        """W in J/m^3 at the isochoric first invariant ``i1_bar`` (``energy.yeoh`` with this set)."""
        return yeoh(i1_bar, self.c1, self.c2, self.c3)

    def scaled(self, factor: float) -> "YeohMaterial":
        """The same material with every c_i multiplied by ``factor`` (used by calibration)."""
        return replace(self, c1=self.c1 * factor, c2=self.c2 * factor, c3=self.c3 * factor,
                       name=f"{self.name}*{factor:g}")


def material_from_spec(spec, field: str = "material") -> YeohMaterial:
    """Build a material from a preset name or a mapping as in docs/design_file.md.

    ``model: neo_hookean`` takes ``c1`` only (or ``shear_modulus``, c1 = mu/2).
    """
    if isinstance(spec, str):
        if spec not in PRESETS:
            raise DesignError(field, spec, f"unknown material preset; known: {sorted(PRESETS)}")
        return replace(material_from_spec(PRESETS[spec], field), name=spec)
    if not isinstance(spec, dict):
        raise DesignError(field, spec, "must be a preset name or a mapping with model and coefficients")
    model = spec.get("model", "yeoh")
    if model not in ("yeoh", "neo_hookean"):
        raise DesignError(f"{field}.model", model, "must be 'yeoh' or 'neo_hookean'")
    allowed = {"model", "c1", "c2", "c3", "bulk_modulus", "density", "shear_modulus", "name"}
    for key in spec:
        if key not in allowed:
            raise DesignError(f"{field}.{key}", spec[key], f"unknown material key; allowed: {sorted(allowed)}")
    coeffs = {}
    if model == "neo_hookean":
        if "c2" in spec or "c3" in spec:
            raise DesignError(f"{field}.c2", spec.get("c2", spec.get("c3")), "neo_hookean takes c1 only")
        if "c1" in spec:
            coeffs["c1"] = _number(spec["c1"], f"{field}.c1")
        elif "shear_modulus" in spec:
            coeffs["c1"] = _number(spec["shear_modulus"], f"{field}.shear_modulus") / 2.0
        else:
            raise DesignError(f"{field}.c1", None, "missing (neo_hookean needs c1 or shear_modulus)")
    else:
        if "c1" not in spec:
            raise DesignError(f"{field}.c1", None, "missing (Yeoh needs at least c1)")
        for key in ("c1", "c2", "c3"):
            if key in spec:
                coeffs[key] = _number(spec[key], f"{field}.{key}")
    if coeffs["c1"] <= 0:
        raise DesignError(f"{field}.c1", coeffs["c1"], "must be positive (it is half the shear modulus)")
    for key in ("bulk_modulus", "density"):
        if key in spec:
            coeffs[key] = _number(spec[key], f"{field}.{key}")
            if coeffs[key] <= 0:
                raise DesignError(f"{field}.{key}", coeffs[key], "must be positive")
    return YeohMaterial(name=str(spec.get("name", model)), **coeffs)


def _number(value, field: str) -> float:
    v = finite_number(value)
    if v is None:
        raise DesignError(field, value, "must be a finite number")
    return v

