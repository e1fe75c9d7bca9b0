"""The section rung's ramps through its commands: the order commands are solved in, which of them
one continuation walks and from which solved state, the polyline of pressures it follows (its
arc length, Pa, is the continuation parameter), snaps past limit points (by arc length, else by
minimising the potential just past them), and what a ramp that stops leaves behind (a mixin of
``SectionModel``, which holds the problem, the settings, the solved states, the records and the
corrector ``_correct``).

A command is solved along the ray from rest (channels ramped in proportion, as a bench does),
starting from a solved state on that ray or within local_radius of the command. States reached
along other paths may sit on another branch (the lumen folds), so they are not used as starting
points: answers do not depend on the order of commands."""
from __future__ import annotations

import numpy as np

from ..continuation import (LIMIT_POINT, NUMERICAL_FAILURE, ArcControl, Correction, RampPoint, RampResult,
                            StepControl, arc_length, ramp, stop_tag)
from ..units import PA_PER_BAR

# limit points passed by arc length per continuation (snaps), and the largest drop of the pressure
# (fraction of the limit pressure) a snap may have before the limit point counts as the branch's end
MAX_SNAPS = 4
MAX_SNAP_DROP = 0.3


def ray_order(pressures: np.ndarray) -> list[int]:
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


def describe_pressures(p: np.ndarray) -> str:
    """``p = 0.1500, 0.0000 bar``: a pressure vector (Pa) as messages name it."""
    return "p = " + ", ".join(f"{v / PA_PER_BAR:.4f}" for v in p) + " bar"


class CommandPath:
    """The polyline of pressure vectors (Pa) ``corners[0] -> corners[1] -> ...`` parameterised by
    t (Pa), the sum of each leg's largest channel change; ``loads[i]`` is t at ``corners[i]``."""

    def __init__(self, corners: list[np.ndarray]):
        self.corners = corners
        self.legs = np.array([np.max(np.abs(b - a)) for a, b in zip(corners[:-1], corners[1:])])
        self.loads = np.concatenate([[0.0], np.cumsum(self.legs)])

    def leg(self, t: float) -> int:
        return int(np.clip(np.searchsorted(self.loads, t, side="right") - 1, 0, len(self.legs) - 1))

    def pressure_at(self, t: float) -> np.ndarray:
        j = self.leg(t)
        f = 0.0 if self.legs[j] == 0 else (t - self.loads[j]) / self.legs[j]
        return self.corners[j] + min(max(f, 0.0), 1.0) * (self.corners[j + 1] - self.corners[j])

    def direction_at(self, t: float) -> np.ndarray:
        """Pa per unit of t along the leg at ``t``."""
        j = self.leg(t)
        return (self.corners[j + 1] - self.corners[j]) / self.legs[j]

    def describe(self, t: float) -> str:
        return describe_pressures(self.pressure_at(t))


class PathContinuation:
    """Ramps of the section rung through its commands."""

    # ------------------------------------------------------------------ which path, from where
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

    # ------------------------------------------------------------------ the ramp
    def _solve_path(self, pressures: np.ndarray, todo: list[int], start_key: tuple):
        """Ramp from the converged state at ``start_key`` through the commands ``todo`` in order.

        The path is the polyline start -> p[todo[0]] -> p[todo[1]] ...; its arc length (Pa) is
        the continuation parameter. Stops at the first command it cannot reach. Returns (the
        answers reached as (index, state, iterations, negative directions), the index of the
        command it could not reach or None, its message, the last converged state's summary)."""
        first = pressures[todo[0]]
        known = self._known_failure(start_key, first)
        if known is not None:
            return [], todo[0], self._failure_message(first, known[0]), known[1]
        path = CommandPath([np.asarray(start_key)] + [pressures[i] for i in todo])
        failed_retries = [0]

        def corrector(guess, t, previous, minimise: bool = False) -> Correction:
            return self._correct(guess, t, previous, minimise, path.pressure_at, path.describe, failed_retries)

        result = self._ramp_through(path, corrector, self._states[start_key])
        done = self._answers(pressures, todo, result.points)
        if result.converged:
            return done, None, "", None
        failed = todo[len(result.points)]
        why, last = self._record_failure(path, result)
        return done, failed, self._failure_message(pressures[failed], why), last

    def _ramp_through(self, path: CommandPath, corrector, start_state: np.ndarray) -> RampResult:
        """``continuation.ramp`` along ``path`` from ``start_state``; where it stops for no named
        reason (adaptive steps only), up to MAX_SNAPS limit points are passed and it goes on."""
        from ..section_fe.solver import unstable_directions   # (scipy: not on a node's start-up path)

        s = self.settings
        control = StepControl(initial_step=s.initial_step, max_step=s.max_step, min_step=s.min_step,
                              adaptive=s.adaptive, domain_step=s.contact_resolution)
        result = ramp(corrector, start_state, path.loads[1:], control, describe=path.describe)
        points = list(result.points)
        for _ in range(MAX_SNAPS):
            if result.converged or result.stop_reason != NUMERICAL_FAILURE or not s.adaptive:
                break
            if (result.previous is not None and unstable_directions(
                    self.problem, result.last_state, path.pressure_at(result.last_load) / self.problem.c_ref)):
                # the ramp's last state lies just past a limit point (an unstable branch): step back
                result.last_load, result.last_state = result.previous
                result.previous = None
            stable = (result.last_load, result.last_state)
            before = result.previous
            t_next = path.loads[1 + len(points)]          # the command it could not reach
            result = self._probe_limit_point(result, corrector, min(result.last_load + 2 * s.min_step, t_next),
                                             lambda t: path.pressure_at(t) / self.problem.c_ref, path.describe)
            landed = self._past_limit_point(result, path, corrector, stable, before, t_next)
            if landed is None:
                break
            t_arc, landing, t_limit = landed
            rest = list(path.loads[1 + len(points):])
            while rest and rest[0] <= t_arc:              # commands the path passed on its way back up
                corr = corrector(landing, rest[0], landing)
                if not corr.converged:
                    break
                points.append(RampPoint(load=rest[0], state=corr.state, iterations=corr.iterations, info=corr.info))
                rest.pop(0)
            if rest and rest[0] <= t_arc:
                result = RampResult(points=[], converged=False, last_load=t_arc, last_state=landing,
                                    stop_reason=NUMERICAL_FAILURE,
                                    message=f"did not converge at {path.describe(rest[0])} after the snap past "
                                            f"{path.describe(t_limit)} ({corr.message})")
                break
            result = ramp(corrector, landing, rest, control, start=t_arc, describe=path.describe)
            points += result.points
        result.points = points
        return result

    def _past_limit_point(self, result: RampResult, path: CommandPath, corrector, stable: tuple,
                          before: tuple | None, t_next: float):
        """Where the body lands past the point ``stable`` (load, state) the ramp stopped at, short of
        the command at ``t_next``: (its load, its state, the limit's load), by arc length over a limit
        point or, failing that, by minimising the potential just past it; None when this branch ends
        there (``result.message`` then says why). Every pass is recorded."""
        s, c_ref = self.settings, self.problem.c_ref
        if result.stop_reason == LIMIT_POINT:
            arc, t_limit, note = self._follow_by_arc_length(path, stable, before)
        else:                                             # a numerical failure with no limit point near
            arc, t_limit, note = None, stable[0], "the continuation cannot follow the path"
        if arc is not None and arc.passed:
            self.passed_limit_points.append({"pressure": path.pressure_at(t_limit).tolist(),
                                             "lowest_pressure": path.pressure_at(arc.lowest_load * c_ref).tolist(),
                                             "by": "arc length"})
            return arc.load * c_ref, arc.state, t_limit
        if arc is not None and arc.below_floor:
            result.message += f"; {note}: the end of this branch"
            return None
        # the stable state the body jumps to just past that pressure: minimise the potential there
        t_arc = min(t_limit + s.min_step, t_next)
        jump = corrector(stable[1], t_arc, stable[1], minimise=True)
        if not (jump.converged and self.problem.smallest_tangent_eigenvalue(
                jump.state, path.pressure_at(t_arc) / c_ref) > 0):
            why = jump.message or "the state it reaches is not stable"
            result.message += (f"; {note}; minimising the potential at {path.describe(t_arc)} finds no stable "
                               f"state ({why})" + (": the end of this branch" if arc is not None else ""))
            return None
        event = {"pressure": path.pressure_at(t_limit).tolist(), "lowest_pressure": None,
                 "by": "minimised at the next pressure"}
        (self.passed_limit_points if arc is not None else self.bridged_failures).append(event)
        return t_arc, jump.state, t_limit

    def _follow_by_arc_length(self, path: CommandPath, stable: tuple, before: tuple | None):
        """The path followed by arc length from the last stable (load, state) over the limit point:
        (``continuation.arc_length``'s result, the limit's load, a note for messages)."""
        from ..section_fe.solver import PathStep

        s, c_ref, n = self.settings, self.problem.c_ref, self.problem.n
        direction = path.direction_at(stable[0])
        base = path.pressure_at(stable[0]) - stable[0] * direction
        x_rest = self._states[tuple([0.0] * self.design.n_channels)]
        rate = np.linalg.norm(stable[1][:n] - x_rest[:n]) / (stable[0] / c_ref)
        towards = None if before is None else (stable[1][:n] - before[1][:n], (stable[0] - before[0]) / c_ref)
        arc = arc_length(PathStep(self.problem, direction, rate, base / c_ref, tol=s.tol,
                                  max_iterations=max(s.max_newton, 12), linear=self.linear, towards=towards),
                         stable[1], stable[0] / c_ref,
                         ArcControl(initial_step=2 * s.min_step / c_ref, min_step=s.min_step / 8 / c_ref,
                                    max_step=s.max_step / c_ref),
                         floor=(1 - MAX_SNAP_DROP) * stable[0] / c_ref)
        t_limit, t_low = arc.limit_load * c_ref, arc.lowest_load * c_ref
        fate = (f"falls below {path.describe((1 - MAX_SNAP_DROP) * stable[0])} without rising again"
                if arc.below_floor else f"{arc.message} (down to {path.describe(t_low)})")
        return arc, t_limit, (f"followed by arc length from {path.describe(stable[0])}: the path turns back at "
                              f"{path.describe(t_limit)} and {fate}")

    # ------------------------------------------------------------------ what a ramp leaves
    def _answers(self, pressures: np.ndarray, todo: list[int], points: list[RampPoint]) -> list[tuple]:
        """(index, state, iterations, negative directions) per command the ramp reached; a stable
        answer is remembered as a start for later commands, a saddle never is."""
        from ..section_fe.solver import unstable_directions

        c_ref = self.problem.c_ref
        done = []
        for i, point in zip(todo, points):
            x = point.state
            negative = point.info.get("negative_directions")
            if negative is None and np.any(pressures[i] != 0):    # a command the ramp did not step to
                negative = unstable_directions(self.problem, x, pressures[i] / c_ref)
            if negative:
                # a saddle the ramp kept (no contact, no fill: perhaps past a limit point); as an
                # answer it is left for the stable state next to it if there is one, else refused
                x, negative = self._stable_answer(x, pressures[i] / c_ref)
            if not negative:
                self._remember(pressures[i], x)
            done.append((i, x, point.iterations, int(negative or 0)))
        return done

    def _record_failure(self, path: CommandPath, result: RampResult) -> tuple[str, dict]:
        """Remember where a ramp stopped (its last converged state as a start, and the failure, so
        commands further out along the same direction from there fail the same way without a
        ramp): (why it stopped, the last converged state's summary)."""
        last_p = path.pressure_at(result.last_load)
        self._remember(last_p, result.last_state)
        k, lam, _ = self._outputs(result.last_state)
        last = {"pressure": last_p.tolist(), "curvature": k.tolist(), "axial_stretch": float(lam)}
        failing_p = path.pressure_at(min(result.last_load + self.settings.min_step, path.loads[-1]))
        why = f"{result.message} {stop_tag(result.stop_reason)}"
        self._failures.append((tuple(float(v) for v in last_p), failing_p, why, last))
        return why, last

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
        return f"section model: command {describe_pressures(p)} {why}"

    def _remember(self, p: np.ndarray, x: np.ndarray) -> None:
        key = tuple(float(v) for v in p)
        self._states[key] = x
        self._states.move_to_end(key)
        while len(self._states) > self._max_states:
            self._states.popitem(last=False)


__all__ = ["CommandPath", "MAX_SNAPS", "MAX_SNAP_DROP", "PathContinuation", "describe_pressures", "ray_order"]
