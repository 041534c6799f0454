"""RBE2, RBAR, RBE3 and NASTRAN-95's CRIGD1/CRIGD2: rigid and interpolation elements."""

from __future__ import annotations

from solver_adapters.bdf.fields import (_blank, _components, _id_list, _ignored_reals, _int,
                                        _max_fields, _real)
from solver_adapters.bdf.numbers import _INT, _real_or_none
from solver_adapters.deck import Rbe2, Rbe3


def _dependent_grids(c, first: int, last: int) -> list[int]:
    """The grid IDs of fields ``first``..``last``, ``A THRU B`` ranges expanded (a range over a
    million IDs long is an error at field ``first``)."""
    gm: list[int] = []
    for item in _id_list(c, first, last):
        if isinstance(item, tuple):
            if item[1] - item[0] > 1_000_000:
                raise c.error(first, f"THRU range {item[0]}-{item[1]} is too long")
            gm.extend(range(item[0], item[1] + 1))
        else:
            gm.append(item)
    return gm


def _rbe2(r, c) -> None:
    eid, gn = _int(c, 2), _int(c, 3)
    cm = _components(c, 4, required=True)
    last = len(c.fields)
    # optional ALPHA [TREF] after the grid list (thermal expansion: read, then ignored). Both are
    # reals, so they are told from grid IDs by their decimal point or exponent.
    nonblank = [i for i in range(5, last + 1) if c.text(i)]
    tail = [i for i in nonblank
            if not _INT.fullmatch(c.text(i)) and _real_or_none(c.text(i)) is not None]
    if tail:
        after = [i for i in nonblank if i > tail[0]]
        if len(after) > 1 or any(_INT.fullmatch(c.text(i)) for i in after):
            raise c.error(tail[0], "integer field given a real (only ALPHA and TREF, both reals, "
                                   "may follow the grid list)")
        for i in [tail[0]] + after:
            _real(c, i)
        last = tail[0] - 1
    gm = _dependent_grids(c, 5, last)
    if not gm:
        raise c.error(5, "RBE2 needs at least one dependent grid GM")
    r.claim("element", eid, c, 2)
    r.deck.rbe2s[eid] = Rbe2(eid, gn, cm, tuple(gm), c.src)


def _rbe3(r, c) -> None:
    """RBE3: EID (blank) REFGRID REFC WT1 C1 G1,1 G1,2 ... WT2 C2 G2,1 ... [ALPHA a [TREF t]].

    Each weight group is a real WT, component digits C and one or more grids (blank fields
    between them are skipped). UM (dependent components moved to independent grids) is not
    supported (error); ALPHA and TREF are read and have no effect."""
    eid = _int(c, 2)
    _blank(c, 3, "field 3")
    ref = _int(c, 4)
    refc = _components(c, 5, required=True)
    last = len(c.fields)
    groups: list[tuple[float, str, tuple[int, ...]]] = []
    i = 6
    while i <= last:
        text = c.text(i)
        if not text:
            i += 1
            continue
        if text == "UM":
            raise c.error(i, "UM (dependent components on the independent grids) not supported")
        if text in ("ALPHA", "TREF"):
            j = next((k for k in range(i + 1, last + 1) if c.text(k)), None)
            if j is None:
                raise c.error(i, f"{text} must be followed by a real value")
            _real(c, j)
            i = j + 1
            continue
        if _INT.fullmatch(text):
            raise c.error(i, "weight WT must be a real (e.g. 1.0); an integer here would be a "
                             "grid without its weight and components")
        w = _real(c, i)
        if not w > 0.0:
            raise c.error(i, "weight WT must be > 0")
        comps = _components(c, i + 1, required=True)
        grids: list[int] = []
        j = i + 2
        while j <= last and (not c.text(j) or _INT.fullmatch(c.text(j))):
            if c.text(j):
                grids.append(_int(c, j))
            j += 1
        if not grids:
            raise c.error(i + 2, "weight group needs at least one grid")
        groups.append((w, comps, tuple(grids)))
        i = j
    if not groups:
        raise c.error(6, "RBE3 needs at least one weight group WT C G...")
    r.claim("element", eid, c, 2)
    r.deck.rbe3s[eid] = Rbe3(eid, ref, refc, tuple(groups), c.src)


def _rbar(r, c) -> None:
    """RBAR: EID GA GB CNA CNB CMA CMB ALPHA / TREF (MSC QRG RBAR): a rigid bar between GA and
    GB; CNA, CNB the independent components at GA, GB (six in all), CMA, CMB the dependent ones
    (both blank: every component not independent), components of each grid's CD system.

    All six independent components at one grid (CNA = 123456 or CNB = 123456, the way RBAR is
    written almost always) make the RBAR the RBE2 of that grid with the other grid's dependent
    components: it is held as that RBE2 (``card="RBAR"``). Independent components split over
    both grids (CNA = 1236, CNB = 45) are an error: not supported. ALPHA and TREF (thermal
    expansion) are read and have no effect."""
    _max_fields(c, 10)
    eid, ga, gb = _int(c, 2), _int(c, 3), _int(c, 4)
    cna, cnb, cma, cmb = ("" if c.text(i) == "0" else _components(c, i, required=False)
                          for i in (5, 6, 7, 8))      # 0: blank, as NASTRAN allows
    _ignored_reals(c, (9, 10))
    if len(cna) + len(cnb) != 6:
        raise c.error(5, f"CNA ({cna or 'blank'}) and CNB ({cnb or 'blank'}) must hold six "
                         f"independent components in all")
    for i, (dep, ind, end) in enumerate(((cma, cna, "A"), (cmb, cnb, "B"))):
        both = sorted(set(dep) & set(ind))
        if both:
            raise c.error(7 + i, f"CM{end} component(s) {''.join(both)} are also independent "
                                 f"(in CN{end})")
    if cna and cnb:
        raise c.error(6, f"independent components at both grids (CNA={cna}, CNB={cnb}) not "
                         f"supported: give all six at one grid (CNA=123456 or CNB=123456)")
    if not cma and not cmb:              # NASTRAN: every component not independent is dependent
        cma = "".join(d for d in "123456" if d not in cna)
        cmb = "".join(d for d in "123456" if d not in cnb)
    gn, gm, cm = (ga, gb, cmb) if cna else (gb, ga, cma)
    if not cm:
        raise c.error(8 if cna else 7, "no dependent component: the RBAR ties nothing")
    r.claim("element", eid, c, 2)
    r.deck.rbe2s[eid] = Rbe2(eid, gn, cm, (gm,), c.src, card="RBAR")


def _crigd1(r, c) -> None:
    """CRIGD1 EID IG G1 G2 ... (or IG GID1 THRU GID2): NASTRAN-95's rigid element coupling all six
    components of each dependent grid to the reference grid IG (User's Manual, CRIGD1), which is
    the RBE2 of IG with CM = 123456 (held as that RBE2, ``card="CRIGD1"``)."""
    eid, ig = _int(c, 2), _int(c, 3)
    gm = _dependent_grids(c, 4, len(c.fields))
    if not gm:
        raise c.error(4, "CRIGD1 needs at least one dependent grid")
    r.claim("element", eid, c, 2)
    r.deck.rbe2s[eid] = Rbe2(eid, ig, "123456", tuple(gm), c.src, card="CRIGD1")


def _crigd2(r, c) -> None:
    """CRIGD2 EID IG G1 C1 G2 C2 ...: NASTRAN-95's rigid element coupling the components Ci of each
    dependent grid Gi to all six of IG (User's Manual, CRIGD2). With one component list for all
    its grids (as decks write it) it is the RBE2 of IG with CM = that list (``card="CRIGD2"``);
    different lists on one card are an error (not supported: one CRIGD2 per list)."""
    eid, ig = _int(c, 2), _int(c, 3)
    pairs = [i for i in range(4, len(c.fields) + 1, 2) if c.text(i) or c.text(i + 1)]
    if not pairs:
        raise c.error(4, "CRIGD2 needs at least one dependent grid and its components")
    gm, cms = [], []
    for i in pairs:
        gm.append(_int(c, i))
        cms.append(_components(c, i + 1, required=True))
    if len(set(cms)) > 1:
        i = pairs[cms.index(next(x for x in cms if x != cms[0]))]
        raise c.error(i + 1, f"CRIGD2 with different components on its grids ({cms[0]} at grid "
                             f"{gm[0]}, {c.text(i + 1)} at grid {c.text(i)}) is not supported: "
                             f"write one CRIGD2 for each component list")
    r.claim("element", eid, c, 2)
    r.deck.rbe2s[eid] = Rbe2(eid, ig, cms[0], tuple(gm), c.src, card="CRIGD2")


PARSERS = {"RBE2": _rbe2, "RBE3": _rbe3, "RBAR": _rbar, "CRIGD1": _crigd1, "CRIGD2": _crigd2}
