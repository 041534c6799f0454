"""CBAR, BAROR, PBAR, PBARL, and the bulk converter of CBAR and CBEAM cards."""

from __future__ import annotations

from itertools import repeat

import numpy as np

from solver_adapters.bdf.fields import (_blank, _components, _ignored_reals, _int, _max_fields,
                                        _orientation, _pin, _real, valid_components)
from solver_adapters.bdf.numbers import int_column, int_like, real_column, strings
from solver_adapters.bdf.sections import library_pbar, library_section
from solver_adapters.bdf.table import entities
from solver_adapters.deck import CBar, PBar

_CBAR_KEYS = ("eid", "pid", "ga", "gb", "x", "g0", "src", "pa", "pb", "wa", "wb", "card")

OFFT = ("GGG", "BGG", "GGO", "BGO", "GOG", "BOG", "GOO", "BOO")
"""The OFFT values of NASTRAN's CBAR and CBEAM (MSC QRG, CBAR remark 8): orientation vector
in GA's displacement system (G) or basic (B), then each end's offset in its grid's
displacement system (G) or in the offset system (O); converted to basic by
``_Reader.resolve_bars``."""


def _offt(c, x=None, g0=None) -> str:
    """OFFT (field 9): one of :data:`OFFT` (blank: BAROR's, else GGG), returned as written.

    COSMIC NASTRAN's CBAR and BAROR have the flag F there instead (NASTRAN-95 User's Manual,
    CBAR): 1, the orientation given as the vector X1 X2 X3; 2, as the grid G0. Both are in GA's
    displacement system, and the offsets in each end's, as OFFT GGG: taken as GGG, the flag
    checked against the fields it describes."""
    t = c.text(9)
    if t in ("1", "2"):
        if (t == "1" and g0 is not None) or (t == "2" and x is not None):
            raise c.error(9, f"flag F = {t} (COSMIC NASTRAN) says the orientation is given "
                             f"{'as a vector X1 X2 X3' if t == '1' else 'as a grid G0'}; fields 6-8 give "
                             f"{'a grid' if t == '1' else 'a vector'}")
        return "GGG"
    if t not in ("", *OFFT):
        raise c.error(9, f"offset option OFFT must be one of {', '.join(OFFT)} (orientation vector "
                         f"in GA's displacement system G or basic B, then each end's offset in its "
                         f"grid's displacement system G or in the offset system O; COSMIC NASTRAN's "
                         f"flag F, 1 or 2, as GGG)")
    return t


def _cbar(r, c) -> None:
    """CBAR: EID PID GA GB X1/G0 X2 X3 OFFT / PA PB W1A W2A W3A W1B W2B W3B.

    A blank PID, orientation or OFFT takes the BAROR value (applied in ``finish``); a blank PID
    without BAROR PID is the EID. The orientation vector and offsets are converted to basic in
    ``resolve_coordinates``."""
    _max_fields(c, 17)
    eid = _int(c, 2)
    pid = _int(c, 3, eid)
    ga, gb = _int(c, 4), _int(c, 5)
    x, g0 = _orientation(c)
    offt = _offt(c, x, g0)
    pa, pb = _pin(c, 10), _pin(c, 11)
    wa = tuple(_real(c, i, 0.0) for i in (12, 13, 14))
    wb = tuple(_real(c, i, 0.0) for i in (15, 16, 17))
    r.claim("element", eid, c, 2)
    if offt:
        r.cbar_offt[eid] = offt
    r.deck.cbars[eid] = CBar(eid, pid, ga, gb, x, g0, c.src, pa, pb,
                             wa if any(wa) else None, wb if any(wb) else None)
    if not c.text(3):
        r.pid_blank.append(eid)
    if x is None and g0 is None:
        r.orient_blank.append((eid, c))


def _pins(col: np.ndarray) -> tuple[list[str] | None, np.ndarray]:
    """Pin-flag fields: the sorted digits of each (``""`` for blank or 0; None: all blank) and
    which are valid."""
    if not col.any():
        return None, np.ones(len(col), bool)
    u, inv = np.unique(col, return_inverse=True)
    values, bad = [], []
    for v in u.tolist():
        t = v.decode("utf-8", "replace").upper()
        values.append("" if t in ("", "0") else "".join(sorted(t)))
        bad.append(t not in ("", "0") and not valid_components(t))
    inv = inv.ravel()
    return [values[i] for i in inv.tolist()], ~np.array(bad, bool)[inv]


def bulk_bars(r, table, cards: np.ndarray, beam: bool) -> np.ndarray:
    """CBARs (``beam``: CBEAMs) in bulk, as :func:`_cbar` (:func:`.beams._cbeam`) reads each;
    returns the cards left to those parsers (anything but the common layouts)."""
    n = len(cards)
    last = 19 if beam else 17
    M = table.matrix(cards, last - 1)
    ok = ~(M[:, last:] != b"").any(axis=1)
    if beam:
        ok &= (M[:, 17] == b"") & (M[:, 18] == b"")                 # SA, SB
    eid, k = int_column(M[:, 1]); ok &= k
    pid, k = int_column(M[:, 2], 0); ok &= k
    pid_blank = M[:, 2] == b""
    pid = np.where(pid_blank, eid, pid)
    ga, k = int_column(M[:, 3]); ok &= k
    gb, k = int_column(M[:, 4]); ok &= k
    o = M[:, 5:8]
    is_g0 = int_like(o[:, 0])
    ok &= ~is_g0 | ((o[:, 1] == b"") & (o[:, 2] == b""))
    g0 = np.zeros(n, np.int64)
    if is_g0.any():
        g0[is_g0], k = int_column(o[is_g0, 0]); ok[is_g0] &= k
    X = np.zeros((n, 3))
    for j in range(3):
        X[:, j], k = real_column(o[:, j], 0.0); ok &= k | is_g0
    orient_blank = (o == b"").all(axis=1)
    offt = strings.upper(M[:, 8])
    ok &= (offt == b"") | (offt == b"GGG") | (offt == b"BGG")
    pa, k = _pins(M[:, 9]); ok &= k
    pb, k = _pins(M[:, 10]); ok &= k
    W = np.zeros((n, 6))
    for j in range(6):
        W[:, j], k = real_column(M[:, 11 + j], 0.0); ok &= k
    if beam:
        ok &= ~orient_blank                      # BEAMOR defaults: the parser's error
    elif orient_blank.any():
        x_default, g0_default = _orientation(r.baror) if r.baror is not None else (None, None)
        if x_default is None and g0_default is None:
            ok &= ~orient_blank                  # no default: apply_baror's error
        elif g0_default is not None:
            is_g0 = is_g0 | orient_blank
            g0 = np.where(orient_blank, g0_default, g0)
        else:
            X[orient_blank] = x_default
    if not beam and r.baror is not None:
        baror_pid = _int(r.baror, 3, 0)
        if baror_pid:
            pid = np.where(pid_blank, baror_pid, pid)
    rows = np.flatnonzero(ok)
    if rows.size:
        sel = cards[rows]
        ids = eid[rows].tolist()
        g = is_g0[rows]
        if not g.any():
            xs, g0s = list(map(tuple, X[rows].tolist())), repeat(None)
        elif g.all():
            xs, g0s = repeat(None), g0[rows].tolist()
        else:
            xs = [None if a else x for a, x in zip(g.tolist(), map(tuple, X[rows].tolist()))]
            g0s = [int(v) if a else None for a, v in zip(g.tolist(), g0[rows].tolist())]
        Wr = W[rows]
        ends = []
        for half in (Wr[:, :3], Wr[:, 3:]):
            has = (half != 0).any(axis=1)
            ends.append(repeat(None) if not has.any() else
                        [tuple(w) if h else None for h, w in zip(has.tolist(), half.tolist())])
        pins = [repeat("") if p is None else [p[i] for i in rows.tolist()] for p in (pa, pb)]
        card = "CBEAM" if beam else "CBAR"
        bars = entities(CBar, _CBAR_KEYS, zip(ids, pid[rows].tolist(), ga[rows].tolist(), gb[rows].tolist(),
                                              xs, g0s, table.src(sel), *pins, *ends, repeat(card)))
        r.bulk("cbars", "element", sel, ids, bars)
        offts = offt[rows]
        for i in np.flatnonzero(offts != b"").tolist() if not beam else range(len(ids)):
            r.cbar_offt[ids[i]] = offts[i].decode() or "GGG"
    return cards[~ok]


def _baror(r, c) -> None:
    """BAROR: defaults for CBAR fields PID (3), X1 X2 X3 or G0 (6-8), OFFT (9)."""
    _max_fields(c, 9)
    for i in (2, 4, 5):
        _blank(c, i, f"BAROR field {i}")
    _int(c, 3, 0)
    _offt(c, *_orientation(c))
    if r.baror is not None:
        raise c.error(1, f"only one BAROR is allowed (the first is at {r.baror.src})")
    r.baror = c


def _pbar(r, c) -> None:
    """PBAR: PID MID A I1 I2 J NSM / C1 C2 D1 D2 E1 E2 F1 F2 / K1 K2 I12.

    K1, K2 (fields 18, 19): shear stiffness per unit length K1*A*G (plane 1), K2*A*G (plane 2).
    Blank is NASTRAN's default, infinite shear stiffness (Euler-Bernoulli); 0.0 is taken the same
    way (as MYSTRAN does). I12 (field 20): product of inertia, I1 * I2 > I12^2 required (QRG).
    NASTRAN ignores K1/K2 when I12 is non-zero (MSC and Autodesk QRG PBAR), and so does MYSTRAN 18
    (measured: the same displacements with and without them, tests/test_cards.py): they are
    ignored here too, with a note.
    """
    _max_fields(c, 20)
    pid, mid = _int(c, 2), _int(c, 3)
    a, i1, i2, j = (_real(c, i, 0.0) for i in (4, 5, 6, 7))
    _ignored_reals(c, [8] + list(range(10, 18)))  # NSM, stress recovery points C..F
    _blank(c, 9, "field 9")
    k: list[float | None] = []
    for i in (18, 19):
        value = _real(c, i, None)
        if value is not None and value < 0.0:
            raise c.error(i, "shear area factor must be > 0 (blank or 0.0: no shear flexibility)")
        if value and a == 0.0:
            raise c.error(i, "shear area factor needs a non-zero area A (NASTRAN: K1, K2 must be "
                             "blank if A = 0.0)")
        k.append(value or None)
    i12 = _real(c, 20, 0.0)
    if i12 != 0.0:
        if not i1 * i2 > i12 * i12:
            raise c.error(20, "product of inertia I12 needs I1 * I2 > I12^2")
        if k[0] or k[1]:
            r.note(c, "K1/K2 ignored beside a non-zero I12, as NASTRAN ignores them: no shear flexibility")
            k = [None, None]
    r.claim("property", pid, c, 2)
    r.deck.pbars[pid] = PBar(pid, mid, a, i1, i2, j, c.src, k[0], k[1], i12)


def _pbarl(r, c) -> None:
    """PBARL: PID MID GROUP TYPE / DIM1 ... DIMn NSM (MSC QRG). The section's A, I1, I2, J, K1,
    K2 (:func:`.sections.pbarl_section`) make an equivalent PBAR; NSM has no effect on the stiffness."""
    pid, mid, kind, dims = library_section(c, max_fields=True)
    library_pbar(r, c, pid, mid, kind, dims)


PARSERS = {"CBAR": _cbar, "BAROR": _baror, "PBAR": _pbar, "PBARL": _pbarl}
BULK = {"CBAR": lambda r, t, cards: bulk_bars(r, t, cards, beam=False)}
