"""Cross-reference checks of a read deck: one :class:`ModelError` listing every problem."""

from __future__ import annotations

from itertools import chain
from operator import attrgetter

import numpy as np

from solver_adapters.bdf.grids import PARALLEL_SINE, ZERO_LENGTH
from solver_adapters.deck import Deck
from solver_adapters.protocol import ModelError

_ROD_PROPERTY = {"CROD": "PROD", "CTUBE": "PTUBE"}
"""The property card each rod element with a PID needs."""


def _ints(items, key: str) -> np.ndarray:
    return np.fromiter(map(attrgetter(key), items), np.int64, len(items))


def _vectors(items, key: str) -> np.ndarray | None:
    """The 3-vectors ``key`` of ``items`` as an ``(n, 3)`` array (None where one is None)."""
    values = list(map(attrgetter(key), items))
    if values.count(None):
        return None
    return np.fromiter(chain.from_iterable(values), float, 3 * len(items)).reshape(-1, 3)


def _bulk_ok(deck: Deck) -> bool:
    """Whether the grids' CP/CD systems, the bars and the rods pass every check of
    :func:`_problems`, all at once (False: some may not; the one-by-one checks tell)."""
    grids = deck.grids
    if any(g.cp or g.cd for g in grids.values()):
        if any((g.cp and g.cp not in deck.coords) or (g.cd and g.cd not in deck.coords)
               for g in grids.values()):
            return False
    ids = np.fromiter(grids, np.int64, len(grids))
    order = np.argsort(ids)
    ids = ids[order]
    xyz = np.fromiter(chain.from_iterable(map(attrgetter("xyz"), grids.values())), float,
                      3 * len(grids)).reshape(-1, 3)[order]

    def pos(g: np.ndarray) -> np.ndarray | None:
        """Positions of grids ``g`` in ``ids``; None if one does not exist."""
        if not ids.size:
            return None if g.size else g
        p = np.minimum(np.searchsorted(ids, g), ids.size - 1)
        return p if (ids[p] == g).all() else None

    for p in deck.pbars.values():
        if p.mid not in deck.mat1s or ((p.k1 or p.k2) and deck.mat1s[p.mid].g == 0.0):
            return False
    bars = list(deck.cbars.values())
    if bars:
        wanted = {"CBAR": ("PBAR", "PBARL"), "CBEAM": ("PBEAM", "PBEAML")}
        for pid, card in set(zip(map(attrgetter("pid"), bars), map(attrgetter("card"), bars))):
            if pid not in deck.pbars or deck.pbars[pid].card not in wanted[card]:
                return False
        ga, gb = _ints(bars, "ga"), _ints(bars, "gb")
        ia, ib = pos(ga), pos(gb)
        if ia is None or ib is None or (ga == gb).any():
            return False
        xa, xb = xyz[ia], xyz[ib]
        axis = xb - xa
        for key, sign in (("wb", 1.0), ("wa", -1.0)):
            w = list(map(attrgetter(key), bars))
            if w.count(None) < len(bars):
                rows = [k for k, v in enumerate(w) if v is not None]
                axis[rows] += sign * np.array([w[k] for k in rows], float)
        size = np.maximum(np.abs(xa).max(axis=1), np.abs(xb).max(axis=1))
        na = np.linalg.norm(axis, axis=1)
        if (na <= ZERO_LENGTH * size).any():
            return False
        v = _vectors(bars, "x")
        if v is None:                                   # some bars have a G0
            g0 = np.array([b.g0 or 0 for b in bars], np.int64)
            has_g0 = g0 != 0
            v = np.array([b.x if b.g0 is None else (0.0, 0.0, 0.0) for b in bars], float)
            i0 = pos(g0[has_g0])
            if i0 is None or (g0 == ga).any() or (g0 == gb).any():
                return False
            v[has_g0] = xyz[i0] - xa[has_g0]
        nv = np.linalg.norm(v, axis=1)
        if (nv == 0.0).any() or (np.linalg.norm(np.cross(v, axis), axis=1) <= PARALLEL_SINE * nv * na).any():
            return False
    rods = list(deck.rods.values())
    if rods:
        for r in rods:
            if (r.pid is not None and (r.pid not in deck.prods or deck.prods[r.pid].card !=
                                       _ROD_PROPERTY.get(r.card))) or \
                    (r.mid is not None and r.mid not in deck.mat1s):
                return False
        ga, gb = _ints(rods, "ga"), _ints(rods, "gb")
        ia, ib = pos(ga), pos(gb)
        if ia is None or ib is None or (ga == gb).any():
            return False
        xa, xb = xyz[ia], xyz[ib]
        size = np.maximum(np.abs(xa).max(axis=1), np.abs(xb).max(axis=1))
        if (np.linalg.norm(xb - xa, axis=1) <= ZERO_LENGTH * size).any():
            return False
    return True


def validate(deck: Deck) -> None:
    """Cross-reference checks; raise one :class:`ModelError` listing every problem found.

    CBAR -> PBAR -> MAT1, CBAR end grids and G0, GA != GB, non-zero length, orientation not
    parallel to the axis; PBAR K1/K2 need G > 0; CROD -> PROD -> MAT1, CONROD -> MAT1, rod grids
    and length; RBE2, SPC/SPC1 and spring grids; CELAS1 -> PELAS; SPCADD -> SPC/SPC1 sets.

    The many grids, bars and rods of a large deck are checked all at once (:func:`_bulk_ok`);
    only when that finds a problem are they gone through one by one, for the message.
    """
    problems = _problems(deck, bulk_checked=_bulk_ok(deck))
    if problems:
        problems = _problems(deck, bulk_checked=False)
        shown = "\n  ".join(problems[:50])
        more = f"\n  ... and {len(problems) - 50} more" if len(problems) > 50 else ""
        raise ModelError(f"{len(problems)} model error(s):\n  {shown}{more}")


def _problems(deck: Deck, bulk_checked: bool) -> list[str]:
    """Every problem of the deck, in the order of the message (``bulk_checked``: the grids'
    systems, the bars and the rods were found right already, so they are not gone through)."""
    problems: list[str] = []

    def bad(entity, card: str, ident: int, message: str) -> None:
        problems.append(f"{entity.src}: {card} {ident}: {message}")

    def need_grids(entity, card: str, ident: int, grids, what: str) -> None:
        missing = [g for g in grids if g not in deck.grids]
        if missing:
            bad(entity, card, ident, f"{what} {', '.join(map(str, missing[:10]))} "
                                     f"{'does' if len(missing) == 1 else 'do'} not exist (no GRID)")

    for g in () if bulk_checked else deck.grids.values():
        for key, value in (("CP", g.cp), ("CD", g.cd)):
            if value and value not in deck.coords:
                bad(g, "GRID", g.id, f"{key} {value}: coordinate system not defined")
    for p in deck.pbars.values():
        if p.mid not in deck.mat1s:
            bad(p, "PBAR", p.pid, f"material MID {p.mid} not found (no MAT1)")
        elif (p.k1 or p.k2) and deck.mat1s[p.mid].g == 0.0:
            bad(p, "PBAR", p.pid, f"K1/K2 shear factors need a shear modulus, but MAT1 {p.mid} "
                                  f"has G = 0")
    for p in deck.prods.values():
        if p.mid not in deck.mat1s:
            bad(p, p.card, p.pid, f"material MID {p.mid} not found (no MAT1)")
    for r in () if bulk_checked else deck.rods.values():
        wanted = _ROD_PROPERTY.get(r.card)
        if r.pid is not None and r.pid not in deck.prods:
            other = (" (it is a PBAR)" if r.pid in deck.pbars
                     else " (it is a PELAS)" if r.pid in deck.pelas else "")
            bad(r, r.card, r.eid, f"property PID {r.pid} not found (no {wanted}){other}")
        elif r.pid is not None and deck.prods[r.pid].card != wanted:
            bad(r, r.card, r.eid, f"property PID {r.pid} is a {deck.prods[r.pid].card}; a "
                                  f"{r.card} needs a {wanted}")
        if r.mid is not None and r.mid not in deck.mat1s:
            bad(r, r.card, r.eid, f"material MID {r.mid} not found (no MAT1)")
        need_grids(r, r.card, r.eid, [r.ga, r.gb], "grid")
        if r.ga == r.gb:
            bad(r, r.card, r.eid, f"G1 and G2 are the same grid {r.ga}")
        elif r.ga in deck.grids and r.gb in deck.grids:
            xa, xb = np.array(deck.grids[r.ga].xyz), np.array(deck.grids[r.gb].xyz)
            if np.linalg.norm(xb - xa) <= ZERO_LENGTH * max(np.abs(xa).max(), np.abs(xb).max()):
                bad(r, r.card, r.eid, f"zero length: grids {r.ga} and {r.gb} coincide")
    for b in () if bulk_checked else deck.cbars.values():
        wanted = ("PBEAM", "PBEAML") if b.card == "CBEAM" else ("PBAR", "PBARL")
        if b.pid not in deck.pbars:
            other = (" (it is a PELAS)" if b.pid in deck.pelas
                     else " (it is a PROD)" if b.pid in deck.prods else "")
            bad(b, b.card, b.eid, f"property PID {b.pid} not found (no {' or '.join(wanted)}){other}")
        elif deck.pbars[b.pid].card not in wanted:
            bad(b, b.card, b.eid, f"property PID {b.pid} is a {deck.pbars[b.pid].card}; a "
                                  f"{b.card} needs a {' or '.join(wanted)}")
        need_grids(b, b.card, b.eid, [b.ga, b.gb] + ([b.g0] if b.g0 is not None else []), "grid")
        if b.ga == b.gb:
            bad(b, b.card, b.eid, f"GA and GB are the same grid {b.ga}")
            continue
        if b.ga not in deck.grids or b.gb not in deck.grids:
            continue
        xa, xb = np.array(deck.grids[b.ga].xyz), np.array(deck.grids[b.gb].xyz)
        axis = xb - xa                    # v is measured from grid GA, the axis between bar ends
        if b.wa is not None or b.wb is not None:
            axis = axis + np.array(b.wb or (0.0, 0.0, 0.0)) - np.array(b.wa or (0.0, 0.0, 0.0))
        if np.linalg.norm(axis) <= ZERO_LENGTH * max(np.abs(xa).max(), np.abs(xb).max()):
            what = "the bar ends (offsets included)" if b.wa or b.wb else f"grids {b.ga} and {b.gb}"
            bad(b, b.card, b.eid, f"zero length: {what} coincide")
            continue
        if b.g0 is not None:
            if b.g0 in (b.ga, b.gb):
                bad(b, b.card, b.eid, f"G0 {b.g0} is one of the bar's own grids")
                continue
            if b.g0 not in deck.grids:
                continue
            v = np.array(deck.grids[b.g0].xyz) - xa
        else:
            v = np.array(b.x)
        nv, na = np.linalg.norm(v), np.linalg.norm(axis)
        if nv == 0.0:
            bad(b, b.card, b.eid, "orientation vector is zero")
        elif np.linalg.norm(np.cross(v, axis)) <= PARALLEL_SINE * nv * na:
            bad(b, b.card, b.eid, "orientation vector is parallel to the bar axis")
    for e in deck.rbe2s.values():
        need_grids(e, e.card, e.eid, [e.gn], "independent grid GN" if e.card == "RBE2" else "grid")
        need_grids(e, e.card, e.eid, e.gm, "dependent grid(s)" if e.card == "RBE2" else "grid")
        if e.gn in e.gm:
            bad(e, e.card, e.eid, f"GN {e.gn} is also a dependent grid" if e.card == "RBE2"
                else f"GA and GB are the same grid {e.gn}")
    for e in deck.rbe3s.values():
        need_grids(e, "RBE3", e.eid, [e.refgrid], "reference grid REFGRID")
        indep = [g for _, _, gs in e.groups for g in gs]
        need_grids(e, "RBE3", e.eid, indep, "independent grid(s)")
        if e.refgrid in indep:
            bad(e, "RBE3", e.eid, f"REFGRID {e.refgrid} is also an independent grid")
    def two_grids(e, card: str, props: dict, pcard: str, need_cid: str) -> None:
        """A two-grid element's property, grids, and an axis from GA to GB or else from CID."""
        if e.pid not in props:
            bad(e, card, e.eid, f"property PID {e.pid} not found (no {pcard})")
        need_grids(e, card, e.eid, [g for g in (e.ga, e.gb, e.g0) if g], "grid(s)")
        if e.ga == e.gb:
            bad(e, card, e.eid, f"GA and GB are the same grid {e.ga}")
        elif e.cid is None and e.gb in deck.grids and e.ga in deck.grids:
            xa, xb = np.array(deck.grids[e.ga].xyz), np.array(deck.grids[e.gb].xyz)
            if np.linalg.norm(xb - xa) <= ZERO_LENGTH * max(np.abs(xa).max(), np.abs(xb).max(), 1e-300):
                bad(e, card, e.eid, f"GA and GB coincide: {need_cid}")

    for b in deck.bushes.values():
        two_grids(b, "CBUSH", deck.pbushes, "PBUSH", "the element axes need CID")
        if b.cid is not None and b.cid != 0 and b.cid not in deck.coords:
            bad(b, "CBUSH", b.eid, f"CID {b.cid}: coordinate system not defined")
    for e in deck.gaps.values():
        two_grids(e, "CGAP", deck.pgaps, "PGAP", "the gap axis needs CID")
    for s in deck.spc1s:
        need_grids(s, s.card, s.sid if s.card == "SPC1" else "(reference DOFs)", s.grids, "grid(s)")
    spc_sets = {s.sid for s in deck.spc1s}
    for a in deck.spcadds.values():
        if a.sid in spc_sets:
            bad(a, "SPCADD", a.sid, f"SID {a.sid} is also the ID of an SPC/SPC1 set")
        missing = [k for k in a.sets if k not in spc_sets]
        if missing:
            bad(a, "SPCADD", a.sid, f"set(s) {', '.join(map(str, missing[:10]))} not found "
                                    f"(no SPC or SPC1 with that SID)")
    for m in deck.mpcs:
        need_grids(m, "MPC", m.sid, [g for g, _, _ in m.terms], "grid(s)")
    mpc_sets = {m.sid for m in deck.mpcs}
    for a in deck.mpcadds.values():
        if a.sid in mpc_sets:
            bad(a, "MPCADD", a.sid, f"SID {a.sid} is also the ID of an MPC set")
        missing = [k for k in a.sets if k not in mpc_sets]
        if missing:
            bad(a, "MPCADD", a.sid, f"set(s) {', '.join(map(str, missing[:10]))} not found "
                                    f"(no MPC with that SID)")
    for u in deck.unmodelled:
        if u.grids:
            need_grids(u, u.name, u.fields[0], u.grids, "grid(s)")
    scalar = deck.scalar_points()
    if scalar:             # a scalar point has no position and one DOF: springs, MPC, SPC only
        joined = [(b, b.card, b.eid, (b.ga, b.gb, b.g0)) for b in deck.cbars.values()]
        joined += [(r, r.card, r.eid, (r.ga, r.gb)) for r in deck.rods.values()]
        joined += [(b, "CBUSH", b.eid, (b.ga, b.gb, b.g0)) for b in deck.bushes.values()]
        joined += [(e, "CGAP", e.eid, (e.ga, e.gb, e.g0)) for e in deck.gaps.values()]
        joined += [(e, e.card, e.eid, (e.gn, *e.gm)) for e in deck.rbe2s.values()]
        joined += [(e, "RBE3", e.eid, (e.refgrid, *(g for _, _, gs in e.groups for g in gs)))
                   for e in deck.rbe3s.values()]
        joined += [(u, u.name, u.fields[0], u.grids) for u in deck.unmodelled if u.grids]
        for entity, card, ident, points in joined:
            hit = sorted({g for g in points if g in scalar})
            if hit:
                bad(entity, card, ident, f"{'point' if len(hit) == 1 else 'points'} "
                                         f"{', '.join(map(str, hit[:10]))}: scalar point(s) (SPOINT), "
                                         f"which only CELAS springs, MPCs and SPCs can join (a "
                                         f"scalar point has one DOF and no position)")
    for s in deck.springs.values():
        need_grids(s, s.card, s.eid, [g for g in (s.g1, s.g2) if g != 0], "grid(s)")
        if s.card in ("CELAS1", "CELAS3") and s.pid not in deck.pelas:
            other = " (it is a PBAR)" if s.pid in deck.pbars else ""
            bad(s, s.card, s.eid, f"property PID {s.pid} not found (no PELAS){other}")
    return problems
