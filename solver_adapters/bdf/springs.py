"""CBUSH/PBUSH bushings and the scalar springs PELAS, CELAS1, CELAS2, CELAS3, CELAS4."""

from __future__ import annotations

import re

from solver_adapters.bdf.fields import _ignored_reals, _int, _max_fields, _orientation, _real
from solver_adapters.deck import Bush, PBush, Pelas, Spring


def _cbush(r, c) -> None:
    """CBUSH: EID PID GA GB GO/X1 X2 X3 CID / S OCID S1 S2 S3 (MSC QRG). The element axes are
    CID's (CID >= 0) or, with CID blank, x from GA to GB and the orientation vector (GO, or X
    in GA's CD system) in the x-y plane. The springs are at one point: with OCID blank or -1 on
    the line GA-GB at S (default 0.5); with OCID >= 0 at GA plus the offset S1 S2 S3 given in
    system OCID (its axes at GA; 0: basic), S then ignored (MSC QRG CBUSH remark 8; S1-S3 with
    OCID -1 are ignored as in NASTRAN, with a note)."""
    _max_fields(c, 14)
    eid = _int(c, 2)
    pid = _int(c, 3, eid)
    ga, gb = _int(c, 4), _int(c, 5, 0, minimum=0)
    x, g0 = _orientation(c)
    cid = _int(c, 9, None, minimum=0) if c.text(9) else None
    s = _real(c, 10, 0.5)
    if not 0.0 <= s <= 1.0:
        raise c.error(10, "spring location S must be in [0, 1]")
    ocid = _int(c, 11, -1, minimum=-1)
    offset = (_real(c, 12, 0.0), _real(c, 13, 0.0), _real(c, 14, 0.0))
    if ocid == -1:
        if any(offset):
            r.note(c, "CBUSH S1-S3 with OCID blank or -1 are ignored (as in NASTRAN: the spring "
                      "is on the line GA-GB at S)")
        offset = None
    elif ocid != 0 and ocid not in r.cords:
        r.pending_cids.append((c, ocid, 11))
    if cid is None and x is None and g0 is None and gb == 0:
        raise c.error(9, "a grounded CBUSH needs CID (or an orientation) for its element axes")
    if cid is not None and cid not in r.cords and cid != 0:
        r.pending_cids.append((c, cid, 9))
    r.claim("element", eid, c, 2)
    r.deck.bushes[eid] = Bush(eid, pid, ga, gb, x, g0, cid, s, c.src,
                              ocid if offset is not None else -1, offset)


def _pbush(r, c) -> None:
    """PBUSH: PID "K" K1..K6 / blank "B" B1..B6 / blank "GE" GE1..GE6 / blank "RCV" SA ST EA ET
    (one line each, any order, the keywords in field 3 of each line). The K line is the stiffness (blank: 0); damping B, GE and the stress recovery
    coefficients RCV are read and have no effect on a static solve. Other keywords (M, the
    frequency-dependent FREQ lines) are errors."""
    pid = _int(c, 2)
    k = (0.0,) * 6
    seen = set()
    # keyword fields: 3 on the first line, then the second field of each continuation line
    # (the first one blank), so that the keywords line up in field 3 of every line
    for i in range(3, len(c.fields) + 1, 8):
        key = c.text(i)
        if i > 3 and c.text(i - 1):
            raise c.error(i - 1, "field must be blank (a PBUSH continuation line starts with a "
                                 "blank field, then the keyword K, B, GE or RCV)")
        if not any(c.text(j) for j in range(i, i + 7)):
            continue
        if key not in ("K", "B", "GE", "RCV") or key in seen:
            raise c.error(i, f"PBUSH line keyword {key or '(blank)'} not supported: one each of "
                             f"K, B, GE, RCV")
        seen.add(key)
        values = tuple(_real(c, j, 0.0) for j in range(i + 1, i + 7))
        if key == "K":
            k = values
    if "K" not in seen:
        raise c.error(3, "PBUSH needs a K line (stiffnesses K1..K6)")
    r.claim("property", pid, c, 2)
    r.deck.pbushes[pid] = PBush(pid, k, c.src)


def _pelas(r, c) -> None:
    _max_fields(c, 9)
    for base in (2, 6):
        if base == 6 and not any(c.text(i) for i in range(6, 10)):
            break
        pid, k = _int(c, base), _real(c, base + 1)
        _ignored_reals(c, (base + 2, base + 3))  # GE, S
        r.claim("property", pid, c, base)
        r.deck.pelas[pid] = Pelas(pid, k, c.src)


def _spring_end(r, c, ig: int) -> tuple[int, int]:
    """G and C of one end (MSC QRG CELAS1/2: C is 1-6 on a grid, 0 or blank on a scalar point;
    G blank or 0: grounded). Component 0 stands for a scalar point's DOF until the reader's
    ``finish`` has checked that G is one."""
    g = _int(c, ig, 0, minimum=0)
    text = c.text(ig + 1)
    if g == 0:
        if text not in ("", "0"):
            raise c.error(ig + 1, "component given for a grounded end (G blank or 0)")
        return 0, 0
    if text in ("", "0"):
        r.point_refs.append((c, ig + 1, g, 0))
        return g, 0
    if not re.fullmatch(r"[1-6]", text):
        raise c.error(ig + 1, "component must be one digit 1-6 (a grid) or 0 or blank (a scalar point)")
    r.point_refs.append((c, ig + 1, g, int(text)))
    return g, int(text)


def _scalar_end(r, c, i: int) -> tuple[int, int]:
    """S of CELAS3/CELAS4: a scalar point (component 0 until checked) or blank/0 (grounded)."""
    g = _int(c, i, 0, minimum=0)
    if g:
        r.point_refs.append((c, i, g, 0))
    return g, 0


def _celas(r, c) -> None:
    """CELAS1 EID PID G1 C1 G2 C2; CELAS2 EID K G1 C1 G2 C2 GE S; CELAS3 EID PID S1 S2;
    CELAS4 EID K S1 S2 (MSC QRG: CELAS3/CELAS4 join scalar points only; GE, S have no effect).
    A CELAS3/CELAS4 may define a second element in fields 6-9 (NASTRAN-95 User's Manual, CELAS3
    remark 3: "One or two scalar springs may be defined on a single card")."""
    scalar = c.name in ("CELAS3", "CELAS4")
    _max_fields(c, {"CELAS1": 7, "CELAS2": 9, "CELAS3": 9, "CELAS4": 9}[c.name])
    for b in (0, 4) if scalar else (0,):
        if b and not any(c.text(i) for i in range(6, 10)):
            break
        eid = _int(c, 2 + b)
        if c.name in ("CELAS1", "CELAS3"):
            pid, k = _int(c, 3 + b, eid), None
        else:
            pid, k = None, _real(c, 3 + b)
            if c.name == "CELAS2":
                _ignored_reals(c, (8, 9))  # GE, S
        if scalar:
            (g1, c1), (g2, c2) = _scalar_end(r, c, 4 + b), _scalar_end(r, c, 5 + b)
        else:
            (g1, c1), (g2, c2) = _spring_end(r, c, 4), _spring_end(r, c, 6)
        if g1 == 0:
            if g2 == 0:
                raise c.error(4 + b, "both ends of the spring are grounded")
            (g1, c1), (g2, c2) = (g2, c2), (g1, c1)
        r.claim("element", eid, c, 2 + b)
        r.deck.springs[eid] = Spring(eid, g1, c1, g2, c2, k, pid, c.name, c.src)


PARSERS = {"CBUSH": _cbush, "PBUSH": _pbush, "PELAS": _pelas, "CELAS1": _celas, "CELAS2": _celas,
           "CELAS3": _celas, "CELAS4": _celas}
