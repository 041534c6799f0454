"""CROD, PROD and CONROD: axial and torsion members."""

from __future__ import annotations

import numpy as np

from solver_adapters.bdf.fields import _ignored_reals, _int, _max_fields, _real
from solver_adapters.bdf.numbers import int_column
from solver_adapters.deck import Prod, Rod


def _crod(r, c) -> None:
    """CROD: EID PID (default EID) G1 G2."""
    _max_fields(c, 5)
    eid = _int(c, 2)
    pid = _int(c, 3, eid)
    ga, gb = _int(c, 4), _int(c, 5)
    r.claim("element", eid, c, 2)
    r.deck.rods[eid] = Rod(eid, ga, gb, pid=pid, card="CROD", src=c.src)


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


PARSERS = {"CROD": _crod, "PROD": _prod, "CONROD": _conrod}
BULK = {"CROD": bulk_crod}
