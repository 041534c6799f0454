"""Assembly, constraints and factorization of the reference frame model.

``u_g = T u_f``: every grid component (g-set, 6 per grid) is a combination of the independent
free components (f-set). SPC1 and GRID PS components get a zero row; RBE2 dependent components
are exact rigid-body combinations of the independent grid's six components (no penalty):

    u_m = u_n + theta_n x (x_m - x_n),   theta_m = theta_n                      (rigid link)

The reduced stiffness ``K_ff = T^T K_gg T`` is factorized once and reused for every batch.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from solver_adapters.deck import Deck
from solver_adapters.protocol import (DofLabel, ModelError, ScalarSpring, UnstableStructureError)
from solver_adapters.reference import frame

PIVOT_RATIO = 1e-10
"""A pivot below this fraction of its DOF's diagonal stiffness marks a mechanism.

For an SPD matrix the LU pivot of DOF i equals K_ii minus what its coupling to DOFs eliminated
before it explains; a ratio near machine precision (1e-16) means the DOF is a linear
combination of the others, i.e. a mechanism. 1e-10 leaves six orders of margin for legitimately
soft springs (the smallest ratio seen on the fixtures with joint springs of 1 N*m/rad is ~1e-7).
"""


@dataclass
class Assembled:
    """The assembled model: labels, the g-to-f map ``T`` and the reduced stiffness ``K_ff``."""
    grid_ids: np.ndarray            # sorted grid ids
    g_labels: list[DofLabel]        # 6 per grid, grid-major
    T: sp.csr_matrix                # (n_g, n_f)
    K_gg: sp.csr_matrix
    K_ff: sp.csc_matrix
    f_labels: list[DofLabel]

    def g_index(self, dofs) -> np.ndarray:
        pos = np.searchsorted(self.grid_ids, [d[0] for d in dofs])
        return 6 * pos + np.array([d[1] for d in dofs], dtype=int) - 1


def _element_arrays(deck: Deck):
    bars = sorted(deck.cbars.values(), key=lambda b: b.eid)
    xyz = {g.id: np.array(g.xyz, float) for g in deck.grids.values()}
    xa = np.array([xyz[b.ga] for b in bars]).reshape(-1, 3)
    xb = np.array([xyz[b.gb] for b in bars]).reshape(-1, 3)
    v = np.array([np.array(b.x, float) if b.g0 is None else xyz[b.g0] - xyz[b.ga]
                  for b in bars]).reshape(-1, 3)
    props = []
    for b in bars:
        p = deck.pbars[b.pid]
        m = deck.mat1s[p.mid]
        props.append((m.e, m.g, p.a, p.i1, p.i2, p.j))
    props = np.array(props, float).reshape(-1, 6)
    return bars, xa, xb, v, props


def assemble(deck: Deck, extra_springs: tuple[ScalarSpring, ...] = ()) -> Assembled:
    """Vectorized sparse assembly of bars and springs, then constraint elimination."""
    grid_ids = np.array(sorted(deck.grids), dtype=int)
    n_g = 6 * len(grid_ids)
    pos = {g: i for i, g in enumerate(grid_ids)}
    rows, cols, vals = [], [], []

    bars, xa, xb, v, props = _element_arrays(deck)
    if bars:
        try:
            R, L = frame.rotation_matrices(xa, xb, v)
        except ValueError as exc:
            b = bars[int(exc.args[0][0])]
            raise ModelError(f"{b.src}: CBAR {b.eid}: orientation vector is parallel to the bar "
                             f"axis GA={b.ga} -> GB={b.gb}") from None
        if np.any(L <= 0):
            b = bars[int(np.flatnonzero(L <= 0)[0])]
            raise ModelError(f"{b.src}: CBAR {b.eid}: zero length (GA={b.ga}, GB={b.gb} coincide)")
        kl = frame.local_stiffness(L, *props.T)
        kg = frame.global_stiffness(R, kl)
        ia = np.array([pos[b.ga] for b in bars])
        ib = np.array([pos[b.gb] for b in bars])
        dof = np.concatenate([6 * ia[:, None] + np.arange(6), 6 * ib[:, None] + np.arange(6)], axis=1)
        rows.append(np.repeat(dof, 12, axis=1).ravel())
        cols.append(np.tile(dof, (1, 12)).ravel())
        vals.append(kg.ravel())

    springs = [(s.g1, s.c1, s.g2, s.c2, deck.spring_stiffness(s)) for s in deck.springs.values()]
    springs += [(s.a[0], s.a[1], s.b[0] if s.b else 0, s.b[1] if s.b else 0, s.k) for s in extra_springs]
    for g1, c1, g2, c2, k in springs:
        for g in (g1, g2):
            if g and g not in pos:
                raise ModelError(f"spring references grid {g}, which is not in the deck")
        a = 6 * pos[g1] + c1 - 1
        if g2:
            b = 6 * pos[g2] + c2 - 1
            rows.append(np.array([a, b, a, b])); cols.append(np.array([a, b, b, a]))
            vals.append(np.array([k, k, -k, -k], float))
        else:
            rows.append(np.array([a])); cols.append(np.array([a])); vals.append(np.array([k], float))

    K_gg = sp.csr_matrix((np.concatenate(vals) if vals else np.zeros(0),
                          (np.concatenate(rows) if rows else np.zeros(0, int),
                           np.concatenate(cols) if cols else np.zeros(0, int))), shape=(n_g, n_g))
    T, f_index = constraint_map(deck, grid_ids, pos)
    K_ff = (T.T @ K_gg @ T).tocsc()
    K_ff = ((K_ff + K_ff.T) * 0.5).tocsc()       # exact symmetry despite round-off in T^T K T
    g_labels = [(int(g), c) for g in grid_ids for c in range(1, 7)]
    return Assembled(grid_ids, g_labels, T, K_gg, K_ff, [g_labels[i] for i in f_index])


def constraint_map(deck: Deck, grid_ids: np.ndarray, pos: dict[int, int]):
    """``T`` (n_g x n_f) and the g-index of each f column. See the module docstring."""
    n_g = 6 * len(grid_ids)
    fixed = np.zeros(n_g, bool)
    for g in deck.grids.values():
        for c in g.ps:
            fixed[6 * pos[g.id] + int(c) - 1] = True
    for s in deck.spc1s:
        for gid in s.grids:
            for c in s.components:
                fixed[6 * pos[gid] + int(c) - 1] = True

    dependent: dict[int, tuple[int, int, str]] = {}   # g-index -> (rbe2 eid, gn, src)
    for r in sorted(deck.rbe2s.values(), key=lambda r: r.eid):
        for gm in r.gm:
            for c in r.cm:
                i = 6 * pos[gm] + int(c) - 1
                if i in dependent:
                    raise ModelError(f"{r.src}: RBE2 {r.eid}: grid {gm} component {c} is already "
                                     f"dependent on RBE2 {dependent[i][0]}")
                if fixed[i]:
                    raise ModelError(f"{r.src}: RBE2 {r.eid}: dependent grid {gm} component {c} "
                                     f"is also constrained by an SPC; constrain the independent grid instead")
                dependent[i] = (r.eid, r.gn, r.src)

    f_index = np.flatnonzero(~fixed & ~np.isin(np.arange(n_g), list(dependent)))
    col_of = {int(i): j for j, i in enumerate(f_index)}
    xyz = {g.id: np.array(g.xyz, float) for g in deck.grids.values()}

    resolved: dict[int, dict[int, float]] = {}

    def row(i: int, depth: int = 0) -> dict[int, float]:
        """The f-set combination that gives g-component ``i``."""
        if i in col_of:
            return {col_of[i]: 1.0}
        if fixed[i]:
            return {}
        if i in resolved:
            return resolved[i]
        if depth > len(dependent):
            eid = dependent[i][0]
            raise ModelError(f"RBE2 {eid}: circular dependency between RBE2 elements")
        eid, gn, src = dependent[i]
        gm = int(grid_ids[i // 6])
        c = i % 6
        n0 = 6 * pos[gn]
        combo: dict[int, float] = {}

        def add(j: int, w: float) -> None:
            for col, val in row(j, depth + 1).items():
                combo[col] = combo.get(col, 0.0) + w * val

        if c < 3:
            add(n0 + c, 1.0)
            r = xyz[gm] - xyz[gn]                 # u_m = u_n + theta_n x r
            cross = {0: ((4, r[2]), (5, -r[1])), 1: ((5, r[0]), (3, -r[2])), 2: ((3, r[1]), (4, -r[0]))}
            for comp, w in cross[c]:
                if w != 0.0:
                    add(n0 + comp, w)
        else:
            add(n0 + c, 1.0)
        resolved[i] = combo
        return combo

    r_idx, c_idx, v_idx = [], [], []
    for i in range(n_g):
        for col, val in row(i).items():
            r_idx.append(i); c_idx.append(col); v_idx.append(val)
    T = sp.csr_matrix((v_idx, (r_idx, c_idx)), shape=(n_g, len(f_index)))
    return T, f_index


class Factorization:
    """One sparse factorization of ``K_ff`` reused for every right-hand side.

    ``backend`` is ``"superlu"`` (SciPy, symmetric-mode ordering, always available) or
    ``"pardiso"`` (Intel MKL PARDISO through the optional ``pypardiso`` package).
    """

    def __init__(self, model: Assembled, backend: str = "superlu"):
        self.model, self.backend = model, backend
        K = model.K_ff
        t0 = time.perf_counter()
        diag = K.diagonal()
        dead = np.flatnonzero(diag == 0.0)
        if dead.size:
            raise UnstableStructureError(
                "the stiffness has no diagonal term at these free components: nothing connects "
                "them (a grid without elements, or a rotation no element reaches); add an SPC1 or "
                "an element", [model.f_labels[i] for i in dead])
        negative = np.flatnonzero(diag < 0.0)
        if negative.size:
            raise UnstableStructureError(
                "negative diagonal stiffness at these free components: negative springs exceed "
                "what the elements provide, the structure would be unstable",
                [model.f_labels[i] for i in negative])
        if backend == "superlu":
            self._lu = self._superlu(K)
            self._check_pivots(K, diag)
        elif backend == "pardiso":
            try:
                import pypardiso
            except ImportError:
                raise ModelError("backend 'pardiso' needs the optional package pypardiso: "
                                 "pip install 'blackbox-joints[pardiso]'") from None
            self._ps = pypardiso.PyPardisoSolver()
            self._ps.set_matrix_type(11)
            self._Kcsr = K.tocsr()
            self._ps.factorize(self._Kcsr)
        else:
            raise ModelError(f"unknown factorization backend {backend!r}; use 'superlu' or 'pardiso'")
        self.factor_s = time.perf_counter() - t0

    @staticmethod
    def _superlu(K: sp.csc_matrix):
        opts = dict(permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
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
            moving = self._mechanism_dofs(lu, max(int(bad.size), 1))
            labels = [self.model.f_labels[i] for i in moving]
            grids = sorted({g for g, _ in labels})
            raise UnstableStructureError(
                f"the structure is a mechanism or is not fully supported ({bad.size} zero-energy "
                f"mode(s)); it can move without straining, most at grids {grids[:20]}: check "
                f"SPC1/GRID PS supports, RBE2 ties and unconnected rotations", labels)

    def _mechanism_dofs(self, lu, n_modes: int) -> np.ndarray:
        """Free DOFs that move most in the zero-energy modes (inverse iteration on ``lu``)."""
        n = self.model.K_ff.shape[0]
        x = np.random.default_rng(0).standard_normal((n, n_modes))
        for _ in range(3):
            x, _ = np.linalg.qr(lu.solve(x))
        amp = np.max(np.abs(x), axis=1)
        order = np.argsort(-amp)
        return order[amp[order] > 0.2 * amp[order[0]]][:24]

    def solve(self, F: np.ndarray) -> np.ndarray:
        if self.backend == "pardiso":
            return np.asarray(self._ps.solve(self._Kcsr, np.asarray(F, float)))
        return self._lu.solve(np.asarray(F, float))
