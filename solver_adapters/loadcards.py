"""NASTRAN static load cards: FORCE, MOMENT, FORCE1, MOMENT1, FORCE2, MOMENT2, SLOAD, PLOAD1, GRAV,
RFORCE, SPCD and LOAD.

The study's ``model.bdf`` carries no loads (they come from ``loads.csv``), so the bulk-data reader
(:mod:`solver_adapters.bdf`) rejects these cards. ``blackbox import`` reads them here from the
cards of a whole input file (:func:`solver_adapters.bdf.bulk_cards`) and resolves the set a
subcase selects with ``LOAD = n`` into nodal forces and moments in the basic system:

* ``FORCE  SID G CID F N1 N2 N3``: force F (N1, N2, N3) at grid G; ``MOMENT`` alike;
* ``FORCE1 SID G F G1 G2``: force F along the unit vector from G1 to G2; ``MOMENT1`` alike;
* ``FORCE2 SID G F G1 G2 G3 G4``: force F along the unit vector of (G2 - G1) x (G4 - G3);
  ``MOMENT2`` alike;
* ``PLOAD1 SID EID TYPE SCALE X1 P1 X2 P2``: a load on a bar or beam, ``GRAV SID CID A N1
  N2 N3``: the acceleration A N on the lumped mass, and ``RFORCE SID G CID A R1 R2 R3``: the
  centrifugal load of a steady rotation on it, as NASTRAN's equivalent nodal loads
  (:mod:`solver_adapters.elementloads`, :mod:`solver_adapters.reference.loads`);
* ``SLOAD SID S1 F1 S2 F2 S3 F3``: the loads Fi on scalar points Si (their one DOF);
* ``LOAD SID S S1 L1 S2 L2 ...``: the set S * sum(Si * set Li), the Li being sets of the cards
  above (a LOAD set may not name another LOAD set, as in NASTRAN; a pair left blank, as the
  trailing fields of a line, is skipped).
* ``SPCD SID G1 C1 D1 G2 C2 D2``: the displacement Di enforced on components Ci of grid Gi (in
  its CD system) in the subcases whose load set holds it, scaled in a LOAD combination as a
  load is (:meth:`LoadCards.enforced`); it is not a force, so :meth:`LoadCards.resolve` leaves it
  out. ``blackbox import`` makes it a load (docs/import.md, enforced displacements).

Several cards of one set add up. A CID other than 0 gives the vector in that coordinate system (CORD1R/C/S,
CORD2R/C/S of the deck; for a cylindrical or spherical system, along its directions at the
grid). The resolved loads are returned in each grid's displacement system (its CD; the basic
system for CD 0), the components loads.csv holds.
Other load cards (PLOAD, PLOAD2, PLOAD4, TEMPP1, RFORCE1, ...) are recorded by set: selecting
such a set is an error naming the card. A subcase's thermal load (``TEMPERATURE(LOAD) = n``: TEMP,
TEMPD, TEMPRB) is resolved by :meth:`LoadCards.resolve_thermal` (:mod:`solver_adapters.thermalloads`);
a LOAD set does not include temperature cards (NASTRAN selects them with TEMPERATURE only).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# the field readers every load card shares (located errors for blank, bad or extra fields)
from solver_adapters.bdf.fields import valid_components
from solver_adapters.elementloads import (MassReader, _int, _max_fields, _real, coord_system, read_grav, read_pload1,
                                         read_rforce)
from solver_adapters.protocol import DeckFormatError
from solver_adapters.thermalloads import TEMPERATURE_CARDS, ThermalCards, read_thermal_cards

__all__ = ["LOAD_CARDS", "OTHER_LOAD_CARDS", "PointLoad", "EnforcedValue", "LoadCombination", "LoadCards",
           "read_load_cards",
           "InputFile", "read_input_file"]

LOAD_CARDS = frozenset({"FORCE", "MOMENT", "FORCE1", "MOMENT1", "FORCE2", "MOMENT2", "LOAD",
                        "PLOAD1", "GRAV", "RFORCE", "SLOAD", "SPCD"})
"""The load cards this module reads (PLOAD1, GRAV and RFORCE through :mod:`solver_adapters.elementloads`)."""

OTHER_LOAD_CARDS = frozenset({
    "ACCEL", "ACCEL1", "RFORCE1", "PLOAD", "PLOAD2", "PLOAD4", "PLOADX1",
    "PLOADB3", "DEFORM", "TEMP", "TEMPD", "TEMPP1", "TEMPRB", "QBDY1", "QVOL",
    "DAREA", "LSEQ", "CLOAD", "PRESAX", "FORCEAX", "MOMAX",
})
"""Load cards of other kinds: dropped from the model, an error when a selected set uses them."""


@dataclass(frozen=True)
class PointLoad:
    """One FORCE/MOMENT-family card: ``vector`` is F*(N1, N2, N3) for FORCE/MOMENT (in system
    ``cid``); for FORCE1/2, MOMENT1/2 the direction comes from ``direction_grids``. One pair
    Si Fi of an SLOAD (``card`` ``"SLOAD"``): ``grid`` the scalar point, ``vector`` (F, 0, 0),
    ``field`` the NASTRAN field of Si."""
    card: str
    sid: int
    grid: int
    cid: int
    scale: float
    vector: tuple[float, float, float] | None
    direction_grids: tuple[int, ...] = ()
    src: str = ""
    raw: object = None   # the card, for located errors
    field: int = 3       # the field naming the grid (point), for located errors

    @property
    def is_moment(self) -> bool:
        return self.card.startswith("MOMENT")


@dataclass(frozen=True)
class EnforcedValue:
    """One G C D triple of an SPCD card: ``value`` enforced on each of ``components`` (digits)
    of ``grid``, in the grid's displacement system; ``field`` the NASTRAN field of G."""
    sid: int
    grid: int
    components: str
    value: float
    src: str = ""
    raw: object = None
    field: int = 3


@dataclass(frozen=True)
class LoadCombination:
    """LOAD: SID, overall scale S and the (Si, Li) terms."""
    sid: int
    scale: float
    terms: tuple[tuple[float, int], ...]
    src: str = ""
    raw: object = None


@dataclass
class LoadCards:
    """The load cards of a deck, by set ID: point loads, PLOAD1 (``bar``), GRAV (``gravity``;
    its masses read by ``masses`` from the deck's cards), LOAD combinations, other kinds."""
    point: dict[int, list[PointLoad]] = field(default_factory=dict)
    combinations: dict[int, LoadCombination] = field(default_factory=dict)
    other: dict[int, list[object]] = field(default_factory=dict)   # SID -> cards of other kinds
    bar: dict[int, list] = field(default_factory=dict)              # SID -> PLOAD1 (BarLoad)
    gravity: dict[int, list] = field(default_factory=dict)          # SID -> GRAV, RFORCE
    spcd: dict[int, list[EnforcedValue]] = field(default_factory=dict)  # SID -> SPCD triples
    masses: object = None                                            # elementloads.MassReader
    cards: list = field(default_factory=list)                       # every bulk card (thermal)
    _thermal: ThermalCards | None = None

    @property
    def thermal(self) -> ThermalCards:
        """TEMP, TEMPD, TEMPRB and MAT1 A/TREF, read when a subcase first selects a thermal load
        (a deck whose temperature cards no subcase selects is not held to them)."""
        if self._thermal is None:
            self._thermal = read_thermal_cards(self.cards)
        return self._thermal

    @property
    def set_ids(self) -> set[int]:
        return (set(self.point) | set(self.combinations) | set(self.other) | set(self.bar) | set(self.gravity)
                | set(self.spcd))

    def _has(self, sid: int) -> bool:
        return (sid in self.point or sid in self.other or sid in self.bar or sid in self.gravity
                or sid in self.spcd)

    def enforced(self, sid: int) -> dict[tuple[int, int], tuple[float, EnforcedValue]]:
        """The displacements set ``sid`` enforces (its SPCD cards, through a LOAD combination
        scaled by S * Si): ``{(grid, component): (value, the SPCD triple)}``, components in the
        grid's displacement system. Two SPCD entries on one DOF of a set add up, as loads do."""
        if sid in self.combinations:
            combo = self.combinations[sid]
            terms = [(combo.scale * si, li) for si, li in combo.terms]
        else:
            terms = [(1.0, sid)]
        out: dict[tuple[int, int], tuple[float, EnforcedValue]] = {}
        for scale, li in terms:
            for e in self.spcd.get(li, ()):
                for ch in e.components:
                    dof = (e.grid, int(ch))
                    before = out.get(dof, (0.0, e))[0]
                    out[dof] = (before + scale * e.value, e)
        return out

    def resolve(self, sid: int, deck, *, where: str = "") -> dict[tuple[int, int], float]:
        """The nodal loads of set ``sid``: ``{(grid, component): value}`` in the basic system
        (components 1-3 forces, 4-6 moments), summed over the set's cards. ``deck`` gives the
        grids (for FORCE1/2 directions and existence). ``where`` names what selected the set."""
        sel = f" (selected by {where})" if where else ""
        if sid in self.combinations:
            combo = self.combinations[sid]
            total: dict[tuple[int, int], float] = {}
            for k, (si, li) in enumerate(combo.terms):
                if li in self.combinations:
                    raise combo.raw.error(5 + 2 * k, f"LOAD set {li} is itself a LOAD combination; "
                                                     f"NASTRAN does not allow nested LOAD sets")
                if not self._has(li):
                    raise combo.raw.error(5 + 2 * k, f"load set {li} not found (no FORCE, MOMENT, "
                                                     f"SLOAD, PLOAD1, GRAV, RFORCE or SPCD card with SID {li}){sel}")
                for dof, v in self._point_set(li, deck, sel).items():
                    total[dof] = total.get(dof, 0.0) + combo.scale * si * v
            return total
        if not self._has(sid):
            raise DeckFormatError(f"load set {sid}{sel} not found: no LOAD, FORCE, MOMENT, SLOAD, "
                                  f"PLOAD1, GRAV, RFORCE or SPCD card has SID {sid}")
        return self._point_set(sid, deck, sel)

    def resolve_thermal(self, tsid: int, deck, *, where: str = "",
                        initial: int | None = None) -> dict[tuple[int, int], float]:
        """The nodal loads of temperature set ``tsid`` (selected by ``TEMPERATURE(LOAD)``), in
        each grid's displacement system, as :meth:`resolve` gives a load set's; ``initial`` the
        TEMPERATURE(INITIAL) set, if any."""
        sel = f" (selected by {where})" if where else ""
        others = [c for c in self.other.get(tsid, ()) if c.name not in TEMPERATURE_CARDS]
        if others:
            kinds = sorted({c.name for c in others})
            raise others[0].error(1, f"temperature set {tsid}{sel} contains {', '.join(kinds)}: only "
                                     f"TEMP, TEMPD and TEMPRB (on bars, beams and rods) are imported")
        if not self.thermal.has(tsid):
            raise DeckFormatError(f"temperature set {tsid}{sel} not found: no TEMP, TEMPD or TEMPRB "
                                  f"card has SID {tsid}")
        if initial is not None and not self.thermal.has(initial):
            raise DeckFormatError(f"initial temperature set {initial} not found: no TEMP, TEMPD or "
                                  f"TEMPRB card has SID {initial}")
        out: dict[tuple[int, int], float] = {}
        _add_basic(out, self.thermal.loads(tsid, deck, sel, initial), deck)
        return out

    def _point_set(self, sid: int, deck, sel: str) -> dict[tuple[int, int], float]:
        if sid in self.other:
            c = self.other[sid][0]
            kinds = sorted({o.name for o in self.other[sid]})
            raise c.error(1, f"load set {sid}{sel} contains {', '.join(kinds)}: only FORCE, MOMENT, "
                             f"FORCE1/2, MOMENT1/2, SLOAD, PLOAD1, GRAV, RFORCE, SPCD and LOAD are imported")
        out: dict[tuple[int, int], float] = {}
        for p in self.point.get(sid, ()):
            if p.grid not in deck.grids:
                raise p.raw.error(p.field, f"{'scalar point' if p.card == 'SLOAD' else 'grid'} "
                                           f"{p.grid} does not exist (no "
                                           f"{'SPOINT' if p.card == 'SLOAD' else 'GRID'}){sel}")
            is_scalar = getattr(deck.grids[p.grid], "scalar", False)
            if p.card == "SLOAD" or is_scalar:
                if p.card != "SLOAD" or not is_scalar:
                    raise p.raw.error(p.field, f"point {p.grid} is a scalar point (SPOINT): its "
                                               f"load is an SLOAD{sel}" if is_scalar else
                                      f"point {p.grid} is a GRID, not a scalar point (SPOINT): "
                                      f"SLOAD loads scalar points only{sel}")
                dof = (p.grid, 1)
                out[dof] = out.get(dof, 0.0) + p.vector[0]
                continue
            vec = _basic_vector(p, deck)
            if getattr(deck.grids[p.grid], "cd", 0):
                # components in the grid's displacement system (rows: its directions in basic)
                vec = deck.displacement_frames([p.grid])[0] @ vec
            base = 4 if p.is_moment else 1
            for k in range(3):
                if vec[k] != 0.0:
                    dof = (p.grid, base + k)
                    out[dof] = out.get(dof, 0.0) + float(vec[k])
        for load in self.bar.get(sid, ()):
            _add_basic(out, load.loads(deck, sel), deck)
        for g in self.gravity.get(sid, ()):
            _add_basic(out, g.loads(deck, self.masses, sel), deck)
        return out


def _add_basic(out: dict, loads: dict[tuple[int, int], float], deck) -> None:
    """Nodal loads given in basic added to ``out`` in each grid's displacement system."""
    by_grid: dict[int, np.ndarray] = {}
    for (g, c), v in loads.items():
        by_grid.setdefault(g, np.zeros(6))[c - 1] += v
    for g, v in by_grid.items():
        if getattr(deck.grids[g], "cd", 0):
            frame = deck.displacement_frames([g])[0]
            v = np.concatenate([frame @ v[:3], frame @ v[3:]])
        for k in range(6):
            if v[k] != 0.0:
                out[(g, k + 1)] = out.get((g, k + 1), 0.0) + float(v[k])


def _unit(v: np.ndarray, card, i: int, what: str) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if n == 0.0:
        raise card.error(i, f"{what} has zero length: no direction")
    return v / n


def _basic_vector(p: PointLoad, deck) -> np.ndarray:
    c = p.raw
    if p.vector is not None:
        v = np.array(p.vector, dtype=float)
        if p.cid == 0:
            return v
        system = coord_system(deck, c, 4, p.cid)
        if p.grid not in deck.grids:
            raise c.error(3, f"grid {p.grid} does not exist (no GRID)")
        try:
            frame = system.frames_at(np.array([deck.grids[p.grid].xyz], dtype=float))[0]
        except ValueError:
            raise c.error(4, f"grid {p.grid} lies on the axis of the {system.card} {p.cid}, where "
                             f"its directions are undefined") from None
        return frame.T @ v                 # rows of frame: the system's directions in basic
    xyz = {}
    for k, g in enumerate(p.direction_grids):
        if g not in deck.grids:
            raise c.error(5 + k, f"grid {g} does not exist (no GRID)")
        xyz[k] = np.array(deck.grids[g].xyz, dtype=float)
    if len(p.direction_grids) == 2:
        d = _unit(xyz[1] - xyz[0], c, 5, "the vector from G1 to G2")
    else:
        a = _unit(xyz[1] - xyz[0], c, 5, "the vector from G1 to G2")
        b = _unit(xyz[3] - xyz[2], c, 7, "the vector from G3 to G4")
        d = _unit(np.cross(a, b), c, 5, "(G2 - G1) x (G4 - G3)")
    return p.scale * d


def _point(c) -> PointLoad:
    name = c.name
    sid, g = _int(c, 2), _int(c, 3)
    if name in ("FORCE", "MOMENT"):
        _max_fields(c, 8)
        cid = _int(c, 4, minimum=0, default=0)
        f = _real(c, 5)
        n = (_real(c, 6, 0.0), _real(c, 7, 0.0), _real(c, 8, 0.0))
        return PointLoad(name, sid, g, cid, f, (f * n[0], f * n[1], f * n[2]), (), c.src, c)
    if name in ("FORCE1", "MOMENT1"):
        _max_fields(c, 6)
        f, grids = _real(c, 4), (_int(c, 5), _int(c, 6))
        if grids[0] == grids[1]:
            raise c.error(6, "G1 and G2 are the same grid: no direction")
    else:
        _max_fields(c, 8)
        f, grids = _real(c, 4), tuple(_int(c, i) for i in range(5, 9))
    return PointLoad(name, sid, g, 0, f, None, grids, c.src, c)


def _sload(c) -> list[PointLoad]:
    """SLOAD SID S1 F1 S2 F2 S3 F3 (MSC QRG SLOAD): one load per pair; a pair left blank is
    skipped."""
    _max_fields(c, 8)
    sid = _int(c, 2)
    out = []
    for i in (3, 5, 7):
        if not c.text(i) and not c.text(i + 1):
            continue
        s, f = _int(c, i), _real(c, i + 1)
        out.append(PointLoad("SLOAD", sid, s, 0, f, (f, 0.0, 0.0), (), c.src, c, i))
    if not out:
        raise c.error(3, "SLOAD needs at least one pair S1 F1")
    return out


def _spcd(c) -> list[EnforcedValue]:
    """SPCD SID G1 C1 D1 G2 C2 D2 (MSC QRG SPCD): one value per triple; a triple left blank is
    skipped. Components are digits 1-6 of a grid (a scalar point's enforced value is not read)."""
    _max_fields(c, 8)
    sid = _int(c, 2)
    out = []
    for i in (3, 6):
        if not any(c.text(k) for k in (i, i + 1, i + 2)):
            continue
        g = _int(c, i)
        comps = c.text(i + 1)
        if comps in ("", "0"):
            raise c.error(i + 1, "an enforced value at a scalar point (component 0 or blank) is not "
                                 "imported: only grid components 1-6")
        if not valid_components(comps):
            raise c.error(i + 1, "components must be unique digits 1-6")
        out.append(EnforcedValue(sid, g, comps, _real(c, i + 2, 0.0), c.src, c, i))
    if not out:
        raise c.error(3, "SPCD needs at least one triple G1 C1 D1")
    return out


def _combination(c) -> LoadCombination:
    sid, s = _int(c, 2), _real(c, 3)
    terms: list[tuple[float, int]] = []
    seen: dict[int, int] = {}
    i = 4
    last = max((k for k in range(4, len(c.fields) + 1) if c.text(k)), default=3)
    while i <= last:
        if not c.text(i) and not c.text(i + 1):      # a pair left blank (a line's trailing fields)
            i += 2
            continue
        si, li = _real(c, i), _int(c, i + 1)
        if li in seen:
            raise c.error(i + 1, f"load set {li} appears twice in this LOAD card (NASTRAN forbids it)")
        if li == sid:
            raise c.error(i + 1, f"LOAD set {sid} names itself")
        seen[li] = i + 1
        terms.append((si, li))
        i += 2
    if not terms:
        raise c.error(4, "LOAD needs at least one pair S1 L1")
    return LoadCombination(sid, s, tuple(terms), c.src, c)


def _bulk_points(cards) -> dict[int, PointLoad]:
    """FORCE and MOMENT cards of one card table read all at once (``id(card)`` -> its load), as
    :func:`_point` reads each; the cards it leaves (any other layout, a bad field) are read by
    :func:`_point`, which names the error."""
    from solver_adapters.bdf.numbers import int_column, real_column
    from solver_adapters.bdf.table import TableCard
    picked = [c for c in cards if c.name in ("FORCE", "MOMENT")]
    if not picked or not all(isinstance(c, TableCard) and c.table is picked[0].table for c in picked):
        return {}
    table = picked[0].table
    idx = np.array([c.index for c in picked], np.int64)
    M = table.matrix(idx, 7)                    # columns 1-7: fields 2-8
    ok = ~(M[:, 8:] != b"").any(axis=1)
    sid, k = int_column(M[:, 1]); ok &= k
    g, k = int_column(M[:, 2]); ok &= k
    cid, k = int_column(M[:, 3], 0, 0); ok &= k
    f, k = real_column(M[:, 4]); ok &= k
    n = np.empty((len(idx), 3))
    for j in range(3):
        n[:, j], k = real_column(M[:, 5 + j], 0.0); ok &= k
    v = f[:, None] * n
    out = {}
    rows = np.flatnonzero(ok).tolist()
    for i, s, gg, c, ff, vec in zip(rows, sid[rows].tolist(), g[rows].tolist(), cid[rows].tolist(),
                                    f[rows].tolist(), map(tuple, v[rows].tolist())):
        card = picked[i]
        out[id(card)] = PointLoad(card.name, s, gg, c, ff, vec, (), card.src, card)
    return out


def read_load_cards(cards) -> LoadCards:
    """The load cards among ``cards`` (from :func:`solver_adapters.bdf.bulk_cards`), by set;
    the cards of other kinds are skipped. Errors name the file, line, card and field."""
    out = LoadCards()
    cards = list(cards)
    made = _bulk_points(cards)
    for c in cards:
        if c.name == "LOAD":
            combo = _combination(c)
            if combo.sid in out.combinations:
                raise c.error(2, f"duplicate LOAD set ID {combo.sid} (already defined at "
                                 f"{out.combinations[combo.sid].src})")
            out.combinations[combo.sid] = combo
        elif c.name == "PLOAD1":
            load = read_pload1(c)
            out.bar.setdefault(load.sid, []).append(load)
        elif c.name in ("GRAV", "RFORCE"):
            g = read_grav(c) if c.name == "GRAV" else read_rforce(c)
            out.gravity.setdefault(g.sid, []).append(g)
        elif c.name == "SPCD":
            for e in _spcd(c):
                out.spcd.setdefault(e.sid, []).append(e)
        elif c.name == "SLOAD":
            for p in _sload(c):
                out.point.setdefault(p.sid, []).append(p)
        elif c.name in LOAD_CARDS:
            p = made.get(id(c)) or _point(c)
            out.point.setdefault(p.sid, []).append(p)
        elif c.name in OTHER_LOAD_CARDS:
            sid = _int(c, 2)
            out.other.setdefault(sid, []).append(c)
    for sid, combo in out.combinations.items():
        if out._has(sid):
            first = (out.point.get(sid) or out.bar.get(sid) or out.gravity.get(sid) or out.spcd.get(sid)
                     or [None])[0]
            where = first.raw.src if first is not None else out.other[sid][0].src
            raise combo.raw.error(2, f"set ID {sid} is both a LOAD combination and a load set "
                                     f"({where}); NASTRAN requires LOAD set IDs to be unique")
    return out


@dataclass(frozen=True)
class InputFile:
    """A whole NASTRAN input file: its case control (``None`` for bulk data only), every bulk
    card as read (:func:`solver_adapters.bdf.read_bulk`), the files read, the load cards by set,
    and the reading itself (``bulk``: the included files' texts as read)."""
    path: str
    case_control: object
    cards: list
    files: list
    loads: LoadCards
    bulk: object = None


def read_input_file(path, text: str | None = None, include_dirs=None) -> InputFile:
    """Read the input file ``path`` (``text``: its content, if already read): the case control
    (:mod:`solver_adapters.casecontrol`), the bulk cards and the load cards. The model itself is
    made from a chosen subset of the cards with :func:`solver_adapters.bdf.deck_from_cards`
    (``blackbox import`` leaves out the load cards and the constraint sets not selected).
    INCLUDEs read only files inside the input file's folder tree or ``include_dirs`` (None: the
    user's configured folders)."""
    from pathlib import Path

    from solver_adapters.bdf import read_bulk
    from solver_adapters.casecontrol import read_case_control

    p = Path(path)
    if text is None:
        try:
            text = p.read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            raise DeckFormatError(f"cannot read the deck: {exc.strerror or exc}", file=str(p)) from None
    cc = read_case_control(text, str(p))
    bulk = read_bulk(p, text, include_dirs)
    loads = read_load_cards(c for c in bulk.cards if c.name in LOAD_CARDS or c.name in OTHER_LOAD_CARDS)
    loads.masses = MassReader(bulk.cards)
    loads.cards = bulk.cards
    return InputFile(str(p), cc, bulk.cards, bulk.files, loads, bulk)
