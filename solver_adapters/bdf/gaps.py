"""CGAP/PGAP gap elements, as a linear static solution has them: linear with the stiffness of
their initial state (MSC QRG CGAP remark 1), which the initial opening U0 sets (PGAP.linear)."""

from __future__ import annotations

from solver_adapters.bdf.fields import _int, _max_fields, _orientation, _real
from solver_adapters.deck import Gap, PGap

GAP_NOTE = ("PGAP F0 (preload), TMAX, MAR and TRMIN (penalty adjustment) and MU2 act in a "
            "nonlinear solution only: a linear static solution keeps the gap in its initial state "
            "(closed: KA axial and KT transverse; open: KB axial), and so does the study")
"""The note of a PGAP with a value a linear solution does not use."""


def _cgap(r, c) -> None:
    """CGAP: EID PID GA GB X1/G0 X2 X3 CID (MSC QRG CGAP). PID blank: EID. The gap axis is x,
    from GA to GB, or CID's T1 direction at GA (CID given, required when GA and GB coincide)."""
    _max_fields(c, 9)
    eid = _int(c, 2)
    pid = _int(c, 3, eid)
    ga, gb = _int(c, 4), _int(c, 5)
    x, g0 = _orientation(c)
    cid = _int(c, 9, None, minimum=0) if c.text(9) else None
    if cid is not None and cid != 0 and cid not in r.cords:
        r.pending_cids.append((c, cid, 9))
    r.claim("element", eid, c, 2)
    r.deck.gaps[eid] = Gap(eid, pid, ga, gb, x, g0, cid, c.src)


def _pgap(r, c) -> None:
    """PGAP: PID U0 F0 KA KB KT MU1 MU2 / TMAX MAR TRMIN (MSC QRG PGAP): KA > 0 (required),
    KB, KT >= 0 (blank: their defaults, PGap.linear)."""
    _max_fields(c, 12)
    pid = _int(c, 2)
    u0, f0 = _real(c, 3, 0.0), _real(c, 4, 0.0)
    ka = _real(c, 5)
    if not ka > 0.0:
        raise c.error(5, "KA (axial stiffness of the closed gap) must be > 0")
    kb = _real(c, 6, None)
    kt = _real(c, 7, None)
    for i, v in ((6, kb), (7, kt)):
        if v is not None and v < 0.0:
            raise c.error(i, f"{'KB' if i == 6 else 'KT'} must be >= 0")
    mu1, mu2 = _real(c, 8, 0.0), _real(c, 9, None)
    if mu1 < 0.0:
        raise c.error(8, "MU1 must be >= 0")
    tail = [_real(c, i, 0.0) for i in (10, 11, 12)]          # TMAX, MAR, TRMIN
    if f0 or mu2 or any(tail):
        r.note(c, GAP_NOTE)
    r.claim("property", pid, c, 2)
    r.deck.pgaps[pid] = PGap(pid, u0, f0, ka, kb, kt, mu1, mu2, c.src)


PARSERS = {"CGAP": _cgap, "PGAP": _pgap}
