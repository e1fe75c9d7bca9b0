"""From a bench recording to per-step statistics (docs/actuator.md "The bench").

Each ``sample`` marker on the step topic is one reading: the latest measured
pressures, angle and force received before the marker, if none of them is older than the
recording's ``stale_after_s`` (a stale reading is never analysed as a fresh one: the sample is
left out). Steps that started but never ended (the rig failed mid-run, the bench was killed)
are left out too: the analysis uses the completed steps. The readings are the rig contract's
stamped topics (docs/rig.md), or for older recordings the deprecated unstamped ones. On the
force bench the scale
reading at p = 0 of the same trial (its first loading step) is subtracted (tare).
Per step (bench, drive, phase, level) the mean and standard deviation over trials and
samples are reported for pressure, curvature, R_C = l / theta and force; loading and
unloading are compared at equal measured pressure (hysteresis), see ``hysteresis``.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from .. import topics
from ..core.errors import SoftcathError

DEFAULT_TOPICS = {
    "step": topics.BENCH_STEP,
    "angle": topics.BENCH_BEND_ANGLE,
    "force": topics.BENCH_WRENCH,
}
# Recordings made before the stamped rig contract (deprecated topics).
LEGACY_TOPICS = {
    "step": topics.BENCH_STEP,
    "pressure_measured": topics.PRESSURE_MEASURED,
    "angle": topics.BENCH_ANGLE,
    "force": topics.BENCH_FORCE,
}
DEFAULT_STALE_AFTER_S = 0.5  # bench_node's default, for recordings that do not say


@dataclass
class SampleRow:
    step: int
    bench: str
    sample_name: str
    length: float            # m
    trial: int
    phase: str
    drive: str
    level: float
    pressure_cmd: np.ndarray  # Pa (C,)
    pressure: np.ndarray      # Pa (C,), measured
    angle: float              # rad
    force: float              # N, tared on the force bench
    settled: bool = True

    @property
    def curvature(self) -> float:
        return self.angle / self.length


@dataclass
class StepStats:
    bench: str
    drive: str
    phase: str
    level: float
    n: int
    pressure_mean: np.ndarray     # Pa (C,)
    pressure_std: np.ndarray
    curvature_mean: float         # 1/m
    curvature_std: float
    radius_mean: float            # m (nan where the bend is within the reading noise)
    radius_std: float
    force_mean: float             # N
    force_std: float
    length: float
    unsettled: int = 0
    model: dict = field(default_factory=dict)  # name -> {"curvature": , "radius": , "force": }

    @property
    def pressure_magnitude(self) -> float:
        return float(np.max(self.pressure_mean))


def latest_at_events(events: list[tuple[int, dict]], streams: dict[str, list[tuple[int, object]]],
                     when: dict[str, int] | None = None):
    """For each event in time order: (time ns, marker, {stream: its latest value at or before it, or
    None}). ``when``, if given, is kept up to date with each stream's latest time (ns)."""
    idx = {k: 0 for k in streams}
    latest: dict[str, object] = {k: None for k in streams}
    when = {} if when is None else when
    when.update({k: 0 for k in streams})
    for t, ev in events:
        for k, seq in streams.items():
            while idx[k] < len(seq) and seq[idx[k]][0] <= t:
                when[k], latest[k] = seq[idx[k]]
                idx[k] += 1
        yield t, ev, latest


def rows_from_events(events: list[tuple[int, dict]], streams: dict[str, list[tuple[int, object]]],
                     stale_after: float | None = None, skipped: list | None = None) -> list[SampleRow]:
    """``events``: (time ns, marker dict) in time order. ``streams``: name -> [(time ns, value)] for
    'pressure_measured' (array) or 'pressure_ch0', 'pressure_ch1', ... (floats, one per channel),
    'angle', 'force' (floats), each in time order. With ``stale_after`` (s) a sample whose latest
    reading of any stream is older than that is left out (and its marker appended to ``skipped``).
    Samples of steps that started and never ended are left out, and so are those of an entry taken
    back (a ``retract`` marker: the manual bench's undo)."""
    when: dict[str, int] = {}
    channels = sorted((k for k in streams if k.startswith("pressure_ch")), key=lambda k: int(k[len("pressure_ch"):]))
    settled_by_step: dict[int, bool] = {}
    started, ended = set(), set()
    rows: list[SampleRow] = []
    for t, ev, latest in latest_at_events(events, streams, when):
        kind = ev.get("event")
        if kind == "retract":
            rows = [r for r in rows if r.step != int(ev["step"])]
            continue
        if kind == "step_start":
            started.add(ev["step"])
        elif kind == "step_end":
            ended.add(ev["step"])
        elif kind == "settled":
            settled_by_step[ev["step"]] = bool(ev.get("settled", True))
        if kind != "sample":
            continue
        if channels:
            pressure = None if any(latest[c] is None for c in channels) else [latest[c] for c in channels]
        else:
            pressure = latest.get("pressure_measured")
        if pressure is None:
            continue  # nothing measured yet: not a reading
        if stale_after is not None and any(latest[k] is not None and t - when[k] > stale_after * 1e9 for k in streams):
            if skipped is not None:
                skipped.append(ev)
            continue  # a stale reading is not a reading
        rows.append(SampleRow(
            step=int(ev["step"]), bench=ev["bench"], sample_name=ev["sample_name"],
            length=float(ev["sample_length_m"]), trial=int(ev["trial"]), phase=ev["phase"], drive=ev["drive"],
            level=float(ev["level"]), pressure_cmd=np.asarray(ev["pressure_cmd_pa"], dtype=float),
            pressure=np.asarray(pressure, dtype=float),
            angle=float(latest["angle"]) if latest.get("angle") is not None else math.nan,
            force=float(latest["force"]) if latest.get("force") is not None else math.nan,
            settled=settled_by_step.get(int(ev["step"]), True)))
    incomplete = started - ended
    return tare_forces([r for r in rows if r.step not in incomplete])


def tare_forces(rows: list[SampleRow]) -> list[SampleRow]:
    """Subtract, per (sample, drive, trial) on the force bench, the mean reading at the first p = 0 step."""
    tare: dict[tuple, float] = {}
    for key in {(r.sample_name, r.drive, r.trial) for r in rows if r.bench == "force"}:
        zero = [r for r in rows if r.bench == "force" and (r.sample_name, r.drive, r.trial) == key
                and r.level == 0 and r.phase == "loading"]
        if zero:
            first = min(r.step for r in zero)
            tare[key] = float(np.mean([r.force for r in zero if r.step == first]))
    for r in rows:
        if r.bench == "force":
            r.force = r.force - tare.get((r.sample_name, r.drive, r.trial), math.nan)
    return rows


def check_rows_match_design(rows, design) -> None:
    """Readings of ``design``: one pressure per channel of it (another design named on a recording is
    refused in one line, not met as a shape error inside a rung)."""
    counts = sorted({int(np.size(r.pressure)) for r in rows})
    if counts and counts != [design.n_channels]:
        raise SoftcathError(f"the recording's readings carry {', '.join(map(str, counts))} channel pressure(s); "
                            f"design '{design.name}' has {design.n_channels}: name the design it recorded")


def rows_from_recording(path, topics: dict[str, str] | None = None, skipped: list | None = None) -> list[SampleRow]:
    """Sample rows of a bench recording: the stamped rig topics, or (a recording without them)
    the deprecated unstamped ones; ``topics`` overrides names (keys as DEFAULT_TOPICS). The sample
    markers left out because a reading was stale are appended to ``skipped``."""
    from .. import topics as names
    from ..recording.reader import iter_messages, read_metadata, recording_topics

    present = recording_topics(path)
    channel_topics = sorted((t for t in present if names.message_type(t) == names.FLUID_PRESSURE_TYPE),
                            key=lambda t: int(t.rsplit("ch", 1)[1]))
    stamped = bool(channel_topics) and not (topics and "pressure_measured" in topics)
    chosen = {**(DEFAULT_TOPICS if stamped else LEGACY_TOPICS), **(topics or {})}
    if stamped:
        chosen.update({f"pressure_ch{t.rsplit('ch', 1)[1]}": t for t in channel_topics})
    by_topic = {v: k for k, v in chosen.items()}
    events: list[tuple[int, dict]] = []
    streams: dict[str, list] = {k: [] for k in chosen if k != "step"}
    try:
        for m in iter_messages(path, topics=list(chosen.values())):
            kind = by_topic[m.topic]
            msg = m.message
            if kind == "step":
                ev = json.loads(msg.data)
                if not isinstance(ev, dict):
                    raise ValueError("a step marker is not a JSON object")
                events.append((m.log_time_ns, ev))
            elif kind == "pressure_measured":
                streams[kind].append((m.log_time_ns, np.asarray(msg.data, dtype=float)))
            elif kind.startswith("pressure_ch"):
                streams[kind].append((m.log_time_ns, float(msg.fluid_pressure)))
            elif hasattr(msg, "wrench"):
                streams[kind].append((m.log_time_ns, float(msg.wrench.force.z)))
            elif hasattr(msg, "vector"):
                streams[kind].append((m.log_time_ns, float(msg.vector.x)))
            else:
                streams[kind].append((m.log_time_ns, float(msg.data)))
    except (ValueError, KeyError, TypeError, AttributeError) as exc:   # a recording not written by the bench
        raise SoftcathError(f"{path}: not a bench recording the report can read ({type(exc).__name__}: "
                            f"{str(exc)[:120]})") from None
    meta = read_metadata(path).get("softcath", {})
    try:
        stale_after = float(meta.get("stale_after_s", DEFAULT_STALE_AFTER_S))
    except ValueError:
        stale_after = DEFAULT_STALE_AFTER_S
    return rows_from_events(events, {k: v for k, v in streams.items() if v or k != "pressure_measured"},
                            stale_after=stale_after, skipped=skipped)


def summarise(rows: list[SampleRow], angle_resolution: float = math.radians(1.0)) -> list[StepStats]:
    """Mean and std per (bench, drive, phase, level). R_C is left out (nan) where the mean angle is
    below ``angle_resolution`` (rad): there l / theta measures the noise, not the bend."""
    groups: dict[tuple, list[SampleRow]] = {}
    for r in rows:
        groups.setdefault((r.bench, r.drive, r.phase, r.level), []).append(r)
    out = []
    for (bench, drive, phase, level), rs in groups.items():
        p = np.array([r.pressure for r in rs])
        k = np.array([r.curvature for r in rs])
        f = np.array([r.force for r in rs])
        ang = np.array([r.angle for r in rs])
        std = (lambda x: float(np.std(x, ddof=1)) if len(x) > 1 else 0.0)
        if bench == "angle" and abs(float(np.mean(ang))) >= angle_resolution:
            radius = np.array([r.length for r in rs]) / ang
            r_mean, r_std = float(np.mean(radius)), std(radius)
        else:
            r_mean, r_std = math.nan, math.nan
        out.append(StepStats(bench=bench, drive=drive, phase=phase, level=level, n=len(rs),
                             pressure_mean=p.mean(axis=0), pressure_std=p.std(axis=0, ddof=1) if len(rs) > 1
                             else np.zeros(p.shape[1]),
                             curvature_mean=float(np.mean(k)) if bench == "angle" else math.nan,
                             curvature_std=std(k) if bench == "angle" else math.nan,
                             radius_mean=r_mean, radius_std=r_std,
                             force_mean=float(np.mean(f)) if bench == "force" else math.nan,
                             force_std=std(f) if bench == "force" else math.nan,
                             length=float(np.mean([r.length for r in rs])),
                             unsettled=sum(not r.settled for r in rs)))
    order = {"loading": 0, "unloading": 1}
    out.sort(key=lambda s: (s.bench, s.drive, order[s.phase], s.level if s.phase == "loading" else -s.level))
    return out


@dataclass
class Hysteresis:
    bench: str
    drive: str
    level: float            # the unloading step's level
    quantity: str           # "curvature" (1/m) or "force" (N)
    pressure: float         # Pa, the unloading step's mean measured pressure (largest channel)
    loading: float          # the loading curve's local model at ``pressure``
    unloading: float
    difference: float       # unloading - loading, at equal measured pressure
    t_statistic: float      # difference / its standard error
    significant: bool       # |t| beyond the family-wise threshold of its curve
    threshold: float = 0.0  # that threshold


def _lagrange(x: float, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights of the polynomial through ``nodes`` at ``x``, and of its slope at ``x``."""
    w, dw = np.ones(len(nodes)), np.zeros(len(nodes))
    for i, xi in enumerate(nodes):
        others = np.delete(nodes, i)
        den = float(np.prod(xi - others))
        w[i] = float(np.prod(x - others)) / den
        dw[i] = sum(float(np.prod(x - np.delete(others, j))) for j in range(len(others))) / den
    return w, dw


def _nearest(x: float, xs: np.ndarray, k: int) -> np.ndarray:
    return np.sort(np.argsort(np.abs(xs - x), kind="stable")[:k])


def loading_curve_at(x: float, xs, ys, var_y, var_x):
    """The loading curve at pressure ``x`` (Pa) from its steps (mean pressures ``xs`` ascending, means
    ``ys``, variances of those means ``var_y`` and ``var_x``): a quadratic through the three steps
    nearest ``x``. Returns (value, [(variance term, which step)]): the steps' reading noise, their
    pressure noise times the local slope, and the interpolation error (the cubic through the four
    nearest steps minus the quadratic, step -1), so a convex curve between steps is not read as a
    difference."""
    order = 3 if len(xs) >= 3 else len(xs)
    idx = _nearest(x, xs, order)
    w, _ = _lagrange(x, xs[idx])
    value = float(w @ ys[idx])
    terms = []
    for i, wi in zip(idx, w):
        _, dw = _lagrange(xs[i], xs[idx])
        slope = float(dw @ ys[idx])
        terms += [(wi ** 2 * var_y[i], i), (wi ** 2 * slope ** 2 * var_x[i], i)]
    if len(xs) >= 4:
        idx4 = _nearest(x, xs, 4)
        w4, _ = _lagrange(x, xs[idx4])
        terms.append(((float(w4 @ ys[idx4]) - value) ** 2, -1))
    return value, terms


def loading_slope_at(x: float, xs, ys) -> float:
    idx = _nearest(x, xs, 3 if len(xs) >= 3 else len(xs))
    return float(_lagrange(x, xs[idx])[1] @ ys[idx])


def hysteresis(stats: list[StepStats], family_alpha: float = 0.01) -> list[Hysteresis]:
    """Loading vs unloading at equal *measured* pressure, per curve (bench, drive).

    Each unloading step is compared with the loading curve at the unloading step's measured
    pressure (the regulator approaches a level from below on the way up and from above on the way
    down, so equal commanded levels differ in pressure). The loading curve there is a quadratic
    through its three nearest steps (``loading_curve_at``). The difference's variance holds every
    error a rig without hysteresis shows: the reading noise of the steps, the noise of their mean
    measured pressures times the curve's slope (on a steep curve a few tens of Pa of gauge noise
    are a large difference in bend), and the interpolation error of a curved loading branch
    between its steps. t = difference / its standard error, Welch-Satterthwaite degrees of freedom
    (the interpolation error counted with one). A curve's levels are tested together: a level is
    significant when |t| exceeds the two-sided Bonferroni threshold for ``family_alpha`` over the
    curve's levels, so a run without hysteresis flags nothing in a curve with probability at least
    about 1 - family_alpha, however many levels it has.
    """
    from scipy.stats import t as student_t

    curves: dict[tuple, dict[str, list[StepStats]]] = {}
    for s in stats:
        curves.setdefault((s.bench, s.drive), {"loading": [], "unloading": []})[s.phase].append(s)
    out = []
    for (bench, drive), phases in curves.items():
        q = "curvature" if bench == "angle" else "force"
        up = sorted((s for s in phases["loading"] if np.isfinite(getattr(s, f"{q}_mean"))),
                    key=lambda s: s.pressure_magnitude)
        down = [s for s in phases["unloading"] if np.isfinite(getattr(s, f"{q}_mean"))]
        if len(up) < 2 or not down:
            continue
        xs = np.array([s.pressure_magnitude for s in up])
        ys = np.array([getattr(s, f"{q}_mean") for s in up])
        var_y = np.array([np.nan_to_num(getattr(s, f"{q}_std")) ** 2 / s.n for s in up])
        var_x = np.array([_pressure_var(s) for s in up])
        ns = np.array([s.n for s in up])
        p_one = family_alpha / (2 * len(down))
        for d in down:
            x = d.pressure_magnitude
            mu_l, terms = loading_curve_at(x, xs, ys, var_y, var_x)
            terms = [(v, ns[i] if i >= 0 else 2) for v, i in terms]
            slope = loading_slope_at(x, xs, ys)
            terms += [(np.nan_to_num(getattr(d, f"{q}_std")) ** 2 / d.n, d.n), (slope ** 2 * _pressure_var(d), d.n)]
            var = sum(v for v, _ in terms)
            mu_d = getattr(d, f"{q}_mean")
            if var > 0:
                t = (mu_d - mu_l) / math.sqrt(var)
                dof = var ** 2 / sum(v ** 2 / (n - 1) for v, n in terms if n > 1 and v > 0)
                threshold = float(student_t.ppf(1.0 - p_one, dof))
            else:
                t, threshold = 0.0, math.inf
            out.append(Hysteresis(bench, drive, d.level, q, x, mu_l, mu_d, mu_d - mu_l, t,
                                  abs(t) > threshold, threshold))
    out.sort(key=lambda h: (h.bench, h.drive, h.level))
    return out


def _pressure_var(s: StepStats) -> float:
    """Variance of a step's mean measured pressure (its largest channel)."""
    c = int(np.argmax(s.pressure_mean))
    return float(s.pressure_std[c]) ** 2 / s.n


MODEL_QUANTITIES = ("curvature", "radius", "force")


def model_quantities(stats: list[StepStats], model) -> dict[str, np.ndarray]:
    """The model's theta / l (1/m), R_C = l / theta (m) and blocking force (N) at each step's mean
    measured pressure; NaN where it did not converge (or is straight, for R_C)."""
    from ..core.prediction import angle_per_length
    from .blocking import BlockingForce

    force = BlockingForce(model)
    p = np.array([s.pressure_mean for s in stats])
    state = model.evaluate(np.clip(p, 0.0, None))
    k = np.atleast_2d(state.curvature)
    per_length = angle_per_length(state, model, [s.length for s in stats])   # theta / l: what the angle bench reads as curvature
    conv = np.atleast_1d(state.converged)
    with np.errstate(divide="ignore"):
        radius = np.where(conv & (per_length > 0), 1.0 / per_length, math.nan)
    return {"curvature": np.where(conv, per_length, math.nan), "radius": radius,
            "force": np.array([float(force.from_curvature(k[i], s.length)) if conv[i] else math.nan
                               for i, s in enumerate(stats)])}


def overlay_model(stats: list[StepStats], model, label: str, band95: dict | None = None) -> None:
    """Store ``model_quantities`` in ``stats[i].model[label]``; ``band95`` (same keys, 95% half-widths,
    e.g. from a calibration's covariance) as ``<quantity>_band95``."""
    if not stats:
        return
    q = model_quantities(stats, model)
    for i, s in enumerate(stats):
        s.model[label] = {name: float(q[name][i]) for name in MODEL_QUANTITIES}
        if band95 is not None:
            s.model[label].update({f"{name}_band95": float(band95[name][i]) for name in MODEL_QUANTITIES})
