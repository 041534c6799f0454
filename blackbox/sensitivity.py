"""Sensitivity of the response to the joint parameters (Section 3.2).

* :func:`direct` -- the direct method in the condensed space (eq. 18): no solver run.
* :func:`semi_analytic` -- eq. 18 with ``dK_J/dk`` approximated by finite differences of the
  joint matrix (Section 3.2.4): still no solver run.
* :func:`finite_difference` -- forward (eq. 6) or central (eq. 7) differences on the *full*
  model: the joint is put into the structure as scalar springs (CELAS2 cards for a NASTRAN-type
  code, :func:`blackbox.joints.spring_network`) and the whole structure is re-solved, one solver
  run (one factorization) per perturbed parameter value: ``n`` runs forward, ``2n`` central.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from blackbox.condensation import CondensedModel
from blackbox.joints import JointModel, spring_network
from solver_adapters.protocol import DofLabel, LoadMatrix, ScalarSpring, SolverAdapter


def direct(model: CondensedModel, k: np.ndarray, dofs: Sequence[DofLabel]) -> np.ndarray:
    """``dU/dk`` at ``dofs`` for every case, shape ``(n_params, len(dofs), L)`` (eq. 18)."""
    return model.pick_sensitivities(model.sensitivities(np.asarray(k, float)), dofs)


def semi_analytic(model: CondensedModel, k: np.ndarray, dofs: Sequence[DofLabel],
                  rel_step: float = 1e-6) -> np.ndarray:
    """Eq. 18 with ``dK_J/dk_i ~ (K_J(k + h e_i) - K_J(k)) / h``, ``h = rel_step * max(|k_i|, 1)``."""
    k = np.asarray(k, float)
    K0 = model.assembly.matrix(k)
    D = np.empty((k.size,) + K0.shape)
    for i in range(k.size):
        h = rel_step * max(abs(k[i]), 1.0)
        kp = k.copy()
        kp[i] += h
        D[i] = (model.assembly.matrix(kp) - K0) / h
    return model.pick_sensitivities(model.sensitivities(k, D=D), dofs)


def joint_springs(joints: Sequence[JointModel], k: np.ndarray,
                  deck_joints: Sequence[tuple[JointModel, np.ndarray]] = ()) -> list[ScalarSpring]:
    """Scalar springs that put the joints into the full model; springs already in the deck
    (``deck_joints``: model and its parameters) are cancelled by springs of opposite sign."""
    springs: list[ScalarSpring] = []
    start = 0
    for j in joints:
        springs += spring_network(j, np.asarray(k, float)[start:start + j.n_params])
        start += j.n_params
    for j, kd in deck_joints:
        springs += [ScalarSpring(s.a, s.b, -s.k) for s in spring_network(j, kd)]
    return springs


def full_response(adapter: SolverAdapter, joints: Sequence[JointModel], k: np.ndarray,
                  loads: LoadMatrix, dofs: Sequence[DofLabel],
                  deck_joints: Sequence[tuple[JointModel, np.ndarray]] = ()) -> np.ndarray:
    """One solve of the full structure with the joints in the deck: ``(len(dofs), L)``."""
    full = adapter.with_springs(joint_springs(joints, k, deck_joints))
    out = full.solve(loads, dofs)
    _absorb_stats(adapter, full)
    return out.values


def finite_difference(adapter: SolverAdapter, joints: Sequence[JointModel], k: np.ndarray,
                      loads: LoadMatrix, dofs: Sequence[DofLabel], scheme: str = "forward",
                      rel_step: float = 1e-4, base: np.ndarray | None = None,
                      deck_joints: Sequence[tuple[JointModel, np.ndarray]] = ()) -> np.ndarray:
    """``dU/dk`` by re-solving the full model (eq. 6 or 7), shape ``(n_params, len(dofs), L)``.

    ``base`` is ``U(k)`` if the caller already has it (forward differences need it).
    Step ``h_i = rel_step * max|k_j|`` over the parameters of ``k_i``'s joint (a small
    off-diagonal K_C entry stepped relative to itself would move the response below round-off;
    absolute ``rel_step`` when the joint's parameters are all 0).
    """
    if scheme not in ("forward", "central"):
        raise ValueError(f"scheme must be 'forward' or 'central', got {scheme!r}")
    k = np.asarray(k, float)
    if scheme == "forward" and base is None:
        base = full_response(adapter, joints, k, loads, dofs, deck_joints)
    out = np.empty((k.size, len(dofs), loads.n_cases))
    scale = np.concatenate([np.full(j.n_params, np.max(np.abs(k[a:a + j.n_params])))
                            for j, a in zip(joints, np.cumsum([0] + [j.n_params for j in joints])[:-1])])
    for i in range(k.size):
        h = rel_step * scale[i] if scale[i] != 0 else rel_step
        kp = k.copy()
        kp[i] += h
        up = full_response(adapter, joints, kp, loads, dofs, deck_joints)
        if scheme == "forward":
            out[i] = (up - base) / h
        else:
            km = k.copy()
            km[i] -= h
            out[i] = (up - full_response(adapter, joints, km, loads, dofs, deck_joints)) / (2 * h)
    return out


def _absorb_stats(parent: SolverAdapter, child: SolverAdapter) -> None:
    """Count a derived adapter's runs on the adapter the caller holds (for the benchmark)."""
    if child is parent:
        return
    s, c = parent.stats, child.stats
    s.runs += c.runs
    s.right_hand_sides += c.right_hand_sides
    s.factorizations += c.factorizations
    s.wall_s += c.wall_s
    s.peak_rss_bytes = max(s.peak_rss_bytes, c.peak_rss_bytes)
