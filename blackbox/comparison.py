"""Comparison of the simple and the complex joint model (Chapter 6, eq. 34-35).

Both models are identified from the same measurements with ONE solver run: the condensation
(:func:`blackbox.condensation.condense`) depends only on the boundary DOFs, which are the same
``3 + 3n`` joint DOFs for both models, so one :class:`Condensed` feeds two
:class:`CondensedModel` s and :func:`identify` runs twice (:func:`identify_both`).

The fitted models are then compared under the loading that separates them most, the *maximum
difference in strain energies* (MDSE) loading: the ``F`` maximising (eq. 34)::

    (E_complex - E_simple) / L_f,   E = 1/2 F^T C F  (eq. 35a-b),   L_f = 1/2 F^T F  (eq. 35c)

For flexibility matrices ``C`` the quotient is the Rayleigh quotient of ``D = C_complex -
C_simple``: its maximum is the largest eigenvalue of ``D`` and the loading is the eigenvector
(Strang [38]); :func:`mdse_load` normalises it so that its largest component is ``+1``
(Table 6.2). Two flexibilities are compared:

* **isolated joint** (Tables 6.2-6.4): branch ``n`` clamped, so the joint is statically
  determinate and ``C = K_C^-1`` over the ``3n - 3`` rotations of branches ``1..n-1``. For the
  simple model ``K_C`` is the leading ``(3n-3)`` block of its ``K_U`` (the same block that
  :func:`blackbox.joints.simple_to_complex_params` returns), for the complex model its ``K_C``
  (:func:`clamped_stiffness` covers both, and any other joint model);
* **joint in the structure** (Table 6.5, Figure 6.2): the assembly flexibility at the joint's
  ``3n`` rotation DOFs, ``(K_R + K_J)^-1 = (I + G_BB dK)^-1 G_BB`` with ``dK = K_J - K_deck``
  from the one :class:`Condensed` (:func:`assembly_flexibility`), also for an infinitely
  flexible joint (``K_J = 0``).

The assembly loading is restricted to the rotations (moments), as in Table 6.5: eq. 34 weighs
all components of ``F`` alike, so mixing forces (N) and moments (N*m) would make the loading
depend on the length unit.

Several joints are compared joint by joint: for joint ``j`` only its model changes (simple fit,
complex fit, ``K_J = 0``, truth), every other joint stays at its complex estimate, so the
differences are due to joint ``j`` alone.

Energies are ``1/2 F^T C F`` (eq. 35). The dissertation's Tables 6.3, 6.7, 6.10 and 6.14
list ``F^T u = F^T C F`` -- twice that (e.g. Table 6.3's ``E_complex = 0.3358E-5`` is Table
6.4's ``F . u``); the relative difference ``R`` is the same either way.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import numpy as np
from scipy import stats

from blackbox.condensation import Condensed, CondensedModel
from blackbox.errors import ComparisonError
from blackbox.identification import IdentificationResult, Observations, identify
from blackbox.joints import JointModel, SimpleJoint, simple_to_complex_params
from solver_adapters.protocol import DofLabel

__all__ = ["ComparisonError", "MDSE", "Stage", "JointComparison", "ModelFits", "clamped_stiffness",
           "isolated_flexibility", "assembly_flexibility", "mdse_load", "strain_energy",
           "evaluate_load", "compare_flexibilities", "compare_joints", "identify_both",
           "append_case", "dof_name", "likelihood_ratio", "energy_uncertainty"]

_AXES = "xyz"
_COND_MAX = 1e14        # a flexibility solve worse conditioned than this is a mechanism


# --------------------------------------------------------------------------------------------
# flexibilities
# --------------------------------------------------------------------------------------------
def clamped_stiffness(joint: JointModel, k: Sequence[float]) -> np.ndarray:
    """``K_C``: the stiffness of the isolated joint with branch ``n`` clamped, ``(3n-3)^2``.

    Any ``K_U`` that annihilates the rigid rotations is ``B K_C B^T`` with ``K_C`` its leading
    ``(3n-3)`` block (:func:`blackbox.joints.simple_to_complex_params`): the complex model's
    ``K_C`` and the simple model's Table 2.1 without branch ``n``'s rows and columns.
    """
    m = 3 * joint.n_branches - 3
    return joint.unconstrained_matrix(k)[:m, :m]


def _inverse_spd(K: np.ndarray, what: str) -> np.ndarray:
    K = 0.5 * (K + K.T)
    lam = np.linalg.eigvalsh(K)
    if not lam.min() > max(abs(lam.max()), np.finfo(float).tiny) / _COND_MAX:
        raise ComparisonError(f"{what} is not positive definite (eigenvalues {lam.min():.3g} .. "
                              f"{lam.max():.3g}): the joint is a mechanism, it has no flexibility")
    C = np.linalg.inv(K)
    return 0.5 * (C + C.T)


def isolated_flexibility(joint: JointModel, k: Sequence[float]) -> np.ndarray:
    """``K_C^-1`` (eq. 35 for the isolated joint, branch ``n`` clamped)."""
    return _inverse_spd(clamped_stiffness(joint, k), f"K_C of joint {joint.name!r} ({joint.model_name} model)")


def _scatter(boundary: Sequence[DofLabel], parts: Sequence[tuple[JointModel, np.ndarray | None]]) -> np.ndarray:
    """``K_J`` over the boundary from ``(joint, k)`` pairs; ``k = None`` is ``K_J = 0``."""
    index = {d: i for i, d in enumerate(boundary)}
    K = np.zeros((len(boundary), len(boundary)))
    for joint, k in parts:
        if k is None:
            continue
        try:
            idx = np.array([index[d] for d in joint.dofs])
        except KeyError as exc:
            raise ComparisonError(f"joint {joint.name!r}: DOF {exc.args[0]} is not a boundary DOF "
                                  f"of the condensation") from None
        K[np.ix_(idx, idx)] += joint.matrix(k)
    return K


def assembly_flexibility(condensed: Condensed, K_J: np.ndarray, K_deck: np.ndarray | None = None,
                         dofs: Sequence[DofLabel] | None = None) -> np.ndarray:
    """The structure's flexibility at boundary DOFs with the joints ``K_J`` added (eq. 22):
    ``(K_R + dK)^-1 = (I + G_BB dK)^-1 G_BB``, ``dK = K_J - K_deck``; rows and columns ``dofs``
    (default: all boundary DOFs). No solver run."""
    G = condensed.G_BB
    nB = G.shape[0]
    dK = np.asarray(K_J, float) - (np.zeros((nB, nB)) if K_deck is None else np.asarray(K_deck, float))
    A = np.eye(nB) + G @ dK
    # A = G (G^-1 + dK): with dK positive semidefinite (joints added, nothing taken out of the deck)
    # it is never singular, however stiff a joint -- a large condition number then only says the
    # joint is near rigid, and the solve stays accurate. Only a negative dK (a joint softer than
    # springs already in the deck) can make a mechanism.
    semidefinite = float(np.linalg.eigvalsh(0.5 * (dK + dK.T))[0]) >= -1e-12 * max(float(np.abs(dK).max()), 1e-300)
    if not semidefinite and np.linalg.cond(A) > _COND_MAX:
        raise ComparisonError("the structure with these joint stiffnesses is a mechanism "
                              "((I + G_BB dK) is singular): no flexibility")
    C = np.linalg.solve(A, G)
    if not np.all(np.isfinite(C)):
        raise ComparisonError("the structure's flexibility with these joint stiffnesses is not finite")
    C = 0.5 * (C + C.T)
    if dofs is None:
        return C
    index = {d: i for i, d in enumerate(condensed.boundary)}
    idx = np.array([index[(int(g), int(c))] for g, c in dofs])
    return C[np.ix_(idx, idx)]


# --------------------------------------------------------------------------------------------
# eq. 34-35
# --------------------------------------------------------------------------------------------
def strain_energy(flex: np.ndarray, F: np.ndarray) -> float:
    """``E = 1/2 F^T C F`` (eq. 35a-b)."""
    F = np.asarray(F, float)
    return float(0.5 * F @ np.asarray(flex, float) @ F)


def mdse_load(flex_complex: np.ndarray, flex_simple: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The MDSE loading (eq. 34): the eigenvector of the largest eigenvalue of
    ``D = C_complex - C_simple``, scaled so that its largest-magnitude component is ``+1``.

    Returns ``(load, eigenvalues descending, eigenvectors as columns in that order)``; the
    eigenvalue ``lambda_max = max_F (E_complex - E_simple) / L_f`` for unit-length ``F``.
    """
    D = np.asarray(flex_complex, float) - np.asarray(flex_simple, float)
    if D.ndim != 2 or D.shape[0] != D.shape[1]:
        raise ComparisonError(f"flexibility matrices must be square and alike, got {D.shape}")
    lam, V = np.linalg.eigh(0.5 * (D + D.T))
    order = np.argsort(lam)[::-1]
    lam, V = lam[order], V[:, order]
    v = V[:, 0]
    load = v / v[np.argmax(np.abs(v))]
    return load, lam, V


@dataclass(frozen=True, eq=False)
class MDSE:
    """One comparison under one loading ``load`` on ``dofs``: energies ``1/2 F^T C F`` and
    displacements ``C F`` of every flexibility in ``flex`` (keys ``complex``, ``simple`` and
    optionally ``infinitely_flexible``, ``truth``)."""
    dofs: tuple[DofLabel, ...]
    names: tuple[str, ...]                  # readable DOF names, e.g. theta_x2
    load: np.ndarray
    eigenvalues: np.ndarray                 # of C_complex - C_simple, descending (nan if not computed)
    flex: Mapping[str, np.ndarray]
    energies: Mapping[str, float]
    displacements: Mapping[str, np.ndarray]

    @property
    def relative_difference(self) -> float:
        """``R = (E_complex - E_simple) / E_complex`` (Table 6.3)."""
        return (self.energies["complex"] - self.energies["simple"]) / self.energies["complex"]

    @property
    def truth_difference(self) -> float | None:
        """``(E_truth - E_simple) / E_truth`` when a truth is known: the coupling the simple
        model misses, free of the complex fit's estimation error."""
        if "truth" not in self.energies:
            return None
        return (self.energies["truth"] - self.energies["simple"]) / self.energies["truth"]

    @property
    def dominant(self) -> int:
        """Index of the load's largest component."""
        return int(np.argmax(np.abs(self.load)))

    @property
    def dominant_share(self) -> float:
        """Share of the load's squared length in its largest component (1 = a pure unit load)."""
        return float(self.load[self.dominant] ** 2 / (self.load @ self.load))

    def error_ratio(self) -> float | None:
        """``|E_simple - E_complex| / |E_inf - E_complex|``: the simple model's energy error as a
        fraction of the error of an infinitely flexible joint (dissertation: ~30 %)."""
        if "infinitely_flexible" not in self.energies:
            return None
        den = self.energies["infinitely_flexible"] - self.energies["complex"]
        return abs(self.energies["simple"] - self.energies["complex"]) / abs(den) if den else float("inf")

    def to_json(self) -> dict:
        out = {"dofs": [list(d) for d in self.dofs], "names": list(self.names),
               "mdse_load": self.load.tolist(),
               "dominant": {"dof": list(self.dofs[self.dominant]), "name": self.names[self.dominant],
                            "share": self.dominant_share},
               "eigenvalues": [float(x) if np.isfinite(x) else None for x in self.eigenvalues],
               "strain_energy": {**{k: float(v) for k, v in self.energies.items()},
                                 "relative_difference": self.relative_difference},
               "displacements": {k: v.tolist() for k, v in self.displacements.items()}}
        if self.truth_difference is not None:
            out["strain_energy"]["relative_difference_truth_vs_simple"] = self.truth_difference
        ratio = self.error_ratio()
        if ratio is not None:
            out["strain_energy"]["simple_error_over_infinitely_flexible_error"] = ratio
        return out


def evaluate_load(dofs: Sequence[DofLabel], names: Sequence[str], flex: Mapping[str, np.ndarray],
                  load: np.ndarray, eigenvalues: np.ndarray | None = None) -> MDSE:
    """Energies and displacements of every flexibility under a given load."""
    load = np.asarray(load, float)
    en = {k: strain_energy(C, load) for k, C in flex.items()}
    disp = {k: np.asarray(C, float) @ load for k, C in flex.items()}
    ev = np.full(len(load), np.nan) if eigenvalues is None else np.asarray(eigenvalues, float)
    return MDSE(tuple(dofs), tuple(names), load, ev, dict(flex), en, disp)


def compare_flexibilities(dofs: Sequence[DofLabel], names: Sequence[str],
                          flex: Mapping[str, np.ndarray]) -> MDSE:
    """The MDSE loading of ``flex["complex"]`` vs ``flex["simple"]`` and every flexibility's
    energy and displacements under it."""
    if "complex" not in flex or "simple" not in flex:
        raise ComparisonError(f"need the 'complex' and 'simple' flexibilities, got {sorted(flex)}")
    load, lam, _ = mdse_load(flex["complex"], flex["simple"])
    return evaluate_load(dofs, names, flex, load, lam)


def dof_name(joint: JointModel, dof: DofLabel) -> str:
    """``theta_x2`` for rotation x of branch 2, ``u_y`` for a translation (of branch 1's grid)."""
    g, c = int(dof[0]), int(dof[1])
    if c <= 3:
        return f"u_{_AXES[c - 1]}"
    return f"theta_{_AXES[c - 4]}{joint.grids.index(g) + 1}"


# --------------------------------------------------------------------------------------------
# both models, joint by joint
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class JointComparison:
    """Chapter 6 for one joint: the isolated joint (Tables 6.2-6.4) and the joint in the
    structure (Table 6.5, Figure 6.2)."""
    name: str
    n_branches: int
    isolated: MDSE
    assembly: MDSE

    def to_json(self) -> dict:
        return {"name": self.name, "n_branches": self.n_branches,
                "isolated": self.isolated.to_json(), "assembly": self.assembly.to_json()}


def _split(joints: Sequence[JointModel], k: np.ndarray) -> list[np.ndarray]:
    out, i = [], 0
    for j in joints:
        out.append(np.asarray(k[i:i + j.n_params], float))
        i += j.n_params
    if i != len(k):
        raise ComparisonError(f"{len(k)} parameters given for joints needing {i}")
    return out


def compare_joints(condensed: Condensed, simple_joints: Sequence[JointModel], k_simple: np.ndarray,
                   complex_joints: Sequence[JointModel], k_complex: np.ndarray,
                   K_deck: np.ndarray | None = None,
                   truth: Mapping[str, tuple[JointModel, np.ndarray]] | None = None,
                   loads: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None) -> list[JointComparison]:
    """Chapter 6 for every joint (same order and grids in both joint lists).

    ``truth``: ``{joint name: (model, k)}`` whose flexibilities are added to the comparison
    (never used to choose the loading). ``loads``: ``{joint name: (isolated load, assembly
    load)}`` to evaluate given loadings instead of computing the MDSE ones (Table 6.7 with
    the loading of Table 6.2, say)."""
    if [j.grids for j in simple_joints] != [j.grids for j in complex_joints]:
        raise ComparisonError("the simple and the complex joint lists must describe the same joints")
    ks, kc = _split(simple_joints, k_simple), _split(complex_joints, k_complex)
    truth = dict(truth or {})
    out = []
    for j, (sj, cj) in enumerate(zip(simple_joints, complex_joints)):
        m = 3 * cj.n_branches - 3
        iso_dofs = cj.rotation_dofs[:m]
        iso = {"complex": isolated_flexibility(cj, kc[j]), "simple": isolated_flexibility(sj, ks[j])}
        if cj.name in truth:
            tj, tk = truth[cj.name]
            iso["truth"] = isolated_flexibility(tj, tk)

        others = [(c, k) for i, (c, k) in enumerate(zip(complex_joints, kc)) if i != j]

        def flex_with(model: JointModel, k: np.ndarray | None) -> np.ndarray:
            return assembly_flexibility(condensed, _scatter(condensed.boundary, others + [(model, k)]),
                                        K_deck, cj.rotation_dofs)

        asm = {"complex": flex_with(cj, kc[j]), "simple": flex_with(sj, ks[j]),
               "infinitely_flexible": flex_with(cj, None)}
        if cj.name in truth:
            asm["truth"] = flex_with(*truth[cj.name])
        iso_names = [dof_name(cj, d) for d in iso_dofs]
        asm_names = [dof_name(cj, d) for d in cj.rotation_dofs]
        if loads and cj.name in loads:
            li, la = loads[cj.name]
            lam_i = mdse_load(iso["complex"], iso["simple"])[1]
            lam_a = mdse_load(asm["complex"], asm["simple"])[1]
            a = evaluate_load(iso_dofs, iso_names, iso, li, lam_i)
            b = evaluate_load(cj.rotation_dofs, asm_names, asm, la, lam_a)
        else:
            a = compare_flexibilities(iso_dofs, iso_names, iso)
            b = compare_flexibilities(cj.rotation_dofs, asm_names, asm)
        out.append(JointComparison(cj.name, cj.n_branches, a, b))
    return out


@dataclass(frozen=True, eq=False)
class Stage:
    """One identification of both models on a study's data, and their comparison."""
    n_measurements: int
    cases: tuple[str, ...]                                  # the study's load cases
    fits: "ModelFits"
    joints: list["JointComparison"]
    uncertainty: list[dict]                                 # energy_uncertainty, per joint
    fixed_load: list["JointComparison"] | None = None      # under an earlier stage's MDSE loadings


# --------------------------------------------------------------------------------------------
# identification of both models from one condensation
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ModelFits:
    """Both identifications on the same data and condensation."""
    simple: IdentificationResult
    complex: IdentificationResult
    simple_model: CondensedModel
    complex_model: CondensedModel
    complex_start: str          # "simple fit" or "initial"


def likelihood_ratio(fits: ModelFits) -> dict:
    """The simple model is the complex one with ``K_C`` restricted (nested): ``chi2_simple -
    chi2_complex`` is ~chi2(p_complex - p_simple) if the simple model is right. Approximate:
    springs at their bound 0 violate the regularity conditions (the p-value is then conservative)."""
    s, c = fits.simple, fits.complex
    stat = float(s.chi2 - c.chi2)
    dof = int(c.n_params - s.n_params)
    p = float(stats.chi2.sf(max(stat, 0.0), dof)) if dof > 0 else float("nan")
    return {"statistic": stat, "dof": dof, "p_value": p,
            "delta_bic": float(c.bic - s.bic), "preferred_by_bic": "complex" if c.bic < s.bic else "simple"}


def identify_both(condensed: Condensed, simple_joints: Sequence[JointModel],
                  complex_joints: Sequence[JointModel], obs: Observations, k0_simple: np.ndarray,
                  k0_complex: np.ndarray, K_deck: np.ndarray | None = None,
                  holdout: Observations | None = None, **options) -> ModelFits:
    """Identify the simple and the complex model on one condensation (no solver run).

    The complex fit starts from the simple fit's ``K_C`` (:func:`simple_to_complex_params`, the
    complex model that reproduces the simple fit exactly, so the complex fit can only improve
    on it) when that is admissible; if that start fails to converge, or is not admissible, from
    ``k0_complex`` (the study's ``initial``); the lower chi-square is kept."""
    ms = CondensedModel(condensed, simple_joints, K_deck)
    mc = CondensedModel(condensed, complex_joints, K_deck)
    rs = identify(ms, obs, k0_simple, holdout=holdout, **options)
    start = None
    if all(isinstance(j, SimpleJoint) for j in simple_joints):
        start = np.concatenate([simple_to_complex_params(j, k)
                                for j, k in zip(simple_joints, _split(simple_joints, rs.k))])
        if start.shape != np.shape(k0_complex) or not all(
                c.is_admissible(k, strict=True) for c, k in zip(complex_joints, _split(complex_joints, start))):
            start = None
    rc, how = None, "initial"
    if start is not None:
        rc, how = identify(mc, obs, start, holdout=holdout, **options), "simple fit"
    if rc is None or not rc.converged:
        alt = identify(mc, obs, k0_complex, holdout=holdout, **options)
        if rc is None or alt.chi2 < rc.chi2 or (alt.converged and not rc.converged):
            rc, how = alt, "initial"
    return ModelFits(rs, rc, ms, mc, how)


def _draws(result: IdentificationResult, joints: Sequence[JointModel], n: int,
           rng: np.random.Generator) -> np.ndarray | None:
    """``n`` parameter vectors from ``N(k, covariance)`` (natural parameters), admissible ones
    only: simple-model springs clipped at the estimator's floor (1e-6 x the joint's stiffest, a
    spring at its bound stays there), complex draws with a ``K_C`` that is not positive definite
    dropped. None when a parameter is not identifiable (the spread is then unbounded)."""
    if not np.all(result.identifiable) or not np.all(np.isfinite(result.covariance)):
        return None
    w, V = np.linalg.eigh(0.5 * (result.covariance + result.covariance.T))
    X = result.k + rng.standard_normal((n, len(result.k))) @ (V * np.sqrt(np.clip(w, 0, None))).T
    ok = np.ones(n, dtype=bool)
    i = 0
    for j in joints:
        sl = slice(i, i + j.n_params)
        i += j.n_params
        if isinstance(j, SimpleJoint):
            X[:, sl] = np.maximum(X[:, sl], 1e-6 * float(np.max(result.k[sl])))
        else:
            ok &= np.array([j.is_admissible(x[sl], strict=True) for x in X])
    return X[ok]


def energy_uncertainty(condensed: Condensed, fits: ModelFits, comps: Sequence[JointComparison],
                       K_deck: np.ndarray | None = None, n: int = 1000, seed: int = 0,
                       confidence: float = 0.95) -> list[dict]:
    """Spread of the energies and of ``R`` at each comparison's (fixed) loading when both fits
    vary within their covariances: draws from ``N(k, cov)`` of each model, independently
    (:func:`_draws`). ``R`` of fitted models contains their estimation error -- a poorly
    determined complex fit makes the MDSE loading find its error, not the coupling -- and this
    says how much. The loading itself is held fixed (it was chosen to maximise the difference on
    these very estimates, so ``R`` is if anything biased upward). Per joint:
    ``{"isolated"|"assembly": {"relative_difference_std", "relative_difference_interval",
    "energy_std": {...}, "energy_interval": {...}, "draws"}}`` or None where a parameter is not
    identifiable."""
    rng = np.random.default_rng(seed)
    sj, cj = fits.simple_model.assembly.joints, fits.complex_model.assembly.joints
    Xs, Xc = _draws(fits.simple, sj, n, rng), _draws(fits.complex, cj, n, rng)
    out = []
    a = 50.0 * (1.0 - confidence)
    for j, comp in enumerate(comps):
        if Xs is None or Xc is None or not len(Xs) or not len(Xc):
            out.append({"isolated": None, "assembly": None})
            continue
        m = min(len(Xs), len(Xc))
        rows = {"isolated": [], "assembly": []}
        for xs, xc in zip(Xs[:m], Xc[:m]):
            ks, kc = _split(sj, xs), _split(cj, xc)
            Fi, Fa = comp.isolated.load, comp.assembly.load
            ei = (strain_energy(isolated_flexibility(cj[j], kc[j]), Fi),
                  strain_energy(isolated_flexibility(sj[j], ks[j]), Fi))
            others = [(c, k) for i, (c, k) in enumerate(zip(cj, kc)) if i != j]
            fa = [assembly_flexibility(condensed, _scatter(condensed.boundary, others + [(mdl, k)]), K_deck,
                                       cj[j].rotation_dofs) for mdl, k in ((cj[j], kc[j]), (sj[j], ks[j]))]
            ea = (strain_energy(fa[0], Fa), strain_energy(fa[1], Fa))
            rows["isolated"].append(ei)
            rows["assembly"].append(ea)
        res = {}
        for key, v in rows.items():
            E = np.array(v)
            R = (E[:, 0] - E[:, 1]) / E[:, 0]
            res[key] = {"relative_difference_std": float(np.std(R, ddof=1)),
                        "relative_difference_interval": [float(x) for x in np.percentile(R, [a, 100 - a])],
                        "energy_std": {"complex": float(np.std(E[:, 0], ddof=1)),
                                       "simple": float(np.std(E[:, 1], ddof=1))},
                        # the energies' spread is skewed (E ~ 1/k): percentiles, not +- std, bound it
                        "energy_interval": {"complex": [float(x) for x in np.percentile(E[:, 0], [a, 100 - a])],
                                            "simple": [float(x) for x in np.percentile(E[:, 1], [a, 100 - a])]},
                        "confidence": confidence, "draws": int(m)}
        out.append(res)
    return out


def append_case(condensed: Condensed, F_B: np.ndarray, label: str) -> Condensed:
    """The condensation with one more load case applied at boundary DOFs only, by superposition:
    ``U_B0 = G_BB F_B``, ``U_O0 = G_OB F_B`` (the unit-load columns already hold the response to
    any boundary load). No solver run."""
    F = np.asarray(F_B, float).reshape(-1)
    if F.shape != (len(condensed.boundary),):
        raise ComparisonError(f"a boundary load needs {len(condensed.boundary)} values, got {F.shape}")
    if label in condensed.cases:
        raise ComparisonError(f"load case {label!r} already exists")
    return replace(condensed, cases=condensed.cases + (str(label),),
                   U_B0=np.column_stack([condensed.U_B0, condensed.G_BB @ F]),
                   U_O0=np.column_stack([condensed.U_O0, condensed.G_OB @ F]))
