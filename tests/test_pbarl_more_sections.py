"""PBARL/PBEAML library sections BOX1, CHAN1, CHAN2, CROSS, H, HAT, HEXA, I1, T1, T2 and Z.

References: each section drawn as a polygon from the MSC QRG PBARL figure (the reading of its
dimensions documented in ``pbarl_section``), its area and second moments integrated by Green's
theorem (the shoelace formulas); the thin-walled torsion formulas cited per type, written from
the figure's walls; the shear factors transcribed from MYSTRAN 18's BD_PBARL.f90; MYSTRAN 18
solving the same cantilever (through the mystran adapter, and reading the PBARL itself).

Tolerances: section constants against the polygon 1e-12 relative (both exact for the idealized
shape: round-off only), against the formulas 1e-12 (the same arithmetic written twice); MYSTRAN
prints 7 significant digits, so displacements agree to RTOL = 1e-6 of each load case's largest
(test_deck_tail's RTOL).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from solver_adapters.bdf import pbarl_section, read_deck, read_deck_text
from solver_adapters.protocol import DeckFormatError, LoadMatrix
from solver_adapters.reference import ReferenceAdapter

from conftest import needs_mystran

RTOL = 1e-6
EXACT = 1e-12

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")   # MYSTRAN run dirs below tmp_path

SECTIONS = {
    "BOX1": (0.10, 0.12, 0.010, 0.010, 0.008, 0.012),   # width, height, top, bottom, right, left
    "BOX1 top/bottom": (0.10, 0.12, 0.009, 0.014, 0.010, 0.010),
    "CHAN1": (0.03, 0.004, 0.07, 0.08),                 # flange beyond web, web, web's clear height, height
    "CHAN2": (0.005, 0.004, 0.04, 0.08),                # legs, base, height, width
    "CROSS": (0.06, 0.01, 0.08, 0.008),                 # arms (both), bar's width, height, arms' thickness
    "H": (0.05, 0.01, 0.08, 0.006),                     # web's clear width, flanges (both), height, web
    "HAT": (0.05, 0.004, 0.06, 0.02),                   # height, wall, top width, brim
    "HEXA": (0.02, 0.08, 0.05),                         # tip, width, height
    "I1": (0.05, 0.005, 0.09, 0.10),                    # flanges beyond web (both), web, web's clear height, height
    "T1": (0.08, 0.05, 0.006, 0.005),                   # flange's height, web's length, flange, web
    "T2": (0.06, 0.08, 0.006, 0.005),                   # flange width, height, flange, web
    "Z": (0.03, 0.004, 0.07, 0.08),                     # flange beyond web, web, web's clear height, height
}
"""Dimensions of each new type, all different, so that a dimension read in another's place shows.
The second BOX1 has unequal top and bottom walls (the first unequal side walls)."""


def kind_of(name: str) -> str:
    return name.split()[0]


# --------------------------------------------------------------------------------------------
# the sections drawn from the figure, integrated by Green's theorem
# --------------------------------------------------------------------------------------------
def outline(name: str) -> list[list[tuple[float, float]]]:
    """The section as closed polygons of (z, y) vertices: material counter-clockwise, a hole
    clockwise (z to the right, y up, as in the figure)."""
    d = SECTIONS[name]
    kind = kind_of(name)
    if kind == "BOX1":
        w, h, tt, tb, tr, tl = d
        return [[(0, 0), (w, 0), (w, h), (0, h)], [(tl, tb), (tl, h - tt), (w - tr, h - tt), (w - tr, tb)]]
    if kind == "CHAN1":
        bf, tw, hw, h = d
        tf, b = (h - hw) / 2, bf + tw
        return [[(0, 0), (b, 0), (b, tf), (tw, tf), (tw, h - tf), (b, h - tf), (b, h), (0, h)]]
    if kind == "CHAN2":
        t1, t2, h, w = d
        return [[(0, 0), (w, 0), (w, h), (w - t1, h), (w - t1, t2), (t1, t2), (t1, h), (0, h)]]
    if kind == "CROSS":
        b, tv, h, th = d
        a = (b + tv) / 2
        return [[(-tv / 2, -h / 2), (tv / 2, -h / 2), (tv / 2, -th / 2), (a, -th / 2), (a, th / 2),
                 (tv / 2, th / 2), (tv / 2, h / 2), (-tv / 2, h / 2), (-tv / 2, th / 2), (-a, th / 2),
                 (-a, -th / 2), (-tv / 2, -th / 2)]]
    if kind == "H":
        b, tf, h, tw = d
        c = b / 2 + tf / 2
        return [[(-c, -h / 2), (-b / 2, -h / 2), (-b / 2, -tw / 2), (b / 2, -tw / 2), (b / 2, -h / 2),
                 (c, -h / 2), (c, h / 2), (b / 2, h / 2), (b / 2, tw / 2), (-b / 2, tw / 2),
                 (-b / 2, h / 2), (-c, h / 2)]]
    if kind == "HAT":
        h, t, w, bf = d
        z = w / 2
        return [[(-z - bf, 0), (-z + t, 0), (-z + t, h - t), (z - t, h - t), (z - t, 0), (z + bf, 0),
                 (z + bf, t), (z, t), (z, h), (-z, h), (-z, t), (-z - bf, t)]]
    if kind == "HEXA":
        c, w, h = d
        return [[(-w / 2, 0), (-w / 2 + c, -h / 2), (w / 2 - c, -h / 2), (w / 2, 0), (w / 2 - c, h / 2),
                 (-w / 2 + c, h / 2)]]
    if kind == "I1":
        bf, tw, hw, h = d
        tf, a = (h - hw) / 2, (bf + tw) / 2
        return [[(-a, 0), (a, 0), (a, tf), (tw / 2, tf), (tw / 2, h - tf), (a, h - tf), (a, h), (-a, h),
                 (-a, h - tf), (-tw / 2, h - tf), (-tw / 2, tf), (-a, tf)]]
    if kind == "T1":
        h, bw, tf, tw = d                  # the flange upright at z in [0, tf], the web to its left
        return [[(0, -h / 2), (tf, -h / 2), (tf, h / 2), (0, h / 2), (0, tw / 2), (-bw, tw / 2),
                 (-bw, -tw / 2), (0, -tw / 2)]]
    if kind == "T2":
        b, h, tf, tw = d                   # the flange at the bottom
        return [[(-b / 2, 0), (b / 2, 0), (b / 2, tf), (tw / 2, tf), (tw / 2, h), (-tw / 2, h),
                 (-tw / 2, tf), (-b / 2, tf)]]
    if kind == "Z":
        bf, tw, hw, h = d                  # the top flange towards -z, the bottom one towards +z
        e = bf + tw / 2
        return [[(-tw / 2, -h / 2), (e, -h / 2), (e, -hw / 2), (tw / 2, -hw / 2), (tw / 2, h / 2),
                 (-e, h / 2), (-e, hw / 2), (-tw / 2, hw / 2)]]
    raise KeyError(name)


def green(loops) -> tuple[float, float, float, float]:
    """A, I1 = int (y - yc)^2 dA, I2 = int (z - zc)^2 dA, I12 = int (y - yc)(z - zc) dA of the
    region the loops bound, by Green's theorem: each edge (z_i, y_i) -> (z_j, y_j) adds, with
    c = z_i y_j - z_j y_i, c/2 to A, (z_i + z_j) c/6 to int z dA, (z_i^2 + z_i z_j + z_j^2) c/12
    to int z^2 dA (likewise in y) and (z_i y_j + 2 z_i y_i + 2 z_j y_j + z_j y_i) c/24 to
    int y z dA."""
    a = sz = sy = szz = syy = syz = 0.0
    for loop in loops:
        for (zi, yi), (zj, yj) in zip(loop, loop[1:] + loop[:1]):
            c = zi * yj - zj * yi
            a += c / 2
            sz += (zi + zj) * c / 6
            sy += (yi + yj) * c / 6
            szz += (zi * zi + zi * zj + zj * zj) * c / 12
            syy += (yi * yi + yi * yj + yj * yj) * c / 12
            syz += (zi * yj + 2 * zi * yi + 2 * zj * yj + zj * yi) * c / 24
    zc, yc = sz / a, sy / a
    return a, syy - a * yc * yc, szz - a * zc * zc, syz - a * zc * yc


@pytest.mark.parametrize("name", SECTIONS)
def test_area_and_inertias_against_the_figure(name):
    """A, I1, I2, I12 of the reader against the figure's polygon integrated by Green's theorem
    (round-off: both exact). I12 is zero for every type but Z, whose flanges lie in the quadrants
    -z/+y and +z/-y of the centroid: I12 < 0."""
    a, i1, i2, j, k1, k2, i12 = pbarl_section(kind_of(name), SECTIONS[name])
    ga, g1, g2, g12 = green(outline(name))
    assert ga > 0
    assert (a, i1, i2) == pytest.approx((ga, g1, g2), rel=EXACT)
    if kind_of(name) == "Z":
        assert i12 == pytest.approx(g12, rel=EXACT) and i12 < 0 and i1 * i2 > i12 * i12
    else:
        assert i12 == 0.0 and abs(g12) < EXACT * np.sqrt(g1 * g2)


# --------------------------------------------------------------------------------------------
# torsion constants and shear factors
# --------------------------------------------------------------------------------------------
def thin_walled_j(name: str) -> float:
    """J from the figure's walls: the open thin-walled sum (1/3) sum b t^3 over the walls
    (flanges their full width; webs between the flanges' faces, except I1's and Z's between
    the flanges' mid-planes, as the reader's I); BOX1 Bredt's 4 A_m^2 / sum(s/t) on the walls'
    mid-line; HEXA Saint-Venant's A^4 / (4 pi^2 I_p) of the polygon. Thin-walled: exact as
    b/t grows, O(t/b) off otherwise; the reader follows the same rule, so round-off here."""
    d = SECTIONS[name]
    kind = kind_of(name)
    if kind == "BOX1":
        w, h, tt, tb, tr, tl = d
        bm, hm = w - (tl + tr) / 2, h - (tt + tb) / 2
        return 4 * (bm * hm) ** 2 / (bm / tt + bm / tb + hm / tl + hm / tr)
    if kind == "CHAN1":
        bf, tw, hw, h = d
        tf = (h - hw) / 2
        return (2 * (bf + tw) * tf**3 + hw * tw**3) / 3
    if kind == "CHAN2":
        t1, t2, h, w = d
        return (2 * h * t1**3 + (w - 2 * t1) * t2**3) / 3
    if kind == "CROSS":
        b, tv, h, th = d
        return (h * tv**3 + b * th**3) / 3
    if kind == "H":
        b, tf, h, tw = d
        return (2 * h * (tf / 2) ** 3 + b * tw**3) / 3
    if kind == "HAT":
        h, t, w, bf = d
        return (w + 2 * (h - t) + 2 * bf) * t**3 / 3            # top, webs, brims
    if kind == "HEXA":
        a, i1, i2, _ = green(outline(name))
        return a**4 / (4 * np.pi**2 * (i1 + i2))
    if kind in ("I1", "Z"):
        bf, tw, hw, h = d
        tf = (h - hw) / 2
        return (2 * (bf + tw) * tf**3 + (h - tf) * tw**3) / 3
    if kind == "T1":
        h, bw, tf, tw = d
        return (h * tf**3 + bw * tw**3) / 3
    if kind == "T2":
        b, h, tf, tw = d
        return (b * tf**3 + (h - tf) * tw**3) / 3
    raise KeyError(name)


def cowper_t(flange: float, tf: float, web: float, tw: float) -> float:
    """MYSTRAN 18's shear factor of a T in its web's plane (SECTION_PROPS_T/T1/T2), the flange
    ``flange`` x ``tf``, the web ``web`` long beyond it and ``tw`` thick."""
    m = flange * tf / ((web + tf / 2) * tw)
    n = flange / (web + tf / 2)
    return 10 * (1 + 4 * m) ** 2 / (12 + 96 * m + 276 * m * m + 192 * m**3 + 30 * n * n * m * (1 + m))


def mystran_k(name: str, a: float) -> tuple[float | None, float | None]:
    """K1, K2 as MYSTRAN 18's BD_PBARL.f90 computes them for the type (``a`` the area), each in
    the plane it acts in the figure (CHAN2: MYSTRAN's K1 is its web's, which the figure lays
    along z: K2 here)."""
    d = SECTIONS[name]
    kind = kind_of(name)
    if kind == "BOX1":
        w, h, tt, tb, tr, tl = d
        return (h - tt - tb) / h, (w - tl - tr) / w
    if kind == "CHAN1":
        bf, tw, hw, h = d
        return hw / h, bf / (bf + tw)
    if kind == "CHAN2":
        t1, t2, h, w = d
        return (h - t2) / h, (w - 2 * t1) / w
    if kind == "CROSS":
        b, tv, h, th = d
        return 5 / 6 * h * tv / a, 5 / 6 * (b + tv) * th / a
    if kind == "H":
        b, tf, h, tw = d
        return 5 / 6 * 2 * h * tf / 2 / a, b * tw / a
    if kind == "HAT":
        h, t, w, bf = d
        return (h - 2 * t) / h, (w + (w - 2 * t)) / (w + bf)
    if kind == "HEXA":
        return 5 / 6, 5 / 6
    if kind == "I1":
        bf, tw, hw, h = d
        return hw * tw / a, 5 / 6 * (h - hw) * (bf + tw) / a
    if kind == "T1":
        h, bw, tf, tw = d
        return 5 / 6 * h * tf / a, cowper_t(h, tf, bw, tw)
    if kind == "T2":
        b, h, tf, tw = d
        return cowper_t(b, tf, h - tf, tw), 5 / 6 * b * tf / a
    if kind == "Z":
        return None, None                  # NASTRAN ignores K1/K2 beside I12
    raise KeyError(name)


@pytest.mark.parametrize("name", SECTIONS)
def test_torsion_constant_and_shear_factors(name):
    """J as the thin-walled formula from the figure's walls (Bredt for BOX1, Saint-Venant's
    approximation for the solid HEXA); K1, K2 as MYSTRAN 18 computes them (HAT's K2 is MYSTRAN's
    too, above 1 for these brims narrower than the hat's inside)."""
    a, _, _, j, k1, k2, _ = pbarl_section(kind_of(name), SECTIONS[name])
    assert j == pytest.approx(thin_walled_j(name), rel=EXACT)
    expected = mystran_k(name, a)
    assert (k1 is None, k2 is None) == (expected[0] is None, expected[1] is None)
    if k1 is not None:
        assert (k1, k2) == pytest.approx(expected, rel=EXACT)


def test_hexa_torsion_constant_of_a_regular_hexagon():
    """Saint-Venant's approximation on a regular hexagon of side s: 1.0661 s^4, 3.0 % above St
    Venant's torsion constant 1.0355 s^4 (a finite-element solution of Prandtl's stress
    function, linear triangles, refined and extrapolated; the same solver gives the unit
    square's 0.14058; torsion tables give 1.04 s^4). MYSTRAN 18's rectangle of the mean width
    gives 0.9353 s^4, 10 % low."""
    s = 1.0
    a, i1, i2, j, *_ = pbarl_section("HEXA", (s / 2, 2 * s, np.sqrt(3) * s))
    assert (a, i1, i2) == pytest.approx((1.5 * np.sqrt(3) * s**2, 5 * np.sqrt(3) / 16 * s**4,
                                         5 * np.sqrt(3) / 16 * s**4), rel=EXACT)
    assert j == pytest.approx(1.0661 * s**4, abs=5e-5)
    assert j / (1.0355 * s**4) == pytest.approx(1.03, abs=0.001)


def test_types_that_are_others_drawn_otherwise():
    """CHAN1, I1 and T2 are the CHAN, I and T of the same shape; CHAN2 and T1 the CHAN and T
    turned by 90 degrees (I1 and I2, K1 and K2 exchanged); a BOX1 of equal opposite walls the
    BOX: every constant, to round-off."""
    def turned(s):
        a, i1, i2, j, k1, k2, i12 = s
        return a, i2, i1, j, k2, k1, i12

    def same(x, y):
        assert x == pytest.approx(y, rel=EXACT, abs=0.0)

    same(pbarl_section("CHAN1", (0.03, 0.004, 0.07, 0.08)), pbarl_section("CHAN", (0.034, 0.08, 0.004, 0.005)))
    same(pbarl_section("I1", (0.05, 0.005, 0.09, 0.10)),
         pbarl_section("I", (0.10, 0.055, 0.055, 0.005, 0.005, 0.005)))
    same(pbarl_section("T2", (0.06, 0.08, 0.006, 0.005)), pbarl_section("T", (0.06, 0.08, 0.006, 0.005)))
    same(pbarl_section("CHAN2", (0.005, 0.004, 0.04, 0.08)), turned(pbarl_section("CHAN", (0.04, 0.08, 0.004, 0.005))))
    same(pbarl_section("T1", (0.08, 0.05, 0.006, 0.005)), turned(pbarl_section("T", (0.08, 0.056, 0.006, 0.005))))
    same(pbarl_section("BOX1", (0.1, 0.12, 0.01, 0.01, 0.008, 0.008)), pbarl_section("BOX", (0.1, 0.12, 0.01, 0.008)))


# --------------------------------------------------------------------------------------------
# the cantilever: reference solver, mystran adapter, MYSTRAN reading the PBARL, PBEAML
# --------------------------------------------------------------------------------------------
def cantilever(name: str, card: str = "PBARL", element: str = "CBAR") -> str:
    """A cantilever 1.5 long along x, clamped at grid 1, orientation vector y, of the section
    ``name`` on a PBARL (or PBEAML) and a CBAR (or CBEAM)."""
    dims = ",".join(repr(x) for x in SECTIONS[name])
    return (f"GRID,1,,0.,0.,0.\nGRID,2,,1.5,0.,0.\n{element},1,1,1,2,0.,1.,0.\n"
            f"{card},1,1,,{kind_of(name)}\n,{dims}\nMAT1,1,7.+10,,.33\nSPC1,1,123456,1\n")


TIP = [(2, c) for c in range(1, 7)]
LOADS = LoadMatrix.from_dense([(2, 2), (2, 3), (2, 4)], np.diag([100.0, 100.0, 10.0]), ["Fy", "Fz", "Mx"])
"""The tip loaded in y, in z and by a torque, one load case each."""


def largest_difference(ours: np.ndarray, theirs: np.ndarray) -> float:
    """The largest difference over the load case's largest displacement, translations and
    rotations together, over the load cases."""
    return float(max(np.abs(ours[:, k] - theirs[:, k]).max() / np.abs(ours[:, k]).max()
                     for k in range(ours.shape[1])))


@pytest.mark.parametrize("name", SECTIONS)
@needs_mystran
def test_cantilever_reference_solver_and_mystran_agree(tmp_path, name):
    """The PBARL cantilever through the reference solver and through the mystran adapter (which
    hands MYSTRAN the reader's section as a PBAR): the same tip displacements to MYSTRAN's 7
    digits. Measured: 3.8e-7 at most (I1; 3.1e-7 HAT, CHAN1, CHAN2, T2)."""
    from solver_adapters.nastran import MystranAdapter
    p = tmp_path / "m.bdf"
    p.write_text(cantilever(name))
    ours = ReferenceAdapter(read_deck(p)).solve(LOADS, TIP).values
    theirs = MystranAdapter(p).solve(LOADS, TIP).values
    assert largest_difference(ours, theirs) <= RTOL
    if kind_of(name) == "Z":
        assert abs(ours[2, 0]) > 0.1 * abs(ours[1, 0])    # y and z bending couple (I12)


MYSTRAN_OWN = {
    "BOX1": {2: 0.00861, 3: 0.87816, 5: 0.87740, 6: 0.00045},
    "BOX1 top/bottom": {2: 0.00890, 3: 0.86322, 5: 0.86238, 6: 0.00051},
    "CHAN1": {3: 0.14290, 4: 1.32525, 5: 0.14252},
    "CHAN2": {2: 0.15854, 3: 0.84753, 4: 1.36162, 5: 0.84702, 6: 0.15800},
    "CROSS": {},
    "H": {},
    "HAT": {2: 1.79379, 3: 0.46307, 4: 0.86956, 5: 0.46197, 6: 1.79499},
    "HEXA": {3: 2.99717, 4: 1.08777, 5: 3.00000},
    "I1": {4: 1.02500},
    "T1": {},
    "T2": {4: 1.01508},
    "Z": {4: 1.02465},
}
"""MYSTRAN 18 reading the PBARL itself: the tip flexibility's diagonal terms that differ from
the reader's (component: MYSTRAN's over the reader's, as measured; every other term agrees to
RTOL_F06). J: MYSTRAN's own open-section factors (CHAN1, CHAN2 1.12, HAT 1.15) and wall lengths
(I1, T2, Z), HEXA its mean-width rectangle. I1, I2: MYSTRAN's formulas for BOX1 (its centroid
and corners), CHAN1 and HAT (I2, I1), HEXA (I2 without the tips' distance from the axis) are not
the figure's shape's, and it lays CHAN2's width DIM4 along y. Held here, so that a change of
either shows."""


@pytest.mark.parametrize("name", MYSTRAN_OWN)
@needs_mystran
def test_mystran_reading_the_pbarl_itself(tmp_path, name):
    """MYSTRAN 18 run on the PBARL deck itself (its own section constants): CROSS, H and T1
    agree in every term of the tip flexibility, shear included (0.2 to 0.8 % of their tip
    deflections: their K1, K2 are MYSTRAN's); I1, T2 and Z in all but torsion, Z's coupling of y
    and z included (its I12 has MYSTRAN's sign); the others as :data:`MYSTRAN_OWN` lists, the
    terms of the planes it leaves alone to RTOL_F06."""
    from test_cards import assert_close_to_mystran, mystran_direct, unit_cases, unit_loads
    p = tmp_path / "m.bdf"
    p.write_text(cantilever(name))
    ours = ReferenceAdapter(read_deck(p)).solve(unit_loads(2), TIP).values
    theirs = mystran_direct(tmp_path / "run", p, unit_cases(2, 1.0), TIP)
    differ = MYSTRAN_OWN[name]
    for comp, ratio in differ.items():
        assert theirs[comp - 1, comp - 1] / ours[comp - 1, comp - 1] == pytest.approx(ratio, abs=5e-5), comp
    same = [c - 1 for c in range(1, 7) if c not in differ]     # each listed with its plane's other
    keep = np.ix_(same, same)
    assert_close_to_mystran(ours[keep], theirs[keep])
    if kind_of(name) == "Z":
        assert theirs[1, 2] == pytest.approx(ours[1, 2], rel=RTOL) and ours[1, 2] > 0


@pytest.mark.parametrize("name", [n for n in SECTIONS if kind_of(n) != "Z"])
def test_pbeaml_on_cbeam_is_the_pbarl_on_cbar(name):
    """Each symmetric type on a PBEAML and a CBEAM is the PBARL on a CBAR: the same section
    constants, the same tip displacements (round-off)."""
    bar = read_deck_text(cantilever(name), name="bar.bdf")
    beam = read_deck_text(cantilever(name, "PBEAML", "CBEAM"), name="beam.bdf")
    fields = ("a", "i1", "i2", "j", "k1", "k2", "i12")
    assert [getattr(beam.pbars[1], f) for f in fields] == [getattr(bar.pbars[1], f) for f in fields]
    assert beam.pbars[1].card == "PBEAML"
    u_bar = ReferenceAdapter(bar).solve(LOADS, TIP).values
    u_beam = ReferenceAdapter(beam).solve(LOADS, TIP).values
    np.testing.assert_allclose(u_beam, u_bar, rtol=EXACT, atol=EXACT * np.abs(u_bar).max())


def test_z_on_pbeaml_is_refused_as_l_is():
    """Z is unsymmetric (I12 != 0): like L, refused on PBEAML at its TYPE field (a CBEAM keeps
    its shear flexibility with I12, which is not modelled together)."""
    with pytest.raises(DeckFormatError, match="TYPE Z .unsymmetric, I12 != 0. is not supported on PBEAML") as info:
        read_deck_text(cantilever("Z", "PBEAML", "CBEAM"), name="z.bdf")
    assert (info.value.file, info.value.line, info.value.card, info.value.field) == ("z.bdf", 4, "PBEAML", 5)


# --------------------------------------------------------------------------------------------
# dimensions that give no section: located errors
# --------------------------------------------------------------------------------------------
BAD = [
    ("BOX1", (0.1, 0.12, 0.01, 0.01, 0.05, 0.06), 14, "side walls DIM5 + DIM6 fill the width DIM1"),
    ("BOX1", (0.1, 0.12, 0.06, 0.07, 0.01, 0.01), 12, "top and bottom walls DIM3 + DIM4 fill the height DIM2"),
    ("BOX1", (0.1, 0.12, 0.01, 0.012, 0.008, 0.009), 14,
     "unequal top and bottom walls (DIM3, DIM4) together with unequal side walls (DIM5, DIM6) give a "
     "product of inertia I12 whose sign depends"),
    ("CHAN1", (0.03, 0.004, 0.08, 0.08), 12, "web height DIM3 fills the height DIM4"),
    ("CHAN2", (0.05, 0.004, 0.04, 0.08), 10, "legs 2 DIM1 fill the width DIM4"),
    ("CHAN2", (0.005, 0.05, 0.04, 0.08), 11, "base thickness DIM2 fills the height DIM3"),
    ("CROSS", (0.06, 0.01, 0.08, 0.09), 13, "arms' thickness DIM4 exceeds the height DIM3"),
    ("H", (0.05, 0.01, 0.08, 0.09), 13, "web thickness DIM4 exceeds the height DIM3"),
    ("HAT", (0.05, 0.06, 0.2, 0.02), 11, "wall thickness DIM2 fills the height DIM1"),
    ("HAT", (0.05, 0.004, 0.006, 0.02), 11, "walls 2 DIM2 exceed the top width DIM3"),
    ("HEXA", (0.05, 0.08, 0.05), 10, "tips 2 DIM1 fill the width DIM2"),
    ("I1", (0.05, 0.005, 0.1, 0.1), 12, "web height DIM3 fills the height DIM4"),
    ("T1", (0.08, 0.05, 0.006, 0.09), 13, "web thickness DIM4 exceeds the flange's height DIM1"),
    ("T2", (0.06, 0.08, 0.09, 0.005), 12, "flange thickness DIM3 fills the height DIM2"),
    ("T2", (0.06, 0.08, 0.006, 0.07), 13, "web thickness DIM4 exceeds the flange width DIM1"),
    ("Z", (0.03, 0.004, 0.09, 0.08), 12, "web height DIM3 fills the height DIM4"),
]


@pytest.mark.parametrize("kind, dims, field, why", BAD, ids=[f"{b[0]}-{b[2]}" for b in BAD])
def test_dimensions_that_give_no_section_are_located_errors(kind, dims, field, why):
    """The PBARL's field of the offending dimension, on its continuation line (line 5)."""
    text = (f"GRID,1,,0.,0.,0.\nGRID,2,,1.5,0.,0.\nCBAR,1,1,1,2,0.,1.,0.\nPBARL,1,1,,{kind}\n,"
            + ",".join(repr(x) for x in dims) + "\nMAT1,1,7.+10,,.33\n")
    with pytest.raises(DeckFormatError, match=re.escape(f"{kind} section: {why}")) as info:
        read_deck_text(text, name="bad.bdf")
    exc = info.value
    assert (exc.file, exc.line, exc.card, exc.field) == ("bad.bdf", 5, "PBARL", field), str(exc)
    assert f"field {field}" in str(exc)


def test_every_new_type_has_its_number_of_dimensions():
    """MYSTRAN 18's BAR_SHAPE table (BD_PBARL.f90): the number of DIMs of each type, which the
    reader takes (one more is NSM, a field beyond it an error)."""
    from solver_adapters.bdf.sections import PBARL_DIMS, UNSYMMETRIC
    assert {k: PBARL_DIMS[k] for k in ("BOX1", "CHAN1", "CHAN2", "CROSS", "H", "HAT", "HEXA", "I1",
                                       "T1", "T2", "Z")} == \
        {"BOX1": 6, "CHAN1": 4, "CHAN2": 4, "CROSS": 4, "H": 4, "HAT": 4, "HEXA": 3, "I1": 4,
         "T1": 4, "T2": 4, "Z": 4}
    assert UNSYMMETRIC == {"L", "Z"}
    with pytest.raises(DeckFormatError, match="PBARL has at most 13 fields") as info:
        read_deck_text("PBARL,1,1,,HEXA\n,.02,.08,.05,0.,1.\nMAT1,1,7.+10,,.33\n", name="x.bdf")
    assert info.value.field == 14
