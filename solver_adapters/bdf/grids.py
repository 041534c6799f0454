"""GRID, SPOINT, GRDSET and the coordinate systems CORD1R/C/S, CORD2R/C/S."""

from __future__ import annotations

from itertools import repeat

import numpy as np

from solver_adapters.bdf.fields import (_blank, _components, _id_list, _int, _max_fields, _real,
                                       valid_components)
from solver_adapters.bdf.numbers import int_column, real_column
from solver_adapters.bdf.table import entities
from solver_adapters.deck import Coord, Grid

# Two directions closer than this (sine of the angle) give no usable element plane: the bar's
# y axis would be decided by the rounding of the input coordinates (about 1e-16 relative).
PARALLEL_SINE = 1e-9
# A bar shorter than this fraction of its coordinates' magnitude has no direction above rounding.
ZERO_LENGTH = 1e-12


def _grid(r, c) -> None:
    """GRID ID CP X1 X2 X3 CD PS SEID; a blank CP, CD, PS or SEID takes the GRDSET value (applied
    in ``finish``, which also converts X1-X3 from the CP system to basic). PS 0 is no constraint
    (NASTRAN-95 User's Manual, GRID: "Integer >= 0 or blank"), and not blank: GRDSET's PS does not
    apply to it."""
    _max_fields(c, 9)
    gid = _int(c, 2)
    cp = _int(c, 3, 0, minimum=0)
    xyz = (_real(c, 4, 0.0), _real(c, 5, 0.0), _real(c, 6, 0.0))
    cd = _int(c, 7, 0, minimum=0)
    ps = "" if c.text(8) == "0" else _components(c, 8, required=False)
    if _int(c, 9, 0, minimum=0) != 0:
        raise c.error(9, "superelements are not supported: SEID must be blank")
    r.claim("GRID", gid, c, 2)
    r.deck.grids[gid] = Grid(gid, xyz, ps, c.src, cp, cd)
    if cp or cd:
        r.grid_cards[gid] = c
    for i, key in ((3, "CP"), (7, "CD"), (9, "SEID")):
        if not c.text(i):
            if r.first_blank[key] is None:
                r.first_blank[key] = gid
            if key != "SEID":
                r.blank_sys[key].append(gid)
    if not c.text(8):
        r.blank_ps.append(gid)


def bulk_grid(r, table, cards: np.ndarray) -> np.ndarray:
    """GRIDs in bulk (as :func:`_grid` reads each); returns the cards left to :func:`_grid`."""
    M = table.matrix(cards, 8)                  # columns 1-8: fields 2-9
    ok = ~(M[:, 9:] != b"").any(axis=1)
    gid, k = int_column(M[:, 1]); ok &= k
    cp, k = int_column(M[:, 2], 0, 0); ok &= k
    xyz = np.empty((len(cards), 3))
    for j in range(3):
        xyz[:, j], k = real_column(M[:, 3 + j], 0.0); ok &= k
    cd, k = int_column(M[:, 6], 0, 0); ok &= k
    seid, k = int_column(M[:, 8], 0, 0); ok &= k & (seid == 0)
    ps_col = M[:, 7]
    if ps_col.any():
        ps_u, ps_inv = np.unique(ps_col, return_inverse=True)
    else:
        ps_u, ps_inv = ps_col[:1], np.zeros(len(cards), np.int64)
    ps_map = []
    for v in ps_u.tolist():
        t = v.decode("utf-8", "replace")
        ps_map.append("" if t == "0" else "".join(sorted(t)) if not t or valid_components(t) else None)
    ps_bad = np.array([p is None for p in ps_map], bool)
    ok &= ~ps_bad[ps_inv.ravel()]
    rows = np.flatnonzero(ok)
    if rows.size:
        sel = cards[rows]
        ids = gid[rows].tolist()
        src = table.src(sel)
        pss = repeat(ps_map[0]) if len(ps_map) == 1 else [ps_map[i] for i in ps_inv.ravel()[rows].tolist()]
        cpl = cp[rows].tolist() if cp[rows].any() else repeat(0)
        cdl = cd[rows].tolist() if cd[rows].any() else repeat(0)
        grids = entities(Grid, ("id", "xyz", "ps", "src", "cp", "cd"),
                         zip(ids, map(tuple, xyz[rows].tolist()), pss, src, cpl, cdl))
        r.bulk("grids", "GRID", sel, ids, grids)
        sys_rows = np.flatnonzero((cp[rows] != 0) | (cd[rows] != 0))
        for i in sys_rows.tolist():
            r.grid_cards[ids[i]] = int(sel[i])
        blank = M[rows][:, [2, 6, 8, 7]] == b""
        for j, key in enumerate(("CP", "CD", "SEID")):
            b = np.flatnonzero(blank[:, j])
            if b.size:
                r.note_blank(key, int(sel[b[0]]), ids[b[0]])
                if key != "SEID":
                    r.blank_sys[key].extend(gid[rows][b].tolist())
        b = np.flatnonzero(blank[:, 3])
        if b.size:
            r.blank_ps.extend(gid[rows][b].tolist())
    return cards[~ok]


def _grdset(r, c) -> None:
    """GRDSET: defaults for the GRID fields CP (3), CD (7), PS (8), SEID (9); checked and applied
    to the GRIDs in ``finish`` (a non-zero CP, CD or SEID is an error once a GRID would use it)."""
    _max_fields(c, 9)
    for i in (2, 4, 5, 6):
        _blank(c, i, f"GRDSET field {i}")
    for i in (3, 7, 9):
        _int(c, i, 0, minimum=0)
    if c.text(8) != "0":
        _components(c, 8, required=False)
    if r.grdset is not None:
        raise c.error(1, f"only one GRDSET is allowed (the first is at {r.grdset.src})")
    r.grdset = c


def _cord2(r, c) -> None:
    """CORD2R/C/S: CID RID A1 A2 A3 B1 B2 B3 / C1 C2 C3 (MSC QRG): A the origin, B on the z axis,
    C in the x-z plane, all three in system RID (0 or blank: basic)."""
    _max_fields(c, 12)
    cid = _int(c, 2)
    rid = _int(c, 3, 0, minimum=0)
    if rid == cid:
        raise c.error(3, f"RID {rid} is the system itself")
    pts = tuple(tuple(_real(c, i + k, 0.0) for k in range(3)) for i in (4, 7, 10))
    r.claim("CORD", cid, c, 2)
    r.cords[cid] = (c.name[-1], c, (rid, pts))


def _cord1(r, c) -> None:
    """CORD1R/C/S: CIDA G1A G2A G3A [CIDB G1B G2B G3B]: the system through three grids (G1 the
    origin, G2 on the z axis, G3 in the x-z plane), one or two systems per card."""
    _max_fields(c, 9)
    for base in (2, 6):
        if base == 6 and not any(c.text(i) for i in range(6, 10)):
            break
        cid = _int(c, base)
        grids = tuple(_int(c, base + k) for k in (1, 2, 3))
        if len(set(grids)) < 3:
            raise c.error(base + 1, "G1, G2 and G3 must be three different grids")
        r.claim("CORD", cid, c, base)
        r.cords[cid] = (c.name[-1], c, (base, grids))


def coord_from_points(cid: int, kind: str, pts: np.ndarray, c, d: tuple) -> Coord:
    """The system with origin ``pts[0]``, z axis towards ``pts[1]``, x-z plane through ``pts[2]``
    (basic positions): z = (B - A)/|B - A|, y = z x (C - A) normalized, x = y x z (MSC QRG, CORD2R)."""
    a, b, cc = pts
    scale = max(np.abs(pts).max(), 1e-300)
    ez = b - a
    first = 4 if c.name.startswith("CORD2") else d[0] + 1    # field of A (CORD2) or G1 (CORD1)
    step = 3 if c.name.startswith("CORD2") else 1
    if np.linalg.norm(ez) <= ZERO_LENGTH * scale:
        raise c.error(first + step, f"coordinate system {cid}: the z-axis point coincides with "
                                    f"the origin")
    ez = ez / np.linalg.norm(ez)
    ey = np.cross(ez, cc - a)
    if np.linalg.norm(ey) <= PARALLEL_SINE * max(np.linalg.norm(cc - a), 1e-300):
        raise c.error(first + 2 * step, f"coordinate system {cid}: the x-z plane point lies on "
                                        f"the z axis")
    ey = ey / np.linalg.norm(ey)
    ex = np.cross(ey, ez)
    return Coord(cid, kind, tuple(a.tolist()), (tuple(ex.tolist()), tuple(ey.tolist()),
                                               tuple(ez.tolist())), c.name, c.src)


def _spoint(r, c) -> None:
    """SPOINT ID1 ID2 ... or ID1 THRU ID2 (MSC QRG SPOINT): scalar points, each one degree of
    freedom, held in ``Deck.grids`` as a ``Grid`` with ``scalar`` set (component 1 its DOF,
    2-6 held). Their IDs share the grids' ID space, as NASTRAN requires."""
    items = _id_list(c, 2, len(c.fields))
    if not items:
        raise c.error(2, "SPOINT needs at least one scalar point ID")
    for item in items:
        lo, hi = item if isinstance(item, tuple) else (item, item)
        if lo < 1:
            raise c.error(2, f"scalar point ID {lo} must be positive")
        for sid in range(lo, hi + 1):
            if sid in r.spoints:     # NASTRAN allows a scalar point to be listed twice
                continue
            r.claim("GRID", sid, c, 2)
            r.spoints[sid] = Grid(sid, (0.0, 0.0, 0.0), "23456", c.src, 0, 0, True)


PARSERS = {"GRID": _grid, "SPOINT": _spoint, "GRDSET": _grdset, **{f"CORD2{k}": _cord2 for k in "RCS"},
           **{f"CORD1{k}": _cord1 for k in "RCS"}}
BULK = {"GRID": bulk_grid}
