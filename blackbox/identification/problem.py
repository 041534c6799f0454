"""The identification problem in the condensed space and its parameter coordinates (Sec. 4.3).

:class:`_Problem` locates the observations in a :class:`~blackbox.condensation.CondensedModel`
and gives the prediction (eq. 22/30 in flexibility form) and the analytic Jacobian (eq. 18 at
the measured rows): no solver run after the one batched condensation. It is the
:class:`blackbox.fitting.lm.LeastSquaresProblem` that the Levenberg-Marquardt core iterates.

Parameter coordinates (:class:`JointCoordinates`)
    * simple-model springs (:class:`~blackbox.joints.SimpleJoint`) are iterated in ``log k``, so
      they stay ``> 0`` (steps capped at a factor 100). The bound ``k = 0`` is an active set
      (:class:`SpringFloor`): when the natural-coordinate Gauss-Newton step would take springs
      below a floor (:data:`SPRING_FLOOR` times the joint's stiffest spring) that bounded step is
      tried first (in log k the bound is infinitely far and the iteration would crawl), and a
      spring at the floor that still wants to decrease is held there.
    * the complex model is iterated in *matrix-logarithm* coordinates (:class:`MatrixLog`):
      ``K_C = expm(S)``, ``S`` symmetric, ``phi`` = the upper triangle of ``S``. Every ``phi``
      gives a positive definite ``K_C``, and a step changes ``K_C`` relatively, as ``log k`` does
      a spring: the response is ~``K^-1``, so in the natural entries the iteration crawls along
      the positive definite boundary with its steps cut there. ``dk/dphi`` is then a block (the
      Frechet derivative of ``expm``), not a diagonal; a step is capped by the spectral norm of
      ``dS`` (every eigenvalue of ``K_C`` changes by at most a factor 100). Statistics,
      intervals and profiles stay in the entries of ``K_C``: a profile needs its entry as a
      coordinate, so profiles iterate the complex model in the natural entries
      (:meth:`_Problem.natural`), starting at the optimum, with step rejection.
    * any other joint model is iterated in its natural parameters with step rejection.

    A ``K_C`` eigenvalue the data do not bound from above (a joint far stiffer than the
    structure in one mode, e.g. the cube's Table 5.12 joint with 5 % noise: ``std(log mu) = 4``
    at the truth; the maximum-likelihood estimate is then rigid in that mode in ~3 of 4 noise
    replicates) runs off to ``1e11-1e16`` and the iteration takes 9-30 steps to stop; the
    covariance then flags every entry as not identifiable (rank 20 of 21). A bound "rigid
    relative to the structure" (like the springs' floor) would end that sooner; not done.
"""

from __future__ import annotations

import copy
from typing import Callable, Sequence

import numpy as np

from blackbox.condensation import CondensedModel, Response
from blackbox.errors import IdentificationError
from blackbox.fitting.lm import bounded_gauss_newton_step
from blackbox.identification.observations import Observations
from blackbox.joints import ComplexJoint, JointModel, SimpleJoint

__all__ = ["SPRING_FLOOR", "JointCoordinates", "MatrixLog", "SpringFloor"]

SPRING_FLOOR = 1e-6                 # a spring below this times its joint's stiffest is held at "0"


# --------------------------------------------------------------------------------------------
# matrix-logarithm coordinates of a complex joint
# --------------------------------------------------------------------------------------------
class MatrixLog:
    """``K_C = expm(S)`` with ``S`` symmetric: the coordinates ``phi`` of a complex joint are the
    upper triangle of ``S`` (row then column, the order of the parameters ``k``, the upper
    triangle of ``K_C``). Every ``S`` gives a positive definite ``K_C``, and a step in ``S``
    changes ``K_C`` *relatively* -- the analogue of ``log k`` for a spring: ``S = log(k) I`` is
    the complex model with every eigenvalue ``k``. With ``S = V diag(l) V^T``,
    ``K_C = V diag(exp l) V^T`` and the Frechet derivative of ``expm`` at ``S`` in a direction
    ``E`` is (Daleckii-Krein; Higham, *Functions of Matrices*, 2008, Thm. 3.11)::

        dK_C = V (Gamma o (V^T E V)) V^T,   Gamma_ij = (e^l_i - e^l_j) / (l_i - l_j)  (e^l_i if equal)

    the first divided differences of ``exp``; ``dk/dphi`` is that map on the basis ``E_q`` of
    symmetric matrices (``E_ij + E_ji`` off the diagonal), restricted to the upper triangle.
    Checked against ``scipy.linalg.expm_frechet`` in the tests."""

    def __init__(self, sl: slice, m: int):
        self.sl, self.m = sl, m
        self.iu = np.triu_indices(m)
        E = np.zeros((self.iu[0].size, m, m))
        q = np.arange(self.iu[0].size)
        E[q, self.iu[0], self.iu[1]] = 1.0
        E[q, self.iu[1], self.iu[0]] = 1.0
        self.E = E

    def sym(self, v: np.ndarray) -> np.ndarray:
        A = np.zeros((self.m, self.m))
        A[self.iu] = v
        return A + np.triu(A, 1).T

    def to_k(self, phi: np.ndarray) -> np.ndarray:
        if not np.all(np.isfinite(phi)):
            return np.full(phi.shape, np.nan)
        lam, V = np.linalg.eigh(self.sym(phi))
        return ((V * np.exp(np.minimum(lam, 700.0))) @ V.T)[self.iu]     # > 1e150: inadmissible

    def to_phi(self, k: np.ndarray) -> np.ndarray:
        if not np.all(np.isfinite(k)):
            return np.full(k.shape, np.nan)
        mu, V = np.linalg.eigh(self.sym(k))
        if mu[0] <= 0.0:
            return np.full(k.shape, np.nan)
        return ((V * np.log(mu)) @ V.T)[self.iu]

    def dk_dphi(self, k: np.ndarray) -> np.ndarray:
        """``(n_params, n_params)``: column ``q`` is ``dk / dphi_q`` at ``K_C(k)``."""
        mu, V = np.linalg.eigh(self.sym(k))
        lam = np.log(np.maximum(mu, np.finfo(float).tiny))
        a = np.abs(lam[:, None] - lam[None, :])
        with np.errstate(invalid="ignore", divide="ignore"):   # (1 - e^-a) / a without overflow
            q = np.where(a > 0.0, -np.expm1(-a) / a, 1.0)
        gamma = np.exp(np.maximum(lam[:, None], lam[None, :])) * q
        Et = V.T @ self.E @ V                      # V^T E_q V for every basis matrix, O(q m^3)
        dK = V @ (Et * gamma) @ V.T
        return dK[:, self.iu[0], self.iu[1]].T



# --------------------------------------------------------------------------------------------
# the coordinates of an assembly of joints
# --------------------------------------------------------------------------------------------
class JointCoordinates:
    """The coordinates ``phi`` of the concatenated parameters ``k`` of ``joints``: log k for
    springs, logm K_C for complex joints, k for the rest (a :class:`blackbox.fitting.lm.Coordinates`)."""

    def __init__(self, joints: Sequence[JointModel]):
        slices, start = [], 0
        for j in joints:
            slices.append(slice(start, start + j.n_params))
            start += j.n_params
        self.p = start
        self.log_mask = np.zeros(self.p, dtype=bool)
        for j, sl in zip(joints, slices):
            if isinstance(j, SimpleJoint):
                self.log_mask[sl] = True
        self.spring_slices = [sl for j, sl in zip(joints, slices) if isinstance(j, SimpleJoint)]
        self.others = [(j, sl) for j, sl in zip(joints, slices) if not isinstance(j, SimpleJoint)]
        # complex joints: phi = the upper triangle of S = logm(K_C) (K_C = expm(S))
        self.mlog = [MatrixLog(sl, j.m) for j, sl in self.others if isinstance(j, ComplexJoint)]
        self.mlog_mask = np.zeros(self.p, dtype=bool)
        for b in self.mlog:
            self.mlog_mask[b.sl] = True
        self.log_coords = self.log_mask | self.mlog_mask

    def natural(self) -> "JointCoordinates":
        """The same with every complex joint in its natural parameters (the entries of ``K_C``;
        springs stay in log k)."""
        out = copy.copy(self)
        out.mlog = []
        out.mlog_mask = np.zeros(self.p, dtype=bool)
        out.log_coords = self.log_mask.copy()
        return out

    def to_natural(self, phi: np.ndarray) -> np.ndarray:
        k = np.array(phi, dtype=float)
        k[self.log_mask] = np.exp(np.minimum(k[self.log_mask], 700.0))   # > 1e150: inadmissible
        for b in self.mlog:
            k[b.sl] = b.to_k(k[b.sl])
        return k

    def to_coords(self, k: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_natural`; ``nan`` for a spring <= 0 or a ``K_C`` that is not
        positive definite (no coordinates there)."""
        phi = np.array(k, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            phi[self.log_mask] = np.where(phi[self.log_mask] > 0.0, np.log(phi[self.log_mask]), np.nan)
        for b in self.mlog:
            phi[b.sl] = b.to_phi(phi[b.sl])
        return phi

    def chain(self, J_k: np.ndarray, k: np.ndarray) -> np.ndarray:
        """``J_k dk/dphi``: a Jacobian in ``k`` (columns) to one in ``phi``. ``dk/dphi`` is
        ``diag(k)`` for springs, the identity for natural parameters and, per complex joint, the
        Frechet derivative of ``expm`` at ``S`` (:class:`MatrixLog`)."""
        J = J_k * np.where(self.log_mask, k, 1.0)
        for b in self.mlog:
            J[:, b.sl] = J_k[:, b.sl] @ b.dk_dphi(k[b.sl])
        return J

    def log_step(self, step: np.ndarray) -> float:
        """How far a step in ``phi`` moves in log coordinates: the largest ``|d log k|`` of a
        spring and spectral norm of ``dS`` of a complex joint (which bounds the change of every
        eigenvalue's logarithm, Weyl). 0 when nothing is in log coordinates."""
        big = float(np.max(np.abs(step[self.log_mask]), initial=0.0))
        for b in self.mlog:
            big = max(big, float(np.max(np.abs(np.linalg.eigvalsh(b.sym(step[b.sl]))), initial=0.0)))
        return big

    def scale(self, k: np.ndarray) -> np.ndarray:
        """The size of each parameter: ``k`` for springs (at least 1e-3 of the joint's stiffest),
        ``max|diag K_J|`` of the joint otherwise."""
        s = np.abs(np.asarray(k, float)).copy()
        for sl in self.spring_slices:                    # a spring near 0 keeps its joint's scale
            s[sl] = np.maximum(s[sl], 1e-3 * np.max(s[sl]))
        for j, sl in self.others:
            s[sl] = float(np.max(np.abs(np.diag(j.matrix(k[sl])))))
        tiny = np.finfo(float).tiny
        return np.where(s > tiny, s, 1.0)

    def unit_size(self, k: np.ndarray) -> np.ndarray:
        """Of a unit of ``phi``: 1 in log coordinates, the parameter's :meth:`scale` otherwise."""
        return np.where(self.log_coords, 1.0, self.scale(k))

    def floor_value(self, k: np.ndarray) -> np.ndarray:
        """:data:`SPRING_FLOOR` times the stiffest spring of the joint (springs only, else 0)."""
        out = np.zeros(self.p)
        for sl in self.spring_slices:
            out[sl] = SPRING_FLOOR * np.max(k[sl])
        return out

    def at_floor(self, k: np.ndarray, relative: float = SPRING_FLOOR) -> np.ndarray:
        """Springs at or below ``relative`` times the stiffest spring of their joint."""
        out = np.zeros(self.p, dtype=bool)
        for sl in self.spring_slices:
            out[sl] = k[sl] <= relative * np.max(k[sl]) * (1.0 + 1e-9)
        return out


class SpringFloor:
    """The bound ``k >= floor`` of the simple-model springs as an active set (a
    :class:`blackbox.fitting.lm.Bounds`): a spring at twice the floor that the step still takes
    down is held; when the Gauss-Newton step, taken in the natural parameters (``k d log k``),
    would cross the floor, the step with the crossing springs at the floor is offered."""

    def __init__(self, coords: JointCoordinates, admissible: Callable[[np.ndarray], bool]):
        self.coords, self.admissible = coords, admissible

    def at_bound(self, k: np.ndarray) -> np.ndarray:
        return self.coords.at_floor(k, 2.0 * SPRING_FLOOR)

    def held(self, k: np.ndarray, step: np.ndarray, use: np.ndarray) -> np.ndarray:
        return use & (step < 0.0) & self.at_bound(k)

    def bounded_point(self, k, J_k, r, step, use, held):
        c = self.coords
        lg = use & c.log_mask
        crossing = np.zeros(c.p, dtype=bool)
        # the natural GN step is k * d(log k): a spring crosses the floor iff d log k < floor/k - 1
        crossing[lg] = step[lg] < c.floor_value(k)[lg] / k[lg] - 1.0
        if not np.any(crossing & ~held):
            return None
        return self.natural_step(J_k, r, k, use & ~held)

    def natural_step(self, J_k: np.ndarray, r: np.ndarray, k: np.ndarray, use: np.ndarray) -> np.ndarray | None:
        """The Gauss-Newton step in natural coordinates with the springs bounded below by the
        floor (:func:`blackbox.fitting.lm.bounded_gauss_newton_step`): ``None`` unless some
        spring's natural step would cross the floor, or when the result is not admissible."""
        c = self.coords
        lower = np.where(c.log_mask, c.floor_value(k), -np.inf)
        k_new, active = bounded_gauss_newton_step(J_k, r, k, use, lower, np.full(c.p, np.inf), size=c.scale(k))
        if not np.any(active):
            return None
        return k_new if self.admissible(k_new) else None


# --------------------------------------------------------------------------------------------
# the problem in the condensed space
# --------------------------------------------------------------------------------------------
class _Problem:
    """Observations located in the condensed model; predictions, Jacobians, coordinates."""

    def __init__(self, model: CondensedModel, obs: Observations):
        c = model.c
        L, nB = len(c.cases), len(c.boundary)
        if obs.case_labels and obs.case_labels != tuple(c.cases):
            raise IdentificationError(
                f"observations refer to cases {list(obs.case_labels)}, the condensed model has "
                f"{list(c.cases)}")
        if len(obs) and int(obs.case_index.max()) >= L:
            raise IdentificationError(f"case_index {int(obs.case_index.max())} is out of range "
                                      f"for the {L} condensed cases")
        try:
            loc = model.locate(obs.dofs)
        except KeyError as exc:
            raise IdentificationError(str(exc.args[0])) from None
        self.model, self.obs = model, obs
        self.L, self.nB = L, nB
        self.rows = np.array([i if s == "B" else nB + i for s, i in loc], dtype=int)
        self.flat = self.rows * L + obs.case_index
        # rows measured relative to a reference DOF (Section 5.2): predicted u(dof) - u(ref)
        self.has_ref = np.array([r is not None for r in obs.ref_dofs], dtype=bool) if obs.ref_dofs \
            else np.zeros(len(obs), dtype=bool)
        ref_rows = np.zeros(len(obs), dtype=int)
        if self.has_ref.any():
            try:
                rloc = model.locate([r for r in obs.ref_dofs if r is not None])
            except KeyError as exc:
                raise IdentificationError(str(exc.args[0])) from None
            ref_rows[self.has_ref] = [i if s == "B" else nB + i for s, i in rloc]
        self.ref_rows = ref_rows
        self.flat_ref = ref_rows * L + obs.case_index
        all_rows = np.concatenate([self.rows, ref_rows[self.has_ref]])
        self._rows_u, inv = np.unique(all_rows, return_inverse=True)
        self._rows_inv = inv[:len(obs)]
        self._ref_inv = inv[len(obs):]
        self.y, self.sigma = obs.values, obs.sigma
        self.w = 1.0 / obs.sigma
        asm = model.assembly
        self.p = asm.n_params
        self.coordinates = JointCoordinates(asm.joints)
        self.bounds = SpringFloor(self.coordinates, self.admissible)
        # Every model of blackbox.joints is linear in k (K_J = sum k_p dK_J/dk_p): then K_J is a
        # contraction with a constant basis, much cheaper than asking every joint each time.
        probe = np.arange(1.0, self.p + 1.0)
        D = asm.derivatives(probe)
        self._D = D if (np.allclose(D, asm.derivatives(2.0 * probe), rtol=1e-14, atol=0.0) and
                        np.allclose(np.tensordot(probe, D, 1), asm.matrix(probe), rtol=1e-14,
                                    atol=1e-14 * float(np.abs(D).max(initial=1.0)))) else None
        self._Dflat = D.reshape(self.p, -1)

    # ---- the least-squares problem of blackbox.fitting.lm -------------------------------------
    @property
    def n_params(self) -> int:
        return self.p

    @property
    def weights(self) -> np.ndarray:
        return self.w

    def jacobian(self, k: np.ndarray, r: Response) -> np.ndarray:
        return self.jacobian_k(k, r)

    # ---- coordinates: log k for springs, logm K_C for complex joints, k for the rest ----------
    @property
    def log_mask(self) -> np.ndarray:
        return self.coordinates.log_mask

    @property
    def mlog_mask(self) -> np.ndarray:
        return self.coordinates.mlog_mask

    @property
    def log_coords(self) -> np.ndarray:
        return self.coordinates.log_coords

    def natural(self) -> "_Problem":
        """The same problem with every complex joint in its natural parameters (the entries of
        ``K_C``; springs stay in log k): for profiling an entry of ``K_C``, which must then be a
        coordinate."""
        out = copy.copy(self)
        out.coordinates = self.coordinates.natural()
        out.bounds = SpringFloor(out.coordinates, out.admissible)
        return out

    def to_k(self, phi: np.ndarray) -> np.ndarray:
        return self.coordinates.to_natural(phi)

    def to_phi(self, k: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_k`; ``nan`` where ``k`` has no coordinates."""
        return self.coordinates.to_coords(k)

    def chain(self, J_k: np.ndarray, k: np.ndarray) -> np.ndarray:
        return self.coordinates.chain(J_k, k)

    def log_step_size(self, step: np.ndarray) -> float:
        return self.coordinates.log_step(step)

    def scale(self, k: np.ndarray) -> np.ndarray:
        return self.coordinates.scale(k)

    def floor_value(self, k: np.ndarray) -> np.ndarray:
        return self.coordinates.floor_value(k)

    def at_floor(self, k: np.ndarray, relative: float = SPRING_FLOOR) -> np.ndarray:
        return self.coordinates.at_floor(k, relative)

    def admissible(self, k: np.ndarray) -> bool:
        """Finite, springs > 0 (always so in log space), other joints ``is_admissible(strict)``."""
        if not np.all(np.isfinite(k)) or np.any(k[self.log_mask] <= 0.0) or np.max(np.abs(k)) > 1e150:
            return False
        return all(j.is_admissible(k[sl], strict=True) for j, sl in self.coordinates.others)

    def clipped(self, k: np.ndarray, relative: float) -> np.ndarray | None:
        """The nearest point (Frobenius norm, per joint) whose ``K_C`` eigenvalues are at least
        ``relative`` times the joint's largest (Higham 1988: clip the eigenvalues); ``None`` when
        a ``K_C`` has no positive eigenvalue, or the result is not admissible (e.g. a spring
        < 0: springs and other joint models are left as they are)."""
        out = np.array(k, dtype=float)
        if not np.all(np.isfinite(out)):
            return None
        for j, sl in self.coordinates.others:
            if isinstance(j, ComplexJoint):
                mu, V = np.linalg.eigh(j.kc_matrix(out[sl]))
                if not mu[-1] > 0.0:
                    return None
                out[sl] = j.params_from_kc((V * np.maximum(mu, relative * mu[-1])) @ V.T)
        return out if self.admissible(out) else None

    # ---- model -----------------------------------------------------------------------------
    def dK(self, k: np.ndarray) -> np.ndarray:
        """``K_J(k) - K_deck`` over the boundary DOFs."""
        K_J = self.model.assembly.matrix(k) if self._D is None else (k @ self._Dflat).reshape(self.nB, self.nB)
        return K_J - self.model.K_deck

    def derivatives(self, k: np.ndarray) -> np.ndarray:
        return self.model.assembly.derivatives(k) if self._D is None else self._D

    def predict(self, k: np.ndarray) -> tuple[np.ndarray, Response]:
        """Eq. 22/30 in flexibility form, as ``CondensedModel.response`` (same result, tested)."""
        c = self.model.c
        try:
            if self._D is None:
                r = self.model.response(k)
            else:
                dK = self.dK(k)
                U_B = np.linalg.solve(np.eye(self.nB) + c.G_BB @ dK, c.U_B0)
                r = Response(U_B, c.U_O0 - c.G_OB @ (dK @ U_B))
        except np.linalg.LinAlgError:                     # singular: reported as non-finite
            r = Response(np.full_like(c.U_B0, np.nan), np.full_like(c.U_O0, np.nan))
        full = np.vstack([r.U_B, r.U_O]).ravel()
        f = full[self.flat]
        if self.has_ref.any():
            f = f - np.where(self.has_ref, full[self.flat_ref], 0.0)
        return f, r

    def jacobian_k(self, k: np.ndarray, r: Response) -> np.ndarray:
        """``dU/dk`` at the observed rows, ``(n_obs, n_params)``: eq. 18 in flexibility form,
        evaluated only where measured (``CondensedModel.sensitivities`` gives every row; the two
        agree to rounding, see the tests). With ``H = d U / d F_B`` of the structure with joints,
        ``H = [A^-1 G_BB; G_OB (I - dK A^-1 G_BB)]``, ``A = I + G_BB dK`` and ``D_p = dK_J/dk_p``::

            dU/dk_p = -H D_p U_B                                      (no solver run)
        """
        c = self.model.c
        dK = self.dK(k)
        W = np.linalg.solve(np.eye(self.nB) + c.G_BB @ dK, c.G_BB)
        H = np.vstack([W, c.G_OB - (c.G_OB @ dK) @ W])[self._rows_u]
        D = self.derivatives(k)
        p, nB, L = self.p, self.nB, self.L
        V = (D.reshape(-1, nB) @ r.U_B).reshape(p, nB, L)
        T = (H @ V.transpose(1, 0, 2).reshape(nB, -1)).reshape(len(self._rows_u), p, L)
        J = -T[self._rows_inv, :, self.obs.case_index]
        if self.has_ref.any():
            J[self.has_ref] += T[self._ref_inv, :, self.obs.case_index[self.has_ref]]
        return J

    def chi2(self, f: np.ndarray, y: np.ndarray | None = None) -> float:
        rr = ((self.y if y is None else y) - f) * self.w
        return float(rr @ rr)
