"""Thermal loads of a linear static subcase (``TEMPERATURE(LOAD) = n``, ``TEMP = n``), read
from the cards of an input file for ``blackbox import``:

* ``TEMP SID G1 T1 G2 T2 G3 T3``: the temperatures of grids;
* ``TEMPD SID1 T1 SID2 T2 ...``: the temperature of every grid of set SIDi that no TEMP of the
  set names;
* ``TEMPRB SID EID TA TB TP1A TP1B TP2A TP2B``: the mean temperatures of a bar's or rod's ends
  and the bar's effective linear gradients (they replace the grids' temperatures for that
  element); only the first line: MSC's continuation holds stress-recovery temperatures and then
  further elements, MYSTRAN's only further elements, so a continuation is an error naming both;
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
    element: dict[int, dict[int, tuple[tuple[float, ...], object]]] = field(default_factory=dict)
    materials: dict[int, tuple[float, float]] = field(default_factory=dict)
    rigid_alpha: list = field(default_factory=list)   # RBE2/RBAR cards with an ALPHA

    @property
    def set_ids(self) -> set[int]:
        return set(self.grid) | set(self.default) | set(self.element)

    def has(self, sid: int) -> bool:
        return sid in self.set_ids

    def element_temperatures(self, sid: int, deck, sel: str):
        """``{eid: (T mean, TP1A, TP1B, TP2A, TP2B, kind)}`` of every bar and rod of the model
        under set ``sid``; a located error for an element end with no temperature."""
        grids, default = self.grid.get(sid, {}), self.default.get(sid)
        own = self.element.get(sid, {})

        def at(g: int, what: str) -> float:
            if g in grids:
                return grids[g][0]
            if default is not None:
                return default[0]
            first = next(iter(own.values()), None) or next(iter(grids.values()), None)
            raise first[1].error(2, f"temperature set {sid}{sel} gives grid {g} ({what}) no "
                                    f"temperature: no TEMP names it and the set has no TEMPD")

        out = {}
        for eid, (values, card) in own.items():
            if eid not in deck.cbars and eid not in deck.rods:
                raise card.error(3, f"element {eid} is not a CBAR, CBEAM, CROD, CONROD or CTUBE of "
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

    def _first_card(self, sid: int):
        for table in (self.element.get(sid, {}), self.grid.get(sid, {})):
            for _, card in table.values():
                return card
        return self.default[sid][1]

    def loads(self, sid: int, deck, sel: str = "", initial: int | None = None) -> dict[tuple[int, int], float]:
        """The nodal loads (basic) of temperature set ``sid`` on the model's bars and rods:
        strain alpha (T - TREF) of each. ``initial`` (a TEMP(INIT) set) is accepted only where
        it changes nothing: every loaded element's initial temperature equal to its TREF."""
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
            if alpha == 0.0:
                continue
            if init is not None and init[eid][0] != tref:
                raise card.error(1, f"TEMPERATURE(INITIAL) = {initial} gives {element.card} {eid} the "
                                    f"initial temperature {init[eid][0]:g}, not its MAT1 {mid} TREF "
                                    f"{tref:g}: which of the two the thermal strain starts from "
                                    f"differs between NASTRAN versions, so the thermal load is not "
                                    f"imported{sel}")
            strain = alpha * (t - tref)
            try:
                if kind == "bar":
                    loads = thermal_bar_loads(deck, element, alpha, strain, (tp1a, tp1b), (tp2a, tp2b))
                else:
                    loads = thermal_rod_loads(deck, element, strain)
            except LoadError as exc:
                raise self.element[sid][eid][1].error(exc.args[0], exc.args[1]) from None
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
            if len(c.fields) > 9 and any(c.text(i) for i in range(10, len(c.fields) + 1)):
                raise c.error(10, "a TEMPRB continuation is read differently by MSC Nastran (stress-"
                                  "recovery temperatures TCA ... TFB, then further elements) and by "
                                  "MYSTRAN (further elements only): give each element a TEMPRB of "
                                  "one line")
            sid, eid = _int(c, 2), _int(c, 3)
            values = (_real(c, 4), _real(c, 5), *(_real(c, i, 0.0) for i in range(6, 10)))
            table = out.element.setdefault(sid, {})
            if eid in table:
                raise c.error(3, f"element {eid} has a TEMPRB in set {sid} already ({table[eid][1].src})")
            table[eid] = (values, c)
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
