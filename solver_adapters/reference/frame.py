"""3D Euler-Bernoulli frame element (CBAR without offsets, pins or shear flexibility), vectorized.

Local axes follow NASTRAN's CBAR: x from GA to GB; the orientation vector v lies in plane 1
(the element x-y plane); z = x cross v; y = z cross x. Plane-1 bending (deflection along y,
rotation about z) uses I1; plane-2 bending (deflection along z, rotation about y) uses I2.
Local DOF order at each end: u, v, w, theta_x, theta_y, theta_z.

Reference: Przemieniecki, *Theory of Matrix Structural Analysis* (1968), eq. 5.115 (the 12x12
space-frame stiffness with shear deformation set to zero); MSC Nastran Reference Manual, CBAR.
"""

from __future__ import annotations

import numpy as np


def local_stiffness(L: np.ndarray, E: np.ndarray, G: np.ndarray, A: np.ndarray,
                    I1: np.ndarray, I2: np.ndarray, J: np.ndarray) -> np.ndarray:
    """Local 12x12 stiffness for each of ``ne`` elements, shape ``(ne, 12, 12)``."""
    ne = L.shape[0]
    k = np.zeros((ne, 12, 12))
    ea, gj = E * A / L, G * J / L
    for (i, j), val in {(0, 0): ea, (6, 6): ea, (0, 6): -ea,
                        (3, 3): gj, (9, 9): gj, (3, 9): -gj}.items():
        k[:, i, j] = val
    # plane 1: v (1, 7) and theta_z (5, 11), I1
    b1, b2, b3, b4 = 12 * E * I1 / L**3, 6 * E * I1 / L**2, 4 * E * I1 / L, 2 * E * I1 / L
    for (i, j), val in {(1, 1): b1, (7, 7): b1, (1, 7): -b1,
                        (1, 5): b2, (1, 11): b2, (5, 7): -b2, (7, 11): -b2,
                        (5, 5): b3, (11, 11): b3, (5, 11): b4}.items():
        k[:, i, j] = val
    # plane 2: w (2, 8) and theta_y (4, 10), I2 (signs: theta_y = -dw/dx)
    c1, c2, c3, c4 = 12 * E * I2 / L**3, 6 * E * I2 / L**2, 4 * E * I2 / L, 2 * E * I2 / L
    for (i, j), val in {(2, 2): c1, (8, 8): c1, (2, 8): -c1,
                        (2, 4): -c2, (2, 10): -c2, (4, 8): c2, (8, 10): c2,
                        (4, 4): c3, (10, 10): c3, (4, 10): c4}.items():
        k[:, i, j] = val
    iu = np.triu_indices(12, 1)
    k[:, iu[1], iu[0]] = k[:, iu[0], iu[1]]
    return k


def rotation_matrices(xa: np.ndarray, xb: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Direction-cosine matrices ``(ne, 3, 3)`` (rows: local x, y, z in basic) and lengths ``(ne,)``.

    ``v`` is the orientation vector of each element (basic system). Raises ``ValueError`` with the
    element positions for zero-length elements or ``v`` parallel to the axis (callers translate it).
    """
    d = xb - xa
    L = np.linalg.norm(d, axis=1)
    ex = d / L[:, None]
    ez = np.cross(ex, v)
    nz = np.linalg.norm(ez, axis=1)
    vn = np.linalg.norm(v, axis=1)
    bad = np.flatnonzero(nz <= 1e-8 * np.maximum(vn, 1e-300))
    if bad.size:
        raise ValueError(bad)
    ez = ez / nz[:, None]
    ey = np.cross(ez, ex)
    return np.stack([ex, ey, ez], axis=1), L


def global_stiffness(R: np.ndarray, k_local: np.ndarray) -> np.ndarray:
    """``T^T k T`` with ``T = blockdiag(R, R, R, R)`` for every element, shape ``(ne, 12, 12)``."""
    ne = R.shape[0]
    T = np.zeros((ne, 12, 12))
    for b in range(4):
        T[:, 3 * b:3 * b + 3, 3 * b:3 * b + 3] = R
    return np.einsum("eji,ejk,ekl->eil", T, k_local, T, optimize=True)
