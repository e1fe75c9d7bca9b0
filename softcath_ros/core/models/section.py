"""Section rung (2.5D): the long-actuator limit as a finite-strain FE problem on the cross-section.

The body is treated as infinitely long: every cross-section deforms the same way in its
plane, and out of plane the body bends uniformly with curvature k and stretches by lambda
(kinematics and potential: ``section_fe/problem.py``). Solved by Newton on a P2/P0 mixed
mesh (``section_fe/mesh.py``, Triangle) with a pressure ramp (``core/continuation.py``).

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
from ..continuation import (LIMIT_POINT, MATERIAL_RANGE, NUMERICAL_FAILURE, OUTSIDE_MODEL, UNSTABLE, ArcControl,
                            Correction, RampPoint, RampResult, StepControl, arc_length, ramp, stop_tag)
from ..design import Design
from ..energy import yeoh_convexity_limit
from ..errors import ModelError
from ..section_fe.settings import SectionSettings, discretise
from ..section_fe.solver import LinearSolver, PathStep, newton, unstable_directions
from ..options import Option
from .base import BendModel, BendState, RungInfo, SolverDiagnostics, options_of
from .section_stability import ESCAPE_ITERATIONS, StableStates
from ..units import PA_PER_BAR


# limit points passed by arc length per continuation (snaps), and the largest drop of the pressure
# (fraction of the limit pressure) a snap may have before the limit point counts as the branch's end
MAX_SNAPS = 4
# halvings of an inadmissible predictor's step before the corrector gives up on it
PREDICTOR_CUTS = 3
# iterations of the minimiser that looks for the state a snap lands in, and of the one that
# retries a step plain Newton failed
SNAP_ITERATIONS = 40
RETRY_ITERATIONS = 30
MAX_FAILED_RETRIES = 10    # per continuation
MAX_SNAP_DROP = 0.3

# what a cached batch holds (an entry without one of them is solved again)
_CACHED_ARRAYS = ("curvature", "axial_stretch", "converged", "message", "channel_area", "newton_iterations",
                  "negative_directions", "last_converged")


def _ray_order(pressures: np.ndarray) -> list[int]:
    """The order commands are solved in: the rest state first, then per ray (at its first command)
    that ray's commands by increasing pressure, so that one ramp walks up through all of them instead
    of back down to a smaller one; commands on rays of their own keep their order (a trajectory)."""
    peak = np.max(np.abs(pressures), axis=1)
    first: dict[tuple, int] = {}
    keys = []
    for i, (p, m) in enumerate(zip(pressures, peak)):
        ray = () if m == 0 else tuple(np.round(p / m, 12))
        keys.append((-1 if m == 0 else first.setdefault(ray, i), m, i))
    return [k[2] for k in sorted(keys)]


class SectionModel(StableStates, BendModel):
    name = "section"
    solver_version = "section-7"   # bump when the discretisation or the solver changes an answer (4-5: 3-fold mesh, best-fit frame; 6: saddles left for stable states; 7: Triangle mesher)
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
        todo = _ray_order(pressures)
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

    # A command is solved along the ray from rest (channels ramped in proportion, as a bench
    # does), starting from a solved state on that ray or within local_radius of the command.
    # States reached along other paths may sit on another branch (the lumen folds), so they
    # are not used as starting points: answers do not depend on the order of commands.
    def _near(self, a: np.ndarray, b: np.ndarray) -> bool:
        return float(np.max(np.abs(a - b))) <= self.settings.local_radius

    @staticmethod
    def _same_ray(a: np.ndarray, b: np.ndarray) -> bool:
        na, nb = np.linalg.norm(a), np.linalg.norm(b)
        return na == 0 or nb == 0 or float(a @ b) >= (1 - 1e-12) * na * nb

    def _start_for(self, target: np.ndarray) -> tuple:
        ok = [k for k in self._states
              if self._same_ray(np.asarray(k), target) or self._near(np.asarray(k), target)]
        return min(ok, key=lambda k: float(np.max(np.abs(np.asarray(k) - target))))

    def _path(self, pressures: np.ndarray, todo: list[int]) -> list[int]:
        """The longest prefix of ``todo`` that one continuation can walk (same ray or close)."""
        path = [todo[0]]
        for i in todo[1:]:
            a, b = pressures[path[-1]], pressures[i]
            if not (self._same_ray(a, b) or self._near(a, b)):
                break
            path.append(i)
        return path

    def _solve_path(self, pressures: np.ndarray, todo: list[int], start_key: tuple):
        """Ramp from the converged state at ``start_key`` through the commands ``todo`` in order.

        The path is the polyline start -> p[todo[0]] -> p[todo[1]] ...; its arc length (Pa) is
        the continuation parameter. Stops at the first command it cannot reach."""
        first = pressures[todo[0]]
        known = self._known_failure(start_key, first)
        if known is not None:
            return [], todo[0], self._failure_message(first, known[0]), known[1]
        corners = [np.asarray(start_key)] + [pressures[i] for i in todo]
        seg = np.array([np.max(np.abs(b - a)) for a, b in zip(corners[:-1], corners[1:])])
        cum = np.concatenate([[0.0], np.cumsum(seg)])

        def pressure_at(t: float) -> np.ndarray:
            j = int(np.clip(np.searchsorted(cum, t, side="right") - 1, 0, len(seg) - 1))
            f = 0.0 if seg[j] == 0 else (t - cum[j]) / seg[j]
            return corners[j] + min(max(f, 0.0), 1.0) * (corners[j + 1] - corners[j])

        c_ref = self.problem.c_ref

        failed_retries = [0]

        def corrector(guess, t, previous, minimise: bool = False) -> Correction:
            return self._correct(guess, t, previous, minimise, pressure_at, describe, failed_retries)

        def describe(t: float) -> str:
            p = pressure_at(t)
            return "p = " + ", ".join(f"{v / PA_PER_BAR:.4f}" for v in p) + " bar"

        s = self.settings
        control = StepControl(initial_step=s.initial_step, max_step=s.max_step, min_step=s.min_step,
                              adaptive=s.adaptive, domain_step=s.contact_resolution)
        result = ramp(corrector, self._states[start_key], cum[1:], control, describe=describe)
        points = list(result.points)
        for _ in range(MAX_SNAPS):
            if result.converged or result.stop_reason != NUMERICAL_FAILURE or not s.adaptive:
                break
            if (result.previous is not None and unstable_directions(
                    self.problem, result.last_state, pressure_at(result.last_load) / c_ref)):
                # the ramp's last state lies just past a limit point (an unstable branch): step back
                result.last_load, result.last_state = result.previous
                result.previous = None
            stable = (result.last_load, result.last_state)
            before = result.previous
            t_next = cum[1 + len(points)]                 # the command it could not reach
            result = self._probe_limit_point(result, corrector, min(result.last_load + 2 * s.min_step, t_next),
                                             lambda t: pressure_at(t) / c_ref, describe)
            if result.stop_reason == LIMIT_POINT:
                # follow the path by arc length from the last stable state
                j = int(np.clip(np.searchsorted(cum, stable[0], side="right") - 1, 0, len(seg) - 1))
                direction = (corners[j + 1] - corners[j]) / seg[j]            # Pa per unit of t
                base = pressure_at(stable[0]) - stable[0] * direction
                x_rest = self._states[tuple([0.0] * self.design.n_channels)]
                rate = np.linalg.norm(stable[1][:self.problem.n] - x_rest[:self.problem.n]) / (stable[0] / c_ref)
                towards = None if before is None else (stable[1][:self.problem.n] - before[1][:self.problem.n],
                                                        (stable[0] - before[0]) / c_ref)
                arc = arc_length(PathStep(self.problem, direction, rate, base / c_ref, tol=s.tol,
                                          max_iterations=max(s.max_newton, 12), linear=self.linear, towards=towards),
                                 stable[1], stable[0] / c_ref,
                                 ArcControl(initial_step=2 * s.min_step / c_ref, min_step=s.min_step / 8 / c_ref,
                                            max_step=s.max_step / c_ref),
                                 floor=(1 - MAX_SNAP_DROP) * stable[0] / c_ref)
                t_limit, t_low = arc.limit_load * c_ref, arc.lowest_load * c_ref
                fate = (f"falls below {describe((1 - MAX_SNAP_DROP) * stable[0])} without rising again"
                        if arc.below_floor else f"{arc.message} (down to {describe(t_low)})")
                note = f"followed by arc length from {describe(stable[0])}: the path turns back at {describe(t_limit)} and {fate}"
            else:                                         # a numerical failure with no limit point near
                arc, t_limit, note = None, stable[0], "the continuation cannot follow the path"
            if arc is not None and arc.passed:
                t_arc, landing = arc.load * c_ref, arc.state
                self.passed_limit_points.append({"pressure": pressure_at(t_limit).tolist(),
                                                 "lowest_pressure": pressure_at(t_low).tolist(), "by": "arc length"})
            elif arc is not None and arc.below_floor:
                result.message += f"; {note}: the end of this branch"
                break
            else:
                # the stable state the body jumps to just past that pressure: minimise the potential there
                t_arc = min(t_limit + s.min_step, t_next)
                jump = corrector(stable[1], t_arc, stable[1], minimise=True)
                if not (jump.converged and self.problem.smallest_tangent_eigenvalue(
                        jump.state, pressure_at(t_arc) / c_ref) > 0):
                    why = jump.message or "the state it reaches is not stable"
                    result.message += (f"; {note}; minimising the potential at {describe(t_arc)} finds no stable "
                                       f"state ({why})" + (": the end of this branch" if arc is not None else ""))
                    break
                landing = jump.state
                event = {"pressure": pressure_at(t_limit).tolist(), "lowest_pressure": None,
                         "by": "minimised at the next pressure"}
                (self.passed_limit_points if arc is not None else self.bridged_failures).append(event)
            rest = list(cum[1 + len(points):])
            while rest and rest[0] <= t_arc:              # commands the path passed on its way back up
                corr = corrector(landing, rest[0], landing)
                if not corr.converged:
                    break
                points.append(RampPoint(load=rest[0], state=corr.state, iterations=corr.iterations, info=corr.info))
                rest.pop(0)
            if rest and rest[0] <= t_arc:
                result = RampResult(points=[], converged=False, last_load=t_arc, last_state=landing,
                                    stop_reason=NUMERICAL_FAILURE,
                                    message=f"did not converge at {describe(rest[0])} after the snap past "
                                            f"{describe(t_limit)} ({corr.message})")
                break
            result = ramp(corrector, landing, rest, control, start=t_arc, describe=describe)
            points += result.points
        result.points = points
        done = []
        for i, point in zip(todo, result.points):
            x = point.state
            negative = point.info.get("negative_directions")
            if negative is None and np.any(pressures[i] != 0):    # a command the ramp did not step to
                negative = unstable_directions(self.problem, x, pressures[i] / c_ref)
            if negative:
                # a saddle the ramp kept (no contact, no fill: perhaps past a limit point); as an
                # answer it is left for the stable state next to it if there is one, else refused
                x, negative = self._stable_answer(x, pressures[i] / c_ref)
            if not negative:     # a saddle is never a start for later commands
                self._remember(pressures[i], x)
            done.append((i, x, point.iterations, int(negative or 0)))
        if result.converged:
            return done, None, "", None
        failed = todo[len(result.points)]
        last_p = pressure_at(result.last_load)
        self._remember(last_p, result.last_state)
        k, lam, _ = self._outputs(result.last_state)
        last = {"pressure": last_p.tolist(), "curvature": k.tolist(), "axial_stretch": float(lam)}
        # Commands further out along the same direction from this state fail the same way.
        failing_p = pressure_at(min(result.last_load + s.min_step, cum[-1]))
        why = f"{result.message} {stop_tag(result.stop_reason)}"
        self._failures.append((tuple(float(v) for v in last_p), failing_p, why, last))
        return done, failed, self._failure_message(pressures[failed], why), last

    def _correct(self, guess, t, previous, minimise: bool, pressure_at, describe, failed_retries: list) -> Correction:
        """The ramp's corrector at path parameter ``t`` (pressures ``pressure_at(t)``): Newton (a
        stable-only minimiser where saddles are met), with the predictor's step halved while it is
        inadmissible, a minimiser as retry, saddles left, and the validity checks that stop a ramp."""
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

    def _known_failure(self, start_key: tuple, target: np.ndarray):
        start = np.asarray(start_key)
        d_t = target - start
        for key, p_fail, message, last in self._failures:
            if key != start_key:
                continue
            d_f = p_fail - start
            nt, nf = np.linalg.norm(d_t), np.linalg.norm(d_f)
            if nf > 0 and nt >= nf and float(d_t @ d_f) >= (1 - 1e-9) * nt * nf:
                return message, last
        return None

    @staticmethod
    def _failure_message(p: np.ndarray, why: str) -> str:
        return f"section model: command p = {', '.join(f'{v / PA_PER_BAR:.4f}' for v in p)} bar {why}"

    def _remember(self, p: np.ndarray, x: np.ndarray) -> None:
        key = tuple(float(v) for v in p)
        self._states[key] = x
        self._states.move_to_end(key)
        while len(self._states) > self._max_states:
            self._states.popitem(last=False)

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
