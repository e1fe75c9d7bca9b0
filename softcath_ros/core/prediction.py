"""Model + kinematics in one step: pressures -> bend state -> tip pose (what `predict` reports)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .body_contact import BodyContact, body_contact, may_reach
from .continuation import OUTSIDE_MODEL, stop_tag
from .kinematics import backbone_poses, planar_backbone_poses, radius_l_over_theta, tip_pose
from .models.base import BendModel


@dataclass
class Prediction:
    pressures_pa: list[float]
    curvature_per_m: list[float]
    axial_stretch: float
    radius_of_curvature_m: float | None   # R_C = l / theta: length over the tip's bending angle; None when straight
    centreline_radius_m: float | None     # 1/|k|, the stretched centreline's radius; None when straight
    bending_angle_rad: float
    tip_position_m: list[float]
    tip_orientation_xyzw: list[float]
    converged: bool
    solve_time_s: float
    reason: str = ""
    contact_force_n: float | None = None   # the tip's contact reaction, for rungs that model contact
    band95: dict | None = None   # 95% half-widths from a calibration's covariance (core/calibration_file.py)
    negative_directions: int | None = None   # the tangent's negative eigenvalues at the solved state (section
                                             # rung: 0, a stable state; a saddle is refused); None: not measured

    def to_json(self) -> dict:
        d = dict(self.__dict__)
        if self.converged:
            d.pop("reason")
        else:  # never print numbers from a solve that failed
            for key in ("curvature_per_m", "axial_stretch", "radius_of_curvature_m", "centreline_radius_m",
                        "bending_angle_rad", "tip_position_m", "tip_orientation_xyzw", "contact_force_n", "band95"):
                d[key] = None
        if d["contact_force_n"] is None:   # only rungs that model contact report it
            d.pop("contact_force_n")
        if d["band95"] is None:
            d.pop("band95")
        if d["negative_directions"] is None:   # only rungs that check stability report it
            d.pop("negative_directions")
        return d


def predict(model: BendModel, pressures: np.ndarray, length: float | None = None) -> list[Prediction]:
    """Evaluate ``model`` on a batch (N, C) of pressures (Pa); ``length`` overrides the design's (m).

    The rung answers for that length (``model.at_length``: the rod solves a rod of that length; a rung
    that solves a body of the design's length only, fe3d, refuses another). The tip pose is the
    constant-curvature arc's of the channelled part with the straight cap beyond (``arc_and_cap``),
    unless the rung solves the backbone itself (``info.solves_backbone``: the rod under loads, whose tip
    pose no single arc reproduces)."""
    length = model.design.length if length is None else float(length)
    model = model.at_length(length)
    arc_length, cap = arc_and_cap(model, length)
    own_length = math.isclose(length, model.design.length, rel_tol=1e-12)   # the body the rung solved
    t0 = time.perf_counter()
    state = model.evaluate(np.atleast_2d(pressures))
    elapsed = (time.perf_counter() - t0) / max(len(pressures), 1)
    with np.errstate(over="ignore", invalid="ignore"):   # overflow is caught below, per command
        if own_length and model.info.solves_backbone:
            pos = np.asarray(state.tip.position, dtype=float)
            quat = np.asarray(state.tip.orientation_xyzw, dtype=float)
            angle = np.asarray(state.tip.angle, dtype=float)
        else:
            arc = arc_length * state.axial_stretch
            pos, quat = tip_pose(state.curvature, arc, cap)
            angle = np.hypot(state.curvature[:, 0], state.curvature[:, 1]) * arc
    contact = state.contact_force
    negative = None if state.diagnostics is None else state.diagnostics.negative_directions
    # a rung that measures R_C itself (fe3d: l over its tip's angle) is reported as it measured it
    measured_rc = state.radius_l_over_theta if own_length else None
    radius = model.design.outer_radius
    out = []
    for i, p in enumerate(np.atleast_2d(pressures)):
        k = state.curvature[i]
        kappa = float(np.hypot(*k))
        theta = float(angle[i])
        converged, reason = bool(state.converged[i]), "" if state.converged[i] else (state.message or "did not converge")
        finite = np.isfinite(np.concatenate([k, [state.axial_stretch[i], angle[i]], pos[i], quat[i]])).all()
        if converged and not finite:   # never report inf/nan as an answer
            converged, reason = False, "non-finite result: the pressure or length is beyond what the rung can represent"
        if converged:   # a free body through itself or its shaft predicts nothing (core/body_contact.py)
            solved = None if state.backbone is None else np.asarray(state.backbone)[i]
            reached = body_reach(k, arc_length * float(state.axial_stretch[i]), cap, radius, solved)
            if reached is not None:
                converged, reason = False, f"{reached.describe()} {stop_tag(OUTSIDE_MODEL)}"
        out.append(Prediction(
            pressures_pa=[float(v) for v in p],
            curvature_per_m=[float(v) for v in k],
            axial_stretch=float(state.axial_stretch[i]),
            radius_of_curvature_m=(float(measured_rc[i]) if measured_rc is not None and np.isfinite(measured_rc[i])
                                   else _finite_or_none(radius_l_over_theta(length, theta))),
            centreline_radius_m=(1.0 / kappa) if kappa > 0 else None,
            bending_angle_rad=float(angle[i]),
            tip_position_m=[float(v) for v in pos[i]],
            tip_orientation_xyzw=[float(v) for v in quat[i]],
            converged=converged,
            solve_time_s=elapsed,
            reason=reason,
            contact_force_n=None if contact is None else float(np.asarray(contact)[i]),
            negative_directions=None if negative is None or negative[i] < 0 else int(negative[i])))
    return out


# bump when how a bend state becomes a tip pose, angle or R_C changes (part of cached predictions' keys)
KINEMATICS_VERSION = "arc-cap-2"   # 1: the tip cap straight beyond the channelled part's arc; 2: a body that
                                   # reaches itself or its shaft is refused


def body_reach(curvature, arc_length: float, cap: float, radius: float, backbone=None) -> BodyContact | None:
    """Where a body of ``radius`` (m) reaches itself or its shaft (``body_contact``), or None: the
    constant-curvature arc of ``curvature`` (2,) 1/m and deformed ``arc_length`` (m) with the straight
    ``cap`` beyond, or the solved ``backbone`` (M, 3) m when given (the rod under loads). An arc within
    half a turn is not sampled (``may_reach``), so a live node pays for the check only past it."""
    k = np.asarray(curvature, dtype=float)
    if backbone is None and not bool(may_reach(math.hypot(k[0], k[1]) * arc_length)):
        return None
    if backbone is None:
        n = math.ceil((arc_length + cap) / (0.5 * radius)) + 1
        points, _ = backbone_poses(k, arc_length, n, cap)
    else:
        solved = np.asarray(backbone, dtype=float)
        total = float(np.linalg.norm(np.diff(solved, axis=0), axis=1).sum())
        points, _ = planar_backbone_poses(solved, math.ceil(total / (0.5 * radius)) + 1)
    return body_contact(points, radius)


def arc_and_cap(model: BendModel, length: float) -> tuple[float, float]:
    """(reference length of the arc, length of the straight cap beyond it), m, of ``model``'s body of
    ``length``: the channelled part bends, the tip cap (the design's ``cap_thickness``) carries no moment
    and stays straight; a rung whose arc is fitted to the whole body's tip (``info.arc_spans_cap``, fe3d)
    has no cap beyond its arc."""
    cap = 0.0 if model.info.arc_spans_cap else model.design.cap_thickness
    return length - cap, cap


def angle_per_length(state, model: BendModel, length: float | None = None) -> np.ndarray:
    """theta / l of a constant-curvature state (batched) of ``model``'s body of ``length`` (m, or one
    per command; default the design's): |k| x axial stretch x the arc's share of the length
    (``arc_and_cap``), 1/m. What a bench reads as curvature (tip angle over sample length); its
    inverse is R_C = l / theta."""
    length = np.asarray(model.design.length if length is None else length, dtype=float)
    arc, _ = arc_and_cap(model, length)
    k = np.atleast_2d(state.curvature)
    return np.hypot(k[:, 0], k[:, 1]) * np.atleast_1d(state.axial_stretch) * arc / length


def state_backbone(state, arc_length: float, cap: float, n_points: int, index: int = 0):
    """Backbone poses (n_points, 3), (n_points, 4) of one command of ``state``: the rung's own
    solved backbone when it has one (the rod under loads), else the constant-curvature arc of
    arc length ``arc_length`` x stretch and the straight ``cap`` beyond (``arc_and_cap``)."""
    if state.backbone is not None:
        solved = np.asarray(state.backbone)
        return planar_backbone_poses(solved.reshape(-1, *solved.shape[-2:])[index], n_points)
    k = np.asarray(state.curvature).reshape(-1, 2)[index]
    stretch = float(np.asarray(state.axial_stretch).reshape(-1)[index])
    return backbone_poses(k, arc_length * stretch, n_points, cap)


def _finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None


def format_mm(value_m: float | None) -> str:
    return "inf" if value_m is None or not math.isfinite(value_m) else f"{value_m * 1e3:.2f}"
