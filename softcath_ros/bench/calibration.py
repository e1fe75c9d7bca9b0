"""Fit a model rung to a bench recording: pressure shift and material scale.

Parameters (both dimensionless):
- ``pressure_shift`` s: the model is evaluated at (1 - s) times the measured pressure
  (the published FE-to-experiment gap is s ~ 0.25);
- ``material_scale`` m: every Yeoh coefficient of the body multiplied by m.
Residuals: every sample's curvature (angle bench) and tared blocking force (force
bench), each divided by its step's spread (floored at the reading noise) so the two
benches weigh comparably. scipy least squares; 95% confidence intervals from the
Jacobian at the optimum, cov = (J^T J)^-1 * SSR / (n - 2). The bench's own biases
(friction, out-of-plane) are not separated from the model error: the fit absorbs them.
For the closed form, curvature depends on (1 - s) / m and force on (1 - s) only, so
both benches are needed to tell the two apart; the correlation is reported.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from ..core.errors import SoftcathError
from .analysis import SampleRow, summarise
from .blocking import BlockingForce

Z95 = 1.959963984540054


@dataclass
class CalibrationResult:
    rung: str
    pressure_shift: float
    material_scale: float
    ci95: dict[str, float]       # half-widths
    correlation: float
    n_residuals: int
    rms_before: float            # normalised residual rms at s = 0, m = 1
    rms_after: float
    success: bool
    message: str

    def to_json(self) -> dict:
        return dict(self.__dict__)


def scaled_design(design, material_scale: float):
    return replace(design, material=design.material.scaled(material_scale))


def _residual_setup(rows: list[SampleRow], curvature_floor: float, force_floor: float):
    stats = {(s.bench, s.drive, s.phase, s.level): s for s in summarise(rows)}
    use = [r for r in rows if np.isfinite(r.angle if r.bench == "angle" else r.force)]
    if not use:
        raise SoftcathError("no usable readings in the recording: nothing to calibrate against")
    meas, sigma = [], []
    for r in use:
        s = stats[(r.bench, r.drive, r.phase, r.level)]
        if r.bench == "angle":
            meas.append(r.curvature)
            sigma.append(max(s.curvature_std if np.isfinite(s.curvature_std) else 0.0, curvature_floor))
        else:
            meas.append(r.force)
            sigma.append(max(s.force_std if np.isfinite(s.force_std) else 0.0, force_floor))
    return use, np.array(meas), np.array(sigma)


def calibrate(rows: list[SampleRow], design, rung: str = "closed_form", *,
              curvature_floor: float = 0.5, force_floor: float = 0.3e-3,
              x0=(0.0, 1.0)) -> CalibrationResult:
    """Fit (pressure_shift, material_scale) to ``rows``. Floors: 1/m and N (reading noise)."""
    from ..core.models import make_model

    use, meas, sigma = _residual_setup(rows, curvature_floor, force_floor)
    pressures = np.clip(np.array([r.pressure for r in use]), 0.0, None)
    is_angle = np.array([r.bench == "angle" for r in use])
    lengths = np.array([r.length for r in use])
    if is_angle.all() or not is_angle.any():
        bench = "angle" if is_angle.all() else "force"
        note = f"only the {bench} bench was recorded: shift and scale are weakly separable"
    else:
        note = ""

    def predict(x):
        shift, scale = x
        model = make_model(rung, scaled_design(design, scale))
        state = model.evaluate(pressures * (1.0 - shift))
        k = np.atleast_2d(state.curvature)
        kmag = np.hypot(k[:, 0], k[:, 1])
        force = BlockingForce(model)
        f = np.array([force.from_curvature(k[i], lengths[i]) for i in range(len(use))])
        pred = np.where(is_angle, kmag, f)
        conv = np.atleast_1d(state.converged)
        return np.where(conv, pred, np.nan)

    def residuals(x):
        r = (predict(x) - meas) / sigma
        return np.nan_to_num(r, nan=1e3)

    r0 = residuals(np.array(x0, dtype=float))
    sol = least_squares(residuals, x0=np.array(x0, dtype=float), bounds=([-0.9, 0.05], [0.9, 20.0]),
                        x_scale=[0.1, 0.3], diff_step=1e-4)
    n, k = len(sol.fun), 2
    dof = max(n - k, 1)
    s2 = float(sol.fun @ sol.fun) / dof
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * s2
        half = Z95 * np.sqrt(np.clip(np.diag(cov), 0.0, None))
        corr = float(cov[0, 1] / math.sqrt(cov[0, 0] * cov[1, 1])) if cov[0, 0] > 0 and cov[1, 1] > 0 else math.nan
    except np.linalg.LinAlgError:
        half, corr = np.array([math.inf, math.inf]), math.nan
        note = (note + "; " if note else "") + "singular Jacobian: parameters not identifiable from this data"
    return CalibrationResult(rung=rung, pressure_shift=float(sol.x[0]), material_scale=float(sol.x[1]),
                             ci95={"pressure_shift": float(half[0]), "material_scale": float(half[1])},
                             correlation=corr, n_residuals=n,
                             rms_before=float(np.sqrt(np.mean(r0**2))), rms_after=float(np.sqrt(np.mean(sol.fun**2))),
                             success=bool(sol.success), message="; ".join(x for x in (sol.message, note) if x))


def calibrated_design_dict(design, result: CalibrationResult, recording: str) -> dict:
    """The design file of the calibrated actuator: material scaled by the fit. The pressure
    shift is a model correction, not a design property: it goes in the description and in
    the calibration sidecar the report reads."""
    d = scaled_design(design, result.material_scale).to_dict()
    d["name"] = f"{design.name}_calibrated"
    d["description"] = (f"{design.name} calibrated on {recording} with rung {result.rung}: material scale "
                        f"{result.material_scale:.4g} +- {result.ci95['material_scale']:.2g} (95%), pressure shift "
                        f"{result.pressure_shift:.4g} +- {result.ci95['pressure_shift']:.2g} (95%, apply as "
                        f"p_model = (1 - shift) p)")
    return d


def load_calibration(path) -> dict:
    """A calibration file written by ``softcath calibrate`` (the ``.calibration.yaml`` sidecar),
    read with the bounded reader and checked: ``rung`` a known rung, ``material_scale`` > 0 and
    ``pressure_shift`` < 1, both finite. Anything else is one line naming the field."""
    from ..core.checks import finite_number
    from ..core.errors import shown
    from ..core.models import available_models
    from ..core.yaml_io import load_yaml_file

    data = load_yaml_file(path)
    if not isinstance(data, dict):
        raise SoftcathError(f"calibration {path}: must be a mapping (the .calibration.yaml that "
                            "`softcath calibrate` writes)")
    rung = data.get("rung")
    if rung not in available_models():
        raise SoftcathError(f"calibration {path}: field 'rung' = {shown(rung)}: not one of {available_models()}")
    for key, ok, rule in (("material_scale", lambda v: v > 0, "must be positive"),
                          ("pressure_shift", lambda v: v < 1, "must be below 1")):
        v = finite_number(data.get(key))
        if v is None or not ok(v):
            raise SoftcathError(f"calibration {path}: field '{key}' = {shown(data.get(key))}: {rule} (a finite number)")
        data[key] = v
    return data
