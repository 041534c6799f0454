"""PBARL/PBEAML library sections: the section constants of each supported TYPE."""

from __future__ import annotations

import numpy as np

from solver_adapters.bdf.fields import _blank, _max_fields, _int, _real
from solver_adapters.deck import PBar

# PBARL section types: number of dimensions DIM1..DIMn (MSC QRG, PBARL)
PBARL_DIMS = {"ROD": 1, "TUBE": 2, "TUBE2": 2, "BAR": 2, "BOX": 4, "I": 6, "CHAN": 4, "T": 4, "L": 4,
              "BOX1": 6, "CHAN1": 4, "CHAN2": 4, "CROSS": 4, "H": 4, "HAT": 4, "HEXA": 3, "I1": 4,
              "T1": 4, "T2": 4, "Z": 4}
PBEAM_SO = ("YES", "YESA", "NO")
"""A PBEAM or PBEAML station's stress-output option, the first field of its station line."""


def pbeam_stations(c) -> tuple[list[int], int]:
    """The stations of PBEAM card ``c`` after end A (MSC QRG PBEAM: a line SO X/XB A I1 I2 I12 J
    NSM each, and a line of stress points after it when SO = YES): the field number of each
    station's SO, in card order, and the field number where the line after them (K1 K2 ...)
    starts."""
    f0, out = 18, []
    while f0 <= len(c.fields) and c.text(f0) in PBEAM_SO:
        out.append(f0)
        f0 += 16 if c.text(f0) == "YES" else 8
    return out, f0


# types whose section is not symmetric about y or z (I12 != 0): PBARL only (see _pbeaml)
UNSYMMETRIC = frozenset({"L", "Z"})


def pbarl_section(kind: str, d: tuple[float, ...]) -> tuple[float, ...]:
    """``(A, I1, I2, J, K1, K2, I12)`` of a PBARL section from its dimensions ``d`` (DIM1...), in
    NASTRAN's element axes: y is the section's height direction (plane 1, I1 about z), z its
    width direction (plane 2, I2 about y); I12 = int y z dA about the centroid (zero but for
    L and Z). ``ValueError(field offset, message)`` for dimensions that give no section (a wall
    thicker than the section), or a BOX1 whose I12 is not established (below).

    A, I1, I2 are exact for the idealized shape (rectangles, circles), about the centroid.
    TUBE2 is TUBE given by its outer radius DIM1 and wall thickness DIM2 (inner radius DIM1 -
    DIM2), as MYSTRAN 18 takes it (BD_PBARL.f90, SECTION_PROPS_TUBE2).
    J: ROD, TUBE exact (polar moment); BAR Roark's series for a solid rectangle
    (a b^3 (1/3 - 0.21 b/a (1 - b^4 / (12 a^4))), a >= b, within 0.5 % of St Venant's value);
    BOX Bredt's thin-walled closed section on the wall mid-line, 4 A_m^2 / sum(s_i / t_i);
    I, CHAN, T the open thin-walled sum of (1/3) b t^3 over the walls. K1, K2 (shear area
    factors, plane 1 and 2): the values MYSTRAN 18 computes for PBARL (BD_PBARL.f90): 5/6 for
    BAR, 6/7 for ROD, Cowper's tube factor with NU = 0, the web (or wall) area fraction for
    BOX, I, CHAN and T (5/6 of the flange fraction across the flanges; Cowper's T-section factor
    in the web plane of T). NASTRAN's own K1/K2 for PBARL are not documented in the QRG.

    L (an angle; NX Nastran Element Library Reference, PBARL TYPE L): DIM1 the width of the
    horizontal leg (along z, its thickness DIM3 along y), DIM2 the height of the vertical leg
    (along y, its thickness DIM4 along z); the element axes start at the shear center, the
    intersection of the legs' mid-lines, and the legs run along +y and +z from the corner (the
    Element Library's figure: vertical leg on the left, horizontal leg at the bottom, y up and z
    to the right as in its T section; the sign of I12 follows from this choice, which no run of
    NASTRAN could confirm here: MYSTRAN has no L). As for every PBARL the bar's axis is the grid line (PBARL does
    not offset the neutral axis from the shear center). A, I1, I2 and I12 are exact for the
    two rectangles (horizontal leg DIM1 x DIM3, vertical leg DIM4 x (DIM2 - DIM3) above it),
    about the centroid; I12 = int y z dA is negative (the legs lie in the quadrants +z/-y and
    -z/+y of the centroid). J is the open thin-walled sum over the legs' mid-line lengths,
    (b DIM3^3 + h DIM4^3) / 3 with b = DIM1 - DIM4/2, h = DIM2 - DIM3/2 (the Element Library's
    formula). K1, K2: none (Euler-Bernoulli): NASTRAN ignores a PBAR's K1/K2 when I12 is not
    zero (QRG PBAR), and an angle's I12 never is.

    The other types of MSC's standard library (MSC QRG PBARL, "Definition of Cross-Section
    Geometry and Stress Recovery Points"; y up, z to the right). That figure is an image that
    could not be viewed here: each type's dimensions below are the reading on which MSC's area
    equations (as pyNastran quotes them), pyNastran's drawings of the figure (bdf/cards/
    properties/bars.py, bdf/cards/elements/beam_connectivity.py) and MYSTRAN 18 (BD_PBARL.f90,
    SECTION_PROPS_*) agree, but for CHAN2, where MYSTRAN differs and this follows the others. A,
    I1, I2 (and Z's I12) are exact for the idealized shape, about the centroid. K1, K2 are the
    values MYSTRAN 18 computes (in the plane they act in where this turns its section). J as
    said per type; MYSTRAN 18's own J differs for CHAN1, CHAN2 and HAT (its factors 1.12, 1.12,
    1.15 and other wall lengths), I1, T2 and Z (other web lengths: 1.5 to 2.5 %) and HEXA.

    BOX1: width DIM1 (z), height DIM2 (y), top and bottom walls DIM3, DIM4 thick, right and left
    walls DIM5, DIM6 thick (over the full height). K1 = (DIM2 - DIM3 - DIM4) / DIM2, K2 = (DIM1 -
    DIM5 - DIM6) / DIM1; J Bredt's on the mid-line, as BOX (a BOX1 of equal opposite walls is the
    BOX of DIM1 DIM2 DIM3 DIM5). With DIM3 != DIM4 and DIM5 != DIM6 the box has a product of
    inertia whose sign depends on which side each wall is drawn, which the sources do not settle
    (and MYSTRAN takes as 0): an error. MYSTRAN 18's own I1, I2 are not the box's.
    CHAN1: a channel, web DIM2 thick, flanges reaching DIM1 beyond it, web's clear height DIM3,
    height DIM4: the CHAN of width DIM1 + DIM2, height DIM4, web DIM2, flanges (DIM4 - DIM3) / 2,
    every constant CHAN's. MYSTRAN 18's own I2 differs.
    CHAN2: a U, legs DIM1 thick and DIM3 high (y, the base included) on a base DIM2 thick and DIM4
    wide (z): the CHAN of width DIM3, height DIM4, web DIM2, flanges DIM1 turned by 90 degrees (I1
    and I2 exchanged, and K1 and K2). MYSTRAN 18 takes DIM4 along y (its I1 is near this one's I2
    and the reverse); the mystran adapter writes the reader's section (a PBAR), not MYSTRAN's.
    CROSS: a vertical bar DIM2 wide (z) and DIM3 high (y) with an arm DIM1/2 long and DIM4 thick on
    each side at mid-height: J = (DIM3 DIM2^3 + DIM1 DIM4^3) / 3 (bar and arms as rectangles, as
    MYSTRAN), K1 = 5/6 DIM2 DIM3 / A, K2 = 5/6 (DIM1 + DIM2) DIM4 / A.
    H: two vertical flanges DIM2/2 thick and DIM3 high, DIM1 apart (z), joined at mid-height by a
    web DIM4 thick: J = (2 DIM3 (DIM2/2)^3 + DIM1 DIM4^3) / 3 (as MYSTRAN), K1 = 5/6 DIM2 DIM3 / A,
    K2 = DIM1 DIM4 / A.
    HAT: height DIM1, every wall DIM2 thick, top DIM3 wide (over the webs' outer faces), a brim
    DIM4 beyond each web at the bottom: J = A DIM2^2 / 3 (the walls' thin-walled sum, MYSTRAN's
    without its factor 1.15), K1 = (DIM1 - 2 DIM2) / DIM1, K2 = (2 DIM3 - 2 DIM2) / (DIM3 + DIM4)
    (MYSTRAN's, > 1 when the brims are narrower than the inside width DIM3 - 2 DIM2). MYSTRAN 18's
    own I1, I2 differ.
    HEXA: width DIM2 (z), height DIM3 (y), each end a triangle DIM1 long to a point at mid-height:
    J Saint-Venant's approximation A^4 / (4 pi^2 (I1 + I2)) for a solid section (a regular
    hexagon: 3 % above a finite-element solution of the stress function; within 8 % on the
    shapes tried; MYSTRAN 18's rectangle of the mean width is 10 % low there, up to 23 %), K1 =
    K2 = 5/6. MYSTRAN 18's own I2 leaves out the tips' distance from the axis.
    I1: an I, web DIM2 thick, flanges reaching DIM1/2 beyond it on each side, web's clear height
    DIM3, height DIM4: the I of height DIM4, flanges DIM1 + DIM2 wide and (DIM4 - DIM3) / 2 thick,
    web DIM2, every constant I's.
    T1: a flange DIM1 high (y) and DIM3 thick with a web DIM2 long (z, beyond the flange) and DIM4
    thick at its mid-height: the T of width DIM1, height DIM2 + DIM3, flange DIM3, web DIM4 turned
    by 90 degrees.
    T2: T upside down (the flange DIM1 x DIM3 at the bottom): every constant T's.
    Z: a web DIM2 thick with a clear height DIM3 between flanges t_f = (DIM4 - DIM3) / 2 thick that
    reach DIM1 beyond it, the top one towards -z, the bottom one towards +z (pyNastran's drawing;
    MYSTRAN 18's I12 has the same sign): I12 = int y z dA = -t_f DIM1 (DIM1 + DIM2) (DIM3 + t_f)
    / 2, negative; A, I1, J those of the I1 of the same dimensions; K1, K2 none, as for L.
    """
    pi = np.pi
    if kind == "ROD":
        (r,) = d
        i = pi * r**4 / 4
        return pi * r * r, i, i, 2 * i, 6 / 7, 6 / 7, 0.0
    if kind in ("TUBE", "TUBE2"):
        r1, r2 = d
        if kind == "TUBE2":                       # DIM2 the wall thickness (MSC QRG PBARL)
            if not 0.0 < r2 <= r1:
                raise ValueError(1, "wall thickness DIM2 must be positive and at most the outer radius DIM1")
            r2 = r1 - r2
        elif not r2 < r1:
            raise ValueError(1, "inner radius DIM2 must be smaller than the outer radius DIM1")
        i = pi * (r1**4 - r2**4) / 4
        m2 = (r2 / r1) ** 2
        k = 6 * (1 + m2) ** 2 / (7 * (1 + m2) ** 2 + 20 * m2)
        return pi * (r1 * r1 - r2 * r2), i, i, 2 * i, k, k, 0.0
    if kind == "BAR":
        b, h = d                                  # DIM1 width (z), DIM2 height (y)
        return b * h, b * h**3 / 12, h * b**3 / 12, _rectangle_j(b, h), 5 / 6, 5 / 6, 0.0
    if kind == "BOX":
        b, h, th, tv = d                          # width, height, horizontal / vertical walls
        bi, hi = b - 2 * tv, h - 2 * th
        if bi <= 0:
            raise ValueError(3, "vertical walls DIM4 fill the width DIM1 (2 DIM4 >= DIM1)")
        if hi <= 0:
            raise ValueError(2, "horizontal walls DIM3 fill the height DIM2 (2 DIM3 >= DIM2)")
        am = (b - tv) * (h - th)
        j = 4 * am * am / (2 * (b - tv) / th + 2 * (h - th) / tv)
        return (b * h - bi * hi, (b * h**3 - bi * hi**3) / 12, (h * b**3 - hi * bi**3) / 12, j,
                hi / h, bi / b, 0.0)
    if kind == "I":
        h, wb, wt, tw, tb, tt = d                 # depth, bottom/top flange widths, thicknesses
        hw = h - tb - tt
        if hw <= 0:
            raise ValueError(4, "flange thicknesses DIM5 + DIM6 fill the depth DIM1")
        if tw > min(wb, wt):
            raise ValueError(3, "web thickness DIM4 exceeds a flange width")
        parts = [(wb, tb, tb / 2), (tw, hw, tb + hw / 2), (wt, tt, h - tt / 2)]  # (z, y size, y_c)
        a = sum(w * t for w, t, _ in parts)
        yc = sum(w * t * y for w, t, y in parts) / a
        i1 = sum(w * t**3 / 12 + w * t * (y - yc) ** 2 for w, t, y in parts)
        i2 = sum(t * w**3 / 12 for w, t, _ in parts)
        j = (wb * tb**3 + wt * tt**3 + (h - (tb + tt) / 2) * tw**3) / 3
        return a, i1, i2, j, hw * tw / a, 5 / 6 * (wb * tb + wt * tt) / a, 0.0
    if kind == "CHAN":
        b, h, tw, tf = d                          # width (z), height (y), web, flange thickness
        if h - 2 * tf <= 0:
            raise ValueError(3, "flange thickness DIM4 fills the height DIM2 (2 DIM4 >= DIM2)")
        if tw >= b:
            raise ValueError(2, "web thickness DIM3 fills the width DIM1")
        hw, bf = h - 2 * tf, b - tw
        a = hw * tw + 2 * b * tf
        i1 = (b * h**3 - bf * hw**3) / 12
        parts = [(h, tw, tw / 2), (2 * tf, bf, tw + bf / 2)]    # (y size, z size, z_c)
        zc = sum(hh * w * z for hh, w, z in parts) / a
        i2 = sum(hh * w**3 / 12 + hh * w * (z - zc) ** 2 for hh, w, z in parts)
        j = (2 * b * tf**3 + hw * tw**3) / 3
        return a, i1, i2, j, hw / h, bf / b, 0.0
    if kind == "T":
        b, h, tf, tw = d                          # flange width (z), height (y), thicknesses
        hw = h - tf
        if hw <= 0:
            raise ValueError(2, "flange thickness DIM3 fills the height DIM2")
        if tw > b:
            raise ValueError(3, "web thickness DIM4 exceeds the flange width DIM1")
        a = b * tf + hw * tw
        yc = (b * tf * (hw + tf / 2) + hw * tw * hw / 2) / a
        i1 = b * tf**3 / 12 + b * tf * (hw + tf / 2 - yc) ** 2 + tw * hw**3 / 12 + hw * tw * (yc - hw / 2) ** 2
        i2 = (tf * b**3 + hw * tw**3) / 12
        j = (b * tf**3 + hw * tw**3) / 3
        m = b * tf / ((hw + tf / 2) * tw)
        n = b / (hw + tf / 2)
        k1 = 10 * (1 + 4 * m) ** 2 / (12 + 96 * m + 276 * m * m + 192 * m**3 + 30 * n * n * m * (1 + m))
        return a, i1, i2, j, k1, 5 / 6 * b * tf / a, 0.0
    if kind == "L":
        b, h, t1, t2 = d                          # width (z), height (y), their legs' thicknesses
        if not t1 < h:
            raise ValueError(2, "horizontal leg thickness DIM3 fills the height DIM2 (DIM3 >= DIM2)")
        if not t2 < b:
            raise ValueError(3, "vertical leg thickness DIM4 fills the width DIM1 (DIM4 >= DIM1)")
        # (z0, z1, y0, y1) of the two rectangles, from the corner of the legs' mid-lines
        parts = [(-t2 / 2, b - t2 / 2, -t1 / 2, t1 / 2), (-t2 / 2, t2 / 2, t1 / 2, h - t1 / 2)]
        areas = [(z1 - z0) * (y1 - y0) for z0, z1, y0, y1 in parts]
        a = sum(areas)
        zc = sum(ar * (z0 + z1) / 2 for ar, (z0, z1, _, _) in zip(areas, parts)) / a
        yc = sum(ar * (y0 + y1) / 2 for ar, (_, _, y0, y1) in zip(areas, parts)) / a
        i1 = i2 = i12 = 0.0
        for ar, (z0, z1, y0, y1) in zip(areas, parts):
            dz, dy = (z0 + z1) / 2 - zc, (y0 + y1) / 2 - yc
            i1 += ar * ((y1 - y0) ** 2 / 12 + dy * dy)
            i2 += ar * ((z1 - z0) ** 2 / 12 + dz * dz)
            i12 += ar * dz * dy                   # a rectangle's own product about its centre is 0
        j = ((b - t2 / 2) * t1**3 + (h - t1 / 2) * t2**3) / 3
        return a, i1, i2, j, None, None, i12
    return _more_sections(kind, d)


def _rectangle_j(b: float, h: float) -> float:
    """Roark's series for the torsion constant of a solid b x h rectangle (a >= t its sides):
    a t^3 (1/3 - 0.21 t/a (1 - t^4 / (12 a^4))), within 0.5 % of St Venant's value."""
    a, t = max(b, h), min(b, h)
    return a * t**3 * (1 / 3 - 0.21 * t / a * (1 - t**4 / (12 * a**4)))


def _rectangles(parts) -> tuple[float, float, float]:
    """A, I1 = int (y - yc)^2 dA, I2 = int (z - zc)^2 dA of non-overlapping rectangles
    ``(z0, z1, y0, y1)`` symmetric about y = 0 or z = 0 (their I12 is 0), by the parallel-axis
    theorem about the centroid."""
    areas = [(z1 - z0) * (y1 - y0) for z0, z1, y0, y1 in parts]
    a = sum(areas)
    zc = sum(ar * (z0 + z1) / 2 for ar, (z0, z1, _, _) in zip(areas, parts)) / a
    yc = sum(ar * (y0 + y1) / 2 for ar, (_, _, y0, y1) in zip(areas, parts)) / a
    i1 = sum(ar * ((y1 - y0) ** 2 / 12 + ((y0 + y1) / 2 - yc) ** 2) for ar, (_, _, y0, y1) in zip(areas, parts))
    i2 = sum(ar * ((z1 - z0) ** 2 / 12 + ((z0 + z1) / 2 - zc) ** 2) for ar, (z0, z1, _, _) in zip(areas, parts))
    return a, i1, i2


def _turned(section: tuple) -> tuple:
    """A symmetric section turned by 90 degrees: I1 and I2 exchanged, and K1 and K2."""
    a, i1, i2, j, k1, k2, i12 = section
    return a, i2, i1, j, k2, k1, i12


def _more_sections(kind: str, d: tuple[float, ...]) -> tuple[float, ...]:
    """:func:`pbarl_section` of BOX1, CHAN1, CHAN2, CROSS, H, HAT, HEXA, I1, T1, T2 and Z."""
    if kind == "BOX1":
        w, h, tt, tb, tr, tl = d                  # width (z), height (y), top, bottom, right, left walls
        wi, hi = w - tl - tr, h - tt - tb
        if wi <= 0:
            raise ValueError(4, "side walls DIM5 + DIM6 fill the width DIM1")
        if hi <= 0:
            raise ValueError(2, "top and bottom walls DIM3 + DIM4 fill the height DIM2")
        if tt != tb and tl != tr:
            raise ValueError(4, "unequal top and bottom walls (DIM3, DIM4) together with unequal side "
                                "walls (DIM5, DIM6) give a product of inertia I12 whose sign depends on "
                                "which side of the figure each wall is on, not established here (and "
                                "MYSTRAN 18 takes it as 0): not supported; make DIM3 = DIM4 or DIM5 = DIM6")
        ao, ai = w * h, wi * hi
        a = ao - ai
        # the outer rectangle less the hole, whose centre is ((tl - tr)/2, (tb - tt)/2) from the
        # outer one's: the parallel-axis terms of the two sum to -ao ai d^2 / a
        i1 = (w * h**3 - wi * hi**3) / 12 - ao * ai * ((tb - tt) / 2) ** 2 / a
        i2 = (h * w**3 - hi * wi**3) / 12 - ao * ai * ((tl - tr) / 2) ** 2 / a
        am = (w - (tl + tr) / 2) * (h - (tt + tb) / 2)
        j = 4 * am * am / ((h - (tt + tb) / 2) * (1 / tl + 1 / tr) + (w - (tl + tr) / 2) * (1 / tt + 1 / tb))
        return a, i1, i2, j, hi / h, wi / w, 0.0
    if kind == "CHAN1":
        bf, tw, hw, h = d                         # flange beyond the web, web, web's clear height, height
        if not hw < h:
            raise ValueError(2, "web height DIM3 fills the height DIM4 (DIM3 >= DIM4)")
        return pbarl_section("CHAN", (bf + tw, h, tw, (h - hw) / 2))
    if kind == "CHAN2":
        tf, tw, h, w = d                          # legs' and base's thicknesses, height (y), width (z)
        if not 2 * tf < w:
            raise ValueError(0, "legs 2 DIM1 fill the width DIM4 (2 DIM1 >= DIM4)")
        if not tw < h:
            raise ValueError(1, "base thickness DIM2 fills the height DIM3 (DIM2 >= DIM3)")
        return _turned(pbarl_section("CHAN", (h, w, tw, tf)))
    if kind == "CROSS":
        b, tv, h, th = d                          # arms (both), vertical bar's width, height, arms' thickness
        if th > h:
            raise ValueError(3, "arms' thickness DIM4 exceeds the height DIM3")
        a, i1, i2 = _rectangles([(-tv / 2, tv / 2, -h / 2, h / 2), (-(b + tv) / 2, -tv / 2, -th / 2, th / 2),
                                 (tv / 2, (b + tv) / 2, -th / 2, th / 2)])
        return a, i1, i2, (h * tv**3 + b * th**3) / 3, 5 / 6 * h * tv / a, 5 / 6 * (b + tv) * th / a, 0.0
    if kind == "H":
        b, tf, h, tw = d                          # web's clear width, flanges (both), height, web
        if tw > h:
            raise ValueError(3, "web thickness DIM4 exceeds the height DIM3")
        a, i1, i2 = _rectangles([(-(b + tf) / 2, -b / 2, -h / 2, h / 2), (b / 2, (b + tf) / 2, -h / 2, h / 2),
                                 (-b / 2, b / 2, -tw / 2, tw / 2)])
        return a, i1, i2, (2 * h * (tf / 2) ** 3 + b * tw**3) / 3, 5 / 6 * tf * h / a, b * tw / a, 0.0
    if kind == "HAT":
        h, t, w, bf = d                           # height, wall, top width (z), brims
        if not t < h:
            raise ValueError(1, "wall thickness DIM2 fills the height DIM1 (DIM2 >= DIM1)")
        if 2 * t > w:
            raise ValueError(1, "walls 2 DIM2 exceed the top width DIM3")
        z1 = w / 2
        a, i1, i2 = _rectangles([(-z1, z1, h - t, h), (-z1, -z1 + t, 0.0, h - t), (z1 - t, z1, 0.0, h - t),
                                 (-z1 - bf, -z1, 0.0, t), (z1, z1 + bf, 0.0, t)])
        return a, i1, i2, a * t * t / 3, (h - 2 * t) / h, (2 * w - 2 * t) / (w + bf), 0.0
    if kind == "HEXA":
        c, w, h = d                               # tip (z) of each end, width (z), height (y)
        if not 2 * c < w:
            raise ValueError(0, "tips 2 DIM1 fill the width DIM2 (2 DIM1 >= DIM2)")
        wr = w - 2 * c                            # the rectangle between the two triangular tips
        a = (wr + c) * h
        i1 = wr * h**3 / 12 + c * h**3 / 24
        i2 = h * wr**3 / 12 + h * c * (wr * wr / 4 + wr * c / 3 + c * c / 6)
        return a, i1, i2, a**4 / (4 * np.pi**2 * (i1 + i2)), 5 / 6, 5 / 6, 0.0
    if kind == "I1":
        bf, tw, hw, h = d                         # flanges beyond the web (both), web, web's clear height, height
        if not hw < h:
            raise ValueError(2, "web height DIM3 fills the height DIM4 (DIM3 >= DIM4)")
        tf = (h - hw) / 2
        return pbarl_section("I", (h, bf + tw, bf + tw, tw, tf, tf))
    if kind == "T1":
        h, bw, tf, tw = d                         # flange's height (y), web's length (z), their thicknesses
        if tw > h:
            raise ValueError(3, "web thickness DIM4 exceeds the flange's height DIM1")
        return _turned(pbarl_section("T", (h, bw + tf, tf, tw)))
    if kind == "T2":
        return pbarl_section("T", d)              # T upside down: flange DIM1 x DIM3 at the bottom
    if kind == "Z":
        bf, tw, hw, h = d                         # flange beyond the web, web, web's clear height, height
        if not hw < h:
            raise ValueError(2, "web height DIM3 fills the height DIM4 (DIM3 >= DIM4)")
        tf = (h - hw) / 2
        a, i1, _, j, _, _, _ = pbarl_section("I", (h, bf + tw, bf + tw, tw, tf, tf))
        # the I1 of these dimensions with its flanges moved by bf / 2, the top one to -z, the bottom
        # one to +z: I2 and I12 gain the flanges' parallel-axis terms
        i2 = hw * tw**3 / 12 + 2 * (tf * (bf + tw) ** 3 / 12 + tf * (bf + tw) * (bf / 2) ** 2)
        i12 = -tf * (bf + tw) * bf * (hw + tf) / 2
        return a, i1, i2, j, None, None, i12
    raise KeyError(kind)


def library_section(c, *, max_fields: bool) -> tuple[int, int, str, tuple[float, ...]]:
    """The common head of PBARL and PBEAML: PID MID GROUP TYPE, fields 6-9 blank, then the
    section's DIM1..DIMn (> 0) and NSM; ``max_fields``: nothing may follow NSM (PBARL)."""
    pid, mid = _int(c, 2), _int(c, 3)
    group = c.text(4)
    if group not in ("", "MSCBML0"):
        raise c.error(4, f"GROUP {group} not supported: only the standard library MSCBML0 (blank)")
    kind = c.text(5)
    if kind not in PBARL_DIMS:
        raise c.error(5, f"section TYPE {kind or '(blank)'} not supported; supported: "
                         f"{', '.join(PBARL_DIMS)}")
    for i in (6, 7, 8, 9):
        _blank(c, i, f"field {i}")
    n = PBARL_DIMS[kind]
    if max_fields:
        _max_fields(c, 10 + n)
    dims = tuple(_real(c, 10 + k) for k in range(n))
    for k, v in enumerate(dims):
        if v <= 0.0:
            raise c.error(10 + k, f"dimension DIM{k + 1} must be > 0")
    _real(c, 10 + n, 0.0)                   # NSM (of end A for PBEAML)
    return pid, mid, kind, dims


def library_pbar(r, c, pid: int, mid: int, kind: str, dims: tuple[float, ...]) -> None:
    """The equivalent PBAR of a library section (:func:`pbarl_section`), under the card's name."""
    try:
        a, i1, i2, j, k1, k2, i12 = pbarl_section(kind, dims)
    except ValueError as exc:
        raise c.error(10 + exc.args[0], f"{kind} section: {exc.args[1]}") from None
    r.claim("property", pid, c, 2)
    r.deck.pbars[pid] = PBar(pid, mid, a, i1, i2, j, c.src, k1, k2, i12, card=c.name)
