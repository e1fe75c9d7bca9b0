"""Tabular bench data (CSV) into a bench recording (bench.session), for report and calibrate.

One row per reading. Columns (header names, any order; extra columns are ignored):

| column | meaning |
| --- | --- |
| `pressure_bar`, `pressure_kpa` or `pressure_pa` | the step's set pressure (one of them) |
| `reading` | the reading, in `unit` |
| `unit` | `deg` or `rad` (angle bench), `g`, `mN` or `N` (force bench, the untared scale reading) |
| `trial` | trial number, 1, 2, ... |
| `phase` | `loading` or `unloading` |
| `sample_length_mm` or `sample_length_m` | length of the sample the reading is of |
| `channel` (optional) | the pressurised channel, default 0 |
| `measured_pressure_bar`/`_kpa`/`_pa` (optional) | the gauge at the reading, default the set pressure |
| `sample` (optional) | sample name, default `<bench>_<length>mm` |

Consecutive rows with the same bench, sample, channel, trial, phase and pressure are one
step's readings. Times in the recording are the import's (1 ms apart, in file order), not
the measurement's. Every error names the file, the row (line number, header = 1) and the
column.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

from ..core.errors import SoftcathError
from ..core import units
from ..core.units import PA_PER_BAR
from .protocol import BenchSample, Step, protocol_from_dict
from .session import BenchSession, grams_to_newton

PRESSURE_UNITS = {u.lower(): pa for u, pa in units.PRESSURE_UNITS.items()}   # column suffixes: pressure_bar, _kpa, _pa
ANGLE_UNITS = {"deg": math.pi / 180.0, "rad": 1.0}
FORCE_UNITS = {"g": None, "mn": 1e-3, "n": 1.0}   # g: a mass on the scale, times standard gravity


class CsvImportError(SoftcathError):
    """A bad cell: ``FILE row R, column C: why``."""


def _cell_error(path, row: int, column: str, why: str) -> CsvImportError:
    return CsvImportError(f"{path} row {row}, column {column}: {why}")


def _unit_column(header: list[str], stem: str, units: dict, path, required: bool) -> tuple[str, float] | None:
    found = [(f"{stem}_{u}", f) for u, f in units.items() if f"{stem}_{u}" in header]
    if len(found) > 1:
        raise CsvImportError(f"{path} row 1: columns {[c for c, _ in found]} give the {stem} twice; keep one")
    if not found and required:
        raise CsvImportError(f"{path} row 1: no {stem} column; expected one of "
                           f"{[f'{stem}_{u}' for u in units]}")
    return found[0] if found else None


def _bench_reading(path, line_no: int, row: dict, unit: str, value: float) -> dict:
    """Which bench a reading is from (its unit) and the reading in SI, checked."""
    rec = {}
    if unit in ANGLE_UNITS:
        rec["bench"] = "angle"
        rec["angle_rad"] = value * ANGLE_UNITS[unit]
        if not 0.0 <= rec["angle_rad"] <= 2 * math.pi * (1 + 1e-12):
            raise _cell_error(path, line_no, "reading", f"angle {value:g} {unit} is outside 0-360 degrees")
    elif unit in FORCE_UNITS:
        rec["bench"] = "force"
        if value < 0:
            raise _cell_error(path, line_no, "reading", f"scale reading {value:g} {row['unit']} is negative "
                              "(the tare is the reading at 0 bar: give what the scale shows)")
        rec["force_n"] = grams_to_newton(value) if unit == "g" else value * FORCE_UNITS[unit]
    else:
        raise _cell_error(path, line_no, "unit", f"'{row['unit']}': expected deg, rad (angle) or g, mN, N (force)")
    return rec


def _trial_phase_channel(path, line_no: int, row: dict) -> dict:
    """A reading's trial (0-based), phase and channel, checked."""
    rec = {}
    try:
        trial = int(row["trial"])
    except ValueError:
        trial = 0
    if trial < 1:
        raise _cell_error(path, line_no, "trial", f"'{row['trial']}' is not a trial number 1, 2, ...")
    rec["trial"] = trial - 1
    phase = row["phase"].lower()
    if phase not in ("loading", "unloading"):
        raise _cell_error(path, line_no, "phase", f"'{row['phase']}': expected loading or unloading")
    rec["phase"] = phase
    channel = row.get("channel", "") or "0"
    if not channel.isdigit():
        raise _cell_error(path, line_no, "channel", f"'{channel}' is not a channel index 0, 1, ...")
    rec["channel"] = int(channel)
    return rec


def read_rows(path, max_pressure: float) -> list[dict]:
    """The CSV's readings, checked; each a dict (bench, sample, length_m, channel, trial (0-based),
    phase, pressure_pa, measured_pa, angle_rad or force_n, row)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise CsvImportError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise CsvImportError(f"{path}: not a CSV text file (not UTF-8 at byte {exc.start})") from None
    reader = csv.reader(text.splitlines())
    try:
        header = [h.strip().lower() for h in next(reader)]
    except StopIteration:
        raise CsvImportError(f"{path}: empty file (expected a header row)") from None
    for col in ("reading", "unit", "trial", "phase"):
        if col not in header:
            raise CsvImportError(f"{path} row 1: no '{col}' column (columns: {header})")
    p_col, p_scale = _unit_column(header, "pressure", PRESSURE_UNITS, path, True)
    l_col, l_scale = _unit_column(header, "sample_length", {"mm": 1e-3, "m": 1.0}, path, True)
    m_found = _unit_column(header, "measured_pressure", PRESSURE_UNITS, path, False)
    out = []
    for line_no, cells in enumerate(reader, start=2):
        if not any(c.strip() for c in cells):
            continue
        if len(cells) != len(header):
            raise CsvImportError(f"{path} row {line_no}: {len(cells)} cells, the header has {len(header)}")
        row = dict(zip(header, (c.strip() for c in cells)))

        def number(col: str, scale: float = 1.0) -> float:
            try:
                v = float(row[col])
            except ValueError:
                raise _cell_error(path, line_no, col, f"'{row[col]}' is not a number") from None
            if not math.isfinite(v):
                raise _cell_error(path, line_no, col, f"'{row[col]}' is not a finite number")
            return v * scale

        pressure = number(p_col, p_scale)
        if pressure < 0 or pressure > max_pressure * (1 + 1e-9):
            raise _cell_error(path, line_no, p_col, f"{row[p_col]} is outside [0, the design's max_pressure "
                              f"{max_pressure / PA_PER_BAR:g} bar]")
        measured = pressure
        if m_found and row[m_found[0]] != "":
            measured = number(*m_found)
            if measured < 0 or measured > max_pressure * (1 + 1e-9):
                raise _cell_error(path, line_no, m_found[0], f"{row[m_found[0]]} is outside [0, the design's "
                                  f"max_pressure {max_pressure / PA_PER_BAR:g} bar]")
        length = number(l_col, l_scale)
        if length <= 0:
            raise _cell_error(path, line_no, l_col, f"{row[l_col]} must be positive")
        unit = row["unit"].lower()
        value = number("reading")
        rec = {"row": line_no, "pressure_pa": pressure, "measured_pa": measured, "length_m": length}
        rec.update(_bench_reading(path, line_no, row, unit, value))
        rec.update(_trial_phase_channel(path, line_no, row))
        rec["sample"] = row.get("sample") or f"{rec['bench']}_{length * 1e3:g}mm"
        out.append(rec)
    if not out:
        raise CsvImportError(f"{path}: no readings below the header")
    return out


def _check_tare(path, rows: list[dict]) -> None:
    """The force analysis subtracts the reading at 0 bar (loading) of the same trial: it must exist."""
    for r in rows:
        if r["bench"] != "force":
            continue
        key = (r["sample"], r["channel"], r["trial"])
        if not any((q["sample"], q["channel"], q["trial"]) == key and q["bench"] == "force" and
                   q["pressure_pa"] == 0 and q["phase"] == "loading" for q in rows):
            raise _cell_error(path, r["row"], "pressure", f"force sample {r['sample']} trial {r['trial'] + 1} has "
                              "no loading reading at 0 bar, the tare its forces are taken from")


def recording_name(csv_path, name: str | None = None) -> str:
    """The recording folder an import writes: ``name``, or bench_imported_<the CSV's stem>."""
    return name or f"bench_imported_{Path(csv_path).stem}"


def import_csv(csv_path, design, output_dir, name: str | None = None) -> dict:
    """Write ``csv_path`` as a bench recording under ``output_dir``. Returns path and counts."""
    import time

    csv_path = Path(csv_path)
    rows = read_rows(csv_path, design.max_pressure)
    _check_tare(csv_path, rows)
    for r in rows:
        if r["channel"] >= design.n_channels:
            raise _cell_error(csv_path, r["row"], "channel", f"{r['channel']}: design {design.name} has "
                              f"{design.n_channels} channel(s)")
    # Steps: runs of consecutive rows with the same key, numbered in file order.
    steps: list[Step] = []
    per_step: list[list[dict]] = []
    last = None
    for r in rows:
        key = (r["bench"], r["sample"], r["length_m"], r["channel"], r["trial"], r["phase"], r["pressure_pa"])
        if key != last:
            p = [0.0] * design.n_channels
            p[r["channel"]] = r["pressure_pa"]
            steps.append(Step(len(steps), r["bench"], BenchSample(r["sample"], r["length_m"]), r["trial"],
                              r["phase"], f"channel {r['channel']}", r["pressure_pa"], tuple(p)))
            per_step.append([])
            last = key
        per_step[-1].append(r)
    benches = {}
    for s in steps:
        benches.setdefault(s.bench, {})[s.sample.name] = s.sample.length
    levels = sorted({s.level for s in steps})
    protocol = protocol_from_dict({
        "name": f"imported_{csv_path.stem}", "description": f"imported from {csv_path.name}",
        "design": design.name, "drive": "channels", "channels": sorted({r["channel"] for r in rows}),
        "staircase": {"levels": levels, "down": any(s.phase == "unloading" for s in steps)},
        "trials": max(s.trial for s in steps) + 1, "samples_per_step": max(len(x) for x in per_step),
        "benches": [{"kind": b, "samples": [{"name": n, "length": ln} for n, ln in samples.items()]}
                    for b, samples in benches.items()]})
    ticks = iter(range(time.time_ns(), 1 << 63, 1_000_000))  # 1 ms apart, in file order
    name = recording_name(csv_path, name)
    session = BenchSession(Path(output_dir) / name, protocol, design, steps,
                           rig={"kind": "import", "file": str(csv_path)}, clock=lambda: next(ticks))
    complete = False
    try:
        for step, readings in zip(steps, per_step):
            for r in readings:
                p = list(step.pressures)
                p[r["channel"]] = r["measured_pa"]
                session.reading(step, p, [r["angle_rad"] if step.bench == "angle" else r["force_n"]],
                                csv_row=r["row"])
        complete = True
    finally:
        session.close(complete, "imported" if complete else "import interrupted")
    return {"recording": str(session.path), "readings": len(rows), "steps": len(steps), "protocol": protocol}
