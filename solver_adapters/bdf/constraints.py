"""Single-point constraints: SPC1, SPC (zero enforced value) and SPCADD."""

from __future__ import annotations

from solver_adapters.bdf.fields import _components, _id_list, _int, _max_fields, _real
from solver_adapters.deck import SpcAdd


def _spc1(r, c) -> None:
    sid = _int(c, 2)
    comps = _components(c, 3, required=True)
    items = _id_list(c, 4, len(c.fields))
    if not items:
        raise c.error(4, "SPC1 needs at least one grid")
    r.spc1_pending.append((sid, comps, items, c.src))


def _spc(r, c) -> None:
    """SPC: SID G1 C1 D1 G2 C2 D2. Only a zero enforced value (D blank or 0.0) is supported: it
    is the SPC1 constraint of the same set; a non-zero D is an enforced displacement (error)."""
    _max_fields(c, 8)
    sid = _int(c, 2)
    for base in (3, 6):
        if base == 6 and not any(c.text(i) for i in (6, 7, 8)):
            break
        g = _int(c, base)
        comps = _components(c, base + 1, required=True)
        if _real(c, base + 2, 0.0) != 0.0:
            raise c.error(base + 2, "enforced displacement not supported: D must be 0.0 or blank")
        r.spc1_pending.append((sid, comps, [g], c.src))


def _spcadd(r, c) -> None:
    """SPCADD: SID S1 S2 ... (the SPC/SPC1 sets it combines). All sets of a deck apply anyway
    (the case control, which could select one, is not read): SPCADD is checked, not needed."""
    sid = _int(c, 2)
    sets = [_int(c, i) for i in range(3, len(c.fields) + 1) if c.text(i)]
    if not sets:
        raise c.error(3, "SPCADD needs at least one set ID")
    r.claim("SPCADD", sid, c, 2)
    r.deck.spcadds[sid] = SpcAdd(sid, tuple(sets), c.src)


PARSERS = {"SPC1": _spc1, "SPC": _spc, "SPCADD": _spcadd}
