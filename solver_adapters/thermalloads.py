"""Thermal loads of a linear static subcase (``TEMPERATURE(LOAD) = n``, ``TEMP = n``), read
from the cards of an input file for ``blackbox import``:

* ``TEMP SID G1 T1 G2 T2 G3 T3``: the temperatures of grids;
* ``TEMPD SID1 T1 SID2 T2 ...``: the temperature of every grid of set SIDi that no TEMP of the
  set names;
* ``TEMPRB SID EID1 TA TB TP1A TP1B TP2A TP2B / TCA TDA TEA TFA TCB TDB TEB TFB / EID2 EID3
  ...`` (MSC QRG TEMPRB): the mean temperatures of a bar's or rod's ends (blank: 0.0) and the
  bar's effective linear gradients (they replace the grids' temperatures for those elements).
  The second line's temperatures at the stress-recovery points C, D, E, F of each end are read
  and do not load the structure ("used for stress recovery only", QRG); the third line on lists
  further elements that get the same temperatures, ``EIDa THRU EIDb`` meaning every bar and rod
  of the model in the range. MYSTRAN reads the continuation otherwise (further elements only):
  the mystran adapter gets the import's nodal loads, never the TEMPRB;
* ``MAT1`` A (field 7, the expansion coefficient) and TREF (field 8, the stress-free
  temperature, default 0.0).

The element temperature of a CBAR, CBEAM, CROD, CONROD or CTUBE is the mean of its two ends
(TEMPRB TA and TB, or its grids' temperatures; the gradients then zero), as NASTRAN and
MYSTRAN take it for the axial load; the nodal loads are the fixed-end forces of the free
thermal strain (:mod:`solver_adapters.reference.loads`). Springs (CELAS), CBUSH and the rigid
elements as the reference solver models them (no ALPHA) have no thermal load, as in NASTRAN
(and MYSTRAN, which gives ELAS and BUSH elements no temperature). Errors name the card, its
file, line and field.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from solver_adapters.elementloads import _int, _max_fields, _real
from solver_adapters.reference.loads import LoadError, thermal_bar_loads, thermal_rod_loads

__all__ = ["TEMPERATURE_CARDS", "ThermalCards", "read_thermal_cards"]

TEMPERATURE_CARDS = frozenset({"TEMP", "TEMPD", "TEMPRB"})
"""The temperature cards this module reads (TEMPP1, TEMPP3, TEMPAX ... stay refused)."""


@dataclass
class ThermalCards:
    """The temperature cards of a deck by set: grid temperatures (``grid``: SID -> grid ->
    (T, card)), defaults (``default``: SID -> (T, card)), bar/rod end temperatures
    (``element``: SID -> EID -> ((TA, TB, TP1A, TP1B, TP2A, TP2B), card)), and the MAT1 A and
    TREF (``materials``: MID -> (A, TREF))."""
    grid: dict[int, dict[int, tuple[float, object]]] = field(default_factory=dict)
    default: dict[int, tuple[float, object]] = field(default_factory=dict)
    element: dict[int, dict[int, tuple[tuple[float, ...], object, int]]] = field(default_factory=dict)
    # TEMPRB EIDa THRU EIDb: SID -> (a, b) -> (values, card, field of EIDa)
    ranges: dict[int, dict[tuple[int, int], tuple[tuple[float, ...], object, int]]] = field(default_factory=dict)
    materials: dict[int, tuple[float, float]] = field(default_factory=dict)
    rigid_alpha: list = field(default_factory=list)   # RBE2/RBAR cards with an ALPHA

    @property
    def set_ids(self) -> set[int]:
        return set(self.grid) | set(self.default) | set(self.element) | set(self.ranges)

    def has(self, sid: int) -> bool:
        return sid in self.set_ids

    def element_temperatures(self, sid: int, deck, sel: str):
        """``{eid: (T mean, TP1A, TP1B, TP2A, TP2B, kind)}`` of every bar and rod of the model
        under set ``sid``; a located error for an element end with no temperature."""
        grids, default = self.grid.get(sid, {}), self.default.get(sid)
        own = self.elements(sid, deck)

        def at(g: int, what: str) -> float:
            if g in grids:
                return grids[g][0]
            if default is not None:
                return default[0]
            first = next(iter(own.values()), None) or next(iter(grids.values()), None)
            raise first[1].error(2, f"temperature set {sid}{sel} gives grid {g} ({what}) no "
                                    f"temperature: no TEMP names it and the set has no TEMPD")

        out = {}
        for eid, (values, card, i) in own.items():
            if eid not in deck.cbars and eid not in deck.rods:
                raise card.error(i, f"element {eid} is not a CBAR, CBEAM, CROD, CONROD or CTUBE of "
                                    f"the model: TEMPRB gives temperatures to bars and rods{sel}")
        for eid, b in deck.cbars.items():
            if eid in own:
                t = own[eid][0]
                out[eid] = (0.5 * (t[0] + t[1]), *t[2:], "bar")
            else:
                out[eid] = (0.5 * (at(b.ga, f"end A of {b.card} {eid}") + at(b.gb, f"end B of {b.card} {eid}")),
                            0.0, 0.0, 0.0, 0.0, "bar")
        for eid, r in deck.rods.items():
            if eid in own:
                t = own[eid][0]
                out[eid] = (0.5 * (t[0] + t[1]), 0.0, 0.0, 0.0, 0.0, "rod")
            else:
                out[eid] = (0.5 * (at(r.ga, f"end A of {r.card} {eid}") + at(r.gb, f"end B of {r.card} {eid}")),
                            0.0, 0.0, 0.0, 0.0, "rod")
        return out

    def elements(self, sid: int, deck) -> dict[int, tuple[tuple[float, ...], object, int]]:
        """The TEMPRB temperatures of set ``sid`` by element: ``(values, card, field)``, the
        ``THRU`` ranges as the model's bars and rods in them."""
        own = dict(self.element.get(sid, {}))
        for (lo, hi), (values, card, i) in self.ranges.get(sid, {}).items():
            for eid in [*deck.cbars, *deck.rods]:
                if lo <= eid <= hi:
                    if eid in own:
                        raise card.error(i, f"element {eid} (of {lo} THRU {hi}) has a TEMPRB in set "
                                            f"{sid} already ({own[eid][1].src})")
                    own[eid] = (values, card, i)
        return own

    def _first_card(self, sid: int):
        for table in (self.element.get(sid, {}), self.ranges.get(sid, {}), self.grid.get(sid, {})):
            for entry in table.values():
                return entry[1]
        return self.default[sid][1]

    def loads(self, sid: int, deck, sel: str = "", initial: int | None = None) -> dict[tuple[int, int], float]:
        """The nodal loads (basic) of temperature set ``sid`` on the model's bars and rods:
        strain alpha (T - TREF) of each, or alpha (T - T0) with ``initial`` (a TEMP(INIT) set:
        T0 its temperature of the element, its gradients subtracted from the load's)."""
        card = self._first_card(sid)
        if deck.unmodelled:
            u = deck.unmodelled[0]
            raise card.error(1, f"temperature set {sid}{sel}: the model has elements the reference "
                                f"solver does not model ({u.name} at {u.src}): their thermal load "
                                f"is not known here")
        if self.rigid_alpha:
            c = self.rigid_alpha[0]
            raise c.error(1, f"{c.name} with a thermal expansion coefficient ALPHA, and temperature "
                             f"set {sid} is selected{sel}: the thermal expansion of rigid elements "
                             f"is not modelled")
        temps = self.element_temperatures(sid, deck, sel)
        init = self.element_temperatures(initial, deck, sel) if initial is not None else None
        out: dict[tuple[int, int], float] = {}
        for eid, (t, tp1a, tp1b, tp2a, tp2b, kind) in temps.items():
            element = deck.cbars[eid] if kind == "bar" else deck.rods[eid]
            mid = deck.pbars[element.pid].mid if kind == "bar" else deck.rod_section(element)[0]
            alpha, tref = self.materials.get(mid, (0.0, 0.0))
            designed = deck.designed.get(("MAT1", mid), {})     # SOL 200: MAT1 A, TREF designed
            alpha, tref = designed.get(7, alpha), designed.get(8, tref)
            if alpha == 0.0:
                continue
            if init is not None:
                # MSC QRG TEMPERATURE (case), remark 6: in linear statics the TEMPERATURE(INITIAL)
                # set, when given, is the initial temperature of the thermal strain instead of
                # TREF; its gradients are the initial state's too
                t0, g0a, g0b, g0c, g0d, _ = init[eid]
                strain = alpha * (t - t0)
                tp1a, tp1b, tp2a, tp2b = tp1a - g0a, tp1b - g0b, tp2a - g0c, tp2b - g0d
            else:
                strain = alpha * (t - tref)
            try:
                if kind == "bar":
                    loads = thermal_bar_loads(deck, element, alpha, strain, (tp1a, tp1b), (tp2a, tp2b))
                else:
                    loads = thermal_rod_loads(deck, element, strain)
            except LoadError as exc:
                raise self.elements(sid, deck)[eid][1].error(exc.args[0], exc.args[1]) from None
            for key, v in loads.items():
                out[key] = out.get(key, 0.0) + v
        return out


def read_thermal_cards(cards) -> ThermalCards:
    """The temperature cards and the MAT1 expansion coefficients among ``cards`` (every bulk
    card of the input file); located errors for bad fields and duplicates."""
    out = ThermalCards()
    for c in cards:
        name = c.name
        if name == "TEMP":
            _max_fields(c, 8)
            sid = _int(c, 2)
            pairs = [(i, i + 1) for i in (3, 5, 7) if c.text(i) or c.text(i + 1)]
            if not pairs:
                raise c.error(3, "TEMP needs at least one pair G T")
            table = out.grid.setdefault(sid, {})
            for gi, ti in pairs:
                g, t = _int(c, gi), _real(c, ti)
                if g in table:
                    raise c.error(gi, f"grid {g} has a temperature in set {sid} already "
                                      f"({table[g][1].src})")
                table[g] = (t, c)
        elif name == "TEMPD":
            _max_fields(c, 9)
            for i in (2, 4, 6, 8):
                if not c.text(i) and not c.text(i + 1):
                    continue
                sid, t = _int(c, i), _real(c, i + 1)
                if sid in out.default:
                    raise c.error(i, f"set {sid} has a TEMPD already ({out.default[sid][1].src})")
                out.default[sid] = (t, c)
        elif name == "TEMPRB":
            _read_temprb(c, out)
        elif name == "MAT1":
            out.materials[_int(c, 2)] = (_real(c, 7, 0.0), _real(c, 8, 0.0))
        elif name == "RBAR" and c.text(9):
            if _real(c, 9, 0.0):
                out.rigid_alpha.append(c)
        elif name == "RBE2":
            if any("." in c.text(i) for i in range(5, len(c.fields) + 1)):
                out.rigid_alpha.append(c)
        elif name == "RBE3":
            if any(c.text(i) == "ALPHA" for i in range(2, len(c.fields) + 1)):
                out.rigid_alpha.append(c)
    return out


def _read_temprb(c, out: ThermalCards) -> None:
    """TEMPRB SID EID1 TA TB TP1A TP1B TP2A TP2B / TCA ... TFB / EID2 EID3 ... (MSC QRG): the
    first line's temperatures for EID1 and every element of the third line on (``THRU``
    between two IDs: the range); the stress-recovery temperatures are read and not used."""
    sid, eid = _int(c, 2), _int(c, 3)
    values = tuple(_real(c, i, 0.0) for i in range(4, 10))
    for i in range(10, 18):                         # TCA TDA TEA TFA TCB TDB TEB TFB
        _real(c, i, 0.0)
    table = out.element.setdefault(sid, {})
    ranges = out.ranges.setdefault(sid, {})

    def claim(e: int, i: int) -> None:
        if e in table:
            raise c.error(i, f"element {e} has a TEMPRB in set {sid} already ({table[e][1].src})")
        table[e] = (values, c, i)

    claim(eid, 3)
    n = len(c.fields)
    i = 18
    while i <= n:
        if not c.text(i):
            i += 1
            continue
        if c.text(i) == "THRU":
            raise c.error(i, "THRU needs an element ID before it")
        e = _int(c, i)
        if i + 1 <= n and c.text(i + 1) == "THRU":
            hi = _int(c, i + 2)
            if hi <= e:
                raise c.error(i + 2, f"THRU range {e} THRU {hi}: the second ID must be larger")
            ranges[(e, hi)] = (values, c, i)
            i += 3
        else:
            claim(e, i)
            i += 1
