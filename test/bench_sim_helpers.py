"""Offline bench runs for tests: the protocol engine driving the simulated rig on a fake clock."""
import json


from softcath_ros import topics
from softcath_ros.bench.protocol import ProtocolRunner, expand_steps


def run_offline(protocol, rig, dt=0.01, max_time=600.0):
    """Returns (events [(t_ns, marker)], streams {name: [(t_ns, value)]}), as a recording would hold."""
    design = rig.model.design
    steps = expand_steps(protocol, design.n_channels, design.max_pressure)
    runner = ProtocolRunner(protocol, steps)
    events, streams = [], {"pressure_measured": [], "angle": [], "force": []}
    t = 0.0
    pending = runner.start(t)
    while True:
        for ev in pending:
            if ev["event"] == "step_start":
                rig.mount(ev["bench"], ev["sample_length_m"])
            events.append((int(t * 1e9) + 1, ev))  # markers follow the readings of the same tick
        if runner.done or t > max_time:
            break
        rig.advance(dt, runner.command)
        t += dt
        reading = rig.read()
        tn = int(t * 1e9)
        streams["pressure_measured"].append((tn, reading.pressures.copy()))
        streams["angle"].append((tn, reading.angle))
        streams["force"].append((tn, reading.force))
        pending = runner.update(t, reading.pressures)
    return events, streams


def write_recording(bag_dir, events, streams, design_yaml: str, simulated=True, extra=None, rig=None):
    """Write an offline run as a bench recording would be written (same topics and types).
    ``extra``: topic -> [(time ns, CDR bytes)] of further topics (types from topics.MESSAGE_TYPES).
    ``rig``: the simulated rig (SimulatedRig) whose parameters bench_node records, as sim_bench_node
    announces them."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64, Float64MultiArray, String

    from softcath_ros.recording import BagWriter

    with BagWriter(bag_dir, custom_data={"simulated": str(simulated).lower()}) as w:
        for topic in (topics.BENCH_STEP, topics.PRESSURE_MEASURED, topics.BENCH_ANGLE, topics.BENCH_FORCE):
            w.add_topic(topic, topics.MESSAGE_TYPES[topic])
        meta = {"simulated": str(simulated).lower(), "protocol": "test"}
        if rig is not None:
            from dataclasses import asdict

            meta["rig"] = json.dumps({"simulated": True, "model": rig.model.name, "rig": asdict(rig.params)})
        w.add_metadata("softcath", meta)
        w.add_attachment("design.yaml", "application/yaml", design_yaml.encode())
        for topic in extra or {}:
            w.add_topic(topic, topics.MESSAGE_TYPES[topic])
        merged = [(t, ("x", topic), v) for topic, seq in (extra or {}).items() for t, v in seq] + \
                 [(t, "m", v) for t, v in streams["pressure_measured"]] + \
                 [(t, "a", v) for t, v in streams["angle"]] + [(t, "f", v) for t, v in streams["force"]] + \
                 [(t, "e", ev) for t, ev in events]
        merged.sort(key=lambda x: x[0])
        for t, kind, v in merged:
            if isinstance(kind, tuple):
                w.write(kind[1], v, t)
            elif kind == "m":
                w.write(topics.PRESSURE_MEASURED, serialize_message(Float64MultiArray(data=list(map(float, v)))), t)
            elif kind == "a":
                w.write(topics.BENCH_ANGLE, serialize_message(Float64(data=float(v))), t)
            elif kind == "f":
                w.write(topics.BENCH_FORCE, serialize_message(Float64(data=float(v))), t)
            else:
                w.write(topics.BENCH_STEP, serialize_message(String(data=json.dumps(v))), t)
    return bag_dir / f"{bag_dir.name}_0.mcap"


class TabulatedBlockingForce:
    """The rig's blocking force (bench.blocking) of one truth and sample length, tabulated over the
    curvature magnitude: a single channel bends in one direction, so the rod solve (~6 ms a reading)
    is read from a table in runs over many seeds."""

    def __init__(self, model, length: float, max_curvature: float = 400.0, n: int = 300):
        import numpy as np

        from softcath_ros.bench.blocking import BlockingForce

        exact = BlockingForce(model)
        self.length = length
        bend = np.asarray(model.evaluate(np.full(model.n_channels, 0.5 * model.design.max_pressure)).curvature, float)
        self.direction = bend / np.hypot(*bend)   # the stiffness differs between bending directions
        self.k = np.linspace(0.0, max_curvature, n)
        self.f = np.array([exact.from_curvature(k * self.direction, length) for k in self.k])

    def from_curvature(self, curvature, length):
        import numpy as np

        assert abs(length - self.length) < 1e-12, "tabulated for one sample length"
        mag = float(np.hypot(*curvature))
        assert mag == 0 or not np.isfinite(mag) or abs(float(np.dot(curvature, self.direction)) - mag) < 1e-9 * mag
        return np.interp(mag, self.k, self.f) if mag <= self.k[-1] else np.nan
