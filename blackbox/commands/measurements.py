"""``blackbox measurements READINGS --channels CHANNELS.csv --study STUDY``: rig readings become
the study's ``measurements.csv`` (docs/measurements.md).

A test rig writes channels, not displacements: each instrument reads in its own units, from its
own zero, mounted one way or the other, and every load step is scanned several times. Two files
say it all:

* the **channel map** (``channel,grid,component,sign,gain,reference_grid,units[,accuracy]``):
  which DOF each channel measures (in the grid's displacement system), ``sign`` (+1 or -1: the
  instrument reads along or against the component), ``gain`` (study units per reading unit, e.g.
  0.001 for a displacement in mm in a study in m, or a calibration factor in m/V), an optional
  ``reference_grid`` (the instrument measures relative to that grid: a transducer between two
  points), ``units`` (of the readings: a length unit on a translation, an angle on a rotation, or
  a raw unit such as V), and an optional ``accuracy`` (+- bound of a reading's error, reading
  units, from the instrument's data sheet);
* the **readings** (``case,<channel>,<channel>,...``), one row per scan, in the order taken: a row
  labelled ``zero`` is a scan of the unloaded structure, any other label is a load case of the
  study's ``loads.csv``. Consecutive rows with one label are repeated scans of one state.

Each step is referred to the zero block read last before it (the rig's drift between zeros is
taken out). For a channel ``c``, the value of case ``L`` is

    u = sign * gain * (mean of L's scans - mean of the zero block before them)

and its standard deviation ``sigma = |gain| s sqrt(1/n + 1/n0)`` (``n`` scans of the step, ``n0``
of its zero), with ``s`` the channel's scatter pooled over every block of two or more scans, zero
blocks included (:func:`blackbox.noise.pooled_scatter`); a declared ``accuracy`` adds
``(|gain| a / sqrt 3)^2`` (GUM type B, :mod:`blackbox.noise`). A channel never scanned twice in a
row has no scatter: its rows leave sigma blank for the study to estimate (declared accuracy or
the fit).
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from blackbox.errors import StudyError
from blackbox.noise import RECTANGULAR, pooled_scatter, sigma_interval
from blackbox.study import Study, load_study
from solver_adapters import tables
from solver_adapters.tables import TableFormatError

__all__ = ["Channel", "Step", "MeasurementsImport", "read_channels", "read_readings", "run", "ZERO"]

ZERO = "zero"
"""The label of a scan of the unloaded structure in the readings file."""

CHANNEL_HEADER = ("channel", "grid", "component", "sign", "gain", "reference_grid", "units")
LENGTH_UNITS = {"m", "mm", "cm", "um", "µm", "μm", "micron", "in", "inch", "ft", "nm"}
ANGLE_UNITS = {"rad", "mrad", "urad", "µrad", "μrad", "deg", "degree", "degrees", "°", "arcsec", "arcmin"}


@dataclass(frozen=True)
class Channel:
    """One instrument of the channel map (line ``line`` of the file)."""
    name: str
    grid: int
    component: int
    sign: float
    gain: float
    reference: int | None
    units: str
    accuracy: float | None
    line: int

    @property
    def key(self) -> tuple[int, int, int]:
        return (self.grid, self.component, self.reference or 0)


@dataclass
class Step:
    """A block of consecutive scans with one label: rows (line numbers) and, per channel, the
    readings (blank cells left out) and the zero block it is referred to."""
    label: str
    lines: list[int]
    readings: dict[str, list[float]] = field(default_factory=dict)
    zero: "Step | None" = None


def _located(fn):
    def wrapped(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except TableFormatError as exc:
            raise StudyError(exc.message, file=exc.file, line=exc.line, column=exc.column) from None
    return wrapped


@_located
def read_channels(path: Path, study: Study) -> list[Channel]:
    """The channel map, every row checked against the study's deck (located errors)."""
    path = Path(path)
    grids = set(study.deck.grids)
    out: list[Channel] = []
    names: dict[str, int] = {}
    dofs: dict[tuple[int, int, int], tuple[str, int]] = {}
    for line, rec in tables.rows(path, CHANNEL_HEADER, ("accuracy",)):
        name = rec["channel"]
        if not name:
            raise StudyError("empty channel name", file=str(path), line=line, column="channel")
        if name in names:
            raise StudyError(f"channel {name!r} is mapped twice (first on line {names[name]})", file=str(path),
                             line=line, column="channel")
        if name.lower() == ZERO or name.lower() == "case":
            raise StudyError(f"{name!r} cannot name a channel (it labels the readings' first column or a zero scan)",
                             file=str(path), line=line, column="channel")
        g = tables.parse_int(rec["grid"], path, line, "grid")
        if g not in grids:
            raise StudyError(f"grid {g} is not in the study's deck", file=str(path), line=line, column="grid")
        c = tables.parse_int(rec["component"], path, line, "component")
        if not 1 <= c <= 6:
            raise StudyError(f"component must be 1..6, got {c}", file=str(path), line=line, column="component")
        sign = tables.parse_float(rec["sign"], path, line, "sign")
        if sign not in (1.0, -1.0):
            raise StudyError(f"sign must be 1 or -1 (the instrument reads along or against the component), got "
                             f"{rec['sign']!r}", file=str(path), line=line, column="sign")
        gain = tables.parse_float(rec["gain"], path, line, "gain")
        if gain == 0.0:
            raise StudyError("gain must not be 0 (study units per reading unit)", file=str(path), line=line,
                             column="gain")
        ref = None
        if rec["reference_grid"]:
            ref = tables.parse_int(rec["reference_grid"], path, line, "reference_grid")
            if ref not in grids:
                raise StudyError(f"reference grid {ref} is not in the study's deck", file=str(path), line=line,
                                 column="reference_grid")
            if ref == g:
                raise StudyError("a channel cannot measure a grid relative to itself", file=str(path), line=line,
                                 column="reference_grid")
        units = rec["units"]
        u = units.strip().lower()
        if (c <= 3 and u in ANGLE_UNITS) or (c >= 4 and u in LENGTH_UNITS):
            kind = "translation" if c <= 3 else "rotation"
            raise StudyError(f"units {units!r} cannot read component {c} (a {kind}): the channel is mapped to the "
                             f"wrong component or its units are wrong", file=str(path), line=line, column="units")
        acc = None
        if rec.get("accuracy"):
            acc = tables.parse_float(rec["accuracy"], path, line, "accuracy")
            if acc <= 0:
                raise StudyError(f"accuracy must be > 0 (+- bound, reading units) or blank, got {rec['accuracy']!r}",
                                 file=str(path), line=line, column="accuracy")
        ch = Channel(name, g, c, sign, gain, ref, units, acc, line)
        if ch.key in dofs:
            first, fl = dofs[ch.key]
            raise StudyError(f"channel {name!r} measures grid {g} component {c}"
                             + (f" relative to grid {ref}" if ref else "")
                             + f" as channel {first!r} on line {fl} does: two instruments on one DOF are one "
                               "channel's repeats, or one of them is mapped to the wrong DOF", file=str(path),
                             line=line, column="grid")
        dofs[ch.key] = (name, line)
        names[name] = line
        out.append(ch)
    if not out:
        raise StudyError("no channel rows", file=str(path))
    return out


@_located
def read_readings(path: Path, channels: list[Channel], cases: set[str], channels_path: Path) -> list[Step]:
    """The readings as blocks of scans, each load step's block tied to its zero block."""
    path = Path(path)
    reader = csv.reader(io.StringIO(tables.read_text(path), newline=""))
    header = next(reader, None)
    if not header or header[0].strip() != "case":
        raise StudyError(f"header must be case,<channel>,<channel>,..., got {','.join(header or [])!r}",
                         file=str(path), line=1)
    cols = [h.strip() for h in header[1:]]
    mapped = {c.name: c for c in channels}
    seen: dict[str, int] = {}
    for j, name in enumerate(cols):
        if name in seen:
            raise StudyError(f"channel {name!r} has two columns", file=str(path), line=1, column=name)
        seen[name] = j
        if name not in mapped:
            raise StudyError(f"channel {name!r} is not in the channel map {Path(channels_path).name} (unmapped: "
                             "say which grid and component it reads, or drop the column)", file=str(path), line=1,
                             column=name)
    for c in channels:
        if c.name not in seen:
            raise StudyError(f"channel {c.name!r} has no column in the readings {path.name}", file=str(channels_path),
                             line=c.line, column="channel")
    if ZERO in cases:
        raise StudyError(f"a load case is labelled {ZERO!r}, which the readings reserve for a scan of the "
                         "unloaded structure; rename the case in loads.csv", file=str(path))
    steps: list[Step] = []
    last_zero: Step | None = None
    for row in reader:
        line = reader.line_num
        if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
            continue
        if len(row) != len(header):
            raise StudyError(f"expected {len(header)} columns, got {len(row)}", file=str(path), line=line)
        label = row[0].strip()
        is_zero = label.lower() == ZERO
        if not is_zero and label not in cases:
            raise StudyError(f"{label!r} is neither {ZERO!r} (a scan of the unloaded structure) nor a load case "
                             "of the study's loads.csv", file=str(path), line=line, column="case")
        label = ZERO if is_zero else label
        if not steps or steps[-1].label != label:          # a new block of scans
            if not is_zero and last_zero is None:
                raise StudyError(f"case {label!r} is read before any {ZERO!r} scan: the rig's zero (the unloaded "
                                 "structure) must be read first", file=str(path), line=line, column="case")
            steps.append(Step(label, [], {}, None if is_zero else last_zero))
            if is_zero:
                last_zero = steps[-1]
        step = steps[-1]
        step.lines.append(line)
        for name, text in zip(cols, row[1:]):
            text = text.strip()
            if not text:
                continue
            try:
                v = float(text)
            except ValueError:
                raise StudyError(f"expected a number (or blank: no reading), got {text!r}", file=str(path),
                                 line=line, column=name) from None
            if not math.isfinite(v):
                raise StudyError(f"reading must be finite, got {text!r}", file=str(path), line=line, column=name)
            step.readings.setdefault(name, []).append(v)
    if not any(s.label != ZERO for s in steps):
        raise StudyError("no scan of a load case (only zero scans, or no rows)", file=str(path))
    return steps


@dataclass(frozen=True, eq=False)
class MeasurementsImport:
    """The readings turned into measurement rows, with each channel's scatter."""
    study: Study
    readings_path: Path
    channels_path: Path
    channels: tuple[Channel, ...]
    rows: tuple[tuple[str, int, int, float, float, int | None, int, int], ...]
    """(case, grid, component, value, sigma or nan, reference grid, scans, zero scans)"""
    scatter: dict[str, tuple[float, int]]          # channel -> (s in reading units, dof)
    zero_offsets: dict[str, float]                 # channel -> mean of its first zero block (reading units)
    notes: tuple[str, ...]
    confidence: float = 0.95
    command: str = "measurements"

    @property
    def has_reference(self) -> bool:
        return any(r[5] is not None for r in self.rows)

    def csv_text(self) -> str:
        head = "case,grid,component,value,sigma" + (",reference_grid" if self.has_reference else "")
        lines = [head]
        for case, g, c, v, s, ref, _, _ in self.rows:
            sig = repr(float(s)) if math.isfinite(s) else ""
            lines.append(f"{case},{g},{c},{float(v)!r},{sig}" + (f",{ref or ''}" if self.has_reference else ""))
        return "\n".join(lines) + "\n"

    def to_json(self) -> dict:
        chans = []
        for c in self.channels:
            s, nu = self.scatter[c.name]
            lo, hi = sigma_interval(s, nu, self.confidence) if nu else (math.nan, math.nan)
            chans.append({"channel": c.name, "grid": c.grid, "component": c.component, "sign": c.sign,
                          "gain": c.gain, "reference_grid": c.reference, "units": c.units, "accuracy": c.accuracy,
                          "scatter": _num(s), "scatter_dof": nu, "scatter_ci": [_num(lo), _num(hi)],
                          "sigma_one_reading_study_units": _num(abs(c.gain) * s) if nu else None,
                          "zero_offset": _num(self.zero_offsets.get(c.name, math.nan))})
        return {"study": self.study.name, "readings": str(self.readings_path), "channel_map": str(self.channels_path),
                "rows": len(self.rows), "rows_without_sigma": sum(1 for r in self.rows if not math.isfinite(r[4])),
                "channels": chans, "notes": list(self.notes), "confidence": self.confidence}

    def report(self) -> str:
        pct = f"{100 * self.confidence:g}%"
        out = [f"# Measurements of {self.study.name} from rig readings", "",
               f"Readings `{self.readings_path.name}`, channel map `{self.channels_path.name}`: {len(self.rows)} "
               f"measurement rows over {len({r[0] for r in self.rows})} load case(s) and {len(self.channels)} "
               "channel(s). Each step is referred to the zero scans read last before it; sigma = |gain| s "
               "sqrt(1/n + 1/n0) with s the channel's scatter pooled over its repeated scans (zero scans "
               "included), plus the declared accuracy (+- a, rectangular) where given.", "",
               f"| channel | grid | component | sign | gain | units | scatter s (reading units) | dof | {pct} "
               "interval | sigma of one reading (study units) | zero offset |",
               "|---|---|---|---|---|---|---|---|---|---|---|"]
        for c in self.channels:
            s, nu = self.scatter[c.name]
            lo, hi = sigma_interval(s, nu, self.confidence) if nu else (math.nan, math.nan)
            out.append(f"| {c.name} | {c.grid}{f' (rel. {c.reference})' if c.reference else ''} | {c.component} | "
                       f"{c.sign:+g} | {c.gain:g} | {c.units} | {_g(s)} | {nu} | [{_g(lo)}, {_g(hi)}] | "
                       f"{_g(abs(c.gain) * s) if nu else 'n/a'} | {_g(self.zero_offsets.get(c.name, math.nan))} |")
        scans = {}
        for case, *_, n, n0 in self.rows:
            scans.setdefault(case, (n, n0))
        out += ["", "| case | scans (per channel, most) | zero scans |", "|---|---|---|"]
        for case, (n, n0) in list(scans.items())[:60]:
            out.append(f"| {case} | {n} | {n0} |")
        if len(scans) > 60:
            out.append(f"| ... {len(scans) - 60} more | | |")
        if self.notes:
            out += ["", "## Notes", ""] + [f"- {n}" for n in self.notes]
        out += ["", f"Copy `measurements.csv` into the study folder ({self.study.root}) to use it: "
                    "`blackbox identify STUDY --out DIR`."]
        return "\n".join(out) + "\n"

    def write(self, out: Path) -> list[str]:
        out = Path(out)
        (out / "measurements.csv").write_text(self.csv_text())
        (out / "channels.json").write_text(json.dumps(self.to_json(), indent=2))
        (out / "report.md").write_text(self.report())
        return ["measurements.csv", "channels.json", "report.md"]


def _num(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _g(v: float) -> str:
    return f"{v:.4g}" if math.isfinite(v) else "n/a"


def run(readings: str | Path, channels: str | Path, study: Study | str | Path) -> MeasurementsImport:
    """Read the channel map and the readings (every error located), refer each step to its
    zero, pool each channel's scatter, and return the measurement rows (module docstring)."""
    study = study if isinstance(study, Study) else load_study(study)
    readings, channels = Path(readings), Path(channels)
    chans = read_channels(channels, study)
    steps = read_readings(readings, chans, set(study.loads.cases), channels)
    notes: list[str] = []
    scatter = {c.name: pooled_scatter([s.readings.get(c.name, []) for s in steps]) for c in chans}
    zero_offsets = {}
    for c in chans:
        z = next((s for s in steps if s.label == ZERO and s.readings.get(c.name)), None)
        if z is not None:
            zero_offsets[c.name] = float(np.mean(z.readings[c.name]))
    # per (case, channel): the blocks of the case, each with its zero
    order = list(dict.fromkeys(s.label for s in steps if s.label != ZERO))
    rows = []
    for case in order:
        blocks = [s for s in steps if s.label == case]
        for c in chans:
            pairs = []
            for b in blocks:
                r = b.readings.get(c.name, [])
                z = b.zero.readings.get(c.name, []) if b.zero is not None else []
                if r and z:
                    pairs.append((np.array(r), np.array(z)))
                elif r:
                    notes.append(f"channel {c.name!r}: the zero scans before case {case!r} (line {b.zero.lines[0]}) "
                                 f"have no reading of it; those scans of the case are left out")
            if not pairs:
                notes.append(f"channel {c.name!r} has no reading of case {case!r} (lines {blocks[0].lines[0]}-"
                             f"{blocks[-1].lines[-1]}): no row")
                continue
            n_tot = sum(len(r) for r, _ in pairs)
            raw = sum(float(np.sum(r - z.mean())) for r, z in pairs) / n_tot
            value = c.sign * c.gain * raw
            s, nu = scatter[c.name]
            if nu and s > 0.0:
                var = s * s * (1.0 / n_tot + sum((len(r) / n_tot) ** 2 / len(z) for r, z in pairs))
                if c.accuracy is not None:
                    var += (c.accuracy / RECTANGULAR) ** 2
                sigma = abs(c.gain) * math.sqrt(var)
            elif c.accuracy is not None:
                sigma = abs(c.gain) * c.accuracy / RECTANGULAR
            else:
                sigma = math.nan
            rows.append((case, c.grid, c.component, value, sigma, c.reference, n_tot,
                         max(len(z) for _, z in pairs)))
    lonely = [c.name for c in chans if not scatter[c.name][1] and c.accuracy is None]
    if lonely:
        notes.append(f"channel(s) {', '.join(lonely)} were never scanned twice in a row and declare no accuracy: "
                     "their rows leave sigma blank (the study's declared accuracy, or the fit, gives it)")
    zero_scatter = [c.name for c in chans if scatter[c.name][1] and scatter[c.name][0] == 0.0]
    if zero_scatter:
        notes.append(f"channel(s) {', '.join(zero_scatter)} repeat their readings exactly (scatter 0: the "
                     "instrument's resolution hides its noise): "
                     + ("their rows use the declared accuracy" if all(next(c for c in chans if c.name == n).accuracy
                                                                       for n in zero_scatter)
                        else "declare their accuracy in the channel map, else their rows leave sigma blank"))
    return MeasurementsImport(study, readings, channels, tuple(chans), tuple(rows), scatter, zero_offsets,
                              tuple(dict.fromkeys(notes)), study.config.identification.confidence)
