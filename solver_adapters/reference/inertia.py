"""Inertia relief (PARAM,INREL,-1): the applied loads balanced by the inertia loads of the
rigid-body acceleration they give the free structure, as NASTRAN's linear static solution does
it (MSC Nastran Linear Static Analysis User's Guide, chapter "Inertia Relief"; MSC QRG SUPORT
and PARAM,INREL).

NASTRAN, with r the SUPORT DOFs (the r-set) and l the other independent DOFs:

    D = -K_ll^-1 K_lr           the motion of the l DOFs for unit motions of the r DOFs
    Phi = [D; I]                 the rigid-body modes the r-set defines
    m_r = Phi^T M Phi            the rigid-body mass
    a_r = m_r^-1 Phi^T P         the rigid-body acceleration of the applied loads P
    K_ll u_l = P_l - (M Phi a_r)_l,   u_r = 0

so the displacements are those of the structure held at the r-set under the balanced loads
``P - M Phi a_r`` (whose resultant on every rigid-body mode is zero: the r-set reacts nothing).
:func:`relieve` computes those balanced loads; the study then holds the r-set (the SUPORT
entries are constraints of its model) and solves them as any load.

The study stays valid when a diagnosis or an identification changes the stiffness of joints or
members, because the balanced loads depend on the mass and the geometry only: for a free
structure with a statically determinate r-set, D is the rigid-body motion of the l DOFs, the
same for any stiffness that gives rigid-body motions no strain energy (a joint's spring between
coincident grids, a member's stiffness factor). :func:`relieve` checks that this holds, and
refuses otherwise: D computed from the stiffness must be a rigid-body motion of the grids
(``RIGID_TOL``), which it is not when something else holds the structure in an r direction (an
SPC, a spring to ground, an MPC) or when the r-set holds more than the rigid-body motions, and
the rigid-body motion must meet no stiffness at the r-set (``ENERGY_TOL``). It then uses the
exact geometric rigid-body motions (the least-squares fit of D by them), so that the loads do not
carry the round-off of ``K_ll^-1``.

The mass is NASTRAN's default lumped mass (PARAM,COUPMASS off), the one a GRAV load acts on
(:class:`~solver_adapters.reference.loads.Masses`): half of each bar's and rod's (rho A + NSM) L
at its ends (a tapered beam's by :func:`~solver_adapters.reference.loads.bar_end_masses`; a bar's
offset ends, carried rigidly to the grid), a CONM2's mass at its centre of
gravity with its inertia, a CONM1's matrix, a CMASS1/CMASS2 to ground on its component, all
times PARAM,WTMASS. The lumped mass of a bar or rod has no rotational inertia.
"""

from __future__ import annotations

import copy

import numpy as np
import scipy.sparse as sp

from solver_adapters.errors import ModelError, UnstableStructureError
from solver_adapters.protocol import DeckFormatError
from solver_adapters.reference.loads import Masses, bar_end_masses, bar_frame
from solver_adapters.reference.model import Factorization, assemble, displacement_transform

SUPORT_CARDS = ("SUPORT", "SUPORT1")

RIGID_TOL = 1e-6
"""Largest departure of D (from the stiffness) from a rigid-body motion of the grids, relative to
its largest value: a solve of K_ll is accurate to about eps * cond(K_ll) (1e-16 * 1e8 for a
frame of ill-conditioned members), and a non-rigid D (the structure held elsewhere, or an r-set
that holds a deformation) departs by a fraction of its size."""

ENERGY_TOL = 1e-8
"""Largest force K Phi of a rigid-body mode, relative to the largest stiffness term times the
mode's largest motion: the element stiffnesses give rigid-body motions no force to round-off
(1e-16 relative per term); a spring to ground of a millionth of the structure's stiffness at an
r DOF would give 1e-6."""


def _where(src: str) -> dict:
    file, _, line = src.rpartition(":")
    return {"file": file or None, "line": int(line) if line.isdigit() else None}


def _skew(e: np.ndarray) -> np.ndarray:
    """S(e) with S(e) v = e x v."""
    return np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])


def point_mass(m: float, e) -> np.ndarray:
    """The 6x6 mass matrix at a grid of a point mass ``m`` at offset ``e`` (basic) from it: the
    point moves u + theta x e = [I, -S(e)] [u; theta]."""
    A = np.hstack([np.eye(3), -_skew(np.asarray(e, float))])
    return m * (A.T @ A)


def mass_matrix(deck, masses: Masses, grid_ids: np.ndarray) -> sp.csr_matrix:
    """NASTRAN's default lumped mass matrix (basic components, 6 per grid of ``grid_ids``): block
    diagonal, each grid's 6x6 block from the masses at it (see the module docstring)."""
    pos = {int(g): k for k, g in enumerate(np.asarray(grid_ids).tolist())}
    blocks = np.zeros((len(pos), 6, 6))

    def add(grid: int, block: np.ndarray) -> None:
        blocks[pos[grid]] += block

    for b in deck.cbars.values():
        mpl = masses.bar_pid.get(b.pid, 0.0)
        if mpl:
            _, L, wa, wb = bar_frame(deck, b)
            ma, mb = bar_end_masses(mpl, L)
            add(b.ga, point_mass(ma, wa))
            add(b.gb, point_mass(mb, wb))
    for r in deck.rods.values():
        mpl = masses.conrod.get(r.eid, 0.0) if r.pid is None else masses.rod_pid.get(r.pid, 0.0)
        if mpl:
            L = float(np.linalg.norm(np.subtract(deck.grids[r.gb].xyz, deck.grids[r.ga].xyz)))
            for grid in (r.ga, r.gb):
                add(grid, point_mass(0.5 * mpl * L, np.zeros(3)))
    for grid, m, offset in masses.conm2:
        add(grid, point_mass(m, offset))
    for grid, inertia in masses.conm2_inertia or ():
        block = np.zeros((6, 6))
        block[3:, 3:] = inertia
        add(grid, block)
    for grid, matrix in masses.conm1 or ():
        add(grid, matrix)
    for grid, comp, m in masses.scalar or ():
        d = deck.displacement_frames([grid])[0][(comp - 1) % 3]
        block = np.zeros((6, 6))
        k = 0 if comp <= 3 else 3
        block[k:k + 3, k:k + 3] = m * np.outer(d, d)
        add(grid, block)
    blocks *= masses.wtmass
    n = len(pos)
    return sp.bsr_matrix((blocks, np.arange(n), np.arange(n + 1)), shape=(6 * n, 6 * n)).tocsr()


def rigid_modes(deck, grid_ids: np.ndarray) -> np.ndarray:
    """The six rigid-body motions of the grids (n_g x 6, in each grid's CD components):
    translations along the basic axes, rotations about them through the grids' centroid."""
    xyz = np.array([deck.grids[g].xyz for g in np.asarray(grid_ids).tolist()], float).reshape(-1, 3)
    n = len(xyz)
    G = np.zeros((n, 6, 6))
    arm = xyz - xyz.mean(axis=0)
    for i in range(3):
        e = np.zeros(3)
        e[i] = 1.0
        G[:, i, i] = 1.0
        G[:, :3, 3 + i] = np.cross(e, arm)
        G[:, 3 + i, 3 + i] = 1.0
    G = G.reshape(6 * n, 6)
    D = displacement_transform(deck, np.asarray(grid_ids))
    return G if D is None else D.T @ G


def relieve(deck, masses: Masses, cases: list[dict[tuple[int, int], float]], *, param_src: str = ""
            ) -> tuple[list[dict[tuple[int, int], float]], list[np.ndarray], float]:
    """The loads of each case (``{(grid, component): value}`` in each grid's CD) balanced by
    inertia relief on the deck's SUPORT/SUPORT1 DOFs. Returns the balanced loads, each case's
    rigid-body acceleration (one value per r DOF, in the order of the SUPORT entries) and the
    rigid-body mass's largest eigenvalue. DeckFormatError at the SUPORT (or, without one, the
    PARAM,INREL at ``param_src``) when inertia relief does not apply (module docstring)."""
    sup = [s for s in deck.spc1s if s.card in SUPORT_CARDS]
    if not sup:
        raise DeckFormatError("PARAM,INREL,-1 (inertia relief on the SUPORT DOFs) needs SUPORT "
                              "entries, or a SUPORT1 set the case control selects (SUPORT1 = n): "
                              "the model has none", card="PARAM", **_where(param_src))
    first = sup[0]

    def refuse(message: str) -> DeckFormatError:
        return DeckFormatError(f"inertia relief (PARAM,INREL,-1): {message}", card=first.card,
                               **_where(first.src))

    scalar = [g.id for g in deck.grids.values() if getattr(g, "scalar", False)]
    if scalar:
        raise refuse(f"the model has scalar points (SPOINT {scalar[0]}), which have no rigid-body "
                     f"motion: inertia relief is imported for models of grids only")
    rset: list[tuple[int, int]] = []
    for s in sup:
        rset += [(g, int(c)) for g in s.grids for c in s.components]

    free = copy.copy(deck)
    free.spc1s = [s for s in deck.spc1s if s.card not in SUPORT_CARDS]
    A = assemble(free)                         # r-set free
    held = assemble(deck)                      # r-set held: K_ll, with the mechanism checks
    at = {lab: k for k, lab in enumerate(A.f_labels)}
    missing = [d for d in rset if d not in at]
    if missing:
        g, c = missing[0]
        raise refuse(f"SUPORT grid {g} component {c} is not an independent DOF with stiffness (a "
                     f"rigid element's dependent DOF, or one AUTOSPC constrains: no element gives "
                     f"it stiffness)")
    r_idx = np.array([at[d] for d in rset])
    try:
        l_idx = np.array([at[lab] for lab in held.f_labels], dtype=np.int64)
    except KeyError as exc:
        raise refuse(f"holding the r-set leaves DOF {exc.args[0]} that the free model does not "
                     f"have") from None
    K = A.K_ff.tocsc()
    K_lr = K[l_idx][:, r_idx].toarray()
    try:
        fac = Factorization(held, backend="superlu")
    except (ModelError, UnstableStructureError) as exc:
        raise refuse(f"the structure held at the SUPORT DOFs is still a mechanism, so they do not "
                     f"hold every rigid-body motion (too few, or placed so that some motion is "
                     f"left free): {exc}") from None
    try:
        Dl = -fac.solve(K_lr)
    finally:
        fac.close()
    phi = np.zeros((len(A.f_labels), len(rset)))
    phi[l_idx] = Dl
    phi[r_idx, np.arange(len(rset))] = 1.0

    # D must be a rigid-body motion of the grids: fit it by the six and use the exact fit
    G = rigid_modes(deck, A.grid_ids)[A.g_index(A.f_labels)]
    coef, *_ = np.linalg.lstsq(G, phi, rcond=None)
    fit = G @ coef
    for j, (g, c) in enumerate(rset):
        dev = float(np.abs(phi[:, j] - fit[:, j]).max() / max(np.abs(phi[:, j]).max(), 1e-300))
        if dev > RIGID_TOL:
            raise refuse(f"a unit motion of SUPORT grid {g} component {c} (the others held) "
                         f"deforms the structure ({dev:.2g} of the motion) instead of moving it "
                         f"rigidly: the structure is held elsewhere in that direction (an SPC, a "
                         f"spring to ground, an MPC), or the SUPORT DOFs hold more than its "
                         f"rigid-body motions (not statically determinate). Inertia relief needs "
                         f"a free structure and a statically determinate r-set")
    phi = fit
    force = K @ phi
    kmax = float(np.abs(K).max())
    for j, (g, c) in enumerate(rset):
        rel = float(np.abs(force[:, j]).max() / (kmax * max(np.abs(phi[:, j]).max(), 1e-300)))
        if rel > ENERGY_TOL:
            raise refuse(f"moving the structure rigidly along SUPORT grid {g} component {c} meets "
                         f"stiffness ({rel:.2g} of the largest stiffness term): something holds "
                         f"the structure in that direction (a spring to ground, an SPC), so it is "
                         f"not free, as inertia relief needs")

    phi_g = A.T @ phi                              # every g DOF, dependent ones too (CD)
    M = mass_matrix(deck, masses, A.grid_ids)
    Dt = displacement_transform(deck, A.grid_ids)
    if Dt is not None:
        M = (Dt.T @ M @ Dt).tocsr()
    m_phi = M @ phi_g
    m_r = phi_g.T @ m_phi
    m_r = 0.5 * (m_r + m_r.T)
    eig = np.linalg.eigvalsh(m_r)
    if not eig.max() > 0.0 or eig.min() <= 1e-10 * eig.max():
        raise refuse("the model's mass gives some rigid-body motion of the r-set no inertia (the "
                     "rigid-body mass matrix is singular: no MAT1 RHO, NSM or CONM on it), so no "
                     "acceleration can balance a load along it")
    index = {lab: k for k, lab in enumerate(A.g_labels)}
    out, accel = [], []
    for loads in cases:
        P = np.zeros(len(A.g_labels))
        for dof, v in loads.items():
            P[index[dof]] += v
        a = np.linalg.solve(m_r, phi_g.T @ P)
        bal = P - m_phi @ a
        out.append({A.g_labels[k]: float(bal[k]) for k in np.flatnonzero(bal)})
        accel.append(a)
    return out, accel, float(eig.max())
