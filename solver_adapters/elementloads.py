"""The load cards that act on elements rather than grids: PLOAD1 (bars and beams), GRAV and
RFORCE (the lumped mass), read from the cards of an input file for ``blackbox import``. Their
nodal loads come from the reference solver's elements (:mod:`solver_adapters.reference.loads`,
which says how NASTRAN applies each); a GRAV or RFORCE reads the masses from MAT1 RHO, the NSM
of PBAR, PBARL, PBEAM, PBEAML, PROD and CONROD, the CONM2 cards and PARAM,WTMASS. Errors name
the card, its file, line and field.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver_adapters.bdf import parse_int, parse_real
from solver_adapters.bdf.sections import PBARL_DIMS, pbeam_stations
from solver_adapters.protocol import DeckFormatError
from solver_adapters.reference.loads import (SCALES, TYPES, LoadError, Masses, Pload1,
                                             gravity_loads, pload1_loads)

__all__ = ["BarLoad", "Gravity", "Rotation", "read_pload1", "read_grav", "read_rforce", "MassReader"]

_OTHER_MASS = ("CMASS3", "CMASS4", "NSM", "NSM1", "NSMADD", "NSML", "NSML1")


def _int(c, i: int, *, minimum: int = 1, default: int | None = None) -> int:
    text = c.text(i)
    if not text:
        if default is None:
            raise c.error(i, "required integer field is blank")
        return default
    try:
        v = parse_int(text)
    except DeckFormatError as exc:
        raise c.error(i, str(exc).split(": ")[-1]) from None
    if v < minimum:
        raise c.error(i, f"must be >= {minimum}")
    return v


def _real(c, i: int, default: float | None = None) -> float:
    text = c.text(i)
    if not text:
        if default is None:
            raise c.error(i, "required real field is blank")
        return default
    try:
        return parse_real(text)
    except DeckFormatError as exc:
        raise c.error(i, str(exc).split(": ")[-1]) from None


def card_value(deck, c, i: int, default: float) -> float:
    """Field ``i`` of the property or material card ``c`` as the model has it: its value at
    the initial design when a SOL 200 relation designs it (``Deck.designed``), else the card's."""
    got = deck.designed.get((c.name, _int(c, 2)), {}) if deck.designed else {}
    return got[i] if i in got else _real(c, i, default)


def _max_fields(c, n: int) -> None:
    for i in range(n + 1, len(c.fields) + 1):
        if c.text(i):
            raise c.error(i, f"{c.name} has at most {n} fields")


@dataclass(frozen=True)
class BarLoad:
    """One PLOAD1 card: its set, the load and the card (for located errors)."""
    sid: int
    load: Pload1
    raw: object

    def loads(self, deck, sel: str = "") -> dict[tuple[int, int], float]:
        """Nodal loads in basic; located errors for a load that cannot be applied."""
        c, eid = self.raw, self.load.eid
        b = deck.cbars.get(eid)
        if b is None:
            other = " (it is a rod)" if eid in deck.rods else ""
            raise c.error(3, f"element {eid} is not a CBAR or CBEAM of the model{other}: PLOAD1 "
                             f"applies to bars and beams{sel}")
        try:
            return pload1_loads(deck, b, self.load)
        except LoadError as exc:
            raise c.error(exc.args[0], exc.args[1]) from None


def read_pload1(c) -> BarLoad:
    """PLOAD1 SID EID TYPE SCALE X1 P1 X2 P2 (MSC QRG). X2 blank or equal to X1: a
    concentrated load P1 at X1; else a load varying linearly from P1 at X1 to P2 at X2. P2
    blank is 0.0, as in NASTRAN: pyNastran's pload1.bdf, whose distributed moments leave P2
    blank, agrees with NASTRAN's own results (its pload1.op2) that way, and not with P2 = P1."""
    _max_fields(c, 9)
    sid, eid = _int(c, 2), _int(c, 3)
    kind, scale = c.text(4), c.text(5)
    if kind not in TYPES:
        raise c.error(4, f"TYPE must be one of {', '.join(TYPES)}")
    if scale not in SCALES:
        raise c.error(5, f"SCALE must be one of {', '.join(SCALES)}")
    x1, p1 = _real(c, 6), _real(c, 7)
    x2 = _real(c, 8, x1)
    p2 = _real(c, 9, 0.0)
    return BarLoad(sid, Pload1(eid, kind, scale, x1, p1, None if x2 == x1 else x2, p2), c)


def coord_system(deck, card, field: int, cid: int, sel: str = ""):
    """The coordinate system ``cid`` of ``deck`` that field ``field`` of ``card`` names; a located
    error when the deck has none (``sel``: what selected the load, for the message)."""
    system = (getattr(deck, "coords", None) or {}).get(cid)
    if system is None:
        raise card.error(field, f"coordinate system CID {cid} not found (no CORD1R/C/S or "
                                f"CORD2R/C/S with that ID){sel}")
    return system


@dataclass(frozen=True)
class Gravity:
    """One GRAV card: SID CID A N1 N2 N3 (MB: no effect here)."""
    sid: int
    cid: int
    vector: tuple[float, float, float]
    raw: object

    def loads(self, deck, masses: "MassReader", sel: str = "") -> dict[tuple[int, int], float]:
        c = self.raw
        accel = np.array(self.vector, float)
        if self.cid:
            system = coord_system(deck, c, 3, self.cid, sel)
            if system.kind != "R":
                raise c.error(3, f"CID {self.cid} is a {system.card}: a GRAV direction is given in a "
                                 f"rectangular system only{sel}")
            accel = np.asarray(system.axes).T @ accel
        return gravity_loads(deck, masses.masses(c, deck, sel), accel)


def read_grav(c) -> Gravity:
    _max_fields(c, 8)
    sid = _int(c, 2)
    cid = _int(c, 3, minimum=0, default=0)
    a = _real(c, 4)
    n = (_real(c, 5, 0.0), _real(c, 6, 0.0), _real(c, 7, 0.0))
    _int(c, 8, minimum=-1, default=0)                       # MB: superelements only
    if not any(n):
        raise c.error(5, "the direction N1, N2, N3 is zero")
    return Gravity(sid, cid, (a * n[0], a * n[1], a * n[2]), c)


@dataclass(frozen=True)
class Rotation:
    """One RFORCE card: SID G CID A R1 R2 R3 METHOD / RACC MB IDRF (MSC QRG RFORCE): the
    centrifugal load of a steady rotation at A revolutions per unit time about the axis through
    grid G (0: the basic origin) along (R1, R2, R3), rectangular components in system CID (of a
    cylindrical or spherical one, along the rectangular axes it is defined by): the angular
    velocity w = 2 pi A (R1, R2, R3), not normalised (Autodesk Nastran QRG RFORCE remark 1), and
    each grid's mass loaded by -w x (w x (x - x_G)), its centripetal acceleration reversed:
    outwards, m |w|^2 times its distance from the axis."""
    sid: int
    grid: int
    cid: int
    a: float
    vector: tuple[float, float, float]
    raw: object

    def loads(self, deck, masses: "MassReader", sel: str = "") -> dict[tuple[int, int], float]:
        c = self.raw
        r = np.array(self.vector, float)
        if self.cid:
            system = coord_system(deck, c, 4, self.cid, sel)
            # "rectangular components" (MSC QRG RFORCE): a cylindrical or spherical CID's
            # components along the rectangular axes it is defined by
            r = np.asarray(system.axes).T @ r
        if self.grid and self.grid not in deck.grids:
            raise c.error(3, f"grid {self.grid} does not exist (no GRID){sel}")
        x0 = np.array(deck.grids[self.grid].xyz, float) if self.grid else np.zeros(3)
        w = 2.0 * np.pi * self.a * r
        ww = float(w @ w)

        def field(grid: int) -> np.ndarray:
            d = np.array(deck.grids[grid].xyz, float) - x0
            return ww * d - w * float(w @ d)           # -w x (w x d)

        return gravity_loads(deck, masses.masses(c, deck, sel, "RFORCE"), field)


def read_rforce(c) -> Rotation:
    """RFORCE SID G CID A R1 R2 R3 METHOD / RACC MB IDRF. METHOD 1 (blank; NASTRAN's default:
    the mass matrix times each grid's acceleration) only; an angular acceleration RACC, an
    element set IDRF are refused (located); MB (superelements) has no effect."""
    _max_fields(c, 12)
    sid = _int(c, 2)
    g = _int(c, 3, minimum=0, default=0)
    cid = _int(c, 4, minimum=0, default=0)
    a = _real(c, 5, 0.0)
    r = (_real(c, 6, 0.0), _real(c, 7, 0.0), _real(c, 8, 0.0))
    if not any(r):
        raise c.error(6, "the rotation vector R1, R2, R3 is zero")
    if _int(c, 9, default=1) != 1:
        raise c.error(9, "METHOD 2 (the elements' own mass distribution) is not imported: only METHOD 1 "
                         "(blank), the lumped mass times each grid's acceleration")
    if _real(c, 10, 0.0) != 0.0:
        raise c.error(10, "an angular acceleration RACC is not imported (a steady rotation only)")
    _int(c, 11, minimum=-1, default=0)
    if c.text(12):
        raise c.error(12, "IDRF (a rotation of part of the model) is not imported")
    return Rotation(sid, g, cid, a, r, c)


class MassReader:
    """The masses a GRAV acts on, read once from the input file's cards when a selected set
    has a GRAV (:class:`~solver_adapters.reference.loads.Masses`)."""

    def __init__(self, cards) -> None:
        self.cards = cards
        self._masses: Masses | None = None

    def masses(self, grav, deck, sel: str, lead: str = "GRAV") -> Masses:
        """The masses, read at the first call; errors are located at the card ``grav`` (a GRAV,
        or the PARAM,INREL of an inertia relief: ``lead`` names it)."""
        if self._masses is None:
            self._masses = self._read(grav, deck, sel, lead)
        return self._masses

    def _read(self, grav, deck, sel: str, lead: str) -> Masses:
        def refuse(card, why: str) -> DeckFormatError:
            return grav.error(1, f"{lead}{sel} acts on the mass of the whole model, and {card.name} at "
                                 f"{card.src} {why}")

        if deck.unmodelled:
            u = deck.unmodelled[0]
            raise grav.error(1, f"{lead}{sel} acts on the mass of the whole model, and the model has "
                                f"elements the reference solver does not model ({u.name} at {u.src}): "
                                f"their mass is not known here")
        rho: dict[int, float] = {}
        nsm: dict[str, dict[int, float]] = {"bar": {}, "rod": {}, "conrod": {}}
        conm2: list[tuple[int, float, tuple[float, float, float]]] = []
        inertia: list[tuple[int, np.ndarray]] = []
        conm1: list[tuple[int, np.ndarray]] = []
        scalar_cards: list = []
        pmass: dict[int, float] = {}
        wtmass = 1.0
        for c in self.cards:
            name = c.name
            if name in _OTHER_MASS:
                raise refuse(c, "is a mass this import does not read (it reads MAT1 RHO, the NSM "
                                "of bar, beam and rod properties, CONM1, CONM2, and CMASS1/CMASS2 "
                                "to ground)")
            if name == "MAT1":
                rho[_int(c, 2)] = card_value(deck, c, 6, 0.0)
            elif name == "PARAM" and c.text(2) == "WTMASS":
                wtmass = _real(c, 3)
            elif name == "PARAM" and c.text(2) == "COUPMASS" and _int(c, 3, minimum=-999, default=-1) > 0:
                raise refuse(c, "asks for the coupled mass matrix; this import applies NASTRAN's "
                                "default lumped mass only")
            elif name == "PBAR":
                nsm["bar"][_int(c, 2)] = card_value(deck, c, 8, 0.0)
            elif name in ("PBARL", "PBEAML"):
                n = PBARL_DIMS.get(c.text(5), 0)
                nsm["bar"][_int(c, 2)] = card_value(deck, c, 10 + n, 0.0)
            elif name == "PBEAM":
                self._pbeam(deck, c, nsm, refuse)
            elif name == "PROD":
                nsm["rod"][_int(c, 2)] = card_value(deck, c, 7, 0.0)
            elif name == "CONROD":
                nsm["conrod"][_int(c, 2)] = _real(c, 9, 0.0)
            elif name == "CONM2":
                g, m, x, i33 = self._conm2(c, deck)
                conm2.append((g, m, x))
                if i33.any():
                    inertia.append((g, i33))
            elif name == "CONM1":
                conm1.append(self._conm1(c, deck))
            elif name in ("CMASS1", "CMASS2"):
                scalar_cards.append(c)
            elif name == "PMASS":
                for base in (2, 4, 6, 8):
                    if c.text(base):
                        pmass[_int(c, base)] = _real(c, base + 1)
        bar_pid = {pid: self._bar_mass(p, rho.get(p.mid, 0.0), nsm["bar"].get(pid, 0.0))
                   for pid, p in deck.pbars.items()}
        rod_pid = {pid: rho.get(p.mid, 0.0) * p.a + nsm["rod"].get(pid, 0.0) for pid, p in deck.prods.items()}
        conrod = {r.eid: rho.get(r.mid, 0.0) * r.a + nsm["conrod"].get(r.eid, 0.0)
                  for r in deck.rods.values() if r.pid is None}
        scalar = [self._cmass(c, pmass, refuse) for c in scalar_cards]
        return Masses(bar_pid, rod_pid, conrod, conm2, wtmass, conm1, scalar, inertia)

    @staticmethod
    def _cmass(c, pmass: dict, refuse) -> tuple[int, int, float]:
        """CMASS1 EID PID G1 C1 G2 C2 (mass from PMASS) or CMASS2 EID M G1 C1 G2 C2: a scalar
        mass on one grid component (in the grid's CD system); one between two components
        is refused (the reference solver has no scalar mass element to check it with)."""
        if c.name == "CMASS1":
            pid = _int(c, 3, default=_int(c, 2))
            if pid not in pmass:
                raise c.error(3, f"PMASS {pid} not found")
            m = pmass[pid]
        else:
            m = _real(c, 3, 0.0)
        g1, c1 = _int(c, 4, minimum=0, default=0), _int(c, 5, minimum=0, default=0)
        g2, c2 = _int(c, 6, minimum=0, default=0), _int(c, 7, minimum=0, default=0)
        if g1 and g2:
            raise refuse(c, "joins two grid components; only a scalar mass to ground is read")
        g, comp = (g1, c1) if g1 else (g2, c2)
        if not g or not 1 <= comp <= 6:
            raise c.error(4, "a scalar mass needs a grid and a component 1-6 (scalar points are "
                             "not supported)")
        return g, comp, m

    @staticmethod
    def _conm1(c, deck) -> tuple[int, np.ndarray]:
        """CONM1 EID G CID M11 M21 M22 M31 ... M66 (the lower triangle, row by row): the 6x6 mass
        matrix at the grid in system CID (0: basic; else rectangular), turned into basic."""
        g = _int(c, 3)
        cid = _int(c, 4, minimum=0, default=0)
        if g not in deck.grids:
            raise c.error(3, f"grid {g} does not exist (no GRID)")
        m = np.zeros((6, 6))
        i = 5
        for row in range(6):
            for col in range(row + 1):
                m[row, col] = m[col, row] = _real(c, i, 0.0)
                i += 1
        if cid:
            system = (getattr(deck, "coords", None) or {}).get(cid)
            if system is None or system.kind != "R":
                raise c.error(4, f"CID {cid}: a CONM1 matrix needs a rectangular coordinate system "
                                 f"of the deck")
            T = np.zeros((6, 6))
            T[:3, :3] = T[3:, 3:] = np.asarray(system.axes)
            m = T.T @ m @ T
        return g, m

    @staticmethod
    def _bar_mass(p, rho: float, nsm) -> float | tuple[float, float]:
        """A bar property's mass per length, ``rho A + NSM``; at end A and end B when it varies
        along the beam (a tapered area, an NSM(B) of its own: linear between them)."""
        a_b = p.taper[0] if p.taper is not None else p.a
        nsm_a, nsm_b = nsm if isinstance(nsm, tuple) else (nsm, nsm)
        if a_b == p.a and nsm_b == nsm_a:
            return rho * p.a + nsm_a
        return rho * p.a + nsm_a, rho * a_b + nsm_b

    @staticmethod
    def _pbeam(deck, c, nsm: dict, refuse) -> None:
        """A PBEAM's mass per length: NSM(A) (field 9) and end B's (X/XB = 1.0; blank: NSM(A)),
        linear between them; an intermediate station's NSM must be NSM(A) (a mass varying
        through intermediate stations is refused), and the centre-of-gravity offsets M1, M2 must
        be zero."""
        pid = _int(c, 2)
        value = card_value(deck, c, 9, 0.0)
        end_b = value
        stations, kf = pbeam_stations(c)
        for f0 in stations:
            if _real(c, f0 + 1) == 1.0:
                end_b = card_value(deck, c, f0 + 7, value)
            elif _real(c, f0 + 7, value) != value:
                raise refuse(c, f"has a mass per length NSM varying through an intermediate station "
                                f"(field {f0 + 7})")
        nsm["bar"][pid] = value if end_b == value else (value, end_b)
        if any(_real(c, i, 0.0) for i in range(kf + 8, kf + 12)):
            raise refuse(c, "has centre-of-gravity offsets M1, M2: its mass is not on the beam's axis")

    @staticmethod
    def _conm2(c, deck) -> tuple[int, float, tuple[float, float, float], np.ndarray]:
        """CONM2 EID G CID M X1 X2 X3 / I11 I21 I22 I31 I32 I33: the mass at the grid moved by
        the offset X, given in system CID (0: basic; -1: X is the centre of gravity itself, in
        basic), and its inertia about the centre of gravity in basic (MSC QRG CONM2: the matrix
        [I11 -I21 -I31; -I21 I22 -I32; -I31 -I32 I33], in system CID; a GRAV does not use it)."""
        g = _int(c, 3)
        cid = _int(c, 4, minimum=-1, default=0)
        m = _real(c, 5, 0.0)
        x = np.array([_real(c, i, 0.0) for i in (6, 7, 8)])
        if g not in deck.grids:
            raise c.error(3, f"grid {g} does not exist (no GRID)")
        i11, i21, i22, i31, i32, i33 = (_real(c, i, 0.0) for i in range(10, 16))
        inertia = np.array([[i11, -i21, -i31], [-i21, i22, -i32], [-i31, -i32, i33]])
        if cid == -1:
            x = x - np.array(deck.grids[g].xyz)
        elif cid:
            system = (getattr(deck, "coords", None) or {}).get(cid)
            if system is None or system.kind != "R":
                raise c.error(4, f"CID {cid}: a CONM2 offset needs a rectangular coordinate system "
                                 f"of the deck")
            axes = np.asarray(system.axes)
            x = axes.T @ x
            inertia = axes.T @ inertia @ axes
        return g, m, tuple(x.tolist()), inertia
