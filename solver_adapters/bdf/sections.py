"""PBARL/PBEAML library sections: the section constants of each supported TYPE."""

from __future__ import annotations

import numpy as np

from solver_adapters.bdf.fields import _blank, _max_fields, _int, _real
from solver_adapters.deck import PBar

# PBARL section types: number of dimensions DIM1..DIMn (MSC QRG, PBARL)
PBARL_DIMS = {"ROD": 1, "TUBE": 2, "TUBE2": 2, "BAR": 2, "BOX": 4, "I": 6, "CHAN": 4, "T": 4, "L": 4}
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
UNSYMMETRIC = frozenset({"L"})


def pbarl_section(kind: str, d: tuple[float, ...]) -> tuple[float, ...]:
    """``(A, I1, I2, J, K1, K2, I12)`` of a PBARL section from its dimensions ``d`` (DIM1...), in
    NASTRAN's element axes: y is the section's height direction (plane 1, I1 about z), z its
    width direction (plane 2, I2 about y); I12 = int y z dA about the centroid (zero but for
    L). ``ValueError(field offset, message)`` for dimensions that give no section (a wall
    thicker than the section).

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
        a, t = max(b, h), min(b, h)
        j = a * t**3 * (1 / 3 - 0.21 * t / a * (1 - t**4 / (12 * a**4)))
        return b * h, b * h**3 / 12, h * b**3 / 12, j, 5 / 6, 5 / 6, 0.0
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
