"""A PBEAM tapered from end A to end B (solver_adapters/bdf/beams.py, reference/frame.py).

References:
* NX NASTRAN's own displacements of pyNastran's ``models/sol200/model_200.bdf`` (its OP2, in
  ``tests/data/decks/nastran/model_200.csv``; compared in ``test_deck_tail.py``'s public decks):
  the rule that reproduces them, 3-point Gauss quadrature of the flexibility, was measured there;
* a cantilever whose I varies linearly, in closed form (integrating the unit-load moment over
  1 / E I(x)): the 3-point rule is not exact for one element, but converges to it as the beam is
  cut into elements, each tapered between its ends;
* the prismatic beam's closed form (Przemieniecki eq. 5.115), which a taper of equal ends is.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from solver_adapters.bdf import read_deck_text
from solver_adapters.bdf_write import write_deck
from solver_adapters.protocol import DeckFormatError, LoadMatrix
from solver_adapters.reference import ReferenceAdapter, frame

E, G = 2.1e11, 8.0e10


def test_equal_ends_are_the_prismatic_closed_form():
    """Equal sections at both ends: the closed form to rounding (the quadrature is exact for a
    polynomial integrand of degree 2), with and without shear flexibility; J = 0: no torsion."""
    sec = (3e-3, 4e-6, 9e-6, 2e-6)
    L = 2.3
    for k1, k2 in ((None, None), (0.8, 0.6)):
        kt = frame.tapered_local_stiffness(L, E, G, sec, sec, k1, k2)
        kc = frame.local_stiffness(*(np.array([v]) for v in (L, E, G, *sec)),
                                   np.array([k1 * sec[0] if k1 else np.inf]),
                                   np.array([k2 * sec[0] if k2 else np.inf]))[0]
        assert np.abs(kt - kc).max() <= 1e-13 * np.abs(kc).max()
    kt = frame.tapered_local_stiffness(L, E, G, sec[:3] + (0.0,), sec[:3] + (0.0,), None, None)
    assert not kt[3].any() and not kt[:, 9].any()


def _cantilever(n: int, i_a: float, i_b: float, L: float = 2.0) -> str:
    """A cantilever along x of ``n`` CBEAMs, I1 linear from ``i_a`` at the root to ``i_b`` at the
    tip, each element tapered between its own ends (the PBEAM of element k has both)."""
    lines = [f"GRID,{k + 1},,{L * k / n!r},0.,0." for k in range(n + 1)]
    lines.append("SPC1,1,123456,1")
    lines.append(f"MAT1,1,{E!r},{G!r}")
    inertia = np.linspace(i_a, i_b, n + 1).tolist()
    for k in range(n):
        ia, ib = inertia[k], inertia[k + 1]
        lines.append(f"CBEAM,{k + 1},{k + 1},{k + 1},{k + 2},0.,1.,0.")
        lines.append(f"PBEAM,{k + 1},1,1.-2,{ia!r},1.-5,,1.-5\n,,,,,,,,\n,NO,1.,1.-2,{ib!r},1.-5,,1.-5\n,0.,0.")
    return "\n".join(lines) + "\n"


def test_cantilever_converges_to_the_closed_form():
    """Tip load P along y (plane 1, I1) on a cantilever whose I1 falls linearly from I0 to
    I0 / 4: v(L) = P / E int_0^L (L - x)^2 / I(x) dx (closed form below). One element (three
    Gauss points) is 0.09 % off it; 8 elements agree to 1e-7 and 32 to 1e-10 (measured 9.1e-4,
    4.8e-8, 7.1e-12: the rule's error falls as h^6, 64 times a halving)."""
    P, L, i0 = 1.0e3, 2.0, 8.0e-6
    i1 = i0 / 4.0
    c = (i1 - i0) / L                                       # I(x) = i0 + c x
    # int (L - x)^2 / (i0 + c x) dx, with s = i0 + c x, L - x = (i0 + c L - s) / c = (b - s) / c
    b = i0 + c * L
    exact = P / (E * c ** 3) * (b ** 2 * np.log(b / i0) - 2 * b * (b - i0) + 0.5 * (b ** 2 - i0 ** 2))
    tip = {}
    for n in (1, 8, 32):
        deck = read_deck_text(_cantilever(n, i0, i1, L))
        load = LoadMatrix.from_dense([(n + 1, 2)], np.array([[P]]), ["1"])
        tip[n] = float(ReferenceAdapter(deck).solve(load, [(n + 1, 2)]).values[0, 0])
    assert 5e-4 < abs(tip[1] / exact - 1) < 2e-3
    assert abs(tip[8] / exact - 1) < 1e-7 and abs(tip[32] / exact - 1) < 1e-10


def test_taper_is_read_and_written_back():
    """End B's A, I1, I2, J (I12 and NSM aside) are the taper; write_deck (diagnose's edited
    decks) writes it as end B's station, which reads back as the same property."""
    deck = read_deck_text(_cantilever(1, 8e-6, 2e-6))
    p = deck.pbars[1]
    assert (p.a, p.i1, p.i2, p.j) == (1e-2, 8e-6, 1e-5, 1e-5) and p.taper == (1e-2, 2e-6, 1e-5, 1e-5)
    assert dataclasses.replace(read_deck_text(write_deck(deck, "large")).pbars[1], src=p.src) == p


@pytest.mark.parametrize("station, field, says", [
    (",NO,.5,1.-2,5.-6,1.-5,,1.-5\n,NO,1.,1.-2,2.-6,1.-5,,1.-5", 21, "varies through an intermediate station"),
    (",NO,1.,1.-2,2.-6,1.-5,1.-7,1.-5", 23, "I12"),
    (",NO,1.,0.,2.-6,1.-5,,1.-5", 20, "A > 0 at both ends"),
])
def test_a_taper_the_reader_does_not_model_is_a_located_error(station, field, says):
    text = _cantilever(1, 8e-6, 2e-6).replace(f",NO,1.,1.-2,{2e-6!r},1.-5,,1.-5", station)
    assert station in text
    with pytest.raises(DeckFormatError, match=says) as err:
        read_deck_text(text)
    assert (err.value.card, err.value.field) == ("PBEAM", field)


def test_external_adapters_refuse_a_tapered_beam():
    """MYSTRAN 18 has no CBEAM (the run deck writes CBARs, prismatic), OpenSees's elastic beams
    and FRAMESOLVE's are prismatic: each adapter names the property before any run."""
    from solver_adapters import legacy, opensees
    from solver_adapters.nastran import check_writable
    deck = read_deck_text(_cantilever(1, 8e-6, 2e-6))
    with pytest.raises(DeckFormatError, match="cannot run PBEAM 1: it is tapered") as err:
        check_writable(deck)
    assert err.value.card == "PBEAM"
    for adapter in (legacy, opensees):
        assert [card for card, _, why in adapter.unsupported_features(deck) if "tapered" in why] == ["PBEAM 1"]


def test_a_load_along_a_tapered_beam_is_refused_at_its_card(tmp_path):
    """A distributed PLOAD1 needs the element's fixed-end loads, not modelled for a taper: the
    import says so at the card; a load at an end is a nodal load and imports."""
    from blackbox.commands import import_deck
    body = _cantilever(1, 8e-6, 2e-6)
    head = "SOL 101\nCEND\nSUBCASE 1\n  SPC = 1\n  LOAD = 5\nBEGIN BULK\n"
    path = tmp_path / "t.bdf"
    path.write_text(head + body + "PLOAD1,5,1,FZ,LE,0.,100.,2.,100.\nENDDATA\n")
    with pytest.raises(DeckFormatError, match="tapered") as err:
        import_deck.run(path)
    assert err.value.card == "PLOAD1"
    path.write_text(head + body + "PLOAD1,5,1,FZ,LE,2.,100.\nENDDATA\n")
    assert import_deck.run(path).cases == ("1",)
