"""3D frame element (CBAR; CROD as its axial + torsion part), vectorized.

Pin flags (:func:`release_pins`, static condensation of the local matrix) and rigid offsets
(:func:`offset_transform`, applied to the global matrix) are applied by the assembly to the few
elements that have them.

Bending is Euler-Bernoulli unless a shear area is given (PBAR K1/K2): then Timoshenko, with the
shear flexibility ratio of each bending plane

    phi = 12 E I / (G As L^2),   As = K A  (K1 for plane 1 with I1, K2 for plane 2 with I2),

and the bending terms 12EI/(L^3 (1+phi)), 6EI/(L^2 (1+phi)), (4+phi)EI/(L (1+phi)),
(2-phi)EI/(L (1+phi)) (Przemieniecki eq. 5.115 with its shear parameter). ``As = inf`` (K blank)
gives phi = 0 and the same floating-point operations as the Euler-Bernoulli terms, so those
results are bit for bit unchanged. The element is exact for end loads (constant shear): a
cantilever's tip deflection is P L^3 / (3 E I) + P L / (K G A) with any number of elements.
A product of inertia I12 (PBAR) couples the two bending planes (:func:`_coupling_entries`).

Local axes follow NASTRAN's CBAR: x from GA to GB; the orientation vector v lies in plane 1
(the element x-y plane); z = x cross v; y = z cross x. Plane-1 bending (deflection along y,
rotation about z) uses I1; plane-2 bending (deflection along z, rotation about y) uses I2.
Local DOF order at each end: u, v, w, theta_x, theta_y, theta_z.

Reference: Przemieniecki, *Theory of Matrix Structural Analysis* (1968), eq. 5.115 (the 12x12
space-frame stiffness with shear deformation); MSC Nastran Reference Manual, CBAR; MSC Nastran
Quick Reference Guide, PBAR remark 5 (shear stiffness per unit length K1*A*G, K2*A*G).

Layout: the public functions take and return element-major arrays ``(ne, 12, 12)``. The
assembly uses the entry-major variants (``*_em``, arrays ``(12, 12, ne)``): every matrix entry is
then one contiguous vector over the elements, so each operation is a long, cache-friendly vector
operation (about 10x faster for the local stiffness and 5x for the rotation at 5e5 elements).
"""

from __future__ import annotations

import numpy as np


def shear_ratio(L, E, G, I, As):
    """``phi = 12 E I / (G As L^2)`` per element; exactly 0 where ``As`` is infinite (no shear
    flexibility), also when ``G`` or ``I`` is 0 there."""
    As = np.asarray(As, float)
    finite = np.isfinite(As)
    if not finite.any():
        return np.zeros(np.shape(L))
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = 12.0 * E * I / (G * np.where(finite, As, 1.0) * L**2)
    return np.where(finite, phi, 0.0)


# bending DOFs of plane 1 (v, theta_z at A and B) and plane 2 (w, theta_y), and the signs that
# make plane 2's DOFs (w, -theta_y) follow the same convention as plane 1's (v, theta_z)
_PLANE1 = (1, 5, 7, 11)
_PLANE2 = (2, 4, 8, 10)
_SIGN2 = (1.0, -1.0, 1.0, -1.0)


def _coupling_entries(L, E, I12) -> dict:
    """Entries coupling the two bending planes through the product of inertia I12 = int y z dA.

    The bending energy is 1/2 int kappa^T E [[I1, I12], [I12, I2]] kappa with kappa = (v'', w''),
    so in the DOFs q1 = (v_A, theta_zA, v_B, theta_zB), q2 = (w_A, -theta_yA, w_B, -theta_yB)
    the stiffness is E [[I1 kb, I12 kb], [I12 kb, I2 kb]], kb the unit Euler-Bernoulli matrix.
    A cantilever's tip flexibility is then (L^3 / 3E) [[I1, I12], [I12, I2]]^-1 (as MYSTRAN)."""
    e12 = E * I12
    kb = ((12 / L**3, 6 / L**2, -12 / L**3, 6 / L**2),
          (6 / L**2, 4 / L, -6 / L**2, 2 / L),
          (-12 / L**3, -6 / L**2, 12 / L**3, -6 / L**2),
          (6 / L**2, 2 / L, -6 / L**2, 4 / L))
    out = {}
    for a, p in enumerate(_PLANE1):
        for b, q in enumerate(_PLANE2):
            out[(min(p, q), max(p, q))] = _SIGN2[b] * e12 * kb[a][b]
    return out


def _entries(L, E, G, A, I1, I2, J, As1=None, As2=None, I12=None):
    """The upper-triangle entries ``{(i, j): values over elements}`` of the local stiffness.

    ``As1``/``As2``: shear areas of planes 1 and 2 (``None`` or ``inf``: Euler-Bernoulli);
    ``I12``: product of inertia (``None`` or all 0: uncoupled planes; not combined with shear
    areas, as in NASTRAN, which ignores K1/K2 when I12 is non-zero)."""
    ea, gj = E * A / L, G * J / L
    p1 = shear_ratio(L, E, G, I1, np.inf if As1 is None else As1)
    p2 = shear_ratio(L, E, G, I2, np.inf if As2 is None else As2)
    d1, d2 = 1.0 + p1, 1.0 + p2
    b1, b2 = 12 * E * I1 / L**3 / d1, 6 * E * I1 / L**2 / d1
    b3, b4 = (4 + p1) * E * I1 / L / d1, (2 - p1) * E * I1 / L / d1
    c1, c2 = 12 * E * I2 / L**3 / d2, 6 * E * I2 / L**2 / d2
    c3, c4 = (4 + p2) * E * I2 / L / d2, (2 - p2) * E * I2 / L / d2
    coupling = _coupling_entries(L, E, I12) if I12 is not None and np.any(I12) else {}
    return coupling | {(0, 0): ea, (6, 6): ea, (0, 6): -ea,
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
                       I1: np.ndarray, I2: np.ndarray, J: np.ndarray,
                       As1: np.ndarray | None = None, As2: np.ndarray | None = None,
                       I12: np.ndarray | None = None) -> np.ndarray:
    """Local 12x12 stiffness of each of ``ne`` elements, entry-major: shape ``(12, 12, ne)``.

    ``As1``, ``As2``: shear areas K1*A, K2*A (``None``/``inf``: no shear flexibility);
    ``I12``: product of inertia (``None``/0: none)."""
    k = np.zeros((12, 12, np.shape(L)[0]))
    for (i, j), val in _entries(L, E, G, A, I1, I2, J, As1, As2, I12).items():
        k[i, j] = val
        k[j, i] = val
    return k


def local_stiffness(L: np.ndarray, E: np.ndarray, G: np.ndarray, A: np.ndarray,
                    I1: np.ndarray, I2: np.ndarray, J: np.ndarray,
                    As1: np.ndarray | None = None, As2: np.ndarray | None = None,
                    I12: np.ndarray | None = None) -> np.ndarray:
    """Local 12x12 stiffness for each of ``ne`` elements, shape ``(ne, 12, 12)``."""
    return np.ascontiguousarray(
        local_stiffness_em(L, E, G, A, I1, I2, J, As1, As2, I12).transpose(2, 0, 1))


TAPER_POINTS = 3
"""Gauss-Legendre points over the length of a tapered beam's flexibility integral. NASTRAN's
rule, measured: with 3 points the displacements of pyNastran's ``models/sol200/model_200``
(four CBEAMs tapered from end A to end B, NX NASTRAN's OP2 at the initial design) are matched to
2.7e-8 of each component's largest, the OP2's single precision; with 2 or 4 points, or the exact
integral, they are 1e-5 to 1e-3 off."""


def tapered_local_stiffness(L: float, E: float, G: float, end_a, end_b, k1: float | None,
                            k2: float | None) -> np.ndarray:
    """Local 12x12 stiffness of a beam whose section (``end_a``, ``end_b``: A, I1, I2, J at its
    ends) varies linearly along it, as NASTRAN's CBEAM takes a tapered PBEAM: the flexibility of
    the beam clamped at end A and loaded at end B, ``int P(x)^T D(x)^-1 P(x) dx`` (``P`` the
    section forces of the end-B loads, ``D`` the section stiffness EA, K1 A G, K2 A G, GJ, E I2,
    E I1 at ``x``), by :data:`TAPER_POINTS`-point Gauss-Legendre quadrature, inverted and
    completed by equilibrium. ``k1``, ``k2``: the shear factors (``None``: rigid in shear).
    Exact for a prismatic beam (its integrand is a polynomial of degree 2): the closed form of
    :func:`local_stiffness`. J = 0 at both ends: no torsional stiffness, as a prismatic beam's."""
    t, w = np.polynomial.legendre.leggauss(TAPER_POINTS)
    xs, ws = (t + 1.0) * (0.5 * L), w * (0.5 * L)
    a0, a1 = np.asarray(end_a, float), np.asarray(end_b, float)
    F = np.zeros((6, 6))        # end-B loads Fx Fy Fz Mx My Mz -> end-B displacements
    torsion = bool(a0[3] or a1[3])
    for x, wt in zip(xs, ws):
        A, I1, I2, J = a0 + (a1 - a0) * (x / L)
        r = L - x
        F[0, 0] += wt / (E * A)
        if torsion:
            F[3, 3] += wt / (G * J)
        # plane 1: Mz(x) = Mz + r Fy (I1); plane 2: My(x) = My - r Fz (I2)
        F[1, 1] += wt * r * r / (E * I1) + (wt / (k1 * A * G) if k1 else 0.0)
        F[1, 5] += wt * r / (E * I1)
        F[5, 5] += wt / (E * I1)
        F[2, 2] += wt * r * r / (E * I2) + (wt / (k2 * A * G) if k2 else 0.0)
        F[2, 4] -= wt * r / (E * I2)
        F[4, 4] += wt / (E * I2)
    F[5, 1], F[4, 2] = F[1, 5], F[2, 4]
    if not torsion:
        F[3, 3] = 1.0
    Kbb = np.linalg.inv(F)
    if not torsion:
        Kbb[3, 3] = 0.0
    T = np.eye(6)               # end-A loads = -T (end-B loads); end-B rigid motion = T^T (end A)
    T[4, 2], T[5, 1] = -L, L
    H = np.vstack([-T, np.eye(6)])
    k = H @ Kbb @ H.T
    return 0.5 * (k + k.T)


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


def neutral_axis(k: np.ndarray, n: np.ndarray) -> np.ndarray:
    """A PBEAM's neutral axis offset ``n`` ``(m, 2)`` (element y, z) from the element axis (the
    shear centre): the local stiffness ``(m, 12, 12)`` with the axial strain taken on the
    neutral axis, whose axial displacement is u_N = u + n_z theta_y - n_y theta_z at each end,
    while bending, shear and torsion stay on the element axis: ``T^T k T`` with ``T`` the identity
    but for those two rows (MSC Nastran Reference Manual, CBEAM: the axial force acts at the
    neutral axis, the shear forces at the shear centre)."""
    m = k.shape[0]
    T = np.broadcast_to(np.eye(12), (m, 12, 12)).copy()
    for u in (0, 6):
        T[:, u, u + 4] = n[:, 1]
        T[:, u, u + 5] = -n[:, 0]
    out = np.einsum("mji,mjk,mkl->mil", T, k, T)
    return 0.5 * (out + out.transpose(0, 2, 1))


def release_pins(k: np.ndarray, released: list[int]) -> np.ndarray:
    """Pin flags: the local stiffness ``(m, 12, 12)`` with the local DOFs ``released`` (0-11; end A
    0-5, end B 6-11, order u v w theta_x theta_y theta_z) condensed out by static condensation,

        k_cc - k_cr k_rr^-1 k_rc,   released rows and columns zero,

    i.e. the element transmits no force or moment in a released component (MSC Nastran
    Reference Manual, CBAR pin flags). Raises ``ValueError`` with the element positions whose
    ``k_rr`` is singular (the releases leave the element a rigid-body motion: e.g. the same
    axial or transverse component released at both ends)."""
    r = np.asarray(released, dtype=int)
    c = np.setdiff1d(np.arange(12), r)
    k_rr = k[:, r][:, :, r]
    scale = np.abs(k_rr).max(axis=(1, 2))
    bad = np.flatnonzero(~(np.linalg.cond(k_rr) < 1e10) | (scale == 0.0))
    if bad.size:
        raise ValueError(bad)
    k_rc = k[:, r][:, :, c]
    out = np.zeros_like(k)
    cond = k[:, c][:, :, c] - np.einsum("mri,mrj->mij", k_rc, np.linalg.solve(k_rr, k_rc))
    out[np.ix_(np.arange(k.shape[0]), c, c)] = 0.5 * (cond + cond.transpose(0, 2, 1))
    return out


def offset_transform(kg: np.ndarray, wa: np.ndarray, wb: np.ndarray) -> np.ndarray:
    """Rigid offsets: ``T^T kg T`` for global element stiffnesses ``(m, 12, 12)`` whose ends sit at
    ``grid + w`` (``wa``, ``wb``: ``(m, 3)``, basic system). The bar end moves with its grid as
    a rigid body: u_end = u_grid + theta_grid x w, theta_end = theta_grid, so
    ``T = blockdiag([[I, -S(wa)], [0, I]], [[I, -S(wb)], [0, I]])`` with ``S(w) a = w x a``."""
    m = kg.shape[0]
    T = np.broadcast_to(np.eye(12), (m, 12, 12)).copy()
    for off, w in ((0, wa), (6, wb)):
        wx, wy, wz = w[:, 0], w[:, 1], w[:, 2]
        # -S(w): rows are the end translation, columns the grid rotation
        T[:, off + 0, off + 4], T[:, off + 0, off + 5] = wz, -wy
        T[:, off + 1, off + 3], T[:, off + 1, off + 5] = -wz, wx
        T[:, off + 2, off + 3], T[:, off + 2, off + 4] = wy, -wx
    out = np.einsum("mji,mjk,mkl->mil", T, kg, T)
    return 0.5 * (out + out.transpose(0, 2, 1))
