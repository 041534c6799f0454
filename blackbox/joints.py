"""Flexible-joint models of Chapter 2: the simple model (Sec. 2.2) and the complex model (Sec. 2.3).

A flexible joint with ``n`` branches is ``n`` coincident branch-end grids tied in translation
(the RBE2 of the deck, ``docs/study-format.md``). Its joint stiffness ``K_J`` acts on the
``3 + 3n`` boundary DOFs, in this order::

    (g1,1) (g1,2) (g1,3)                 translations of GN = branch 1's grid (rows of zeros)
    (g1,4) (g1,5) (g1,6)                 theta_x1, theta_y1, theta_z1
    (g2,4) (g2,5) (g2,6)                 theta_x2, theta_y2, theta_z2
    ...                                  ... up to branch n                      (eq. 3)

Both models act on the ``3n`` rotations only; the translation block of ``K_J`` is zero because the
branches are tied in translation by the RBE2. Inside this module ``K_U`` is the ``3n x 3n``
rotation block (the "unconstrained joint" of eq. 4) and ``K_J`` the embedded ``(3+3n)`` matrix.

Both models are linear in their parameters ``k``: ``K_J(k) = sum_i k_i dK_J/dk_i``. Hence
``K_J(k) u = X(u) k`` with ``X(u)[:, i] = dK_J/dk_i u`` -- the matrix ``X_m`` of eq. 25-26
(Table 5.1 for the simple model) on which the fixed-point scheme of Chapter 4 regresses.

Simple model (Sec. 2.2, eq. 1-3, Table 2.1)
    ``3 C(n,2)`` torsional springs ``k_{p ij}``, one per plane ``p in {x,y,z}`` and branch pair
    ``i < j``; parameter names ``kx12, ky12, kz12, kx13, ...`` (pairs in lexicographic order,
    then the planes). The dissertation's ``k_x31`` is our ``kx13``.

Complex model (Sec. 2.3, eq. 4, Tables 2.2-2.4)
    ``K_U = B K_C B^T`` with ``K_C`` the symmetric ``(3n-3) x (3n-3)`` stiffness of the joint with
    branch ``n`` clamped and ``B = [I_{3n-3}; -(I_3 ... I_3)]`` the equilibrium matrix (Table 2.3).
    ``3(n-1)(3n-2)/2`` parameters: the upper triangle of ``K_C``, row then column, 1-based,
    named ``k11, k12, ..., k66`` (n = 3); when ``3n - 3 >= 10`` (n >= 5) every name carries an
    underscore, ``k1_1, k1_2, ..., k12_12``, so that e.g. ``k1_11`` and ``k11_1`` stay distinct.

Also here: the "actual joint" of Sec. 5.4.1 (:func:`actual_joint_stub_kc`, a stub-frame
reference ``K_C``), the exact scalar-spring network of a joint (:func:`spring_network`, for
CELAS2 cards), and :func:`simple_to_complex_params` (the simple model as a complex one).
"""

from __future__ import annotations

import abc
import itertools
from dataclasses import dataclass
from functools import cached_property
from typing import Mapping, Sequence

import numpy as np

from blackbox.errors import JointModelError
from solver_adapters.protocol import DofLabel, ScalarSpring

__all__ = [
    "JointModelError",
    "JointModel",
    "SimpleJoint",
    "ComplexJoint",
    "joint_dofs",
    "equilibrium_matrix",
    "rigid_rotation_modes",
    "complex_param_names",
    "complex_params_from_kc",
    "kc_from_complex_params",
    "simple_to_complex_params",
    "frame_element_stiffness",
    "actual_joint_stub_kc",
    "spring_network",
    "make_joint",
    "JOINT_MODELS",
]

PLANES = ("x", "y", "z")
JOINT_MODELS = ("simple", "complex")


# --------------------------------------------------------------------------------------------
# DOF layout
# --------------------------------------------------------------------------------------------
def joint_dofs(grids: Sequence[int]) -> list[DofLabel]:
    """The ``3 + 3n`` boundary DOF labels of a joint (``docs/study-format.md``, eq. 3).

    ``[(g1,1), (g1,2), (g1,3), (g1,4), (g1,5), (g1,6), (g2,4), (g2,5), (g2,6), ...]``: the
    translations of branch 1's grid (GN of the RBE2), then the rotations of every branch grid.
    """
    g = _check_grids(grids)
    return [(g[0], c) for c in (1, 2, 3)] + [(gb, c) for gb in g for c in (4, 5, 6)]


def rigid_rotation_modes(n: int) -> np.ndarray:
    """``(3n, 3)``: all branches rotating equally about x, y, z -- the null space of ``K_U``.

    Column ``p`` is ``e_p`` repeated for every branch. Every joint model here is free in a rigid
    rotation of the whole joint (self-equilibrated spring forces), so ``K_U @ R == 0``.
    """
    n = _check_n(n)
    return np.tile(np.eye(3), (n, 1))


def equilibrium_matrix(n: int) -> np.ndarray:
    """The equilibrium matrix ``B`` (``3n x (3n-3)``) of eq. 4 with branch ``n`` clamped.

    Column ``c`` holds a unit moment on rotation ``c`` of a free branch end and the reactions of
    the statically determinate joint (branch ``n`` clamped): ``-1`` on the same axis of branch
    ``n``. Hence ``B = [I_{3n-3}; -(I_3 I_3 ... I_3)]``; for ``n = 3`` this is Table 2.3.
    """
    n = _check_n(n)
    m = 3 * n - 3
    return np.vstack([np.eye(m), -np.tile(np.eye(3), (1, n - 1))])


def _check_n(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise JointModelError(f"a joint needs an integer number of branches n >= 2, got {n!r}")
    return int(n)


def _check_grids(grids: Sequence[int]) -> tuple[int, ...]:
    try:
        g = tuple(grids)
    except TypeError:
        raise JointModelError(f"joint grids must be a sequence of grid ids, got {grids!r}") from None
    if len(g) < 2:
        raise JointModelError(f"a joint needs at least 2 branch grids, got {list(g)!r}")
    for gid in g:
        if isinstance(gid, bool) or not isinstance(gid, (int, np.integer)) or gid <= 0:
            raise JointModelError(f"joint grid ids must be positive integers, got {list(g)!r}")
    g = tuple(int(x) for x in g)
    if len(set(g)) != len(g):
        raise JointModelError(f"joint grid ids must be distinct (one grid per branch), got {list(g)!r}")
    return g


# --------------------------------------------------------------------------------------------
# the common interface
# --------------------------------------------------------------------------------------------
class JointModel(abc.ABC):
    """A joint stiffness ``K_J(k)`` over the ``3 + 3n`` joint DOFs, linear in ``k``.

    Concrete models are frozen dataclasses with fields ``name`` and ``grids`` (branch 1 first)
    and implement :meth:`param_names` and :meth:`unconstrained_matrix` / :meth:`_basis`.
    """

    name: str
    grids: tuple[int, ...]

    # ---- layout ------------------------------------------------------------------------
    @property
    def n_branches(self) -> int:
        return len(self.grids)

    @property
    def n_dofs(self) -> int:
        """``3 + 3n``."""
        return 3 + 3 * self.n_branches

    @property
    def dofs(self) -> tuple[DofLabel, ...]:
        """The ``3 + 3n`` boundary DOF labels, see :func:`joint_dofs`."""
        return tuple(joint_dofs(self.grids))

    @property
    def rotation_dofs(self) -> tuple[DofLabel, ...]:
        """The ``3n`` rotation labels ``(g_b, 4..6)`` on which ``K_U`` acts (eq. 3)."""
        return self.dofs[3:]

    @property
    @abc.abstractmethod
    def param_names(self) -> tuple[str, ...]:
        """Parameter names in parameter-vector order (``docs/study-format.md``)."""

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    # ---- stiffness -----------------------------------------------------------------------
    @abc.abstractmethod
    def unconstrained_matrix(self, k: Sequence[float]) -> np.ndarray:
        """``K_U(k)``: the ``3n x 3n`` rotation block of the joint stiffness."""

    @abc.abstractmethod
    def _basis(self) -> np.ndarray:
        """``(n_params, 3n, 3n)``: ``dK_U/dk_i`` (constant, the models are linear in ``k``)."""

    def matrix(self, k: Sequence[float]) -> np.ndarray:
        """``K_J(k)``, ``(3+3n) x (3+3n)``: ``K_U`` embedded after 3 zero translation rows/columns."""
        return self._embed(self.unconstrained_matrix(k))

    def derivatives(self, k: Sequence[float] | None = None) -> np.ndarray:
        """``dK_J/dk_i`` for every parameter, ``(n_params, 3+3n, 3+3n)``, exact.

        Both models are linear in ``k``, so the result does not depend on ``k``; the argument is
        kept (and checked when given) so that a nonlinear model could share the signature.
        """
        if k is not None:
            self._check_k(k)
        out = np.zeros((self.n_params, self.n_dofs, self.n_dofs))
        out[:, 3:, 3:] = self._basis()
        return out

    def x_matrix(self, theta: np.ndarray) -> np.ndarray:
        """``X(u)`` with ``K_J(k) @ u == X(u) @ k`` for every ``k`` (eq. 24-25, Table 5.1).

        ``theta`` is a joint-DOF vector of length ``3 + 3n`` (:attr:`dofs` order): returns
        ``(3+3n, n_params)`` with column ``i`` equal to ``dK_J/dk_i @ u``. Several load cases as
        columns, ``(3+3n, L)``, give ``(L, 3+3n, n_params)`` (one ``X_m`` per case).
        """
        u = np.asarray(theta, dtype=float)
        if u.ndim not in (1, 2) or u.shape[0] != self.n_dofs:
            raise JointModelError(
                f"joint {self.name!r}: x_matrix needs a joint-DOF vector of length {self.n_dofs} "
                f"(3 + 3n) or an array ({self.n_dofs}, n_cases), got shape {u.shape}")
        basis = self._basis()                       # (p, 3n, 3n)
        rot = u[3:]
        if u.ndim == 1:
            X = np.zeros((self.n_dofs, self.n_params))
            X[3:, :] = np.einsum("pij,j->ip", basis, rot)
            return X
        X = np.zeros((u.shape[1], self.n_dofs, self.n_params))
        X[:, 3:, :] = np.einsum("pij,jc->cip", basis, rot)
        return X

    @abc.abstractmethod
    def is_admissible(self, k: Sequence[float], strict: bool = False) -> bool:
        """Whether ``k`` describes a physically admissible (non-negative energy) joint."""

    @abc.abstractmethod
    def initial_params(self, value: float) -> np.ndarray:
        """The start vector of ``study.toml``'s ``initial`` (``docs/study-format.md``)."""

    # ---- parameter vectors <-> dicts -------------------------------------------------------
    def to_dict(self, k: Sequence[float]) -> dict[str, float]:
        """``{name: value}`` in parameter order."""
        kv = self._check_k(k)
        return {nm: float(v) for nm, v in zip(self.param_names, kv)}

    def from_dict(self, values: Mapping[str, float]) -> np.ndarray:
        """The parameter vector from ``{name: value}``; every name exactly once, no others."""
        names = self.param_names
        missing = [nm for nm in names if nm not in values]
        unknown = [nm for nm in values if nm not in set(names)]
        if missing or unknown:
            raise JointModelError(
                f"joint {self.name!r}: parameters do not match the {self.model_name} model "
                f"({', '.join(names) or 'none'}): missing {missing}, unknown {unknown}")
        return self._check_k([values[nm] for nm in names])

    @property
    def model_name(self) -> str:
        return type(self).__name__.removesuffix("Joint").lower()

    # ---- helpers -------------------------------------------------------------------------
    def _check_k(self, k: Sequence[float]) -> np.ndarray:
        kv = np.asarray(k, dtype=float)
        if kv.shape != (self.n_params,):
            raise JointModelError(
                f"joint {self.name!r} ({self.model_name} model) has {self.n_params} parameters "
                f"{self.param_names}, got a vector of shape {kv.shape}")
        if not np.all(np.isfinite(kv)):
            raise JointModelError(f"joint {self.name!r}: parameters must be finite, got {kv.tolist()}")
        return kv

    def _embed(self, K_U: np.ndarray) -> np.ndarray:
        K_J = np.zeros((self.n_dofs, self.n_dofs))
        K_J[3:, 3:] = K_U
        return K_J


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not name.strip():
        raise JointModelError(f"a joint needs a non-empty name, got {name!r}")
    return name


# --------------------------------------------------------------------------------------------
# simple model, Sec. 2.2
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SimpleJoint(JointModel):
    """Simple model: ``3 C(n,2)`` torsional springs between branch pairs, per plane (Sec. 2.2).

    Strain energy (eq. 1, written for general ``n``)::

        U_E = 1/2 sum_{p in x,y,z} sum_{i<j} k_{p ij} (theta_{p i} - theta_{p j})^2

    and ``K_ij = d^2 U_E / d theta_i d theta_j`` (eq. 2) over the rotations of eq. 3 -- Table 2.1
    for ``n = 3``. Planes do not couple.

    ``rigid_pairs``: branch pairs ``(i, j)`` (1-based) whose connection is practically rigid
    (Sec. 2.2, last paragraph). They carry no parameters; the dissertation sets
    ``theta_{p i} = theta_{p j}`` for ``p = x, y, z``. :meth:`rigid_constraints` lists those
    equalities as DOF-label pairs (for elimination, e.g. RBE2 rotations or MPCs) and
    :meth:`rigid_penalty_matrix` gives the alternative: very stiff springs of a chosen value.
    ``matrix(k)`` contains neither.

    ``constrained_springs``: springs ``(plane, i, j)`` between two rotation components that the
    structure's supports fix (both branch grids' component of that plane constrained, as in a
    planar model, whose out-of-plane rotations are held by SPCs). Such a spring cannot act; it
    carries no parameter (its data could never determine it).
    """

    name: str
    grids: tuple[int, ...]
    rigid_pairs: tuple[tuple[int, int], ...] = ()
    constrained_springs: tuple[tuple[str, int, int], ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", _check_name(self.name))
        g = _check_grids(self.grids)
        object.__setattr__(self, "grids", g)
        n = len(g)
        pairs = []
        for pair in self.rigid_pairs:
            try:
                i, j = (int(x) for x in pair)
            except (TypeError, ValueError):
                raise JointModelError(
                    f"joint {self.name!r}: rigid_pairs must be pairs of branch numbers, got {pair!r}") from None
            i, j = min(i, j), max(i, j)
            if i == j or i < 1 or j > n:
                raise JointModelError(
                    f"joint {self.name!r}: rigid pair {pair!r} must name two different branches "
                    f"in 1..{n}")
            if (i, j) in pairs:
                raise JointModelError(f"joint {self.name!r}: rigid pair {(i, j)} given twice")
            pairs.append((i, j))
        object.__setattr__(self, "rigid_pairs", tuple(sorted(pairs)))
        held = []
        for spring in self.constrained_springs:
            try:
                p, i, j = str(spring[0]), int(spring[1]), int(spring[2])
            except (TypeError, ValueError, IndexError):
                raise JointModelError(f"joint {self.name!r}: constrained_springs must be (plane, i, j), "
                                      f"got {spring!r}") from None
            i, j = min(i, j), max(i, j)
            if p not in PLANES or i == j or i < 1 or j > n:
                raise JointModelError(f"joint {self.name!r}: constrained spring {spring!r} must name a plane "
                                      f"{PLANES} and two different branches in 1..{n}")
            held.append((p, i, j))
        object.__setattr__(self, "constrained_springs", tuple(sorted(set(held))))

    @cached_property
    def spring_pairs(self) -> tuple[tuple[int, int], ...]:
        """The flexible branch pairs ``(i, j)``, ``i < j``, 1-based, lexicographic order."""
        rigid = set(self.rigid_pairs)
        return tuple(p for p in itertools.combinations(range(1, self.n_branches + 1), 2)
                     if p not in rigid)

    @cached_property
    def springs(self) -> tuple[tuple[str, int, int], ...]:
        """``(plane, i, j)`` of every parameter, in parameter order (constrained springs left out)."""
        held = set(self.constrained_springs)
        return tuple((p, i, j) for (i, j) in self.spring_pairs for p in PLANES if (p, i, j) not in held)

    @cached_property
    def param_names(self) -> tuple[str, ...]:
        """``kx12, ky12, kz12, kx13, ...``: pairs ``i < j`` in lexicographic order, then planes."""
        return tuple(f"k{p}{i}{j}" for (p, i, j) in self.springs)

    @cached_property
    def _basis_cache(self) -> np.ndarray:
        n3 = 3 * self.n_branches
        D = np.zeros((self.n_params, n3, n3))
        for q, (p, i, j) in enumerate(self.springs):
            a = 3 * (i - 1) + PLANES.index(p)
            b = 3 * (j - 1) + PLANES.index(p)
            D[q, a, a] = D[q, b, b] = 1.0
            D[q, a, b] = D[q, b, a] = -1.0
        D.flags.writeable = False
        return D

    def _basis(self) -> np.ndarray:
        return self._basis_cache

    def unconstrained_matrix(self, k: Sequence[float]) -> np.ndarray:
        """``K_U``: eq. 2 applied to eq. 1, Table 2.1 for ``n = 3``."""
        kv = self._check_k(k)
        return np.einsum("p,pij->ij", kv, self._basis_cache)

    def is_admissible(self, k: Sequence[float], strict: bool = False) -> bool:
        """All springs ``k >= 0`` (``k > 0`` when ``strict``)."""
        kv = self._check_k(k)
        return bool(np.all(kv > 0.0) if strict else np.all(kv >= 0.0))

    def initial_params(self, value: float) -> np.ndarray:
        """Every spring equal to ``value``."""
        return np.full(self.n_params, float(value))

    def rigid_constraints(self) -> list[tuple[DofLabel, DofLabel]]:
        """DOF-label pairs to be made equal: ``((g_i, c), (g_j, c))`` for each rigid pair, c = 4, 5, 6.

        Sec. 2.2: "if the connections between branches 1 and 2 are rigid, then set
        theta_x1 = theta_x2, theta_y1 = theta_y2 and theta_z1 = theta_z2".
        """
        return [((self.grids[i - 1], c), (self.grids[j - 1], c))
                for (i, j) in self.rigid_pairs for c in (4, 5, 6)]

    def rigid_penalty_matrix(self, scale: float) -> np.ndarray:
        """``(3+3n)`` matrix of springs of stiffness ``scale`` on every rigid pair and plane.

        A penalty version of :meth:`rigid_constraints`: add it to ``matrix(k)``. Pick ``scale``
        a few decades above the structure's rotational stiffness (too large spoils the
        conditioning of the condensed system).
        """
        if not np.isfinite(scale) or scale < 0:
            raise JointModelError(f"rigid penalty scale must be finite and >= 0, got {scale!r}")
        n3 = 3 * self.n_branches
        K = np.zeros((n3, n3))
        for (i, j) in self.rigid_pairs:
            for p in range(3):
                a, b = 3 * (i - 1) + p, 3 * (j - 1) + p
                K[a, a] += scale
                K[b, b] += scale
                K[a, b] -= scale
                K[b, a] -= scale
        return self._embed(K)


# --------------------------------------------------------------------------------------------
# complex model, Sec. 2.3
# --------------------------------------------------------------------------------------------
def complex_param_names(n: int) -> tuple[str, ...]:
    """Names of the upper triangle of ``K_C`` (row then column, 1-based).

    ``k{i}{j}`` while ``m = 3n - 3 <= 9``; ``k{i}_{j}`` for every name when ``m >= 10``.
    """
    m = 3 * _check_n(n) - 3
    sep = "_" if m >= 10 else ""
    return tuple(f"k{i + 1}{sep}{j + 1}" for i in range(m) for j in range(i, m))


def complex_params_from_kc(K_C: np.ndarray) -> np.ndarray:
    """The complex-model parameter vector: the upper triangle of ``K_C``, row then column.

    ``K_C`` must be square, of size ``3n - 3`` for some ``n >= 2``, and symmetric (checked to
    a relative 1e-9: it is built by condensation, whose rounding is far below that).
    """
    K = np.asarray(K_C, dtype=float)
    if K.ndim != 2 or K.shape[0] != K.shape[1] or K.shape[0] < 3 or K.shape[0] % 3:
        raise JointModelError(f"K_C must be square of size 3n-3 (n >= 2), got shape {K.shape}")
    scale = max(float(np.max(np.abs(K))), np.finfo(float).tiny)
    if np.max(np.abs(K - K.T)) > 1e-9 * scale:
        raise JointModelError("K_C must be symmetric (Table 2.2)")
    iu = np.triu_indices(K.shape[0])
    return 0.5 * (K + K.T)[iu]


def kc_from_complex_params(k: Sequence[float], n: int) -> np.ndarray:
    """``K_C`` (Table 2.2) from the upper-triangle parameter vector of an ``n``-branch joint."""
    m = 3 * _check_n(n) - 3
    kv = np.asarray(k, dtype=float)
    if kv.shape != (m * (m + 1) // 2,):
        raise JointModelError(
            f"an {n}-branch complex joint has {m * (m + 1) // 2} parameters, got shape {kv.shape}")
    K = np.zeros((m, m))
    K[np.triu_indices(m)] = kv
    return K + np.triu(K, 1).T


@dataclass(frozen=True)
class ComplexJoint(JointModel):
    """Complex model: ``K_U = B K_C B^T`` (eq. 4), coupling all planes (Sec. 2.3).

    ``K_C`` (Table 2.2) is the stiffness of the joint with branch ``n`` clamped, over the
    ``3n - 3`` rotations of branches ``1..n-1``; ``B`` (Table 2.3, :func:`equilibrium_matrix`)
    adds the clamped branch's reactions. ``K_U`` is Table 2.4 for ``n = 3``; it annihilates the
    rigid rotations (:func:`rigid_rotation_modes`) and has rank ``3n - 3`` when ``K_C`` is
    positive definite. Parameters: :func:`complex_param_names`.
    """

    name: str
    grids: tuple[int, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", _check_name(self.name))
        object.__setattr__(self, "grids", _check_grids(self.grids))

    @property
    def m(self) -> int:
        """``3n - 3``, the order of ``K_C``."""
        return 3 * self.n_branches - 3

    @cached_property
    def param_names(self) -> tuple[str, ...]:
        return complex_param_names(self.n_branches)

    @cached_property
    def B(self) -> np.ndarray:
        """The equilibrium matrix of eq. 4 (Table 2.3 for ``n = 3``)."""
        return equilibrium_matrix(self.n_branches)

    def kc_matrix(self, k: Sequence[float]) -> np.ndarray:
        """``K_C`` (Table 2.2) from the parameter vector."""
        return kc_from_complex_params(self._check_k(k), self.n_branches)

    def params_from_kc(self, K_C: np.ndarray) -> np.ndarray:
        """The parameter vector of a given ``K_C`` (:func:`complex_params_from_kc`)."""
        K = np.asarray(K_C, dtype=float)
        if K.shape != (self.m, self.m):
            raise JointModelError(
                f"joint {self.name!r}: K_C must be {self.m} x {self.m} (3n - 3), got {K.shape}")
        return complex_params_from_kc(K)

    @cached_property
    def _basis_cache(self) -> np.ndarray:
        m, B = self.m, self.B
        D = np.zeros((self.n_params, 3 * self.n_branches, 3 * self.n_branches))
        for q, (i, j) in enumerate(zip(*np.triu_indices(m))):
            E = np.zeros((m, m))
            E[i, j] = E[j, i] = 1.0
            D[q] = B @ E @ B.T
        D.flags.writeable = False
        return D

    def _basis(self) -> np.ndarray:
        return self._basis_cache

    def unconstrained_matrix(self, k: Sequence[float]) -> np.ndarray:
        """``K_U = B K_C B^T`` (eq. 4; Table 2.4 for ``n = 3``)."""
        K_C = self.kc_matrix(k)
        return self.B @ K_C @ self.B.T

    def is_admissible(self, k: Sequence[float], strict: bool = False) -> bool:
        """``K_C`` positive semi-definite (positive definite when ``strict``).

        Semi-definiteness allows a relative ``-1e-12 * max|lambda|`` for rounding in the
        eigenvalues; definiteness is a successful Cholesky factorization.
        """
        K_C = self.kc_matrix(k)
        if strict:
            try:
                np.linalg.cholesky(K_C)
            except np.linalg.LinAlgError:
                return False
            return True
        lam = np.linalg.eigvalsh(K_C)
        return bool(lam.min() >= -1e-12 * max(float(np.abs(lam).max()), np.finfo(float).tiny))

    def initial_params(self, value: float) -> np.ndarray:
        """``K_C = value * I`` (``initial`` in ``docs/study-format.md``)."""
        return complex_params_from_kc(float(value) * np.eye(self.m))


# --------------------------------------------------------------------------------------------
# relations between the models and to the deck
# --------------------------------------------------------------------------------------------
def simple_to_complex_params(simple: SimpleJoint, k: Sequence[float]) -> np.ndarray:
    """Complex-model parameters whose ``K_U`` equals the simple model's ``K_U(k)`` exactly.

    Any symmetric ``K_U`` with the rigid-rotation null space is ``B K_C B^T`` with ``K_C`` its
    leading ``(3n-3)`` block: writing ``K_U = [[A, C], [C^T, D]]``, ``K_U R = 0`` gives
    ``C = -A T^T`` and ``D = T A T^T`` with ``T = (I_3 ... I_3)``, which is ``B A B^T``. The
    simple model is thus the complex model with ``K_C`` = Table 2.1 minus branch n's rows and
    columns (rigid pairs included: they only remove springs).
    """
    if not isinstance(simple, SimpleJoint):
        raise JointModelError(f"simple_to_complex_params needs a SimpleJoint, got {type(simple).__name__}")
    K_U = simple.unconstrained_matrix(k)
    m = 3 * simple.n_branches - 3
    return complex_params_from_kc(K_U[:m, :m])


def spring_network(model: JointModel, k: Sequence[float]) -> list[ScalarSpring]:
    """``K_U(k)`` as scalar springs between joint rotation DOF labels (CELAS2 cards), exactly.

    A spring ``s`` between DOFs ``a`` and ``b`` adds ``s`` to ``K_aa`` and ``K_bb`` and ``-s``
    to ``K_ab``; so ``s_ab = -K_ab`` for every pair ``a < b``, and a grounded spring of
    ``g_a = sum_b K_ab`` (the row sum) makes the diagonal right. For ``K_U`` the row sums vanish:
    the all-ones vector is the sum of the three rigid rotations (:func:`rigid_rotation_modes`),
    which ``K_U`` annihilates (simple model: each spring's forces are self-equilibrated;
    complex model: ``B^T R = 0``). Grounded springs are therefore emitted only when a row sum
    exceeds rounding (``1e-12 * max|K|``); pairs with ``|K_ab| <= 1e-14 * max|K|`` (zero up to
    rounding in ``B K_C B^T``) are skipped. Negative springs are normal for the complex model.
    """
    K = model.unconstrained_matrix(k)
    labels = model.rotation_dofs
    scale = float(np.max(np.abs(K))) if K.size else 0.0
    if scale == 0.0:
        return []
    springs: list[ScalarSpring] = []
    n3 = K.shape[0]
    for a in range(n3):
        for b in range(a + 1, n3):
            kab = 0.5 * (K[a, b] + K[b, a])
            if abs(kab) > 1e-14 * scale:
                springs.append(ScalarSpring(labels[a], labels[b], float(-kab)))
    rows = K.sum(axis=1)
    for a in range(n3):
        if abs(rows[a]) > 1e-12 * scale:
            springs.append(ScalarSpring(labels[a], None, float(rows[a])))
    return springs


def make_joint(name: str, grids: Sequence[int], model: str, **options) -> JointModel:
    """A joint model by name: ``"simple"`` (options ``rigid_pairs``, ``constrained_springs``) or
    ``"complex"`` (no options)."""
    allowed = {"simple": ("rigid_pairs", "constrained_springs"), "complex": ()}
    if model not in allowed:
        raise JointModelError(f"joint {name!r}: model must be 'simple' or 'complex', got {model!r}")
    unknown = sorted(set(options) - set(allowed[model]))
    if unknown:
        raise JointModelError(
            f"joint {name!r}: unknown option(s) {unknown} for the {model} model "
            f"(allowed: {list(allowed[model]) or 'none'})")
    grids = _check_grids(grids)
    if model == "simple":
        return SimpleJoint(name, grids, tuple(tuple(p) for p in options.get("rigid_pairs", ())),
                           tuple(tuple(s) for s in options.get("constrained_springs", ())))
    return ComplexJoint(name, grids)


# --------------------------------------------------------------------------------------------
# the "actual joint" of Sec. 5.4.1
# --------------------------------------------------------------------------------------------
def frame_element_stiffness(xa: Sequence[float], xb: Sequence[float], E: float, G: float,
                            A: float, Iy: float, Iz: float, J: float,
                            orientation: Sequence[float] | None = None) -> np.ndarray:
    """Global ``12 x 12`` stiffness of a 3-D Euler-Bernoulli frame element from ``xa`` to ``xb``.

    DOFs ``(u, v, w, theta_x, theta_y, theta_z)`` at end a, then at end b, global axes. Local
    ``x`` runs from a to b; local ``y`` is the part of ``orientation`` normal to ``x`` (default:
    global z, or global y when the element is parallel to z), local ``z = x cross y`` -- as
    the CBAR orientation vector. ``Iz`` resists bending in the local x-y plane (``v``,
    ``theta_z``), ``Iy`` in the local x-z plane (``w``, ``theta_y``); ``J`` is the torsion
    constant (``G J / L``). No shear deformation.
    """
    xa, xb = np.asarray(xa, dtype=float), np.asarray(xb, dtype=float)
    d = xb - xa
    L = float(np.linalg.norm(d))
    if not L > 0:
        raise JointModelError("frame element of zero length")
    e1 = d / L
    if orientation is None:
        orientation = (0.0, 0.0, 1.0) if abs(e1[2]) < 0.9 else (0.0, 1.0, 0.0)
    v = np.asarray(orientation, dtype=float)
    e2 = v - (v @ e1) * e1
    if np.linalg.norm(e2) < 1e-9 * max(np.linalg.norm(v), 1.0):
        raise JointModelError(f"orientation vector {v.tolist()} is parallel to the element axis")
    e2 /= np.linalg.norm(e2)
    e3 = np.cross(e1, e2)

    k = np.zeros((12, 12))
    ea, gj = E * A / L, G * J / L
    k[np.ix_([0, 6], [0, 6])] = ea * np.array([[1, -1], [-1, 1]])
    k[np.ix_([3, 9], [3, 9])] = gj * np.array([[1, -1], [-1, 1]])
    # bending in local x-y plane: v1, tz1, v2, tz2 (Iz)
    bz = E * Iz / L ** 3 * np.array([[12, 6 * L, -12, 6 * L],
                                     [6 * L, 4 * L * L, -6 * L, 2 * L * L],
                                     [-12, -6 * L, 12, -6 * L],
                                     [6 * L, 2 * L * L, -6 * L, 4 * L * L]])
    k[np.ix_([1, 5, 7, 11], [1, 5, 7, 11])] = bz
    # bending in local x-z plane: w1, ty1, w2, ty2 (Iy); theta_y = -dw/dx flips the couplings
    by = E * Iy / L ** 3 * np.array([[12, -6 * L, -12, -6 * L],
                                     [-6 * L, 4 * L * L, 6 * L, 2 * L * L],
                                     [-12, 6 * L, 12, 6 * L],
                                     [-6 * L, 2 * L * L, 6 * L, 4 * L * L]])
    k[np.ix_([2, 4, 8, 10], [2, 4, 8, 10])] = by
    R = np.vstack([e1, e2, e3])
    T = np.kron(np.eye(4), R)
    return T.T @ k @ T


def actual_joint_stub_kc(directions: Sequence[Sequence[float]], length: float, E: float,
                         G: float, A: float, Iy: float, Iz: float, J: float,
                         orientation_vectors: Sequence[Sequence[float]] | None = None) -> np.ndarray:
    """``K_C`` of the stub-frame "actual joint" of Sec. 5.4.1, ``(3n-3) x (3n-3)``.

    Interpretation of "a three member joint of equal length ... clamped at one of the ends and
    hinged at the remaining two ends. The 6 d.o.f. at the hinged ends form the boundary d.o.f.
    The stiffness matrix is reduced in terms of the boundary d.o.f.": ``n`` frame stubs
    (:func:`frame_element_stiffness`) of length ``length`` from a common centre node along the
    unit vectors ``directions[b]`` (from the joint into branch ``b``'s member). Branch ``n``'s far
    end is clamped; the other far ends are hinged (translations fixed, rotations free); the
    centre node's 6 DOFs are condensed out statically. The result is the stiffness over the
    rotations ``(theta_x, theta_y, theta_z)`` of far ends ``1..n-1`` in global axes -- the
    ``K_C`` of eq. 4 / Table 2.2 (symmetric positive definite). Bending terms scale like
    ``1/length`` (``4EI/L``), so the stub length sets how flexible the joint is.

    Check against Table 5.12 (cube joint at node 7, Table 3.1 members, ``length = 1e-2``; both
    tables are in :mod:`blackbox.reference_tables`): with branch 1 towards node 3 (-z), branch 2
    towards node 8 (-x) and branch 3 towards node 6 (-y, clamped) every entry's sign and ratio
    agree to the table's 4 digits, but the table is ``10 x`` this ``K_C`` (as if ``E, G`` -- or
    ``A, I, J`` -- were ten times Table 3.1's); the table's ``k13 = 0.7508E5`` is ``0.7805E5``
    here (= its own ``k23, k45, k46``, as the joint's x<->z mirror symmetry requires) and its
    ``k34 = -0.1530E4`` has the opposite sign here. Other branch orders or free far-end
    translations do not reproduce the pattern.
    """
    D = np.asarray(directions, dtype=float)
    if D.ndim != 2 or D.shape[1] != 3 or D.shape[0] < 2:
        raise JointModelError(f"directions must be an (n, 3) array with n >= 2, got shape {D.shape}")
    norms = np.linalg.norm(D, axis=1)
    if np.any(norms == 0) or not np.all(np.isfinite(D)):
        raise JointModelError("every stub direction must be a finite non-zero vector")
    D = D / norms[:, None]
    for label, val in (("length", length), ("E", E), ("G", G), ("A", A), ("Iy", Iy),
                       ("Iz", Iz), ("J", J)):
        if not (np.isfinite(val) and val > 0):
            raise JointModelError(f"stub property {label} must be finite and > 0, got {val!r}")
    n = D.shape[0]
    if orientation_vectors is not None and len(orientation_vectors) != n:
        raise JointModelError(f"need one orientation vector per stub ({n}), got {len(orientation_vectors)}")

    nn = n + 1                                      # node 0 = centre, node b = far end of stub b
    K = np.zeros((6 * nn, 6 * nn))
    for b in range(n):
        ov = None if orientation_vectors is None else orientation_vectors[b]
        ke = frame_element_stiffness(np.zeros(3), length * D[b], E, G, A, Iy, Iz, J, ov)
        idx = np.r_[0:6, 6 * (b + 1):6 * (b + 2)]
        K[np.ix_(idx, idx)] += ke
    bnd = [6 * b + c for b in range(1, n) for c in (3, 4, 5)]   # free-end rotations
    cen = list(range(6))                                          # condensed
    K_bb = K[np.ix_(bnd, bnd)]
    K_bc = K[np.ix_(bnd, cen)]
    K_cc = K[np.ix_(cen, cen)]
    K_C = K_bb - K_bc @ np.linalg.solve(K_cc, K_bc.T)
    return 0.5 * (K_C + K_C.T)
