"""The reader: cards into a :class:`~solver_adapters.deck.Deck`, by two paths that give the same
deck and the same errors.

* The reference path reads one card at a time in the deck's order (:mod:`.tokens`, then each
  card's parser); the first bad field of the deck is the error.
* The bulk path (:func:`read_table`) splits the whole deck at once (:mod:`.table`), converts the
  many cards of one kind together (GRID, CBAR, CBEAM, CROD: the ``BULK`` converters of the card
  families) and gives every other card, and every card a converter does not take, to its
  parser. Whatever goes wrong there (a bad field, a duplicate ID, an unknown card, a model
  error) makes :func:`read` start again on the reference path, which finds the same problem and
  raises the message it always did, at the same card of the deck.
"""

from __future__ import annotations

import gc
import itertools
from dataclasses import replace

import numpy as np

from solver_adapters.bdf import design, matrices
from solver_adapters.bdf.catalog import (BULK, ELEMENT_GRIDS, NOT_PASSABLE, PARSERS,
                                         _connects_nothing, known, unsupported_error)
from solver_adapters.bdf.fields import _components, _int, _orientation
from solver_adapters.bdf.grids import coord_from_points
from solver_adapters.bdf.numbers import typed
from solver_adapters.bdf.params import NO_EFFECT, PBUSHT_NOTE, _param
from solver_adapters.bdf.table import CardTable, Irregular, TableCard
from solver_adapters.deck import ON_AXIS_RULE, Deck, Spc1, Unmodelled
from solver_adapters.errors import ReaderFallback as Fallback
from solver_adapters.protocol import DeckFormatError, ModelError

UNUSED_IF_UNREFERENCED = frozenset({
    "PSHELL", "PCOMP", "PCOMPG", "PCOMP1", "PSOLID", "PSHEAR", "PWELD", "PFAST", "PLPLANE",
    "PLSOLID", "PSHLN1", "PSHLN2", "MAT2", "MAT3", "MAT8", "MAT9", "MAT10", "MAT11"})
"""Properties of shells, solids and connectors, and their materials, which no bar, beam, rod or
spring can name (their PIDs and MIDs are read by elements the reader does not model): with no
element of the deck using one, it has no effect on the structure (:meth:`_Reader.unused_sections`)."""

_UNUSED_NOTE = ("a shell or solid property or material that no element of the deck uses: no effect "
                "on the structure")

_MERGED = ("grids", "cbars", "rods")
"""Deck collections that both the bulk converters and the parsers fill (kept in deck order)."""


PROPERTY_FAMILIES = {"PBAR": "bar", "PBARL": "bar", "PBEAM": "bar", "PBEAML": "bar",
                     "PROD": "rod", "PTUBE": "rod", "PBUSH": "bush", "PELAS": "elas", "PGAP": "gap"}
"""Property card -> the family of elements that name it (CBAR/CBEAM, CROD/CTUBE, CBUSH, CELAS1/3,
CGAP). A property ID is unique within its family only: an element finds its property among its
own family's cards, so a PBUSH 3 beside a PBEAML 3 is no ambiguity (NX and MSC Nastran accept
such decks: pyNastran issue #188, its maintainer's word; MYSTRAN 18 runs a PBAR 1 beside a
PROD 1, measured), while two PBAR-family cards with one ID stay an error."""


class _Reader:
    def __init__(self, keep_unmodelled: bool = False, table: CardTable | None = None) -> None:
        self.deck = Deck()
        # True: cards not modelled go to Deck.unmodelled (for an external solver) instead of
        # being errors; cards of NOT_PASSABLE stay errors
        self.keep_unmodelled = keep_unmodelled
        self.table = table
        # ID -> "CARD at file:line"; elements (CBAR, RBE2, CELASi) share one ID space; properties
        # one per family of the elements that name them (PROPERTY_FAMILIES)
        self.ids: dict[str, dict[int, str]] = {"GRID": {}, "element": {}, "MAT1": {},
                                               **{f"property {k}": {} for k in set(PROPERTY_FAMILIES.values())},
                                               "SPCADD": {}, "MPCADD": {}, "CORD": {},
                                               **{k: {} for k in design.PARSERS if k not in ("DLINK", "DTABLE")}}
        self.design = design.DesignState.empty()   # SOL 200's design model, applied in finish()
        self.dmig_headers: dict[str, object] = {}  # DMIG name -> its header card
        self.dmig_columns: dict[str, list] = {}    # DMIG name -> (card, GJ, CJ, terms) per column
        self.genels: list[tuple] = []              # GENEL cards as parsed, resolved in finish()
        self.spc1_pending: list[tuple[int, str, list[int | tuple[int, int]], str, object, int]] = []
        self.spoints: dict[int, object] = {}      # SPOINT ID -> its Grid (scalar), in finish()
        # (card, field, point, component) of every spring end and MPC term (component 0: blank
        # or 0, a scalar point's DOF): checked against the kind of point in finish()
        self.point_refs: list[tuple[object, int, int, int]] = []
        # card name -> [count, first card] of every card that is neither modelled nor NO_EFFECT
        self.unsupported: dict[str, list] = {}
        # GRDSET defaults, applied in finish() (bulk data is unordered: GRDSET may come last)
        self.grdset = None
        self.first_blank: dict[str, int | None] = {"CP": None, "CD": None, "SEID": None}
        self.blank_ps: list[int] = []
        self.blank_sys: dict[str, list[int]] = {"CP": [], "CD": []}
        # GRIDs with a non-zero CP or CD (for errors): the card, or its index in the table
        self.grid_cards: dict[int, object] = {}
        # coordinate-system cards, resolved in finish(): CID -> (kind, card, definition)
        self.cords: dict[int, tuple] = {}
        self.cbar_offt: dict[int, str] = {}       # OFFT as written (blank: BAROR's or GGG)
        self.pending_cids: list = []              # CBUSH CIDs and OCIDs (card, id, field), checked in finish()
        # BAROR defaults, applied in finish(): CBARs with a blank PID, with no orientation
        self.baror = None
        self.pid_blank: list[int] = []
        self.orient_blank: list = []
        # bulk path: per collection, (card indices, keys, entities) of each converter's cards
        self.bulk_parts: dict[str, list[tuple[np.ndarray, list, list]]] = {}
        self.bulk_ids: dict[str, list[tuple[np.ndarray, list]]] = {}
        self.frames: dict[int, np.ndarray] = {}       # grid -> its CD directions (CD != 0)
        self.notes: dict[str, list[str]] = {}         # message -> the cards it concerns

    # ---- cards into the deck ------------------------------------------------------------
    def add(self, card) -> None:
        if card.name == "PARAM":
            _param(self, card)
        if card.name in NO_EFFECT:
            if card.name == "PBUSHT":
                self.note(card, PBUSHT_NOTE)
            n, src = self.deck.no_effect.get(card.name, (0, card.src))
            self.deck.no_effect[card.name] = (n + 1, src)
            return
        parser = PARSERS.get(card.name)
        if parser is None:
            if self.keep_unmodelled and card.name not in NOT_PASSABLE and known(card.name):
                self.keep(card)
                return
            entry = self.unsupported.setdefault(card.name, [0, card])
            entry[0] += 1
            return
        parser(self, card)
        if card.name in design.TARGET_CARDS:
            design.record_target(self, card)

    def bulk(self, collection: str, id_space: str, cards: np.ndarray, keys: list, entities: list) -> None:
        """Entities a bulk converter made from ``cards`` (table indices), for ``collection`` of
        the deck, their IDs claimed in ``id_space`` (checked for duplicates in :func:`read_table`)."""
        self.bulk_parts.setdefault(collection, []).append((cards, keys, entities))
        self.bulk_ids.setdefault(id_space, []).append((cards, keys))

    def note(self, card, message: str) -> None:
        """A note on something read but not modelled as written (Deck.notes: one line per
        message, naming every card it concerns)."""
        self.notes.setdefault(message, []).append(f"{card.name} {card.text(2)} at {card.src}")

    def note_blank(self, key: str, card: int, gid: int) -> None:
        if self.first_blank[key] is None:
            self.first_blank[key] = gid

    def grid_card(self, gid: int):
        c = self.grid_cards[gid]
        return TableCard(self.table, c, "GRID") if isinstance(c, int) else c

    def keep(self, card) -> None:
        """An unmodelled card into ``Deck.unmodelled``: its fields typed (integer, real, word,
        blank) as NASTRAN reads them, its grids when the card's layout is known (an element of
        :data:`ELEMENT_GRIDS`: those fields, which must be grid IDs; a property, material or
        other card that connects no grid: none; any other card: unknown). An element's EID joins
        the element ID space (NASTRAN: unique over all elements), so a clash is caught."""
        fields = tuple(typed(f.text) for f in card.fields[1:])
        layout = ELEMENT_GRIDS.get(card.name)
        grids: tuple[int, ...] | None
        if layout is not None:
            grids = tuple(_int(card, i) for i in layout if card.text(i))
            self.claim("element", _int(card, 2), card, 2)
        else:
            grids = () if _connects_nothing(card.name) else None
        self.deck.unmodelled.append(Unmodelled(card.name, fields, card.src, grids))

    def apply_baror(self) -> None:
        """BAROR's PID and orientation into the CBARs that leave those fields blank."""
        b = self.baror
        pid = _int(b, 3, 0) if b is not None else 0
        if pid:
            for eid in self.pid_blank:
                self.deck.cbars[eid] = replace(self.deck.cbars[eid], pid=pid)
        x, g0 = _orientation(b) if b is not None else (None, None)
        for eid, c in self.orient_blank:
            if x is None and g0 is None:
                raise c.error(6, "orientation vector X1 X2 X3 or grid G0 required (blank here "
                                 "and no BAROR default)")
            self.deck.cbars[eid] = replace(self.deck.cbars[eid], x=x, g0=g0)

    def unused_sections(self) -> None:
        """Shell and solid properties and their materials that no element of the deck uses
        (:data:`UNUSED_IF_UNREFERENCED`: a pre-processor exports every property of its model)
        have no effect on the structure: counted in ``Deck.no_effect`` with a note, instead of
        kept for an external solver or refused. Without ``keep_unmodelled`` every unmodelled
        card is refused anyway unless all of them are such cards (then no element uses them);
        with it, a property is unused when no other kept card names its PID in field 3 (every
        integer field of a card of unknown layout counts), and a material when no kept card
        holds its MID in any integer field."""
        def accept(name: str, src: str, count: int) -> None:
            n, first = self.deck.no_effect.get(name, (0, src))
            self.deck.no_effect[name] = (n + count, first)
            self.notes.setdefault(_UNUSED_NOTE, []).append(f"{name} at {src}")

        if not self.keep_unmodelled:
            if self.unsupported and set(self.unsupported) <= UNUSED_IF_UNREFERENCED:
                for name, (n, card) in self.unsupported.items():
                    accept(name, card.src, n)
                self.unsupported.clear()
            return
        kept = self.deck.unmodelled
        if not any(u.name in UNUSED_IF_UNREFERENCED for u in kept):
            return

        def ints(u) -> set:
            return {f for f in u.fields if isinstance(f, int)}

        pids: set = set()
        for u in kept:
            if u.name in UNUSED_IF_UNREFERENCED:
                continue
            if u.grids is None:
                pids |= ints(u)
            elif u.grids and len(u.fields) > 1 and isinstance(u.fields[1], int):
                pids.add(u.fields[1])
        props = [u for u in kept if u.name in UNUSED_IF_UNREFERENCED and not u.name.startswith("MAT")]
        unused = {id(u) for u in props if not (u.fields and u.fields[0] in pids)}
        mids: set = set()
        for u in kept:
            if id(u) not in unused and not u.name.startswith("MAT"):
                mids |= ints(u)
        unused |= {id(u) for u in kept if u.name in UNUSED_IF_UNREFERENCED and u.name.startswith("MAT")
                   and not (u.fields and u.fields[0] in mids)}
        for u in kept:
            if id(u) in unused:
                accept(u.name, u.src, 1)
        self.deck.unmodelled = [u for u in kept if id(u) not in unused]

    def check_unsupported(self) -> None:
        """One DeckFormatError naming every unsupported card: count and first location of each.

        It points (file, line, field 1) at the first unsupported card of the deck."""
        self.unused_sections()
        if not self.unsupported:
            return
        raise unsupported_error([(name, n, c.src) for name, (n, c) in self.unsupported.items()],
                                keeping=self.keep_unmodelled)

    def claim(self, kind: str, ident: int, card, i: int) -> None:
        """Register ``ident`` of ``kind`` ("GRID", "element", "property" (of the card's family),
        ...) as defined by ``card``; an ID defined twice is an error naming both cards."""
        table = self.ids[f"property {PROPERTY_FAMILIES[card.name]}" if kind == "property" else kind]
        if ident in table:
            raise card.error(i, f"duplicate {kind} ID {ident} (already defined by {table[ident]})")
        table[ident] = f"{card.name} at {card.src}"

    def resolve_coordinates(self) -> None:
        """Coordinate systems into :class:`Coord` (basic origin and axes), GRID positions from
        their CP system into basic, CBAR orientation vectors and offsets from the grids' CD
        systems into basic. Definitions may chain in any order (a CORD2 in another system, a
        CORD1 on grids given in another system); a loop is an error."""
        deck = self.deck
        for gid in self.grid_cards:
            g = deck.grids[gid]
            for i, key, value in ((3, "CP", g.cp), (7, "CD", g.cd)):
                if value and value not in self.cords:
                    c = self.grid_card(gid)
                    via = "" if c.name == "GRID" else f" (the GRDSET default of GRID {gid} at {g.src})"
                    raise c.error(i, f"{key} {value}{via}: coordinate system {value} is not defined "
                                     f"(no CORD1R/C/S or CORD2R/C/S with CID {value})")
        for cid, (kind, c, d) in self.cords.items():
            if c.name.startswith("CORD2"):
                if d[0] and d[0] not in self.cords:
                    raise c.error(3, f"RID {d[0]}: coordinate system {d[0]} is not defined")
            else:
                for k, g in enumerate(d[1]):
                    if g not in deck.grids:
                        raise c.error(d[0] + 1 + k, f"grid {g} does not exist (no GRID)")
        pending_grids: dict[int, list[int]] = {}
        for gid, g in deck.grids.items():
            if g.cp:
                pending_grids.setdefault(g.cp, []).append(gid)
        waiting = {gid for ids in pending_grids.values() for gid in ids}
        pending = dict(self.cords)
        while pending or pending_grids:
            progress = False
            for cid in list(pending):
                kind, c, d = pending[cid]
                if c.name.startswith("CORD2"):
                    rid, pts = d
                    if rid and rid not in deck.coords:
                        continue
                    pts = np.array(pts, float)
                    if rid:
                        pts = deck.coords[rid].to_basic(pts)
                else:
                    if any(g in waiting for g in d[1]):
                        continue
                    pts = np.array([deck.grids[g].xyz for g in d[1]], float)
                deck.coords[cid] = coord_from_points(cid, kind, pts, c, d)
                del pending[cid]
                progress = True
            for cp in [k for k in pending_grids if k in deck.coords]:
                ids = pending_grids.pop(cp)
                xyz = deck.coords[cp].to_basic(np.array([deck.grids[g].xyz for g in ids], float))
                for gid, x in zip(ids, xyz.tolist()):
                    deck.grids[gid] = replace(deck.grids[gid], xyz=tuple(x))
                waiting.difference_update(ids)
                progress = True
            if not progress:
                cid, (kind, c, d) = next(iter(pending.items()))
                raise c.error(2, f"coordinate system {cid} cannot be resolved: its definition "
                                 f"depends on itself (systems {', '.join(map(str, sorted(pending)))} "
                                 f"refer to each other, directly or through grids)")
        with_cd = [gid for gid, g in deck.grids.items() if g.cd]
        self.frames = dict(zip(with_cd, deck.displacement_frames(with_cd)))
        for gid in deck.grids_on_cd_axis(with_cd):
            c = self.grid_card(gid)          # the GRID, or the GRDSET its CD came from
            self.notes.setdefault(ON_AXIS_RULE, []).append(
                f"GRID {gid} at {c.src}" if c.name == "GRID" else f"GRID {gid} (its CD from the {c.name} at {c.src})")

    def resolve_bars(self) -> None:
        """Every bar's orientation vector and offsets into basic, as its OFFT says (MSC QRG,
        CBAR remark 8): the first letter is the orientation vector's system (G: GA's
        displacement system, B: basic), the second and third those of the offsets at ends A
        and B (G: the grid's displacement system; O: the offset system, whose x axis runs from
        GA to GB, the grids themselves, with y in the plane of x and the orientation vector and
        z = x cross v). A blank OFFT of a CBAR is BAROR's, else GGG."""
        deck, frames = self.deck, self.frames
        offt_default = self.baror.text(9) if self.baror is not None else ""
        if offt_default in ("1", "2"):                # COSMIC's flag F (bars._offt): GGG
            offt_default = "GGG"
        in_offset = {eid for eid, o in self.cbar_offt.items() if "O" in o[1:]}
        if "O" in offt_default[1:]:
            in_offset |= {e for e, b in deck.cbars.items() if b.card == "CBAR" and e not in self.cbar_offt}
        if not frames and not in_offset:
            return
        for eid, b in deck.cbars.items():
            fa, fb = frames.get(b.ga), frames.get(b.gb)
            if fa is None and fb is None and eid not in in_offset:
                continue
            offt = self.cbar_offt.get(eid) or (offt_default if b.card == "CBAR" else "") or "GGG"
            x, wa, wb = b.x, b.wa, b.wb
            if fa is not None and x is not None and offt[0] == "G":
                x = tuple((fa.T @ np.array(x)).tolist())       # GA's CD components -> basic
            axes = self._offset_axes(b, x) if "O" in offt[1:] else None
            if wa is not None:
                if offt[1] == "O":
                    wa = tuple((np.array(wa) @ axes).tolist())
                elif fa is not None:
                    wa = tuple((fa.T @ np.array(wa)).tolist())
            if wb is not None:
                if offt[2] == "O":
                    wb = tuple((np.array(wb) @ axes).tolist())
                elif fb is not None:
                    wb = tuple((fb.T @ np.array(wb)).tolist())
            deck.cbars[eid] = replace(b, x=x, wa=wa, wb=wb)

    def _offset_axes(self, b, x) -> np.ndarray:
        """Rows x, y, z of a bar's offset system in basic (``x``: its orientation vector in basic)."""
        grids = self.deck.grids
        if b.ga not in grids or b.gb not in grids or (b.g0 is not None and b.g0 not in grids):
            return np.eye(3)                       # a missing grid: validate() names it
        xa, xb = np.array(grids[b.ga].xyz), np.array(grids[b.gb].xyz)
        v = np.array(grids[b.g0].xyz) - xa if b.g0 is not None else np.array(x)
        ex = xb - xa
        ez = np.cross(ex, v)
        if np.linalg.norm(ex) == 0.0 or np.linalg.norm(ez) <= 1e-9 * np.linalg.norm(ex) * np.linalg.norm(v):
            raise ModelError(f"1 model error(s):\n  {b.src}: {b.card} {b.eid}: offsets in the offset "
                             f"system (OFFT) need GA and GB apart and an orientation vector not "
                             f"parallel to GA -> GB")
        ex, ez = ex / np.linalg.norm(ex), ez / np.linalg.norm(ez)
        return np.array([ex, np.cross(ez, ex), ez])

    def finish(self) -> Deck:
        """GRDSET defaults into the GRIDs; SPC1 ``G1 THRU G2`` expanded (as in NASTRAN, grids of
        the range that do not exist are skipped)."""
        self.unused_sections()
        if self.grdset is not None:
            c = self.grdset
            gid = self.first_blank["SEID"]
            if _int(c, 9, 0, minimum=0) != 0 and gid is not None:
                raise c.error(9, f"superelements are not supported: SEID {_int(c, 9)} of GRDSET is "
                                 f"the default of every GRID whose SEID is blank, e.g. GRID {gid} at "
                                 f"{self.deck.grids[gid].src}; GRDSET SEID must be 0 or blank")
            ps = "" if c.text(8) == "0" else _components(c, 8, required=False)
            cp, cd = _int(c, 3, 0, minimum=0), _int(c, 7, 0, minimum=0)
            for key, value in (("CP", cp), ("CD", cd)):
                if value:
                    for gid in self.blank_sys[key]:
                        self.grid_cards.setdefault(gid, c)
                        self.deck.grids[gid] = replace(self.deck.grids[gid], **{key.lower(): value})
            if ps:
                for gid in self.blank_ps:
                    self.deck.grids[gid] = replace(self.deck.grids[gid], ps=ps)
        self.resolve_coordinates()
        for c, cid, i in self.pending_cids:
            if cid not in self.deck.coords:
                name = "CID" if i == 9 else "OCID"
                raise c.error(i, f"{name} {cid}: coordinate system {cid} is not defined")
        self.apply_baror()
        self.resolve_bars()
        self.deck.grids.update(self.spoints)
        scalar = set(self.spoints)
        for c, i, g, comp in self.point_refs:
            if g in self.deck.grids:              # a missing point: validate() names it
                _check_point(c, i, g, comp, scalar)
        ordered = None
        # SUPORT/SUPORT1 entries (sid None) form a constraint set of their own
        taken = {p[0] for p in self.spc1_pending if p[0] is not None} | set(self.deck.spcadds)
        suport_sid = max(taken, default=0) + 1
        for sid, comps, items, src, card, field in self.spc1_pending:
            grids: list[int] = []
            for item in items:
                if isinstance(item, tuple):
                    if ordered is None:
                        ordered = np.array(sorted(self.deck.grids), np.int64)
                    lo, hi = np.searchsorted(ordered, item[0]), np.searchsorted(ordered, item[1], "right")
                    grids.extend(ordered[lo:hi].tolist())
                else:
                    grids.append(item)
            if grids and (scalar or comps == "0"):
                comps = _spc_on_points(card, field, comps, grids, scalar, self.deck.grids)
            if grids:
                self.deck.spc1s.append(Spc1(suport_sid if sid is None else sid, comps, tuple(grids),
                                            src, "SPC1" if sid is not None else card.name))
        if any(p[0] is None for p in self.spc1_pending):
            _suport_apart(self.deck, [p for p in self.spc1_pending if p[0] is None])
        if scalar:
            _to_component_1(self.deck, scalar)
        matrices.finish(self)
        design.apply(self, PARSERS, _Reader)
        self.deck.notes = [f"{', '.join(cards[:5])}{f' and {len(cards) - 5} more' if len(cards) > 5 else ''}: "
                           f"{message}" for message, cards in self.notes.items()]
        return self.deck


def _suport_apart(deck: Deck, pending) -> None:
    """A SUPORT/SUPORT1 component may not also be held by an SPC, SPC1 or GRID PS, nor be named
    by two of them (NASTRAN: a DOF belongs to one of the mutually exclusive sets r and s)."""
    held: dict[tuple[int, int], str] = {}
    for s in deck.spc1s:
        if s.card == "SPC1":
            for g in s.grids:
                for k in s.components:
                    held.setdefault((g, int(k)), f"an SPC/SPC1 of set {s.sid} at {s.src}")
    for g in deck.grids.values():
        for k in g.ps or "":
            held.setdefault((g.id, int(k)), f"GRID {g.id}'s PS at {g.src}")
    for _, comps, items, _, card, field in pending:
        for g in items:
            for k in ("1" if comps == "0" else comps):
                key = (g, int(k))
                if key in held:
                    raise card.error(field, f"grid {g} component {k} is also held by {held[key]}: "
                                            f"a DOF is a reference (r-set) DOF or a constrained "
                                            f"(s-set) one, not both (NASTRAN refuses it too)")
                held[key] = f"{card.name} at {card.src}"


def _check_point(c, i: int, g: int, comp: int, scalar: set[int]) -> None:
    """A reference to point ``g`` with component ``comp`` (0: blank or 0) must fit its kind
    (MSC QRG: 1-6 on a grid, 0 or blank on a scalar point; 1, which MYSTRAN requires on a
    scalar point in CELAS1/CELAS2 and MPC, is taken as its one DOF too). A point that exists in
    neither kind is left to ``validate``, which names it."""
    if g in scalar:
        if comp not in (0, 1):
            raise c.error(i, f"point {g} is a scalar point (SPOINT): its one component is 0 or "
                             f"blank, not {comp}")
    elif comp == 0 and c.name not in ("CELAS3", "CELAS4"):
        raise c.error(i, f"component 0 or blank names a scalar point, but point {g} is no SPOINT "
                         f"(a grid needs a component 1-6)")
    elif comp == 0:
        raise c.error(i, f"{c.name} joins scalar points only, and point {g} is no SPOINT")


def _spc_on_points(c, i: int, comps: str, grids: list[int], scalar: set[int], known) -> str:
    """The components of an SPC/SPC1 entry on ``grids``, checked against their kinds: ``"0"``
    (blank or 0) for scalar points only, digits for grids only (``"1"`` also on a scalar point).
    A point in neither (``known``: every point) is left to ``validate``, which names it."""
    for g in grids:
        if g not in known:
            continue
        if comps == "0" and g not in scalar:
            raise c.error(i, f"component 0 or blank names scalar points, but point {g} is no "
                             f"SPOINT (a grid needs components 1-6)")
        if comps not in ("0", "1") and g in scalar:
            raise c.error(i, f"point {g} is a scalar point (SPOINT): its one component is 0 or "
                             f"blank, not {comps}")
    return "1" if comps == "0" else comps


def _to_component_1(deck: Deck, scalar: set[int]) -> None:
    """Component 0 (a scalar point's one DOF) as the component 1 that holds it."""
    for eid, s in deck.springs.items():
        if (s.g1 and not s.c1) or (s.g2 and not s.c2):
            deck.springs[eid] = replace(s, c1=s.c1 or (1 if s.g1 else 0), c2=s.c2 or (1 if s.g2 else 0))
    deck.mpcs[:] = [m if all(c for _, c, _ in m.terms) else
                    replace(m, terms=tuple((g, c or 1, a) for g, c, a in m.terms)) for m in deck.mpcs]


# --------------------------------------------------------------------------------------------
# the two paths
# --------------------------------------------------------------------------------------------
def read_cards(cards, keep_unmodelled: bool, validate) -> Deck:
    """The reference path: ``cards`` one at a time, in the deck's order."""
    r = _Reader(keep_unmodelled)
    for card in cards:
        r.add(card)
    r.check_unsupported()
    deck = r.finish()
    validate(deck)
    return deck


class _NoGC:
    """Garbage collection paused while many entities are made (each would count towards a
    collection that finds nothing to free)."""

    def __enter__(self):
        self.was = gc.isenabled()
        gc.disable()

    def __exit__(self, *exc):
        if self.was:
            gc.enable()


def read_table(table: CardTable, keep_unmodelled: bool, validate, cards: np.ndarray | None = None) -> Deck:
    """The bulk path on the cards of ``table`` (``cards``: a subset, table indices ascending).
    Raises :class:`Fallback` (or the error a parser raised) when the reference path must read
    the deck instead."""
    with _NoGC():
        return _read_table(table, keep_unmodelled, validate, cards)


def _read_table(table, keep_unmodelled, validate, cards):
    r = _Reader(keep_unmodelled, table)
    kinds = table.kinds(cards)
    one_by_one: list[np.ndarray] = []
    bulk: dict[str, np.ndarray] = {}
    for name, idx in kinds.items():
        if name in NO_EFFECT:
            r.deck.no_effect[name] = (len(idx), table.src(idx[:1])[0])
            if name == "PARAM":
                for c in idx.tolist():
                    _param(r, TableCard(table, c, name))
            elif name == "PBUSHT":
                for c in idx.tolist():
                    r.note(TableCard(table, c, name), PBUSHT_NOTE)
        elif name in BULK:
            bulk[name] = idx
        elif name in PARSERS or (keep_unmodelled and name not in NOT_PASSABLE and known(name)):
            one_by_one.append(idx)
        else:
            raise Fallback(name)                # unsupported: the reference path names them all
    added: dict[str, list[tuple[int, object]]] = {k: [] for k in _MERGED}
    names = table.names

    def parse(idx: np.ndarray) -> None:
        d = r.deck
        for c in np.sort(idx).tolist():
            sizes = (len(d.grids), len(d.cbars), len(d.rods))
            r.add(TableCard(table, c, names[c].decode()))
            for k, (coll, n) in enumerate(zip(_MERGED, sizes)):
                col = getattr(d, coll)
                if len(col) == n + 1:
                    added[coll].append((c, next(reversed(col))))
                elif len(col) > n:              # a card of two elements (COSMIC's CROD, CTUBE)
                    new = list(itertools.islice(reversed(col), len(col) - n))[::-1]
                    added[coll] += [(c, key) for key in new]

    if one_by_one:
        parse(np.concatenate(one_by_one))
    left = [BULK[name](r, table, idx) for name, idx in bulk.items()]
    if left:
        parse(np.concatenate(left))
    _merge(r, added)
    _check_ids(r)
    deck = r.finish()
    validate(deck)
    deck.files = table.files if cards is None else []
    return deck


def _merge(r: _Reader, added: dict) -> None:
    """Each collection filled by converters and parsers, in the deck's order of the cards."""
    for coll, parts in r.bulk_parts.items():
        mine = getattr(r.deck, coll)
        extra = added[coll]
        if len(parts) == 1 and not extra:
            _, keys, ents = parts[0]
            setattr(r.deck, coll, dict(zip(keys, ents)))
            continue
        idx = np.concatenate([p[0] for p in parts] + [np.array([c for c, _ in extra], np.int64)])
        keys = [k for p in parts for k in p[1]] + [k for _, k in extra]
        ents = [e for p in parts for e in p[2]] + [mine[k] for _, k in extra]
        order = np.argsort(idx, kind="stable").tolist()
        setattr(r.deck, coll, {keys[i]: ents[i] for i in order})


def _check_ids(r: _Reader) -> None:
    """No ID twice in one ID space (the reference path names the duplicate and the first)."""
    for space, parts in r.bulk_ids.items():
        ids = np.concatenate([np.asarray(k, np.int64) for _, k in parts]
                             + [np.fromiter(r.ids[space], np.int64, len(r.ids[space]))])
        if ids.size and 0 <= ids.min() and ids.max() < 8 * ids.size + 1024:
            twice = np.bincount(ids).max() > 1
        else:
            s = np.sort(ids)
            twice = bool((s[1:] == s[:-1]).any())
        if twice:
            raise Fallback(f"duplicate {space} ID")
