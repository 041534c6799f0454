"""One conformance suite that every solver adapter passes, ours and a user's.

The same checks are reachable two ways (zarr's ``StoreTests``, scipy's solver test mixins):

* :func:`run_conformance` returns a :class:`ConformanceReport`; ``blackbox conformance ADAPTER``
  prints it and writes it as JSON and Markdown;
* :class:`AdapterConformance` is a pytest base class. Subclass it in your own test suite and
  implement ``make_adapter(deck_path)``; every ``test_*`` method then runs on the fixture decks::

      from solver_adapters.conformance import AdapterConformance

      class TestMyCode(AdapterConformance):
          def make_adapter(self, deck_path):
              return MyAdapter(deck_path)

The checks (names as in the report)
-----------------------------------
``dof_labels``               ``dofs()`` unique, six components 1-6 per grid, ``grid_xyz()`` gives
                             finite coordinates for exactly those grids
``unknown_labels``           an unknown load or report label raises :class:`UnknownDofError`
                             before any run (``stats`` unchanged)
``linearity_superposition``  ``solve(a F1 + b F2) = a solve(F1) + b solve(F2)``; a zero load
                             case gives zero displacements
``maxwell_betti``            the flexibility at a sample of DOFs is symmetric, ``F_ij = F_ji``
``batch_equals_one_by_one``  a batch of cases equals each case solved alone
``determinism``              the same call twice gives the same numbers
``reference_agreement[D]``   agrees with the in-process reference solver on deck ``D``
``with_springs``             ``with_springs`` agrees with the reference's ``with_springs``, the
                             springs change the answer, and the original adapter is unchanged
``stats_counters``           every run advances ``stats.runs``; ``right_hand_sides`` by the cases
``probe_loads``              unit loads on all six components at seeded grids of the deck agree
                             with the reference (said, not failed, when the reference cannot read
                             the deck: cards it does not model)
``field_formats``            the deck spelt in every field format and continuation style
                             (:data:`FIELD_STYLES`: small, large with implicit and explicit
                             ``+``/``*`` markers, a bare ``+`` then ``*``, ``+APEX``/``*APEX``,
                             free, large free) agrees with the reference on the same text
``grounded_springs``         a CELAS2 with G2 blank and a CELAS1 with G1 blank (springs to ground)
``deck_edits``               the decks ``blackbox diagnose`` edits: the element deck (every member
                             alone, clamped at end a) and a split deck (grids split into members
                             tied by CELAS2, supports on CELAS2 to ground), in large field
``feature[F]``               the generated frame with one model feature added (:data:`FEATURES`:
                             offsets, pin flags, shear pin flags, CD systems, a support in a CD
                             system, rods, RBE3, springs between branch rotations, several load
                             cases with springs) agrees with the reference, or the adapter refuses
                             it with an :class:`UnsupportedFeatureError` naming the card
                             (``REFUSED``: passed, and said); an adapter that ignores the feature
                             solves another structure and fails
``mechanism``                an unsupported, rotated frame raises a :class:`SolverError` (at best
                             :class:`UnstableStructureError`), never returns displacements
``misbehaviour[S]``          switch ``S`` raises a typed :class:`SolverError`
                             (:class:`SolverTimeoutError` for a hang, within the timeout plus a
                             grace), never returns a result, leaves no process behind and keeps
                             (or cleans) its run directory as documented. The switches: those the
                             adapter declares (``conformance_misbehaviour`` on its class, as
                             ``LegacyAdapter``), else, for any adapter that runs a command
                             (:class:`~solver_adapters.subprocess.CommandAdapter`), its command run
                             behind ``_misbehave.py`` (:data:`COMMAND_SWITCHES`)

Tolerances
----------
An adapter declares its precision as an optional attribute ``rtol`` (a relative error bound,
normwise per load case); the default :data:`DEFAULT_RTOL` = 1e-6 suits a code that prints 7
significant digits (MYSTRAN's F06: a printed value is within 5e-7 of the exact one). Adapters
that compute in double precision and hand over binary or ``repr`` digits declare 1e-9 (the
reference solver's own error on the fixtures is ~1e-13; 1e-9 leaves room for the condition
number of other frames). Comparisons are normwise per case (column) because a backward-stable
linear solve bounds the error of a solution vector relative to its largest entry, not entry by
entry: a displacement that is 1e-12 of the largest one carries the same absolute error as it.
Each check's comment says how the bound follows from ``rtol``.

``solver_adapters`` must not import ``blackbox``: the generated deck is written with
:mod:`solver_adapters.bdf_write`, and ``loads.csv`` is read by :func:`read_loads_csv` here.
pytest is imported only when pytest runs the base class.
"""

from __future__ import annotations

import copy
import json
import math
import shutil
import sys
import tempfile
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import psutil
import scipy.sparse as sp

from solver_adapters.errors import CheckFailure, FeatureRefused
from solver_adapters.protocol import (DofLabel, LoadMatrix, ScalarSpring, SolverAdapter, SolverError,
                                      SolverTimeoutError, UnknownDofError)

DEFAULT_RTOL = 1e-6
"""Precision assumed for an adapter without an ``rtol`` attribute: 7 printed significant digits."""

BUILTIN_RTOL = {"reference": 1e-9, "legacy": 1e-9}
"""Precision of our adapters that do not (yet) carry an ``rtol`` attribute. The reference solver
is double precision in-process; FRAMESOLVE solves in double precision and prints at least 13
significant digits (``solver_adapters.legacy.real_field``/its D-format listing)."""

HANG_GRACE_S = 5.0
"""A hanging run must raise within its timeout plus this: the runner polls every few tenths of a
second, then terminates the tree and waits up to 2 s before killing (``subprocess.kill_tree``)."""

OUTPUT_FAILURE_TIMEOUT_S = 60.0
"""The time limit of a run whose misbehaviour must be detected from its output (a crash, no
output, output cut short), not by the clock: the run itself may take seconds on a loaded
machine, and a timeout there would hide whether the output was read."""

PROCESS_GONE_S = 3.0
"""How long a killed process may take to disappear (be reaped) before it counts as left behind."""

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
SEED = 20240611

AdapterFactory = Callable[[Path], SolverAdapter]


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CheckResult:
    """One check: its ``name``, whether it ``passed``, what was seen (``detail``), its wall time;
    ``refused``: a feature check the adapter passed by refusing the deck with a typed
    :class:`~solver_adapters.errors.UnsupportedFeatureError` (it does not claim to model it)."""

    name: str
    passed: bool
    detail: str
    wall_s: float
    refused: bool = False


@dataclass(frozen=True)
class ConformanceReport:
    """Every check run on one adapter (:func:`run_conformance`)."""

    adapter: str
    deck: str
    rtol: float
    checks: tuple[CheckResult, ...]
    wall_s: float

    @property
    def passed(self) -> bool:
        return bool(self.checks) and all(c.passed for c in self.checks)

    @property
    def failed(self) -> list[CheckResult]:
        return [c for c in self.checks if not c.passed]

    @property
    def refused(self) -> list[CheckResult]:
        """Feature checks passed by a typed refusal (the adapter cannot express the feature)."""
        return [c for c in self.checks if c.refused]

    def lines(self) -> list[str]:
        """One line per check (what ``blackbox conformance`` prints)."""
        out = [check_line(c) for c in self.checks]
        n_ok = sum(c.passed for c in self.checks)
        refused = [c.name for c in self.refused]
        out.append(f"{n_ok}/{len(self.checks)} checks passed for adapter {self.adapter!r} "
                   f"(rtol {self.rtol:g}) in {self.wall_s:.1f} s"
                   + (f"; {len(refused)} refused with a typed error: {', '.join(refused)}" if refused else ""))
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"adapter": self.adapter, "deck": self.deck, "rtol": self.rtol, "passed": self.passed,
                "wall_s": self.wall_s, "checks": [asdict(c) for c in self.checks]}

    def to_markdown(self) -> str:
        head = [f"# Conformance of adapter `{self.adapter}`", "",
                f"- result: **{'PASS' if self.passed else 'FAIL'}** "
                f"({sum(c.passed for c in self.checks)}/{len(self.checks)} checks)",
                f"- deck: `{self.deck}`", f"- declared precision rtol: {self.rtol:g}",
                f"- wall time: {self.wall_s:.2f} s", "",
                "| check | result | wall s | detail |", "|---|---|---|---|"]
        rows = [f"| {c.name} | {'refused' if c.refused else 'pass' if c.passed else '**FAIL**'} | {c.wall_s:.2f} | "
                f"{c.detail.replace('|', '/').replace(chr(10), ' ')} |" for c in self.checks]
        return "\n".join(head + rows) + "\n"

    def write(self, out_dir: str | Path) -> tuple[Path, Path]:
        """``conformance.json`` and ``conformance.md`` in ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / "conformance.json").write_text(json.dumps(self.to_dict(), indent=2))
        (out / "conformance.md").write_text(self.to_markdown())
        return out / "conformance.json", out / "conformance.md"


def check_line(c: CheckResult) -> str:
    """The line ``blackbox conformance`` prints for one check."""
    word = "REFUSED" if c.refused else "PASS" if c.passed else "FAIL"
    return f"{word}  {c.name:<34} {c.wall_s:7.2f} s  {c.detail}"


@dataclass(frozen=True)
class Misbehaviour:
    """How to make an adapter fail on purpose, for the ``misbehaviour[S]`` checks.

    ``make(deck_path, switch, workdir_root)`` returns an adapter whose runs misbehave as
    ``switch`` says and whose run directories go below ``workdir_root``; ``program`` is a
    substring of the command line of every process the solver starts (the leftover-process check
    looks for it); ``timeout_s`` is the timeout ``make`` gives the adapter; switches in
    ``timeout_switches`` must raise :class:`SolverTimeoutError`, the others another
    :class:`SolverError`. ``keeps_failed_run_dir`` is the documented behaviour when the adapter
    has no ``keep_failed`` attribute of its own.
    """

    make: Callable[[Path, str, Path], SolverAdapter]
    switches: tuple[str, ...]
    program: str
    timeout_s: float = 2.0
    timeout_switches: tuple[str, ...] = ("hang",)
    keeps_failed_run_dir: bool = True
    grace_s: float = HANG_GRACE_S


def builtin_misbehaviour(adapter_name: str, timeout_s: float = 2.0) -> Misbehaviour | None:
    """The misbehaviour switches an adapter registered under ``adapter_name`` declares itself,
    else None: ``conformance_misbehaviour(timeout_s)`` on its factory returns a
    :class:`Misbehaviour` or a mapping of its fields (``legacy`` declares six switches)."""
    from solver_adapters.registry import adapter_factory

    declare = getattr(adapter_factory(adapter_name), "conformance_misbehaviour", None)
    if not callable(declare):
        return None
    spec = declare(timeout_s)
    if isinstance(spec, Mapping):     # the fields of Misbehaviour (an adapter need not import this module)
        spec = Misbehaviour(**{**spec, "switches": tuple(spec["switches"])})
    return spec


MISBEHAVE = Path(__file__).resolve().with_name("_misbehave.py")
"""The program :func:`command_misbehaviour` puts in front of a command (``solver_adapters._misbehave``)."""

COMMAND_SWITCHES = ("crash", "hang", "silent", "truncate")
"""What :func:`command_misbehaviour` makes any external command do (see ``_misbehave``)."""


def command_misbehaviour(adapter_factory: AdapterFactory, timeout_s: float = 2.0) -> Misbehaviour:
    """Misbehaviour switches for any adapter that runs its code as a
    :class:`~solver_adapters.subprocess.CommandAdapter` (a dialect, ours or a plug-in's): its
    command line is run behind ``_misbehave.py MODE --``, which crashes, hangs, writes nothing, or
    runs the code and cuts its output in half. Every one must end in a typed error, never in
    numbers, whatever the dialect."""
    from solver_adapters.subprocess import CommandAdapter, locate_program

    def make(deck: Path, switch: str, root: Path) -> SolverAdapter:
        a = adapter_factory(deck)
        if not isinstance(a, CommandAdapter):
            raise TypeError(f"{type(a).__name__} is not a CommandAdapter: no command line to wrap")
        program = locate_program(a.command[0])
        # the adapter was built with the user's consent; the wrapper is this package's own program
        a.command = [sys.executable, str(MISBEHAVE), switch, "--",
                     str(program) if program is not None else a.command[0], *a.command[1:]]
        a.timeout_s, a.workdir_root = float(timeout_s), Path(root)
        return a

    return Misbehaviour(make, COMMAND_SWITCHES, str(MISBEHAVE), timeout_s=timeout_s,
                        keeps_failed_run_dir=False)


def misbehaviour_for(adapter_factory: AdapterFactory, deck: Path, name: str | None = None,
                     timeout_s: float = 2.0) -> tuple[Misbehaviour | None, str]:
    """The misbehaviour checks for an adapter, and a sentence saying which: the switches it
    declares itself (:func:`builtin_misbehaviour`, by registered ``name``), else the generic ones
    of :func:`command_misbehaviour` when it runs an external command, else none (an in-process
    adapter: nothing to crash or hang)."""
    from solver_adapters.subprocess import CommandAdapter

    own = builtin_misbehaviour(name, timeout_s) if name is not None else None
    if own is not None:
        return own, f"its own switches {', '.join(own.switches)}"
    try:
        external = isinstance(adapter_factory(deck), CommandAdapter)
    except Exception:  # noqa: BLE001 - the construct check reports it
        external = False
    if external:
        return (command_misbehaviour(adapter_factory, timeout_s),
                f"its command run behind {MISBEHAVE.name} ({', '.join(COMMAND_SWITCHES)})")
    return None, "none: it runs in this process (no command to crash, hang or cut short)"


def adapter_rtol(adapter: Any, override: float | None = None) -> float:
    """The precision to hold ``adapter`` to: ``override``, else its ``rtol`` attribute, else the
    builtin table by name, else :data:`DEFAULT_RTOL`."""
    for value in (override, getattr(adapter, "rtol", None),
                  BUILTIN_RTOL.get(getattr(adapter, "name", ""))):
        if value is not None:
            value = float(value)
            if not 0 < value < 1:
                raise ValueError(f"rtol must be in (0, 1), got {value!r}")
            return value
    return DEFAULT_RTOL


# --------------------------------------------------------------------------------------------
# decks and loads
# --------------------------------------------------------------------------------------------
def read_loads_csv(path: str | Path) -> LoadMatrix:
    """``loads.csv`` beside a fixture deck, through the project's one reader of that file."""
    from solver_adapters.tables import read_loads

    return read_loads(path)


def fixture_decks() -> dict[str, Path]:
    """The repository's fixture decks (``fixtures/cube``, ``fixtures/car``) that are present."""
    return {n: FIXTURES / n / "model.bdf" for n in ("cube", "car") if (FIXTURES / n / "model.bdf").is_file()}


def write_generated_deck(folder: str | Path) -> tuple[Path, LoadMatrix]:
    """A small two-storey 3D frame written to ``folder``, exercising the card subset of docs/study-format.md:
    free-field main file with an ``INCLUDE`` of a large-field property file, GRID PS, two SPC1
    sets, CBAR with an orientation vector and with G0, an RBE2 flexible joint of 4 branches, a
    CELAS2 between branch grids and a CELAS1/PELAS pair. Returns the deck and 4 load cases.

    Units N, m. Steel-like section (E = 210 GPa, G = 80 GPa, a 60 x 60 x 4 mm box approximated
    by A = 9e-4 m^2, I = 4.5e-7 m^4, J = 7e-7 m^4).
    """
    from solver_adapters.bdf_write import format_card

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    xy = [(0.0, 0.0), (1.1, 0.0), (1.0, 0.8), (0.0, 0.9)]
    grids = {}
    for level, z in enumerate((0.0, 1.0, 1.8)):
        for k, (x, y) in enumerate(xy):
            # rounded: MYSTRAN rejects free-field entries longer than 16 characters (1.1500000000000001)
            grids[1 + 4 * level + k] = (round(x + 0.05 * level, 9), y, z)
    grids[81], grids[82], grids[83] = grids[8], grids[8], grids[8]   # joint at grid 8: 4 branches
    bars = [(1, 5), (2, 6), (3, 7), (4, 81),            # columns, storey 1 (4-8 is branch 81)
            (5, 9), (6, 10), (7, 11), (8, 12),           # columns, storey 2 (8-12 is branch 8)
            (5, 6), (6, 7), (7, 82), (83, 5),            # beams, level 1 (7-8, 8-5 branches 82, 83)
            (9, 10), (10, 11), (11, 12), (12, 9), (5, 7)]  # beams, level 2, a brace
    main = ["$ generated by solver_adapters.conformance.write_generated_deck (free field)",
            "BEGIN BULK", "INCLUDE 'generated_props.bdf'"]
    for g, xyz in sorted(grids.items()):
        main.append(format_card("GRID", [g, None, *xyz, None, "123456" if g == 1 else None], "free"))
    for e, (a, b) in enumerate(bars, 1):
        d = np.subtract(grids[b], grids[a])
        if e == 13:
            orient: list = [12, None, None]                             # G0: the third corner
        elif abs(d[2]) > 0.5 * np.linalg.norm(d):
            orient = [1.0, 0.0, 0.0]
        else:
            orient = [0.0, 0.0, 1.0]
        main.append(format_card("CBAR", [e, 1, a, b, *orient], "free"))
    main += [format_card("SPC1", [1, "123456", 2, 3], "free"),
             format_card("SPC1", [2, "123", 4], "free"),
             format_card("SPC1", [2, "456", 4], "free"),
             format_card("RBE2", [900, 8, "123", 81, 82, 83], "free"),
             format_card("CELAS2", [901, 5.0e4, 8, 4, 81, 4], "free"),
             format_card("CELAS1", [902, 7, 10, 1, 11, 1], "free"),
             "ENDDATA"]
    props = ["$ properties (large field), included by generated.bdf",
             format_card("MAT1", [1, 2.1e11, 8.0e10, None], "large"),
             format_card("PBAR", [1, 1, 9.0e-4, 4.5e-7, 4.5e-7, 7.0e-7], "large"),
             format_card("PELAS", [7, 2.0e6], "large")]
    (folder / "generated_props.bdf").write_text("\n".join(p.rstrip("\n") for p in props) + "\n")
    deck = folder / "generated.bdf"
    deck.write_text("\n".join(m.rstrip("\n") for m in main) + "\n")
    rng = np.random.default_rng(SEED)
    free = [5, 6, 7, 9, 10, 11, 12, 8, 82]
    dofs = [(g, c) for g in free for c in range(1, 7)]
    values = np.zeros((len(dofs), 4))
    for j in range(4):
        for i in rng.choice(len(dofs), size=5, replace=False):
            values[i, j] = (100.0 if dofs[i][1] <= 3 else 10.0) * rng.uniform(-1, 1)
    keep = np.flatnonzero(np.any(values != 0, axis=1))
    return deck, LoadMatrix.from_dense([dofs[i] for i in keep], values[keep], [f"G{j + 1}" for j in range(4)])


def conformance_decks(tmp_dir: str | Path) -> dict[str, tuple[Path, LoadMatrix]]:
    """Name -> (deck, load cases): ``generated`` (written to ``tmp_dir``) and the fixtures present."""
    out = {"generated": write_generated_deck(Path(tmp_dir) / "generated")}
    for name, deck in fixture_decks().items():
        out[name] = (deck, read_loads_csv(deck.parent / "loads.csv"))
    return out


def random_loads(dofs: Sequence[DofLabel], n_cases: int = 4, per_case: int = 6, seed: int = SEED) -> LoadMatrix:
    """Seeded load cases on random DOFs (1 N forces, 0.1 N*m moments): for a deck without loads."""
    dofs = list(dofs)
    rng = np.random.default_rng(seed)
    values = np.zeros((len(dofs), n_cases))
    for j in range(n_cases):
        for i in rng.choice(len(dofs), size=min(per_case, len(dofs)), replace=False):
            values[i, j] = (1.0 if dofs[i][1] <= 3 else 0.1) * rng.uniform(-1, 1)
    keep = np.flatnonzero(np.any(values != 0, axis=1))
    return LoadMatrix.from_dense([dofs[i] for i in keep], values[keep], [f"R{j + 1}" for j in range(n_cases)])


# --------------------------------------------------------------------------------------------
# the suite
# --------------------------------------------------------------------------------------------
class Suite:
    """What the checks share: the adapter under test (built once, lazily), the reference, the
    deck, its load cases and the precision. Each ``check_*`` function takes a suite, returns a
    one-line detail when the check passes and raises :class:`CheckFailure` when it does not."""

    def __init__(self, adapter_factory: AdapterFactory, deck_path: str | Path, loads: LoadMatrix | None = None,
                 *, reference_factory: AdapterFactory | None = None, rtol: float | None = None,
                 misbehaviour: Misbehaviour | None = None, deck_name: str | None = None):
        self.factory = adapter_factory
        self.deck = Path(deck_path)
        self.deck_name = deck_name or self.deck.parent.name or self.deck.stem
        self._loads = loads
        self.reference_factory = reference_factory or _reference_factory
        self._rtol = rtol
        self.misbehaviour = misbehaviour
        self._adapter: SolverAdapter | None = None
        self._reference: SolverAdapter | None = None

    @property
    def adapter(self) -> SolverAdapter:
        if self._adapter is None:
            self._adapter = self.factory(self.deck)
        return self._adapter

    @property
    def reference(self) -> SolverAdapter:
        if self._reference is None:
            self._reference = self.reference_factory(self.deck)
        return self._reference

    @property
    def rtol(self) -> float:
        return adapter_rtol(self.adapter, self._rtol)

    @property
    def loads(self) -> LoadMatrix:
        if self._loads is None:
            self._loads = random_loads(self.adapter.dofs())
        return self._loads

    def two_cases(self) -> tuple[LoadMatrix, LoadMatrix]:
        """Two load cases of the deck (a second seeded one when the deck has only one)."""
        L = self.loads
        if L.n_cases >= 2:
            return L.select([0]), L.select([1])
        return L.select([0]), random_loads(self.adapter.dofs(), n_cases=1)


def _reference_factory(deck: Path) -> SolverAdapter:
    from solver_adapters.reference import ReferenceAdapter
    return ReferenceAdapter(deck)


def _fail(message: str) -> CheckFailure:
    return CheckFailure(message)


def _scale(U: np.ndarray, fallback: float | None = None) -> np.ndarray:
    """Largest |entry| of each column; an all-zero column gets ``fallback`` (the largest of all)."""
    s = np.max(np.abs(U), axis=0) if U.size else np.zeros(U.shape[1])
    big = float(np.max(s)) if s.size else 0.0
    return np.where(s > 0, s, fallback if fallback is not None else big)


def _compare(got: np.ndarray, want: np.ndarray, tol: np.ndarray, what: str, dofs, cases) -> float:
    """Raise :class:`CheckFailure` unless ``|got - want| <= tol`` column by column; return the
    worst ``max|got - want| / tol`` (below 1 means it passed)."""
    got, want = np.asarray(got, float), np.asarray(want, float)
    if got.shape != want.shape:
        raise _fail(f"{what}: shape {got.shape}, expected {want.shape}")
    if not np.all(np.isfinite(got)):
        i, j = np.argwhere(~np.isfinite(got))[0]
        raise _fail(f"{what}: non-finite value {got[i, j]} at DOF {dofs[i]} case {cases[j]!r}")
    if got.size == 0:
        return 0.0
    err = np.abs(got - want)
    tol = np.broadcast_to(np.asarray(tol, float), (got.shape[1],))
    if np.any(tol <= 0):
        raise _fail(f"{what}: every displacement is zero, nothing to compare (load the structure)")
    ratio = np.max(err, axis=0) / tol
    j = int(np.argmax(ratio))
    if ratio[j] > 1.0:
        i = int(np.argmax(err[:, j]))
        raise _fail(f"{what}: case {cases[j]!r} DOF {dofs[i]}: {got[i, j]!r} vs {want[i, j]!r}, "
                    f"difference {err[i, j]:.3g} > tolerance {tol[j]:.3g} ({ratio[j]:.3g}x)")
    return float(ratio[j])


def _solve(adapter: SolverAdapter, loads: LoadMatrix, report: Sequence[DofLabel], what: str):
    """``adapter.solve`` with the protocol's shape and label promises checked."""
    report = tuple(report)
    out = adapter.solve(loads, report)
    if tuple(tuple(d) for d in out.dofs) != report:
        raise _fail(f"{what}: Displacements.dofs are not the requested report labels in order")
    if tuple(out.cases) != tuple(loads.cases):
        raise _fail(f"{what}: Displacements.cases {tuple(out.cases)[:5]} are not the load cases "
                    f"{loads.cases[:5]} in order")
    if np.asarray(out.values).shape != (len(report), loads.n_cases):
        raise _fail(f"{what}: values have shape {np.shape(out.values)}, expected {(len(report), loads.n_cases)}")
    return out


def _combine(loads: LoadMatrix, columns: Sequence[np.ndarray], names: Sequence[str]) -> LoadMatrix:
    """Cases that are linear combinations (``columns[k]`` weights over ``loads``' cases)."""
    W = np.column_stack(columns)
    return LoadMatrix(loads.dofs, sp.csc_matrix(loads.values @ W), tuple(names))


# ---- label checks --------------------------------------------------------------------------
def check_dof_labels(s: Suite) -> str:
    a = s.adapter
    dofs = [tuple(d) for d in a.dofs()]
    if not dofs:
        raise _fail("dofs() is empty")
    if any(len(d) != 2 or not all(isinstance(v, (int, np.integer)) for v in d) for d in dofs):
        raise _fail("dofs() must be (grid, component) pairs of integers")
    if len(set(dofs)) != len(dofs):
        dup = next(d for d in dofs if dofs.count(d) > 1)
        raise _fail(f"dofs() has duplicates, e.g. {dup}")
    bad = [d for d in dofs if not 1 <= d[1] <= 6]
    if bad:
        raise _fail(f"components must be 1..6, got {bad[:5]}")
    per_grid: dict[int, set[int]] = {}
    for g, c in dofs:
        per_grid.setdefault(int(g), set()).add(int(c))
    partial = [g for g, cs in per_grid.items() if cs != set(range(1, 7))]
    if partial:
        raise _fail(f"grids without all six components 1-6: {partial[:5]}")
    if [tuple(d) for d in a.dofs()] != dofs:
        raise _fail("dofs() changed between two calls")
    xyz = a.grid_xyz()
    missing = sorted(set(per_grid) - set(xyz))
    extra = sorted(set(xyz) - set(per_grid))
    if missing or extra:
        raise _fail(f"grid_xyz() and dofs() disagree on the grids: missing {missing[:5]}, extra {extra[:5]}")
    badxyz = [g for g, p in xyz.items() if len(tuple(p)) != 3 or not all(math.isfinite(float(v)) for v in p)]
    if badxyz:
        raise _fail(f"grid_xyz() has non-finite or non-3D coordinates for grids {badxyz[:5]}")
    return f"{len(dofs)} labels on {len(per_grid)} grids, unique, components 1-6, coordinates for every grid"


def check_unknown_labels(s: Suite) -> str:
    a = s.adapter
    grids = sorted({int(g) for g, _ in a.dofs()})
    known = (grids[0], 1)
    ghost = grids[-1] + 1000
    tries = [("load on an unknown grid", LoadMatrix.unit([(ghost, 1)]), [known]),
             ("report of an unknown grid", LoadMatrix.unit([known]), [known, (ghost, 3)]),
             ("report of component 7", LoadMatrix.unit([known]), [(grids[0], 7)])]
    for what, loads, report in tries:
        before = a.stats.snapshot()
        try:
            a.solve(loads, report)
        except UnknownDofError:
            pass
        except Exception as exc:  # noqa: BLE001 - any other type is the failure being reported
            raise _fail(f"{what} raised {type(exc).__name__}, not UnknownDofError: {exc}") from None
        else:
            raise _fail(f"{what} returned a result instead of raising UnknownDofError")
        after = a.stats.snapshot()
        if (after["runs"], after["right_hand_sides"]) != (before["runs"], before["right_hand_sides"]):
            raise _fail(f"{what}: the solver ran (stats.runs {before['runs']} -> {after['runs']}) "
                        f"before the labels were checked")
    return "unknown load grid, unknown report grid and component 7 raise UnknownDofError without a run"


# ---- numerical properties ------------------------------------------------------------------
def check_linearity_superposition(s: Suite) -> str:
    a, rtol = s.adapter, s.rtol
    F1, F2 = s.two_cases()
    L = F1.hstack(F2)
    alpha, beta = 2.5, -0.75
    batch = _combine(L, [np.array([1.0, 0.0]), np.array([0.0, 1.0]), np.array([alpha, beta]),
                         np.array([0.0, 0.0])], ["F1", "F2", "aF1+bF2", "zero"])
    report = a.dofs()
    U = _solve(a, batch, report, "superposition batch").values
    u1, u2, u3, u0 = U.T
    s1, s2, s3 = (float(np.max(np.abs(u))) for u in (u1, u2, u3))
    if s1 == 0 or s2 == 0:
        raise _fail("a load case gave no displacement at all; the check needs loads that move the structure")
    # each of u1, u2, u3 is within rtol * (its column's largest entry) of the exact answer, and
    # the exact answers satisfy u3 = a u1 + b u2, so the residual is bounded by the weighted sum
    tol = rtol * (s3 + abs(alpha) * s1 + abs(beta) * s2)
    worst = _compare(u3[:, None], (alpha * u1 + beta * u2)[:, None], tol, "superposition", report, ["aF1+bF2"])
    # a zero load case has the exact answer 0; allow the solver's rounding relative to the others
    _compare(u0[:, None], np.zeros((len(report), 1)), rtol * max(s1, s2), "zero load case", report, ["zero"])
    return (f"solve({alpha} F1 {beta:+} F2) = {alpha} u1 {beta:+} u2 within {worst:.2g} of the "
            f"tolerance; zero load gives zero ({len(report)} DOFs, one batch)")


def sample_dofs(adapter: SolverAdapter, n: int = 12, seed: int = SEED) -> list[DofLabel]:
    """``n`` DOFs on distinct grids, components mixed, seeded."""
    dofs = list(adapter.dofs())
    grids = sorted({g for g, _ in dofs})
    rng = np.random.default_rng(seed)
    picked = rng.permutation(grids)[:n]
    return [(int(g), int(rng.integers(1, 7))) for g in picked]


def check_maxwell_betti(s: Suite) -> str:
    a, rtol = s.adapter, s.rtol
    dofs = sample_dofs(a)
    F = _solve(a, LoadMatrix.unit(dofs), dofs, "unit loads").values
    d = np.diag(F)
    if np.any(d < -rtol * np.max(np.abs(d))):
        i = int(np.argmin(d))
        raise _fail(f"negative direct flexibility F_ii = {d[i]!r} at DOF {dofs[i]} (stiffness not positive)")
    free = np.flatnonzero(d > 0)
    if free.size < 3:
        raise _fail(f"only {free.size} of the sampled DOFs {dofs} move under their own load")
    # For an SPD stiffness |F_ij| <= sqrt(F_ii F_jj) (Cauchy-Schwarz in the energy product), so
    # sqrt(F_ii F_jj) is the scale of the pair; each of F_ij and F_ji is within rtol of it.
    scale = np.sqrt(np.outer(np.maximum(d, 0), np.maximum(d, 0)))
    err = np.abs(F - F.T)
    tol = 2 * rtol * scale
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(tol > 0, err / tol, np.where(err > 0, np.inf, 0.0))
    i, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    if ratio[i, j] > 1.0:
        raise _fail(f"F[{dofs[i]}, {dofs[j]}] = {F[i, j]!r} but F[{dofs[j]}, {dofs[i]}] = {F[j, i]!r}: "
                    f"asymmetry {err[i, j]:.3g} > {tol[i, j]:.3g}")
    off = np.abs(F[np.ix_(free, free)] - np.diag(np.diag(F[np.ix_(free, free)])))
    coupled = int(np.sum(off > 1e-3 * scale[np.ix_(free, free)]))
    return (f"{len(dofs)}x{len(dofs)} flexibility symmetric within {ratio[i, j]:.2g} of the tolerance "
            f"({free.size} free DOFs, {coupled // 2} coupled pairs)")


def check_batch_equals_one_by_one(s: Suite) -> str:
    a, rtol = s.adapter, s.rtol
    k = min(3, s.loads.n_cases)
    L = s.loads.select(range(k))
    report = a.dofs()
    U = _solve(a, L, report, "batch").values
    singles = np.column_stack([_solve(a, L.select([j]), report, f"case {L.cases[j]!r} alone").values[:, 0]
                               for j in range(k)])
    # both are within rtol * column scale of the same exact answer
    worst = _compare(singles, U, 2 * rtol * _scale(U), "one-by-one vs batch", report, L.cases)
    same = bool(np.array_equal(singles, U))
    return (f"{k} cases in one batch equal {k} single runs "
            + ("bit for bit" if same else f"within {worst:.2g} of the tolerance"))


def check_determinism(s: Suite) -> str:
    a, rtol = s.adapter, s.rtol
    report = a.dofs()
    U1 = _solve(a, s.loads, report, "first call").values
    U2 = _solve(a, s.loads, report, "second call").values
    # a parallel solver may sum in another order: both within rtol of the exact answer
    worst = _compare(U2, U1, 2 * rtol * _scale(U1), "second identical call", report, s.loads.cases)
    same = bool(np.array_equal(U1, U2))
    return f"{s.loads.n_cases} cases twice: " + ("identical bit for bit" if same else
                                                  f"equal within {worst:.2g} of the tolerance")


def check_reference_agreement(s: Suite) -> str:
    a, rtol = s.adapter, s.rtol
    report = a.dofs()
    ref_dofs = tuple(s.reference.dofs())
    if set(ref_dofs) != set(report):
        raise _fail(f"the adapter's DOF labels differ from the reference's: "
                    f"{sorted(set(report) ^ set(ref_dofs))[:5]}")
    U = _solve(a, s.loads, report, "adapter").values
    R = s.reference.solve(s.loads, report).values
    # the reference is exact to ~1e-13 here; the adapter must be within its declared rtol of the
    # largest displacement of each case
    worst = _compare(U, R, rtol * _scale(R), "adapter vs reference", report, s.loads.cases)
    return (f"{s.loads.n_cases} cases x {len(report)} DOFs within {worst:.2g} of rtol {rtol:g} "
            f"(normwise per case)")


def spring_dofs(s: Suite) -> tuple[list[ScalarSpring], LoadMatrix]:
    """Springs that visibly change the answer: one between two translations on different grids
    and one from a rotation to ground, each about as stiff as the structure there (k = 1/F_ii
    from the reference), plus unit loads at their DOFs added to the deck's cases."""
    ref = s.reference
    cands = sample_dofs(ref, n=24, seed=SEED + 1)
    F = ref.solve(LoadMatrix.unit(cands), cands).values
    d = np.diag(F)
    trans = [(dof, d[i]) for i, dof in enumerate(cands) if dof[1] <= 3 and d[i] > 0]
    rots = [(dof, d[i]) for i, dof in enumerate(cands) if dof[1] >= 4 and d[i] > 0]
    if not rots:
        rots = [((g, 4 + (c - 1) % 3), f) for (g, c), f in trans[2:3]]
    if len(trans) < 2 or not rots:
        raise _fail(f"no free DOFs for springs among {cands}")
    (ta, fa), (tb, fb) = trans[0], trans[1]
    (rc, fc) = rots[0]
    springs = [ScalarSpring(ta, tb, 1.0 / (fa + fb)), ScalarSpring(rc, None, 1.0 / max(fc, 1e-300))]
    return springs, s.loads.hstack(LoadMatrix.unit([ta, rc], prefix="spring"))


def check_with_springs(s: Suite) -> str:
    a, rtol = s.adapter, s.rtol
    springs, L = spring_dofs(s)
    report = a.dofs()
    before = _solve(a, L, report, "without springs").values
    sprung = a.with_springs(springs)
    if sprung is a:
        raise _fail("with_springs returned the same adapter object; it must return a new one")
    U = _solve(sprung, L, report, "with springs").values
    R = s.reference.with_springs(springs).solve(L, report).values
    worst = _compare(U, R, rtol * _scale(R), "with_springs vs reference with_springs", report, L.cases)
    change = float(np.max(np.abs(U - before) / _scale(R)))
    if change <= 100 * rtol:
        raise _fail(f"the springs did not change the displacements (largest change {change:.2g} of "
                    f"a case's scale): were they written to the model?")
    after = _solve(a, L, report, "original after with_springs").values
    _compare(after, before, 2 * rtol * _scale(before), "original adapter after with_springs", report, L.cases)
    return (f"{len(springs)} springs (k = {springs[0].k:.3g}, {springs[1].k:.3g}) agree with the reference "
            f"within {worst:.2g} of the tolerance, change the answer by {change:.2g}; original unchanged")


def check_stats_counters(s: Suite) -> str:
    a = s.adapter
    if not hasattr(a, "stats"):
        raise _fail("the adapter has no stats attribute")
    seen = []
    for cases in (s.loads, s.loads.select([0])):
        before = a.stats.snapshot()
        hits = _cache_hits(a)
        _solve(a, cases, a.dofs()[:6], "stats probe")
        after = a.stats.snapshot()
        runs, rhs = after["runs"] - before["runs"], after["right_hand_sides"] - before["right_hand_sides"]
        if runs == 0 and rhs == 0 and hits is not None and _cache_hits(a) == hits + 1:
            seen.append(f"{cases.n_cases} case(s): served by the adapter's cache (no run)")
            continue
        if runs < 1:
            raise _fail(f"a solve of {cases.n_cases} case(s) did not advance stats.runs ({before['runs']})")
        if rhs != cases.n_cases:
            raise _fail(f"a solve of {cases.n_cases} case(s) advanced stats.right_hand_sides by {rhs}")
        if after["wall_s"] < before["wall_s"]:
            raise _fail("stats.wall_s went down")
        seen.append(f"{cases.n_cases} case(s): +{runs} run(s), +{rhs} RHS")
    return "; ".join(seen)


def _cache_hits(adapter: Any) -> int | None:
    """Hits of a caching adapter (``solver_adapters.cache.CachedAdapter.cache_stats``): a hit
    legitimately makes no run, so the stats check accepts it."""
    stats = getattr(adapter, "cache_stats", None)
    return getattr(stats, "hits", None)


def _leftovers(program: str, root: Path) -> list[psutil.Process]:
    """Live processes (not zombies) whose command line names ``program`` and that run in, or
    name, a directory under ``root`` (so other users of the same program are not counted)."""
    found, me, root_s = [], psutil.Process().pid, str(root)
    for p in psutil.process_iter(["pid", "cmdline", "status"]):
        try:
            if p.pid == me or p.info["status"] == psutil.STATUS_ZOMBIE:
                continue
            cmd = " ".join(p.info["cmdline"] or [])
            if program not in cmd:
                continue
            if root_s in cmd or p.cwd().startswith(root_s):
                found.append(p)
        except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
            continue
    return found


def check_misbehaviour(s: Suite, switch: str) -> str:
    spec = s.misbehaviour
    if spec is None:
        raise _fail("no misbehaviour declared for this adapter")
    root = Path(tempfile.mkdtemp(prefix=f"conformance-{switch}-"))
    try:
        a = spec.make(s.deck, switch, root)
        want_timeout = switch in spec.timeout_switches
        limit = spec.timeout_s
        if not want_timeout and isinstance(getattr(a, "timeout_s", None), (int, float)):
            limit = a.timeout_s = max(float(a.timeout_s), OUTPUT_FAILURE_TIMEOUT_S)
        keeps = bool(getattr(a, "keep_failed", spec.keeps_failed_run_dir))
        L = s.loads.select(range(min(2, s.loads.n_cases)))
        t0 = time.perf_counter()
        try:
            result = a.solve(L, a.dofs())
        except SolverError as exc:
            error = exc
        except Exception as exc:  # noqa: BLE001 - an untyped error is what this check reports
            raise _fail(f"raised {type(exc).__name__} (not a SolverError): {exc}") from None
        else:
            raise _fail(f"returned a result ({np.shape(result.values)}) instead of raising")
        wall = time.perf_counter() - t0
        if want_timeout and not isinstance(error, SolverTimeoutError):
            raise _fail(f"raised {type(error).__name__}, expected SolverTimeoutError")
        if not want_timeout and isinstance(error, SolverTimeoutError):
            raise _fail("raised SolverTimeoutError: the failure was not detected from the output")
        if wall > limit + spec.grace_s:
            raise _fail(f"took {wall:.1f} s to fail (timeout {limit:g} s + grace {spec.grace_s:g} s)")
        t1 = time.perf_counter()
        left = _leftovers(spec.program, root)
        while left and time.perf_counter() - t1 < PROCESS_GONE_S:
            time.sleep(0.1)
            left = _leftovers(spec.program, root)
        if left:
            for p in left:  # do not leave them running for the rest of the session
                try:
                    p.kill()
                except psutil.Error:
                    pass
            raise _fail(f"left {len(left)} process(es) behind: "
                        f"{[' '.join(p.info['cmdline'] or []) for p in left][:3]}")
        dirs = [p for p in root.iterdir()]
        kept = getattr(error, "workdir", None)
        if keeps:
            if not kept or not Path(kept).is_dir():
                raise _fail(f"the run directory should be kept for inspection (keep_failed) but the "
                            f"error names {kept!r}")
            if Path(kept).resolve().parent != root.resolve() or len(dirs) != 1:
                raise _fail(f"expected exactly the kept run directory under the workdir root, found {dirs}")
            where = f"run directory kept ({Path(kept).name})"
        else:
            if dirs:
                raise _fail(f"keep_failed is off but run directories were left: {dirs}")
            where = "run directory cleaned"
        first = str(error).splitlines()[0] if str(error) else ""
        return f"{type(error).__name__} after {wall:.1f} s, no process left, {where}: {first[:90]}"
    finally:
        shutil.rmtree(root, ignore_errors=True)


# ---- what the commands send: every field format, grounded springs, the edited decks ----------
FIELD_STYLES = ("small", "small_markers", "large", "large_markers", "large_plus_star", "large_apex",
                "free", "free_large")
"""The ways a deck may spell the same cards (``deck_text``): small field with implicit
(blank field 1) and explicit (``+Cn`` in columns 73-80 and field 1) continuations; large field
with implicit ``*`` continuations, explicit ``+Cn``/``*Cn`` markers, a bare ``+`` continued by a
bare ``*``, and the one marker ``+APEX``/``*APEX`` for every card; free field (``,``
continuations) and large free field (``GRID*,`` four fields a line, ``*,`` continuations)."""


def _card_lines(text: str) -> list[list[str]]:
    """The cards of a :func:`~solver_adapters.bdf_write.write_deck` text, each a list of lines."""
    cards: list[list[str]] = []
    for line in text.splitlines():
        if not line.strip() or line.startswith("$") or line.strip() in ("BEGIN BULK", "ENDDATA"):
            continue
        if line[:1] in (" ", "*", "+", ","):
            cards[-1].append(line)
        else:
            cards.append([line])
    return cards


def deck_text(model, style: str) -> str:
    """The bulk data of ``model`` (a parsed :class:`~solver_adapters.deck.Deck`) written in
    ``style`` (:data:`FIELD_STYLES`), ``BEGIN BULK`` to ``ENDDATA``."""
    from solver_adapters.bdf_write import write_deck

    if style not in FIELD_STYLES:
        raise ValueError(f"style must be one of {FIELD_STYLES}, got {style!r}")
    base = {"small": "small", "small_markers": "small", "free": "free"}.get(style, "large")
    if style == "free_large":
        base = "large"
    cards = _card_lines(write_deck(model, base))
    out = ["BEGIN BULK"]
    tag = 0
    for lines in cards:
        if style in ("small", "large", "free"):
            out += lines
            continue
        if style == "free_large":
            rows = [ln.ljust(72) for ln in lines]
            name = rows[0][:8].strip()
            fields = [[r[8 + 16 * k: 24 + 16 * k].strip() for k in range(4)] for r in rows]
            out += [(name if i == 0 else "*") + "," + ",".join(f) for i, f in enumerate(fields)]
            continue
        for i, line in enumerate(lines):
            if i > 0:
                marker = {"small_markers": f"+C{tag:X}", "large_markers": f"*C{tag:X}",
                          "large_plus_star": "*", "large_apex": "*APEX"}[style]
                line = marker.ljust(8) + line[8:]
            if i < len(lines) - 1:
                tag += 1
                marker = {"small_markers": f"+C{tag:X}", "large_markers": f"+C{tag:X}",
                          "large_plus_star": "+", "large_apex": "+APEX"}[style]
                line = line.ljust(72) + marker
            out.append(line.rstrip())
    return "\n".join(out + ["ENDDATA"]) + "\n"


def probe_loads(adapter: SolverAdapter, n_grids: int = 4, seed: int = SEED) -> LoadMatrix:
    """Unit loads on all six components of ``n_grids`` seeded grids (6 n cases): every kind of
    load at places spread over the model."""
    grids = sorted({g for g, _ in adapter.dofs()})
    picked = sorted(int(g) for g in np.random.default_rng(seed).permutation(grids)[:n_grids])
    return LoadMatrix.unit([(g, c) for g in picked for c in range(1, 7)], prefix="probe")


def _agree_on(s: Suite, deck: Path, what: str, loads: LoadMatrix | None = None) -> str:
    """The adapter and the reference built on ``deck`` agree under ``loads`` (default: probe
    loads) at every DOF, normwise per case to ``rtol`` (as ``reference_agreement``)."""
    a = s.factory(deck)
    ref = s.reference_factory(deck)
    loads = loads if loads is not None else probe_loads(ref)
    report = ref.dofs()
    U = _solve(a, loads, report, what).values
    R = ref.solve(loads, report).values
    worst = _compare(U, R, s.rtol * _scale(R), f"{what} vs reference", report, loads.cases)
    return f"{loads.n_cases} cases, worst {worst:.2g} of the tolerance"


def _work_dir(s: Suite, name: str) -> Path:
    return Path(tempfile.mkdtemp(prefix=f"conformance-{name}-"))


def check_field_formats(s: Suite) -> str:
    """The suite's deck spelt in every style of :data:`FIELD_STYLES`: each agrees with the
    reference on the same text (our reader reads all of them alike, the adapter must too)."""
    model = _read(s.deck)
    tmp = _work_dir(s, "formats")
    try:
        details, failed = [], []
        for style in FIELD_STYLES:
            deck = tmp / style / "model.bdf"
            deck.parent.mkdir()
            deck.write_text(deck_text(model, style))
            try:
                details.append(f"{style}: {_agree_on(s, deck, style).split(', ')[1]}")
            except CheckFailure as exc:
                failed.append(f"{style}: {exc}")
            except Exception as exc:  # noqa: BLE001 - the report names what the adapter raised
                failed.append(f"{style}: raised {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
        if failed:
            raise _fail(f"{len(failed)} of {len(FIELD_STYLES)} styles disagree: " + "; ".join(failed))
        return "; ".join(details)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _read(deck: Path):
    from solver_adapters.bdf import read_deck
    return read_deck(deck)


def _member_stiffness(model, b) -> tuple[float, float]:
    """A translational and a rotational stiffness of the order of CBAR ``b``'s own end stiffness
    (12 E I / L^3, 4 E I / L with the larger I): springs of that size change the answer visibly
    and keep the model as well conditioned as the structure."""
    p = model.pbars[b.pid]
    e = model.mat1s[p.mid].e
    length = float(np.linalg.norm(np.subtract(model.grids[b.gb].xyz, model.grids[b.ga].xyz)))
    i = max(p.i1, p.i2, 1e-30)
    return 12 * e * i / length**3, 4 * e * i / length


def check_grounded_springs(s: Suite) -> str:
    """Springs to ground as a deck writes them: a CELAS2 with G2 C2 blank and a CELAS1 (PELAS)
    with G1 C1 blank, at free DOFs, each about as stiff as the structure there."""
    from solver_adapters.bdf_write import format_card, write_deck
    import copy
    model = copy.deepcopy(_read(s.deck))
    ref = s.reference
    cands = sample_dofs(ref, n=8, seed=SEED + 2)
    F = np.diag(ref.solve(LoadMatrix.unit(cands), cands).values)
    free = [(d, f) for d, f in zip(cands, F) if f > 0]
    if len(free) < 2:
        raise _fail(f"no free DOFs for grounded springs among {cands}")
    eid = max([0, *model.cbars, *model.rbe2s, *model.springs, *model.rods]) + 1
    pid = max([0, *model.pbars, *model.pelas, *model.prods]) + 1
    (g1, c1), f1 = free[0]
    (g2, c2), f2 = free[1]
    text = write_deck(model, "free").replace("ENDDATA\n", "")
    text += format_card("CELAS2", [eid, 1.0 / f1, g1, c1], "free")
    text += format_card("PELAS", [pid, 1.0 / f2], "free")
    text += format_card("CELAS1", [eid + 1, pid, None, None, g2, c2], "free") + "ENDDATA\n"
    tmp = _work_dir(s, "grounded")
    try:
        deck = tmp / "grounded.bdf"
        deck.write_text(text)
        loads = probe_loads(ref).hstack(LoadMatrix.unit([(g1, c1), (g2, c2)], prefix="spring"))
        return f"CELAS2 at {(g1, c1)}, CELAS1 at {(g2, c2)} to ground: " + _agree_on(s, deck, "grounded springs", loads)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def element_deck_of(model):
    """Every CBAR alone between two grids of its own at its ends (same EID, PID, orientation;
    G0 turned into a vector), end a clamped by one SPC1: the element deck ``blackbox diagnose``
    runs to get each member's stiffness."""
    from solver_adapters.deck import CBar, Deck, Grid, Spc1
    d = Deck(pbars=dict(model.pbars), mat1s=dict(model.mat1s))
    ends = []
    for i, eid in enumerate(sorted(model.cbars)):
        b = model.cbars[eid]
        ga, gb = 2 * i + 1, 2 * i + 2
        d.grids[ga] = Grid(ga, model.grids[b.ga].xyz)
        d.grids[gb] = Grid(gb, model.grids[b.gb].xyz)
        x = b.x if b.g0 is None else tuple(np.subtract(model.grids[b.g0].xyz, model.grids[b.ga].xyz).tolist())
        d.cbars[eid] = CBar(eid, b.pid, ga, gb, x=tuple(float(v) for v in x), pa=b.pa, pb=b.pb, wa=b.wa, wb=b.wb)
        ends.append(gb)
    d.spc1s = [Spc1(1, "123456", tuple(2 * i + 1 for i in range(len(model.cbars))))]
    return d, ends


def split_deck_of(model):
    """The kind of split deck ``blackbox diagnose`` runs: at every grid where several CBARs end,
    each member but the first moved to a new grid at the same place and tied back by six CELAS2
    (between the two grids), and every SPC1 support replaced by CELAS2 springs to ground (G2
    blank), all about as stiff as the members there. Returns the deck and the spring DOFs."""
    import copy
    from dataclasses import replace as _replace
    from solver_adapters.deck import Grid, Spring
    d = copy.deepcopy(model)
    for eid, b in d.cbars.items():    # G0 as a vector: a split G0 grid must not turn the bar
        if b.g0 is not None:
            v = np.subtract(d.grids[b.g0].xyz, d.grids[b.ga].xyz)
            d.cbars[eid] = _replace(b, g0=None, x=tuple(float(t) for t in v))
    next_grid = max(d.grids) + 1
    next_eid = max([0, *d.cbars, *d.rbe2s, *d.springs, *d.rods]) + 1
    at: dict[int, list[int]] = {}
    for eid in sorted(d.cbars):
        b = d.cbars[eid]
        at.setdefault(b.ga, []).append(eid)
        at.setdefault(b.gb, []).append(eid)
    tied = {g for r in d.rbe2s.values() for g in (r.gn, *r.gm)} | {g for sp in d.springs.values() for g in (sp.g1, sp.g2)}
    touched = []
    for g, eids in sorted(at.items()):
        if len(eids) < 2 or g in tied or d.grids[g].ps:
            continue
        for eid in eids[1:]:
            b = d.cbars[eid]
            new = next_grid
            next_grid += 1
            d.grids[new] = Grid(new, d.grids[g].xyz)
            d.cbars[eid] = _replace(b, ga=new) if b.ga == g else _replace(b, gb=new)
            kt, kr = _member_stiffness(model, model.cbars[eid])
            for c in range(1, 7):
                d.springs[next_eid] = Spring(next_eid, g, c, new, c, k=kt if c <= 3 else kr, card="CELAS2")
                next_eid += 1
            touched.append(g)
    grounded = []
    for spc in d.spc1s:
        for g in spc.grids:
            eid = at.get(g, [None])[0]
            kt, kr = _member_stiffness(model, model.cbars[eid]) if eid is not None else (1e9, 1e9)
            for c in spc.components:
                d.springs[next_eid] = Spring(next_eid, g, int(c), 0, 0, k=kt if int(c) <= 3 else kr, card="CELAS2")
                next_eid += 1
                grounded.append((g, int(c)))
    d.spc1s, d.spcadds = [], {}
    return d, touched, grounded


def check_deck_edits(s: Suite) -> str:
    """The decks ``blackbox diagnose`` edits and runs (written in large field, as it does): the
    element deck (every member alone, clamped at end a) and the split deck (grids split into
    members tied by CELAS2, supports on CELAS2 to ground)."""
    from solver_adapters.bdf_write import write_deck
    model = _read(s.deck)
    if not model.cbars:
        return "no CBAR members: diagnose makes no edited decks for this deck"
    tmp = _work_dir(s, "edits")
    try:
        out = []
        edeck, ends = element_deck_of(model)
        p = tmp / "elements.bdf"
        p.write_text(write_deck(edeck, "large"))
        some = ends[:: max(1, len(ends) // 6)][:6]
        out.append("element deck: " + _agree_on(s, p, "element deck",
                                                  LoadMatrix.unit([(g, c) for g in some for c in range(1, 7)])))
        sdeck, touched, grounded = split_deck_of(model)
        p = tmp / "split.bdf"
        p.write_text(write_deck(sdeck, "large"))
        out.append(f"split deck ({len(touched)} grids split, {len(grounded)} supports on springs to ground): "
                   + _agree_on(s, p, "split deck"))
        return "; ".join(out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def check_probe_loads(s: Suite) -> str:
    """Unit loads on all six components at seeded grids of the deck itself agree with the
    reference; when the reference cannot read the deck (cards it does not model) there is
    nothing to compare with, and the check says so."""
    from solver_adapters.protocol import DeckFormatError
    try:
        s.reference
    except DeckFormatError as exc:
        return f"not compared: the reference solver cannot read the deck ({str(exc).splitlines()[0][:120]})"
    return _agree_on(s, s.deck, "probe loads")


# ---- model features: each deck adds one to the generated frame ------------------------------
FEATURES: dict[str, str] = {
    "offsets": "CBAR offsets WA/WB (basic system) on the top ring beams and a column",
    "pin_flags": "CBAR pin flags releasing moments (5, 6), the axial force (1) and the torque (4)",
    "shear_pin_flags": "CBAR pin flags releasing the shear forces (2, 3)",
    "cd_systems": "grids whose components are in a rotated CORD2R and a CORD2C system: loads, "
                  "results, a clamped support and a joint branch in them",
    "cd_supports": "a support holding components 1 and 3 of a rotated CD system, not 2",
    "rods": "CROD with PROD, and CONROD, as storey diagonals (axial and torsion stiffness only)",
    "rbe3": "an RBE3 reference grid averaging the four top corners, loaded",
    "branch_springs": "CELAS2 springs between the rotations of a joint's branch grids (tied in "
                      "translation by an RBE2), also between different components",
    "spring_cases": "several load cases in one run of a deck with springs and with_springs: each "
                    "case must not keep the spring forces of the case before",
}
"""The feature decks (:func:`feature_deck`) and what each adds. An adapter that ignores the
feature solves another structure and fails its ``feature[NAME]`` check; one that cannot express
it passes only by refusing the deck with an ``UnsupportedFeatureError``."""

_FEATURE_GRIDS = {"offsets": (9, 10, 11), "pin_flags": (6, 7, 9, 12), "shear_pin_flags": (6, 7, 11),
                  "cd_systems": (9, 12, 82), "cd_supports": (4, 5), "rods": (6, 7, 12), "rbe3": (90, 11),
                  "branch_springs": (81, 82, 83), "spring_cases": (81, 82, 83)}


def _feature_model(base, feature: str):
    """The generated model with ``feature`` added (a copy), and the same model as an adapter that
    ignores the feature would solve it."""
    from dataclasses import replace
    from solver_adapters.deck import Coord, Grid, Prod, Rbe3, Rod, Spc1, Spring

    m = copy.deepcopy(base)
    ignored = copy.deepcopy(base)
    if feature == "offsets":
        for eid in (13, 14, 15, 16):
            m.cbars[eid] = replace(m.cbars[eid], wa=(0.0, 0.02, 0.06), wb=(0.03, 0.0, 0.06))
        m.cbars[5] = replace(m.cbars[5], wa=(0.04, -0.03, 0.0))
    elif feature == "pin_flags":
        for eid, pa, pb in ((17, "56", "1"), (16, "", "6"), (14, "4", ""), (2, "", "5")):
            m.cbars[eid] = replace(m.cbars[eid], pa=pa, pb=pb)
    elif feature == "shear_pin_flags":
        for eid, pa, pb in ((15, "2", ""), (10, "", "3")):
            m.cbars[eid] = replace(m.cbars[eid], pa=pa, pb=pb)
    elif feature in ("cd_systems", "cd_supports"):
        c, s_ = math.cos(math.radians(35.0)), math.sin(math.radians(35.0))
        tilt = np.array([[c, s_, 0.0], [-s_, c, 0.0], [0.0, 0.0, 1.0]]) @ \
            np.array([[1.0, 0.0, 0.0], [0.0, math.cos(0.4), math.sin(0.4)], [0.0, -math.sin(0.4), math.cos(0.4)]])
        m.coords[5] = Coord(5, "R", (0.2, -0.1, 0.3), tuple(tuple(float(v) for v in r) for r in tilt))
        m.coords[6] = Coord(6, "C", (0.5, 0.45, 0.0), ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), card="CORD2C")
        ignored.coords = dict(m.coords)
        if feature == "cd_systems":
            for g, cd in ((9, 5), (6, 5), (82, 5), (12, 6), (7, 6), (2, 6)):
                m.grids[g] = replace(m.grids[g], cd=cd)
        else:
            m.grids[4] = replace(m.grids[4], cd=5)
            m.spc1s = [s if 4 not in s.grids or s.components != "123" else Spc1(s.sid, "13", s.grids, s.src)
                       for s in m.spc1s]
            ignored.spc1s = list(m.spc1s)
    elif feature == "rods":
        m.prods[30] = Prod(30, 1, 2.0e-4, 3.0e-8)
        m.rods[30] = Rod(30, 6, 12, pid=30)
        m.rods[31] = Rod(31, 2, 7, mid=1, a=1.5e-4, j=2.0e-8, card="CONROD")
    elif feature == "rbe3":
        corners = (9, 10, 11, 12)
        centre = np.mean([m.grids[g].xyz for g in corners], axis=0)
        for d in (m, ignored):
            d.grids[90] = Grid(90, tuple(float(v) for v in centre))
        m.rbe3s[40] = Rbe3(40, 90, "123456", ((1.0, "123", corners),))
    elif feature in ("branch_springs", "spring_cases"):
        for eid, k, a, b in ((910, 4.0e4, (81, 5), (82, 5)), (911, 6.0e4, (82, 6), (83, 6)),
                             (912, -1.5e4, (81, 4), (83, 6)), (913, 3.0e4, (82, 4), (83, 5)),
                             (914, 2.5e4, (83, 4), (81, 4))):
            m.springs[eid] = Spring(eid, a[0], a[1], b[0], b[1], k=k)
    else:
        raise ValueError(f"unknown feature {feature!r}; known: {', '.join(FEATURES)}")
    return m, ignored


def feature_deck(folder: str | Path, feature: str) -> tuple[Path, LoadMatrix, Path]:
    """The generated frame (:func:`write_generated_deck`) with ``feature`` (:data:`FEATURES`)
    added, written in free field to ``folder/<feature>.bdf``; its load cases (the generated
    deck's four and unit loads on all six components of the feature's grids); and the same deck
    as an adapter that ignores the feature would solve it (``<feature>_ignored.bdf``)."""
    from solver_adapters.bdf_write import write_deck
    folder = Path(folder)
    base_path, base_loads = write_generated_deck(folder / "base")
    m, ignored = _feature_model(_read(base_path), feature)
    deck, other = folder / f"{feature}.bdf", folder / f"{feature}_ignored.bdf"
    deck.write_text(write_deck(m, "free"))
    other.write_text(write_deck(ignored, "free"))
    grids = _FEATURE_GRIDS[feature]
    return deck, base_loads.hstack(LoadMatrix.unit([(g, c) for g in grids for c in range(1, 7)], prefix="at")), other


def check_feature(s: Suite, feature: str) -> str:
    """The adapter on :func:`feature_deck` agrees with the reference solver (normwise per case, to
    ``rtol``), or refuses the deck with an :class:`~solver_adapters.errors.UnsupportedFeatureError`.
    ``spring_cases`` also adds springs with ``with_springs`` and checks that the cases solved in
    one run equal each case solved alone. The detail says how much the feature changes the
    reference's answer (what an adapter ignoring it would be off by)."""
    from solver_adapters.errors import UnsupportedFeatureError
    tmp = _work_dir(s, f"feature-{feature}")
    try:
        deck, loads, ignored_deck = feature_deck(tmp, feature)
        ref = s.reference_factory(deck)
        report = ref.dofs()
        try:
            a = s.factory(deck)
            extra: list[ScalarSpring] = []
            if feature == "spring_cases":
                extra = [ScalarSpring((82, 5), None, 2.0e4), ScalarSpring((81, 6), (83, 4), 3.5e4),
                         ScalarSpring((9, 1), (11, 2), 1.0e5)]
                a, ref = a.with_springs(extra), ref.with_springs(extra)
            U = _solve(a, loads, report, feature).values
        except UnsupportedFeatureError as exc:
            if not exc.features:
                raise _fail(f"raised UnsupportedFeatureError naming no card: {exc}") from None
            raise FeatureRefused(f"refused by the adapter (UnsupportedFeatureError naming {', '.join(exc.cards[:4])}"
                           f"{' ...' if len(exc.cards) > 4 else ''}): {exc.features[0][2][:100]}") from None
        R = ref.solve(loads, report).values
        worst = _compare(U, R, s.rtol * _scale(R), f"{feature} vs reference", report, loads.cases)
        detail = f"{loads.n_cases} cases, worst {worst:.2g} of the tolerance"
        if feature == "spring_cases":
            # the batch's last cases, each alone: a case that kept forces of the cases before it
            # in the run differs (the first case has nothing before it)
            last = list(range(max(1, loads.n_cases - 4), loads.n_cases))
            singles = np.column_stack([_solve(a, loads.select([j]), report, f"case {loads.cases[j]!r} alone")
                                       .values[:, 0] for j in last])
            w2 = _compare(U[:, last], singles, 2 * s.rtol * _scale(R[:, last]), "cases in one run vs each alone",
                          report, [loads.cases[j] for j in last])
            detail += (f"; its last {len(last)} cases equal each case solved alone within {w2:.2g} "
                       f"of the tolerance ({len(extra)} springs added by with_springs)")
        try:
            ign = s.reference_factory(ignored_deck)
            if feature == "spring_cases":
                ign = ign.with_springs(extra)
            keep = [i for i, d in enumerate(report) if d in set(ign.dofs())]
            with warnings.catch_warnings():    # loads lost where the feature's grid hangs free
                warnings.simplefilter("ignore")
                G = ign.solve(loads, [report[i] for i in keep]).values
            change = float(np.max(np.max(np.abs(G - R[keep]), axis=0) / _scale(R)))
            detail += f"; the feature changes the answer by {change:.2g} of a case's largest displacement"
        except SolverError as exc:
            detail += f"; without the feature the structure fails ({type(exc).__name__})"
        return detail
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def mechanism_deck(folder: str | Path) -> tuple[Path, LoadMatrix]:
    """The generated frame turned by a seeded rotation and with every support removed: a
    mechanism (six rigid-body motions) whose singular pivots are rounding errors, not zeros, so a
    code that only looks for zero pivots solves it into huge displacements."""
    from dataclasses import replace
    from solver_adapters.bdf_write import write_deck
    folder = Path(folder)
    deck, loads = write_generated_deck(folder / "base")
    m = copy.deepcopy(_read(deck))
    R = np.linalg.qr(np.random.default_rng(SEED).standard_normal((3, 3)))[0]
    m.grids = {g: replace(v, xyz=tuple(float(t) for t in R @ np.array(v.xyz)), ps="") for g, v in m.grids.items()}
    m.cbars = {e: replace(b, x=tuple(float(t) for t in R @ np.array(b.x)) if b.x is not None else None)
               for e, b in m.cbars.items()}
    m.spc1s, m.spcadds = [], {}
    out = folder / "mechanism.bdf"
    out.write_text(write_deck(m, "free"))
    return out, loads


def check_mechanism(s: Suite) -> str:
    """A mechanism (:func:`mechanism_deck`) must raise a :class:`SolverError`, at best an
    :class:`~solver_adapters.errors.UnstableStructureError`, never return displacements."""
    from solver_adapters.errors import UnstableStructureError
    tmp = _work_dir(s, "mechanism")
    try:
        deck, loads = mechanism_deck(tmp)
        try:
            a = s.factory(deck)
            out = a.solve(loads, a.dofs())
        except UnstableStructureError as exc:
            return f"raised UnstableStructureError: {str(exc).splitlines()[0][:110]}"
        except SolverError as exc:
            return (f"raised {type(exc).__name__} (an UnstableStructureError would tell the user what is "
                    f"wrong): {str(exc).splitlines()[0][:90]}")
        except Exception as exc:  # noqa: BLE001 - an untyped error is what this check reports
            raise _fail(f"raised {type(exc).__name__} (not a SolverError): {exc}") from None
        size = float(np.max(np.abs(out.values))) if out.values.size else 0.0
        raise _fail(f"solved a mechanism (an unsupported, rotated frame) without an error: largest "
                    f"displacement {size:.3g}; check the solver's return codes or the equilibrium of "
                    f"its answer and raise UnstableStructureError")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


CHECKS: tuple[tuple[str, Callable[[Suite], str]], ...] = (
    ("dof_labels", check_dof_labels),
    ("unknown_labels", check_unknown_labels),
    ("linearity_superposition", check_linearity_superposition),
    ("maxwell_betti", check_maxwell_betti),
    ("batch_equals_one_by_one", check_batch_equals_one_by_one),
    ("determinism", check_determinism),
    ("with_springs", check_with_springs),
    ("stats_counters", check_stats_counters),
    ("probe_loads", check_probe_loads),
    ("field_formats", check_field_formats),
    ("grounded_springs", check_grounded_springs),
    ("deck_edits", check_deck_edits),
)
"""The checks on the main deck, in the order :func:`run_conformance` runs them (the reference
agreement and misbehaviour checks follow, one per deck and per switch)."""


REFERENCE_CHECKS = frozenset({"with_springs", "probe_loads", "field_formats", "grounded_springs", "deck_edits"})
"""Checks of :data:`CHECKS` that compare with the reference solver on the suite's deck (and
``reference_agreement``): when the reference cannot read that deck they run on the first
agreement deck instead (:func:`run_conformance`)."""


def _reference_cannot_read(s: Suite) -> str | None:
    """Why the reference solver cannot be built on the suite's deck (the first line of the
    reader's message: cards it does not model), or None when it can."""
    from solver_adapters.protocol import DeckFormatError
    try:
        s.reference
    except DeckFormatError as exc:
        return f"the reference solver cannot read the deck ({str(exc).splitlines()[0][:160]})"
    return None


def run_check(name: str, fn: Callable[[], str]) -> CheckResult:
    """Run one check; any exception (not only :class:`CheckFailure`) is a failed check."""
    t0 = time.perf_counter()
    try:
        detail, ok = fn(), True
    except FeatureRefused as exc:
        return CheckResult(name, True, str(exc), time.perf_counter() - t0, refused=True)
    except CheckFailure as exc:
        detail, ok = str(exc), False
    except Exception as exc:  # noqa: BLE001 - the report names whatever the adapter raised
        first = str(exc).splitlines()[0] if str(exc) else ""
        detail, ok = f"raised {type(exc).__name__}: {first}", False
    return CheckResult(name, ok, detail, time.perf_counter() - t0)


def run_conformance(adapter_factory: AdapterFactory, deck_path: str | Path, loads: LoadMatrix | None = None,
                    *, reference_factory: AdapterFactory | None = None,
                    misbehaviour: Misbehaviour | None = None, rtol: float | None = None,
                    agreement_decks: Mapping[str, tuple[Path, LoadMatrix | None]] | None = None,
                    deck_name: str | None = None, progress: Callable[[CheckResult], None] | None = None
                    ) -> ConformanceReport:
    """Run every check on the adapter ``adapter_factory(deck_path)``.

    ``loads`` are the deck's load cases (``None``: seeded random ones). ``reference_factory``
    builds the adapter to agree with (default: the in-process reference solver). ``misbehaviour``
    adds one ``misbehaviour[S]`` check per switch. ``rtol`` overrides the adapter's declared
    precision. ``reference_agreement`` runs on the main deck and on every deck of
    ``agreement_decks`` (name -> (deck, loads)). When the reference solver cannot read the main
    deck (cards it does not model, which an external adapter runs), the checks that compare with
    it there (:data:`REFERENCE_CHECKS`) say so and run on the first agreement deck instead.
    ``progress`` is called after each check.
    """
    t0 = time.perf_counter()
    suite = Suite(adapter_factory, deck_path, loads, reference_factory=reference_factory, rtol=rtol,
                  misbehaviour=misbehaviour, deck_name=deck_name)
    results: list[CheckResult] = []

    def record(r: CheckResult) -> None:
        results.append(r)
        if progress is not None:
            progress(r)

    try:
        suite.adapter
    except Exception as exc:  # noqa: BLE001
        record(CheckResult("construct", False, f"adapter_factory({str(deck_path)!r}) raised "
                                               f"{type(exc).__name__}: {exc}", time.perf_counter() - t0))
        return ConformanceReport("?", str(deck_path), rtol or DEFAULT_RTOL, tuple(results), time.perf_counter() - t0)
    unreadable = _reference_cannot_read(suite)
    fallback = None
    for name, fn in CHECKS:
        if unreadable is not None and name in REFERENCE_CHECKS:
            # a deck with cards the reference solver does not model (shells, solids; an external
            # adapter runs it): nothing to compare with here; the check runs on the first
            # agreement deck instead (below), so the adapter is still held to the reference
            record(CheckResult(name, True, f"not compared on this deck: {unreadable}", 0.0))
            continue
        record(run_check(name, lambda fn=fn: fn(suite)))
    if unreadable is None:
        record(run_check(f"reference_agreement[{suite.deck_name}]", lambda: check_reference_agreement(suite)))
    else:
        record(CheckResult(f"reference_agreement[{suite.deck_name}]", True,
                           f"not compared on this deck: {unreadable}", 0.0))
    for name, (deck, deck_loads) in (agreement_decks or {}).items():
        if Path(deck).resolve() == suite.deck.resolve():
            continue
        other = Suite(adapter_factory, deck, deck_loads, reference_factory=reference_factory, rtol=rtol,
                      deck_name=name)
        if unreadable is not None and fallback is None:
            fallback = other
            for check, fn in CHECKS:
                if check in REFERENCE_CHECKS:
                    record(run_check(f"{check}[{name}]", lambda fn=fn, other=other: fn(other)))
        record(run_check(f"reference_agreement[{name}]", lambda other=other: check_reference_agreement(other)))
    for feature in FEATURES:
        record(run_check(f"feature[{feature}]", lambda f=feature: check_feature(suite, f)))
    record(run_check("mechanism", lambda: check_mechanism(suite)))
    if misbehaviour is not None:
        for switch in misbehaviour.switches:
            record(run_check(f"misbehaviour[{switch}]", lambda sw=switch: check_misbehaviour(suite, sw)))
    name = getattr(suite.adapter, "name", type(suite.adapter).__name__)
    return ConformanceReport(str(name), str(deck_path), suite.rtol, tuple(results), time.perf_counter() - t0)


# --------------------------------------------------------------------------------------------
# pytest entry point
# --------------------------------------------------------------------------------------------
class AdapterConformance:
    """Base class for an adapter's pytest suite: subclass it as ``TestSomething`` and implement
    :meth:`make_adapter`. Each ``test_*`` method runs one check of this module.

    Class attributes to override: ``rtol`` (precision, when the adapter has no ``rtol``
    attribute), ``property_decks`` (decks for the property checks) and ``agreement_decks``
    (decks compared with the reference), names among ``generated``, ``cube``, ``car``; a
    fixture deck missing from the checkout is left out. Override :meth:`misbehaviour` to run the
    misbehaviour checks and :meth:`make_reference` to compare with another solver.
    """

    rtol: float | None = None
    property_decks: tuple[str, ...] = ("generated", "cube")
    agreement_decks: tuple[str, ...] = ("generated", "cube", "car")
    misbehaviour_deck: str = "cube"

    # ---- hooks -----------------------------------------------------------------------------
    def make_adapter(self, deck_path: Path) -> SolverAdapter:
        raise NotImplementedError("implement make_adapter(deck_path) in your subclass")

    def make_reference(self, deck_path: Path) -> SolverAdapter:
        return _reference_factory(deck_path)

    def misbehaviour(self) -> Misbehaviour | None:
        return None

    # ---- parametrization (pytest calls this method of the class) ----------------------------
    def pytest_generate_tests(self, metafunc) -> None:
        import pytest

        present = {"generated", *fixture_decks()}
        if "conformance_deck" in metafunc.fixturenames:
            wanted = (self.agreement_decks if metafunc.function.__name__ == "test_reference_agreement"
                      else self.property_decks)
            names = [n for n in wanted if n in present] or ["generated"]
            metafunc.parametrize("conformance_deck", names)
        if "conformance_feature" in metafunc.fixturenames:
            metafunc.parametrize("conformance_feature", list(FEATURES))
        if "misbehave_switch" in metafunc.fixturenames:
            spec = self.misbehaviour()
            params = list(spec.switches) if spec else [
                pytest.param(None, marks=pytest.mark.skip(reason="the adapter declares no misbehaviour switches"))]
            metafunc.parametrize("misbehave_switch", params)

    def _suite(self, deck_name: str, tmp_path: Path) -> Suite:
        if deck_name == "generated":
            deck, loads = write_generated_deck(Path(tmp_path) / "generated")
        else:
            deck = fixture_decks()[deck_name]
            loads = read_loads_csv(deck.parent / "loads.csv")
        return Suite(self.make_adapter, deck, loads, reference_factory=self.make_reference, rtol=self.rtol,
                     misbehaviour=self.misbehaviour(), deck_name=deck_name)

    def _run(self, check: Callable[[Suite], str], deck_name: str, tmp_path: Path) -> None:
        detail = check(self._suite(deck_name, tmp_path))
        print(detail)

    # ---- the checks ---------------------------------------------------------------------------
    def test_dof_labels(self, conformance_deck, tmp_path):
        self._run(check_dof_labels, conformance_deck, tmp_path)

    def test_unknown_labels(self, conformance_deck, tmp_path):
        self._run(check_unknown_labels, conformance_deck, tmp_path)

    def test_linearity_superposition(self, conformance_deck, tmp_path):
        self._run(check_linearity_superposition, conformance_deck, tmp_path)

    def test_maxwell_betti(self, conformance_deck, tmp_path):
        self._run(check_maxwell_betti, conformance_deck, tmp_path)

    def test_batch_equals_one_by_one(self, conformance_deck, tmp_path):
        self._run(check_batch_equals_one_by_one, conformance_deck, tmp_path)

    def test_determinism(self, conformance_deck, tmp_path):
        self._run(check_determinism, conformance_deck, tmp_path)

    def test_reference_agreement(self, conformance_deck, tmp_path):
        self._run(check_reference_agreement, conformance_deck, tmp_path)

    def test_with_springs(self, conformance_deck, tmp_path):
        self._run(check_with_springs, conformance_deck, tmp_path)

    def test_stats_counters(self, conformance_deck, tmp_path):
        self._run(check_stats_counters, conformance_deck, tmp_path)

    def test_probe_loads(self, conformance_deck, tmp_path):
        self._run(check_probe_loads, conformance_deck, tmp_path)

    def test_field_formats(self, conformance_deck, tmp_path):
        self._run(check_field_formats, conformance_deck, tmp_path)

    def test_grounded_springs(self, conformance_deck, tmp_path):
        self._run(check_grounded_springs, conformance_deck, tmp_path)

    def test_deck_edits(self, conformance_deck, tmp_path):
        self._run(check_deck_edits, conformance_deck, tmp_path)

    def test_feature(self, conformance_feature, tmp_path):
        """Passes when the adapter agrees with the reference on the feature's deck, or refuses
        it with a typed UnsupportedFeatureError (printed, so ``pytest -rP`` shows which)."""
        suite = self._suite("generated", tmp_path)
        try:
            print(check_feature(suite, conformance_feature))
        except FeatureRefused as exc:
            print(f"REFUSED: {exc}")

    def test_mechanism(self, tmp_path):
        print(check_mechanism(self._suite("generated", tmp_path)))

    def test_misbehaviour(self, misbehave_switch, tmp_path):
        deck = self.misbehaviour_deck if self.misbehaviour_deck in fixture_decks() else "generated"
        suite = self._suite(deck, tmp_path)
        print(check_misbehaviour(suite, misbehave_switch))
