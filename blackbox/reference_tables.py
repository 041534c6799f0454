"""The dissertation's reference tables that the project compares with or uses as truths.

Numbers are transcribed from *Statistical system identification of structures with flexible
joints*; table numbers below are the dissertation's. Units: N, m, rad throughout (stiffnesses of
joint matrices in N*m/rad, moduli in Pa, areas in m^2, second moments in m^4).

Complex-model tables are dicts ``{"k11": ..., "k12": ..., ..., "k66": ...}``: the upper triangle of
the 6x6 constrained-joint matrix K_C of a 3-branch joint (branch 3 clamped), row by row, which is
also the order of :func:`blackbox.joints.complex_param_names` and of the dissertation's tables.
:func:`as_vector` gives them as an array in that order and :func:`kc_matrix` as the symmetric
matrix.

Two printed entries of Table 5.12 are questionable, and both readings are kept here under
separate names so that every caller says which one it uses:

* ``k13`` is printed 0.7508E5. The cube joint is mirror-symmetric (x <-> z about node 7), which
  forces ``k13 = k23 = k45 = k46``; the other three are printed 0.7805E5, Table 6.1's "actual"
  column prints k13 = 0.7805E5 for the same joint, and the stub "actual joint" of Section 5.4.1
  gives 0.7805E5 (``studies/chapter3.md``). 0.7508E5 is therefore read as a digit swap.
  :data:`TABLE_5_12` keeps the printed value, :data:`TABLE_5_12_SYMMETRIC` has 0.7805E5.
* ``k34 = -0.1530E4`` has the opposite sign of the stub joint's value; both signs keep K_C
  positive definite, the printed sign is kept in both dicts (``studies/chapter6.md``).

Table 5.18 and Table 6.8's "actual" column differ in the car joint's k34 (0.4648E3 against
0.4618E3); :data:`TABLE_5_18` is Table 5.18 as printed.
"""

from __future__ import annotations

import numpy as np

__all__ = ["COMPLEX_3_BRANCH_NAMES", "TABLE_3_1", "TABLE_3_1_LENGTH", "TABLE_5_12",
           "TABLE_5_12_SYMMETRIC", "TABLE_5_18", "TABLE_6_1_ACTUAL", "TABLE_6_1_COMPLEX",
           "TABLE_6_1_SIMPLE", "as_vector", "kc_matrix"]

COMPLEX_3_BRANCH_NAMES: tuple[str, ...] = tuple(f"k{i}{j}" for i in range(1, 7) for j in range(i, 7))
"""Parameter names of a 3-branch complex joint, k11 k12 ... k16 k22 ... k66."""


def _table(text: str) -> dict[str, float]:
    """A complex-model table written as its 21 entries in row order."""
    values = [float(v) for v in text.split()]
    if len(values) != len(COMPLEX_3_BRANCH_NAMES):
        raise ValueError(f"expected {len(COMPLEX_3_BRANCH_NAMES)} entries, got {len(values)}")
    return dict(zip(COMPLEX_3_BRANCH_NAMES, values))


# ---- Table 3.1: the cube of Section 3.7.1 ----------------------------------------------------
TABLE_3_1: dict[str, float] = dict(E=200e9, G=80e9, A=4.0e-4, Iy=1.333e-8, Iz=1.333e-8, J=0.4e-8)
"""Table 3.1, element properties of the cube (every member the same): Young's modulus E and shear
modulus G (Pa), area A (m^2), second moments Iy = Iz (m^4) and torsion constant J (m^4). The keys
are the keyword arguments of :func:`blackbox.joints.actual_joint_stub_kc`."""

TABLE_3_1_LENGTH = 0.2
"""Table 3.1, "Length of Element, L" (m): the cube's edge."""


# ---- Table 5.12: the cube joint (node 7), complex model ---------------------------------------
TABLE_5_12: dict[str, float] = _table(
    "0.6098E7 -0.7255E6 0.7508E5 0.2627E5 -0.1502E6 0.2830E7 "
    "0.6098E7 0.7805E5 -0.2550E5 0.1374E6 -0.1502E6 "
    "0.3122E6 -0.1530E4 -0.2551E5 0.2627E5 "
    "0.3122E6 0.7805E5 0.7805E5 "
    "0.6098E7 -0.7255E6 "
    "0.6098E7")
"""Table 5.12 as printed: K_C of the cube's 3-branch joint at node 7 (N*m/rad), the complex-model
truth of the cube examples (Sections 5.4, 6.2)."""

TABLE_5_12_SYMMETRIC: dict[str, float] = {**TABLE_5_12, "k13": 0.7805e5}
"""Table 5.12 with k13 = 0.7805E5 (N*m/rad), the value the joint's mirror symmetry requires
(k13 = k23 = k45 = k46; see the module docstring). Every other entry as printed. This is the truth
of the ``cube_complex`` fixture."""


# ---- Table 5.18: the car's B-pillar-to-roof-rail joint, complex model -------------------------
TABLE_5_18: dict[str, float] = _table(
    "0.3607E7 -0.1321E6 0.2355E5 0.2355E5 -0.1321E6 0.9408E6 "
    "0.3607E7 0.2355E5 -0.7697E4 -0.1321E6 -0.1321E6 "
    "0.1567E6 0.4648E3 -0.7697E4 0.2355E5 "
    "0.1567E6 0.2355E5 0.2355E5 "
    "0.3607E7 -0.1321E6 "
    "0.3607E7")
"""Table 5.18 as printed: K_C of the car's 3-branch joint (N*m/rad), the complex-model truth of the
car examples (positive definite, eigenvalues 1.56e5 ... 4.61e6)."""


# ---- Table 6.1: the cube joint identified with both models (Chapter 6) ------------------------
TABLE_6_1_ACTUAL: dict[str, float] = _table(
    "0.6098E7 -0.7255E6 0.7805E5 0.2627E5 -0.1502E6 0.2830E7 "
    "0.6098E7 0.7805E5 -0.2551E5 0.1374E6 -0.1502E6 "
    "0.3122E6 -0.1530E4 -0.2551E5 0.2627E5 "
    "0.3122E6 0.7805E5 0.7805E5 "
    "0.6098E7 -0.7255E6 "
    "0.6098E7")
"""Table 6.1, "actual" column (N*m/rad): the cube joint again; it differs from Table 5.12 in k13
(0.7805E5) and k24 (-0.2551E5 against -0.2550E5)."""

TABLE_6_1_COMPLEX: dict[str, float] = _table(
    "0.6093E7 -0.7237E6 0.7896E5 0.3134E5 -0.1431E6 0.2812E7 "
    "0.6240E7 0.7428E5 -0.4054E5 0.7228E5 -0.1295E6 "
    "0.3108E6 -0.9172E3 -0.2547E5 0.1992E5 "
    "0.3009E6 0.8608E5 0.7609E5 "
    "0.6006E7 -0.6980E6 "
    "0.6032E7")
"""Table 6.1, complex-model estimate of the cube joint's K_C (N*m/rad)."""

TABLE_6_1_SIMPLE: dict[str, float] = _table(
    "0.166E7 0 0 -0.4847E6 0 0 "
    "0.3281E7 0 0 -0.7254E6 0 "
    "0.4401E6 0 0 -0.1941E6 "
    "0.1328E7 0 0 "
    "0.2553E7 0 "
    "0.2063E7")
"""Table 6.1, simple-model estimate of the cube joint written as the K_C it implies (N*m/rad):
the entries a simple model cannot have are 0."""


def as_vector(table: dict[str, float]) -> np.ndarray:
    """A complex-model table as a float array in parameter order (k11, k12, ..., k66)."""
    return np.array([table[n] for n in COMPLEX_3_BRANCH_NAMES], dtype=float)


def kc_matrix(table: dict[str, float]) -> np.ndarray:
    """A complex-model table as the symmetric 6x6 K_C (N*m/rad)."""
    K = np.zeros((6, 6))
    K[np.triu_indices(6)] = as_vector(table)
    return K + np.triu(K, 1).T
