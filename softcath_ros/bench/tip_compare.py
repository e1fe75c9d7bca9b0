"""Predicted against measured tip position, when the recording has a measured tip pose.

A rig with a tip tracker (or the simulated rig playing one) publishes /softcath/tip_measured
(PoseStamped, softcath_base). At each ``sample`` marker of the angle bench (the tip is free there; on
the force bench the scale blocks it) the latest measured tip is taken, and the report's model
predicts the tip of that sample: its own length (a 20 mm sample's tip is not the 40 mm body's that
model_node publishes for the design) at the step's commanded pressure (model_node's input too). Per
step (drive, phase, level) the report gives both positions' means and the distance between them.
The samples left out (the model has no answer there) are counted, with why.
"""
from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from .. import topics
from ..core.errors import SoftcathError
from .analysis import latest_at_events


@dataclass
class TipStats:
    drive: str
    phase: str
    level: float
    n: int
    length: float             # m, the sample's
    predicted: np.ndarray     # m (3,), mean
    measured: np.ndarray      # m (3,), mean
    error_mean: float         # m, mean |measured - predicted| over the readings
    error_max: float          # m


def measured_tips(events, streams) -> list[tuple[dict, np.ndarray]]:
    """(sample marker, measured xyz) at each angle-bench sample with a measured tip."""
    out = []
    for _, ev, latest in latest_at_events(events, {"measured": streams["measured"]}):
        if ev.get("event") == "sample" and ev.get("bench") == "angle" and latest["measured"] is not None:
            out.append((ev, latest["measured"]))
    return out


def tip_pairs(measured: list[tuple[dict, np.ndarray]], model, skipped: dict | None = None) \
        -> list[tuple[dict, np.ndarray, np.ndarray]]:
    """(sample marker, predicted xyz, measured xyz): ``model``'s tip for each sample's length at its
    commanded pressure (``core.prediction.predict``). ``skipped`` gains, per reason, the levels
    (drive, phase, level) of the samples it has no answer for."""
    from ..core.prediction import predict

    skipped = {} if skipped is None else skipped
    out = []
    by_length: dict[float, list] = {}
    for ev, xyz in measured:
        by_length.setdefault(float(ev["sample_length_m"]), []).append((ev, xyz))
    for length, items in by_length.items():
        levels = [(ev["drive"], ev["phase"], float(ev["level"])) for ev, _ in items]
        try:
            answers = predict(model, np.array([ev["pressure_cmd_pa"] for ev, _ in items], dtype=float), length)
        except (SoftcathError, ValueError) as exc:
            skipped.setdefault(f"the {model.name} rung predicts no {length * 1e3:g} mm sample ({str(exc)[:120]})",
                               []).extend(levels)
            continue
        for (ev, xyz), answer, level in zip(items, answers, levels):
            if answer.converged:
                out.append((ev, np.array(answer.tip_position_m), xyz))
            else:
                skipped.setdefault(f"the {model.name} rung has no answer ({answer.reason[:200]})", []).append(level)
    return out


def summarise_tips(pairs) -> list[TipStats]:
    groups: dict[tuple, list] = {}
    for ev, pred, meas in pairs:
        groups.setdefault((ev["drive"], ev["phase"], float(ev["level"])), []).append((pred, meas, ev))
    out = []
    for (drive, phase, level), items in groups.items():
        pred = np.array([p for p, _, _ in items])
        meas = np.array([m for _, m, _ in items])
        err = np.linalg.norm(meas - pred, axis=1)
        out.append(TipStats(drive, phase, level, len(items), float(np.mean([ev["sample_length_m"] for *_, ev in items])),
                            pred.mean(axis=0), meas.mean(axis=0), float(err.mean()), float(err.max())))
    order = {"loading": 0, "unloading": 1}
    out.sort(key=lambda s: (s.drive, order[s.phase], s.level if s.phase == "loading" else -s.level))
    return out


def tips_from_recording(path, model, skipped: dict | None = None) -> list[TipStats]:
    """Per-step tip comparison against ``model`` (``tip_pairs``; ``skipped``), or [] when the recording
    has no measured tip pose."""
    from ..recording.reader import iter_messages

    events, streams = [], {"measured": []}
    for m in iter_messages(path, topics=[topics.BENCH_STEP, topics.TIP_MEASURED]):
        if m.topic == topics.BENCH_STEP:
            events.append((m.log_time_ns, json.loads(m.message.data)))
        else:
            p = m.message.pose.position
            streams["measured"].append((m.log_time_ns, np.array([p.x, p.y, p.z])))
    if not streams["measured"]:
        return []
    return summarise_tips(tip_pairs(measured_tips(events, streams), model, skipped))


def _level(drive: str, level: float) -> str:
    from ..core.units import PA_PER_BAR

    return f"{level / PA_PER_BAR:.3f} bar" if drive.startswith("channel") else f"{level:g} of reach"


def markdown_section(stats: list[TipStats], skipped: dict | None = None, model_label: str = "the model") -> list[str]:
    skipped = skipped or {}
    if not stats and not skipped:
        return []
    lines = ["## Tip position: predicted against measured", "",
             f"Angle bench (free tip). Predicted: {model_label} for the sample's own length at the step's commanded "
             "pressure; measured: /softcath/tip_measured, the latest at each reading; in softcath_base.", ""]
    if stats:
        lines += ["| drive | phase | level | sample [mm] | n | predicted x, y, z [mm] | measured x, y, z [mm] "
                  "| error mean [mm] | error max [mm] |", "|---|---|---|---|---|---|---|---|---|"]
        for s in stats:
            xyz = (lambda v: ", ".join(f"{x * 1e3:.2f}" for x in v))
            lines.append(f"| {s.drive} | {s.phase} | {_level(s.drive, s.level)} | {s.length * 1e3:g} | {s.n} | "
                         f"{xyz(s.predicted)} | {xyz(s.measured)} | {s.error_mean * 1e3:.2f} | {s.error_max * 1e3:.2f} |")
        worst = max(stats, key=lambda s: s.error_mean)
        lines += ["", f"Largest mean error {worst.error_mean * 1e3:.2f} mm ({worst.drive}, {worst.phase}, "
                  f"{_level(worst.drive, worst.level)}).", ""]
    for why, levels in skipped.items():
        steps = sorted(set(levels), key=lambda x: (x[0], x[1] != "loading", x[2] if x[1] == "loading" else -x[2]))
        shown = ", ".join(f"{d} {ph} {_level(d, lv)}" for d, ph, lv in steps[:8]) + (" ..." if len(steps) > 8 else "")
        lines += [f"Not compared, {len(levels)} reading(s): {why} ({shown}).", ""]
    return lines
