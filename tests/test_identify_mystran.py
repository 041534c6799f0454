"""`blackbox identify --adapter mystran` gives the reference adapter's estimates with exactly one
MYSTRAN run (the external-codes issue's acceptance).

Tolerance 2e-5 relative: MYSTRAN prints 7 significant digits (docs/mystran.md); the condensed
flexibility and responses agree with the in-process solver to ~1e-7 (measured), and the joint
parameters depend on relative branch rotations, small differences of large rotations, which
amplify that by ~20 here (measured 2.2e-6 on the cube and 4.2e-6 on the car). The issue's 1e-6
cannot be reached with 7-digit output; 2e-5 still catches any modelling difference (those are
O(1e-3) or larger).
"""

import json

import numpy as np
import pytest

from blackbox.cli import main

from conftest import FIXTURES, needs_mystran


@needs_mystran
@pytest.mark.parametrize("name", ["cube", "car"])
def test_identify_through_mystran_matches_reference(name, tmp_path):
    out = {}
    for adapter in ("reference", "mystran"):
        d = tmp_path / adapter
        assert main(["identify", str(FIXTURES / name), "--adapter", adapter, "--out", str(d),
                     "--no-cache"]) == 0
        out[adapter] = json.loads((d / "result.json").read_text())
    assert out["mystran"]["solver"]["runs"] == 1
    assert out["mystran"]["solver"]["right_hand_sides"] == 12 + 20
    ref = np.array([p["value"] for p in out["reference"]["parameters"]])
    mys = np.array([p["value"] for p in out["mystran"]["parameters"]])
    assert np.max(np.abs(mys - ref) / np.abs(ref)) < 2e-5
