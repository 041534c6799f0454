"""DMIG: direct matrix input at grid points, a stiffness added in the g-set (NASTRAN's K2GG);
GENEL, the general element (its stiffness given as a matrix, :func:`_genel`).

MSC QRG DMIG: a header ``DMIG NAME 0 IFO TIN TOUT POLAR NCOL`` and column entries ``DMIG NAME
GJ CJ (blank) G1 C1 A1 B1 / G2 C2 A2 B2 ...``: the terms A of column (GJ, CJ), rows (Gi, Ci),
in the grids' displacement systems (the g-set). A study's model adds every DMIG matrix of its
deck to the stiffness, times PARAM,CK2 (default 1.0), as NASTRAN adds the matrices its case
control selects with ``K2GG = NAME``: ``blackbox import`` keeps only those (docs/import.md).

Read: IFO 6 (symmetric: one of the two off-diagonal terms given, the other its mirror) and 1
(square; it must be symmetric, as a stiffness of the reference solver is), TIN 1 or 2 (real). A
scalar point's component is 0 (held as component 1, as springs name it). Refused, located:
another IFO (rectangular, diagonal ...), complex input, a term given twice (or both of a
symmetric pair), a square matrix that is not symmetric, a column without a header, a point
that does not exist.
"""

from __future__ import annotations

import numpy as np

from solver_adapters.bdf.fields import _int, _real
from solver_adapters.deck import Dmig


def _dmig(r, c) -> None:
    name = c.text(2)
    if not name:
        raise c.error(2, "DMIG needs the matrix NAME")
    if c.text(3) == "0":
        if name in r.dmig_headers:
            raise c.error(2, f"DMIG {name} has a header already ({r.dmig_headers[name].src})")
        ifo, tin = _int(c, 4), _int(c, 5)
        if ifo not in (1, 6):
            raise c.error(4, f"IFO = {ifo}: only a square (1) or symmetric (6) matrix is a stiffness "
                             f"the study adds (K2GG)")
        if tin not in (1, 2):
            raise c.error(5, f"TIN = {tin}: only real input (1, 2) is read (a static stiffness is real)")
        _int(c, 6, 0, minimum=0)                 # TOUT
        if _int(c, 7, 0, minimum=0):
            raise c.error(7, "POLAR is for complex terms: must be blank or 0")
        r.dmig_headers[name] = c
        return
    gj = _int(c, 3)
    cj = _int(c, 4, 0, minimum=0)
    if c.text(5):
        raise c.error(5, "field 5 of a DMIG column entry must be blank")
    terms = []
    for i in range(6, len(c.fields) + 1, 4):
        if not any(c.text(k) for k in range(i, i + 4)):
            continue
        g, comp = _int(c, i), _int(c, i + 1, 0, minimum=0)
        a = _real(c, i + 2)
        if c.text(i + 3) and _real(c, i + 3) != 0.0:
            raise c.error(i + 3, "an imaginary part B: only real terms are read")
        terms.append((g, comp, a, i))
    if not terms:
        raise c.error(6, "a DMIG column entry needs at least one term G1 C1 A1")
    r.dmig_columns.setdefault(name, []).append((c, gj, cj, terms))


_GENEL_WORDS = ("UD", "K", "Z", "S")


def _genel(r, c) -> None:
    """GENEL EID (blank) UI1 CI1 UI2 CI2 ... ["UD" (blank) UD1 CD1 ...] "K"|"Z" KZ11 KZ21 ...
    ["S" S11 S12 ...] (NASTRAN-95 User's Manual 2.4; MSC QRG GENEL): each keyword in field 2 of
    a line; KZ the lower triangle of the stiffness K or flexibility Z over the UI list, by
    columns; S the m x n matrix over UI and UD by rows. The element stiffness over (UI, UD) is
    ``[[K, -K S], [-S^T K, S^T K S]]`` (``K = Z^-1``); without UD, K alone (the UI components
    against ground); with UD and no S, S is the rigid-body motion of the UI points when the UD
    components move (:func:`_rigid_s`). Resolved in :func:`finish` (the grids may come later)."""
    eid = _int(c, 2)
    if c.text(3):
        raise c.error(3, "GENEL field 3 must be blank")
    n = len(c.fields)

    def keyword(i: int) -> bool:         # a keyword stands in field 2 of a continuation line
        return i >= 10 and (i - 2) % 8 == 0 and c.text(i) in _GENEL_WORDS

    def pairs(i: int, what: str) -> tuple[list, int]:
        out = []
        while i <= n and not keyword(i):
            if c.text(i) or c.text(i + 1):
                out.append((_int(c, i), _int(c, i + 1, 0, minimum=0), i))
            i += 2
        if not out:
            raise c.error(i, f"GENEL {eid}: the {what} list is empty")
        return out, i

    ui, i = pairs(4, "UI")
    ud: list = []
    if i <= n and c.text(i) == "UD":
        if c.text(i + 1):
            raise c.error(i + 1, "the field after UD must be blank")
        ud, i = pairs(i + 2, "UD")
    if i > n or c.text(i) not in ("K", "Z"):
        raise c.error(min(i, n), f"GENEL {eid} needs its matrix: K (stiffness) or Z (flexibility) in "
                                 f"field 2 of a continuation line after the UI{'/UD' if ud else ''} list")
    form, start = c.text(i), i

    def values(i: int) -> tuple[list, int]:
        out = []
        while i <= n and not keyword(i):
            if c.text(i):
                out.append((_real(c, i), i))
            i += 1
        return out, i

    kz, i = values(i + 1)
    m = len(ui)
    if len(kz) != m * (m + 1) // 2:
        raise c.error(start, f"GENEL {eid}: {form} needs the lower triangle of an {m} x {m} matrix "
                             f"({m * (m + 1) // 2} values by columns), got {len(kz)}")
    s_values = None
    if i <= n and c.text(i) == "S":
        if not ud:
            raise c.error(i, f"GENEL {eid}: S without a UD list")
        s_values, j = values(i + 1)
        if len(s_values) != m * len(ud):
            raise c.error(i, f"GENEL {eid}: S needs {m} x {len(ud)} values (by rows), got {len(s_values)}")
        i = j
    if i <= n:
        raise c.error(i, f"GENEL {eid}: {c.text(i)} out of place (the order is UI, UD, K or Z, S)")
    r.claim("element", eid, c, 2)
    r.genels.append((c, eid, ui, ud, form, [v for v, _ in kz], None if s_values is None else [v for v, _ in s_values]))


def _rigid_s(r, c, eid: int, ui: list, ud: list) -> np.ndarray:
    """S of a GENEL given without one: column j the UI components' motion when UD component j
    moves the element as a rigid body (a translation, or a rotation about the UD grid), which
    needs every UD component on one grid and every point a grid in the basic system (the
    manual's rule: six UD components of one point; fewer move it in their own directions only)."""
    grids = r.deck.grids
    owners = {g for g, _ in ud}
    if len(owners) != 1:
        raise c.error(4, f"GENEL {eid}: S omitted, and the UD components are on {len(owners)} points: "
                         f"give S (S is computed only for the components of one grid)")
    gd = grids[next(iter(owners))]
    for g in {g for g, _ in ui} | owners:
        if grids[g].scalar or grids[g].cd:
            raise c.error(4, f"GENEL {eid}: S omitted, and point {g} is "
                             f"{'a scalar point' if grids[g].scalar else f'in displacement system {grids[g].cd}'}: "
                             f"give S (it is computed for grids in the basic system only)")
    S = np.zeros((len(ui), len(ud)))
    eye = np.eye(3)
    for j, (_, cd) in enumerate(ud):
        for i, (g, ci) in enumerate(ui):
            if cd <= 3:                           # a unit translation: translations only
                S[i, j] = eye[cd - 1][ci - 1] if ci <= 3 else 0.0
            else:                                 # a unit rotation about the UD grid
                axis = eye[cd - 4]
                if ci <= 3:
                    S[i, j] = np.cross(axis, np.subtract(grids[g].xyz, gd.xyz))[ci - 1]
                else:
                    S[i, j] = axis[ci - 4]
    return S


def _finish_genels(r, dof) -> None:
    for c, eid, ui, ud, form, kz, s_values in r.genels:
        ui_d = [dof(c, g, comp, i) for g, comp, i in ui]
        ud_d = [dof(c, g, comp, i) for g, comp, i in ud]
        both = ui_d + ud_d
        if len(set(both)) != len(both):
            raise c.error(4, f"GENEL {eid} names a component twice in its UI and UD lists")
        m = len(ui)
        M = np.zeros((m, m))
        M[np.triu_indices(m)[::-1]] = kz          # the lower triangle, by columns
        M = np.tril(M) + np.tril(M, -1).T
        if form == "Z":
            try:
                K = np.linalg.inv(M)
            except np.linalg.LinAlgError:
                raise c.error(4, f"GENEL {eid}: its flexibility Z is singular") from None
            K = (K + K.T) / 2.0
        else:
            K = M
        if ud:
            S = (np.array(s_values, float).reshape(m, len(ud)) if s_values is not None
                 else _rigid_s(r, c, eid, [(g, comp) for g, comp, _ in ui], [(g, comp) for g, comp, _ in ud]))
            KS = K @ S
            E = np.block([[K, -KS], [-KS.T, S.T @ KS]])
            E = (E + E.T) / 2.0
        else:
            E = K
        terms = tuple((both[a], both[b], float(E[a, b])) for a in range(len(both)) for b in range(len(both))
                      if E[a, b] != 0.0)
        name = f"GENEL{eid}"
        if name in r.deck.dmigs:
            raise c.error(2, f"GENEL {eid}: a DMIG is named {name} too ({r.deck.dmigs[name].src})")
        r.deck.dmigs[name] = Dmig(name, 1, terms, c.src, card="GENEL")


def finish(r) -> None:
    """The matrices into ``Deck.dmigs``: headers and columns matched, points and components
    checked, the symmetry rules applied; the GENEL elements' stiffness matrices."""
    for name, cols in r.dmig_columns.items():
        if name not in r.dmig_headers:
            c = cols[0][0]
            raise c.error(2, f"DMIG {name} has no header (DMIG {name} 0 IFO TIN ...)")
    grids = r.deck.grids

    def dof(c, g: int, comp: int, i: int) -> tuple[int, int]:
        if g not in grids:
            raise c.error(i, f"point {g} does not exist (no GRID or SPOINT)")
        if grids[g].scalar:
            if comp not in (0, 1):
                raise c.error(i + 1, f"point {g} is a scalar point: component must be 0 or blank")
            return g, 1
        if not 1 <= comp <= 6:
            raise c.error(i + 1, f"component {comp} of GRID {g} must be 1-6")
        return g, comp

    for name, h in r.dmig_headers.items():
        ifo = _int(h, 4)
        seen: dict[tuple, str] = {}
        terms = []
        for c, gj, cj, entries in r.dmig_columns.get(name, []):
            col = dof(c, gj, cj, 3)
            for g, comp, a, i in entries:
                row = dof(c, g, comp, i)
                key = (row, col)
                mirror = (col, row)
                if key in seen or (ifo == 6 and row != col and mirror in seen):
                    raise c.error(i, f"DMIG {name} term ({row[0]}-{row[1]}, {col[0]}-{col[1]}) is "
                                     f"given twice{' (with its symmetric mirror)' if key not in seen else ''} "
                                     f"(first at {seen.get(key) or seen.get(mirror)})")
                seen[key] = c.src
                terms.append((row, col, a))
        if ifo == 1:
            value = {(row, col): a for row, col, a in terms}
            for (row, col), a in value.items():
                if value.get((col, row), 0.0) != a:
                    raise h.error(4, f"DMIG {name} (IFO = 1, square) is not symmetric: term "
                                     f"({row[0]}-{row[1]}, {col[0]}-{col[1]}) = {a:g}, its mirror "
                                     f"{value.get((col, row), 0.0):g}; a stiffness the study adds "
                                     f"must be symmetric")
        r.deck.dmigs[name] = Dmig(name, ifo, tuple(terms), h.src)
    _finish_genels(r, dof)


PARSERS = {"DMIG": _dmig, "GENEL": _genel}
