"""The manual bench: the operator sets each protocol step's pressure and types the reading.

Readings as the published bench took them: the bending angle in degrees off the graph
paper (angle bench) and the scale in grams (force bench; the analysis subtracts the reading
at 0 bar of the same trial, the tare, so type what the scale shows). A reading may carry the
gauge pressure it was taken at, ``READING @ BAR`` (or with its unit, ``@ 15kPa``; default: the commanded pressure, and the
marker says so). Several readings of the step on one line, separated by spaces, are its
samples. Each entry is written and fsynced as it is made (bench.session), so Ctrl-C,
a closed terminal or a crash loses nothing entered.

At each prompt: a number, ``u`` (undo the last entry: that step is asked again), ``s``
(skip this step), ``q`` (stop here; the recording is finalised and marked incomplete),
``?`` (help). Text, a negative mass, an angle outside 0-360 degrees or a gauge pressure
above the design's max_pressure are refused with a message and asked again.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Callable

from ..core.errors import SoftcathError
from ..core.units import PA_PER_BAR, parse_pressure
from .protocol import Step
from .session import BenchSession, grams_to_newton

HELP = ("type the reading (angle bench: degrees 0-360; force bench: grams as the scale shows, "
        "tare at 0 bar; several readings of the step separated by spaces), optionally '@ BAR' with "
        "the gauge pressure; u = undo the last entry, "
        "s = skip this step, q = stop and save, ? = this help")


@dataclass
class Entry:
    """What the operator typed for a step: a value (deg or g), the gauge pressure (bar) or None."""
    kind: str                      # "reading" | "skip" | "undo" | "quit" | "help"
    values: tuple[float, ...] = ()  # one or more readings of the step
    gauge_bar: float | None = None


def parse_entry(text: str, bench: str, max_pressure: float) -> Entry | str:
    """One typed line -> an Entry, or the message saying why it is refused."""
    t = text.strip().lower()
    if t in ("u", "undo"):
        return Entry("undo")
    if t in ("s", "skip"):
        return Entry("skip")
    if t in ("q", "quit", "exit"):
        return Entry("quit")
    if t in ("?", "h", "help"):
        return Entry("help")
    if not t:
        return "empty entry: type the reading, or u / s / q (? for help)"
    reading, _, gauge = t.partition("@")
    unit = "degrees" if bench == "angle" else "grams"
    values = []
    for word in reading.replace(",", " ").split():
        value = _number(word)
        if value is None:
            return f"'{word}' is not a number of {unit} (or u / s / q; ? for help)"
        if bench == "angle" and not 0.0 <= value <= 360.0:
            return f"angle {value:g} deg is outside 0-360 degrees"
        if bench == "force" and value < 0:
            return f"mass {value:g} g is negative: the scale is tared at 0 bar, type what it shows"
        values.append(value)
    if not values:
        return "no reading before '@': type the reading, then '@ BAR'"
    gauge_bar = None
    if gauge.strip():
        try:   # bar unless it carries its unit (core/units.py: one rule for every pressure typed)
            gauge_bar = parse_pressure(gauge.strip(), "gauge pressure", unit="bar") / PA_PER_BAR
        except SoftcathError as exc:
            return f"{exc} (a number of bar)"
        if gauge_bar < 0 or gauge_bar * PA_PER_BAR > max_pressure * (1 + 1e-9):
            return (f"gauge pressure {gauge_bar:g} bar is outside [0, max_pressure "
                    f"{max_pressure / PA_PER_BAR:g} bar]: vent and set the step's pressure")
    return Entry("reading", tuple(values), gauge_bar)


def _number(text: str) -> float | None:
    try:
        v = float(text.strip())
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def describe_step(step: Step, n_steps: int) -> str:
    """What the operator must set up for ``step``."""
    set_to = ", ".join(f"channel {c} {p / PA_PER_BAR:.3f} bar" for c, p in enumerate(step.pressures))
    what = "angle [deg]" if step.bench == "angle" else "scale [g]"
    return (f"step {step.index + 1}/{n_steps}: {step.bench} bench, sample {step.sample.name} "
            f"({step.sample.length * 1e3:g} mm), trial {step.trial + 1}, {step.phase}: set {set_to}; "
            f"read the {what}")


class ManualBench:
    """Asks for every step in turn (``read_line`` returns '' at end of input) and writes ``session``."""

    def __init__(self, session: BenchSession, read_line: Callable[[], str] = sys.stdin.readline,
                 say: Callable[[str], None] = lambda s: print(s, flush=True),
                 prompt: Callable[[str], None] = lambda s: print(s, end="", flush=True)):
        self.session = session
        self.prompt = prompt
        self.steps = session.steps
        self.read_line = read_line
        self.say = say
        self.done: list[tuple[int, str]] = []     # (step index, "reading" | "skip"), in entry order
        self.refused = 0

    def run(self) -> str:
        """Runs until every step has an entry ("complete"), or the operator stops ("quit") or the
        input ends ("end of input"). The session is left open (the caller closes it)."""
        max_p = self.session.design.max_pressure
        i = 0
        n = len(self.steps)
        self.say(HELP)
        while i < n:
            step = self.steps[i]
            self.say(describe_step(step, n))
            while True:
                self.prompt(f"[{i + 1}/{n}] {'angle deg' if step.bench == 'angle' else 'scale g'}> ")
                line = self.read_line()
                if line == "":
                    return "end of input"
                entry = parse_entry(line, step.bench, max_p)
                if isinstance(entry, str):
                    self.refused += 1
                    self.say(f"refused: {entry}; asked again")
                    continue
                break
            if entry.kind == "help":
                self.say(HELP)
            elif entry.kind == "quit":
                return "quit"
            elif entry.kind == "undo":
                if not self.done:
                    self.say("nothing to undo")
                    continue
                j, what = self.done.pop()
                self.session.retract(self.steps[j])
                self.say(f"undone: step {j + 1} ({what}); asked again")
                i = j
            elif entry.kind == "skip":
                self.session.skip(step)
                self.done.append((i, "skip"))
                i += 1
            else:
                gauge = entry.gauge_bar
                measured = list(step.pressures) if gauge is None else self._gauge_pressures(step, gauge)
                source = "commanded" if gauge is None else "gauge"
                unit, convert = ("deg", math.radians) if step.bench == "angle" else ("g", grams_to_newton)
                self.session.reading(step, measured, [convert(v) for v in entry.values],
                                     typed=" ".join(f"{v:g}" for v in entry.values) + f" {unit}",
                                     pressure_source=source)
                self.done.append((i, "reading"))
                i += 1
        return "complete"

    @staticmethod
    def _gauge_pressures(step: Step, gauge_bar: float) -> list[float]:
        """The gauge reads the driven channel (the largest command); the others as commanded."""
        p = list(step.pressures)
        k = max(range(len(p)), key=lambda c: p[c])
        p[k] = gauge_bar * PA_PER_BAR
        return p


def run_manual_bench(protocol_name: str, design_name: str | None, model_name: str, output_dir,
                     read_line: Callable[[], str] = sys.stdin.readline,
                     say: Callable[[str], None] = lambda s: print(s, flush=True),
                     prompt: Callable[[str], None] = lambda s: print(s, end="", flush=True)) -> dict:
    """``softcath characterise --rig manual``: the protocol's steps asked at the terminal into a new
    recording under ``output_dir``. Returns the recording path, how the run ended and counts.
    The recording is finalised however the run ends (Ctrl-C included)."""
    from datetime import datetime
    from pathlib import Path

    from ..core.design import load_design
    from .protocol import expand_steps, load_protocol

    protocol = load_protocol(protocol_name)
    design = load_design(design_name or protocol.design or "implemented_5mm")
    allocator = None
    if protocol.drive == "direction":
        from ..core.allocation import Allocator
        from ..core.models import make_model
        allocator = Allocator(make_model(model_name, design))
    steps = expand_steps(protocol, design.n_channels, design.max_pressure, allocator)
    name = f"bench_{protocol.name}_manual_{datetime.now().strftime('%Y%m%d_%H%M%S')}"
    session = BenchSession(Path(output_dir) / name, protocol, design, steps,
                           rig={"kind": "manual", "angle": "graph paper, deg", "force": "scale, g"})
    bench = ManualBench(session, read_line, say, prompt)
    outcome = "interrupted"
    try:
        outcome = bench.run()
    finally:
        session.close(outcome == "complete", outcome)
    readings = sum(1 for _, what in bench.done if what == "reading")
    return {"recording": str(session.path), "design": design, "outcome": outcome, "n_steps": len(steps),
            "readings": readings, "skipped": sum(1 for _, what in bench.done if what == "skip"),
            "refused": bench.refused}
