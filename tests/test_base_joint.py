"""A joint that is the structure's only support (``blackbox.condensation``, "Reference springs").

A cantilever column whose base is a two-grid joint (footing grid clamped, column base grid tied to
it in translation) is a mechanism with the joint released. The declared model then adds
reference springs across the joint to the solver's deck and carries them exactly
(``K_deck = K_ref``). References: the same study with the springs written into the deck by hand
(``CELAS2`` + ``deck_stiffness``), and the cantilever's closed form on a rotational base spring:

    top deflection  u = F L^3 / (3 E I) + F L^2 / k        (Euler-Bernoulli, base rotation F L / k)
    top rotation    t = F L^2 / (2 E I) + F L / k
    top twist       p = T L / (G J) + T / k_z
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from blackbox.cli import main
from blackbox.commands import diagnose, identify
from blackbox.declared import declared_model
from blackbox.errors import StudyError
from blackbox.structures import FrameBuilder, write_study
from blackbox.study import load_study

from conftest import needs_mystran

L = 1.6                                  # m, column height
N_EL = 4                                 # elements up the column (Euler-Bernoulli: exact for end loads)
TOP = 2 + N_EL
E, G = 30.0e9, 12.5e9                    # Pa
A, I, J = 0.16, 0.4 ** 4 / 12.0, 0.1406 * 0.4 ** 4
TRUE = {"kx12": 3.0e8, "ky12": 2.0e8, "kz12": 5.0e8}     # N*m/rad, base springs about x, y, z
INITIAL = 1.0e8

SAME_RTOL = 1e-9
"""By hand and automatic reference springs of another value: the same algebra, different
round-off in the flexibility (k / k_ref = 2..5 here, about 1e-15 relative in G; 1e-9 leaves room)."""

CLOSED_FORM_RTOL = 1e-7
"""Exact data, identified to xtol 1e-8 in log k: the estimate matches the closed form to ~1e-8."""


def column(planar: bool = False, footing: str = "123456", springs: float = 0.0) -> FrameBuilder:
    """The column: footing grid 1 (constrained ``footing``), base grid 2 coincident, tied to 1 by
    RBE2 CM=123, CBARs 2..TOP up to z = L; ``planar``: components 2, 4, 6 constrained (grid 2: 4, 6);
    ``springs`` > 0: CELAS2 of that stiffness between grids 1 and 2 about x, y, z (by hand)."""
    f = FrameBuilder(E=E, G=G, A=A, I1=I, I2=I, J=J)
    f.grid(1, (0.0, 0.0, 0.0))
    for k in range(N_EL + 1):
        f.grid(2 + k, (0.0, 0.0, L * k / N_EL))
    for k in range(N_EL):
        f.bar(2 + k, 3 + k, v=(1.0, 0.0, 0.0))
    f.fix(1, footing)
    if planar:
        f.fix(2, "46")
        for g in range(3, TOP + 1):
            f.fix(g, "246")
    f.rbe2.append((100, 1, (2,), "123"))
    f.joints.append(("base", (1, 2)))
    if springs:
        f.springs += [(1, c, 2, c, springs) for c in (4, 5, 6)]
    return f


LOADS = [("Fx", TOP, 1, 1.0e5), ("Fy", TOP, 2, 8.0e4), ("T", TOP, 6, 2.0e4),
         ("Fxy", TOP, 1, -6.0e4), ("Fxy", TOP, 2, 5.0e4)]


def closed_form(case: str) -> dict[tuple[int, int], float]:
    """Top displacements of the cantilever on base springs ``TRUE`` (module docstring)."""
    fx = sum(v for c, _, comp, v in LOADS if c == case and comp == 1)
    fy = sum(v for c, _, comp, v in LOADS if c == case and comp == 2)
    t = sum(v for c, _, comp, v in LOADS if c == case and comp == 6)
    ky, kx, kz = TRUE["ky12"], TRUE["kx12"], TRUE["kz12"]
    return {(TOP, 1): fx * (L ** 3 / (3 * E * I) + L ** 2 / ky),
            (TOP, 5): fx * (L ** 2 / (2 * E * I) + L / ky),
            (TOP, 2): fy * (L ** 3 / (3 * E * I) + L ** 2 / kx),
            (TOP, 4): -fy * (L ** 2 / (2 * E * I) + L / kx),
            (TOP, 6): t * (L / (G * J) + 1.0 / kz)}


def write_column_study(folder: Path, builder: FrameBuilder, deck_stiffness: float = 0.0,
                       planar: bool = False, sigma_rel: float = 1e-3) -> Path:
    loads = [r for r in LOADS if not planar or r[2] == 1]
    write_study(folder, builder, loads, "column", initial=INITIAL)
    if deck_stiffness:
        toml = folder / "study.toml"
        toml.write_text(toml.read_text() + f"deck_stiffness = {deck_stiffness!r}\n")
    rows = ["case,grid,component,value,sigma"]
    for case in dict.fromkeys(c for c, *_ in loads):
        for (g, comp), v in closed_form(case).items():
            if planar and comp not in (1, 5):
                continue
            rows.append(f"{case},{g},{comp},{v!r},{abs(v) * sigma_rel + 1e-12!r}")
    (folder / "measurements.csv").write_text("\n".join(rows) + "\n")
    return folder


def _params(res) -> dict[str, np.ndarray]:
    r = res.result
    return {n: np.array([k, s, lo, hi]) for n, k, s, lo, hi in
            zip(r.param_names, r.k, r.std, r.ci_low, r.ci_high)}


def test_released_base_joint_needs_reference_springs(tmp_path):
    """Released, the column turns about its base: the plain condensation cannot run, the declared
    model adds one reference spring per plane at the joint's ``initial`` and records them."""
    study = load_study(write_column_study(tmp_path / "auto", column()), need_measurements=True)
    dm = declared_model(study)
    springs, used = dm.reference_springs()
    assert used == {"base": INITIAL}
    assert sorted((s.a, s.b, s.k) for s in springs) == [((1, c), (2, c), INITIAL) for c in (4, 5, 6)]
    from blackbox.adapters import make_adapter_for
    cm = dm.condense(make_adapter_for(study, "reference"))
    assert len(cm.c.added_springs) == 3
    K = dm.K_deck(cm.c)
    idx = {d: i for i, d in enumerate(cm.c.boundary)}
    assert K[idx[(2, 5)], idx[(2, 5)]] == INITIAL and K[idx[(1, 5)], idx[(2, 5)]] == -INITIAL


@pytest.mark.parametrize("by_hand", [INITIAL, 3.7e8])
def test_identify_equals_deck_springs_written_by_hand(tmp_path, by_hand):
    """The automatic reference springs give what a user gets by writing CELAS2 springs between the
    grids and ``deck_stiffness`` into the study: identical to round-off (bit for bit when the two
    stiffnesses are equal: the same numbers go through the same algebra)."""
    auto = identify.run(write_column_study(tmp_path / "auto", column()), adapter="reference")
    hand = identify.run(write_column_study(tmp_path / "hand", column(springs=by_hand), deck_stiffness=by_hand),
                        adapter="reference")
    assert auto.result.param_names == hand.result.param_names == ("kx12", "ky12", "kz12")
    pa, ph = _params(auto), _params(hand)
    for n in pa:
        if by_hand == INITIAL:
            np.testing.assert_array_equal(pa[n], ph[n])
        else:
            np.testing.assert_allclose(pa[n], ph[n], rtol=SAME_RTOL)
    assert auto.result.chi2 == pytest.approx(hand.result.chi2, rel=SAME_RTOL, abs=1e-12)


def test_identify_recovers_the_cantilever_closed_form(tmp_path):
    """Measurements = the closed form (module docstring) of springs ``TRUE``: the identified base
    springs are the closed form's."""
    res = identify.run(write_column_study(tmp_path / "auto", column()), adapter="reference")
    assert res.ok
    for name, k in zip(res.result.param_names, res.result.k):
        assert k == pytest.approx(TRUE[name], rel=CLOSED_FORM_RTOL), name
    assert res.result.chi2 < 1e-6          # exact data: the residuals are round-off


def test_planar_column_has_only_the_in_plane_spring(tmp_path):
    """A planar model constrains the out-of-plane rotations of both grids: the springs about x
    and z cannot act and are no parameters; the in-plane one matches the closed form."""
    folder = write_column_study(tmp_path / "planar", column(planar=True), planar=True)
    study = load_study(folder, need_measurements=True)
    (joint,) = declared_model(study).joints
    assert joint.param_names == ("ky12",)
    assert joint.constrained_springs == (("x", 1, 2), ("z", 1, 2))
    res = identify.run(study, adapter="reference")
    assert res.ok and res.result.k[0] == pytest.approx(TRUE["ky12"], rel=CLOSED_FORM_RTOL)


def test_every_spring_constrained_is_an_error(tmp_path):
    f = column(planar=True)
    f.fix(2, "456")
    folder = write_column_study(tmp_path / "stuck", f, planar=True)
    with pytest.raises(StudyError, match="fix both ends of every spring"):
        declared_model(load_study(folder))


def test_a_mechanism_no_reference_spring_fixes_names_the_joint(tmp_path, capsys):
    """The footing grid clamped in translation only: springs across the joint join the column to
    a footing that itself turns freely. The error names the joint and the DOFs that move."""
    folder = write_column_study(tmp_path / "loose", column(footing="123"))
    with pytest.raises(StudyError) as err:
        identify.run(folder, adapter="reference")
    msg = str(err.value)
    assert "still is with reference springs across joint(s) 'base'" in msg
    assert "joint 'base' moves at" in msg and "1:5" in msg
    assert main(["identify", str(folder), "--out", str(tmp_path / "out")]) == 2
    assert "joint 'base' moves at" in capsys.readouterr().err


def test_a_mechanism_elsewhere_says_it_is_not_the_joint(tmp_path):
    """A free-floating bar beside the column is a mechanism of its own: the reference springs do
    not help and the error says no joint DOF moves."""
    f = column()
    f.grid(50, (1.0, 0.0, 0.0))
    f.grid(51, (1.0, 0.0, 1.0))
    f.bar(50, 51)
    folder = write_column_study(tmp_path / "floating", f)
    with pytest.raises(StudyError, match="no joint DOF is among the DOFs that move"):
        identify.run(folder, adapter="reference")


def test_diagnose_runs_on_a_base_joint_as_with_springs_by_hand(tmp_path):
    """diagnose cuts the deck the condensation ran (reference springs included): the automatic
    study and the by-hand one give the same diagnosis."""
    effects = ["support_flexibility", "load_scale", "sensor_gain"]
    auto = diagnose.run(write_column_study(tmp_path / "auto", column(planar=True), planar=True, sigma_rel=1e-2),
                        adapter="reference", effects=effects, plots=False)
    hand = diagnose.run(write_column_study(tmp_path / "hand", column(planar=True, springs=INITIAL),
                                           deck_stiffness=INITIAL, planar=True, sigma_rel=1e-2),
                        adapter="reference", effects=effects, plots=False)
    a, h = auto.document, hand.document
    assert a["verdict"] == h["verdict"] == "adequate"
    assert a["before"]["reduced_chi2"] == pytest.approx(h["before"]["reduced_chi2"], rel=SAME_RTOL, abs=1e-12)
    assert [c["effect"] for c in a["candidates"]] == [c["effect"] for c in h["candidates"]]


MYSTRAN_RTOL = 1e-5
"""MYSTRAN prints 7 significant digits (docs/mystran.md): identifications agree to a few 1e-6."""


@needs_mystran
def test_mystran_holds_the_base_joint_too(tmp_path):
    """MYSTRAN also finds the released column singular; with the reference springs written as
    CELAS2 cards it gives the in-process solver's estimate."""
    folder = write_column_study(tmp_path / "col", column(planar=True), planar=True)
    ref = identify.run(folder, adapter="reference")
    mys = identify.run(folder, adapter="mystran")
    assert mys.model.c.added_springs == ref.model.c.added_springs
    assert mys.result.k[0] == pytest.approx(ref.result.k[0], rel=MYSTRAN_RTOL)
