"""A bench recording written directly, without a ROS graph: the manual bench and imported data.

Same bag layout, topics, types, step markers, metadata record and attachments as bench_node
writes, so ``report`` and ``calibrate`` read it unchanged. Each entry is one step's reading:
its markers (step_start, settled, sample, step_end), the commanded and measured pressures and
the reading, all stamped with the time of entry, then the chunk is flushed and fsynced: a
Ctrl-C or a crash loses nothing already entered (``softcath recover`` rebuilds the summary of a
file whose writer was killed). An entry taken back (undo) is not erased (the file is append
only): a ``retract`` marker tells the analysis to drop that step's readings.
"""
from __future__ import annotations

import json
import time
from datetime import datetime
from pathlib import Path

from .. import topics
from ..core.errors import SoftcathError
from ..recording import BagWriter
from ..recording.encode import encode, stamp
from .protocol import Protocol, Step

STANDARD_GRAVITY = 9.80665  # m/s^2: a scale reading in grams -> N
# Topics this writer fills besides the rig contract's stamped readings (topics.rig_topics); their
# types are the bench's (topics.message_type).
WRITTEN = (topics.BENCH_STEP, topics.BENCH_RIG, topics.PRESSURE_CMD)


def run_metadata(protocol: Protocol, design, n_steps: int, simulated: bool, rig: dict | None) -> dict[str, str]:
    """The ``softcath`` metadata record of a bench recording."""
    return {"simulated": str(simulated).lower(), "protocol": protocol.name, "design": design.name,
            "design_hash": design.content_hash(), "n_steps": str(n_steps),
            "started": datetime.now().isoformat(timespec="seconds"),
            "rig": json.dumps(rig) if rig else "unknown"}


class BenchSession:
    """Writes one bench run entry by entry. ``rig``: how the readings were taken (kind, ...)."""

    def __init__(self, bag_dir, protocol: Protocol, design, steps: list[Step], rig: dict,
                 clock=time.time_ns):
        import yaml

        self.protocol, self.design, self.steps = protocol, design, steps
        self._clock = clock
        self._last_ns = 0
        self.t0_ns = clock()
        self.entries = 0
        self.writer = BagWriter(Path(bag_dir), flush_period_s=1.0,
                                custom_data={"simulated": "false", "protocol": protocol.name,
                                             "design": design.name, "rig": rig.get("kind", "unknown")})
        for topic in (*WRITTEN, *topics.rig_topics(design.n_channels)):
            self.writer.add_topic(topic, topics.message_type(topic))
        self.writer.add_metadata("softcath", run_metadata(protocol, design, len(steps), False, rig))
        self.writer.add_attachment("protocol.yaml", "application/yaml", protocol.to_yaml().encode())
        self.writer.add_attachment("design.yaml", "application/yaml",
                                   yaml.safe_dump(design.to_dict(), sort_keys=False).encode())
        self._write(topics.BENCH_RIG, json.dumps({**rig, "simulated": False}))
        self._marker({"event": "protocol_start", "protocol": protocol.name, "n_steps": len(steps)})
        self.writer.flush()

    @property
    def path(self) -> Path:
        return self.writer.path

    # ------------------------------------------------------------------ low level
    def _now(self) -> int:
        """Entry time, ns since the epoch, strictly increasing (the analysis orders by it)."""
        self._last_ns = max(self._clock(), self._last_ns + 1)
        return self._last_ns

    def _write(self, topic: str, value, time_ns: int | None = None) -> None:
        t = time_ns or self._now()
        type_name = topics.message_type(topic)
        self.writer.write(topic, encode(type_name, message_fields(type_name, value, t)), t)

    def _marker(self, event: dict, step: Step | None = None) -> None:
        t = self._now()
        ev = {"event": event["event"], "t": (t - self.t0_ns) * 1e-9}  # s since the run started
        if step is not None:
            ev.update(step.describe())
        ev.update({k: v for k, v in event.items() if k != "event"})
        self._write(topics.BENCH_STEP, json.dumps(ev), t)

    # ------------------------------------------------------------------ entries
    def reading(self, step: Step, pressures_measured, values, **extra) -> None:
        """One step's entry: its readings ``values`` (one or more; rad on the angle bench, N of
        untared scale reading on the force bench), each followed by its sample marker, at
        ``pressures_measured`` (Pa per channel). ``extra`` goes into the step_start marker."""
        topic = topics.BENCH_BEND_ANGLE if step.bench == "angle" else topics.BENCH_WRENCH
        self._marker({"event": "step_start", **extra}, step)
        self._write(topics.PRESSURE_CMD, list(step.pressures))
        for channel, p in enumerate(pressures_measured):
            self._write(topics.pressure_measured_topic(channel), float(p))
        self._marker({"event": "settled", "settled": True, "settle_time_s": 0.0}, step)
        for k, v in enumerate(values):
            self._write(topic, float(v))
            self._marker({"event": "sample", "sample": k}, step)
        self._marker({"event": "step_end"}, step)
        self.entries += 1
        self.writer.flush()

    def skip(self, step: Step, reason: str = "skipped by the operator") -> None:
        """No reading for this step: markers only, no sample."""
        self._marker({"event": "step_start"}, step)
        self._marker({"event": "skipped", "reason": reason}, step)
        self._marker({"event": "step_end"}, step)
        self.entries += 1
        self.writer.flush()

    def retract(self, step: Step) -> None:
        """Take back the last entry made for ``step`` (undo): the analysis drops its readings."""
        self._marker({"event": "retract"}, step)
        self.entries -= 1
        self.writer.flush()

    def close(self, complete: bool, reason: str = "") -> None:
        """Protocol end marker (if complete) and the finished file; says in its metadata whether the
        run completed."""
        if self.writer.closed:
            return
        if complete:
            self._marker({"event": "protocol_end", "n_steps": len(self.steps), "unsettled_steps": []})
        result = {"complete": str(bool(complete)).lower(), "completed_steps": str(self.entries),
                  "n_steps": str(len(self.steps)), "reason": reason}   # as bench_node's record
        self.writer.custom_data.update(complete=result["complete"], completed_steps=result["completed_steps"])
        self.writer.add_metadata("softcath_result", result)
        self.writer.close()


def message_fields(type_name: str, value, time_ns: int) -> dict:
    """The message of ``type_name`` carrying ``value`` (a string, a number or a list of numbers)
    entered at ``time_ns``. Only the types the bench topics have; another type is an error here,
    never a guess at its fields."""
    if type_name == "std_msgs/msg/String":
        return {"data": str(value)}
    if type_name == "std_msgs/msg/Float64":
        return {"data": float(value)}
    if type_name == "std_msgs/msg/Float64MultiArray":
        return {"data": [float(x) for x in value]}
    # the rig contract's stamped readings (docs/rig.md): stamped when entered
    header = {"stamp": stamp(time_ns), "frame_id": topics.FRAME_ID}
    if type_name == topics.FLUID_PRESSURE_TYPE:
        return {"header": header, "fluid_pressure": float(value), "variance": 0.0}
    if type_name == "geometry_msgs/msg/Vector3Stamped":
        return {"header": header, "vector": {"x": float(value), "y": 0.0, "z": 0.0}}
    if type_name == "geometry_msgs/msg/WrenchStamped":
        return {"header": {**header, "frame_id": topics.SCALE_FRAME_ID},
                "wrench": {"force": {"x": 0.0, "y": 0.0, "z": float(value)}, "torque": {"x": 0.0, "y": 0.0, "z": 0.0}}}
    raise SoftcathError(f"the manual bench cannot write {type_name} yet (bench/session.py message_fields)")


def grams_to_newton(grams: float) -> float:
    return float(grams) * 1e-3 * STANDARD_GRAVITY

