"""CROD, PROD, CONROD, CTUBE and PTUBE: axial and torsion members."""

from __future__ import annotations

import math

import numpy as np

from solver_adapters.bdf.fields import _ignored_reals, _int, _max_fields, _real
from solver_adapters.bdf.numbers import int_column
from solver_adapters.deck import Prod, Rod


def _pair_of_rods(r, c, card: str) -> None:
    """CROD or CTUBE: EID PID (default EID) G1 G2, and, as COSMIC NASTRAN allows (NASTRAN-95
    User's Manual, CROD and CTUBE: two elements per entry), a second element EID PID G1 G2 in
    fields 6-9 (all four, or none, as the first's)."""
    _max_fields(c, 9)
    for base in (2, 6):
        if base == 6 and not any(c.text(i) for i in range(6, 10)):
            break
        if base == 6:
            for i in (6, 8, 9):
                if not c.text(i):
                    raise c.error(i, f"fields 6-9 hold a second {card} (EID PID G1 G2, COSMIC NASTRAN's two "
                                     f"elements per entry), and field {i} is blank")
        eid = _int(c, base)
        pid = _int(c, base + 1, eid)
        ga, gb = _int(c, base + 2), _int(c, base + 3)
        r.claim("element", eid, c, base)
        r.deck.rods[eid] = Rod(eid, ga, gb, pid=pid, card=card, src=c.src)


def _crod(r, c) -> None:
    """CROD: EID PID (default EID) G1 G2 [EID PID G1 G2] (:func:`_pair_of_rods`)."""
    _pair_of_rods(r, c, "CROD")


def bulk_crod(r, table, cards: np.ndarray) -> np.ndarray:
    """CRODs in bulk (as :func:`_crod` reads each); returns the cards left to it."""
    M = table.matrix(cards, 4)                  # columns 1-4: fields 2-5
    ok = ~(M[:, 5:] != b"").any(axis=1)
    eid, k = int_column(M[:, 1]); ok &= k
    pid, k = int_column(M[:, 2], 0); ok &= k
    pid = np.where(M[:, 2] == b"", eid, pid)
    ga, k = int_column(M[:, 3]); ok &= k
    gb, k = int_column(M[:, 4]); ok &= k
    rows = np.flatnonzero(ok)
    if rows.size:
        sel = cards[rows]
        ids = eid[rows].tolist()
        rods = [Rod(e, a, b, pid=p, card="CROD", src=s) for e, a, b, p, s in
                zip(ids, ga[rows].tolist(), gb[rows].tolist(), pid[rows].tolist(), table.src(sel))]
        r.bulk("rods", "element", sel, ids, rods)
    return cards[~ok]


def _prod(r, c) -> None:
    """PROD: PID MID A J C NSM (C: stress recovery, NSM: mass; no effect on the stiffness)."""
    _max_fields(c, 7)
    pid, mid = _int(c, 2), _int(c, 3)
    a, j = _real(c, 4), _real(c, 5, 0.0)
    _ignored_reals(c, (6, 7))
    r.claim("property", pid, c, 2)
    r.deck.prods[pid] = Prod(pid, mid, a, j, c.src)


def _conrod(r, c) -> None:
    """CONROD: EID G1 G2 MID A J C NSM (C, NSM: no effect on the stiffness)."""
    _max_fields(c, 9)
    eid, ga, gb, mid = _int(c, 2), _int(c, 3), _int(c, 4), _int(c, 5)
    a, j = _real(c, 6, 0.0), _real(c, 7, 0.0)
    _ignored_reals(c, (8, 9))
    r.claim("element", eid, c, 2)
    r.deck.rods[eid] = Rod(eid, ga, gb, mid=mid, a=a, j=j, card="CONROD", src=c.src)


def _ctube(r, c) -> None:
    """CTUBE: EID PID (default EID) G1 G2 [EID PID G1 G2]: a rod whose section is a PTUBE's
    (:func:`_pair_of_rods`)."""
    _pair_of_rods(r, c, "CTUBE")


def tube_section(od: float, t: float) -> tuple[float, float]:
    """``(A, J)`` of a circular tube of outer diameter ``od`` and wall ``t`` (MSC QRG PTUBE):
    A = pi (OD^2 - D^2) / 4 and the polar moment J = pi (OD^4 - D^4) / 32, D = OD - 2 T the
    inner diameter (T = OD / 2: a solid bar)."""
    d = od - 2.0 * t
    return math.pi * (od ** 2 - d ** 2) / 4.0, math.pi * (od ** 4 - d ** 4) / 32.0


def _ptube(r, c) -> None:
    """PTUBE: PID MID OD T NSM OD2 (MSC QRG): T blank is a solid bar (T = OD / 2); NSM is mass
    (no effect on the stiffness); OD2 (a tapered tube) must be blank or equal to OD."""
    _max_fields(c, 7)
    pid, mid = _int(c, 2), _int(c, 3)
    od = _real(c, 4)
    if not od > 0.0:
        raise c.error(4, "outer diameter OD must be > 0")
    t = _real(c, 5, od / 2.0)
    if not 0.0 < t <= od / 2.0:
        raise c.error(5, f"wall thickness T must be in (0, OD/2 = {od / 2.0:g}] (blank: solid)")
    _ignored_reals(c, (6,))
    if c.text(7) and _real(c, 7) != od:
        raise c.error(7, "a tapered tube (OD2 other than OD) is not supported: blank or OD")
    a, j = tube_section(od, t)
    r.claim("property", pid, c, 2)
    r.deck.prods[pid] = Prod(pid, mid, a, j, c.src, card="PTUBE")


PARSERS = {"CROD": _crod, "PROD": _prod, "CONROD": _conrod, "CTUBE": _ctube, "PTUBE": _ptube}
BULK = {"CROD": bulk_crod}
