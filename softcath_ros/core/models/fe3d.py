"""3D finite-element rung (``fe3d``): the full body in NGSolve, pressure ramped with continuation.

Needs the ``fe`` extra (``pip install softcath_ros[fe]``: NGSolve). See core/fe3d/ for the
mesh (prisms, half model by symmetry), the mixed Yeoh problem and the ramp.

Each distinct pressure direction (ratio between channels) is one ramp from zero through
the requested magnitudes. Results are cached on disk by a hash of the design, mesh, solver
and step settings. A pressure the ramp cannot reach comes back ``converged = False`` with
"did not converge at p = ..." in ``message``; its numbers are NaN, never a guess.

Outputs: curvature vector (1/m) and axial stretch of the arc fitted to the tip (see
core/fe3d/measure.py); per command (NaN where a command failed): ``tip`` (the solved body's
tip position and bending angle), ``radius_l_over_theta`` (R_C = L / theta, the published
definition) and ``diagnostics`` (channel_volume, channel_area at mid-length, newton_iterations,
time_s; channel volume and area NaN at zero pressure, which is not solved).
"""
from __future__ import annotations

import math
from dataclasses import asdict, replace

import numpy as np

from ..cache import CacheStore, store_for
from ..design import Design
from ..errors import ModelError
from ..fe3d.contact import INTORDER
from ..options import Option
from ..section_fe.settings import lumen_fill_fraction
from .base import BendModel, BendState, RungInfo, SolverDiagnostics, TipPose

# The default element and mesh: the combination measured converged to 0.35 bar at 20 mm (docs/models/fe3d.md:
# the in-plane mesh within 0.32 % of a finer one, the prism height within 0.34 % of its limit).
DEFAULT_CONTACT_DISTANCE = 0.02   # of the lumen diameter: 30 um on the implemented design
DEFAULT_MESH_SIZE = 1.4           # of the base MeshSettings, in the section
DEFAULT_LAYER_H = 1.2e-3          # prism height along the body, m
DEFAULT_PRESSURE_ORDER = 1        # P2 + interior bubbles / P1
DEFAULT_INTERIOR_ORDER = 3
DEFAULT_CONTACT_INTORDER = INTORDER   # quadrature order of the lumen contact on the wall (its pair search's points)
# the body the mesh sizes are for (m): a body of another outer diameter gets every mesh length scaled
# by its diameter over this one, so a design scaled as a whole is meshed alike (and, the solid's
# equations being free of a length scale, answers alike at the same pressure)
REFERENCE_DIAMETER = 5.0e-3


def mesh_settings(mesh_size: float = DEFAULT_MESH_SIZE, layer_h: float | None = DEFAULT_LAYER_H,
                  outer_diameter: float = REFERENCE_DIAMETER):
    """The rung's mesh: the base ``MeshSettings()`` scaled by ``mesh_size``, its prisms ``layer_h`` high
    (m; None: scaled too), for a body of ``REFERENCE_DIAMETER``; every length then scaled by
    ``outer_diameter / REFERENCE_DIAMETER``. ModelError (one line) for a value out of range."""
    from ..fe3d.mesh import MeshSettings

    mesh = _reference_mesh(mesh_size, layer_h)
    body = float(outer_diameter) / REFERENCE_DIAMETER
    if body == 1.0:
        return mesh
    return MeshSettings(mesh.section_h * body, mesh.wall_h * body, mesh.layer_h * body, mesh.cap_layers,
                        None if mesh.lumen_h is None else mesh.lumen_h * body, mesh.curvature_safety)


def _reference_mesh(mesh_size, layer_h):
    from ..fe3d.mesh import MeshSettings

    if isinstance(mesh_size, bool) or not 0.1 <= float(mesh_size) <= 10.0:
        raise ModelError(f"fe3d: mesh_size = {mesh_size!r} must be a number in [0.1, 10]")
    mesh = MeshSettings().scaled(float(mesh_size))
    if layer_h is None:
        return mesh
    if isinstance(layer_h, bool) or not 2e-4 <= float(layer_h) <= 2e-2:
        raise ModelError(f"fe3d: layer_h = {layer_h!r} must be a prism height in metres in [2e-4, 2e-2], or None")
    return replace(mesh, layer_h=float(layer_h))


class Fe3dModel(BendModel):
    name = "fe3d"
    solver_version = "fe3d-13"  # bump when a change alters results, so old cache entries are not reused
                                # (7: a ramp stops where the body reaches itself or its shaft;
                                # 8: the default element, mesh and barrier distance; 9: Newton reuses
                                # factorisations, the ramp's steps and stops: the same states to
                                # Newton's tolerance, its stops located differently; 10: the contact's
                                # quadrature order 8 -> 6)
    info = RungInfo(
        summary="3D finite elements of the whole body (NGSolve), pressure ramped with continuation",
        models=("free_bending", "device_stiffness"), needs="fe", depends_on_length=True, arc_spans_cap=True,
        live=False,
        options=(Option("mesh_size", "float", "scales the base mesh in the section (default 1.4; 0.5 = twice as "
                                              "fine as the base)"),
                 Option("layer_h", "float", "prism height along the body in metres (default 1.2e-3; None: the "
                                            "base mesh's scaled by mesh_size); mesh_size and layer_h are for "
                                            "a 5 mm body, scaled with the body's outer diameter"),
                 Option("mesh", "object", "an explicit MeshSettings"),
                 Option("newton", "object", "NewtonSettings"),
                 Option("step_control", "object", "a continuation StepControl"),
                 Option("tangent_predictor", "bool", "predict each step along the tangent"),
                 Option("half", "bool", "half model by symmetry (default: when the whole design is symmetric "
                                         "about x = 0; True: for every direction on a mirror plane)"),
                 Option("cache", "object", "True (the project cache), a cache root directory, or False"),
                 Option("progress", "bool", "a progress bar per ramp"),
                 Option("threads", "int", "solver threads"),
                 Option("lumen_fill", "float", "fill the lumen with a soft solid of this fraction of the "
                                                   "silicone's shear modulus"),
                 Option("contact_distance", "float", "lumen wall self-contact: barrier distance as a fraction of "
                                                         "the lumen diameter (default 0.02; None: off)"),
                 Option("pressure_order", "int", "the element pressure's order: 0 (P2/P0) or 1 (P2/P1, default)"),
                 Option("interior_order", "int", "add condensed element-interior displacement bubbles of this "
                                                 "order (>= 3) to P2 (default 3; None: none)"),
                 Option("contact_intorder", "int", "quadrature order of the lumen contact on the wall: its "
                                                   "pairs are searched at those points (default 6, 2-12)")))

    def __init__(self, design: Design, mesh_size: float = DEFAULT_MESH_SIZE, mesh=None, newton=None,
                 step_control=None, tangent_predictor: bool = True, half: bool | None = None,
                 cache=True, progress: bool = False, threads: int = 2,
                 lumen_fill: float | None = None, contact_distance: float | None = DEFAULT_CONTACT_DISTANCE,
                 pressure_order: int = DEFAULT_PRESSURE_ORDER,
                 interior_order: int | None = DEFAULT_INTERIOR_ORDER, layer_h: float | None = DEFAULT_LAYER_H,
                 contact_intorder: int = DEFAULT_CONTACT_INTORDER):
        """``mesh_size`` scales the base mesh (``MeshSettings()``) in the section and, with ``layer_h``
        None, along the body; ``layer_h`` (m) is the prism height along the body; both are for a
        body of ``REFERENCE_DIAMETER`` (5 mm), every mesh length scaled by the design's outer
        diameter over it. ``mesh`` is an explicit ``MeshSettings`` (absolute; ``layer_h`` its own). The defaults (mesh 1.4, 1.2 mm
        layers, P2 + bubbles / P1, barrier 0.02 of the lumen diameter) are the converged set.
        ``step_control``: a continuation ``StepControl`` (adaptive=False is plain load stepping).
        ``progress`` shows a tqdm bar per ramp. ``lumen_fill``: fill an empty lumen with a soft solid
        of this fraction of the silicone's shear modulus (a self-contact proxy that lets short bodies
        pass the lumen's collapse; core/fe3d/solver.py).
        ``contact_distance``: the empty lumen wall's frictionless self-contact (core/fe3d/contact.py),
        its barrier distance as a fraction of the lumen diameter; None switches it off (the ramp
        then stops where the lumen's shoulders fold, about 0.25 bar). Ignored where the lumen is
        not empty (a device, a fill). ``half``: None (default) the half body when the whole design is
        mirror symmetric about x = 0; True: for each direction on a mirror plane of the section (the
        3-channel design: one channel, or two equal), the half body about that plane, the section
        turned so that it is x = 0 (core/fe3d/symmetry.py ``mirror_plane``), the full body for the
        others; False: the full body.
        ``pressure_order``, ``interior_order``: the element (Fe3dProblem): by default P2 with order-3
        interior bubbles and a P1 pressure, the element that passes the lumen shoulders' fold to
        0.35 bar at 20 mm; P2/P0 (``pressure_order=0, interior_order=None``), the former default,
        stops near 0.23 bar there (docs/models/fe3d.md). ``contact_intorder``: the contact's
        quadrature order on the lumen wall; the pair search, at every such point, is a large part
        of a Newton iteration in contact (docs/models/fe3d.md, "Newton and the ramp").
        Comparison-only variants (displacement-only element, resolved rings, a mirrored full mesh):
        softcath_ros/experimental/fe3d_variants.py."""
        super().__init__(design)
        try:
            import ngsolve  # noqa: F401
        except ImportError as exc:
            raise ModelError("model 'fe3d' needs NGSolve: pip install 'softcath_ros[fe]' "
                             f"(or pip install ngsolve) ({exc})") from None
        from ..fe3d.symmetry import can_use_half_model
        from ..fe3d.ramp import default_step_control
        from ..fe3d.newton_settings import NewtonSettings
        from ..fe3d.solver import check_element

        self.mesh_settings = mesh if mesh is not None else mesh_settings(mesh_size, layer_h, design.outer_diameter)
        self.newton_settings = newton if newton is not None else NewtonSettings(threads=threads)
        self.step_control = step_control if step_control is not None else default_step_control()
        self.tangent_predictor = tangent_predictor
        self.half = can_use_half_model(design) if half is None else half
        self.lumen_fill = lumen_fill_fraction(lumen_fill, "fe3d")
        self.contact_distance = _contact_distance(contact_distance, design, self.lumen_fill)
        try:
            check_element(pressure_order, interior_order)
        except ValueError as exc:
            raise ModelError(f"fe3d: {exc}") from None
        self.pressure_order, self.interior_order = pressure_order, interior_order
        if isinstance(contact_intorder, bool) or not isinstance(contact_intorder, int) or not 2 <= contact_intorder <= 12:
            raise ModelError(f"fe3d: contact_intorder = {contact_intorder!r} must be an integer in 2..12")
        self.contact_intorder = contact_intorder
        self.store = store_for(cache)
        self.use_cache = self.store is not None
        self.progress = progress
        self._problems = {}   # (half, rotation rad) -> Fe3dProblem
        self.last_ramps = []
        self._cache_parts = [design.content_hash(), asdict(self.mesh_settings), asdict(self.newton_settings),
                             asdict(self.step_control),
                             {"tangent_predictor": tangent_predictor, "half": self.half,
                              "lumen_fill": self.lumen_fill, "contact_distance": self.contact_distance,
                              "pressure_order": pressure_order, "interior_order": interior_order,
                              "contact_intorder": contact_intorder, **self._variant()}]
        self.cache_key = CacheStore.key(self.solver_version, self._cache_parts)

    # ------------------------------------------------------------------ plumbing
    def _variant(self) -> dict:
        """What a variant (softcath_ros/experimental) changes: enters the cache key."""
        return {}

    def _problem_options(self) -> dict:
        """Keyword arguments a variant adds to its problem class."""
        return {}

    problem_class = None   # Fe3dProblem (imported lazily); a variant's subclass

    def _turns_to_mirror(self) -> bool:
        """Whether a direction on a mirror plane gets a problem turned to that plane."""
        return bool(self.half)

    @property
    def problem(self):
        """The problem of a direction-independent model: the half body when the whole design is
        symmetric about x = 0 and ``half`` allows, else the full body."""
        from ..fe3d.symmetry import can_use_half_model

        return self._problem_on(bool(self.half) and can_use_half_model(self.design), 0.0)

    def mirror_rotation(self, direction) -> float | None:
        """With ``half`` True: the rotation (rad) that turns a mirror plane of the section and of
        the channel pressures ``direction`` onto x = 0, where the half model's symmetry condition
        is (0 when x = 0 is one); None when the direction lies on no mirror plane (full model)."""
        from ..fe3d.symmetry import can_use_half_model, mirror_plane

        if not self._turns_to_mirror():
            return None
        if can_use_half_model(self.design):
            return 0.0
        angle = mirror_plane(self.design, direction)
        return None if angle is None else math.pi / 2 - angle

    def problem_for(self, direction):
        """The problem a ramp along ``direction`` (pressure per unit, per channel) runs on: the half
        body about the direction's mirror plane (the section turned so that it is x = 0) when
        ``half`` is True and there is one, else the full body."""
        turn = self.mirror_rotation(direction)
        return self._problem_on(turn is not None, turn or 0.0)

    def _problem_on(self, half: bool, turn: float):
        from ..fe3d.symmetry import rotated_section
        from ..fe3d.solver import Fe3dProblem

        key = (half, round(turn, 12))
        if key not in self._problems:
            design = rotated_section(self.design, turn) if turn else self.design
            problem = (self.problem_class or Fe3dProblem)(
                design, self.mesh_settings, self.newton_settings, half, lumen_fill=self.lumen_fill,
                contact_distance=self.contact_distance, pressure_order=self.pressure_order,
                interior_order=self.interior_order, contact_intorder=self.contact_intorder,
                **self._problem_options())
            problem.rotation = turn   # measure() turns its results back into the design's frame
            self._problems[key] = problem
        return self._problems[key]

    def _load_cache(self) -> dict:
        if not self.use_cache:
            return {}
        entries = self.store.load_json("fe3d", self.solver_version, self._cache_parts, self.design.name)
        return entries if isinstance(entries, dict) else {}

    def _save_cache(self, entries: dict) -> None:
        if self.use_cache:
            self.store.save_json("fe3d", self.solver_version, self._cache_parts, entries, self.design.name)

    @staticmethod
    def _key(p: np.ndarray) -> str:
        return ",".join(f"{v:.6g}" for v in p)

    # ------------------------------------------------------------------ evaluation
    def _evaluate_batch(self, pressures: np.ndarray) -> BendState:
        n, c = pressures.shape
        if np.any(pressures < 0) or not np.all(np.isfinite(pressures)):
            raise ModelError("fe3d: pressures must be finite gauge pressures >= 0 Pa")
        cached = self._load_cache()
        results: dict[int, dict] = {}
        messages: list[str] = []
        todo: dict[tuple, list[int]] = {}
        for i, p in enumerate(pressures):
            entry = cached.get(self._key(p))
            if entry is not None:
                results[i] = entry
                continue
            peak = float(p.max())
            if peak == 0.0:
                results[i] = _straight(self.design, c)
                continue
            direction = tuple(np.round(p / peak, 12))
            todo.setdefault(direction, []).append(i)
        for direction, idx in todo.items():
            loads = sorted({float(pressures[i].max()) for i in idx})
            ramp = self._ramp(np.array(direction), loads)
            self.last_ramps.append(ramp)
            by_load = {pt.load: pt for pt in ramp.points}
            for i in idx:
                pt = by_load.get(float(pressures[i].max()))
                if pt is None:
                    results[i] = None
                    continue
                entry = _entry(self.design, pt)
                if entry is None:  # the arc fit failed: report, never a made-up straight answer
                    results[i] = None
                    messages.append(f"no constant-curvature arc fits the solution at p = {pt.load:g} Pa "
                                    f"(fitted arc length {pt.measured['arc_length_m']:.4g} m)")
                    continue
                results[i] = entry
                cached[self._key(pressures[i])] = results[i]
            if not ramp.converged:
                messages.append(ramp.message)
        if todo:
            self._save_cache(cached)
        return _bend_state(results, n, c, "; ".join(messages))

    def _ramp(self, direction, loads):
        from ..fe3d.ramp import run_ramp

        bar = None
        if self.progress:
            from tqdm import tqdm

            bar = tqdm(total=max(loads), unit="Pa", desc=f"fe3d {self.design.name}",
                       bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} Pa [{elapsed}<{remaining}{postfix}]")
        try:
            return run_ramp(self.problem_for(direction), direction, loads, self.step_control,
                            tangent_predictor=self.tangent_predictor, progress=bar)
        finally:
            if bar is not None:
                bar.close()

    def sweep(self, pressures: np.ndarray):
        """Evaluate a ramp of commands (N, C) ignoring the cache; returns (BendState, Fe3dRamp)."""
        saved = self.use_cache
        self.use_cache = False
        try:
            self.last_ramps = []
            state = self.evaluate(pressures)
            return state, (self.last_ramps[0] if self.last_ramps else None)
        finally:
            self.use_cache = saved


def _contact_distance(value, design: Design, lumen_fill) -> float | None:
    """The contact option checked: None where the design has no empty lumen (no lumen, a device,
    a fill) or contact is switched off, else a fraction in (0, 0.2] of the lumen diameter."""
    if value is None or design.lumen is None or design.device is not None or lumen_fill is not None:
        return None
    if isinstance(value, bool) or not 0.0 < float(value) <= 0.2:
        raise ModelError(f"fe3d: contact_distance = {value!r} must be a fraction of the lumen diameter in "
                         "(0, 0.2], or None for no lumen contact")
    return float(value)


def _straight(design: Design, c: int) -> dict:
    return {"curvature": [0.0, 0.0], "axial_stretch": 1.0, "bending_angle_rad": 0.0,
            "radius_l_over_theta_m": float("inf"), "tip_position_m": [0.0, 0.0, design.length],
            "channel_volume_m3": None, "channel_area_m2": None, "newton_iterations": 0, "time_s": 0.0}


def _entry(design: Design, pt) -> dict | None:
    """Outputs at one converged ramp point, or None when no arc fits (e.g. a non-positive arc length)."""
    m = pt.measured
    theta = float(m["bending_angle_rad"])
    arc = float(m["arc_length_m"])
    if not (arc > 0.0 and math.isfinite(arc)):
        return None
    k = (theta / arc) * np.asarray(m["bending_direction"])
    return {"curvature": [float(v) for v in k], "axial_stretch": arc / design.length,
            "bending_angle_rad": theta,
            "radius_l_over_theta_m": design.length / theta if theta > 0 else float("inf"),
            "tip_position_m": [float(v) for v in m["tip_position_m"]],
            "channel_volume_m3": [float(v) for v in m["channel_volume_m3"]],
            "channel_area_m2": [float(v) for v in m["channel_area_m2"]],
            "newton_iterations": int(pt.iterations), "time_s": float(pt.wall_time)}


def _bend_state(results: dict, n: int, c: int, message: str) -> BendState:
    curvature = np.full((n, 2), np.nan)
    stretch = np.full(n, np.nan)
    converged = np.zeros(n, dtype=bool)
    angle, rc, time_s = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    tip = np.full((n, 3), np.nan)
    volume, area = np.full((n, c), np.nan), np.full((n, c), np.nan)
    iterations = np.zeros(n, dtype=int)
    for i in range(n):
        r = results.get(i)
        if r is None:
            continue
        curvature[i] = r["curvature"]
        stretch[i] = r["axial_stretch"]
        converged[i] = True
        angle[i], rc[i], tip[i] = r["bending_angle_rad"], r["radius_l_over_theta_m"], r["tip_position_m"]
        if r["channel_volume_m3"] is not None:
            volume[i], area[i] = r["channel_volume_m3"], r["channel_area_m2"]
        iterations[i], time_s[i] = r["newton_iterations"], r["time_s"]
    return BendState(curvature=curvature, axial_stretch=stretch, converged=converged, message=message,
                     tip=TipPose(position=tip, angle=angle), radius_l_over_theta=rc,
                     diagnostics=SolverDiagnostics(newton_iterations=iterations, channel_area=area,
                                                   channel_volume=volume, time_s=time_s))
