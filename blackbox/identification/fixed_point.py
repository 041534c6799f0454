"""The fixed-point start of the identification (Sec. 4.3.1, eq. 22-29).

Used when every DOF on which the joints act is measured in every fitted case. We use the
*flexibility form* of eq. 24 (multiplied by ``G_BB = K_R^-1``, so the condensed flexibility is
never inverted; ``dK = K_J(k) - K_deck``)::

    G X_m(U_mB) k  =  U_0 - U_m + G K_deck U_mB  +  M E_m ,   M = I + G dK S     (eq. 24-27)
    Y = U_0 - U_m + G K_deck U_mB,   X = G X_m,   V_e = M V_m M^T                  (eq. 27, 29)

with ``G`` the rows of ``[G_BB; G_OB]`` of the measured DOFs (measurements away from the joints
enter too, Sec. 4.2), ``U_0 = [U_B0; U_O0]``, ``X_m`` from the joints' ``x_matrix`` (Table 5.1)
scattered into the boundary rows and ``S`` picking the measured joint DOFs; ``M`` is
``K_overall`` (eq. 25a) in flexibility form. The weighted regression (eq. 28) is repeated with
``V_e`` at the current ``k`` while it cuts ``chi2`` at least tenfold (:data:`FP_STALL`); once it
does not -- it "approaches the neighborhood but does not converge", since ``X_m`` holds noisy
measurements (an errors-in-variables bias) -- Gauss-Newton takes over from the last accepted
point. The regression is unconstrained: a result outside the admissible set (``K_C`` not
positive definite, a spring < 0) is replaced by the better (lower ``chi2``) of the admissible
point on the segment towards it and its nearest positive definite ``K_C`` with the eigenvalues
floored at 0.01-0.3 times the largest (:func:`_admissible_fixed_point`; springs: the segment).
"""

from __future__ import annotations

import numpy as np

from blackbox.fitting.lm import solve_damped
from blackbox.identification.problem import _Problem

FP_STALL = 0.1                      # a fixed-point step is taken only if it cuts chi2 tenfold
FP_FLOORS = (0.01, 0.0316, 0.1, 0.316)   # K_C eigenvalue floors tried (x the largest)


class _FixedPoint:
    """The regression of eq. 26-28 in flexibility form (see the module docstring)."""

    def __init__(self, prob: _Problem):
        model = prob.model
        c = model.c
        asm = model.assembly
        self.prob = prob
        self.G = np.vstack([c.G_BB, c.G_OB])
        self.U0 = np.vstack([c.U_B0, c.U_O0])
        self.K_deck = model.K_deck
        bindex = {d: i for i, d in enumerate(c.boundary)}
        self.joint_idx = [np.array([bindex[d] for d in j.dofs]) for j in asm.joints]
        D = np.abs(asm.derivatives(np.ones(asm.n_params))).sum(axis=0) + np.abs(self.K_deck)
        self.needed = np.flatnonzero(D.sum(axis=0) > 0)         # DOFs on which K_J or K_deck act
        self.reason = ""
        self.case_rows: list[tuple[int, np.ndarray, np.ndarray]] = []
        # Section 5.2: a row measured relative to a reference point becomes absolute by adding the
        # reference point's own (absolute) measurement of the same case; the fixed point is only
        # the start of the iteration, so the correlation this creates is not carried into V_e
        # (the Newton phase uses the rows as measured).
        self.y, self.w = prob.y, prob.w
        if prob.has_ref.any():
            obs = prob.obs
            absolute = {(d, c): i for i, (d, c, r) in
                        enumerate(zip(obs.dofs, obs.case_index.tolist(), prob.has_ref)) if not r}
            y, var = prob.y.copy(), prob.sigma.copy() ** 2
            for i in np.flatnonzero(prob.has_ref):
                j = absolute.get((obs.ref_dofs[i], int(obs.case_index[i])))
                if j is None:
                    self.reason = (f"the fixed-point scheme needs the reference DOF {obs.ref_dofs[i]} "
                                   f"measured absolutely in every case with relative rows")
                    return
                y[i] += prob.y[j]
                var[i] += prob.sigma[j] ** 2
            self.y, self.w = y, 1.0 / np.sqrt(var)
        for case in prob.obs.cases:
            rows = np.flatnonzero(prob.obs.case_index == case)
            if prob.has_ref.any():          # the reference point's rows sit among the absolute ones
                rows = rows[np.unique(prob.rows[rows], return_index=True)[1]]
            pos_of = {int(prob.rows[i]): a for a, i in enumerate(rows)}
            missing = [c.boundary[b] for b in self.needed if int(b) not in pos_of]
            if missing:
                lab = prob.obs.case_labels[case] if prob.obs.case_labels else f"#{case}"
                self.reason = (f"the fixed-point scheme needs every joint DOF measured in every case; "
                               f"case {lab!r} lacks {missing[:4]}{' ...' if len(missing) > 4 else ''}")
                break
            self.case_rows.append((case, rows, np.array([pos_of[int(b)] for b in self.needed])))

    @property
    def applicable(self) -> bool:
        return not self.reason

    def step(self, k: np.ndarray, live: np.ndarray) -> np.ndarray:
        """One weighted regression (eq. 28) with ``V_e`` (eq. 29) at ``k``: the new ``k``. Only the
        ``live`` parameters move: one the model response does not depend on at all would
        otherwise be fitted to the noise in ``X_m``."""
        prob, model = self.prob, self.prob.model
        asm = model.assembly
        dK = prob.dK(k)
        dK_nn = dK[np.ix_(self.needed, self.needed)]
        Xs, Ys = [], []
        for case, rows, pos in self.case_rows:
            srow = prob.rows[rows]
            um = self.y[rows]
            uB = np.zeros(prob.nB)
            uB[self.needed] = um[pos]
            X_m = np.zeros((prob.nB, prob.p))                    # Table 5.1, scattered into B
            for j, idx, sl in zip(asm.joints, self.joint_idx, asm.slices):
                X_m[idx, sl] = j.x_matrix(uB[idx])
            Gr = self.G[srow]
            X = Gr @ X_m                                         # eq. 27b, flexibility form
            Y = self.U0[srow, case] - um + Gr @ (self.K_deck @ uB)   # eq. 27a, flexibility form
            M = np.eye(rows.size)                                # K_overall of eq. 25a, flexibility form
            M[:, pos] += Gr[:, self.needed] @ dK_nn
            Xs.append(np.linalg.solve(M, X) * self.w[rows, None])     # V_e^-1/2 = V_m^-1/2 M^-1
            Ys.append(np.linalg.solve(M, Y) * self.w[rows])
        X, Y = np.vstack(Xs), np.concatenate(Ys)
        # eq. 28 as a least-squares problem for the change (min-norm: unidentifiable directions stay)
        out = k.copy()
        out[live] += solve_damped(X[:, live], Y - X @ k, size=prob.scale(k)[live])
        return out



def _relative_step(prob: _Problem, k_old: np.ndarray, k_new: np.ndarray, free: np.ndarray) -> float:
    """``|d phi|`` in log coordinates (``|d log k|`` for springs, ``|dS_ij|`` for a complex joint
    in ``logm K_C``), ``|dk| / scale`` for the others; the largest over ``free``."""
    d = np.abs(k_new - k_old) / prob.scale(k_old)
    lc = prob.log_coords
    with np.errstate(invalid="ignore"):
        d[lc] = np.abs(prob.to_phi(k_new)[lc] - prob.to_phi(k_old)[lc])
    d[~np.isfinite(d)] = np.inf
    return float(np.max(d[free])) if np.any(free) else 0.0


def _admissible_on_segment(prob: _Problem, k: np.ndarray, k_t: np.ndarray,
                           shrink: float = 0.9) -> np.ndarray | None:
    """The regression of eq. 28 is unconstrained and can leave the admissible set (a spring
    below 0, ``K_C`` not positive definite). The admissible set is convex and ``k`` is in it, so
    the segment towards ``k_t`` stays admissible up to some fraction: bisect for it and stop a
    little short (``shrink``), so that the next iterate is strictly inside."""
    lo, hi = 0.0, 1.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if prob.admissible(k + mid * (k_t - k)):
            lo = mid
        else:
            hi = mid
    if lo <= 0.0:
        return None
    return k + shrink * lo * (k_t - k)


def _admissible_fixed_point(prob: _Problem, k: np.ndarray, k_t: np.ndarray
                            ) -> tuple[np.ndarray | None, float]:
    """The regression's result ``k_t`` made admissible, with its ``chi2``: ``k_t`` itself if it
    is, else the best (lowest ``chi2``) of the admissible point on the segment from ``k``
    (:func:`_admissible_on_segment`) and the nearest points with the ``K_C`` eigenvalues floored
    at :data:`FP_FLOORS` times the largest (:meth:`_Problem.clipped`). The regression leaves
    the positive definite set through the noise in ``X_m`` along a weakly determined direction;
    the segment then shortens the *whole* step, the clipped matrix keeps it (the cube of
    Table 5.12 with 5 % noise from ``K_C = 1e3 I``: ``chi2`` 5e7 -> 3e7 on the segment, -> 2e3
    clipped; over 40 cube and 20 car replicates the floor chosen was 0.03-0.3). Floors far
    below the rest are not offered: the estimate would start Gauss-Newton where the response
    no longer feels that direction (``u ~ 1 / k``) and log coordinates crawl back (a spring
    clipped to 1e-4 of the others on the car with joint-only measurements costs 8 extra
    iterations), which is why springs keep the segment."""
    def chi2(kc: np.ndarray | None) -> float:
        if kc is None:
            return np.inf
        f = prob.predict(kc)[0]
        return prob.chi2(f) if np.all(np.isfinite(f)) else np.inf

    if prob.admissible(k_t):
        return k_t, chi2(k_t)
    cands = [_admissible_on_segment(prob, k, k_t)] + [prob.clipped(k_t, r) for r in FP_FLOORS]
    F = [chi2(c) for c in cands]
    i = int(np.argmin(F))
    return (cands[i], F[i]) if np.isfinite(F[i]) else (None, np.inf)
