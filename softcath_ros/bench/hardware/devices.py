"""The device backends behind one interface, so the regulator and scale state machines do not care
what is on the other end:

- ``open()``: connect (a fault raises ``DeviceFault``, one line);
- ``send(pressures)`` / ``vent()``: the setpoints (already clamped by the caller) / all to zero;
- ``poll()``: everything the device said since the last call, as ``protocol.Reading``,
  ``DeviceError`` or ``Refused`` (a device that does not answer returns nothing);
- ``close()``.

``SerialLines`` speaks the line protocols of ``protocol`` (pyserial), ``ModbusRegulator`` reads
and writes holding/input registers (pymodbus, the map in the params file), ``SimRegulator`` is the
simulated rig's regulator and gauge (bench/sim_rig.py).
"""
from __future__ import annotations

import importlib
import inspect
from dataclasses import dataclass

import numpy as np

from ...core.errors import SoftcathError
from . import protocol

MAX_READ = 4096          # bytes taken from a serial port per poll: a flood cannot stall the loop


class DeviceFault(SoftcathError):
    """The device cannot be opened or used (one line, naming it)."""


def first_line(exc: Exception) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


class Connection:
    """The open/close the serial and Modbus backends share: ``open`` imports the backend's package
    (``module``; missing: one line naming the extra) and keeps what ``connect(module)`` returns (a fault
    there raises DeviceFault), ``close`` closes it once, quietly (the device may be gone)."""
    module = package = ""
    link = None
    fault = ""           # the last I/O error (the device then counts as silent)

    def connect(self, module):
        raise NotImplementedError

    def open(self) -> None:
        try:
            module = importlib.import_module(self.module)
        except ImportError:
            raise DeviceFault(f"the {self.name.split(':')[0]} backend needs {self.package}: "
                              "pip install 'softcath_ros[hardware]'") from None
        self.link = self.connect(module)

    def close(self) -> None:
        link, self.link = self.link, None
        if link is not None:
            try:
                link.close()
            except Exception:   # pyserial / pymodbus on a device that is gone
                pass


class SerialLines(Connection):
    """A serial device speaking a line protocol: readings tagged ``tag`` (``P`` or ``F``)."""
    module = package = "serial"

    def __init__(self, port: str, baud: int, tag: str, n_channels: int, low: float, high: float):
        self.port, self.baud, self.tag = port, int(baud), tag
        self.n_channels, self.low, self.high = n_channels, low, high
        self.lines = protocol.LineSplitter()

    @property
    def name(self) -> str:
        return f"serial:{self.port}"

    def connect(self, serial):
        try:
            return serial.Serial(self.port, self.baud, timeout=0, write_timeout=0.1)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceFault(f"cannot open serial port {self.port} at {self.baud} baud: {first_line(exc)}") from None

    def write(self, data: bytes) -> None:
        if self.link is None:
            return
        try:
            self.link.write(data)
        except Exception as exc:   # pyserial raises SerialException, SerialTimeoutException, OSError
            self.fault = f"write: {exc}"

    def send(self, pressures) -> None:
        self.write(b"".join(protocol.format_set(c, p) for c, p in enumerate(pressures)))

    def vent(self) -> None:
        self.write(protocol.VENT)

    def tare(self) -> None:
        self.write(protocol.TARE)

    def poll(self) -> list:
        if self.link is None:
            return []
        try:
            data = self.link.read(min(max(self.link.in_waiting, 1), MAX_READ))
        except Exception as exc:   # the port vanished (USB pulled): silent
            self.fault = f"read: {exc}"
            return []
        out = []
        for line in self.lines.feed(data):
            if line.strip():
                out.append(protocol.parse_line(line, self.tag, self.n_channels, self.low, self.high))
        return out


@dataclass(frozen=True)
class RegisterMap:
    """Where a Modbus regulator keeps its setpoints and readings, and their scaling (params file):
    a setpoint of p Pa is written as round(p / setpoint_pa_per_count) to holding register
    ``setpoints[ch]``; a reading is ``raw * reading_pa_per_count + reading_offset_pa`` from
    ``readings[ch]`` (input or holding registers; raw 16-bit, two's complement if ``signed``)."""
    setpoints: tuple[int, ...]
    readings: tuple[int, ...]
    setpoint_pa_per_count: float = 100.0       # e.g. 0..10 bar over 0..10000 counts
    reading_pa_per_count: float = 100.0
    reading_offset_pa: float = 0.0
    reading_kind: str = "input"                # "input" or "holding"
    signed: bool = False
    unit: int = 1                              # the Modbus device (slave) id

    def check(self, n_channels: int) -> None:
        for what, regs in (("setpoint", self.setpoints), ("reading", self.readings)):
            if len(regs) != n_channels:
                raise DeviceFault(f"modbus register map: {len(regs)} {what} register(s) for {n_channels} channels")
            if any(not 0 <= r <= 65535 for r in regs):
                raise DeviceFault(f"modbus register map: {what} registers {list(regs)} must lie in 0..65535")
        if self.reading_kind not in ("input", "holding"):
            raise DeviceFault(f"modbus register map: reading_kind {self.reading_kind!r} is not 'input' or 'holding'")
        if not (self.setpoint_pa_per_count > 0 and self.reading_pa_per_count > 0):
            raise DeviceFault("modbus register map: the Pa per count scales must be positive")

    def counts(self, pascal: float) -> int:
        return int(min(max(round(pascal / self.setpoint_pa_per_count), 0), 65535))

    def pascal(self, raw: int) -> float:
        if self.signed and raw >= 32768:
            raw -= 65536
        return raw * self.reading_pa_per_count + self.reading_offset_pa


class ModbusRegulator(Connection):
    """A proportional regulator or valve terminal on Modbus TCP (pymodbus' synchronous client)."""
    module, package = "pymodbus.client", "pymodbus"

    def __init__(self, host: str, port: int, registers: RegisterMap, n_channels: int, low: float, high: float,
                 timeout: float = 0.05):
        registers.check(n_channels)
        self.host, self.port, self.map = host, int(port), registers
        self.n_channels, self.low, self.high, self.timeout = n_channels, low, high, timeout
        self._unit_kw = "slave"

    @property
    def name(self) -> str:
        return f"modbus:{self.host}:{self.port}/{self.map.unit}"

    def connect(self, pymodbus_client):
        client = pymodbus_client.ModbusTcpClient(self.host, port=self.port, timeout=self.timeout, retries=0)
        params = inspect.signature(client.read_holding_registers).parameters
        self._unit_kw = "device_id" if "device_id" in params else "slave"   # (pymodbus >= 3.10 renamed it)
        if not client.connect():
            client.close()
            raise DeviceFault(f"cannot connect to Modbus TCP {self.host}:{self.port}")
        return client

    def _call(self, method: str, *args, **kw):
        """The response, or None (no answer, a Modbus exception, a closed connection)."""
        if self.link is None:
            return None
        try:
            response = getattr(self.link, method)(*args, **{self._unit_kw: self.map.unit}, **kw)
        except Exception as exc:   # pymodbus raises ModbusException / ConnectionException / OSError
            self.fault = f"{method}: {first_line(exc)}"
            return None
        if response is None or response.isError():
            self.fault = f"{method}: {response}"
            return None
        return response

    def send(self, pressures) -> None:
        for reg, p in zip(self.map.setpoints, pressures):
            self._call("write_register", reg, self.map.counts(float(p)))

    def vent(self) -> None:
        self.send(np.zeros(self.n_channels))

    def poll(self) -> list:
        method = "read_input_registers" if self.map.reading_kind == "input" else "read_holding_registers"
        out = []
        for ch, reg in enumerate(self.map.readings):
            r = self._call(method, reg, count=1)
            if r is None:
                return out      # the device stopped answering mid-poll: what came so far
            raw = int(r.registers[0])
            out.append(protocol.check_reading(ch, self.map.pascal(raw), self.n_channels, self.low, self.high,
                                              f"register {reg} = {raw}"))
        return out


class SimRegulator:
    """The simulated rig's pressure half: its regulator (first-order lag) and gauge (bias and noise),
    advanced by the injected clock between polls."""

    def __init__(self, design_name: str, clock, seed: int = -1):
        self.design_name, self.clock, self.seed = design_name, clock, seed
        self.rig = None
        self.command = None
        self._t = None

    @property
    def name(self) -> str:
        return "simulated"

    def open(self) -> None:
        from ...core.design import load_design
        from ..sim_rig import FRESH_SEED, RigParams, SimulatedRig, truth_model

        design = load_design(self.design_name)
        params = RigParams(seed=self.seed if self.seed >= 0 else FRESH_SEED)
        self.rig = SimulatedRig(truth_model("surrogate", design, params), params)
        self.command = np.zeros(design.n_channels)
        self._t = self.clock()

    def send(self, pressures) -> None:
        self.command = np.asarray(pressures, dtype=float).copy()

    def vent(self) -> None:
        self.command = np.zeros_like(self.command)

    def poll(self) -> list:
        now = self.clock()
        self.rig.advance(min(now - self._t, 0.5), self.command)
        self._t = now
        gauge = self.rig.read().pressures
        return [protocol.Reading(c, float(p)) for c, p in enumerate(gauge)]

    def close(self) -> None:
        self.rig = None
