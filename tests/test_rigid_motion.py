"""A structure its supports leave free to move as a rigid body is an error, whatever rounding does.

The factorization's pivot test catches a mechanism when a pivot falls below 1e-10 of its
diagonal; a support whose components point, in its grid's displacement system, along the motion
it should stop leaves pivots that rounding puts on either side of that line (a bus frame of the
blind benchmark, held vertically at two grids on one line and by two restraints that a CORD1R
turned horizontal, had pivot ratios 1.7e-10 in its deck and 8e-11 in diagnose's copy of it: one
solved to metres per newton, the other failed). ``free_rigid_motion`` fits the six rigid motions
with what the constraints allow and measures the strain energy of those it allows: exact up to
rounding (1e-18 there), so these tests hold with any threshold between 1e-15 and 1e-6.

Reference values are geometry: the free motion is the roll about the line through the two
vertical supports, and the frame with the restraints vertical (CD 0) is held.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from solver_adapters.bdf import read_deck_text
from solver_adapters.protocol import LoadMatrix, UnstableStructureError
from solver_adapters.reference import ReferenceAdapter
from solver_adapters.reference.model import assemble


def _table(cd_side: int, cord: str) -> str:
    """A table: a 2 m x 1 m frame of four legs 1 m high and four top beams, held at the feet.
    Feet 1 and 2 (on the line y = 0) are held in x, y, z and in y, z; feet 3 and 4 (y = 1) in
    component 3 of system ``cd_side``; ``cord`` defines the systems."""
    lines = [cord,
             "GRID,1,,0.,0.,0.", "GRID,2,,2.,0.,0.", f"GRID,3,,2.,1.,0.,{cd_side}", f"GRID,4,,0.,1.,0.,{cd_side}",
             "GRID,5,,0.,0.,1.", "GRID,6,,2.,0.,1.", "GRID,7,,2.,1.,1.", "GRID,8,,0.,1.,1.",
             "MAT1,1,2.1+11,,.3", "PBAR,1,1,1.-3,1.-7,1.-7,2.-7"]
    eid = 1
    for a, b, v in [(1, 5, "1.,0.,0."), (2, 6, "1.,0.,0."), (3, 7, "1.,0.,0."), (4, 8, "1.,0.,0."),
                    (5, 6, "0.,0.,1."), (6, 7, "0.,0.,1."), (7, 8, "0.,0.,1."), (8, 5, "0.,0.,1.")]:
        lines.append(f"CBAR,{eid},1,{a},{b},{v}")
        eid += 1
    lines += ["SPC1,1,123,1", "SPC1,1,23,2", "SPC1,1,3,3,4"]
    return "\n".join(l for l in lines if l) + "\n"


# system 9 through three grids at z = 0: its z axis is horizontal (along x), so "component 3"
# at feet 3 and 4 holds them along x and leaves the roll about the line y = 0 free
CORD1R = "CORD1R,9,1,2,4"
CORD2R_TILTED = "CORD2R,9,,0.,0.,0.,0.,-1.,1.,+C9\n+C9,1.,0.,0."   # z turned 45 deg about x: still holds z


def _solve(text: str):
    ref = ReferenceAdapter(read_deck_text(text))
    return ref.solve(LoadMatrix.unit([(7, 2)]), [(7, 2)]).values[0, 0]


def test_a_restraint_turned_horizontal_by_its_system_leaves_the_roll_free():
    with pytest.raises(UnstableStructureError, match="rigid body") as info:
        _solve(_table(9, CORD1R))
    m = re.search(r"rotation about the axis along \(([^)]*)\) through \(([^)]*)\)", str(info.value))
    axis, point = (np.array([float(v) for v in g.split(",")]) for g in m.groups())
    # the line of feet 1 and 2 (x axis), at its point nearest the frame's centroid (1, 0.5, 0.5);
    # 1e-12: the printed digits of a direction and point that are exact up to rounding
    assert axis == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)
    assert point == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)
    assert {g for g, _ in info.value.dofs} <= {5, 6, 7, 8, 3, 4}  # the top moves most


def test_the_same_frame_held_vertically_or_by_a_tilted_restraint_solves():
    """CD 0 (z vertical) and a system whose z is turned 45 deg about x both hold the roll; the
    top's sway under a lateral force is finite and the same order (the legs bend)."""
    u0 = _solve(_table(0, ""))
    u45 = _solve(_table(9, CORD2R_TILTED))
    assert 0 < abs(u0) < 1e-2 and 0 < abs(u45) < 1e-2


def test_a_translation_nothing_holds_is_named():
    text = _table(0, "").replace("SPC1,1,123,1", "SPC1,1,23,1")      # nothing holds x
    with pytest.raises(UnstableStructureError, match=r"translation along \(1, "):
        _solve(text)


def test_a_spring_to_ground_holds_a_rigid_motion():
    """A CELAS2 from grid 1 to ground along x holds the translation the supports leave free:
    no error, and the sway along x is the spring's F / k plus the frame's own."""
    text = _table(0, "").replace("SPC1,1,123,1", "SPC1,1,23,1") + "CELAS2,99,1.+6,1,1\n"
    ref = ReferenceAdapter(read_deck_text(text))
    u = ref.solve(LoadMatrix.unit([(1, 1)]), [(1, 1)]).values[0, 0]
    assert u == pytest.approx(1e-6, rel=1e-9)      # the force goes straight into the spring


def test_the_check_is_exact_where_the_pivots_are_not():
    """The energy of the free roll is rounding (below 1e-15 of the structure's stiffness), that
    of every motion of a held frame is more than 1e-6: the threshold (1e-10) sits far from both."""
    from solver_adapters.reference import model as m
    free = assemble(read_deck_text(_table(9, CORD1R)))
    assert free.free_rigid is not None
    held = assemble(read_deck_text(_table(0, "")))
    assert held.free_rigid is None
    old = m.RIGID_ENERGY
    try:
        m.RIGID_ENERGY = 1e-15
        assert assemble(read_deck_text(_table(9, CORD1R))).free_rigid is not None
        m.RIGID_ENERGY = 1e-6
        assert assemble(read_deck_text(_table(0, ""))).free_rigid is None
    finally:
        m.RIGID_ENERGY = old
