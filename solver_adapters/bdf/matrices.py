"""DMIG: direct matrix input at grid points, a stiffness added in the g-set (NASTRAN's K2GG).

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


def finish(r) -> None:
    """The matrices into ``Deck.dmigs``: headers and columns matched, points and components
    checked, the symmetry rules applied."""
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


PARSERS = {"DMIG": _dmig}
