"""regulator_node (node ``softcath_regulator``): the pressure half of the rig contract (docs/rig.md,
docs/lab.md) on a real regulator. A managed (lifecycle) node around
``softcath_ros.bench.hardware.regulator``; backends: ``serial`` (the line protocol of
bench/hardware/protocol.py), ``modbus`` (Modbus TCP, the register map in the params file) and
``sim`` (the simulated rig's regulator and gauge).

- configure: opens the device, vents it and checks that every channel answers (one line and a
  failed transition otherwise);
- activate: applies /softcath/pressure_cmd (std_msgs/Float64MultiArray, Pa; each value clamped to
  [0, max_pressure], a wrong count or non-finite value refused) and publishes every new reading on
  /softcath/pressure_measured/ch<i> (sensor_msgs/FluidPressure: its message says absolute pressure;
  here, as throughout the rig contract, ``fluid_pressure`` is the *gauge* pressure in Pa), stamped
  when it was read from the device;
- vents on command timeout, on deactivate, cleanup, SIGINT/SIGTERM, and when the device gives no
  valid reading for ``silence_timeout`` (0.4 s): ERROR on /diagnostics at once, latched until
  deactivated;
- once configured, /softcath/bench/rig (std_msgs/String, transient local): JSON naming the backend
  and device, ``simulated`` true for the sim backend (bench_node records it).

``autostart`` (default true) configures and activates at start-up (a configure fault then ends
the node with exit code 2); with false a lifecycle manager drives it.
"""
from __future__ import annotations

import json
import sys
import time
from functools import partial

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64MultiArray, String

from .. import topics
from ..bench.hardware.devices import ModbusRegulator, RegisterMap, SerialLines, SimRegulator
from ..bench.hardware.regulator import Regulator
from ..core.design import load_design
from ..core.errors import SoftcathError
from .device_node import DeviceNode
from .diagnostics import ThrottledLog, diagnostic_status, publish_statuses
from .parameters import declare
from .executors import take_waiting
from .runtime import run_node

BACKENDS = ("serial", "modbus", "sim")


class RegulatorNode(DeviceNode):

    def __init__(self, **node_options):
        super().__init__(topics.REGULATOR_NODE, **node_options)
        self._log = ThrottledLog(self.get_logger(), 2.0)
        p = partial(declare, self)
        design = load_design(p("design", "implemented_5mm", "design file or shipped design name (channels, max_pressure)"))
        self.n = design.n_channels
        self.design_name = design.name
        self.backend = p("backend", "sim", "serial, modbus or sim", choices=BACKENDS)
        self.max_pressure = p("max_pressure", 0.0, "clamp every setpoint to this, Pa (0: the design's; never above it)",
                              minimum=0.0, maximum=design.max_pressure) or design.max_pressure
        self.rate_hz = p("rate_hz", 50.0, "device polls and setpoint updates per second", minimum=20.0, maximum=1000.0)
        self.command_timeout = p("command_timeout", 0.5, "no pressure command for this long (s): vent",
                                 minimum=0.01, maximum=60.0)
        self.declare_checks("vent, ERROR", "every channel must answer")
        self.max_rate = p("max_rate", 1e9, "setpoint rate limit, Pa/s (1e9: none); venting is immediate", minimum=1.0, maximum=1e9)
        reading_max = p("reading_max", 0.0, "a reading above this (Pa) is refused (0: twice max_pressure)",
                        minimum=0.0, maximum=1e8) or 2.0 * self.max_pressure
        self.reading_range = (p("reading_min", -20000.0, "a reading below this (Pa) is refused", minimum=-1e6,
                                maximum=0.0), reading_max)
        self.variance = p("pressure_variance", 0.0, "the gauge's variance published with each reading, Pa^2 (0: unknown)",
                          minimum=0.0, maximum=1e12)
        self.declare_serial("/dev/ttyACM0", note="serial: ")
        self.modbus = dict(
            host=p("modbus_host", "192.168.0.10", "modbus: the device's address"),
            port=p("modbus_port", 502, "modbus: TCP port", minimum=1, maximum=65535),
            timeout=p("modbus_timeout", 0.05, "modbus: answer timeout per request, s (a silent device is "
                      "declared within silence_timeout + this)", minimum=0.005, maximum=0.1))
        self.registers = dict(
            setpoints=p("setpoint_registers", list(range(self.n)), "modbus: holding register of each channel's setpoint"),
            readings=p("reading_registers", list(range(100, 100 + self.n)), "modbus: register of each channel's reading"),
            setpoint_pa_per_count=p("setpoint_pa_per_count", 100.0, "modbus: Pa per setpoint count", minimum=1e-6,
                                    maximum=1e6),
            reading_pa_per_count=p("reading_pa_per_count", 100.0, "modbus: Pa per reading count", minimum=1e-6,
                                   maximum=1e6),
            reading_offset_pa=p("reading_offset_pa", 0.0, "modbus: Pa added to each scaled reading", minimum=-1e6,
                                maximum=1e6),
            reading_kind=p("reading_kind", "input", "modbus: readings in input or holding registers",
                           choices=("input", "holding")),
            signed=p("reading_signed", False, "modbus: readings are two's complement"),
            unit=p("modbus_unit", 1, "modbus: device (slave) id", minimum=0, maximum=247))
        self.seed = p("seed", -1, "sim: noise seed (-1: fresh)", minimum=-1, maximum=2**32 - 1)
        self.ignored = 0            # commands while not active
        self._command_sub = self.create_subscription(Float64MultiArray, topics.PRESSURE_CMD, self.on_command, 100)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_rig = self.create_publisher(String, topics.BENCH_RIG, latched)
        self.start()

    def _device(self):
        low, high = self.reading_range
        if self.backend == "serial":
            return SerialLines(self.port, self.baud, "P", self.n, low, high)
        if self.backend == "modbus":
            regs = {**self.registers, "setpoints": tuple(self.registers["setpoints"]),
                    "readings": tuple(self.registers["readings"])}
            return ModbusRegulator(self.modbus["host"], self.modbus["port"], RegisterMap(**regs), self.n, low, high,
                                   timeout=self.modbus["timeout"])
        return SimRegulator(self.design_name, time.monotonic, seed=self.seed)

    def make_core(self) -> Regulator:
        return Regulator(self._device(), self.n, self.max_pressure, time.monotonic,
                         command_timeout=self.command_timeout, silence_timeout=self.silence_timeout,
                         check_timeout=self.check_timeout, max_rate=self.max_rate)

    def make_publishers(self) -> list:
        # the recording says what the pressures came from (bench_node keeps it; `simulated` for the sim backend)
        self.pub_rig.publish(String(data=json.dumps({
            "simulated": self.backend == "sim", "node": self.get_name(), "backend": self.backend,
            "device": self.core.device.name, "design": self.design_name, "max_pressure": self.max_pressure,
            "rate_hz": self.rate_hz})))
        return [self.create_lifecycle_publisher(FluidPressure, topics.pressure_measured_topic(c), 10)
                for c in range(self.n)]

    # -- streaming ----------------------------------------------------------------------------------
    def on_command(self, msg) -> None:
        arrived = time.monotonic()
        waiting = take_waiting(self._command_sub)
        if waiting:
            msg, arrived = waiting[-1]
        if self.core is None or self.core.state != "active":
            self.ignored += 1
            return
        status = self.core.command(list(msg.data), arrived)
        if status in ("rejected", "clamped"):
            self._log.warning(status, f"pressure command {status}: {self.core.counters.last_command_problem}")

    def tick(self) -> None:
        readings = self.core.tick()
        stamp = self.get_clock().now().to_msg()     # when they were read from the device
        for r in readings:
            m = FluidPressure(fluid_pressure=r.value, variance=self.variance)
            m.header.stamp, m.header.frame_id = stamp, topics.FRAME_ID
            self.pubs[r.channel].publish(m)

    def diagnostics(self) -> None:
        reg = self.core
        c = reg.counters if reg is not None else None
        level, message = self.level_and_message([] if c is None else [
            c.refused and f"{c.refused} device line(s) refused, last {c.last_refused}",
            c.device_errors and f"device error: {c.last_device_error}",
            c.rejected and f"{c.rejected} command(s) rejected: {c.last_command_problem}"])
        values = [("state", self.state_name), ("backend", self.backend), ("ignored_commands", self.ignored)]
        if c is not None:
            values += [(k, getattr(c, k)) for k in ("readings", "superseded", "refused", "device_errors", "commands",
                                                    "clamped", "rejected", "stale", "timeouts")]
            values += [("setpoints_pa", " ".join(f"{v:.0f}" for v in reg.last_sent))]
        publish_statuses(self, self.pub_diag, diagnostic_status(
            level, topics.REGULATOR_NODE, message, values,
            hardware_id=reg.device.name if reg is not None else self.backend))


def main(args=None) -> int:
    return run_node(RegulatorNode, args, startup_errors=(SoftcathError, ValueError))


if __name__ == "__main__":
    sys.exit(main())
