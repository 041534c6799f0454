"""Study folders (``docs/study-format.md``): ``study.toml``, ``model.bdf``, ``loads.csv``,
``measurements.csv``. Everything is checked before any solver work, and every rejection names
the file, the line and the column.

Every file a study names resolves inside the study folder (:func:`study_file`): a study is data
someone else may send, and it must not make blackbox read the user's other files. A path or a
symbolic link that leads out of the folder is refused unless the user allows that folder, for one
run (``--allow-outside DIR``, :data:`ALLOW_OUTSIDE`) or in their own configuration file
(``allow_outside`` in ``~/.config/blackbox/config.toml``, :mod:`solver_adapters.userconfig`).

This is wiring, not method: it may read the deck (to check grids and joint ties) and pick the
adapter; the method modules only ever see the adapter through ``solver_adapters.protocol``.
"""

from __future__ import annotations

import contextlib
import math
import os
import stat
import tomllib
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from blackbox.errors import StudyError
from blackbox.noise import NoiseModel, Readings, reduce_readings
from solver_adapters import tables
from solver_adapters.deck import Deck
from solver_adapters.tables import TableFormatError
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
    options: dict[str, Any] = {}       # [solver.options]: passed to the adapter, checked by its registry entry


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
    cases: list[str] = []                   # the cases identify fits (labels or glob patterns); [] = all
    holdout_cases: list[str] = []
    confidence: float = Field(0.95, gt=0, lt=1)
    max_iterations: int = Field(30, ge=1)
    fixed_point: bool = True
    bootstrap: int = Field(0, ge=0)
    profile: bool = True                    # profile-likelihood intervals (their coverage is tested)


class MeasurementsConfig(_Strict):
    """What study.toml says about the measurements' noise (blackbox.noise)."""
    translation_accuracy: float | None = Field(None, gt=0)   # +- bound of a translation reading's error
    rotation_accuracy: float | None = Field(None, gt=0)      # +- bound of a rotation reading's error
    sequential: bool = False        # the cases of loads.csv, in its order, are one test's steps in time order


class PreloadConfig(_Strict):
    """One entry of the permanent load the structure carries throughout the test ([[preloads]])."""
    grid: int
    component: int = Field(ge=1, le=6)
    value: float


class StudyConfig(_Strict):
    name: str
    solver: SolverConfig = SolverConfig()
    joints: list[JointConfig] = []
    identification: IdentificationConfig = IdentificationConfig()
    measurements: MeasurementsConfig = MeasurementsConfig()
    preloads: list[PreloadConfig] = []

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
    """Measured displacements, one row per (case, DOF): ``value`` and its ``sigma`` (``nan``
    where only the fit can estimate it; ``noise`` says where each sigma came from)."""
    cases: tuple[str, ...]
    dofs: tuple[DofLabel, ...]
    values: np.ndarray
    sigma: np.ndarray
    lines: tuple[int, ...] = ()
    refs: tuple[DofLabel | None, ...] = ()      # optional reference_grid column (Section 5.2)
    noise: NoiseModel | None = None             # None: every sigma was given

    def __len__(self) -> int:
        return len(self.cases)

    def subset(self, mask: np.ndarray) -> "Measurements":
        idx = np.flatnonzero(mask)
        return Measurements(tuple(self.cases[i] for i in idx), tuple(self.dofs[i] for i in idx),
                            self.values[idx], self.sigma[idx],
                            tuple(self.lines[i] for i in idx) if self.lines else (),
                            tuple(self.refs[i] for i in idx) if self.refs else (),
                            self.noise.subset(idx) if self.noise is not None else None)

    @property
    def fit_rows(self) -> np.ndarray:
        """Rows whose sigma only the fit can estimate (blank, no repeats, no declared accuracy)."""
        return self.noise.fit_rows if self.noise is not None else np.zeros(len(self), dtype=bool)

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
# the study's files stay in the study folder
# --------------------------------------------------------------------------------------------
ALLOW_OUTSIDE: ContextVar[tuple[Path, ...]] = ContextVar("blackbox_allow_outside", default=())
"""Folders outside a study that its files may lie in, for the running command (the CLI's
``--allow-outside``); the user's ``config.toml`` (``allow_outside``) adds its own."""

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a named pipe"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def allowed_folders() -> tuple[Path, ...]:
    """Where a study's files may lie outside its folder: :data:`ALLOW_OUTSIDE` and the user's
    ``allow_outside`` (absolute, symlink-free)."""
    from solver_adapters.userconfig import allowed_outside

    return tuple(Path(p).expanduser().resolve() for p in ALLOW_OUTSIDE.get()) + tuple(allowed_outside())


def study_file(root: str | os.PathLike, name: str | os.PathLike, what: str | None = None, *,
               named_in: Path | None = None) -> Path:
    """``root / name`` as an absolute, symlink-free path, after checking that it stays in the
    study folder ``root`` and, when it exists, that it is a regular file.

    ``what`` names the file in messages (default: ``name``; e.g. ``[solver] deck = '...'``);
    ``named_in``: the file that names it (the error is located there). A path or a symbolic link
    (the file itself or a folder on its way) leading out of the folder raises :class:`StudyError`
    naming both the given and the real path and how to allow it, unless the real path lies in an
    :func:`allowed_folders` folder. Nothing of the outside file is read."""
    root = Path(root)
    top = root.resolve()
    given = root / name
    real = given.resolve()
    what = what or str(name)
    where = str(named_in if named_in is not None else given)
    if not real.is_relative_to(top):
        lexical = Path(os.path.normpath(given.absolute()))
        how = ("through a symbolic link" if lexical.is_relative_to(Path(os.path.normpath(root.absolute())))
               else "by its path")
        if not any(real.is_relative_to(a) for a in allowed_folders()):
            from solver_adapters.userconfig import config_file

            raise StudyError(f"{what} leads outside the study folder {top} ({how}, to {real}): refused, "
                             f"because a study may come from someone else and must not make blackbox read "
                             f"your other files. Put the file in the study folder, or allow its folder: "
                             f"--allow-outside {real.parent} for this run, or allow_outside = "
                             f"[\"{real.parent}\"] in your own {config_file()}", file=where)
    try:
        mode = os.stat(real).st_mode
    except OSError:
        return real                     # missing: the reader says so where it needs the file
    if not stat.S_ISREG(mode):
        kind = next((k for test, k in _KINDS if test(mode)), "not a regular file")
        raise StudyError(f"{what} is {kind}, not a regular file", file=where)
    return real


# --------------------------------------------------------------------------------------------
def read_config(path: Path) -> StudyConfig:
    try:
        with _located():
            data = tomllib.loads(tables.read_text(path))
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"not valid TOML: {exc}", file=str(path)) from None
    try:
        return StudyConfig.model_validate(data)
    except ValidationError as exc:
        msgs = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']} (given {e.get('input')!r})"
                         for e in exc.errors())
        raise StudyError(msgs, file=str(path)) from None


@contextlib.contextmanager
def _located():
    """A table error from the shared CSV reader as a :class:`StudyError` (same location)."""
    try:
        yield
    except TableFormatError as exc:
        raise StudyError(exc.message, file=exc.file, line=exc.line, column=exc.column) from None


def read_text(path: Path) -> str:
    """A study file as UTF-8 text (a byte-order mark accepted; a bad byte located)."""
    with _located():
        return tables.read_text(path)


def read_loads(path: Path, grids: set[int] | None = None) -> LoadMatrix:
    """``case,grid,component,value[,group]``; cases keep their order of first appearance
    (:func:`solver_adapters.tables.read_loads`, the one reader of this file)."""
    with _located():
        return tables.read_loads(path, grids)


def read_load_groups(path: Path) -> dict[str, str]:
    """``{case: group}`` of the optional ``group`` column (empty when absent)."""
    with _located():
        return tables.load_groups(path)


def read_measurements(path: Path, load_cases: set[str], grids: set[int] | None = None,
                      noise: MeasurementsConfig | None = None, confidence: float = 0.95) -> Measurements:
    """``case,grid,component,value[,sigma[,reference_grid]]``; every case must be loaded. With a
    ``reference_grid`` the value is the displacement relative to that grid's same component
    (Section 5.2); blank means absolute. A given sigma is > 0 and finite; a blank sigma (or no
    sigma column) is estimated (:mod:`blackbox.noise`: repeated readings -- several rows of one
    case and DOF, averaged into one --, ``noise``'s declared accuracy, or the fit)."""
    with _located():
        return _read_measurements(path, load_cases, grids, noise or MeasurementsConfig(), confidence)


def _header(path: Path) -> list[str]:
    """The header of measurements.csv: sigma may be left out (then reference_grid too)."""
    first = next(iter(tables.read_text(path).splitlines()), "")
    return [h.strip() for h in first.split(",")]


def _read_measurements(path: Path, load_cases: set[str], grids: set[int] | None,
                       noise: MeasurementsConfig, confidence: float) -> Measurements:
    seen: dict[tuple[str, DofLabel, DofLabel | None], tuple[int, bool]] = {}
    cases, dofs, vals, sig, lines, refs = [], [], [], [], [], []
    has_sigma = _header(path)[4:5] == ["sigma"]
    header = ["case", "grid", "component", "value"] + (["sigma"] if has_sigma else [])
    for line, rec in tables.rows(path, header, ["reference_grid"] if has_sigma else ["sigma", "reference_grid"]):
        dof = tables.parse_dof(rec, path, line, grids)
        ref = None
        if rec.get("reference_grid"):
            rg = tables.parse_int(rec["reference_grid"], path, line, "reference_grid")
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
        val = tables.parse_float(rec["value"], path, line, "value")
        blank = not rec.get("sigma")
        s = math.nan
        if not blank:
            s = tables.parse_float(rec["sigma"], path, line, "sigma")
            if s <= 0:
                raise StudyError(f"sigma must be positive (or blank: estimated), got {rec['sigma']!r}",
                                 file=str(path), line=line, column="sigma")
        key = (rec["case"], dof, ref)
        if key in seen:
            first, first_blank = seen[key]
            if not (blank and first_blank):
                raise StudyError(f"duplicate measurement of case {key[0]!r} grid {dof[0]} component "
                                 f"{dof[1]} (first on line {first}): repeated readings of one step must "
                                 f"leave sigma blank (it is then estimated from them)", file=str(path),
                                 line=line, column="sigma")
        else:
            seen[key] = (line, blank)
        cases.append(rec["case"]); dofs.append(dof); vals.append(val); sig.append(s); lines.append(line)
        refs.append(ref)
    if not cases:
        raise StudyError("no measurement rows", file=str(path))
    values, sigma = np.array(vals), np.array(sig)
    noise_model = None
    if np.isnan(sigma).any():
        readings = Readings(tuple((c, d[0], d[1], r[0] if r is not None else 0) for c, d, r in zip(cases, dofs, refs)),
                            values, sigma, tuple(lines))
        order, values, sigma, noise_model = reduce_readings(readings, noise.translation_accuracy,
                                                            noise.rotation_accuracy, confidence)
        cases = [cases[i] for i in order]
        dofs = [dofs[i] for i in order]
        lines = [lines[i] for i in order]
        refs = [refs[i] for i in order]
    known = np.isfinite(sigma)
    _check_sigma_scale(path, values[known], sigma[known], [ln for ln, k in zip(lines, known) if k],
                       [d for d, k in zip(dofs, known) if k])
    return Measurements(tuple(cases), tuple(dofs), values, sigma, tuple(lines),
                        tuple(refs) if any(r is not None for r in refs) else (), noise_model)


SIGMA_RESOLUTION = 1e-12
"""A sigma below this times the largest measured value of its kind (translation or rotation) is
finer than double precision can resolve after the solver's round-off: the weighted residuals
would be noise times 1e12 or overflow. Rejected with the row's location."""


def _check_sigma_scale(path: Path, values: np.ndarray, sigma: np.ndarray, lines, dofs) -> None:
    rot = np.array([d[1] >= 4 for d in dofs], dtype=bool)
    for kind, sel in (("translation", ~rot), ("rotation", rot)):
        if not sel.any():
            continue
        scale = float(np.max(np.abs(values[sel])))
        if scale == 0.0:
            continue
        bad = np.flatnonzero(sel & (sigma < SIGMA_RESOLUTION * scale))
        if bad.size:
            i = int(bad[0])
            raise StudyError(f"sigma {sigma[i]!r} is below {SIGMA_RESOLUTION:g} x the largest measured "
                             f"{kind} ({scale:.3g}): no measurement is that precise, and weights that "
                             f"large make the fit meaningless ({bad.size} such row(s))",
                             file=str(path), line=lines[i], column="sigma")


def select_cases(cases, patterns, where: str = "[identification] cases") -> tuple[str, ...]:
    """The case labels of ``cases`` (in their order, each once) that match any of ``patterns``:
    a label or a shell-style pattern (``*``, ``?``, ``[...]``; ``fnmatch``, case-sensitive). No
    pattern: every case. A pattern that matches no measured case is an error naming it."""
    labels = tuple(dict.fromkeys(str(c) for c in cases))
    if not patterns:
        return labels
    import fnmatch

    chosen: set[str] = set()
    for p in patterns:
        hit = [c for c in labels if fnmatch.fnmatchcase(c, p)]
        if not hit:
            raise StudyError(f"case selection {p!r} matches no measured case (labels look like "
                             f"{', '.join(repr(c) for c in labels[:3])}{' ...' if len(labels) > 3 else ''})",
                             file=where)
        chosen.update(hit)
    return tuple(c for c in labels if c in chosen)


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
        cds = sorted({getattr(deck.grids[g], "cd", 0) for g in j.grids})
        if len(cds) > 1:
            # a joint's springs act between the same components of its branch grids: the grids
            # must give their components in one system, or a spring would join unlike directions
            raise StudyError(f"joint {j.name!r}: branch grids {j.grids} give their components in different "
                             f"displacement systems (CD {cds}); give them one CD", file=str(toml_path))
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


def check_preloads(config: StudyConfig, deck, toml_path: Path) -> None:
    """Each ``[[preloads]]`` entry acts at a grid of the deck, once per grid and component."""
    seen: set = set()
    for i, p in enumerate(config.preloads):
        if p.grid not in deck.grids:
            raise StudyError(f"preloads[{i}]: grid {p.grid} is not in the deck", file=str(toml_path))
        if (p.grid, p.component) in seen:
            raise StudyError(f"preloads[{i}]: grid {p.grid} component {p.component} is given twice",
                             file=str(toml_path))
        seen.add((p.grid, p.component))


def preload_matrix(config: StudyConfig) -> LoadMatrix | None:
    """The declared permanent load as one load case ``"preload"``, or ``None`` without one."""
    if not config.preloads:
        return None
    dofs = [(p.grid, p.component) for p in config.preloads]
    return LoadMatrix.from_dense(dofs, np.array([[p.value] for p in config.preloads]), ("preload",))


def load_study(root: str | Path, *, need_measurements: bool = False) -> Study:
    """Read and check a study folder (no solver run)."""
    from solver_adapters.bdf import read_deck

    root = Path(root)
    if not root.is_dir():
        raise StudyError("study folder not found", file=str(root))
    toml_path = root / "study.toml"
    study_file(root, "study.toml")
    config = read_config(toml_path)
    deck_path = study_file(root, config.solver.deck, f"[solver] deck = {config.solver.deck!r}", named_in=toml_path)
    if not deck_path.is_file():
        raise StudyError(f"deck {config.solver.deck!r} not found", file=str(toml_path))
    # read for any adapter: cards the reference solver does not model (shells, solids) are kept
    # apart (Deck.unmodelled); the reference adapter refuses them with the reader's message, an
    # external adapter hands them to its solver (blackbox.adapters.make_adapter_for)
    deck = read_deck(deck_path, unmodelled="keep")
    grids = set(deck.grids)
    check_joints(config, deck, toml_path)
    check_preloads(config, deck, toml_path)
    study_file(root, "loads.csv")
    loads = read_loads(root / "loads.csv", grids)
    meas_path = root / "measurements.csv"
    study_file(root, "measurements.csv")
    measurements = None
    if meas_path.exists():
        measurements = read_measurements(meas_path, set(loads.cases), grids, config.measurements,
                                         config.identification.confidence)
        unknown_holdout = set(config.identification.holdout_cases) - set(measurements.cases)
        if unknown_holdout:
            raise StudyError(f"holdout_cases {sorted(unknown_holdout)} have no measurements",
                             file=str(toml_path))
        select_cases(measurements.cases, config.identification.cases, where=str(toml_path))
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
    """The member attached to each branch grid (exactly one per branch grid is expected, and
    nothing the reader does not model: the branch is that bar)."""
    out = []
    joined = deck.unmodelled_grids() if deck.unmodelled else {}
    for g in grids:
        if g in joined:
            raise StudyError(f"branch grid {g} is joined to {', '.join(joined[g][:4])} besides its bar: the "
                             f"branch is not one CBAR, which the stub joint and the branch averaging need")
        bars = [b for b in deck.cbars.values() if g in (b.ga, b.gb)]
        if len(bars) != 1:
            raise StudyError(f"branch grid {g} should end exactly one CBAR, it ends {len(bars)} "
                             f"({[b.eid for b in bars]})")
        b = bars[0]
        other = b.gb if b.ga == g else b.ga
        d = np.subtract(deck.grids[other].xyz, deck.grids[g].xyz)
        L = float(np.linalg.norm(d))
        p = deck.pbars[b.pid]
        if p.taper is not None:
            raise StudyError(f"branch grid {g}: its bar {b.eid} ({p.card} {p.pid}) is tapered; the stub joint "
                             f"and the branch averaging need a prismatic branch")
        m = deck.mat1s[p.mid]
        v = np.array(b.x, float) if b.g0 is None else \
            np.subtract(deck.grids[b.g0].xyz, deck.grids[b.ga].xyz)
        out.append(Branch(g, b.eid, tuple(d / L), L, m.e, m.g, p.a, p.i1, p.i2, p.j, tuple(v)))
    return out
