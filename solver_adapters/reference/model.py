"""Assembly, constraints and factorization of the reference frame model.

Elements: CBAR/CBEAM (Euler-Bernoulli or, with K1/K2, Timoshenko bending; pin flags; offsets) and
CROD/CONROD (axial + torsion), element matrices in ``frame.py``; CBUSH springs; CELAS springs.
Elements are assembled in basic; the g-set is in each grid's CD system (``u_basic = D u_cd``,
``K_gg = D^T K_basic D``), so SPCs, springs, loads and results are in CD components.
RBE3 rows (weighted least squares) and MPC equations (solved for their first component) are
eliminated like RBE2 rows; AUTOSPC (NASTRAN's SOL 101
default, off only with PARAM,AUTOSPC,NO) removes free components without stiffness
(:func:`autospc`) and lists them. It removes grid-point singularities only: a mechanism of the
structure (a rigid-body motion, a linkage) still fails the factorization with an error naming it.

``u_g = T u_f``: every grid component (g-set, 6 per grid) is a combination of the independent
free components (f-set). SPC1 and GRID PS components get a zero row; RBE2 dependent components
are exact rigid-body combinations of the independent grid's six components (no penalty):

    u_m = u_n + theta_n x (x_m - x_n),   theta_m = theta_n                      (rigid link)

The reduced stiffness ``K_ff = T^T K_gg T`` is factorized once and reused for every batch.

Scale (``docs/scale.md``, ``benchmarks/scale.py``): everything here is array work, no Python
loop over grids, DOFs or elements (only over cards that are few: RBE2, SPC1, PBAR), so the
assembly of a 1e6-DOF frame takes ~6 s and 2 GB. The factorization backends are SuperLU (SciPy,
always there) and MKL PARDISO (optional ``pypardiso``: at 1e6 DOFs on 2 cores 4-7x faster
factorization, 8-9x faster 100-RHS solve, less than half the memory); ``"auto"`` takes PARDISO
from :data:`AUTO_PARDISO_MIN_DOFS` free DOFs on.
"""

from __future__ import annotations

import ctypes
import threading
import time
import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from solver_adapters.deck import Deck
from solver_adapters.protocol import (DofLabel, FactorizationError, ModelError, ScalarSpring,
                                      UnstableStructureError)
from solver_adapters.reference import frame

PIVOT_RATIO = 1e-10
"""A pivot below this fraction of its DOF's diagonal stiffness marks a mechanism.

For an SPD matrix the LU pivot of DOF i equals K_ii minus what its coupling to DOFs eliminated
before it explains; a ratio near machine precision (1e-16) means the DOF is a linear
combination of the others, i.e. a mechanism. 1e-10 leaves six orders of margin for legitimately
soft springs (the smallest ratio seen on the fixtures with joint springs of 1 N*m/rad is ~1e-7).
The same test applies to PARDISO's pivots (the diagonal of D in L D L^T, or of L L^T squared).
"""

BACKENDS = ("auto", "superlu", "pardiso")

AUTO_PARDISO_MIN_DOFS = 20_000
"""``backend="auto"`` uses PARDISO from this many free DOFs on (when pypardiso is installed).

Measured on car-body-like tube frames (docs/scale.md): below ~2e4 DOFs both factorize and
solve 100 right-hand sides in a fraction of a second and PARDISO's one-off cost per process
(importing pypardiso and loading MKL, 0.5-1.5 s) cancels its advantage; at 1e5 DOFs PARDISO is
~8x faster to factorize and ~20x faster on the 100 solves (1 s instead of 11 s), at 1e6 DOFs
~22 s instead of ~170 s, with 5.8 instead of 13.8 GB.
"""

SUPERLU_ORDERING = "MMD_AT_PLUS_A"
"""SuperLU column ordering. Measured on the 1e4/1e5-DOF tube frames (docs/scale.md):
MMD_AT_PLUS_A (minimum degree on K + K^T, right for a symmetric matrix) gives the least fill and
the fastest factorization; COLAMD has ~2x the fill, NATURAL after reverse Cuthill-McKee ~6x."""

_CHUNK = 1 << 17   # elements per chunk of the element-stiffness computation (bounds temporaries)


@dataclass
class Assembled:
    """The assembled model: labels, the g-to-f map ``T`` and the reduced stiffness ``K_ff``."""
    grid_ids: np.ndarray            # sorted grid ids
    g_labels: list[DofLabel]        # 6 per grid, grid-major
    T: sp.csr_matrix                # (n_g, n_f)
    K_gg: sp.csr_matrix
    K_ff: sp.csc_matrix
    f_labels: list[DofLabel]
    autospc: list[DofLabel] = dataclasses.field(default_factory=list)   # constrained by AUTOSPC
    autospc_on: bool = True             # whether AUTOSPC ran (the deck's PARAM,AUTOSPC, default YES)
    free_rigid: tuple[str, list[DofLabel]] | None = None   # a rigid motion nothing holds (free_rigid_motion)

    def g_index(self, dofs) -> np.ndarray:
        pos = np.searchsorted(self.grid_ids, [d[0] for d in dofs])
        return 6 * pos + np.array([d[1] for d in dofs], dtype=int) - 1


def _grid_pos(grid_ids: np.ndarray, ids, what: str) -> np.ndarray:
    """Positions of grid ``ids`` in the sorted ``grid_ids``; ModelError naming a missing one."""
    ids = np.asarray(ids, dtype=np.int64)
    p = np.searchsorted(grid_ids, ids)
    p = np.minimum(p, max(len(grid_ids) - 1, 0))
    missing = np.flatnonzero(grid_ids[p] != ids) if len(grid_ids) else np.arange(ids.size)
    if missing.size:
        raise ModelError(f"{what} references grid {int(ids[missing[0]])}, which is not in the deck")
    return p


_N_PROPS = 9   # E, G, A, I1, I2, J, As1, As2 (shear areas K1*A, K2*A; inf: none), I12


def _element_arrays(deck: Deck, grid_ids: np.ndarray, xyz: np.ndarray):
    """Bars sorted by EID, then rods (CROD/CONROD) sorted by EID, with end positions,
    orientation vectors and section properties ``(ne, 9)`` (see ``_N_PROPS``).

    A rod is the frame element with I1 = I2 = 0 (axial EA/L and torsion GJ/L only); its
    orientation vector is the basic axis least aligned with it, which only fixes local y and z,
    on which a rod's stiffness does not depend.
    """
    bars = sorted(deck.cbars.values(), key=lambda b: b.eid)
    rods = sorted(deck.rods.values(), key=lambda r: r.eid)
    nb = len(bars)
    elems = bars + rods
    ne = len(elems)
    ia = _grid_pos(grid_ids, np.fromiter((b.ga for b in elems), np.int64, ne), "element")
    ib = _grid_pos(grid_ids, np.fromiter((b.gb for b in elems), np.int64, ne), "element")
    xa, xb = xyz[ia], xyz[ib]
    has_g0 = np.zeros(ne, bool)
    has_g0[:nb] = np.fromiter((b.g0 is not None for b in bars), bool, nb)
    v = np.zeros((ne, 3))
    v[:nb] = np.array([b.x if b.g0 is None else (0.0, 0.0, 0.0) for b in bars], float).reshape(-1, 3)
    if has_g0.any():
        g0 = _grid_pos(grid_ids, [bars[i].g0 for i in np.flatnonzero(has_g0)], "CBAR G0")
        v[has_g0] = xyz[g0] - xa[has_g0]
    if rods:
        d = np.abs(xb[nb:] - xa[nb:])
        v[np.arange(nb, ne), np.argmin(d, axis=1)] = 1.0
    pids = np.fromiter((b.pid for b in bars), np.int64, nb)
    table = {}
    for pid in np.unique(pids).tolist():
        p = deck.pbars[pid]
        m = deck.mat1s[p.mid]
        as1 = p.k1 * p.a if p.k1 else np.inf
        as2 = p.k2 * p.a if p.k2 else np.inf
        table[pid] = (m.e, m.g, p.a, p.i1, p.i2, p.j, as1, as2, p.i12)
    uniq = np.array(sorted(table), dtype=np.int64)
    props = np.empty((ne, _N_PROPS))
    bar_props = np.array([table[p] for p in uniq.tolist()], float).reshape(-1, _N_PROPS)
    props[:nb] = bar_props[np.searchsorted(uniq, pids)]
    for k, r in enumerate(rods):
        mid, a, j = deck.rod_section(r)
        m = deck.mat1s[mid]
        props[nb + k] = (m.e, m.g, a, 0.0, 0.0, j, np.inf, np.inf, 0.0)
    # pin flags as a bit mask of released local DOFs (bit i: DOF i, end A 0-5, end B 6-11)
    pins = np.zeros(ne, np.int64)
    offs = None
    nax = None                          # PBEAM neutral axis offsets (element y, z)
    for pid in [p for p in table if deck.pbars[p].n1 or deck.pbars[p].n2]:
        if nax is None:
            nax = np.zeros((ne, 2))
        nax[:nb][pids == pid] = (deck.pbars[pid].n1, deck.pbars[pid].n2)
    taper = None                        # tapered PBEAMs: element index -> (end A, end B) sections
    for pid in [p for p in table if deck.pbars[p].taper is not None]:
        pb = deck.pbars[pid]
        taper = taper or {}
        for k in np.flatnonzero(pids == pid).tolist():
            taper[k] = ((pb.a, pb.i1, pb.i2, pb.j), pb.taper, pb.k1, pb.k2)
    for k, b in enumerate(bars):
        if b.pa or b.pb:
            pins[k] = sum(1 << (int(ch) - 1) for ch in b.pa) + sum(1 << (int(ch) + 5) for ch in b.pb)
        if b.wa is not None or b.wb is not None:
            if offs is None:
                offs = np.zeros((ne, 6))
            offs[k] = (*(b.wa or (0.0, 0.0, 0.0)), *(b.wb or (0.0, 0.0, 0.0)))
    return elems, ia, ib, xa, xb, v, props, pins, offs, nax, taper


def _pins_and_offsets(kl: np.ndarray, kg_of, s: int, pins: np.ndarray, offs, elems,
                      nax: np.ndarray | None = None) -> np.ndarray:
    """Chunk ``s:s+m`` of the element stiffnesses: a PBEAM's neutral axis offset applied to the
    local matrices ``kl`` (entry-major), pin flags condensed out of them, then the global
    matrices ``kg_of(kl)`` moved to the grids by the rigid offsets. Only elements with a neutral
    axis offset, pins or offsets are touched (others stay bit for bit as they were)."""
    m = kl.shape[2]
    if nax is not None:
        idx = np.flatnonzero(np.any(nax[s:s + m] != 0.0, axis=1))
        if idx.size:
            kl[:, :, idx] = frame.neutral_axis(kl[:, :, idx].transpose(2, 0, 1),
                                               nax[s + idx]).transpose(1, 2, 0)
    chunk_pins = pins[s:s + m]
    for mask in np.unique(chunk_pins[chunk_pins != 0]).tolist():
        idx = np.flatnonzero(chunk_pins == mask)
        released = [i for i in range(12) if mask >> i & 1]
        try:
            kl[:, :, idx] = frame.release_pins(kl[:, :, idx].transpose(2, 0, 1), released).transpose(1, 2, 0)
        except ValueError as exc:
            b = elems[s + int(idx[int(exc.args[0][0])])]
            raise ModelError(f"{b.src}: CBAR {b.eid}: pin flags PA={b.pa or 'blank'} "
                             f"PB={b.pb or 'blank'} leave the bar a rigid-body motion (e.g. the "
                             f"same axial, torsion or transverse component released at both "
                             f"ends)") from None
    kg = kg_of(kl)
    if offs is not None:
        idx = np.flatnonzero(np.any(offs[s:s + m] != 0.0, axis=1))
        if idx.size:
            w = offs[s + idx]
            kg[:, :, idx] = frame.offset_transform(kg[:, :, idx].transpose(2, 0, 1),
                                                   w[:, :3], w[:, 3:]).transpose(1, 2, 0)
    return kg


def _assemble_bars(ia: np.ndarray, ib: np.ndarray, R: np.ndarray, L: np.ndarray,
                   props: np.ndarray, n_grids: int, pins: np.ndarray | None = None,
                   offs: np.ndarray | None = None, elems=None,
                   nax: np.ndarray | None = None, taper: dict | None = None) -> sp.csr_matrix:
    """Sum of the bars' global stiffness matrices, assembled by 6x6 grid blocks.

    ``pins`` (bit masks of released local DOFs) and ``offs`` (WA, WB per element, ``(ne, 6)``)
    are applied by :func:`_pins_and_offsets`; ``elems`` names the element in errors. ``taper``
    (element index -> end A and end B sections, K1, K2): tapered beams, whose local matrices
    replace the prismatic ones (:func:`frame.tapered_local_stiffness`).

    Each bar adds four 6x6 blocks (aa, bb, ab, ba). The distinct grid pairs (the block pattern)
    come from one ``np.unique`` over 4 * n_bars keys, the block sums from one sparse product
    (pattern x contributions), then BSR -> CSR: about 4x faster and half the memory of a
    scalar COO -> CSR conversion of 144 entries per bar.
    """
    ne = ia.size
    blocks = np.empty((4, ne, 6, 6))
    for s in range(0, ne, _CHUNK):
        e = slice(s, s + _CHUNK)
        kl = frame.local_stiffness_em(L[e], *props[e].T)
        for k in [k for k in taper or () if s <= k < s + _CHUNK]:
            end_a, end_b, k1, k2 = taper[k]
            kl[:, :, k - s] = frame.tapered_local_stiffness(float(L[k]), float(props[k, 0]), float(props[k, 1]),
                                                            end_a, end_b, k1, k2)
        if (pins is not None and pins[e].any()) or (offs is not None and offs[e].any()) or \
                (nax is not None and nax[e].any()):
            kg = _pins_and_offsets(kl, lambda k: frame.global_stiffness_em(R[e], k), s, pins,
                                   offs, elems, nax)
        else:
            kg = frame.global_stiffness_em(R[e], kl)
        m = kg.shape[2]
        for q, (r0, c0) in enumerate(((0, 0), (6, 6), (0, 6), (6, 0))):
            blocks[q, s:s + m] = kg[r0:r0 + 6, c0:c0 + 6].transpose(2, 0, 1)
        del kg
    key = np.concatenate([ia * n_grids + ia, ib * n_grids + ib, ia * n_grids + ib, ib * n_grids + ia])
    ukey, inv = np.unique(key, return_inverse=True)
    nb = ukey.size
    summer = sp.csr_matrix((np.ones(4 * ne), (inv.ravel(), np.arange(4 * ne))), shape=(nb, 4 * ne))
    data = (summer @ blocks.reshape(4 * ne, 36)).reshape(nb, 6, 6)
    del blocks, summer
    brow, bcol = np.divmod(ukey, n_grids)
    indptr = np.zeros(n_grids + 1, np.int64)
    np.cumsum(np.bincount(brow, minlength=n_grids), out=indptr[1:])
    idx_t = np.int32 if 6 * n_grids < 2**31 - 1 and 36 * nb < 2**31 - 1 else np.int64
    K = sp.bsr_matrix((data, bcol.astype(idx_t), indptr.astype(idx_t)),
                      shape=(6 * n_grids, 6 * n_grids)).tocsr()
    K.eliminate_zeros()
    return K


def assemble(deck: Deck, extra_springs: tuple[ScalarSpring, ...] = (),
             timings: dict | None = None) -> Assembled:
    """Vectorized sparse assembly of bars and springs, then constraint elimination.

    ``timings`` (optional dict) receives the wall time of each phase in seconds.
    """
    tm = timings if timings is not None else {}
    t0 = time.perf_counter()
    grid_ids = np.array(sorted(deck.grids), dtype=np.int64)
    n_g = 6 * len(grid_ids)
    xyz = np.array([deck.grids[g].xyz for g in grid_ids.tolist()], float).reshape(-1, 3)
    bars, ia, ib, xa, xb, v, props, pins, offs, nax, taper = _element_arrays(deck, grid_ids, xyz)
    tm["elements_read_s"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    K_gg = sp.csr_matrix((n_g, n_g))
    if bars:
        try:
            if offs is None:
                R, L = frame.rotation_matrices(xa, xb, v)
            else:                     # the bar runs between its ends, v stays measured from GA
                R, L = frame.rotation_matrices(xa + offs[:, :3], xb + offs[:, 3:], v)
        except ValueError as exc:
            b = bars[int(exc.args[0][0])]
            raise ModelError(f"{b.src}: {getattr(b, 'card', 'CBAR')} {b.eid}: orientation vector "
                             f"is parallel to the bar axis GA={b.ga} -> GB={b.gb}") from None
        if np.any(L <= 0):
            b = bars[int(np.flatnonzero(L <= 0)[0])]
            raise ModelError(f"{b.src}: {getattr(b, 'card', 'CBAR')} {b.eid}: zero length "
                             f"(GA={b.ga}, GB={b.gb} coincide)")
        K_gg = _assemble_bars(ia, ib, R, L, props, len(grid_ids), pins, offs, bars, nax, taper)
    if deck.bushes:
        K_gg = (K_gg + bush_stiffness(deck, grid_ids, xyz)).tocsr()
    if getattr(deck, "gaps", None):
        K_gg = (K_gg + gap_stiffness(deck, grid_ids, xyz)).tocsr()
    D = displacement_transform(deck, grid_ids)
    if D is not None:                 # elements are in basic, the g-set in each grid's CD
        K_gg = (D.T @ K_gg @ D).tocsr()
    tm["elements_s"] = time.perf_counter() - t1

    t1 = time.perf_counter()
    springs = [(s.g1, s.c1, s.g2, s.c2, deck.spring_stiffness(s)) for s in deck.springs.values()]
    springs += [(s.a[0], s.a[1], s.b[0] if s.b else 0, s.b[1] if s.b else 0, s.k) for s in extra_springs]
    if springs:
        g1, c1, g2, c2 = (np.array([s[i] for s in springs], dtype=np.int64) for i in range(4))
        k = np.array([s[4] for s in springs], float)
        ends = np.column_stack([g1, g2]).ravel()          # g1, g2 of each spring, in order
        _grid_pos(grid_ids, ends[ends != 0], "spring")
        a = 6 * _grid_pos(grid_ids, g1, "spring") + c1 - 1
        two = g2 != 0
        b = 6 * _grid_pos(grid_ids, g2[two], "spring") + c2[two] - 1
        at, kt = a[two], k[two]
        K_s = sp.coo_matrix((np.concatenate([kt, kt, -kt, -kt, k[~two]]),
                             (np.concatenate([at, b, at, b, a[~two]]),
                              np.concatenate([at, b, b, at, a[~two]]))), shape=(n_g, n_g))
        K_gg = (K_gg + K_s.tocsr()).tocsr()
    if deck.dmigs:
        K_gg = (K_gg + dmig_stiffness(deck, grid_ids)).tocsr()
    tm["springs_s"] = time.perf_counter() - t1

    t1 = time.perf_counter()
    T, f_index = constraint_map(deck, grid_ids, D=D)
    tm["constraint_map_s"] = time.perf_counter() - t1

    t1 = time.perf_counter()
    K_ff = (T.T.tocsr() @ K_gg @ T).tocsr()
    K_ff = ((K_ff + K_ff.T) * 0.5).tocsc()       # exact symmetry despite round-off in T^T K T
    K_ff.sort_indices()
    tm["reduce_s"] = time.perf_counter() - t1

    t1 = time.perf_counter()
    scalar = np.fromiter((bool(getattr(deck.grids[g], "scalar", False)) for g in grid_ids.tolist()), bool,
                         len(grid_ids))
    free_rigid = free_rigid_motion(xyz, scalar, grid_ids, D, T, K_ff)
    tm["rigid_motion_s"] = time.perf_counter() - t1

    removed: np.ndarray = np.zeros(0, np.int64)
    if deck.autospc:
        t1 = time.perf_counter()
        keep, removed = autospc(K_ff, f_index, deck.epzero)
        if removed.size:
            T = T[:, keep].tocsr()
            K_ff = K_ff[keep][:, keep].tocsc()
            K_ff.sort_indices()
            f_index = f_index[keep]
        tm["autospc_s"] = time.perf_counter() - t1

    t1 = time.perf_counter()
    g_labels = list(zip(np.repeat(grid_ids, 6).tolist(),
                        np.tile(np.arange(1, 7), len(grid_ids)).tolist()))
    f_labels = [g_labels[i] for i in f_index.tolist()]
    auto_labels = [g_labels[i] for i in removed.tolist()]
    tm["labels_s"] = time.perf_counter() - t1
    tm["assemble_s"] = time.perf_counter() - t0
    return Assembled(grid_ids, g_labels, T, K_gg, K_ff, f_labels, auto_labels, bool(deck.autospc), free_rigid)


RIGID_ADMISSIBLE = 1e-12
"""A rigid motion whose squared misfit to what the constraints allow is below this fraction of
its own squared norm is one the constraints allow (a support tilted by 1e-6 rad already holds it)."""
RIGID_ENERGY = 1e-10
"""An allowed rigid motion whose strain energy is below this fraction of the structure's typical
stiffness times its squared translation is held by nothing (measured: rounding leaves 5e-18 on a
bus frame free to roll about the line of its vertical supports; the fixtures' held frames keep
6.6e-4 or more)."""


def free_rigid_motion(xyz: np.ndarray, scalar: np.ndarray, grid_ids: np.ndarray, D: sp.spmatrix | None,
                      T: sp.spmatrix, K_ff: sp.spmatrix) -> tuple[str, list[DofLabel]] | None:
    """A rigid-body motion of the whole structure that the supports, rigid elements, springs and
    elements leave without stiffness, described, with the components that move most; None when
    every rigid motion is held.

    The factorization's pivot test sees a mechanism as a pivot that is zero up to rounding, and
    rounding decides whether it is: a support whose components point, in its grid's CD system,
    along the motion it should stop (a vertical restraint turned horizontal by a CORD1R) leaves
    the structure free to roll with pivots of 1e-10 of their diagonal, next to the 1e-10 the test
    uses, and the solve then returns metres for newtons. This test is exact instead: the six
    rigid motions (in basic, turned into each grid's CD; scalar points held) are fitted by what
    ``T`` allows (least squares), those fitted to rounding are allowed, and among them the one of
    least strain energy ``u^T K_ff u`` is free when that energy is below :data:`RIGID_ENERGY` of
    the median translational stiffness times ``|u|^2``."""
    n = len(grid_ids)
    if n == 0 or T.shape[1] == 0:
        return None
    c = xyz.mean(axis=0)
    L = max(float(np.ptp(xyz, axis=0).max()), 1e-30)
    r = (xyz - c) / L
    R = np.zeros((6 * n, 6))
    rows = np.arange(n) * 6
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        R[rows + k, k] = 1.0
        R[rows + 3 + k, 3 + k] = 1.0 / L            # a rotation of 1/L: translations of order 1
        cr = np.cross(e, r)
        for j in range(3):
            R[rows + j, 3 + k] = cr[:, j]
    R[np.repeat(scalar, 6)] = 0.0
    if D is not None:
        R = np.asarray(D.T @ R)
    Tc = T.tocsc()
    try:
        U = spla.splu((Tc.T @ Tc).tocsc()).solve(np.asarray(Tc.T @ R))
    except RuntimeError:              # T without full column rank: the pivot test decides
        return None
    miss = np.asarray(Tc @ U) - R
    G = R.T @ R
    if np.linalg.eigvalsh(G).min() <= 0.0:
        return None
    E = miss.T @ miss
    w, V = sla.eigh((E + E.T) / 2, G)
    V = V[:, w < RIGID_ADMISSIBLE]
    if not V.shape[1]:
        return None
    Uv = U @ V
    A = Uv.T @ (K_ff @ Uv)
    A = (A + A.T) / 2
    diag = K_ff.diagonal()
    trans = np.zeros(T.shape[0], bool)
    trans[(np.arange(T.shape[0]) % 6) < 3] = True
    Ug = np.asarray(Tc @ Uv)
    k_typ = np.median(np.abs(diag)) if diag.size else 0.0
    B = Ug[trans].T @ Ug[trans]
    if k_typ <= 0.0 or np.linalg.eigvalsh(B).min() <= 0.0:
        return None
    lam, a = sla.eigh(A / k_typ, B)
    if lam[0] >= RIGID_ENERGY:
        return None
    mode = V @ a[:, 0]
    t, th = mode[:3], mode[3:] / L
    if np.linalg.norm(th) * L > 1e-6 * np.linalg.norm(t):
        axis = th / np.linalg.norm(th)
        axis = axis if axis[np.argmax(np.abs(axis))] > 0 else -axis
        p = c + np.cross(th, t) / (th @ th)     # the point of the axis nearest the centroid
        what = (f"a rotation about the axis along ({axis[0]:.3g}, {axis[1]:.3g}, {axis[2]:.3g}) through "
                f"({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) (basic)")
    else:
        axis = t / np.linalg.norm(t)
        axis = axis if axis[np.argmax(np.abs(axis))] > 0 else -axis
        what = f"a translation along ({axis[0]:.3g}, {axis[1]:.3g}, {axis[2]:.3g}) (basic)"
    amp = np.abs(Ug @ a[:, 0])
    amp[~trans] = 0.0
    top = np.argsort(-amp)[:12]
    labels = [(int(grid_ids[i // 6]), int(i % 6) + 1) for i in top if amp[i] > 0.2 * amp[top[0]]]
    return what, labels


def dmig_stiffness(deck: Deck, grid_ids: np.ndarray) -> sp.csr_matrix:
    """The DMIG matrices (K2GG) in the g-set, times PARAM,CK2: a symmetric matrix's (IFO 6)
    off-diagonal term stands for its mirror too (MSC QRG DMIG); and the GENEL elements'
    stiffness matrices, which CK2 does not scale."""
    rows, cols, vals = [], [], []
    for m in deck.dmigs.values():
        scale = 1.0 if m.card == "GENEL" else deck.ck2
        for (gi, ci), (gj, cj), a in m.terms:
            rows.append((gi, ci))
            cols.append((gj, cj))
            vals.append(scale * a)
            if m.ifo == 6 and (gi, ci) != (gj, cj):
                rows.append((gj, cj))
                cols.append((gi, ci))
                vals.append(scale * a)
    n_g = 6 * len(grid_ids)
    if not vals:
        return sp.csr_matrix((n_g, n_g))
    r = np.array(rows, dtype=np.int64)
    c = np.array(cols, dtype=np.int64)
    i = 6 * _grid_pos(grid_ids, r[:, 0], "DMIG") + r[:, 1] - 1
    j = 6 * _grid_pos(grid_ids, c[:, 0], "DMIG") + c[:, 1] - 1
    return sp.coo_matrix((np.array(vals, float), (i, j)), shape=(n_g, n_g)).tocsr()


def autospc(K_ff: sp.spmatrix, f_index: np.ndarray, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """NASTRAN's grid-point singularity processing (AUTOSPC): ``(keep, removed)``,
    positions in the f-set to keep and the g-indices of the components it constrains.

    For every grid, the 3x3 blocks of K_ff of its free translations and of its free rotations
    (after SPCs and rigid elements) are decomposed; an eigenvalue below ``ratio`` (PARAM,EPZERO,
    1e-8 by default) times the block's largest is a direction without stiffness, and the free
    component most aligned with it is constrained (all free components of a block without any
    stiffness). Components that are not free do not take part (their rows are decoupled)."""
    gi = np.asarray(f_index)
    group = (gi // 6) * 2 + (gi % 6 >= 3)              # (grid, translation/rotation)
    ugroup, ginv = np.unique(group, return_inverse=True)
    ginv = ginv.ravel()
    local = gi % 3
    K = sp.coo_matrix(K_ff)
    same = ginv[K.row] == ginv[K.col]
    B = np.zeros((ugroup.size, 3, 3))
    np.add.at(B, (ginv[K.row[same]], local[K.row[same]], local[K.col[same]]), K.data[same])
    free = np.zeros((ugroup.size, 3), bool)
    free[ginv, local] = True
    # a component that is not free gets the block's largest free diagonal: decoupled, and
    # neither the largest eigenvalue nor a singular direction
    dmax = np.where(free, np.einsum("gii->gi", B), 0.0).max(axis=1)
    for i in range(3):
        B[:, i, i] += np.where(free[:, i], 0.0, dmax)
    B = 0.5 * (B + B.transpose(0, 2, 1))
    lam, vec = np.linalg.eigh(B)
    lmax = lam.max(axis=1)
    drop = np.zeros((ugroup.size, 3), bool)
    for g in np.flatnonzero(lam.min(axis=1) <= ratio * np.maximum(lmax, 0.0)).tolist():
        if lmax[g] <= 0.0:
            drop[g] = free[g]
            continue
        for j in np.flatnonzero(lam[g] <= ratio * lmax[g]).tolist():
            w = np.abs(vec[g][:, j]) * free[g] * ~drop[g]
            if w.max() > 0.0:
                drop[g, int(np.argmax(w))] = True
    removed_pos = np.flatnonzero(drop[ginv, local])
    keep = np.setdiff1d(np.arange(gi.size), removed_pos)
    return keep, gi[removed_pos]


def _skew(r: np.ndarray) -> np.ndarray:
    """``S(r)`` with ``S(r) a = r x a``."""
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def bush_stiffness(deck: Deck, grid_ids: np.ndarray, xyz: np.ndarray) -> sp.csr_matrix:
    """Sum of the CBUSH stiffnesses in basic (MSC QRG CBUSH/PBUSH): six uncoupled springs
    K1..K6 along the element axes at the spring point p = x_A + S (x_B - x_A) (with OCID >= 0:
    x_A plus the offset S1-S3 in OCID's axes at GA), reached from
    each grid by a rigid link (u_p = u_g + theta_g x (p - x_g)), so that a bush of non-zero
    length carries moments consistently: K = C^T diag(K) C, C = [-E T_A, E T_B] with E the
    element axes (twice: translations and rotations) and T_g the rigid links. GB = 0: the
    springs go to ground at p = x_A. Element axes: CID's (a cylindrical or spherical CID's
    axes at GA), else x along GA -> GB and the orientation vector in the x-y plane (no
    orientation: K1 and K4 only)."""
    n_g = 6 * len(grid_ids)
    rows, cols, vals = [], [], []
    for b in sorted(deck.bushes.values(), key=lambda e: e.eid):
        where = f"{b.src}: CBUSH {b.eid}"
        ia = int(_grid_pos(grid_ids, [b.ga], where)[0])
        xa = xyz[ia]
        ib = int(_grid_pos(grid_ids, [b.gb], where)[0]) if b.gb else None
        xb = xyz[ib] if ib is not None else xa
        if b.cid is not None:
            E = np.eye(3) if b.cid == 0 else deck.coords[b.cid].frames_at(xa[None, :])[0]
        else:
            ex = xb - xa
            if b.g0 is None and b.x is None:
                # no orientation and no CID: x along GA -> GB, valid only for a bush with
                # axial and torsional stiffness alone (K1, K4; MSC QRG CBUSH remark 4), whose
                # y and z axes are then of no consequence
                k = deck.pbushes[b.pid].k
                if any(k[i] != 0.0 for i in (1, 2, 4, 5)) or not np.linalg.norm(ex) > 0.0:
                    raise ModelError(f"{where}: without an orientation vector (GO or X) or CID, "
                                     f"a CBUSH between two distinct grids may have K1 and K4 "
                                     f"only (its y and z axes are undefined)")
                v = np.eye(3)[int(np.argmin(np.abs(ex)))]
            elif b.g0 is not None:
                v = xyz[int(_grid_pos(grid_ids, [b.g0], where)[0])] - xa
            else:
                v = deck.displacement_frames([b.ga])[0].T @ np.array(b.x)
            ez = np.cross(ex, v)
            if not np.linalg.norm(ez) > 1e-9 * np.linalg.norm(ex) * np.linalg.norm(v):
                raise ModelError(f"{where}: orientation vector is parallel to GA -> GB (or zero)")
            ex = ex / np.linalg.norm(ex)
            ez = ez / np.linalg.norm(ez)
            E = np.array([ex, np.cross(ez, ex), ez])
        if b.offset is None:
            p = xa + b.s * (xb - xa)
        else:                         # GA plus the offset in OCID's axes at GA
            F = np.eye(3) if b.ocid == 0 else deck.coords[b.ocid].frames_at(xa[None, :])[0]
            p = xa + F.T @ np.asarray(b.offset, float)
        R = np.kron(np.eye(2), E)
        ends = [(ia, xa, -1.0)] + ([(ib, xb, 1.0)] if ib is not None else [])
        C = np.zeros((6, 6 * len(ends)))
        for k, (_, x, sign) in enumerate(ends):
            T = np.eye(6)
            T[:3, 3:] = -_skew(p - x)
            C[:, 6 * k:6 * k + 6] = sign * R @ T
        K = C.T @ (np.array(deck.pbushes[b.pid].k)[:, None] * C)
        idx = np.concatenate([6 * g + np.arange(6) for g, _, _ in ends])
        rows.append(np.repeat(idx, idx.size))
        cols.append(np.tile(idx, idx.size))
        vals.append(0.5 * (K + K.T).ravel())
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n_g, n_g))


def gap_stiffness(deck: Deck, grid_ids: np.ndarray, xyz: np.ndarray) -> sp.csr_matrix:
    """Sum of the CGAP stiffnesses in basic, as a linear solution has them (MSC QRG CGAP remark
    1: linear with the stiffness of the gap's initial state, :meth:`PGap.linear`): between the
    translations of GA and GB, the axial stiffness along the gap axis e (GA -> GB, or CID's T1
    direction at GA) and the transverse one across it, K = ka e e^T + kt (I - e e^T) (the same
    in y and z, so the orientation vector has no effect); no rotational stiffness."""
    n_g = 6 * len(grid_ids)
    rows, cols, vals = [], [], []
    for e in sorted(deck.gaps.values(), key=lambda g: g.eid):
        where = f"{e.src}: CGAP {e.eid}"
        ia, ib = (int(i) for i in _grid_pos(grid_ids, [e.ga, e.gb], where))
        if e.cid is not None:
            axis = np.eye(3)[0] if e.cid == 0 else deck.coords[e.cid].frames_at(xyz[ia][None, :])[0][0]
        else:
            axis = xyz[ib] - xyz[ia]
            axis = axis / np.linalg.norm(axis)
        ka, kt = deck.pgaps[e.pid].linear()
        K3 = ka * np.outer(axis, axis) + kt * (np.eye(3) - np.outer(axis, axis))
        K = np.block([[K3, -K3], [-K3, K3]])
        idx = np.concatenate([6 * ia + np.arange(3), 6 * ib + np.arange(3)])
        rows.append(np.repeat(idx, 6))
        cols.append(np.tile(idx, 6))
        vals.append(K.ravel())
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n_g, n_g))


def displacement_transform(deck: Deck, grid_ids: np.ndarray) -> sp.csr_matrix | None:
    """``D`` (n_g x n_g) with ``u_basic = D u_cd``: per grid ``blockdiag(F^T, F^T)``, F the
    rows of the grid's CD axes in basic (``Deck.displacement_frames``). ``None`` when every CD
    is 0 (the identity, left out so that such models stay bit for bit as they were)."""
    if not any(g.cd for g in deck.grids.values()):
        return None
    try:
        F = deck.displacement_frames(grid_ids.tolist())
    except ValueError as exc:
        raise ModelError(f"{deck.grids[exc.args[1]].src}: GRID {exc.args[1]}: {exc.args[0]}") from None
    n = len(grid_ids)
    blocks = np.zeros((n, 6, 6))
    blocks[:, :3, :3] = F.transpose(0, 2, 1)
    blocks[:, 3:, 3:] = F.transpose(0, 2, 1)
    D = sp.bsr_matrix((blocks, np.arange(n), np.arange(n + 1)), shape=(6 * n, 6 * n)).tocsr()
    D.eliminate_zeros()
    return D


def constraint_map(deck: Deck, grid_ids: np.ndarray, pos: dict[int, int] | None = None,
                   D: sp.csr_matrix | None = None):
    """``T`` (n_g x n_f) and the g-index of each f column. See the module docstring.

    ``D`` (``u_basic = D u_cd``, from :func:`displacement_transform`): the g-set components are
    in each grid's CD system; SPC components are too, and an RBE2's CM components are those of
    the dependent grid's CD (as in NASTRAN). The rigid link holds in basic, so its rows become
    rows of ``D_m^T A D_n`` (A the basic rigid-link matrix).

    Array work throughout: SPC/PS and RBE2 dependent components are marked by index arrays; the
    RBE2 rows form a sparse ``W`` (dependent g-component -> independent g-components), and
    ``T = (I + W + W^2 + ...) S`` with ``S`` the selection of the free components: one sparse
    product per level of RBE2 chaining (RBE2s whose independent grid is another's dependent).
    ``pos`` (grid id -> position) is accepted for compatibility and not needed.
    """
    grid_ids = np.asarray(grid_ids, dtype=np.int64)
    n_g = 6 * len(grid_ids)
    fixed = np.zeros(n_g, bool)
    ps = [(g.id, g.ps) for g in deck.grids.values() if g.ps]
    for comps in {c for _, c in ps}:
        p = _grid_pos(grid_ids, [gid for gid, c in ps if c == comps], "GRID PS")
        fixed[(6 * p[:, None] + np.array([int(c) - 1 for c in comps])).ravel()] = True
    for s in deck.spc1s:
        p = _grid_pos(grid_ids, list(s.grids), f"{s.src}: {s.card}" + (f" {s.sid}" if s.card == "SPC1" else ""))
        comps = np.array([int(c) - 1 for c in s.components], dtype=np.int64)
        fixed[(6 * p[:, None] + comps).ravel()] = True

    # RBE2 dependent components, in EID order (the order in which conflicts are reported)
    rbe2s = sorted(deck.rbe2s.values(), key=lambda r: r.eid)
    d_idx, d_gn, d_rbe = [], [], []
    for k, r in enumerate(rbe2s):
        gm = _grid_pos(grid_ids, list(r.gm), f"{r.src}: {r.card} {r.eid}")
        gn = _grid_pos(grid_ids, [r.gn], f"{r.src}: {r.card} {r.eid}")[0]
        comps = np.array([int(c) - 1 for c in r.cm], dtype=np.int64)
        i = (6 * gm[:, None] + comps).ravel()              # grid-major, component order of CM
        d_idx.append(i)
        d_gn.append(np.full(i.size, gn, dtype=np.int64))
        d_rbe.append(np.full(i.size, k, dtype=np.int64))
    dep2 = np.concatenate(d_idx) if d_idx else np.zeros(0, np.int64)
    dep_gn = np.concatenate(d_gn) if d_gn else np.zeros(0, np.int64)
    dep_rbe2 = np.concatenate(d_rbe) if d_rbe else np.zeros(0, np.int64)
    rbe3s = sorted(deck.rbe3s.values(), key=lambda r: r.eid)
    dep3, dep_rbe3, W3 = _rbe3_rows(deck, grid_ids, rbe3s, len(rbe2s))
    mpcs = list(getattr(deck, "mpcs", ()))
    depm, dep_mpc, WM = _mpc_rows(grid_ids, mpcs, len(rbe2s) + len(rbe3s))
    W3 = W3 + WM
    rigid = rbe2s + rbe3s + mpcs
    dep = np.concatenate([dep2, dep3, depm])
    dep_rbe = np.concatenate([dep_rbe2, dep_rbe3, dep_mpc])
    if dep.size:
        _check_dependents(dep, dep_rbe, fixed, rigid, grid_ids)

    is_dep = np.zeros(n_g, bool)
    is_dep[dep] = True
    f_index = np.flatnonzero(~fixed & ~is_dep)
    n_f = f_index.size
    S = sp.csr_matrix((np.ones(n_f), (f_index, np.arange(n_f))), shape=(n_g, n_f))
    if not dep.size:
        return S, f_index

    W = W3
    if dep2.size:
        W = (_rigid_links(deck, grid_ids, dep2, dep_gn, dep_rbe2, D) + W3).tocsr()
    # chains: dependent -> dependent edges must not loop
    Wdd = W[:, dep].tocsr()[dep]
    if Wdd.nnz:
        n_comp, label = connected_components(Wdd, directed=True, connection="strong")
        sizes = np.bincount(label, minlength=n_comp)
        looped = np.flatnonzero(sizes[label] > 1)
        if looped.size:
            els = sorted({(rigid[int(k)].eid, getattr(rigid[int(k)], "card", "RBE2"))
                          for k in dep_rbe[looped]})
            raise ModelError(f"{els[0][1]} {els[0][0]}: circular dependency between rigid "
                             f"elements {', '.join(f'{c} {e}' for e, c in els[:20])}")
    T = S.copy()
    term = S
    for _ in range(dep.size + 1):
        term = (W @ term).tocsr()
        term.eliminate_zeros()
        if term.nnz == 0:
            break
        T = T + term
    T = T.tocsr()
    T.sum_duplicates()
    T.eliminate_zeros()
    return T, f_index


def _rigid_links(deck: Deck, grid_ids: np.ndarray, dep: np.ndarray, dep_gn: np.ndarray,
                 dep_rbe: np.ndarray, D: sp.csr_matrix | None) -> sp.csr_matrix:
    """``W`` (n_g x n_g): ``u[dep] = sum W[dep, j] u[j]`` over the independent grid's components.

    Without coordinate systems the rows are those of the rigid link in basic. With them, every
    (RBE2, dependent grid) gets its six basic rows ``A``, transformed to ``D_m^T A D_n``, and the
    rows of the CM components are kept."""
    n_g = 6 * len(grid_ids)
    if D is None:
        rows, gn, comp = dep, dep_gn, dep % 6
        out_rows = dep
    else:
        key = dep_rbe * len(grid_ids) + dep // 6
        ukey, inst = np.unique(key, return_inverse=True)
        inst = inst.ravel()
        first = np.zeros(ukey.size, np.int64)
        first[inst[::-1]] = np.arange(dep.size)[::-1]      # one dependent entry per instance
        m_pos, n_pos = dep[first] // 6, dep_gn[first]
        rows = (6 * np.arange(ukey.size)[:, None] + np.arange(6)).ravel()
        gn = np.repeat(n_pos, 6)
        comp = np.tile(np.arange(6), ukey.size)
        rows_m = np.repeat(m_pos, 6)
    c = comp
    n0 = 6 * gn
    grid_of_row = dep // 6 if D is None else rows_m
    r = _xyz(deck, grid_ids, grid_of_row) - _xyz(deck, grid_ids, gn)     # x_m - x_n
    w_rows, w_cols, w_vals = [rows], [n0 + c], [np.ones(rows.size)]
    # translations: u_m = u_n + theta_n x r  (x: +th_y r_z - th_z r_y; y: +th_z r_x - th_x r_z;
    # z: +th_x r_y - th_y r_x)
    cross = {0: ((4, 2, 1.0), (5, 1, -1.0)),
             1: ((5, 0, 1.0), (3, 2, -1.0)),
             2: ((3, 1, 1.0), (4, 0, -1.0))}
    for cc, terms in cross.items():
        sel = np.flatnonzero(c == cc)
        for rot, axis, sign in terms:
            w = sign * r[sel, axis]
            keep = w != 0.0
            w_rows.append(rows[sel][keep]); w_cols.append(n0[sel][keep] + rot); w_vals.append(w[keep])
    n_rows = n_g if D is None else rows.size
    W = sp.csr_matrix((np.concatenate(w_vals), (np.concatenate(w_rows), np.concatenate(w_cols))),
                      shape=(n_rows, n_g))
    if D is None:
        return W
    P = sp.csr_matrix((np.ones(rows.size), (rows, 6 * rows_m + comp)), shape=(rows.size, n_g))
    Dm = (P @ D @ P.T).tocsr()                       # blockdiag of each instance's D_m
    Wc = (Dm.T @ W @ D).tocsr()
    pick = sp.csr_matrix((np.ones(dep.size), (dep, 6 * inst + dep % 6)), shape=(n_g, rows.size))
    W = (pick @ Wc).tocsr()
    W.eliminate_zeros()
    return W


def _xyz(deck: Deck, grid_ids: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Coordinates ``(len(positions), 3)`` of the grids at ``positions`` in ``grid_ids``."""
    uniq, inv = np.unique(positions, return_inverse=True)
    xyz = np.array([deck.grids[g].xyz for g in grid_ids[uniq].tolist()], float).reshape(-1, 3)
    return xyz[inv.ravel()]


def _check_dependents(dep, dep_rbe, fixed, rigid, grid_ids) -> None:
    """ModelError for the first (RBE2s in EID order, then RBE3s) component that is dependent
    twice or also constrained by an SPC. ``rigid``: the elements indexed by ``dep_rbe``."""
    order = np.argsort(dep, kind="stable")
    s = dep[order]
    again = np.zeros(dep.size, bool)
    again[order[1:][s[1:] == s[:-1]]] = True          # every occurrence after the first
    spc = fixed[dep]
    bad = np.flatnonzero(again | spc)
    if not bad.size:
        return
    k = int(bad[0])
    r = rigid[int(dep_rbe[k])]
    name = getattr(r, "card", "RBE2")
    gm, comp = int(grid_ids[dep[k] // 6]), int(dep[k] % 6) + 1
    if again[k]:
        first = rigid[int(dep_rbe[int(np.flatnonzero(dep == dep[k])[0])])]
        raise ModelError(f"{r.src}: {name} {r.eid}: grid {gm} component {comp} is already "
                         f"dependent on {getattr(first, 'card', 'RBE2')} {first.eid}")
    raise ModelError(f"{r.src}: {name} {r.eid}: dependent grid {gm} component {comp} "
                     f"is also constrained by an SPC; constrain the independent grid instead")


def _mpc_rows(grid_ids: np.ndarray, mpcs, first_index: int):
    """Dependent rows of the MPC equations: ``(dep, equation index, WM)``, ``u[dep] = WM[dep] u``.

    Each equation sum A_i u_i = 0 (components in each grid's CD system, as the g-set) is solved
    for its first term: u_1 = -sum_{i>1} (A_i / A_1) u_i (NASTRAN's m-set: the first component
    of each MPC is dependent). Independent terms may themselves be dependent (on a rigid element
    or another MPC): the chains are followed as the rigid elements' are."""
    n_g = 6 * len(grid_ids)
    if not mpcs:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), sp.csr_matrix((n_g, n_g))
    rows, cols, vals, deps = [], [], [], []
    for m in mpcs:
        where = f"{m.src}: MPC {m.sid}"
        pos = _grid_pos(grid_ids, [g for g, _, _ in m.terms], where)
        idx = 6 * pos + np.array([c for _, c, _ in m.terms], np.int64) - 1
        a = np.array([t[2] for t in m.terms], float)
        if np.any(idx[1:] == idx[0]):
            raise ModelError(f"{where}: the dependent component (grid {m.terms[0][0]} component "
                             f"{m.terms[0][1]}) appears again among the equation's other terms")
        rows.append(np.full(idx.size - 1, idx[0]))
        cols.append(idx[1:])
        vals.append(-a[1:] / a[0])
        deps.append(int(idx[0]))
    WM = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(n_g, n_g))
    WM.sum_duplicates()
    WM.eliminate_zeros()
    return (np.array(deps, np.int64), np.arange(first_index, first_index + len(mpcs), dtype=np.int64),
            WM)


RBE3_COND = 1e12
"""An RBE3 whose weighted normal matrix S^T W S (6x6) has a condition number above this leaves
a motion of its reference grid undetermined by its independent components: an error."""


def _rbe3_rows(deck: Deck, grid_ids: np.ndarray, rbe3s, first_index: int):
    """Dependent rows of the RBE3s: ``(dep, element index, W3)`` with ``u[dep] = W3[dep] u``.

    NASTRAN's interpolation element (MSC QRG RBE3; the weighted least-squares average of the
    independent motions): each independent component (grid i, component c of its CD system,
    weight w) is a row ``s = (F_i A_i)[c]`` of the rigid-body map from the reference grid's basic
    motion to grid i (``A_i = [[I, -S(x_i - x_ref)], [0, I]]``, ``F_i`` the grid's CD axes), so
    that the reference motion is ``(S^T W S)^-1 S^T W u_ind``, turned into the reference grid's
    CD; the REFC rows are kept. Rotational components are weighted by w L^2, L the mean distance
    of the independent grids from the reference grid (MSC Nastran's scaling, so that rotations
    and translations are weighed alike; MYSTRAN 18 weighs them by w alone and couples them
    differently, so the two differ when independent rotations are given)."""
    n_g = 6 * len(grid_ids)
    if not rbe3s:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), sp.csr_matrix((n_g, n_g))
    rows, cols, vals, deps, owners = [], [], [], [], []
    for k, e in enumerate(rbe3s):
        where = f"{e.src}: RBE3 {e.eid}"
        ref = int(_grid_pos(grid_ids, [e.refgrid], where)[0])
        members = [(w, c, int(p)) for w, comps, gs in e.groups
                   for p in _grid_pos(grid_ids, list(gs), where) for c in comps]
        pos = sorted({p for _, _, p in members} | {ref})
        xyz = _xyz(deck, grid_ids, np.array(pos))
        frames = dict(zip(pos, deck.displacement_frames(grid_ids[pos].tolist())))
        at = dict(zip(pos, xyz))
        dist = [np.linalg.norm(at[p] - at[ref]) for p in {p for _, _, p in members}]
        lc2 = float(np.mean(dist)) ** 2
        S = np.zeros((len(members), 6))
        wts = np.zeros(len(members))
        for m, (w, c, p) in enumerate(members):
            r = at[p] - at[ref]
            A = np.eye(6)
            A[:3, 3:] = -np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
            F = np.zeros((6, 6))
            F[:3, :3] = F[3:, 3:] = frames[p]
            ci = int(c) - 1
            S[m] = (F @ A)[ci]
            wts[m] = w * (lc2 if ci >= 3 else 1.0)
        N = S.T @ (wts[:, None] * S)
        if not np.linalg.cond(N) < RBE3_COND:
            raise ModelError(f"{where}: the independent grids and components do not determine "
                             f"all six motions of the reference grid {e.refgrid} (e.g. too few "
                             f"grids, or all on one line with translations only)")
        G = np.linalg.solve(N, S.T * wts)                      # basic reference motion
        Fr = np.zeros((6, 6))
        Fr[:3, :3] = Fr[3:, 3:] = frames[ref]
        G = Fr @ G                                             # in the reference grid's CD
        col = np.array([6 * p + int(c) - 1 for _, c, p in members], dtype=np.int64)
        for c in e.refc:
            ci = int(c) - 1
            rows.append(np.full(col.size, 6 * ref + ci))
            cols.append(col)
            vals.append(G[ci])
            deps.append(6 * ref + ci)
            owners.append(first_index + k)
    W3 = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(n_g, n_g))
    W3.sum_duplicates()
    W3.eliminate_zeros()
    return np.array(deps, np.int64), np.array(owners, np.int64), W3


# --------------------------------------------------------------------------------------------
# factorization backends
# --------------------------------------------------------------------------------------------
_PARDISO_STATE: dict = {}


def pardiso_available() -> bool:
    """True when pypardiso is installed and finds MKL's ``mkl_rt`` library."""
    if "ok" not in _PARDISO_STATE:
        try:
            _mkl_pardiso()
            _PARDISO_STATE["ok"] = True
        except (ImportError, OSError, AttributeError):
            _PARDISO_STATE["ok"] = False
    return _PARDISO_STATE["ok"]


def _mkl_pardiso():
    """``(pardiso, pardiso_getdiag)`` ctypes functions of the mkl_rt that pypardiso loads."""
    if "fn" not in _PARDISO_STATE:
        import pypardiso
        lib = pypardiso.PyPardisoSolver().libmkl       # pypardiso's search for mkl_rt
        i32p = ctypes.POINTER(ctypes.c_int32)
        ptp = ctypes.POINTER(ctypes.c_int64 if ctypes.sizeof(ctypes.c_void_p) == 8 else ctypes.c_int32)
        pardiso = lib.pardiso
        pardiso.argtypes = [ptp, i32p, i32p, i32p, i32p, i32p, ctypes.c_void_p, i32p, i32p,
                            i32p, i32p, i32p, i32p, ctypes.c_void_p, ctypes.c_void_p, i32p]
        pardiso.restype = None
        getdiag = lib.pardiso_getdiag
        getdiag.argtypes = [ptp, ctypes.c_void_p, ctypes.c_void_p, i32p, i32p]
        getdiag.restype = None
        _PARDISO_STATE["fn"] = (pardiso, getdiag, ptp, i32p)
    return _PARDISO_STATE["fn"]


def resolve_backend(backend: str, n_dofs: int) -> str:
    """The concrete backend (``"superlu"`` or ``"pardiso"``) for a name and a model size."""
    if backend == "auto":
        return "pardiso" if n_dofs >= AUTO_PARDISO_MIN_DOFS and pardiso_available() else "superlu"
    if backend not in BACKENDS:
        raise ModelError(f"unknown factorization backend {backend!r}; "
                         f"use 'superlu', 'pardiso' or 'auto'")
    return backend


_PARDISO_ERRORS = {-1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
                   -4: "zero pivot", -5: "unclassified (internal) error", -6: "reordering failed",
                   -7: "diagonal matrix is singular", -8: "32-bit integer overflow",
                   -9: "not enough memory for out-of-core", -10: "error opening OOC files",
                   -11: "read/write error with OOC files", -12: "pardiso_64 called from 32-bit library"}


def _pardiso_error(code: int, phase: int) -> FactorizationError:
    return FactorizationError(f"MKL PARDISO failed in phase {phase}: error {code} "
                              f"({_PARDISO_ERRORS.get(code, 'unknown')})", code=code, phase=phase)


class PardisoLDLT:
    """Sparse symmetric factorization of ``K`` with MKL PARDISO (upper triangle, CSR, 0-based).

    First Cholesky (matrix type 2, real SPD: the normal case, a supported structure); if PARDISO
    reports a non-positive pivot, Bunch-Kaufman ``L D L^T`` (type -2, real symmetric indefinite:
    negative joint springs, or a mechanism) with pivot perturbation 1e-13. Ordering: METIS nested
    dissection. ``pivot_ratio()`` gives each DOF's pivot over its diagonal (from
    ``pardiso_getdiag``) for the same mechanism test as SuperLU's. ``perturbed`` counts pivots
    PARDISO had to perturb (a singular matrix). Calls on one factorization are serialized (one
    PARDISO handle is not safe for concurrent calls); the MKL memory is released by :meth:`close`
    or when the object is collected.
    """

    def __init__(self, K: sp.spmatrix, mtype: int | None = None):
        self._fn = _mkl_pardiso()
        A = sp.triu(K, format="csr")
        A.sum_duplicates()
        A.sort_indices()
        if A.nnz >= 2**31:
            raise FactorizationError("matrix too large for 32-bit PARDISO indexing (nnz >= 2^31)")
        self.n = A.shape[0]
        self.a = np.ascontiguousarray(A.data, dtype=np.float64)
        self.ia = A.indptr.astype(np.int32)
        self.ja = A.indices.astype(np.int32)
        self.perm = np.zeros(self.n, np.int32)
        self.pt = np.zeros(64, np.int64 if ctypes.sizeof(ctypes.c_void_p) == 8 else np.int32)
        self.iparm = np.zeros(64, np.int32)
        self._lock = threading.Lock()
        self._alive = False
        self.mtype = 0
        self.analyse_s = self.numeric_s = 0.0
        if mtype is not None:
            self._factor(mtype)
            return
        try:
            self._factor(2)
        except FactorizationError as exc:
            if exc.code not in (-4, -7):
                raise
            self.close()
            self._factor(-2)

    def _factor(self, mtype: int) -> None:
        self.mtype = mtype
        self.pt[:] = 0
        ip = self.iparm
        ip[:] = 0
        ip[0] = 1          # use the values below, not PARDISO's defaults
        ip[1] = 3          # METIS nested dissection, parallel version (same ordering as 2, faster)
        ip[4] = 2          # return the fill-reducing permutation in perm
        ip[7] = 0          # iterative refinement: automatic (2 steps when pivots were perturbed)
        ip[9] = 13         # pivot perturbation 1e-13 (type -2 only)
        ip[10] = 0         # no scaling
        ip[12] = 0         # no weighted matching (symmetric)
        ip[17] = -1        # report nnz(L)
        ip[20] = 1         # Bunch-Kaufman 1x1 and 2x2 pivots (type -2)
        ip[34] = 1         # zero-based indices
        ip[55] = 1         # keep pivots for pardiso_getdiag
        t = time.perf_counter()
        self._call(11)
        self._alive = True
        self.analyse_s = time.perf_counter() - t
        t = time.perf_counter()
        self._call(22)
        self.numeric_s = time.perf_counter() - t

    def _call(self, phase: int, b: np.ndarray | None = None, x: np.ndarray | None = None,
              nrhs: int = 1) -> None:
        pardiso, _, ptp, i32p = self._fn
        err = ctypes.c_int32(0)
        one = ctypes.c_int32(1)
        with self._lock:
            pardiso(self.pt.ctypes.data_as(ptp), ctypes.byref(one), ctypes.byref(one),
                    ctypes.byref(ctypes.c_int32(self.mtype)), ctypes.byref(ctypes.c_int32(phase)),
                    ctypes.byref(ctypes.c_int32(self.n)), self.a.ctypes.data,
                    self.ia.ctypes.data_as(i32p), self.ja.ctypes.data_as(i32p),
                    self.perm.ctypes.data_as(i32p), ctypes.byref(ctypes.c_int32(nrhs)),
                    self.iparm.ctypes.data_as(i32p), ctypes.byref(ctypes.c_int32(0)),
                    None if b is None else b.ctypes.data, None if x is None else x.ctypes.data,
                    ctypes.byref(err))
        if err.value != 0:
            raise _pardiso_error(err.value, phase)

    @property
    def perturbed(self) -> int:
        return int(self.iparm[13])

    @property
    def nnz_factor(self) -> int:
        return int(self.iparm[17])

    @property
    def peak_memory_bytes(self) -> int:
        """PARDISO's own peak memory estimate (analysis or factorization + solve), bytes."""
        return 1024 * int(max(self.iparm[14], self.iparm[15] + self.iparm[16]))

    def inertia(self) -> tuple[int, int]:
        """(positive, negative) pivots: from type -2 only (type 2 succeeded means all positive)."""
        if self.mtype == 2:
            return self.n, 0
        return int(self.iparm[21]), int(self.iparm[22])

    def pivot_ratio(self) -> np.ndarray:
        """``|pivot_i| / K_ii`` for every DOF i (original order)."""
        _, getdiag, ptp, i32p = self._fn
        df, da = np.zeros(self.n), np.zeros(self.n)
        err = ctypes.c_int32(0)
        with self._lock:
            getdiag(self.pt.ctypes.data_as(ptp), df.ctypes.data, da.ctypes.data,
                    ctypes.byref(ctypes.c_int32(1)), ctypes.byref(err))
        if err.value != 0:
            raise _pardiso_error(err.value, 0)
        ratio = np.empty(self.n)
        ratio[self.perm] = np.abs(df) / da          # df, da are in pivot order: perm[k] is DOF
        return ratio

    def solve(self, B: np.ndarray) -> np.ndarray:
        B = np.asarray(B, dtype=np.float64)
        one = B.ndim == 1
        Bf = np.asfortranarray(B.reshape(self.n, -1))
        X = np.zeros_like(Bf, order="F")
        if Bf.shape[1]:
            self._call(33, Bf, X, Bf.shape[1])
        return X[:, 0] if one else X

    def close(self) -> None:
        if self._alive:
            self._alive = False
            try:
                self._call(-1)
            except Exception:       # noqa: BLE001 - best effort release
                pass

    def __del__(self):
        try:
            self.close()
        except Exception:           # noqa: BLE001 - interpreter shutdown
            pass


class Factorization:
    """One sparse factorization of ``K_ff`` reused for every right-hand side.

    ``backend``: ``"superlu"`` (SciPy, symmetric-mode minimum-degree ordering, always
    available), ``"pardiso"`` (Intel MKL PARDISO through the optional ``pypardiso`` package:
    Cholesky, or L D L^T for an indefinite matrix, METIS ordering, multithreaded) or ``"auto"``
    (PARDISO from :data:`AUTO_PARDISO_MIN_DOFS` free DOFs on when installed, else SuperLU).
    ``self.backend`` is the backend actually used. Both detect mechanisms the same way (pivot
    over diagonal below :data:`PIVOT_RATIO`, plus PARDISO's perturbed-pivot count) and raise
    :class:`UnstableStructureError` naming the DOFs that move.
    """

    def __init__(self, model: Assembled, backend: str = "superlu"):
        self.model = model
        K = model.K_ff
        self.requested_backend = backend
        if backend == "pardiso" and not pardiso_available():
            raise ModelError("backend 'pardiso' needs the optional package pypardiso (MKL): "
                             "pip install 'blackbox-joints[pardiso]'")
        self.backend = resolve_backend(backend, K.shape[0])
        t0 = time.perf_counter()
        diag = K.diagonal()
        dead = np.flatnonzero(diag == 0.0)
        if dead.size:
            raise UnstableStructureError(
                "the stiffness has no diagonal term at these free components: nothing connects "
                "them (a grid without elements, or a rotation no element reaches); add an SPC1 or "
                "an element, or remove PARAM,AUTOSPC,NO from the deck (AUTOSPC, NASTRAN's SOL 101 "
                "default, would constrain them)" if not model.autospc_on else
                "the stiffness has no diagonal term at these free components: nothing connects them",
                [model.f_labels[i] for i in dead])
        negative = np.flatnonzero(diag < 0.0)
        if negative.size:
            raise UnstableStructureError(
                "negative diagonal stiffness at these free components: negative springs exceed "
                "what the elements provide, the structure would be unstable",
                [model.f_labels[i] for i in negative])
        if model.free_rigid is not None:
            what, labels = model.free_rigid
            raise UnstableStructureError(
                f"the structure is a mechanism: the supports leave it free to move as a rigid body "
                f"({what}), most at grids {sorted({g for g, _ in labels})[:20]}: check the SPC1/GRID PS "
                f"components in their grids' displacement systems (CD), which are the directions "
                f"they hold", labels)
        if self.backend == "superlu":
            self._lu = self._superlu(K)
            self._check_pivots(K, diag)
        else:
            self._pd = PardisoLDLT(K)
            self._check_pardiso()
        self.factor_s = time.perf_counter() - t0

    @staticmethod
    def _superlu(K: sp.csc_matrix):
        opts = dict(permc_spec=SUPERLU_ORDERING, diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        try:
            return spla.splu(K, **opts)
        except RuntimeError:
            return None

    def _check_pivots(self, K: sp.csc_matrix, diag: np.ndarray) -> None:
        lu = self._lu
        if lu is None:   # exactly singular: find the mechanism on a slightly shifted matrix
            shifted = self._superlu((K + sp.diags(diag * 1e-13)).tocsc())
            if shifted is None:
                raise UnstableStructureError("the stiffness matrix is exactly singular", [])
            lu = shifted
        piv = np.abs(lu.U.diagonal())
        cols = np.argsort(lu.perm_c)           # U[j, j] belongs to the column i with perm_c[i] == j
        ratio = piv / diag[cols]
        bad = cols[ratio < PIVOT_RATIO]
        if bad.size or self._lu is None:
            self._raise_mechanism(lu.solve, max(int(bad.size), 1), int(bad.size))

    def _check_pardiso(self) -> None:
        pd = self._pd
        ratio = pd.pivot_ratio()
        n_bad = int(np.count_nonzero(ratio < PIVOT_RATIO))
        if n_bad or pd.perturbed:
            n_modes = max(n_bad, min(pd.perturbed, 24), 1)
            self._raise_mechanism(pd.solve, n_modes, max(n_bad, pd.perturbed))

    def _raise_mechanism(self, solve, n_modes: int, n_bad: int) -> None:
        moving = self._mechanism_dofs(solve, min(n_modes, 64))
        labels = [self.model.f_labels[i] for i in moving]
        grids = sorted({g for g, _ in labels})
        raise UnstableStructureError(
            f"the structure is a mechanism or is not fully supported ({n_bad} zero-energy "
            f"mode(s)); it can move without straining, most at grids {grids[:20]}: check "
            f"SPC1/GRID PS supports, RBE2 ties and unconnected rotations", labels)

    def _mechanism_dofs(self, solve, n_modes: int) -> np.ndarray:
        """Free DOFs that move most in the zero-energy modes (inverse iteration)."""
        n = self.model.K_ff.shape[0]
        x = np.random.default_rng(0).standard_normal((n, n_modes))
        for _ in range(3):
            x, _ = np.linalg.qr(solve(x))
        amp = np.max(np.abs(x), axis=1)
        order = np.argsort(-amp)
        return order[amp[order] > 0.2 * amp[order[0]]][:24]

    def solve(self, F: np.ndarray) -> np.ndarray:
        """``K_ff^-1 F`` for one (1-D) or many (columns) right-hand sides at once."""
        if self.backend == "pardiso":
            return self._pd.solve(F)
        return self._lu.solve(np.asarray(F, float))

    def close(self) -> None:
        """Release the factor's memory now (PARDISO's MKL memory; SuperLU's is garbage-collected)."""
        if self.backend == "pardiso":
            self._pd.close()
        else:
            self._lu = None
