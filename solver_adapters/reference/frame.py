"""3D Euler-Bernoulli frame element (CBAR without offsets, pins or shear flexibility), vectorized.

Local axes follow NASTRAN's CBAR: x from GA to GB; the orientation vector v lies in plane 1
(the element x-y plane); z = x cross v; y = z cross x. Plane-1 bending (deflection along y,
rotation about z) uses I1; plane-2 bending (deflection along z, rotation about y) uses I2.
Local DOF order at each end: u, v, w, theta_x, theta_y, theta_z.

Reference: Przemieniecki, *Theory of Matrix Structural Analysis* (1968), eq. 5.115 (the 12x12
space-frame stiffness with shear deformation set to zero); MSC Nastran Reference Manual, CBAR.

Layout: the public functions take and return element-major arrays ``(ne, 12, 12)``. The
assembly uses the entry-major variants (``*_em``, arrays ``(12, 12, ne)``): every matrix entry is
then one contiguous vector over the elements, so each operation is a long, cache-friendly vector
operation (about 10x faster for the local stiffness and 5x for the rotation at 5e5 elements).
"""

from __future__ import annotations

import numpy as np


def _entries(L, E, G, A, I1, I2, J):
    """The upper-triangle entries ``{(i, j): values over elements}`` of the local stiffness."""
    ea, gj = E * A / L, G * J / L
    b1, b2, b3, b4 = 12 * E * I1 / L**3, 6 * E * I1 / L**2, 4 * E * I1 / L, 2 * E * I1 / L
    c1, c2, c3, c4 = 12 * E * I2 / L**3, 6 * E * I2 / L**2, 4 * E * I2 / L, 2 * E * I2 / L
    return {(0, 0): ea, (6, 6): ea, (0, 6): -ea,
            (3, 3): gj, (9, 9): gj, (3, 9): -gj,
            # plane 1: v (1, 7) and theta_z (5, 11), I1
            (1, 1): b1, (7, 7): b1, (1, 7): -b1,
            (1, 5): b2, (1, 11): b2, (5, 7): -b2, (7, 11): -b2,
            (5, 5): b3, (11, 11): b3, (5, 11): b4,
            # plane 2: w (2, 8) and theta_y (4, 10), I2 (signs: theta_y = -dw/dx)
            (2, 2): c1, (8, 8): c1, (2, 8): -c1,
            (2, 4): -c2, (2, 10): -c2, (4, 8): c2, (8, 10): c2,
            (4, 4): c3, (10, 10): c3, (4, 10): c4}


def local_stiffness_em(L: np.ndarray, E: np.ndarray, G: np.ndarray, A: np.ndarray,
                       I1: np.ndarray, I2: np.ndarray, J: np.ndarray) -> np.ndarray:
    """Local 12x12 stiffness of each of ``ne`` elements, entry-major: shape ``(12, 12, ne)``."""
    k = np.zeros((12, 12, np.shape(L)[0]))
    for (i, j), val in _entries(L, E, G, A, I1, I2, J).items():
        k[i, j] = val
        k[j, i] = val
    return k


def local_stiffness(L: np.ndarray, E: np.ndarray, G: np.ndarray, A: np.ndarray,
                    I1: np.ndarray, I2: np.ndarray, J: np.ndarray) -> np.ndarray:
    """Local 12x12 stiffness for each of ``ne`` elements, shape ``(ne, 12, 12)``."""
    return np.ascontiguousarray(local_stiffness_em(L, E, G, A, I1, I2, J).transpose(2, 0, 1))


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


def global_stiffness_em(R: np.ndarray, k_local: np.ndarray) -> np.ndarray:
    """``T^T k T`` with ``T = blockdiag(R, R, R, R)``, entry-major in and out: ``k_local`` is
    ``(12, 12, ne)``, ``R`` is ``(ne, 3, 3)`` as from :func:`rotation_matrices`.

    Works on the 3x3 blocks ``k_ab`` (``kg_ab = R^T k_ab R``); blocks that are zero in the local
    matrix stay zero, and only the upper blocks (a <= b) are computed, the rest by symmetry, so
    the result is exactly symmetric.
    """
    ne = k_local.shape[2]
    Rt = np.ascontiguousarray(R.transpose(1, 2, 0))        # (3, 3, ne): Rt[l, c] = R[:, l, c]
    out = np.zeros((12, 12, ne))
    tmp = np.empty((3, 3, ne))
    for a in range(4):
        for b in range(a, 4):
            blk = k_local[3 * a:3 * a + 3, 3 * b:3 * b + 3]
            nzl = [(i, l) for i in range(3) for l in range(3) if blk[i, l].any()]
            if not nzl:
                continue
            tmp[...] = 0.0                                   # tmp = k_ab R
            for i, l in nzl:
                tmp[i] += blk[i, l] * Rt[l]
            o = out[3 * a:3 * a + 3, 3 * b:3 * b + 3]        # o = R^T tmp
            for i in range(3):
                for j in range(3):
                    o[i] += Rt[j, i] * tmp[j]
            if a != b:
                out[3 * b:3 * b + 3, 3 * a:3 * a + 3] = o.transpose(1, 0, 2)
            else:
                o[...] = 0.5 * (o + o.transpose(1, 0, 2))    # exact symmetry of diagonal blocks
    return out


def global_stiffness(R: np.ndarray, k_local: np.ndarray) -> np.ndarray:
    """``T^T k T`` with ``T = blockdiag(R, R, R, R)`` for every element, shape ``(ne, 12, 12)``."""
    kg = global_stiffness_em(R, np.ascontiguousarray(np.asarray(k_local).transpose(1, 2, 0)))
    return np.ascontiguousarray(kg.transpose(2, 0, 1))
