"""Single-point constraints: SPC1, SPC (zero enforced value) and SPCADD; multipoint
constraints: MPC and MPCADD; the reference DOFs of a free body: SUPORT and SUPORT1."""

from __future__ import annotations

from solver_adapters.bdf.fields import _components, _id_list, _int, _max_fields, _real
from solver_adapters.deck import Mpc, SpcAdd


def _point_components(c, i: int) -> str:
    """SPC/SPC1 C: digits 1-6 (a grid) or ``"0"`` for 0 or blank (MSC QRG: a scalar point),
    checked against the points named in the reader's ``finish``."""
    if c.text(i) in ("", "0"):
        return "0"
    return _components(c, i, required=True)


def _spc1(r, c) -> None:
    sid = _int(c, 2)
    comps = _point_components(c, 3)
    items = _id_list(c, 4, len(c.fields))
    if not items:
        raise c.error(4, "SPC1 needs at least one grid")
    r.spc1_pending.append((sid, comps, items, c.src, c, 3))


def _spc(r, c) -> None:
    """SPC: SID G1 C1 D1 G2 C2 D2. Only a zero enforced value (D blank or 0.0) is supported: it
    is the SPC1 constraint of the same set; a non-zero D is an enforced displacement (error here;
    ``blackbox import`` reads it before the model, blackbox.commands.enforced)."""
    _max_fields(c, 8)
    sid = _int(c, 2)
    for base in (3, 6):
        if base == 6 and not any(c.text(i) for i in (6, 7, 8)):
            break
        g = _int(c, base)
        comps = _point_components(c, base + 1)
        if _real(c, base + 2, 0.0) != 0.0:
            raise c.error(base + 2, "enforced displacement not supported in a study's model: D must be 0.0 or "
                                    "blank (its loads are forces in loads.csv; `blackbox import` of the whole "
                                    "input file turns enforced values into loads on large springs)")
        r.spc1_pending.append((sid, comps, [g], c.src, c, base + 1))


def _spcadd(r, c) -> None:
    """SPCADD: SID S1 S2 ... (the SPC/SPC1 sets it combines). All sets of a deck apply anyway
    (the case control, which could select one, is not read): SPCADD is checked, not needed."""
    sid = _int(c, 2)
    sets = [_int(c, i) for i in range(3, len(c.fields) + 1) if c.text(i)]
    if not sets:
        raise c.error(3, "SPCADD needs at least one set ID")
    r.claim("SPCADD", sid, c, 2)
    r.deck.spcadds[sid] = SpcAdd(sid, tuple(sets), c.src)


def _mpc(r, c) -> None:
    """MPC: SID G1 C1 A1 G2 C2 A2 / (blank) G3 C3 A3 G4 C4 A4 / ... (MSC QRG MPC): the equation
    sum A_i u(G_i, C_i) = 0, components in each grid's CD system. The first term's component
    is the dependent one (A1 must not be 0). A scalar point (C blank or 0) is an error."""
    sid = _int(c, 2)
    terms: list[tuple[int, int, float]] = []
    n = len(c.fields)
    starts = [b for line in range(0, (n + 7) // 8 + 1) for b in (3 + 8 * line, 6 + 8 * line)]
    for b in starts:
        if b > n or not any(c.text(i) for i in (b, b + 1, b + 2)):
            continue
        g = _int(c, b)
        comp = c.text(b + 1)
        if comp not in ("", "0", "1", "2", "3", "4", "5", "6"):
            raise c.error(b + 1, "component must be one digit 1-6 (a grid) or 0 or blank (a scalar point)")
        r.point_refs.append((c, b + 1, g, int(comp or 0)))
        a = _real(c, b + 2)
        if not terms and a == 0.0:
            raise c.error(b + 2, "A1, the coefficient of the dependent component, must not be 0")
        terms.append((g, int(comp or 0), a))
    for i in range(9, n + 1, 8):
        if c.text(i):
            raise c.error(i, "field must be blank (an MPC line holds two G C A triples)")
    for i in range(10, n + 1, 8):
        if c.text(i):
            raise c.error(i, "field must be blank (an MPC continuation starts with a blank field)")
    if not terms:
        raise c.error(3, "MPC needs at least one term G1 C1 A1")
    r.deck.mpcs.append(Mpc(sid, tuple(terms), c.src))


def _mpcadd(r, c) -> None:
    """MPCADD: SID S1 S2 ... (the MPC sets it combines)."""
    sid = _int(c, 2)
    sets = [_int(c, i) for i in range(3, len(c.fields) + 1) if c.text(i)]
    if not sets:
        raise c.error(3, "MPCADD needs at least one set ID")
    r.claim("MPCADD", sid, c, 2)
    r.deck.mpcadds[sid] = SpcAdd(sid, tuple(sets), c.src)


def _suport(r, c) -> None:
    """SUPORT ID1 C1 ID2 C2 ID3 C3 ID4 C4 (MSC QRG SUPORT): the reference DOFs (r-set) of a
    free body; SUPORT1 SID ID1 C1 ID2 C2 ID3 C3 the same, in a set the case control selects
    (SUPORT1 = SID). A linear static solution without inertia relief holds them as it holds an
    SPC (MSC Linear Static Analysis User's Guide, inertia relief: the r-set is removed from the
    a-set and given zero motion); with inertia relief (PARAM,INREL,-1) ``blackbox import``
    balances the loads first. Held here like SPC1 entries of a set of their own (finish())."""
    first = 3 if c.name == "SUPORT1" else 2
    _max_fields(c, first + 5 if c.name == "SUPORT1" else 9)
    if c.name == "SUPORT1":
        _int(c, 2)
    found = False
    for base in range(first, first + 8 if c.name == "SUPORT" else first + 6, 2):
        if not (c.text(base) or c.text(base + 1)):
            continue
        g = _int(c, base)
        comps = _point_components(c, base + 1)
        r.spc1_pending.append((None, comps, [g], c.src, c, base + 1))
        found = True
    if not found:
        raise c.error(first, f"{c.name} needs at least one grid and its components")


PARSERS = {"SPC1": _spc1, "SPC": _spc, "SPCADD": _spcadd, "MPC": _mpc, "MPCADD": _mpcadd,
           "SUPORT": _suport, "SUPORT1": _suport}
