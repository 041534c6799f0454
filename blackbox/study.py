"""Study folders (CONTRACT.md section 1): ``study.toml``, ``model.bdf``, ``loads.csv``,
``measurements.csv``. Everything is checked before any solver work, and every rejection names
the file, the line and the column.

This is wiring, not method: it may read the deck (to check grids and joint ties) and pick the
adapter; the method modules only ever see the adapter through ``solver_adapters.protocol``.
"""

from __future__ import annotations

import csv
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import scipy.sparse as sp
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from blackbox.errors import StudyError
from solver_adapters.deck import Deck
from solver_adapters.protocol import DofLabel, LoadMatrix


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SolverConfig(_Strict):
    adapter: str = "reference"
    deck: str = "model.bdf"
    timeout_s: float = Field(600.0, gt=0)
    command: list[str] | None = None
    dialect: str = "nastran"
    backend: Literal["auto", "superlu", "pardiso"] = "auto"   # auto: PARDISO from 2e4 DOFs if installed


class JointConfig(_Strict):
    name: str
    grids: list[int] = Field(min_length=2, max_length=12)
    model: Literal["simple", "complex"] = "simple"
    initial: float = Field(1.0e3, gt=0)
    deck_stiffness: float = Field(0.0, ge=0)
    rigid_pairs: list[tuple[int, int]] = []

    @field_validator("grids")
    @classmethod
    def _unique(cls, v: list[int]) -> list[int]:
        if len(set(v)) != len(v):
            raise ValueError(f"branch grids must be distinct, got {v}")
        return v


class IdentificationConfig(_Strict):
    holdout_cases: list[str] = []
    confidence: float = Field(0.95, gt=0, lt=1)
    max_iterations: int = Field(30, ge=1)
    fixed_point: bool = True
    bootstrap: int = Field(0, ge=0)
    profile: bool = True                    # profile-likelihood intervals (their coverage is tested)


class StudyConfig(_Strict):
    name: str
    solver: SolverConfig = SolverConfig()
    joints: list[JointConfig] = []
    identification: IdentificationConfig = IdentificationConfig()

    @model_validator(mode="after")
    def _distinct_joints(self) -> "StudyConfig":
        names = [j.name for j in self.joints]
        if len(set(names)) != len(names):
            raise ValueError(f"joint names must be distinct, got {names}")
        grids = [g for j in self.joints for g in j.grids]
        if len(set(grids)) != len(grids):
            raise ValueError("a grid belongs to more than one joint")
        return self


@dataclass(frozen=True)
class Measurements:
    """Measured displacements, one row per (case, DOF): ``value`` and its ``sigma``."""
    cases: tuple[str, ...]
    dofs: tuple[DofLabel, ...]
    values: np.ndarray
    sigma: np.ndarray
    lines: tuple[int, ...] = ()
    refs: tuple[DofLabel | None, ...] = ()      # optional reference_grid column (Section 5.2)

    def __len__(self) -> int:
        return len(self.cases)

    def subset(self, mask: np.ndarray) -> "Measurements":
        idx = np.flatnonzero(mask)
        return Measurements(tuple(self.cases[i] for i in idx), tuple(self.dofs[i] for i in idx),
                            self.values[idx], self.sigma[idx],
                            tuple(self.lines[i] for i in idx) if self.lines else (),
                            tuple(self.refs[i] for i in idx) if self.refs else ())

    @property
    def all_dofs(self) -> list[DofLabel]:
        """Every DOF the rows need a prediction at (measured DOFs and reference DOFs)."""
        return list(dict.fromkeys(list(self.dofs) + [r for r in self.refs if r is not None]))


@dataclass(frozen=True)
class Study:
    root: Path
    config: StudyConfig
    deck_path: Path
    loads: LoadMatrix
    measurements: Measurements | None
    deck: Deck                      # the parsed deck_path (read once, reused by the wiring)

    @property
    def name(self) -> str:
        return self.config.name


# --------------------------------------------------------------------------------------------
def read_config(path: Path) -> StudyConfig:
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise StudyError("study.toml not found", file=str(path)) from None
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"not valid TOML: {exc}", file=str(path)) from None
    try:
        return StudyConfig.model_validate(data)
    except ValidationError as exc:
        msgs = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']} (given {e.get('input')!r})"
                         for e in exc.errors())
        raise StudyError(msgs, file=str(path)) from None


def _rows(path: Path, header: list[str], optional: list[str] = ()):
    """Yield ``(line_no, dict)`` for every data row, checking the header first (``optional``
    columns may follow the required ones)."""
    try:
        fh = path.open(newline="")
    except FileNotFoundError:
        raise StudyError("file not found", file=str(path)) from None
    with fh:
        reader = csv.reader(fh)
        first = next(reader, None)
        got = [h.strip() for h in first or []]
        extra = got[len(header):]
        if first is None or got[:len(header)] != header or extra != list(optional)[:len(extra)]:
            allowed = ",".join(header) + "".join(f"[,{o}]" for o in optional)
            raise StudyError(f"header must be {allowed}, got {','.join(first or [])!r}",
                             file=str(path), line=1)
        header = got
        for row in reader:
            line = reader.line_num
            if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
                continue
            if len(row) != len(header):
                raise StudyError(f"expected {len(header)} columns, got {len(row)}", file=str(path), line=line)
            yield line, {h: c.strip() for h, c in zip(header, row)}


def _int(text: str, path: Path, line: int, col: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise StudyError(f"expected an integer, got {text!r}", file=str(path), line=line, column=col) from None


def _float(text: str, path: Path, line: int, col: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise StudyError(f"expected a number, got {text!r}", file=str(path), line=line, column=col) from None
    if not math.isfinite(v):
        raise StudyError(f"value must be finite, got {text!r}", file=str(path), line=line, column=col)
    return v


def _dof(rec: dict, path: Path, line: int, grids: set[int] | None) -> DofLabel:
    if not rec["case"]:
        raise StudyError("empty case label", file=str(path), line=line, column="case")
    g = _int(rec["grid"], path, line, "grid")
    c = _int(rec["component"], path, line, "component")
    if not 1 <= c <= 6:
        raise StudyError(f"component must be 1..6, got {c}", file=str(path), line=line, column="component")
    if grids is not None and g not in grids:
        raise StudyError(f"grid {g} is not in the deck", file=str(path), line=line, column="grid")
    return (g, c)


def read_loads(path: Path, grids: set[int] | None = None) -> LoadMatrix:
    """``case,grid,component,value``; cases keep their order of first appearance."""
    entries: dict[tuple[str, DofLabel], tuple[float, int]] = {}
    for line, rec in _rows(path, ["case", "grid", "component", "value"]):
        dof = _dof(rec, path, line, grids)
        val = _float(rec["value"], path, line, "value")
        key = (rec["case"], dof)
        if key in entries:
            raise StudyError(f"duplicate row for case {key[0]!r} grid {dof[0]} component {dof[1]} "
                             f"(first on line {entries[key][1]})", file=str(path), line=line)
        entries[key] = (val, line)
    if not entries:
        raise StudyError("no load rows", file=str(path))
    cases = list(dict.fromkeys(c for c, _ in entries))
    dofs = list(dict.fromkeys(d for _, d in entries))
    ci = {c: j for j, c in enumerate(cases)}
    di = {d: i for i, d in enumerate(dofs)}
    r = [di[d] for _, d in entries]
    c = [ci[k] for k, _ in entries]
    v = [val for val, _ in entries.values()]
    return LoadMatrix(tuple(dofs), sp.csc_matrix((v, (r, c)), shape=(len(dofs), len(cases))), tuple(cases))


def read_measurements(path: Path, load_cases: set[str], grids: set[int] | None = None) -> Measurements:
    """``case,grid,component,value,sigma[,reference_grid]``; sigma > 0 and finite; every case
    must be loaded. With a ``reference_grid`` the value is the displacement relative to that
    grid's same component (Section 5.2); blank means absolute."""
    seen: dict[tuple[str, DofLabel, DofLabel | None], int] = {}
    cases, dofs, vals, sig, lines, refs = [], [], [], [], [], []
    for line, rec in _rows(path, ["case", "grid", "component", "value", "sigma"], ["reference_grid"]):
        dof = _dof(rec, path, line, grids)
        ref = None
        if rec.get("reference_grid"):
            rg = _int(rec["reference_grid"], path, line, "reference_grid")
            if grids is not None and rg not in grids:
                raise StudyError(f"reference grid {rg} is not in the deck", file=str(path), line=line,
                                 column="reference_grid")
            if rg == dof[0]:
                raise StudyError("a grid cannot be measured relative to itself", file=str(path),
                                 line=line, column="reference_grid")
            ref = (rg, dof[1])
        if rec["case"] not in load_cases:
            raise StudyError(f"case {rec['case']!r} has no loads in loads.csv", file=str(path),
                             line=line, column="case")
        val = _float(rec["value"], path, line, "value")
        s = _float(rec["sigma"], path, line, "sigma")
        if s <= 0:
            raise StudyError(f"sigma must be positive, got {rec['sigma']!r}", file=str(path),
                             line=line, column="sigma")
        key = (rec["case"], dof, ref)
        if key in seen:
            raise StudyError(f"duplicate measurement of case {key[0]!r} grid {dof[0]} component "
                             f"{dof[1]} (first on line {seen[key]})", file=str(path), line=line)
        seen[key] = line
        cases.append(rec["case"]); dofs.append(dof); vals.append(val); sig.append(s); lines.append(line)
        refs.append(ref)
    if not cases:
        raise StudyError("no measurement rows", file=str(path))
    return Measurements(tuple(cases), tuple(dofs), np.array(vals), np.array(sig), tuple(lines),
                        tuple(refs) if any(r is not None for r in refs) else ())


def check_joints(config: StudyConfig, deck, toml_path: Path) -> None:
    """Each joint's grids exist, coincide, and are tied in translation by an RBE2 from branch 1."""
    for j in config.joints:
        missing = [g for g in j.grids if g not in deck.grids]
        if missing:
            raise StudyError(f"joint {j.name!r}: grids {missing} are not in the deck", file=str(toml_path))
        xyz = np.array([deck.grids[g].xyz for g in j.grids])
        span = float(np.max(np.abs(xyz - xyz[0])))
        size = max(float(np.ptp(np.array([g.xyz for g in deck.grids.values()]), axis=0).max()), 1e-300)
        if span > 1e-9 * size:
            raise StudyError(f"joint {j.name!r}: branch grids {j.grids} are not coincident "
                             f"(they differ by up to {span:g})", file=str(toml_path))
        gn, others = j.grids[0], set(j.grids[1:])
        tied: set[int] = set()
        for r in deck.rbe2s.values():
            if r.gn == gn and set("123") <= set(r.cm):
                tied |= set(r.gm) & others
        if tied != others:
            raise StudyError(f"joint {j.name!r}: branch grids {sorted(others - tied)} are not tied to "
                             f"branch 1 grid {gn} by an RBE2 with GN={gn} and CM containing 123",
                             file=str(toml_path))
        for a, b in j.rigid_pairs:
            if a not in j.grids or b not in j.grids or a == b:
                raise StudyError(f"joint {j.name!r}: rigid pair ({a}, {b}) must name two of its grids",
                                 file=str(toml_path))


def load_study(root: str | Path, *, need_measurements: bool = False) -> Study:
    """Read and check a study folder (no solver run)."""
    from solver_adapters.bdf import read_deck

    root = Path(root)
    if not root.is_dir():
        raise StudyError("study folder not found", file=str(root))
    toml_path = root / "study.toml"
    config = read_config(toml_path)
    deck_path = (root / config.solver.deck).resolve()
    if not deck_path.is_file():
        raise StudyError(f"deck {config.solver.deck!r} not found", file=str(toml_path))
    deck = read_deck(deck_path)
    grids = set(deck.grids)
    check_joints(config, deck, toml_path)
    loads = read_loads(root / "loads.csv", grids)
    meas_path = root / "measurements.csv"
    measurements = None
    if meas_path.exists():
        measurements = read_measurements(meas_path, set(loads.cases), grids)
        unknown_holdout = set(config.identification.holdout_cases) - set(measurements.cases)
        if unknown_holdout:
            raise StudyError(f"holdout_cases {sorted(unknown_holdout)} have no measurements",
                             file=str(toml_path))
    elif need_measurements:
        raise StudyError("measurements.csv not found (needed for this command)", file=str(meas_path))
    return Study(root, config, deck_path, loads, measurements, deck)


@dataclass(frozen=True)
class Branch:
    """One branch of a joint as the deck describes it: its grid, the member leaving the joint,
    the unit direction into that member, the member's section and its CBAR orientation vector."""
    grid: int
    eid: int
    direction: tuple[float, float, float]
    length: float
    E: float
    G: float
    A: float
    I1: float
    I2: float
    J: float
    orientation: tuple[float, float, float]


def joint_branches(deck, grids) -> list[Branch]:
    """The member attached to each branch grid (exactly one per branch grid is expected)."""
    out = []
    for g in grids:
        bars = [b for b in deck.cbars.values() if g in (b.ga, b.gb)]
        if len(bars) != 1:
            raise StudyError(f"branch grid {g} should end exactly one CBAR, it ends {len(bars)} "
                             f"({[b.eid for b in bars]})")
        b = bars[0]
        other = b.gb if b.ga == g else b.ga
        d = np.subtract(deck.grids[other].xyz, deck.grids[g].xyz)
        L = float(np.linalg.norm(d))
        p = deck.pbars[b.pid]
        m = deck.mat1s[p.mid]
        v = np.array(b.x, float) if b.g0 is None else \
            np.subtract(deck.grids[b.g0].xyz, deck.grids[b.ga].xyz)
        out.append(Branch(g, b.eid, tuple(d / L), L, m.e, m.g, p.a, p.i1, p.i2, p.j, tuple(v)))
    return out
