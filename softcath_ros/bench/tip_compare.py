"""Predicted against measured tip position, when the recording has a measured tip pose.

A rig with a tip tracker (or the simulated rig playing one) publishes /softcath/tip_measured
(PoseStamped, softcath_base); model_node's /softcath/tip_pose is the prediction for the
commanded pressures. At each ``sample`` marker of the angle bench (the tip is free there; on
the force bench the scale blocks it) the latest of each is taken; per step (drive, phase,
level) the report gives both positions' means and the distance between them.

A prediction counts only if it came after its step started (model_node publishes nothing for a
command it refuses, and the pose of an earlier step is no prediction for this one), and only for
a sample as long as the body model_node predicts (the design's length): a 20 mm sample's tip is
not a 40 mm body's. The samples left out are counted, with why.
"""
from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from .. import topics
from .analysis import latest_at_events


@dataclass
class TipStats:
    drive: str
    phase: str
    level: float
    n: int
    predicted: np.ndarray     # m (3,), mean
    measured: np.ndarray      # m (3,), mean
    error_mean: float         # m, mean |measured - predicted| over the readings
    error_max: float          # m


def tip_pairs(events, streams, body_length_m: float | None = None, skipped: dict | None = None) \
        -> list[tuple[dict, np.ndarray, np.ndarray]]:
    """(sample marker, predicted xyz, measured xyz) at each angle-bench sample where both exist, the
    prediction is of this step and the sample is ``body_length_m`` long (m; None: any). ``skipped``
    gains, per reason, the levels (drive, phase, level) of the samples left out."""
    out = []
    when: dict[str, int] = {}
    step_started = 0
    skipped = {} if skipped is None else skipped
    for t, ev, latest in latest_at_events(events, streams, when):
        if ev.get("event") == "step_start":
            step_started = t
        if ev.get("event") != "sample" or ev.get("bench") != "angle" or latest["measured"] is None:
            continue
        level = (ev["drive"], ev["phase"], float(ev["level"]))
        length = ev.get("sample_length_m")
        if body_length_m is not None and length is not None and not np.isclose(length, body_length_m, rtol=1e-9):
            skipped.setdefault(f"the sample is {length * 1e3:g} mm long, the predicted body "
                               f"{body_length_m * 1e3:g} mm", []).append(level)
        elif latest["predicted"] is None or when["predicted"] < step_started:
            skipped.setdefault("no prediction for the step (model_node refused its command or had not "
                               "answered)", []).append(level)
        else:
            out.append((ev, latest["predicted"], latest["measured"]))
    return out


def summarise_tips(pairs) -> list[TipStats]:
    groups: dict[tuple, list] = {}
    for ev, pred, meas in pairs:
        groups.setdefault((ev["drive"], ev["phase"], float(ev["level"])), []).append((pred, meas))
    out = []
    for (drive, phase, level), items in groups.items():
        pred = np.array([p for p, _ in items])
        meas = np.array([m for _, m in items])
        err = np.linalg.norm(meas - pred, axis=1)
        out.append(TipStats(drive, phase, level, len(items), pred.mean(axis=0), meas.mean(axis=0),
                            float(err.mean()), float(err.max())))
    order = {"loading": 0, "unloading": 1}
    out.sort(key=lambda s: (s.drive, order[s.phase], s.level if s.phase == "loading" else -s.level))
    return out


def tips_from_recording(path, body_length_m: float | None = None, skipped: dict | None = None) -> list[TipStats]:
    """Per-step tip comparison, or [] when the recording has no measured tip pose (``tip_pairs``:
    ``body_length_m``, ``skipped``)."""
    from ..recording.reader import iter_messages

    events, streams = [], {"predicted": [], "measured": []}
    which = {topics.TIP_POSE: "predicted", topics.TIP_MEASURED: "measured"}
    for m in iter_messages(path, topics=[topics.BENCH_STEP, topics.TIP_POSE, topics.TIP_MEASURED]):
        if m.topic == topics.BENCH_STEP:
            events.append((m.log_time_ns, json.loads(m.message.data)))
        else:
            p = m.message.pose.position
            streams[which[m.topic]].append((m.log_time_ns, np.array([p.x, p.y, p.z])))
    if not streams["measured"]:
        return []
    return summarise_tips(tip_pairs(events, streams, body_length_m, skipped))


def _level(drive: str, level: float) -> str:
    from ..core.units import PA_PER_BAR

    return f"{level / PA_PER_BAR:.3f} bar" if drive.startswith("channel") else f"{level:g} of reach"


def markdown_section(stats: list[TipStats], skipped: dict | None = None) -> list[str]:
    skipped = skipped or {}
    if not stats and not skipped:
        return []
    lines = ["## Tip position: predicted against measured", "",
             "Angle bench (free tip). Predicted: model_node's /softcath/tip_pose for the commanded pressure, "
             "published after the step began; measured: /softcath/tip_measured; both the latest at each reading, "
             "in softcath_base.", ""]
    if stats:
        lines += ["| drive | phase | level | n | predicted x, y, z [mm] | measured x, y, z [mm] | error mean [mm] "
                  "| error max [mm] |", "|---|---|---|---|---|---|---|---|"]
        for s in stats:
            xyz = (lambda v: ", ".join(f"{x * 1e3:.2f}" for x in v))
            lines.append(f"| {s.drive} | {s.phase} | {_level(s.drive, s.level)} | {s.n} | {xyz(s.predicted)} | "
                         f"{xyz(s.measured)} | {s.error_mean * 1e3:.2f} | {s.error_max * 1e3:.2f} |")
        worst = max(stats, key=lambda s: s.error_mean)
        lines += ["", f"Largest mean error {worst.error_mean * 1e3:.2f} mm ({worst.drive}, {worst.phase}, "
                  f"level {worst.level:g}).", ""]
    for why, levels in skipped.items():
        steps = sorted(set(levels), key=lambda x: (x[0], x[1] != "loading", x[2] if x[1] == "loading" else -x[2]))
        shown = ", ".join(f"{d} {ph} {_level(d, lv)}" for d, ph, lv in steps[:8]) + (" ..." if len(steps) > 8 else "")
        lines += [f"Not compared, {len(levels)} reading(s): {why} ({shown}).", ""]
    return lines
