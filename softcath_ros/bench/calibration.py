"""Fit a model rung to a bench recording: pressure shift and material scale.

Parameters (both dimensionless):
- ``pressure_shift`` s: the model is evaluated at (1 - s) times the measured pressure
  (the published FE-to-experiment gap is s ~ 0.25);
- ``material_scale`` m: every modulus of the design multiplied by m (``scaled_design``); for a rung
  that answers shapes for pressures alone this is its pressures divided by m, exactly, so the fit
  builds the rung (a surrogate's table) once (core/calibration_file.py says why).
Residuals: every sample's bending angle per sample length theta / l (angle bench; the model's is
|k| x axial stretch) and tared blocking force (force
bench), each divided by its step's spread (floored at the reading noise) so the two
benches weigh comparably. scipy least squares; 95% confidence intervals from the
Jacobian at the optimum, cov = (J^T J)^-1 * SSR / (n - k), or, where the residuals exceed the
readings' noise (the model misfits, ``misfit_variance``), * the levels' mean square of their mean
residuals when larger (a level's readings share its misfit), with a warning in the message. The force bench's tare (each trial's
p = 0 reading) is one noisy reading shared by all of that trial's forces: each (sample, trial)
gets a fitted force offset (nuisance parameters, k = 2 + their number), so the intervals of
shift and scale include the tare's error instead of treating the trial's forces as independent. The bench's own biases
(friction, out-of-plane) are not separated from the model error: the fit absorbs them.
For the closed form, curvature depends on (1 - s) / m and force on (1 - s) only, so
both benches are needed to tell the two apart; the correlation is reported.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..core.calibration_file import CalibratedModel, pressure_only, scaled_design
from ..core.errors import SoftcathError
from ..core.prediction import angle_per_length
from .analysis import SampleRow, check_rows_match_design, summarise
from .blocking import BlockingForce

Z95 = 1.959963984540054


@dataclass
class CalibrationResult:
    rung: str
    pressure_shift: float
    material_scale: float
    ci95: dict[str, float]       # half-widths
    covariance: list             # 2x2 [[var shift, cov], [cov, var scale]]
    correlation: float
    n_residuals: int
    rms_before: float            # normalised residual rms at s = 0, m = 1
    rms_after: float
    success: bool
    message: str
    misfit_factor: float = 1.0   # the intervals' widening for the model's misfit (1: it fits to the noise)

    def to_json(self) -> dict:
        return dict(self.__dict__)


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


MISFIT = "the model does not fit the readings to their noise"
LACK_OF_FIT_ALPHA = 0.01


def misfit_variance(residuals: np.ndarray, steps: list, n_params: int) -> tuple[float, float, str]:
    """The variance factor of the fit's covariance, its ratio to SSR / (n - k), and a warning when
    the model misfits.

    The residuals are normalised by their level's spread, so a model that fits leaves a sum of
    squares within chi-square(n - k); beyond its ``LACK_OF_FIT_ALPHA`` quantile the model does not fit
    the readings to their noise. Its misfit is then shared by every reading of a level (``steps``: the
    bench, drive, phase, level of each residual), so the readings are not independent: the factor
    is the larger of SSR / (n - k) and the levels' mean square sum n_j rbar_j^2 / (levels - k), which
    counts each level's misfit as one error (misfit e_j shared by a level's n_j readings gives the
    estimate the covariance (J^T J)^-1 (1 + n var e), that mean square's expectation)."""
    from scipy.stats import chi2

    r = np.asarray(residuals, dtype=float)
    n = len(r)
    dof = max(n - n_params, 1)
    ssr = float(r @ r)
    usual = ssr / dof
    p = float(chi2.sf(ssr, dof))
    if p >= LACK_OF_FIT_ALPHA:
        return usual, 1.0, ""
    keys = sorted(set(steps), key=str)
    idx = np.array([keys.index(s) for s in steps])
    counts = np.bincount(idx, minlength=len(keys))
    means = np.bincount(idx, r, minlength=len(keys)) / counts
    levels = float(counts @ means ** 2) / (len(keys) - n_params) if len(keys) > n_params else usual
    s2 = max(usual, levels)
    return s2, math.sqrt(s2 / usual), (
        f"{MISFIT} (normalised residual rms {math.sqrt(ssr / n):.2f}, chi-square p = {p:.1g}): intervals "
        f"widened x{math.sqrt(s2):.1f} over the readings' noise alone, each level's misfit counted as one error")


def calibrate(rows: list[SampleRow], design, rung: str = "closed_form", *,
              curvature_floor: float = 0.5, force_floor: float = 0.3e-3,
              x0=(0.0, 1.0), rebuild: bool = False) -> CalibrationResult:
    """Fit (pressure_shift, material_scale) to ``rows``. Floors: 1/m and N (reading noise).
    ``rebuild``: build the rung on every scaled design the fit tries, even where scaling its
    pressures is exact (the former way; tests and benchmarks/calibration_speed.py compare the two)."""
    from ..core.models import make_model

    check_rows_match_design(rows, design)
    use, meas, sigma = _residual_setup(rows, curvature_floor, force_floor)
    pressures = np.clip(np.array([r.pressure for r in use]), 0.0, None)
    is_angle = np.array([r.bench == "angle" for r in use])
    lengths = np.array([r.length for r in use])
    trials = sorted({(r.sample_name, r.drive, r.trial) for r in use if r.bench == "force"})
    group = np.array([-1 if r.bench == "angle" else trials.index((r.sample_name, r.drive, r.trial)) for r in use])
    if is_angle.all() or not is_angle.any():
        bench = "angle" if is_angle.all() else "force"
        note = f"only the {bench} bench was recorded: shift and scale are weakly separable"
    else:
        note = ""

    # a material scale is the pressure divided by it (core/calibration_file.py): one model for every
    # value the fit tries; a rung with loads is built on each scaled design
    base = make_model(rung, design) if pressure_only(rung) and not rebuild else None

    def predict(x):
        shift, scale, offsets = x[0], x[1], x[2:]
        model = (CalibratedModel(base, shift, material_scale=scale) if base is not None
                 else CalibratedModel(make_model(rung, scaled_design(design, scale)), shift))
        state = model.evaluate(pressures)
        k = np.atleast_2d(state.curvature)
        force = BlockingForce(model)
        f = np.array([force.from_curvature(k[i], lengths[i]) if not is_angle[i] else 0.0 for i in range(len(use))])
        f = f + np.where(group >= 0, offsets[np.maximum(group, 0)] if len(offsets) else 0.0, 0.0)
        pred = np.where(is_angle, angle_per_length(state, model, lengths), f)
        conv = np.atleast_1d(state.converged)
        return np.where(conv, pred, np.nan)

    def residuals(x):
        r = (predict(x) - meas) / sigma
        return np.nan_to_num(r, nan=1e3)

    n_off = len(trials)
    start = np.concatenate([np.asarray(x0, dtype=float), np.zeros(n_off)])
    r0 = residuals(start)
    sol = least_squares(residuals, x0=start, bounds=([-0.9, 0.05] + [-np.inf] * n_off, [0.9, 20.0] + [np.inf] * n_off),
                        x_scale=[0.1, 0.3] + [force_floor] * n_off, diff_step=1e-4)
    n, k = len(sol.fun), 2 + n_off
    s2, widened, misfit = misfit_variance(sol.fun, [(r.bench, r.drive, r.phase, r.level) for r in use], k)
    if misfit:
        note = (note + "; " if note else "") + misfit
    try:
        cov = (np.linalg.inv(sol.jac.T @ sol.jac) * s2)[:2, :2]
        half = Z95 * np.sqrt(np.clip(np.diag(cov), 0.0, None))
        corr = float(cov[0, 1] / math.sqrt(cov[0, 0] * cov[1, 1])) if cov[0, 0] > 0 and cov[1, 1] > 0 else math.nan
    except np.linalg.LinAlgError:
        cov = np.full((2, 2), math.inf)
        half, corr = np.array([math.inf, math.inf]), math.nan
        note = (note + "; " if note else "") + "singular Jacobian: parameters not identifiable from this data"
    return CalibrationResult(rung=rung, pressure_shift=float(sol.x[0]), material_scale=float(sol.x[1]),
                             ci95={"pressure_shift": float(half[0]), "material_scale": float(half[1])},
                             covariance=[[float(v) for v in row] for row in cov],
                             correlation=corr, n_residuals=n,
                             rms_before=float(np.sqrt(np.mean(r0**2))), rms_after=float(np.sqrt(np.mean(sol.fun**2))),
                             success=bool(sol.success), message="; ".join(x for x in (sol.message, note) if x),
                             misfit_factor=widened)
