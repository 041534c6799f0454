"""Standard static condensation from assembled matrices (eq. 13-14), for the benchmark only.

This is what the black-box method avoids needing: access to the solver's stiffness matrix.
It uses the reference solver's assembled ``K_ff`` (outside the protocol) and produces the same
:class:`~blackbox.condensation.Condensed` object as the black-box route, so that the same
identification runs on both and only the way ``K_R``/``F_R`` were obtained differs:

    K_R = K_BB - K_BI K_II^-1 K_IB                                           (eq. 13)
    F_R = F_B  - K_BI K_II^-1 F_I                                            (eq. 14)
"""

from __future__ import annotations

import time
from typing import Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from blackbox.condensation import Condensed
from solver_adapters.protocol import DofLabel, LoadMatrix


def standard_condense(adapter, loads: LoadMatrix, boundary: Sequence[DofLabel]) -> Condensed:
    """Condense the reference adapter's assembled ``K_ff`` onto ``boundary`` (f-set DOFs).

    Observed DOFs away from the joint must be part of ``boundary`` here (the dissertation's
    standard route keeps them uncondensed, Section 4.2).
    """
    t0 = time.perf_counter()
    K, f_labels, T = adapter.stiffness()
    index = {d: i for i, d in enumerate(f_labels)}
    missing = [d for d in boundary if d not in index]
    if missing:
        raise ValueError(f"boundary DOFs {missing[:5]} are not independent free DOFs of the model "
                         f"(constrained or RBE2-dependent)")
    b = np.array([index[tuple(d)] for d in boundary])
    mask = np.ones(K.shape[0], bool)
    mask[b] = False
    i = np.flatnonzero(mask)
    K = K.tocsc()
    K_BB = K[b][:, b].toarray()
    K_BI = K[b][:, i]
    K_II = K[i][:, i].tocsc()
    gi = adapter.model.g_index(loads.dofs)
    F_g = sp.csr_matrix((loads.values.tocoo().data, (gi[loads.values.tocoo().row], loads.values.tocoo().col)),
                        shape=(T.shape[0], loads.n_cases))
    F_f = (T.T @ F_g).toarray()
    lu = spla.splu(K_II, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    rhs = np.hstack([K_BI.T.toarray(), F_f[i]])
    X = lu.solve(rhs)
    nB = len(b)
    K_R = K_BB - K_BI @ X[:, :nB]                                           # eq. 13
    F_R = F_f[b] - K_BI @ X[:, nB:]                                         # eq. 14
    K_R = 0.5 * (K_R + K_R.T)
    G_BB = np.linalg.inv(K_R)
    U_B0 = G_BB @ F_R
    wall = time.perf_counter() - t0
    return Condensed(boundary=tuple(tuple(d) for d in boundary), observed=(), cases=loads.cases,
                     G_BB=0.5 * (G_BB + G_BB.T), G_OB=np.zeros((0, nB)), U_B0=U_B0,
                     U_O0=np.zeros((0, loads.n_cases)), symmetry_error=0.0, solver_runs=0,
                     right_hand_sides=rhs.shape[1], wall_s=wall)
