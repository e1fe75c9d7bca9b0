"""Section rung (2.5D): the long-actuator limit as a finite-strain FE problem on the cross-section.

The body is treated as infinitely long: every cross-section deforms the same way in its
plane, and out of plane the body bends uniformly with curvature k and stretches by lambda
(kinematics and potential: ``section_fe/problem.py``). Solved by Newton on a P2/P0 mixed
mesh (``section_fe/mesh.py``, Triangle) with a pressure ramp (``core/continuation.py``) along the
commands (``section_path.py``).

What it captures that the closed form does not: the channel walls bulge and the channel
area grows with pressure, the silicone is hyperelastic, the fibre and rings act at their
true positions. What it leaves out: the tip cap and the fixed base (end effects over about
one diameter), so it is the limit of a long actuator; R_C does not depend on the length.

A command that cannot be reached (Newton fails even with small steps, an element inverts)
is returned with ``converged=False``, NaN numbers and a message "did not converge at
p = ..." that names the last converged pressure; ``BendState.last_converged`` holds that
state's pressure and curvature.
"""
from __future__ import annotations

import json
from collections import OrderedDict
from pathlib import Path

import numpy as np

from ..cache import CacheStore, store_for
from ..continuation import MATERIAL_RANGE, OUTSIDE_MODEL, UNSTABLE, Correction, stop_tag
from ..design import Design
from ..energy import yeoh_convexity_limit
from ..errors import ModelError
from ..section_fe.settings import SectionSettings, discretise
from ..options import Option
from .base import BendModel, BendState, RungInfo, SolverDiagnostics, options_of
from .section_path import PathContinuation, ray_order
from .section_stability import ESCAPE_ITERATIONS, StableStates


# halvings of an inadmissible predictor's step before the corrector gives up on it
PREDICTOR_CUTS = 3
# iterations of the minimiser that looks for the state a snap lands in, and of the one that
# retries a step plain Newton failed
SNAP_ITERATIONS = 40
RETRY_ITERATIONS = 30
MAX_FAILED_RETRIES = 10    # per continuation

# what a cached batch holds (an entry without one of them is solved again)
_CACHED_ARRAYS = ("curvature", "axial_stretch", "converged", "message", "channel_area", "newton_iterations",
                  "negative_directions", "last_converged")


class SectionModel(PathContinuation, StableStates, BendModel):
    name = "section"
    solver_version = "section-8"   # bump when the discretisation or the solver changes an answer (4-5: 3-fold mesh, best-fit frame; 6: saddles left for stable states; 7: Triangle mesher; 8: the rings' bending on, the factor's pattern kept across contact changes)
    info = RungInfo(
        summary="2.5D finite-strain FE of the cross-section: the long-actuator limit",
        models=("free_bending", "device_stiffness"),
        options=(Option("cache", "object", "False, True (the project cache) or a directory for whole batches"),
                 Option("progress", "bool", "a progress bar per batch")) + options_of(SectionSettings, {
            "mesh_size": "element size in m (default: outer diameter / 20)",
            "tol": "Newton step tolerance (non-dimensional)",
            "max_newton": "Newton iterations per step",
            "initial_step": "first continuation step, Pa",
            "max_step": "largest continuation step, Pa",
            "min_step": "smallest continuation step, Pa",
            "adaptive": "False: fixed steps of initial_step, no cutting",
            "hoop_tension_only": "rings carry tension only",
            "ring_bending": "the rings' own bending stiffness E I / pitch (resists wrinkling)",
            "min_hole_gap": "stop when opposite walls of a hole come closer (fraction of its diameter)",
            "contact_resolution": "how finely the wall-contact pressure is located, Pa",
            "local_radius": "a command this close (Pa) to a solved one starts from it",
            "pressure_load": "'follower' (deformed walls and end caps) or 'end_cap' (the closed form's load)",
            "lumen_fill": "fill the lumen with a soft solid of this fraction of the silicone's shear modulus",
            "contact_distance": "hole wall self-contact: barrier distance, fraction of the hole's diameter "
                                "(None: no contact)"}))

    def __init__(self, design: Design, cache: bool | str | Path = False, progress: bool = False,
                 **settings):
        """``cache``: False, True (the project cache, core/cache.py) or a cache root directory;
        results of whole batches are kept there under a hash of design, mesh, settings and
        pressures. ``progress``: a tqdm bar per batch. ``settings``: ``SectionSettings`` fields."""
        # the solver (scipy) is imported where a rung is built, not with this module: a node that
        # answers from a surrogate table reads this rung's RungInfo but never builds it
        from ..section_fe.linear_solver import LinearSolver

        super().__init__(design)
        try:
            self.settings = SectionSettings(**settings)
        except TypeError as exc:
            raise ModelError(f"model 'section': {exc}; settings: {list(SectionSettings.__annotations__)}") from None
        section = discretise(design, self.settings)
        self.mesh, self.mesh_hash, self.problem = section.mesh, section.mesh_hash, section.problem
        self.linear = LinearSolver()
        mat = design.material
        self._material_limit = yeoh_convexity_limit(mat.c1, mat.c2, mat.c3)   # (I1b, uniaxial stretch) or None
        self._rest_eigenvalue = None
        self.progress = progress
        self.store = store_for(cache)
        # converged states by pressure vector (Pa): starting points for later commands
        self._states: OrderedDict[tuple, np.ndarray] = OrderedDict()
        self._states[tuple([0.0] * design.n_channels)] = self.problem.initial_state()
        self._max_states = 256
        # (last converged pressure key, a pressure it could not reach, message, last state summary)
        self._failures: list[tuple] = []
        # limit points the continuation passed by arc length (snaps): the pressure (Pa) where the
        # path turned back and the lowest pressure on it before it rose again
        self.passed_limit_points: list[dict] = []
        # numerical failures of the continuation (no limit point near) it passed by minimising the
        # potential at the next pressure from the last converged state (a stable state found there)
        self.bridged_failures: list[dict] = []
        # saddles the continuation reached and left for the stable state next to them (pressure Pa,
        # negative directions, the potential's drop in units of c1 R^2)
        self.left_saddles: list[dict] = []

    # ------------------------------------------------------------------ identity
    def _cache_parts(self, pressures: np.ndarray) -> dict:
        return {"design": self.design.content_hash(), "settings": self.settings.key(),
                "mesh_nodes": self.mesh.n_nodes, "mesh": self.mesh_hash,
                "pressures": np.asarray(pressures, dtype=float).tolist()}

    def cache_key(self, pressures: np.ndarray) -> str:
        return CacheStore.key(self.solver_version, self._cache_parts(pressures))

    # ------------------------------------------------------------------ evaluation
    def _evaluate_batch(self, pressures: np.ndarray) -> BendState:
        if self.store is not None:
            cached = self._load_cached(pressures)
            if cached is not None:
                return cached
        n, c = pressures.shape
        curvature = np.full((n, 2), np.nan)
        stretch = np.full(n, np.nan)
        converged = np.zeros(n, dtype=bool)
        area = np.full((n, c), np.nan)
        iterations = np.zeros(n, dtype=int)
        negative_directions = np.full(n, -1)     # -1: not reached
        refused: set[int] = set()
        messages: list[str] = []
        last_converged: list[dict | None] = [None] * n
        todo = ray_order(pressures)
        bar = None
        if self.progress:
            from tqdm import tqdm

            bar = tqdm(total=n, desc="section", unit="cmd")
        origin = tuple([0.0] * c)
        try:
            while todo:
                path = self._path(pressures, todo)
                start = self._start_for(pressures[path[0]])
                done, failed, msg, last = self._solve_path(pressures, path, start)
                if failed is not None and not self._same_ray(np.asarray(start), pressures[failed]):
                    # another start may lie on another branch (a folded lumen): from rest, along the ray
                    retry, failed_again, msg, last = self._solve_path(pressures, [failed], origin)
                    done += retry
                    failed = failed_again
                for i, x, its, negative in done:
                    iterations[i] = its
                    negative_directions[i] = negative
                    if negative:
                        # an equilibrium, but a saddle: never answered as a state of the body
                        refused.add(i)
                        messages.append(self._failure_message(
                            pressures[i], f"reaches a saddle of the potential ({negative} direction(s) of negative "
                                          f"stiffness) {stop_tag(UNSTABLE)}"))
                        continue
                    curvature[i], stretch[i], area[i] = self._outputs(x)
                    converged[i] = True
                if bar is not None:
                    bar.update(len(done) + (failed is not None))
                if failed is not None:
                    messages.append(msg)
                    last_converged[failed] = last
                todo = [i for i in todo if i != failed and not converged[i] and i not in refused]
        finally:
            if bar is not None:
                bar.close()
        state = BendState(curvature=curvature, axial_stretch=stretch, converged=converged,
                          message="; ".join(messages), last_converged=last_converged,
                          diagnostics=SolverDiagnostics(newton_iterations=iterations, channel_area=area,
                                                        negative_directions=negative_directions,
                                                        mesh_nodes=self.mesh.n_nodes, mesh_size=self.mesh.h))
        if self.store is not None:
            self._save_cached(pressures, state)
        return state

    def _correct(self, guess, t, previous, minimise: bool, pressure_at, describe, failed_retries: list) -> Correction:
        """The ramp's corrector at path parameter ``t`` (pressures ``pressure_at(t)``): Newton (a
        stable-only minimiser where saddles are met), with the predictor's step halved while it is
        inadmissible, a minimiser as retry, saddles left, and the validity checks that stop a ramp."""
        from ..section_fe.solver import newton
        c_ref = self.problem.c_ref
        hole_names = [f"channel {i}" for i in range(self.design.n_channels)] + ["lumen"]
        # where saddles are met (contact, fill), a minimiser that ends only at a stable state
        # follows the stable branch from the last state: cheaper than converging to the saddle
        # by Newton and leaving it afterwards
        plain = {"max_iterations": self.settings.max_newton}
        if not minimise and self.settings.adaptive and self._saddles_likely(previous):
            plain = {"max_iterations": ESCAPE_ITERATIONS, "stable_only": True}
        if minimise:      # the stable state a snap at this pressure lands in
            corr = newton(self.problem, guess, pressure_at(t) / c_ref, tol=self.settings.tol,
                          max_iterations=SNAP_ITERATIONS, linear=self.linear, minimise=True)
        else:
            corr = newton(self.problem, guess, pressure_at(t) / c_ref, tol=self.settings.tol,
                          linear=self.linear, **plain)
        for _ in range(0 if minimise else PREDICTOR_CUTS):
            if not corr.info.get("inadmissible_start") or guess is previous:
                break
            # the secant predictor pushed the walls through each other: halve its step
            guess = previous + 0.5 * (guess - previous)
            iterations = corr.iterations
            corr = newton(self.problem, guess, pressure_at(t) / c_ref, tol=self.settings.tol,
                          linear=self.linear, **plain)
            corr.iterations += iterations
        if (not corr.converged and not minimise and self.settings.adaptive and failed_retries[0] < MAX_FAILED_RETRIES
                and not corr.info.get("inadmissible_start")):
            # again as a minimiser of the potential (line search, no wandering test: slower,
            # surer); not with fixed steps (adaptive False), which are plain load stepping, and
            # not after MAX_FAILED_RETRIES failed ones (the ramp is then at a limit point)
            retry = newton(self.problem, guess, pressure_at(t) / c_ref, tol=self.settings.tol,
                           max_iterations=RETRY_ITERATIONS, linear=self.linear, minimise=True)
            retry.iterations += corr.iterations
            failed_retries[0] += not retry.converged
            corr = retry if retry.converged else corr
        if corr.converged and not minimise and corr.info.get("negative_directions"):
            corr = self._leave_saddle(corr, pressure_at(t) / c_ref, describe(t))
        if not corr.converged and corr.stop_reason == UNSTABLE:
            return corr
        if not corr.converged:
            # say how close the holes were to closing: failures cluster just before contact
            gaps = self.problem.hole_gaps(previous)
            i = int(np.argmin(gaps))
            corr.message += f"; narrowest hole at the last converged state: {hole_names[i]}, gap {gaps[i]:.0%}"
            if self.problem.fill is not None:
                corr.message += f", lumen fill min det F {self.problem.fill_min_jacobian(previous):.3g}"
            if gaps[i] < 2 * self.settings.min_hole_gap and np.isfinite(self.problem.open_hole_gaps(previous)[i]):
                # the walls are about to touch: the same validity limit as contact itself
                corr.outside_domain = True
                corr.stop_reason = OUTSIDE_MODEL
                corr.message = f"the walls of the {hole_names[i]} are about to touch ({corr.message})"
        else:
            gaps = self.problem.open_hole_gaps(corr.state)
            if gaps.min() < self.settings.min_hole_gap:
                name = hole_names[int(np.argmin(gaps))]
                corr.converged = False
                corr.outside_domain = True
                corr.stop_reason = OUTSIDE_MODEL
                corr.message = (f"the walls of the {name} touch (gap {gaps.min():.1%} of its diameter); "
                                "self-contact is off (contact_distance None)")
            elif self.problem.crossed_walls(corr.state):
                name = hole_names[self.problem.crossed_walls(corr.state)[0]]
                corr.converged = False
                corr.outside_domain = True
                corr.stop_reason = OUTSIDE_MODEL
                corr.message = (f"the wall of the {name} crosses itself (its folded shoulders pass through "
                                "each other); self-contact is off (contact_distance None)")
            elif self._material_limit is not None:
                i1 = self.problem.max_isochoric_i1(corr.state)
                limit, stretch = self._material_limit
                if i1 > limit:
                    corr.converged = False
                    corr.outside_domain = True
                    corr.stop_reason = MATERIAL_RANGE
                    corr.message = (f"the silicone reaches I1b = {i1:.3g}, past I1b = {limit:.3g} (uniaxial "
                                    f"stretch {stretch:.3g}) where its Yeoh energy (c3 < 0) stops being convex")
        return corr

    def max_principal_stretch(self, pressures) -> float | None:
        """Largest principal stretch anywhere in the silicone at a command this model has solved
        (None if it has not; overrides BendModel's None): the strain measure a design's burst margin is judged by. F is block
        diagonal (in-plane 2x2, axial F33), so the principal stretches are the 2x2 block's
        singular values and F33."""
        x = self._states.get(tuple(float(v) for v in pressures))
        if x is None:
            return None
        F2, f33, _, _ = self.problem._element_kinematics(x)
        in_plane = np.linalg.svd(F2, compute_uv=False)   # (e, q, 2)
        return float(max(in_plane.max(), np.abs(f33).max()))

    def _outputs(self, x):
        lam, kr = self.problem.frame_state(x)
        return kr / self.design.outer_radius, lam, self.problem.channel_areas(x) * self.design.outer_radius ** 2

    # ------------------------------------------------------------------ disk cache
    def _load_cached(self, pressures) -> BendState | None:
        z = self.store.load_arrays("section", self.solver_version, self._cache_parts(pressures), self.design.name,
                                   require=_CACHED_ARRAYS)
        if z is None:
            return None
        return BendState(curvature=z["curvature"], axial_stretch=z["axial_stretch"],
                         converged=z["converged"], message=str(z["message"]),
                         last_converged=json.loads(str(z["last_converged"])),
                         diagnostics=SolverDiagnostics(newton_iterations=z["newton_iterations"],
                                                       channel_area=z["channel_area"],
                                                       negative_directions=z["negative_directions"],
                                                       mesh_nodes=self.mesh.n_nodes,
                                                       mesh_size=self.mesh.h, cached=True))

    def _save_cached(self, pressures, state: BendState) -> None:
        self.store.save_arrays("section", self.solver_version, self._cache_parts(pressures), dict(
            curvature=state.curvature, axial_stretch=state.axial_stretch, converged=state.converged,
            message=np.array(state.message), channel_area=state.diagnostics.channel_area,
            newton_iterations=state.diagnostics.newton_iterations,
            negative_directions=state.diagnostics.negative_directions,
            last_converged=np.array(json.dumps(state.last_converged))), self.design.name)


__all__ = ["SectionModel", "SectionSettings"]
