"""NASTRAN bulk-data writer: pure field formatters, one writer per card, and :func:`write_deck`.

Everything written here is read back by :mod:`solver_adapters.bdf`: small field loses what 8
characters cannot hold (see :func:`print_float_8`), large field keeps about 15 significant digits,
free field keeps every bit (``repr`` digits).
"""

from __future__ import annotations

import math
from dataclasses import replace
from decimal import ROUND_DOWN, ROUND_HALF_EVEN, Context, Decimal
from typing import Iterable, Sequence

import numpy as np

from solver_adapters.deck import (Bush, CBar, Deck, Dmig, Gap, Grid, Mat1, PBar, PBush, Pelas, Prod, Rbe2, Rbe3, Rod,
                                  Spc1, SpcAdd, Spring, Unmodelled)

__all__ = ["print_int", "print_float_8", "print_float_16", "print_float_free", "print_field",
           "format_card", "write_grid", "write_cbar", "write_pbar", "write_mat1", "write_spc1",
           "write_mpc", "write_rbe2", "write_rbe3", "write_pelas", "write_celas1", "write_celas2", "write_spring",
           "write_spcadd", "write_prod", "write_rod", "write_coord", "write_cbush", "write_pbush", "write_cgap", "write_pgap",
           "write_unmodelled", "write_dmig", "cbar_in_cd", "write_deck"]

Field = int | float | str | None
_FORMATS = ("small", "large", "free")


# --------------------------------------------------------------------------------------------
# field formatters
# --------------------------------------------------------------------------------------------
def print_int(value: int) -> str:
    """An integer field: ``12``; ``None`` is a blank field."""
    return "" if value is None else str(int(value))


def _place(digits: str, q: int, negative: bool, width: int) -> str | None:
    """The shortest NASTRAN real for ``int(digits) * 10**q`` that fits ``width``, or None.

    Tries every exponent ``k`` of the implicit-exponent form ``<mantissa><+-k>`` (``k = 0``: plain
    ``123.45``); ties go to no exponent, then to a normalised mantissa (``1.2346+8``).
    """
    n = len(digits)
    e = q + n - 1                       # decimal exponent of the leading digit
    best: tuple[int, bool, int, str] | None = None
    for k in {0, *range(q - 1, q + n + 1)}:
        j = q - k                       # the mantissa is int(digits) * 10**j
        if j >= 0:
            mantissa = digits + "0" * j + "."
        elif -j < n:
            mantissa = digits[:j] + "." + digits[j:]
        else:
            mantissa = "." + "0" * (-j - n) + digits
        suffix = "" if k == 0 else f"{'+' if k > 0 else '-'}{abs(k)}"
        text = ("-" if negative else "") + mantissa + suffix
        key = (len(text), k != 0, abs(k - e), text)
        if len(text) <= width and (best is None or key < best):
            best = key
    return None if best is None else best[3]


def _print_float(value: float, width: int) -> str:
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"cannot write a non-finite real to a deck: {value!r}")
    if x == 0.0:
        return "0."
    negative = x < 0.0
    # 1) the shortest digits that round-trip (repr): exact, if some placement fits
    sign, digit_tuple, q = Decimal(repr(abs(x))).normalize().as_tuple()
    exact = _place("".join(map(str, digit_tuple)), q, negative, width)
    if exact is not None:
        return exact
    # 2) the exact binary value rounded to ever fewer significant digits: the first that fits
    #    is the closest representation of that width (n-digit decimals include the (n-1)-digit)
    full = Decimal(abs(x))
    # a mantissa needs its n digits and a decimal point: no use trying more than width - 1 - sign
    for n in range(min(len(digit_tuple) - 1, width - 1 - negative), 0, -1):
        rounded = Context(prec=n, rounding=ROUND_HALF_EVEN).plus(full).normalize()
        if not math.isfinite(float(rounded)):   # 1.797e308 -> 1.8e308 overflows: round down
            rounded = Context(prec=n, rounding=ROUND_DOWN).plus(full).normalize()
        _, d, q = rounded.as_tuple()
        text = _place("".join(map(str, d)), q, negative, width)
        if text is not None:
            return text
    raise ValueError(f"{value!r} does not fit a {width}-character field")


def print_float_8(value: float) -> str:
    """The closest NASTRAN real to ``value`` that fits 8 characters.

    Exact when the shortest round-trip digits fit (``0.25`` -> ``.25``, ``1e-5`` -> ``1.-5``);
    otherwise the value rounded to as many significant digits as any placement allows, using the
    implicit-exponent form where it saves characters (``1.23456789e12`` -> ``12346.+8``,
    ``-0.000123456`` -> ``-1.235-4``). Always has a decimal point, so it reads back as a real.
    """
    return _print_float(value, 8)


def print_float_16(value: float) -> str:
    """The closest NASTRAN real that fits 16 characters (large field): 15+ significant digits."""
    return _print_float(value, 16)


def print_float_free(value: float, max_width: int | None = None) -> str:
    """Free field: ``repr`` digits with a decimal point (``1.E-09``), which read back bit for bit.

    NASTRAN-type codes allow at most 16 characters per free-field entry (MYSTRAN rejects longer
    ones, error 1002): with ``max_width=16`` a longer ``repr`` becomes the 16-character
    large-field text (12-15 significant digits)."""
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"cannot write a non-finite real to a deck: {value!r}")
    mantissa, _, exponent = repr(x).upper().partition("E")
    if "." not in mantissa:
        mantissa += "."
    text = mantissa + ("E" + exponent if exponent else "")
    return text if max_width is None or len(text) <= max_width else print_float_16(x).strip()


def print_field(value: Field, fmt: str = "small") -> str:
    """One field's text: ``None`` blank, ``int``/``float``/``str`` by type, in format ``fmt``."""
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    if isinstance(value, (bool, int)) or (hasattr(value, "dtype") and value.dtype.kind in "iu"):
        return print_int(int(value))
    return {"small": print_float_8, "large": print_float_16, "free": print_float_free}[fmt](value)


# --------------------------------------------------------------------------------------------
# cards
# --------------------------------------------------------------------------------------------
def format_card(name: str, fields: Sequence[Field], fmt: str = "small") -> str:
    """One card as text lines (ending in a newline). ``fields[0]`` is NASTRAN field 2.

    ``small``: 8-column fields, 8 data fields a line, implicit continuations (blank field 1).
    ``large``: ``NAME*`` then 16-column fields, 4 a line, ``*`` continuations, an even number of
    lines. ``free``: comma separated, 8 data fields a line, continuations start with ``,``.
    Trailing blank fields are dropped.
    """
    if fmt not in _FORMATS:
        raise ValueError(f"fmt must be 'small', 'large' or 'free', got {fmt!r}")
    texts = [print_field(v, fmt) for v in fields]
    while texts and texts[-1] == "":
        texts.pop()
    per_line = 4 if fmt == "large" else 8
    chunks = [texts[i:i + per_line] for i in range(0, max(len(texts), 1), per_line)]
    if fmt == "free":
        return "".join((name if k == 0 else "") + "," + ",".join(c) + "\n"
                       for k, c in enumerate(chunks))
    width = 16 if fmt == "large" else 8
    for t in texts:
        if len(t) > width:
            raise ValueError(f"{name}: field {t!r} is longer than {width} characters")
    if fmt == "large" and len(chunks) % 2:
        chunks.append([])
    first = f"{name}*" if fmt == "large" else name
    cont = "*" if fmt == "large" else ""
    lines = [(first if k == 0 else cont).ljust(8) + "".join(t.rjust(width) for t in c)
             for k, c in enumerate(chunks)]
    return "".join(line.rstrip() + "\n" for line in lines)


def write_grid(g: Grid, fmt: str = "small") -> str:
    """GRID: ID, CP (blank: the position is in basic, as the reader holds it), X1, X2, X3, CD
    (the displacement system as given, blank for basic), PS, SEID (blank)."""
    if getattr(g, "scalar", False):
        return format_card("SPOINT", [g.id], fmt)
    return format_card("GRID", [g.id, None, *g.xyz, getattr(g, "cd", 0) or None, g.ps or None], fmt)


def cbar_in_cd(deck: Deck, b: CBar) -> CBar:
    """The CBAR as its card says it (OFFT blank, GGG): the orientation vector in GA's
    displacement system, the offsets in GA's and GB's; the parsed deck holds them in basic."""
    cds = {g: getattr(deck.grids[g], "cd", 0) for g in (b.ga, b.gb)}
    if not any(cds.values()):
        return b
    frame = dict(zip((b.ga, b.gb), deck.displacement_frames([b.ga, b.gb])))

    def to(g, v):
        return None if v is None else tuple(float(t) for t in frame[g] @ np.asarray(v, float))
    return replace(b, x=to(b.ga, b.x), wa=to(b.ga, b.wa), wb=to(b.gb, b.wb))


def write_cbar(b: CBar, fmt: str = "small", name: str = "CBAR") -> str:
    """CBAR: EID, PID, GA, GB, X1 X2 X3 (orientation vector) or G0 (then X2 X3 blank); then, when
    set, OFFT (blank: GGG), PA, PB, WA, WB (offsets in the basic system)."""
    orient: list[Field] = [b.g0, None, None] if b.g0 is not None else list(b.x)
    fields: list[Field] = [b.eid, b.pid, b.ga, b.gb, *orient]
    if b.pa or b.pb or b.wa is not None or b.wb is not None:
        fields += [None, b.pa or None, b.pb or None, *(b.wa or (None,) * 3), *(b.wb or (None,) * 3)]
    return format_card(name, fields, fmt)


def write_pbar(p: PBar, fmt: str = "small") -> str:
    """PBAR: PID, MID, A, I1, I2, J; K1, K2, I12 (fields 18-20) when set (K blank: no shear
    flexibility)."""
    fields: list[Field] = [p.pid, p.mid, p.a, p.i1, p.i2, p.j]
    if p.k1 is not None or p.k2 is not None or p.i12:
        fields += [None] * 10 + [p.k1, p.k2, p.i12 or None]      # NSM, field 9, C1..F2 blank
    return format_card("PBAR", fields, fmt)


def write_pbeam(p: PBar, fmt: str = "small") -> str:
    """A PBar with a neutral axis offset or a taper (which PBAR cannot hold) as the PBEAM it
    came from: PID MID A I1 I2 I12 J, end B's station (SO = NO, X/XB = 1.0) when tapered, the
    K line (blank K of the PBar: 0.0, no shear flexibility) and the M/N line with N1, N2 at both
    ends."""
    fields: list[Field] = [p.pid, p.mid, p.a, p.i1, p.i2, p.i12, p.j, None] + [None] * 8
    if p.taper is not None:
        a, i1, i2, j = p.taper
        fields += ["NO", 1.0, a, i1, i2, p.i12, j, None]
    fields += [p.k1 or 0.0, p.k2 or 0.0] + [None] * 6 + [None] * 4 + [p.n1, p.n2, p.n1, p.n2]
    return format_card("PBEAM", fields, fmt)


def write_mat1(m: Mat1, fmt: str = "small") -> str:
    """MAT1: MID, E, G, NU (all three written, so nothing is recomputed on reading)."""
    return format_card("MAT1", [m.mid, m.e, m.g, m.nu], fmt)


def write_spc1(s: Spc1, fmt: str = "small") -> str:
    """SPC1: SID, C (component digits), G1, G2, ... (every grid listed, no THRU)."""
    return format_card("SPC1", [s.sid, s.components, *s.grids], fmt)


def write_spcadd(a: SpcAdd, fmt: str = "small", name: str = "SPCADD") -> str:
    """SPCADD (or, ``name="MPCADD"``, MPCADD): SID, S1, S2, ..."""
    return format_card(name, [a.sid, *a.sets], fmt)


def write_mpc(m, fmt: str = "small") -> str:
    """MPC: SID, then two G C A triples a line (field 9 and a continuation's field 2 blank)."""
    fields: list[Field] = [m.sid]
    for k, (g, c, a) in enumerate(m.terms):
        if k and k % 2 == 0:
            fields += [None, None]
        fields += [g, c, float(a)]
    return format_card("MPC", fields, fmt)


def write_prod(p: Prod, fmt: str = "small") -> str:
    """PROD: PID, MID, A, J."""
    return format_card("PROD", [p.pid, p.mid, p.a, p.j], fmt)


def write_rod(r: Rod, fmt: str = "small") -> str:
    """CROD: EID, PID, G1, G2; or CONROD: EID, G1, G2, MID, A, J (as the rod was read)."""
    if r.pid is not None:
        return format_card("CROD", [r.eid, r.pid, r.ga, r.gb], fmt)
    return format_card("CONROD", [r.eid, r.ga, r.gb, r.mid, r.a, r.j], fmt)


def write_rbe2(e: Rbe2, fmt: str = "small") -> str:
    """RBE2: EID, GN (independent grid), CM (dependent components), GM1, GM2, ..."""
    return format_card("RBE2", [e.eid, e.gn, e.cm, *e.gm], fmt)


def write_pelas(p1: Pelas, p2: Pelas | None = None, fmt: str = "small") -> str:
    """PELAS: PID1, K1, GE1 (blank), S1 (blank), PID2, K2 (a second property is optional)."""
    fields: list[Field] = [p1.pid, p1.k, None, None]
    if p2 is not None:
        fields += [p2.pid, p2.k]
    return format_card("PELAS", fields, fmt)


def _end(g: int, c: int) -> list[Field]:
    return [g, c] if g else [None, None]


def write_celas1(s: Spring, fmt: str = "small") -> str:
    """CELAS1: EID, PID, G1, C1, G2, C2 (G2 C2 blank: to ground)."""
    return format_card("CELAS1", [s.eid, s.pid, *_end(s.g1, s.c1), *_end(s.g2, s.c2)], fmt)


def write_celas2(s: Spring, fmt: str = "small", k: float | None = None) -> str:
    """CELAS2: EID, K, G1, C1, G2, C2 (G2 C2 blank: to ground); GE, S blank.

    ``k`` overrides the spring's own stiffness (a CELAS1 written as a CELAS2 needs its PELAS's K).
    """
    stiffness = s.k if k is None else k
    if stiffness is None:
        raise ValueError(f"CELAS2 {s.eid}: no stiffness (a CELAS1 needs k= from its PELAS)")
    return format_card("CELAS2", [s.eid, stiffness, *_end(s.g1, s.c1), *_end(s.g2, s.c2)], fmt)


def write_spring(s: Spring, fmt: str = "small") -> str:
    """The spring as it was read: CELAS1 (``pid`` set), CELAS2, CELAS3 EID PID S1 S2 or CELAS4
    EID K S1 S2 (scalar points; S2 blank: grounded)."""
    if s.card in ("CELAS3", "CELAS4"):
        value = s.pid if s.card == "CELAS3" else float(s.k)
        return format_card(s.card, [s.eid, value, s.g1, s.g2 or None], fmt)
    return write_celas1(s, fmt) if s.card == "CELAS1" else write_celas2(s, fmt)


def write_coord(c, fmt: str = "small") -> str:
    """A resolved coordinate system (``deck.Coord``) as CORD2R/CORD2C/CORD2S in the basic system
    (RID blank): CID, RID, A (origin), B (a point on the z axis), C (a point in the x-z plane, on
    the x axis). Any CORD1x/CORD2x the reader resolved is written this way."""
    origin = [float(v) for v in c.origin]
    z = [o + float(v) for o, v in zip(origin, c.axes[2])]
    x = [o + float(v) for o, v in zip(origin, c.axes[0])]
    return format_card(f"CORD2{c.kind}", [c.cid, None, *origin, *z, *x], fmt)


def write_rbe3(e: Rbe3, fmt: str = "small") -> str:
    """RBE3: EID, blank, REFGRID, REFC, then each weight group WT C G1 G2 ..."""
    fields: list[Field] = [e.eid, None, e.refgrid, e.refc]
    for w, comps, grids in e.groups:
        fields += [float(w), comps, *grids]
    return format_card("RBE3", fields, fmt)


def write_cbush(b: Bush, fmt: str = "small") -> str:
    """CBUSH: EID, PID, GA, GB (blank: grounded), GO or X1 X2 X3 (as given, in GA's CD), CID,
    S (written only when not the default 0.5), OCID and S1-S3 (only when an offset is given)."""
    orient: list[Field] = ([b.g0, None, None] if b.g0 is not None
                           else list(b.x) if b.x is not None else [None, None, None])
    fields: list[Field] = [b.eid, b.pid, b.ga, b.gb or None, *orient, b.cid]
    offset = getattr(b, "offset", None)
    if b.s != 0.5 or offset is not None:
        fields.append(float(b.s) if b.s != 0.5 else None)
    if offset is not None:
        fields += [b.ocid, *(float(v) for v in offset)]
    return format_card("CBUSH", fields, fmt)


def write_pbush(p: PBush, fmt: str = "small") -> str:
    """PBUSH: PID, "K", K1..K6."""
    return format_card("PBUSH", [p.pid, "K", *(float(k) for k in p.k)], fmt)


def write_cgap(e: Gap, fmt: str = "small") -> str:
    """CGAP: EID, PID, GA, GB, GO or X1 X2 X3 (as given, in GA's CD), CID."""
    orient: list[Field] = ([e.g0, None, None] if e.g0 is not None
                           else list(e.x) if e.x is not None else [None, None, None])
    return format_card("CGAP", [e.eid, e.pid, e.ga, e.gb, *orient, e.cid], fmt)


def write_pgap(p, fmt: str = "small") -> str:
    """PGAP: PID, U0, F0, KA, KB, KT, MU1, MU2 (blanks kept: their defaults depend on KA)."""
    return format_card("PGAP", [p.pid, float(p.u0), float(p.f0), float(p.ka),
                                None if p.kb is None else float(p.kb),
                                None if p.kt is None else float(p.kt), float(p.mu1),
                                None if p.mu2 is None else float(p.mu2)], fmt)


def write_unmodelled(u: Unmodelled, fmt: str = "small") -> str:
    """A card the reader keeps without modelling it (a shell, a solid, their properties) with
    its fields as read: integers and words as they are, reals in the format's own precision
    (small field rounds to 8 characters, as for every card)."""
    return format_card(u.name, list(u.fields), fmt)


def _pairs(items: list[Pelas]) -> Iterable[tuple[Pelas, Pelas | None]]:
    for i in range(0, len(items), 2):
        yield items[i], items[i + 1] if i + 1 < len(items) else None


def write_dmig(m: Dmig, scalar: set[int], fmt: str = "small") -> str:
    """A DMIG matrix: its header (IFO as read, real double input) and one column entry per
    column (a scalar point's component as 0)."""
    out = [format_card("DMIG", [m.name, 0, m.ifo, 2], fmt)]
    columns: dict[tuple[int, int], list] = {}
    for row, col, a in m.terms:
        columns.setdefault(col, []).append((row, a))

    def comp(g: int, c: int) -> int:
        return 0 if g in scalar else c

    for (gj, cj), rows in columns.items():
        fields: list[Field] = [m.name, gj, comp(gj, cj), None]
        for (g, c), a in rows:
            fields += [g, comp(g, c), float(a), None]
        out.append(format_card("DMIG", fields, fmt))
    return "".join(out)


def write_genel(m: Dmig, scalar: set[int], fmt: str = "small") -> str:
    """A GENEL as the stiffness form over all its components (its UI and UD lists and S folded
    into one K, no UD): ``GENEL EID (blank) UI CI ...`` then ``K`` and the lower triangle by
    columns, each keyword in field 2 of a line of its own (a scalar point's component as 0)."""
    dofs = list(dict.fromkeys(row for row, _, _ in m.terms))
    value = {(row, col): a for row, col, a in m.terms}
    fields: list[Field] = [int(m.name[5:]), None]
    for g, c in dofs:
        fields += [g, 0 if g in scalar else c]
    fields += [None] * ((-len(fields)) % 8)          # "K" in field 2 of a line of its own
    lower = [float(value.get((dofs[i], dofs[j]), 0.0)) for j in range(len(dofs)) for i in range(j, len(dofs))]
    fields += ["K", *lower]
    return format_card("GENEL", fields, fmt)


def write_deck(deck: Deck, fmt: str = "small") -> str:
    """A complete bulk data section (``BEGIN BULK`` ... ``ENDDATA``) of everything the parsed
    deck holds, cards sorted by ID, so that reading it back gives the same model: grids (in
    basic, CD kept), coordinate systems (as CORD2R/C/S in basic), CBAR/CBEAM as CBAR with
    PBAR/PBARL/PBEAM/PBEAML as the PBAR they are, rods, MAT1, SPC1, SPCADD, RBE2, RBE3, CBUSH,
    PBUSH, PELAS, CELAS1/2, CGAP, PGAP, DMIG (and PARAM,CK2), GENEL, PARAM,AUTOSPC,NO and PARAM,EPZERO when they
    differ from NASTRAN's defaults (designed properties with their values at the initial design),
    and the cards the reader keeps without modelling them (``Deck.unmodelled``: shells,
    solids, for an external solver) field by field. Cards accepted with no effect on a static
    solve (masses, other PARAMs) are left out. Diagnose writes its edited decks with it."""
    if fmt not in _FORMATS:
        raise ValueError(f"fmt must be 'small', 'large' or 'free', got {fmt!r}")
    out = [f"$ bulk data written by blackbox ({fmt} field)\n", "BEGIN BULK\n"]
    if not getattr(deck, "autospc", True):
        out.append(format_card("PARAM", ["AUTOSPC", "NO"], fmt))
    if getattr(deck, "epzero", 1e-8) != 1e-8:
        out.append(format_card("PARAM", ["EPZERO", float(deck.epzero)], fmt))
    out += [write_grid(deck.grids[i], fmt) for i in sorted(deck.grids)]
    coords = getattr(deck, "coords", None) or {}
    out += [write_coord(coords[i], fmt) for i in sorted(coords)]
    beams = {pid for pid, p in deck.pbars.items()
             if getattr(p, "n1", 0.0) or getattr(p, "n2", 0.0) or getattr(p, "taper", None) is not None}
    for i in sorted(deck.cbars):
        b = deck.cbars[i]
        out.append(write_cbar(cbar_in_cd(deck, b), fmt, "CBEAM" if b.pid in beams else "CBAR"))
    out += [(write_pbeam if i in beams else write_pbar)(deck.pbars[i], fmt) for i in sorted(deck.pbars)]
    out += [write_rod(deck.rods[i], fmt) for i in sorted(deck.rods)]
    out += [write_prod(deck.prods[i], fmt) for i in sorted(deck.prods)]
    out += [write_mat1(deck.mat1s[i], fmt) for i in sorted(deck.mat1s)]
    out += [write_spc1(s, fmt) for s in deck.spc1s]
    out += [write_spcadd(deck.spcadds[i], fmt) for i in sorted(deck.spcadds)]
    out += [write_mpc(m, fmt) for m in getattr(deck, "mpcs", ())]
    mpcadds = getattr(deck, "mpcadds", {})
    out += [write_spcadd(mpcadds[i], fmt, "MPCADD") for i in sorted(mpcadds)]
    out += [write_rbe2(deck.rbe2s[i], fmt) for i in sorted(deck.rbe2s)]
    out += [write_rbe3(deck.rbe3s[i], fmt) for i in sorted(deck.rbe3s)]
    out += [write_cbush(deck.bushes[i], fmt) for i in sorted(deck.bushes)]
    out += [write_pbush(deck.pbushes[i], fmt) for i in sorted(deck.pbushes)]
    gaps, pgaps = getattr(deck, "gaps", {}), getattr(deck, "pgaps", {})
    out += [write_cgap(gaps[i], fmt) for i in sorted(gaps)]
    out += [write_pgap(pgaps[i], fmt) for i in sorted(pgaps)]
    out += [write_pelas(a, b, fmt) for a, b in _pairs([deck.pelas[i] for i in sorted(deck.pelas)])]
    out += [write_spring(deck.springs[i], fmt) for i in sorted(deck.springs)]
    dmigs = getattr(deck, "dmigs", {})
    if dmigs and getattr(deck, "ck2", 1.0) != 1.0:
        out.append(format_card("PARAM", ["CK2", float(deck.ck2)], fmt))
    out += [(write_genel if dmigs[k].card == "GENEL" else write_dmig)(dmigs[k], deck.scalar_points(), fmt)
            for k in sorted(dmigs)]
    out += [write_unmodelled(u, fmt) for u in getattr(deck, "unmodelled", ())]
    out.append("ENDDATA\n")
    return "".join(out)
