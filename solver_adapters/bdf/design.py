"""Design optimisation cards (SOL 200): the model analysed at the initial design.

NASTRAN's design optimisation analyses the model whose designed properties are given by the
design model, not by the property cards: a DVPREL1 "defines the relation between an analysis
model property and design variables", P = C0 + sum COEFi * X(DVIDi) (MSC QRG DVPREL1 remark 1;
COEF1 = PVAL takes the coefficient from the property card, remark 7, which is the one way the
card's own value enters the relation), and the first analysis is at the design variables'
initial values XINIT (MSC QRG DESVAR). The reader therefore replaces every designed value of
the cards it models by its relation at XINIT, so that a deck's first SOL 200 analysis is the
linear static solution of the study:

* ``DESVAR ID LABEL XINIT XLB XUB DELXV DDVAL``: XINIT within [XLB, XUB] (defaults -1e20, 1e20);
* ``DLINK ID DDVID C0 CMULT IDV1 C1 ...``: the dependent variable DDVID = C0 + CMULT sum Ci
  X(IDVi) (MSC QRG DLINK remark 1), in place of its own XINIT;
* ``DVPREL1 ID TYPE PID PNAME/FID PMIN PMAX C0 / DVID1 COEF1 ...``: a property of a PBAR, PBARL
  (DIMi), PBEAM (end A of a prismatic beam), PROD, PTUBE or PELAS, named (``A``, ``I1`` ...) or
  by its field number (FID > 0, NASTRAN's field numbering, continuation lines counted on);
* ``DVMREL1 ID TYPE MID MPNAME MPMIN MPMAX C0 / DVID1 COEF1 ...``: a MAT1 value (E, G, NU; RHO,
  A, TREF, which the import's GRAV and thermal loads use; GE, ST, SC, SS: no effect);
* ``DVPREL2`` / ``DVMREL2 ID TYPE PID PNAME PMIN PMAX EQID / DESVAR DVID1 ... / DTABLE LABL1
  ...``: the same properties as the value of the DEQATN equation EQID whose arguments are the
  DVIDs' values and then the DTABLE constants, in that order (MSC QRG DVPREL2), evaluated by
  :mod:`.equations` (a parser of NASTRAN's expressions, never Python's ``eval``).

The designed value is written into the card's field and the card read again by its own parser,
so the value is checked as the card's own would be (and a MAT1's blank E, G or NU is completed
from the designed values, as from values written on the card). A value outside [PMIN, PMAX] is
an error rather than a guess at what the optimiser would do with an infeasible start (the
QRG's default limits, 1e-15 for a property that can only be positive, else -1e35, and 1e20,
apply except to a relation of one variable with C0 = 0.0: remark 6).

Relations on mass and damping cards (PMASS, PDAMP, PVISC, CONM2, CMASS*, CDAMP*) have no effect
on a static solution and are accepted. Refused with a located error naming the card: DVCREL1 and
DVCREL2 on an element with stiffness, an equation that cannot be read or evaluated (named
at its DEQATN), a relation on a card the reader does not model (a PSHELL kept for
MYSTRAN would reach it undesigned) or on a PBUSH (handed to MYSTRAN as written), a negative FID
(a word of NASTRAN's element property table), a PBEAM station other than end A and end B
(``I1(B)``: the field of its station at X/XB = 1.0).
"""

from __future__ import annotations

from dataclasses import dataclass

from solver_adapters.bdf import equations
from solver_adapters.bdf.fields import _int, _max_fields, _real
from solver_adapters.bdf.sections import PBARL_DIMS, pbeam_stations
from solver_adapters.bdf.tokens import _Card, _Field
from solver_adapters.protocol import DeckFormatError

# the cards a relation may design, name -> field number; "NSM"-like fields have no effect on
# the stiffness but are read again by GRAV (mass) and thermal loads (MAT1 A, TREF)
_PBAR = {"A": 4, "I1": 5, "I2": 6, "J": 7, "NSM": 8, "C1": 10, "C2": 11, "D1": 12, "D2": 13,
         "E1": 14, "E2": 15, "F1": 16, "F2": 17, "K1": 18, "K2": 19, "I12": 20}
_PBEAM = {"A": 4, "I1": 5, "I2": 6, "I12": 7, "J": 8, "NSM": 9, "C1": 10, "C2": 11, "D1": 12,
          "D2": 13, "E1": 14, "E2": 15, "F1": 16, "F2": 17}
_PROD = {"A": 4, "J": 5, "C": 6, "NSM": 7}
_PTUBE = {"OD": 4, "T": 5, "NSM": 6}
_MAT1 = {"E": 3, "G": 4, "NU": 5, "RHO": 6, "A": 7, "TREF": 8, "GE": 9, "ST": 10, "SC": 11, "SS": 12}
_PELAS = {"K1": 3, "GE1": 4, "S1": 5}
NAMES = {"PBAR": _PBAR, "PBEAM": _PBEAM, "PROD": _PROD, "PTUBE": _PTUBE, "MAT1": _MAT1,
         "PELAS": _PELAS}
"""Property (material) card -> its designable names and their field numbers (MSC QRG of each
card); a PBARL's are DIM1 ... DIMn and NSM (:data:`PBARL_DIMS`)."""

_SIGNED = {"I12", "NU", "A", "TREF", "C1", "C2", "D1", "D2", "E1", "E2", "F1", "F2"}
"""Names of values that may be negative (the default PMIN is -1e35 for them, 1e-15 otherwise;
MAT1 A is the expansion coefficient)."""

NO_STATIC_EFFECT = frozenset({"PMASS", "PDAMP", "PDAMP5", "PVISC", "PBUSHT", "CONM1", "CONM2",
                              "CMASS1", "CMASS2", "CMASS3", "CMASS4", "CDAMP1", "CDAMP2",
                              "CDAMP3", "CDAMP4", "CDAMP5", "CVISC"})
"""Cards whose designed values are masses or damping: no effect on a linear static solution."""

_BIG = 1.0e20


@dataclass
class _Relation:
    card: object            # the DVPREL1/DVMREL1
    target: str             # TYPE
    tid: int                # PID / MID
    field: int              # the designed field's number on the target card
    name: str               # PNAME (or FID as text)
    pmin: float | None
    pmax: float | None
    c0: float
    terms: list             # (DVID, COEF or None for PVAL, field of DVID on the relation)


def _desvar(r, c) -> None:
    """DESVAR ID LABEL XINIT XLB XUB DELXV DDVAL (MSC QRG): XLB <= XINIT <= XUB."""
    _max_fields(c, 8)
    did = _int(c, 2)
    xinit = _real(c, 4)
    xlb, xub = _real(c, 5, -_BIG), _real(c, 6, _BIG)
    _real(c, 7, 0.0)
    _int(c, 8, 0, minimum=0)
    if xlb > xub:
        raise c.error(5, f"XLB = {xlb:g} is above XUB = {xub:g}")
    if not xlb <= xinit <= xub:
        raise c.error(4, f"XINIT = {xinit:g} is outside [XLB, XUB] = [{xlb:g}, {xub:g}]")
    r.claim("DESVAR", did, c, 2)
    r.design.desvars[did] = (xinit, xlb, xub, c)


def _dlink(r, c) -> None:
    """DLINK ID DDVID C0 CMULT IDV1 C1 IDV2 C2 / IDV3 C3 ... (MSC QRG)."""
    _int(c, 2)
    dd = _int(c, 3)
    c0, cmult = _real(c, 4, 0.0), _real(c, 5, 1.0)
    terms = []
    for i in range(6, len(c.fields) + 1, 2):
        if not c.text(i) and not c.text(i + 1):
            continue
        terms.append((_int(c, i), _real(c, i + 1), i))
    if not terms:
        raise c.error(6, "DLINK needs at least one independent variable IDV1 C1")
    seen = set()
    for dv, _, i in terms:
        if dv in seen:
            raise c.error(i, f"independent variable {dv} appears twice (MSC QRG DLINK remark 4)")
        seen.add(dv)
    if dd in r.design.dlinks:
        raise c.error(3, f"design variable {dd} is dependent on another DLINK already "
                         f"({r.design.dlinks[dd][0].src})")
    r.design.dlinks[dd] = (c, c0, cmult, terms)


def _relation(r, c) -> None:
    """DVPREL1 / DVMREL1: ID TYPE PID/MID PNAME/FID PMIN PMAX C0 / DVID1 COEF1 DVID2 COEF2 ..."""
    rid = _int(c, 2)
    r.claim(c.name, rid, c, 2)
    target, tid = c.text(3), _int(c, 4)
    if not target:
        raise c.error(3, "TYPE (the property or material card) is required")
    pname = c.text(5)
    if not pname:
        raise c.error(5, "PNAME/FID (the designed property) is required")
    pmin, pmax = _real(c, 6, None), _real(c, 7, None)
    c0 = _real(c, 8, 0.0)
    if c.text(9):
        raise c.error(9, "field 9 must be blank (the relation's terms are on the continuation)")
    terms = []
    for i in range(10, len(c.fields) + 1, 2):
        if not c.text(i) and not c.text(i + 1):
            continue
        dv = _int(c, i)
        if c.text(i + 1) == "PVAL":
            if i != 10:
                raise c.error(i + 1, "PVAL is allowed for COEF1 only (MSC QRG remark 7)")
            terms.append((dv, None, i))
        else:
            terms.append((dv, _real(c, i + 1, 1.0), i))
    if not terms:
        raise c.error(10, f"{c.name} needs at least one term DVID1 COEF1 (the continuation is required)")
    r.design.relations.append((c, target, tid, pname, pmin, pmax, c0, terms))


def _refused(r, c) -> None:
    """DVCREL1 / DVCREL2: checked in :func:`apply` against their target."""
    r.claim(c.name, _int(c, 2), c, 2)
    r.design.others.append(c)


def _relation2(r, c) -> None:
    """DVPREL2 / DVMREL2: ID TYPE PID/MID PNAME/FID PMIN PMAX EQID / "DESVAR" DVID1 ... /
    "DTABLE" LABL1 ... (MSC QRG): the equation's arguments are the DVIDs' values, then the
    DTABLE constants, in that order."""
    r.claim(c.name, _int(c, 2), c, 2)
    target, tid = c.text(3), _int(c, 4)
    if not c.text(5):
        raise c.error(5, "PNAME/FID (the designed property) is required")
    pmin, pmax = _real(c, 6, None), _real(c, 7, None)
    eqid = _int(c, 8)
    if c.text(9):
        raise c.error(9, "field 9 must be blank")
    dvids, labels, mode = [], [], None
    for start in range(10, len(c.fields) + 1, 8):
        word = c.text(start)
        if word in ("DESVAR", "DTABLE"):
            mode = word
        elif word:
            raise c.error(start, f"{word}: a continuation starts with DESVAR, DTABLE or a blank field 2")
        elif mode is None:
            raise c.error(start, "the first continuation starts with DESVAR or DTABLE")
        for i in range(start + 1, start + 8):
            if c.text(i):
                (dvids if mode == "DESVAR" else labels).append((_int(c, i) if mode == "DESVAR" else c.text(i), i))
    r.design.relations2.append((c, target, tid, c.text(5), pmin, pmax, eqid, dvids, labels))


def _deqatn(r, c) -> None:
    """DEQATN EQID equation (columns 17-72, then 9-72 of each continuation line): kept as text,
    evaluated when a DVPREL2/DVMREL2 of a modelled card uses it."""
    eqid = _int(c, 2)
    r.claim("DEQATN", eqid, c, 2)
    r.design.equations[eqid] = ("".join(f.text for f in c.fields[2:]), c)


def _dtable(r, c) -> None:
    """DTABLE LABL1 VALU1 LABL2 VALU2 ... (MSC QRG): constants of the equations."""
    for i in range(2, len(c.fields) + 1, 2):
        if not c.text(i) and not c.text(i + 1):
            continue
        label = c.text(i)
        if label in r.design.table:
            raise c.error(i, f"DTABLE label {label} is defined twice (also at {r.design.table[label][1].src})")
        r.design.table[label] = (_real(c, i + 1), c)


PARSERS = {"DESVAR": _desvar, "DLINK": _dlink, "DVPREL1": _relation, "DVMREL1": _relation,
           "DVPREL2": _relation2, "DVMREL2": _relation2, "DVCREL1": _refused, "DVCREL2": _refused,
           "DEQATN": _deqatn, "DTABLE": _dtable}


@dataclass
class DesignState:
    """What the reader collected of the design model, applied in :func:`apply`."""
    desvars: dict
    dlinks: dict
    relations: list
    others: list
    targets: dict           # (card name, ID) -> the card that defines it (modelled cards)
    relations2: list        # DVPREL2 / DVMREL2
    equations: dict         # DEQATN EQID -> (text, card)
    table: dict             # DTABLE label -> (value, card)

    @classmethod
    def empty(cls) -> "DesignState":
        return cls({}, {}, [], [], {}, [], {}, {})

    def __bool__(self) -> bool:
        return bool(self.desvars or self.relations or self.others or self.dlinks or self.relations2)


def record_target(r, c) -> None:
    """Remember a card a relation may design (after its parser read it)."""
    if c.name == "PELAS":
        for base in (2, 6):
            if c.text(base):
                r.design.targets[("PELAS", _int(c, base))] = (c, base)
    else:
        r.design.targets[(c.name, _int(c, 2))] = (c, 2)


TARGET_CARDS = frozenset({"PBAR", "PBARL", "PBEAM", "PBEAML", "PROD", "PTUBE", "PELAS", "PBUSH", "MAT1"})
"""Cards the reader models that a relation may name (PBEAML and PBUSH only to be refused)."""


def _values(r) -> dict[int, tuple[float, object]]:
    """Design variable -> (value at the initial design, the card that gives it): XINIT, or a
    DLINK's relation of the independent variables' XINIT."""
    d = r.design
    out = {k: (v[0], v[3]) for k, v in d.desvars.items()}
    for dd, (c, c0, cmult, terms) in d.dlinks.items():
        if dd not in d.desvars:
            raise c.error(3, f"dependent design variable {dd} has no DESVAR")
        total = 0.0
        for dv, coef, i in terms:
            if dv not in d.desvars:
                raise c.error(i, f"design variable {dv} has no DESVAR")
            if dv in d.dlinks:
                raise c.error(i, f"design variable {dv} is dependent on another DLINK; it cannot "
                                 f"be independent here (MSC QRG DLINK remark 6)")
            total += coef * d.desvars[dv][0]
        value = c0 + cmult * total
        xlb, xub = d.desvars[dd][1], d.desvars[dd][2]
        if not xlb <= value <= xub:
            raise c.error(3, f"dependent design variable {dd} = {value:g} at the initial design, "
                             f"outside its DESVAR's [XLB, XUB] = [{xlb:g}, {xub:g}]")
        out[dd] = (value, c)
    return out


_PBEAM_STATION = {"A": 2, "I1": 3, "I2": 4, "I12": 5, "J": 6, "NSM": 7}   # from a station's SO field


def _pbeam_end_b(card) -> int | None:
    """The field number of the SO field of PBEAM ``card``'s end B station (X/XB = 1.0), or
    ``None`` when it has none."""
    return next((f0 for f0 in reversed(pbeam_stations(card)[0]) if _real(card, f0 + 1, 0.0) == 1.0), None)


def _field_of(c, target: str, pname: str, card) -> tuple[int, str]:
    """(field number, property name) of ``pname`` on the target ``card``."""
    if pname.lstrip("+-").isdigit():
        fid = int(pname)
        if fid <= 0:
            raise c.error(5, f"FID {fid}: a word of NASTRAN's element property table, not a field "
                             f"of the {target} card; give the property's name (PNAME) instead")
        names = NAMES.get(target, {})
        name = next((n for n, f in names.items() if f == fid), None)
        if target in ("PBARL", "PBEAML") or name is None:
            raise c.error(5, f"FID {fid} is not a designable field of {target} here "
                             f"(give the property's name, e.g. {', '.join(list(names)[:4]) or 'DIM1'})")
        return fid, name
    if target == "PBARL":
        n = PBARL_DIMS.get(card.text(5), 0)
        if pname.startswith("DIM") and pname[3:].isdigit() and 1 <= int(pname[3:]) <= n:
            return 9 + int(pname[3:]), pname
        if pname == "NSM":
            return 10 + n, pname
        raise c.error(5, f"{pname} is not a dimension of PBARL {card.text(2)} (TYPE {card.text(5)}: "
                         f"DIM1 ... DIM{n}, NSM)")
    if target == "PBEAM" and pname.endswith("(B)") and pname[:-3] in _PBEAM_STATION:
        f0 = _pbeam_end_b(card)
        if f0 is None:
            raise c.error(5, f"{pname}: PBEAM {card.text(2)} has no end B station (SO, X/XB = 1.0) whose "
                             f"value the relation could design")
        return f0 + _PBEAM_STATION[pname[:-3]], pname
    name = pname[:-3] if target == "PBEAM" and pname.endswith("(A)") else pname
    if target == "PBEAM" and "(" in name:
        raise c.error(5, f"{pname}: a PBEAM station other than end A or end B (the reader models beams "
                         f"tapered from end A to end B, without intermediate stations)")
    names = NAMES.get(target, {})
    if name not in names:
        raise c.error(5, f"{pname} is not a property of {target} (designable: {', '.join(names)})")
    return names[name], name


def _equation_value(c, d: DesignState, eqid: int, args: list[float], labels: list) -> float:
    """A DVPREL2/DVMREL2's value: DEQATN ``eqid`` of the DVIDs' values, then the DTABLE
    constants of ``labels`` ``[(label, field)]``."""
    if eqid not in d.equations:
        raise c.error(8, f"DEQATN {eqid} does not exist")
    for label, i in labels:
        if label not in d.table:
            raise c.error(i, f"DTABLE label {label} is not defined (no DTABLE gives it a value)")
    text, eq = d.equations[eqid]
    try:
        return equations.evaluate(text, [*args, *(d.table[label][0] for label, _ in labels)])
    except equations.EquationError as exc:
        raise eq.error(3, f"DEQATN {eqid} (used by {c.name} {c.text(2)}): {exc}") from None


def _designed_card(card, i: int, value: float) -> _Card:
    """``card`` with field ``i`` replaced by ``value`` (blank fields added up to it)."""
    fields = list(card.fields)
    last = fields[-1]
    while len(fields) < i:
        fields.append(_Field("", last.line, last.pos))
    f = fields[i - 1]
    fields[i - 1] = _Field(f"{value:.17E}", f.line, f.pos)
    return _Card(card.name, card.file, card.line, fields)


def apply(r, card_parsers: dict, scratch_reader) -> None:
    """Every relation's value at the initial design into the card it designs (re-read by the
    card's own parser, ``card_parsers[name]``, into ``scratch_reader()``, a reader of its own);
    the others refused or accepted by their target."""
    d = r.design
    if not d:
        return
    values = _values(r)
    for c in d.others:
        target = c.text(3)
        if target in NO_STATIC_EFFECT:
            continue
        raise c.error(3, f"{c.name} designs a connectivity value of {target} {c.text(4)} (an "
                         f"element's own stiffness or geometry): not applied by the reader, "
                         f"so the study would not be the deck's initial design")
    designed: dict[tuple[str, int], dict[int, tuple[float, object]]] = {}
    work = [(c, target, tid, pname, pmin, pmax, ("linear", c0, terms))
            for c, target, tid, pname, pmin, pmax, c0, terms in d.relations]
    work += [(c, target, tid, pname, pmin, pmax, ("equation", eqid, dvids, labels))
             for c, target, tid, pname, pmin, pmax, eqid, dvids, labels in d.relations2]
    for c, target, tid, pname, pmin, pmax, how in work:
        terms = how[2] if how[0] == "linear" else [(dv, None, i) for dv, i in how[2]]
        if target in NO_STATIC_EFFECT:
            for dv, _, i in terms:
                if dv not in values:
                    raise c.error(i, f"design variable {dv} has no DESVAR")
            continue
        if c.name.startswith("DVMREL") and target != "MAT1":
            raise c.error(3, f"{target}: only MAT1 materials are modelled (DVMREL1 of another "
                             f"material is not applied)")
        if target in ("PBUSH", "PBEAML"):
            why = ("it is handed to MYSTRAN as written" if target == "PBUSH"
                   else "the stations of a PBEAML are not designed here")
            raise c.error(3, f"a designed {target} is not applied ({why}): give the designed value "
                             f"on the {target} card")
        got = d.targets.get((target, tid))
        if got is None:
            if (target, tid) in {(u.name, u.fields[0]) for u in r.deck.unmodelled}:
                raise c.error(3, f"{target} {tid} is kept for an external solver as written; a "
                                 f"designed value of it would not reach that solver")
            raise c.error(4, f"{target} {tid} does not exist (no {target} card with that ID the "
                             f"reader models)")
        card, base = got
        i, name = _field_of(c, target, pname, card)
        if target == "PELAS":
            i += base - 2
        for dv, _, k in terms:
            if dv not in values:
                raise c.error(k, f"design variable {dv} has no DESVAR")
        if how[0] == "linear":
            c0 = how[1]
            value = c0
            for dv, coef, k in terms:
                if coef is None:
                    coef = _real(card, i, 0.0)
                value += coef * values[dv][0]
            limited = not (len(terms) == 1 and c0 == 0.0)
            tiny = 1.0e-15
            how_text = "C0 + sum COEFi XINIT"
        else:
            value = _equation_value(c, d, how[1], [values[dv][0] for dv, _, _ in terms], how[3])
            limited, tiny = True, 1.0e-20            # MSC QRG DVPREL2: PMIN default 1e-20
            how_text = f"DEQATN {how[1]} at XINIT"
        lo = pmin if pmin is not None else (((-1.0e35) if name in _SIGNED else tiny) if limited else None)
        hi = pmax if pmax is not None else (1.0e20 if limited else None)
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise c.error(6 if lo is not None and value < lo else 7,
                          f"{target} {tid} {name} = {value:.8g} at the initial design ({how_text}) "
                          f"is outside [PMIN, PMAX] = [{lo if lo is not None else '-inf'}, "
                          f"{hi if hi is not None else 'inf'}]: the analysis of a start outside the "
                          f"property's limits is not imported")
        slot = designed.setdefault((target, tid), {})
        if i in slot:
            raise c.error(5, f"{target} {tid} {name} is designed twice (also by "
                             f"{slot[i][1].name} {slot[i][1].text(2)} at {slot[i][1].src})")
        slot[i] = (value, c)
    for (target, tid), slot in designed.items():
        card, base = d.targets[(target, tid)]
        new = card
        for i, (value, _) in sorted(slot.items()):
            new = _designed_card(new, i, value)
        scratch = scratch_reader()
        try:
            card_parsers[target](scratch, new)
        except DeckFormatError as exc:
            rel = next(iter(slot.values()))[1]
            raise rel.error(5, f"{target} {tid} with its designed value(s) at the initial design "
                               f"({', '.join(f'field {i} = {v:.8g}' for i, (v, _) in sorted(slot.items()))}) "
                               f"is not a valid {target}: {exc}") from None
        deck, made = r.deck, scratch.deck
        for coll in ("pbars", "prods", "pelas", "mat1s"):
            got = getattr(made, coll)
            if tid in got:
                getattr(deck, coll)[tid] = got[tid]
        r.deck.designed[(target, tid)] = {i: v for i, (v, _) in slot.items()}
        rel = ", ".join(f"{c.name} {c.text(2)}" for _, c in slot.values())
        r.note(card, f"designed by {rel}: the values at the initial design (DESVAR XINIT) replace "
                     f"the card's, as in NASTRAN's design optimisation")
