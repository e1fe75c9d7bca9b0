"""Predicted against measured tip position, when the recording has a measured tip pose.

A rig with a tip tracker (or the simulated rig playing one) publishes /softcath/tip_measured
(PoseStamped, softcath_base); model_node's /softcath/tip_pose is the prediction for the
commanded pressures. At each ``sample`` marker of the angle bench (the tip is free there; on
the force bench the scale blocks it) the latest of each is taken; per step (drive, phase,
level) the report gives both positions' means and the distance between them.
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


def tip_pairs(events, streams) -> list[tuple[dict, np.ndarray, np.ndarray]]:
    """(sample marker, predicted xyz, measured xyz) at each angle-bench sample where both exist."""
    out = []
    for _t, ev, latest in latest_at_events(events, streams):
        if ev.get("event") == "sample" and ev.get("bench") == "angle" and \
                latest["predicted"] is not None and latest["measured"] is not None:
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


def tips_from_recording(path) -> list[TipStats]:
    """Per-step tip comparison, or [] when the recording has no measured tip pose."""
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
    return summarise_tips(tip_pairs(events, streams))


def markdown_section(stats: list[TipStats]) -> list[str]:
    from ..core.units import PA_PER_BAR

    if not stats:
        return []
    lines = ["## Tip position: predicted against measured", "",
             "Angle bench (free tip). Predicted: model_node's /softcath/tip_pose for the commanded pressure; "
             "measured: /softcath/tip_measured; both the latest at each reading, in softcath_base.", "",
             "| drive | phase | level | n | predicted x, y, z [mm] | measured x, y, z [mm] | error mean [mm] "
             "| error max [mm] |", "|---|---|---|---|---|---|---|---|"]
    for s in stats:
        level = f"{s.level / PA_PER_BAR:.3f} bar" if s.drive.startswith("channel") else f"{s.level:g} of reach"
        xyz = (lambda v: ", ".join(f"{x * 1e3:.2f}" for x in v))
        lines.append(f"| {s.drive} | {s.phase} | {level} | {s.n} | {xyz(s.predicted)} | {xyz(s.measured)} | "
                     f"{s.error_mean * 1e3:.2f} | {s.error_max * 1e3:.2f} |")
    worst = max(stats, key=lambda s: s.error_mean)
    lines += ["", f"Largest mean error {worst.error_mean * 1e3:.2f} mm ({worst.drive}, {worst.phase}, "
              f"level {worst.level:g}).", ""]
    return lines
