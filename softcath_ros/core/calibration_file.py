"""Calibration as data: the file `softcath calibrate` writes, and applying it to any rung.

A calibration says how the model must be corrected to match one actuator (docs/calibration.md):
- ``pressure_shift`` s: the rung is evaluated at (1 - s) times the commanded pressure;
- ``material_scale`` m: every modulus of the design multiplied by m (the silicone's Yeoh coefficients
  and bulk modulus, the fibre's, the rings', a device's bending stiffness: ``scaled_design``);
- their 2x2 covariance (from the fit), so predictions carry a 95% band.
It is tied to one design by ``section_hash``: the design's content hash over every field but the
length and the pressure limit (a calibration is of the section and material, fitted on samples of
any length, and holds for any length and lowered limit); applied to another design it is refused.

``build_model(name, design, calibration)`` is the one way to get a calibrated rung: the rung
``name`` wrapped in ``CalibratedModel``, which evaluates it at (1 - s) p / m. Why p / m: every
elastic term of the potential (silicone, fibre, rings, the lumen's contact barrier and fill, whose
moduli are set relative to the silicone's, a device) is linear in the moduli and the pressure's
work is linear in p, so Pi(u; p, m) = m Pi(u; p / m, 1): the same equilibria, the same stability,
the same shapes; forces scale by m. So a rung that answers shapes for pressures alone (no tip
loads, gravity or contact: ``pressure_only``) is built once on the design itself (a surrogate: its
own table, no new table per scale) and read at p / m; a rung with loads (the rod) is built on the
scaled design. The safety limit stays the design's ``max_pressure`` on the commanded pressure.
"""
from __future__ import annotations

import copy
import hashlib
import math
from dataclasses import asdict, dataclass, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from .errors import SoftcathError, shown
from .models import BendModel, BendState, make_model

SCHEMA_VERSION = 2            # 2: material_scale multiplies every modulus (1: the silicone's only)
Z95 = 1.959963984540054       # two-sided 95% quantile of the normal distribution
SHIFT_RANGE = (-0.9, 0.9)     # what the fit may return (bench/calibration.py bounds)
SCALE_RANGE = (0.05, 20.0)


class CalibrationError(SoftcathError):
    """A calibration file is malformed, or was made for another design."""


def _scaled_material(material, m: float):
    return replace(material.scaled(m), bulk_modulus=material.bulk_modulus * m)


def scaled_design(design, material_scale: float):
    """``design`` with every modulus multiplied by ``material_scale``: the silicone's Yeoh
    coefficients and bulk modulus, the limiting fibre's, the rings' Young's modulus and a device's
    bending stiffness (so the potential scales as a whole: module docstring)."""
    m = float(material_scale)
    fibre, rings, device = design.limiting_fibre, design.reinforcement, design.device
    return replace(design, material=_scaled_material(design.material, m),
                   limiting_fibre=None if fibre is None else replace(fibre, material=_scaled_material(fibre.material, m)),
                   reinforcement=None if rings is None else replace(rings, youngs_modulus=rings.youngs_modulus * m),
                   device=None if device is None else replace(device, bending_stiffness=device.bending_stiffness * m))


def pressure_only(name: str) -> bool:
    """Rung ``name`` answers the shape for pressures alone (no tip loads, gravity or contact), so a
    material scale m is exactly its pressures divided by m."""
    from .models import RUNGS, rung_info

    return name in RUNGS and not {"tip_load", "contact", "gravity"} & set(rung_info(name).models)


def section_hash(design) -> str:
    """The design's content hash with the length and max_pressure left out (16 hex digits)."""
    return replace(design, max_pressure=1.0).per_section_hash()


def file_sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@dataclass(frozen=True)
class Calibration:
    design: str                   # design name
    design_hash: str              # section_hash() of the design calibrated
    rung: str                     # the rung that was fitted
    pressure_shift: float         # s: rung evaluated at (1 - s) p
    material_scale: float         # m: Yeoh coefficients x m
    covariance: tuple             # ((var s, cov), (cov, var m))
    rms_before: float             # normalised residual rms at s = 0, m = 1
    rms_after: float              # ... at the fit
    n_residuals: int
    recording: str                # the recording fitted (path as given)
    recording_sha256: str
    date: str                     # ISO 8601, UTC
    fit_converged: bool = True
    message: str = ""
    schema: int = SCHEMA_VERSION

    @property
    def cov(self) -> np.ndarray:
        return np.asarray(self.covariance, dtype=float)

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of (shift, scale)."""
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    @property
    def ci95(self) -> dict[str, float]:
        """95% half-widths of shift and scale."""
        s = Z95 * self.std
        return {"pressure_shift": float(s[0]), "material_scale": float(s[1])}

    @property
    def correlation(self) -> float:
        c = self.cov
        return float(c[0, 1] / math.sqrt(c[0, 0] * c[1, 1])) if c[0, 0] > 0 and c[1, 1] > 0 else math.nan

    def with_values(self, pressure_shift: float, material_scale: float) -> "Calibration":
        return replace(self, pressure_shift=float(pressure_shift), material_scale=float(material_scale))

    def check_design(self, design) -> None:
        """Refuse a design other than the one calibrated (by content hash)."""
        if section_hash(design) != self.design_hash:
            raise CalibrationError(
                f"calibration for design '{self.design}' (hash {self.design_hash}) does not apply to design "
                f"'{design.name}' (hash {section_hash(design)}): it was made for another design; "
                "calibrate this one")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["covariance"] = [[float(v) for v in row] for row in self.cov]
        d["ci95"] = self.ci95            # derived, written for a reader; ignored on load
        return d

    def save(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        header = ("# softcath calibration (docs/calibration.md): the rung is evaluated at (1 - pressure_shift) p\n"
                  "# on the design with every modulus x material_scale\n")
        path.write_text(header + yaml.safe_dump(self.to_dict(), sort_keys=False))
        return path


def from_fit(result, design, recording) -> Calibration:
    """A Calibration from a bench fit (bench/calibration.py ``CalibrationResult``) of ``design``
    to the recording file ``recording``."""
    return Calibration(design=design.name, design_hash=section_hash(design), rung=result.rung,
                       pressure_shift=float(result.pressure_shift), material_scale=float(result.material_scale),
                       covariance=tuple(tuple(float(v) for v in row) for row in result.covariance),
                       rms_before=float(result.rms_before), rms_after=float(result.rms_after),
                       n_residuals=int(result.n_residuals), recording=str(recording),
                       recording_sha256=file_sha256(recording),
                       date=datetime.now(timezone.utc).replace(microsecond=0).isoformat(),
                       fit_converged=bool(result.success), message=str(result.message))


_FIELDS = {"design": str, "design_hash": str, "rung": str, "pressure_shift": float, "material_scale": float,
           "covariance": list, "rms_before": float, "rms_after": float, "n_residuals": int, "recording": str,
           "recording_sha256": str, "date": str}
_OPTIONAL = {"fit_converged": bool, "message": str, "schema": int, "ci95": dict}


def calibration_from_dict(data, source: str = "calibration") -> Calibration:
    """Validate a calibration mapping; every error names the field and the file."""
    def bad(field, value, why):
        return CalibrationError(f"{source}: field '{field}' = {shown(value)}: {why}")

    if not isinstance(data, dict):
        raise CalibrationError(f"{source}: not a calibration file (expected a mapping of fields)")
    for key in data:
        if key not in _FIELDS and key not in _OPTIONAL:
            raise bad(key, data[key], f"unknown field; known: {sorted({**_FIELDS, **_OPTIONAL})}")
    for key in _FIELDS:
        if key not in data:
            raise bad(key, None, "missing required field")
    out = {}
    for key, kind in {**_FIELDS, **_OPTIONAL}.items():
        if key not in data or key == "ci95":
            continue
        v = data[key]
        if kind is float:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise bad(key, v, "must be a finite number")
            v = float(v)
        elif kind is int:
            if isinstance(v, bool) or not isinstance(v, int):
                raise bad(key, v, "must be an integer")
        elif not isinstance(v, kind):
            raise bad(key, v, f"must be a {kind.__name__}")
        out[key] = v
    if out.get("schema", SCHEMA_VERSION) == 1:
        raise bad("schema", 1, "its material_scale scaled the silicone only (this softcath scales every "
                  "modulus): re-run softcath calibrate on its recording")
    if out.get("schema", SCHEMA_VERSION) != SCHEMA_VERSION:
        raise bad("schema", out["schema"], f"this softcath reads schema {SCHEMA_VERSION}")
    from .models import RUNGS

    if out["rung"] not in RUNGS:
        raise bad("rung", out["rung"], f"not a rung of this softcath; rungs: {sorted(RUNGS)}")
    if not SHIFT_RANGE[0] <= out["pressure_shift"] <= SHIFT_RANGE[1]:
        raise bad("pressure_shift", out["pressure_shift"], f"must lie in {list(SHIFT_RANGE)}")
    if not SCALE_RANGE[0] <= out["material_scale"] <= SCALE_RANGE[1]:
        raise bad("material_scale", out["material_scale"], f"must lie in {list(SCALE_RANGE)}")
    cov = out["covariance"]
    try:
        c = np.array(cov, dtype=float)
    except (TypeError, ValueError):
        raise bad("covariance", cov, "must be a 2x2 list of numbers") from None
    if c.shape != (2, 2) or not np.isfinite(c).all():
        raise bad("covariance", cov, "must be a 2x2 list of finite numbers")
    if abs(c[0, 1] - c[1, 0]) > 1e-9 * max(1.0, abs(c).max()) or np.linalg.eigvalsh(0.5 * (c + c.T)).min() < \
            -1e-12 * max(1.0, abs(c).max()):
        raise bad("covariance", cov, "must be symmetric positive semi-definite")
    out["covariance"] = tuple(tuple(float(v) for v in row) for row in c)
    return Calibration(**out)


def load_calibration(path) -> Calibration:
    """Read (the bounded YAML reader: size, UTF-8, depth, no aliases, unique keys) and validate a
    calibration file."""
    from .yaml_io import load_yaml_file

    source = f"calibration {path}"
    if Path(path).is_dir():
        raise CalibrationError(f"{source}: a folder, not a calibration file")
    if not Path(path).is_file():
        raise CalibrationError(f"{source}: no such file")
    return calibration_from_dict(load_yaml_file(path, source), source=source)


def build_model(name: str, design, calibration: Calibration | None = None, **options) -> BendModel:
    """Rung ``name`` for ``design`` (``make_model``), calibrated when ``calibration`` is given:
    refused for another design; otherwise the rung on the scaled material behind the pressure shift."""
    if calibration is None:
        return make_model(name, design, **options)
    calibration.check_design(design)
    m = calibration.material_scale
    if pressure_only(name):
        return CalibratedModel(make_model(name, design, **options), calibration.pressure_shift, calibration,
                               material_scale=m)
    inner = make_model(name, scaled_design(design, m), **options)
    return CalibratedModel(inner, calibration.pressure_shift, calibration)


class CalibratedModel(BendModel):
    """A rung corrected by a calibration: evaluates ``inner`` at (1 - ``pressure_shift``) /
    ``material_scale`` times the commanded pressures. ``inner`` is either already on the scaled
    design (``material_scale`` 1, any rung) or on the design itself with the scale applied here
    (``material_scale`` m: exact for a ``pressure_only`` rung, whose answers are shapes; the model's
    ``design`` is then the scaled one, so what is computed from its moduli, a blocking force from
    EI, scales as it should). Declares what ``inner`` declares; a linear rung stays linear (its
    gains scaled by the factor). ``calibration``: where the values came from (None while a fit
    tries values)."""

    def __init__(self, inner: BendModel, pressure_shift: float, calibration: Calibration | None = None,
                 material_scale: float = 1.0):
        m = float(material_scale)
        if m != 1.0 and not pressure_only(inner.name):
            raise ValueError(f"rung '{inner.name}' takes loads: build it on the scaled design instead")
        super().__init__(inner.design if m == 1.0 else scaled_design(inner.design, m))
        self.inner = inner
        self.calibration = calibration
        self.factor = (1.0 - float(pressure_shift)) / m
        self.name = f"{inner.name} calibrated"
        self.info = inner.info
        self.solver_version = inner.solver_version
        self.built_now = inner.built_now
        if inner.info.linear_gain:
            self.curvature_per_pa = inner.curvature_per_pa * self.factor
            self.stretch_per_pa = inner.stretch_per_pa * self.factor

    def __getattr__(self, attr):   # what a rung adds (a surrogate's path and error bound, auto's selection)
        if attr == "inner":
            raise AttributeError(attr)
        return getattr(self.inner, attr)

    @property
    def pressure_range(self) -> tuple[float, float]:
        lo, hi = self.inner.pressure_range
        if self.factor > 0:
            lo, hi = lo / self.factor, hi / self.factor
        return lo, min(hi, float(self.design.max_pressure))

    def at_length(self, length: float) -> BendModel:
        """The calibrated rung for a body of actuated length ``length`` (m): ``inner`` at that length."""
        inner = self.inner.at_length(length)
        if inner is self.inner:
            return self
        other = copy.copy(self)
        other.inner = inner
        other.design = self.design.with_length(length)
        return other

    def _evaluate_batch(self, pressures: np.ndarray) -> BendState:
        return self.inner.evaluate(pressures * self.factor)

    def curvature_single(self, pressures: np.ndarray):
        return self.inner.curvature_single(np.asarray(pressures, dtype=float) * self.factor)

    def solve(self, pressure, *args, **kwargs):
        return self.inner.solve(pressure * self.factor, *args, **kwargs)

    def max_principal_stretch(self, pressures):
        return self.inner.max_principal_stretch(np.asarray(pressures, dtype=float) * self.factor)


def band95(calibration: Calibration, quantity: Callable[[Calibration], np.ndarray]) -> np.ndarray:
    """95% half-width of ``quantity(calibration)`` (any array) from the calibration's covariance, by
    linearised propagation: the gradient in (shift, scale) by central differences at +-1 standard
    deviation (a step the fit itself resolves, large against solver tolerances), then
    1.96 sqrt(g^T C g) elementwise. Zero where the covariance is zero; NaN where a perturbed
    evaluation did not answer."""
    std = calibration.std
    base = np.asarray(quantity(calibration), dtype=float)
    grads = []
    x = np.array([calibration.pressure_shift, calibration.material_scale])
    bounds = np.array([SHIFT_RANGE, SCALE_RANGE])
    for i in range(2):
        if std[i] == 0:
            grads.append(np.zeros_like(base))
            continue
        hi, lo = x.copy(), x.copy()
        hi[i] = min(x[i] + std[i], bounds[i, 1])
        lo[i] = max(x[i] - std[i], bounds[i, 0])
        f_hi = np.asarray(quantity(calibration.with_values(*hi)), dtype=float)
        f_lo = np.asarray(quantity(calibration.with_values(*lo)), dtype=float)
        grads.append((f_hi - f_lo) / (hi[i] - lo[i]))
    g = np.stack(grads, axis=-1)                          # (..., 2)
    var = np.einsum("...i,ij,...j->...", g, calibration.cov, g)
    return Z95 * np.sqrt(np.clip(var, 0.0, None))
