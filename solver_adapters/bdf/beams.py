"""CBEAM, PBEAM and PBEAML, modelled as the prismatic CBAR element (no warping)."""

from __future__ import annotations

from solver_adapters.bdf.bars import _offt, bulk_bars
from solver_adapters.bdf.fields import _ignored_reals, _int, _max_fields, _orientation, _pin, _real
from solver_adapters.bdf.numbers import _real_or_none, same_printed
from solver_adapters.bdf.sections import PBEAM_SO, UNSYMMETRIC, library_pbar, library_section, pbeam_stations
from solver_adapters.deck import CBar, PBar


def _cbeam(r, c) -> None:
    """CBEAM: EID PID GA GB X1/G0 X2 X3 OFFT / PA PB W1A W2A W3A W1B W2B W3B / SA SB, modelled as
    the CBAR element (a prismatic beam without warping). BIT (tapered beams), the warping scalar
    points SA, SB and BEAMOR defaults are not supported: errors."""
    _max_fields(c, 19)
    for i, name in ((18, "SA"), (19, "SB")):
        if c.text(i):
            raise c.error(i, f"warping scalar point {name} not supported (no warping): must be blank")
    eid = _int(c, 2)
    pid = _int(c, 3, eid)
    ga, gb = _int(c, 4), _int(c, 5)
    x, g0 = _orientation(c)
    if x is None and g0 is None:
        raise c.error(6, "orientation vector X1 X2 X3 or grid G0 required (BEAMOR defaults are "
                         "not supported)")
    if c.text(9) and _real_or_none(c.text(9)) is not None:
        raise c.error(9, "BIT (built-in twist of a tapered beam) not supported: field 9 must be "
                         "blank, GGG or BGG")
    _offt(c)
    pa, pb = _pin(c, 10), _pin(c, 11)
    wa = tuple(_real(c, i, 0.0) for i in (12, 13, 14))
    wb = tuple(_real(c, i, 0.0) for i in (15, 16, 17))
    r.claim("element", eid, c, 2)
    r.cbar_offt[eid] = c.text(9) or "GGG"          # BAROR does not apply to CBEAM
    r.deck.cbars[eid] = CBar(eid, pid, ga, gb, x, g0, c.src, pa, pb,
                             wa if any(wa) else None, wb if any(wb) else None, card="CBEAM")


def _station_value(r, c, i: int, end_a: float, name: str) -> float | None:
    """A station's value where it differs from end A's, else ``None``: blank (end A's), equal
    to end A's, or equal to printing precision (a note, end A's value kept)."""
    text = c.text(i)
    if not text:
        return None
    value = _real(c, i)
    if value == end_a:
        return None
    if same_printed(c.text(_A_FIELD[name]), end_a, text, value):
        r.note(c, f"ends that differ only in printed digits ({name} {c.text(_A_FIELD[name])} "
                  f"and {text}) taken as prismatic, with end A's values")
        return None
    return value


_A_FIELD = {"A": 4, "I1": 5, "I2": 6, "I12": 7, "J": 8}


def _pbeam(r, c) -> None:
    """PBEAM: PID MID A I1 I2 I12 J NSM / C1..F2 (end A stress points) / [SO X/XB A I1 I2 I12
    J NSM [/ C1..F2 when SO = YES]] ... / K1 K2 S1 S2 NSI(A) NSI(B) CW(A) CW(B) / M1(A) M2(A)
    M1(B) M2(B) N1(A) N2(A) N1(B) N2(B) (MSC QRG).

    A station's A, I1, I2, I12, J left blank, equal to end A's, or differing only in printed
    digits (a note) are end A's. End B's (X/XB = 1.0) A, I1, I2, J may differ: a beam tapered
    linearly from end A to end B (``PBar.taper``; every end value positive, J may be 0 at both),
    which NASTRAN's CBEAM integrates as :func:`solver_adapters.reference.frame.tapered_local_stiffness`
    does. A section that varies otherwise is an error: through an intermediate station, in
    I12, or with a neutral-axis offset. K1, K2 default 1.0 (shear stiffness K A G, as in
    NASTRAN; 0.0: rigid in shear). Shear relief S1, S2 must be blank or 0. The warping
    coefficients CW are ignored with a note, as NASTRAN ignores them on a CBEAM without warping
    scalar points (SA, SB; the reader refuses those). The offsets of the centre of gravity M1,
    M2 carry mass only: no effect on a static stiffness (a note; a GRAV load refuses such a
    beam). The neutral axis N1, N2 (blank: 0.0), the same at both ends, is modelled: the axial
    force acts on it, bending and shear on the shear centre axis (``PBar.n1``, ``n2``). NSM,
    NSI and the stress recovery points are read and have no effect on the stiffness."""
    pid, mid = _int(c, 2), _int(c, 3)
    end_a = tuple(_real(c, i, 0.0) for i in (4, 5, 6, 7, 8))     # A I1 I2 I12 J
    _real(c, 9, 0.0)                                              # NSM
    _ignored_reals(c, range(10, 18))                              # C1(A) .. F2(A)
    names = ("A", "I1", "I2", "I12", "J")
    inner = []                                  # intermediate stations: (X/XB, its field, values)
    end_b: dict[str, tuple[float, int]] = {}    # end B's values that differ from end A's
    stations, kf = pbeam_stations(c)
    for f0 in stations:
        xxb = _real(c, f0 + 1)
        if not 0.0 < xxb <= 1.0:
            raise c.error(f0 + 1, "X/XB must be in (0, 1]")
        differs = {name: (v, f0 + 2 + k) for k, name in enumerate(names)
                   if (v := _station_value(r, c, f0 + 2 + k, end_a[k], name)) is not None}
        if xxb == 1.0:
            end_b = differs
        else:
            inner.append((xxb, f0 + 1, differs))
        _real(c, f0 + 7, 0.0)
        if c.text(f0) == "YES":
            _ignored_reals(c, range(f0 + 8, f0 + 16))
    for xxb, i, differs in inner:
        if differs or end_b:
            name, (value, f) = next(iter(differs.items())) if differs else (None, (None, i))
            raise c.error(f, f"a section that varies through an intermediate station (X/XB = {xxb:g}"
                             + (f": {name} {value:g}, at end A {end_a[names.index(name)]:g}" if name else "")
                             + ") is not supported: only a beam tapered linearly from end A to end B "
                               "(no intermediate station)")
    if "I12" in end_b:
        value, f = end_b["I12"]
        raise c.error(f, f"a product of inertia that varies along the beam (I12 {value:g} at end B, "
                         f"{end_a[3]:g} at end A) is not supported")
    if kf + 16 <= len(c.fields):            # a line after the K line and the M/N line
        raise c.error(kf + 16, "PBEAM has fields after its M/N line (or a station without "
                                    "SO = YES, YESA or NO)")
    k = []
    for i in (kf, kf + 1):
        value = _real(c, i, 1.0)
        if value < 0.0:
            raise c.error(i, "shear stiffness factor must be >= 0 (0.0: rigid in shear)")
        if value and end_a[0] == 0.0:
            if not any(end_a):
                raise c.error(4, "the section is empty: A, I1, I2, I12 and J are all 0.0 (a "
                                 "pre-processor's placeholder?): no stiffness to model; give "
                                 "the property its section")
            raise c.error(i, "shear stiffness factor needs a non-zero area A (0.0: rigid in shear)")
        k.append(value or None)
    for i, what in ((kf + 2, "shear relief S1"), (kf + 3, "shear relief S2")):
        if _real(c, i, 0.0) != 0.0:
            raise c.error(i, f"{what} not supported: must be blank or 0.0")
    _ignored_reals(c, (kf + 4, kf + 5))                           # NSI(A), NSI(B)
    if any(_real(c, i, 0.0) != 0.0 for i in (kf + 6, kf + 7)):
        r.note(c, "warping coefficient CW ignored: no warping scalar points SA, SB on its CBEAMs, "
                  "so NASTRAN ignores it too")
    if any(_real(c, i, 0.0) != 0.0 for i in range(kf + 8, kf + 12)):
        r.note(c, "centre-of-gravity offsets M1, M2: mass only, no effect on a static stiffness")
    n_a = (_real(c, kf + 12, 0.0), _real(c, kf + 13, 0.0))
    n_b = (_real(c, kf + 14, 0.0), _real(c, kf + 15, 0.0))
    for j in range(2):
        if n_b[j] != n_a[j] and not same_printed(c.text(kf + 12 + j), n_a[j], c.text(kf + 14 + j), n_b[j]):
            raise c.error(kf + 14 + j, f"neutral axis offset N{j + 1}(B) = {n_b[j]:g} differs from "
                                       f"N{j + 1}(A) = {n_a[j]:g}: a neutral axis that is not parallel "
                                       f"to the shear-centre axis is not supported")
    a, i1, i2, i12, j = end_a
    taper = None
    if end_b:
        if any(n_a):
            raise c.error(kf + 12, "a tapered beam with a neutral-axis offset (N1, N2) is not supported")
        if i12 != 0.0:
            raise c.error(7, "a tapered beam with a product of inertia I12 is not supported")
        taper = tuple(end_b[name][0] if name in end_b else end_a[names.index(name)]
                      for name in ("A", "I1", "I2", "J"))
        for name, va, vb in zip(("A", "I1", "I2", "J"), (a, i1, i2, j), taper):
            if name != "J" and not (va > 0.0 and vb > 0.0):
                raise c.error(end_b[name][1] if name in end_b and vb <= 0.0 else _A_FIELD[name],
                              f"a tapered beam needs {name} > 0 at both ends (end A {va:g}, end B {vb:g})")
            if name == "J" and (va < 0.0 or vb < 0.0):
                raise c.error(end_b[name][1] if vb < 0.0 else 8, f"J must be >= 0 (end A {va:g}, end B {vb:g})")
    if i12 != 0.0:
        if not i1 * i2 > i12 * i12:
            raise c.error(7, "product of inertia I12 needs I1 * I2 > I12^2")
        if k[0] or k[1]:
            raise c.error(kf, "shear flexibility (K1/K2, default 1.0) together with a non-zero "
                              "I12 is not supported: set K1 = K2 = 0.0 or I12 = 0.0")
    r.claim("property", pid, c, 2)
    r.deck.pbars[pid] = PBar(pid, mid, a, i1, i2, j, c.src, k[0], k[1], i12, card="PBEAM",
                             n1=n_a[0], n2=n_a[1], taper=taper)


def _pbeaml(r, c) -> None:
    """PBEAML: PID MID GROUP TYPE / DIM1(A) .. DIMn(A) NSM(A) [SO X/XB DIM1 .. DIMn NSM] ... as
    a prismatic beam: every station's dimensions (blank: end A's) must equal end A's (a
    different one is a tapered beam: error). Section constants as for PBARL."""
    pid, mid, kind, dims = library_section(c, max_fields=False)
    if kind in UNSYMMETRIC:
        # NASTRAN's CBEAM keeps the transverse shear flexibility of such a section (PBEAM's K1/K2
        # default 1.0) together with its I12; the reference solver models shear flexibility and
        # I12 only apart (as PBAR does), so the beam would silently differ
        raise c.error(5, f"section TYPE {kind} (unsymmetric, I12 != 0) is not supported on PBEAML: "
                         f"its shear flexibility together with I12 is not modelled; use PBARL on a CBAR "
                         f"(NASTRAN ignores K1/K2 there when I12 is not zero)")
    n = len(dims)
    f = 11 + n
    while f <= len(c.fields):
        if not any(c.text(i) for i in range(f, len(c.fields) + 1)):
            break
        if c.text(f) not in PBEAM_SO:
            raise c.error(f, "expected SO (YES, YESA or NO) of the next station")
        xxb = _real(c, f + 1)
        if not 0.0 < xxb <= 1.0:
            raise c.error(f + 1, "X/XB must be in (0, 1]")
        for k in range(n):
            value = _real(c, f + 2 + k, dims[k])
            if value != dims[k] and same_printed(c.text(10 + k), dims[k], c.text(f + 2 + k), value):
                r.note(c, f"ends that differ only in printed digits (DIM{k + 1} {c.text(10 + k)} and "
                          f"{c.text(f + 2 + k)}) taken as prismatic, with end A's values")
            elif value != dims[k]:
                raise c.error(f + 2 + k, f"tapered beam not supported: DIM{k + 1} at X/XB = "
                                         f"{xxb:g} is {value:g}, at end A {dims[k]:g}")
        _real(c, f + 2 + n, 0.0)                                   # NSM
        f += n + 3
    library_pbar(r, c, pid, mid, kind, dims)


PARSERS = {"CBEAM": _cbeam, "PBEAM": _pbeam, "PBEAML": _pbeaml}
BULK = {"CBEAM": lambda r, t, cards: bulk_bars(r, t, cards, beam=True)}
