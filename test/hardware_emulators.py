"""Emulated devices for the hardware tests: a serial regulator and a serial scale on a
pseudo-terminal (the host opens the pty's name with pyserial, as a USB serial port), and a Modbus
TCP regulator (pymodbus server on 127.0.0.1, a free port). Each can be told to die, lie or flood.

Started (``start()``) a serial device runs in its own process and behaves as firmware does, for
the node tests (its own process: a busy test process cannot starve it into a silence the node
would rightly call a dead device); the pure tests drive the pty by hand (``say`` / ``heard``) so
that nothing depends on timing."""
from __future__ import annotations

import asyncio
import multiprocessing
import os
import socket
import time

MODES = ("ok", "dead", "nan", "range", "flood", "garbage")


class SharedMode:
    """``mode`` (one of MODES) in shared memory (``self._mode``), so the device's process sees it."""

    @property
    def mode(self) -> str:
        return MODES[self._mode.value]

    @mode.setter
    def mode(self, value: str) -> None:
        self._mode.value = MODES.index(value)


class PtyDevice(SharedMode):
    """The device end of a pseudo-terminal; ``port`` is what the host opens."""

    def __init__(self):
        self.master, slave = os.openpty()
        self.port = os.ttyname(slave)
        self._slave = slave          # kept open so the line stays up while the host reopens it
        import tty

        tty.setraw(slave)
        os.set_blocking(self.master, False)
        self._pending = b""
        self._outbox = b""
        self._lines: list[str] = []  # every line the host sent
        self._context = multiprocessing.get_context("fork")
        self._mode = self._context.Value("i", 0)          # index into MODES, shared with the process
        # lines the process heard (a pipe: a line is readable here once the process has sent it)
        self._heard_in, self._heard = self._context.Pipe(duplex=False)
        self._stop = self._context.Event()
        self._process = None
        self._in_process = False

    @property
    def lines(self) -> list[str]:
        """Every line the host sent so far."""
        while self._heard_in.poll():
            self._lines.append(self._heard_in.recv())
        return self._lines

    def say(self, text: str) -> None:
        """Queue ``text`` and write what the pty takes now (``flush`` writes the rest later); a host
        that does not read loses the oldest bytes beyond 64 kB, as a device's buffer would."""
        self._outbox = (self._outbox + text.encode("latin-1"))[-65536:]
        self.flush()

    def flush(self) -> int:
        """Write what the pty takes of the queue; the bytes still waiting."""
        while self._outbox:
            try:
                n = os.write(self.master, self._outbox[:4096])
            except (BlockingIOError, OSError):
                break
            self._outbox = self._outbox[n:]
        return len(self._outbox)

    def heard(self) -> list[str]:
        """Read what the host sent since the last call (complete lines)."""
        new = []
        while True:
            try:
                data = os.read(self.master, 65536)
            except (BlockingIOError, OSError):
                break
            if not data:
                break
            self._pending += data
        *done, self._pending = self._pending.split(b"\n")
        for raw in done:
            line = raw.decode("ascii", errors="replace").strip()
            new.append(line)
            if not self._in_process:     # (the process sends them to the parent instead)
                self._lines.append(line)
        return new

    def start(self, period: float = 0.02):
        self._process = self._context.Process(target=self._run, args=(period,), daemon=True)
        self._process.start()
        return self

    def _run(self, period):
        self._in_process = True
        while not self._stop.is_set():
            for line in self.heard():
                self._heard.send(line)
                self.on_line(line)
            if self.mode != "dead":
                try:
                    self.say(self.report())
                except OSError:
                    pass
            time.sleep(period)

    def close(self):
        self._stop.set()
        if self._process is not None:
            self._process.join(timeout=5)
            if self._process.is_alive():
                self._process.kill()
            self._process = None
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


class SerialRegulatorEmulator(PtyDevice):
    """Firmware of firmware/regulator: follows SET at once, vents on VENT, reports ``P`` lines."""

    def __init__(self, n_channels: int = 1):
        super().__init__()
        self.setpoints = [0.0] * n_channels

    def on_line(self, line):
        parts = line.split()
        if parts == ["VENT"]:
            self.setpoints = [0.0] * len(self.setpoints)
        elif len(parts) == 3 and parts[0] == "SET":
            self.setpoints[int(parts[1])] = float(parts[2])

    def report(self) -> str:
        if self.mode == "nan":
            return "".join(f"P {c} nan\n" for c in range(len(self.setpoints)))
        if self.mode == "range":
            return "".join(f"P {c} 99000000\n" for c in range(len(self.setpoints)))
        if self.mode == "garbage":
            return "\x00\xff" * 500
        lines = "".join(f"P {c} {p:.0f}\n" for c, p in enumerate(self.setpoints))
        return lines * (200 if self.mode == "flood" else 1)


class SerialScaleEmulator(PtyDevice):
    """Firmware of firmware/scale: ``F`` lines of ``load - tare``; ``TARE`` zeroes at the present load."""

    def __init__(self, load: float = 0.0):
        super().__init__()
        self.load, self.offset = load, 0.0

    @property
    def tares(self) -> int:
        return self.lines.count("TARE")

    def on_line(self, line):
        if line == "TARE":
            self.offset = self.load

    def report(self) -> str:
        if self.mode == "nan":
            return "F nan\n"
        return f"F {self.load - self.offset:.5f}\n"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ModbusRegulatorEmulator(SharedMode):
    """A valve terminal on Modbus TCP, in its own (spawned: the test process runs DDS threads)
    process: holding registers 0.. are the setpoints (counts), input registers 100.. the readings,
    which follow the setpoints (``mode`` 'range': 65535 counts, a reading beyond any sensor).
    ``stop()`` kills it (connections refused from then on)."""

    def __init__(self, n_channels: int = 1, reading_base: int = 100, unit: int = 1, port: int | None = None):
        self.n, self.base, self.unit = n_channels, reading_base, unit
        self.port = port or free_port()
        context = multiprocessing.get_context("spawn")
        self._mode = context.Value("i", 0)
        self._writes_in, writes = context.Pipe(duplex=False)   # (sent before the device answers)
        self._writes_seen: list[tuple[int, int]] = []
        self._process = context.Process(target=_serve_modbus, daemon=True,
                                        args=(n_channels, reading_base, unit, self.port, self._mode, writes))
        self._process.start()
        self._wait_listening()

    @property
    def writes(self) -> list[tuple[int, int]]:
        """(register, counts) the host wrote, in order."""
        while self._writes_in.poll():
            self._writes_seen.append(self._writes_in.recv())
        return self._writes_seen

    def _wait_listening(self, timeout: float = 60.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.5).close()
                return
            except OSError:
                if not self._process.is_alive():
                    break
                time.sleep(0.02)
        raise RuntimeError(f"the Modbus emulator did not start listening (exit code {self._process.exitcode})")

    def stop(self):
        """The device dies (power off): its process is killed."""
        if self._process.is_alive():
            self._process.kill()
        self._process.join(timeout=10)


def _serve_modbus(n, base, unit, port, mode, writes):
    from pymodbus.server import ModbusTcpServer
    from pymodbus.simulator import DataType, SimData, SimDevice

    async def action(function_code, start_address, address, count, registers, set_values):
        if set_values is not None:
            for i, v in enumerate(set_values):
                writes.send((address + i, int(v)))
            return None
        for c in range(n):
            registers[base + c - start_address] = 65535 if MODES[mode.value] == "range" else registers[c - start_address]
        return None

    device = SimDevice(id=unit, simdata=[SimData(0, count=base + n, values=0, datatype=DataType.REGISTERS)],
                       action=action)

    async def serve():   # (pymodbus builds its transport on the running loop)
        await ModbusTcpServer(device, address=("127.0.0.1", port)).serve_forever()

    asyncio.run(serve())
