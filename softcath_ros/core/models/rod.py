"""Rod rung: Kirchhoff statics of the actuator with a moment-curvature law from a higher rung.

The body is a planar, unshearable rod clamped at the base (``core/rod/statics.py``); its sections
carry M(kappa, p) + EI_device kappa, with M the law of the ``source`` rung:
- ``source="section"`` (default): the section rung held at prescribed curvatures
  (``section_fe/moment.py``), tabulated once per design and cached (``core/rod/section_law.py``);
  the stretch lambda(kappa, p) at zero axial force lengthens the segments.
- any other rung name: the linear law M = EI (kappa - kappa_free(p)) with that rung's free
  curvature and the closed form's transformed-section EI (exact for ``closed_form``).
Loads (``core/rod/loads.py``, softcath_base frame): a dead tip force, gravity on the silicone's
weight (rho A g per reference length; the device's and the fluid's weight are not included), and
frictionless tip contact with a plane. The rod is planar: loads and the plane's normal must lie
in the bending plane (the base axis and the bending direction e); one-channel designs only.

``evaluate`` returns curvature = the mean curvature (tip angle / deformed arc length of the
channelled part) along e, axial_stretch = that arc length / (length - cap) (the tip cap,
``cap_thickness``, is rigid and straight, as in the arc rungs: ``core/prediction.arc_and_cap``,
``info.arc_spans_cap`` False), ``backbone`` (N, n+2, 3) joint positions and the tip, ``tip``
(position (N, 3), orientation_xyzw (N, 4), angle (N,) rad) and, when there is a contact plane,
``contact_force`` (N,) N. A command outside the law's table is answered with converged=False and
the reason.
"""
from __future__ import annotations

import copy
import math
from dataclasses import replace

import numpy as np

from ..continuation import Correction, StepControl, ramp, stop_tag
from ..design import Design
from ..errors import ModelError
from ..rod.law import LawRangeError, LinearLaw
from ..rod.loads import REST_TIP, Loads, PlanarLoads, PlaneContact, TipPlaneContact
from ..rod.section_law import LAW_VERSION, LawGrid, section_law
from ..rod.statics import RodSolution, solve_rod
from ..section_properties import transformed_section
from ..options import Option
from ..units import PA_PER_BAR
from .base import BendModel, BendState, RungInfo, SolverDiagnostics, TipPose

_PLANE_TOL = 1e-9
MIN_SEGMENTS, MAX_SEGMENTS = 4, 1000   # a dense Newton per solve: its memory and time grow as n^2 and n^3
# Pa: the pressure ramp of a body in contact (steps of at most half the law's table step, cut to 1/16 of it)
CONTACT_STEPS = StepControl(initial_step=1250.0, max_step=1250.0, min_step=1250.0 / 16)


class RodModel(BendModel):
    name = "rod"
    solver_version = f"rod-3/{LAW_VERSION}"   # bump rod-N when the statics change an answer (2: base hinge, 3: rigid tip cap)
    info = RungInfo(
        summary="Kirchhoff rod statics with a moment-curvature law from a higher rung, under loads",
        models=("free_bending", "device_stiffness", "tip_load", "contact", "gravity"), solves_backbone=True,
        depends_on_length=True,
        builds="its moment-curvature law from the section rung (minutes: about 7 on a shared 2-core machine)",
        options=(Option("source", "str", "the rung whose law the sections carry (default section)"),
                 Option("loads", "object", "a Loads (tip force, gravity, contact); or the three below"),
                 Option("tip_force", "object", "[fx, fy, fz] N in softcath_base"),
                 Option("gravity", "object", "[gx, gy, gz] m/s^2 in softcath_base"),
                 Option("contact", "object", "a TipPlaneContact"),
                 Option("n_segments", "int", "rod segments (4 to 1000)"),
                 Option("grid", "object", "LawGrid: where the section law is tabulated"),
                 Option("cache", "object", "True (the project cache), a cache root directory, or False: "
                                           "where the section law is kept"),
                 Option("progress", "bool", "progress bars while tabulating")),
        more_options="passed to the source rung (e.g. mesh_size)")

    def __init__(self, design: Design, source: str = "section", loads: Loads | None = None,
                 tip_force=None, gravity=None, contact: TipPlaneContact | None = None, n_segments: int = 40,
                 grid: LawGrid | None = None, cache=True, progress: bool = False, **source_options):
        """``loads`` or the separate ``tip_force`` (N), ``gravity`` (m/s^2), ``contact``; ``grid`` and
        ``source_options`` (e.g. ``mesh_size``) set how the section law is tabulated."""
        super().__init__(design)
        if design.n_channels != 1:
            raise ModelError(f"model 'rod': design '{design.name}' has {design.n_channels} channels; the rod "
                             "rung models one-channel designs (a planar law in the bending plane)")
        if loads is not None and (tip_force is not None or gravity is not None or contact is not None):
            raise ModelError("model 'rod': give either loads= or tip_force/gravity/contact, not both")
        self.loads = loads if loads is not None else Loads(
            tip_force=None if tip_force is None else tuple(float(v) for v in tip_force),
            gravity=None if gravity is None else tuple(float(v) for v in gravity), contact=contact)
        if not MIN_SEGMENTS <= n_segments <= MAX_SEGMENTS:
            raise ModelError(f"model 'rod': n_segments {n_segments} must lie in [{MIN_SEGMENTS}, {MAX_SEGMENTS}]")
        self.n_segments = int(n_segments)
        body = replace(design, device=None)
        section = transformed_section(body)
        ch = np.asarray(design.channels[0].center) - section.neutral_axis
        if np.hypot(*ch) == 0:
            raise ModelError(f"model 'rod': the channel of '{design.name}' is on the neutral axis: no bending plane")
        self.direction = -ch / np.hypot(*ch)          # e: the channel side lengthens, the body bends away
        self.device_stiffness = 0.0 if design.device is None else design.device.bending_stiffness
        self.source = source
        if source == "section":
            self.law = section_law(design, grid or LawGrid(), cache=cache, progress=progress, **source_options)
        else:
            from . import make_model

            free_model = make_model(source, body, **source_options)
            ei = float(self.direction @ section.bending_stiffness @ self.direction)

            def free_curvature(p):
                st = free_model.evaluate(np.array([p]))
                if not bool(st.converged):
                    raise LawRangeError(f"rod law from '{source}': {st.message}")
                return float(np.asarray(st.curvature) @ self.direction * st.axial_stretch)

            self.law = LinearLaw(ei, free_curvature, (0.0, design.max_pressure), source=f"linear law from '{source}'")
        self.weight_per_length = design.material.density * section.silicone_area
        self.cap = design.cap_thickness   # the tip cap: rigid and straight, as in the arc rungs (arc_and_cap)
        self.planar = self._planar_loads(self.loads)

    def at_length(self, length: float) -> "RodModel":
        """The rod of actuated length ``length`` (m): the same law (it depends on the section only)
        and loads; a contact plane at the rest tip moves to this length's rest tip."""
        if math.isclose(length, self.design.length, rel_tol=1e-12):
            return self
        other = copy.copy(self)
        other.design = self.design.with_length(length)
        other.planar = other._planar_loads(other.loads)
        return other

    # ------------------------------------------------------------------ loads in the bending plane
    def _in_plane(self, v, what: str) -> tuple[float, float]:
        v = np.asarray(v, dtype=float)
        if v.shape != (3,) or not np.isfinite(v).all():
            raise ModelError(f"model 'rod': {what} {v.tolist()} must be 3 finite numbers (softcath_base)")
        e = self.direction
        off = v[0] * -e[1] + v[1] * e[0]              # component along z x e: out of the bending plane
        if abs(off) > _PLANE_TOL * max(1.0, float(np.linalg.norm(v))):
            raise ModelError(f"model 'rod': {what} {v.tolist()} has a component {off:.3g} out of the bending "
                             f"plane (spanned by z and e = [{e[0]:.3g}, {e[1]:.3g}, 0]); the rod is planar")
        return float(v[2]), float(v[0] * e[0] + v[1] * e[1])

    def _planar_loads(self, loads: Loads) -> PlanarLoads:
        tip = (0.0, 0.0) if loads.tip_force is None else self._in_plane(loads.tip_force, "tip force")
        g = (0.0, 0.0) if loads.gravity is None else self._in_plane(loads.gravity, "gravity")
        weight = (g[0] * self.weight_per_length, g[1] * self.weight_per_length)
        contact = None
        if loads.contact is not None:
            n = self._in_plane(loads.contact.normal, "contact normal")
            norm = math.hypot(*n)
            if norm == 0:
                raise ModelError("model 'rod': the contact normal must not be zero")
            if loads.contact.point == REST_TIP:
                point = (self.design.length, 0.0)
            else:
                point = self._project(loads.contact.point)
            contact = PlaneContact(normal=(n[0] / norm, n[1] / norm), point=point)
        return PlanarLoads(tip_force=tip, weight_per_length=weight, contact=contact)

    def _project(self, point) -> tuple[float, float]:
        p = np.asarray(point, dtype=float)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ModelError(f"model 'rod': contact point {point!r} must be [x, y, z] in m or '{REST_TIP}'")
        e = self.direction
        return float(p[2]), float(p[0] * e[0] + p[1] * e[1])

    # ------------------------------------------------------------------ evaluation
    def solve(self, pressure, length: float | None = None, loads: PlanarLoads | None = None):
        """The rod solution (``RodSolution``) at one pressure (Pa), or the list of them for a 1-D array of
        pressures. One pressure outside the law raises LawRangeError; in a list, its solution has
        ``converged=False`` and the law's message and stop reason.

        With a contact plane the pressures are reached on one ramp from 0 through them in increasing
        order (``core/continuation.ramp``, steps of at most ``CONTACT_STEPS.max_step``), each solve
        starting from the last: the bench's path (the tip on the plane from p = 0), not another
        equilibrium of the same pressure (a body curled past the plane and pressed back)."""
        length = self.design.length if length is None else float(length)
        loads = self.planar if loads is None else loads
        single = np.ndim(pressure) == 0
        out = self._solutions(np.atleast_1d(np.asarray(pressure, dtype=float)), length, loads)
        if single:
            if isinstance(out[0], LawRangeError):
                raise out[0]
            return out[0]
        return [_refused(s, self.n_segments, self.cap) if isinstance(s, LawRangeError) else s for s in out]

    def _solutions(self, pressures: np.ndarray, length: float, loads: PlanarLoads) -> list:
        """Per pressure its RodSolution or the LawRangeError that refused it: directly where nothing is
        touched (or p <= 0), else from one contact ramp through the sorted positive pressures."""
        ramped = loads.contact is not None
        on_ramp = [i for i, p in enumerate(pressures) if ramped and p > 0]
        out: list = [None] * len(pressures)
        for i in sorted(set(range(len(pressures))) - set(on_ramp)):
            try:
                out[i] = solve_rod(self._slice(float(pressures[i])), length, loads, self.n_segments, cap=self.cap)
            except LawRangeError as exc:
                out[i] = exc
        if not on_ramp:
            return out
        result, failed, refusal = self._contact_ramp(sorted({float(pressures[i]) for i in on_ramp}), length, loads)
        reached = {pt.load: pt.state for pt in result.points}
        for i in on_ramp:
            p = float(pressures[i])
            if p in reached:
                out[i] = reached[p]
            elif refusal is not None:        # the ramp stopped below p: where and why
                out[i] = LawRangeError(result.message)
            else:
                out[i] = replace(failed, message=result.message, stop_reason=result.stop_reason)
        return out

    def _contact_ramp(self, pressures, length: float, loads: PlanarLoads):
        """One ramp from 0 through the increasing ``pressures`` (Pa) with the tip on the plane:
        (RampResult, the last failed RodSolution or None, the LawRangeError that stopped it or None)."""
        last = {"failed": None, "refusal": None}     # of the latest attempt: how the ramp's stop failed

        def corrector(guess, t, previous) -> Correction:
            try:
                sol = solve_rod(self._slice(t), length, loads, self.n_segments, guess=guess, cap=self.cap)
            except LawRangeError as exc:
                last["refusal"] = exc
                return Correction(state=None, converged=False, message=str(exc), outside_domain=True,
                                  stop_reason=exc.stop_reason)
            last["refusal"] = None
            if not sol.converged:
                last["failed"] = sol
            return Correction(state=sol, converged=sol.converged, iterations=sol.iterations, message=sol.message,
                              stop_reason=sol.stop_reason)

        result = ramp(corrector, None, pressures, CONTACT_STEPS, extrapolate=None,
                      describe=lambda t: f"p = {t / PA_PER_BAR:.5g} bar")
        return result, last["failed"], last["refusal"]

    def _slice(self, pressure: float):
        return self.law.at(pressure, extra_stiffness=self.device_stiffness)

    def _evaluate_batch(self, pressures: np.ndarray) -> BendState:
        n = len(pressures)
        e = self.direction
        curvature = np.full((n, 2), np.nan)
        stretch = np.full(n, np.nan)
        converged = np.zeros(n, dtype=bool)
        backbone = np.full((n, self.n_segments + 1 + (self.cap > 0), 3), np.nan)
        tip_q = np.full((n, 4), np.nan)
        force = np.full(n, np.nan)
        angle = np.full(n, np.nan)
        messages = []
        for i, (p, sol) in enumerate(zip(pressures[:, 0], self.solve(pressures[:, 0]))):
            if not sol.converged:
                messages.append(f"rod model: command p = {p:.6g} Pa: {sol.message} {stop_tag(sol.stop_reason)}")
                continue
            th = sol.theta[-1]
            curvature[i] = e * th / sol.arc_length
            stretch[i] = sol.arc_length / (self.design.length - self.cap)
            converged[i] = True
            a, b = sol.positions[:, 0], sol.positions[:, 1]
            backbone[i] = np.column_stack([b * e[0], b * e[1], a])
            # rotation by theta about z x e = (-e_y, e_x, 0)
            tip_q[i] = [-e[1] * math.sin(th / 2), e[0] * math.sin(th / 2), 0.0, math.cos(th / 2)]
            force[i] = sol.contact_force
            angle[i] = th
        return BendState(curvature=curvature, axial_stretch=stretch, converged=converged,
                         message="; ".join(messages), backbone=backbone,
                         tip=TipPose(position=backbone[:, -1], angle=angle, orientation_xyzw=tip_q),
                         # a contact force only where there is something to touch
                         contact_force=force if self.loads.contact is not None else None,
                         diagnostics=SolverDiagnostics(law=self.law.source))


def _refused(exc: LawRangeError, n_segments: int, cap: float) -> RodSolution:
    """A solution the law refused: no numbers, its message and stop reason."""
    return RodSolution(theta=np.full(n_segments + 1, np.nan), positions=np.full((n_segments + 1 + (cap > 0), 2), np.nan),
                       kappa=np.full(n_segments, np.nan), arc_length=math.nan, contact_force=math.nan,
                       converged=False, message=str(exc), stop_reason=exc.stop_reason)


__all__ = ["RodModel"]
