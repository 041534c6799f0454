"""Design of the static test before it is run: which loads, which sensors (Ch. 4-6 turned around).

The identification of Chapter 4 ends with the covariance ``(J^T V_m^-1 J)^-1`` of the estimate
(Sec. 4.4; ``J`` the eq. 18 sensitivities). That matrix depends on the loads applied and the DOFs
measured, not on the measured values, so it can be computed *before* the test from a prior guess
of the joint parameters, and the test chosen to make it small.

**One solver run for every candidate.** The candidate loads (single-DOF loads, ``value`` each)
become unit loads in the one batched condensation (:meth:`blackbox.declared.DeclaredModel.condense`,
Sec. 3.4) together with the joint boundary, the candidate sensors its observed DOFs. Any plan's
response and sensitivities then follow by superposition (``value`` times the unit column): the
whitened sensitivity of sensor ``j`` in the case "load ``i``" is

    g_ij = value_i dU_j/dk (k_prior) / sigma_ij                    (eq. 18 at the unit case)

and the Fisher information of a plan (loads ``L``, sensors ``S``, every sensor read in every case)

    F(L, S) = sum_{i in L} sum_{j in S} g_ij g_ij^T                 (= J^T V_m^-1 J of Sec. 4.4)

Its inverse, from the pivoted QR of :func:`blackbox.fitting.statistics.covariance` (the one the
identification reports), gives the predicted standard deviations and linearised intervals
(:func:`blackbox.identification.uncertainty.linear_intervals`: log-space for springs).

**Criteria** (all minimised; sizes: a spring's value, ``sqrt(K_ii K_jj)`` for an entry ``K_ij`` of
``K_C`` as in Chapter 5, so a tiny off-diagonal entry is judged beside its diagonal):

* ``max_relative_ci_width`` (default): the widest linearised interval over the parameters,
  ``(ci_high - ci_low) / size``;
* ``d_optimal``: ``-log det`` of the information in relative units (reported as the geometric
  mean of ``std / size``, ``det^(-1/2p)``);
* ``a_optimal``: ``trace`` of the relative covariance (sum of ``(std / size)^2``);
* ``discrimination``: Chapter 6's question (eq. 34-35: which loading separates the simple from
  the complex joint model) as a design over several cases: the expected excess chi-square of the
  best simple model when the complex prior is true, ``lambda = r^T r - r^T J_s (J_s^T J_s)^+ J_s^T r``
  with ``r = (u_complex - u_simple) / sigma`` over the plan's rows and ``J_s`` the whitened
  simple-model sensitivities (linearised at the simple model fitted once to the complex prior over
  every candidate). Maximised (``-lambda`` minimised). It is additive over the rows through
  ``r^T r``, ``J_s^T r`` and ``J_s^T J_s``, so a plan costs a ``p_s x p_s`` solve.

**Search**: greedy forward selection of the loads (with every candidate sensor), backward
elimination of the sensors down to their budget, then Fedorov exchange (Fedorov 1972; Atkinson &
Donev 1992, ch. 12) of loads and of sensors, best swap first, until no swap improves the
criterion. Until a plan determines every parameter its information is singular; a ridge of
``RIDGE`` times the mean eigenvalue of every candidate's information (relative units) keeps the
greedy steps ranked there. A candidate load is used at most once (a case is a rig set-up).

**Robust design** averages the criterion over draws of the prior parameters
(:func:`prior_draws`: log-normal for springs, normal for other parameters, from the prior's
standard deviations), each draw's sensitivities again from the one condensation.

**Noise of a candidate sensor.** Its ``sigma``, or, blank, the noise model
:func:`blackbox.simulation.noise_sigma` (``relative x |u|`` floored at ``relative x floor x max|u|``
of its kind in the case, over every candidate sensor, ``absolute`` added in quadrature) at the
prior's predicted response; with a reference grid (Sec. 5.2) proportional to the relative motion,
as ``blackbox simulate`` does. The command picks the :class:`~blackbox.simulation.NoiseConfig`
(``blackbox.commands.design``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np
from scipy import stats

from blackbox.condensation import Condensed, CondensedModel
from blackbox.errors import DesignError
from blackbox.fitting.statistics import covariance
from blackbox.identification import Observations
from blackbox.identification.uncertainty import linear_intervals
from blackbox.joints import ComplexJoint, SimpleJoint
from blackbox.simulation import NoiseConfig, noise_sigma
from solver_adapters.protocol import DofLabel, LoadMatrix

__all__ = ["DesignError", "CRITERIA", "RIDGE", "CandidateLoad", "CandidateSensor", "Candidates",
           "CandidateSpace", "Discrimination", "Plan", "Prediction", "DesignCurve", "parameter_size",
           "case_weights", "candidate_space", "candidate_sigma", "discrimination_space", "information", "predict",
           "criterion", "optimise", "exhaustive", "random_plans", "design_curve", "prior_draws", "plan_condensed",
           "plan_observations", "simulate_plan"]

CRITERIA = ("max_relative_ci_width", "d_optimal", "a_optimal", "discrimination")
RIDGE = 1e-9
"""Ridge of a singular plan's information, times the mean eigenvalue of all candidates' (relative
units): a direction no chosen row sees gets a relative std ~3e4 times the full design's, far
above any identifiable one, so the greedy ranking is by the directions that are seen."""
MAX_EXCHANGE_ROUNDS = 50
RESTARTS = 4
"""Random starts of the exchange besides the greedy one (see :func:`optimise`)."""
PINV_RCOND = 1e-10
"""Relative cut-off of the pseudo-inverse of the simple model's information in the
discrimination criterion (directions below it count as not determined by the plan)."""


# --------------------------------------------------------------------------------------------
# candidates
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CandidateLoad:
    """A load that can be applied: ``value`` at ``(grid, component)``; one designed case, or,
    with a ``case`` label, part of the candidate case of that label (its loads applied together)."""
    grid: int
    component: int
    value: float
    case: str | None = None

    @property
    def dof(self) -> DofLabel:
        return (self.grid, self.component)


@dataclass(frozen=True)
class CandidateSensor:
    """A DOF that can be measured; ``sigma`` ``None`` = the noise model; with ``reference_grid``
    the reading is ``u(dof) - u(reference_grid, component)`` (Sec. 5.2)."""
    grid: int
    component: int
    sigma: float | None = None
    reference_grid: int | None = None

    @property
    def dof(self) -> DofLabel:
        return (self.grid, self.component)

    @property
    def ref_dof(self) -> DofLabel | None:
        return None if self.reference_grid is None else (self.reference_grid, self.component)


@dataclass(frozen=True)
class Candidates:
    """Every load and sensor a test could use. The designable cases (:attr:`cases`) are the
    unlabelled loads one by one and the labelled loads grouped by label, in order of first
    appearance; a plan chooses among them."""
    loads: tuple[CandidateLoad, ...]
    sensors: tuple[CandidateSensor, ...]

    def __post_init__(self) -> None:
        if not self.loads:
            raise DesignError("no candidate loads: give at least one row with kind = load")
        if not self.sensors:
            raise DesignError("no candidate sensors: give at least one row with kind = sensor")
        for what, items in (("load", self.loads), ("sensor", self.sensors)):
            keys = [(x.dof, getattr(x, "reference_grid", None), getattr(x, "case", None)) for x in items]
            dup = sorted({k for k in keys if keys.count(k) > 1})
            if dup:
                raise DesignError(f"candidate {what}(s) listed twice: {dup[:5]}")
        bad = [ld.dof for ld in self.loads if ld.value == 0.0 or not math.isfinite(ld.value)]
        if bad:
            raise DesignError(f"candidate load(s) {bad[:5]} have value 0 or not finite: a load needs a magnitude")

    @property
    def cases(self) -> tuple[tuple[int, ...], ...]:
        """The designable cases as tuples of indices into :attr:`loads`."""
        groups: dict = {}
        for i, ld in enumerate(self.loads):
            groups.setdefault(("single", i) if ld.case is None else ("case", ld.case), []).append(i)
        return tuple(tuple(v) for v in groups.values())

    def case_label(self, n: int) -> str:
        """The candidate's own name of designable case ``n`` (its label, or ``grid:component``)."""
        first = self.loads[self.cases[n][0]]
        return first.case if first.case is not None else f"{first.grid}:{first.component}"

    @property
    def load_dofs(self) -> list[DofLabel]:
        return list(dict.fromkeys(ld.dof for ld in self.loads))

    @property
    def observed(self) -> list[DofLabel]:
        """Every DOF the sensors read (their own and their reference DOFs)."""
        dofs = [s.dof for s in self.sensors] + [s.ref_dof for s in self.sensors if s.ref_dof is not None]
        return list(dict.fromkeys(dofs))

    def unit_loads(self) -> LoadMatrix:
        """One unit case per candidate load DOF (labels ``unit:grid:component``): the batch that
        is condensed together with the joint boundary."""
        return LoadMatrix.unit(self.load_dofs)


# --------------------------------------------------------------------------------------------
# the candidate space: whitened sensitivities of every (load, sensor) pair
# --------------------------------------------------------------------------------------------
def parameter_size(joints: Sequence, k: np.ndarray) -> np.ndarray:
    """The natural size of each parameter: ``|k|`` for a spring, ``sqrt(|K_ii K_jj|)`` for the
    entry ``K_ij`` of a complex joint's ``K_C`` (Chapter 5's measure), ``max|diag K_J|`` of the
    joint otherwise. Never 0 (1 in its place)."""
    k = np.asarray(k, float)
    out, start = np.ones(k.size), 0
    for j in joints:
        sl = slice(start, start + j.n_params)
        if isinstance(j, SimpleJoint):
            out[sl] = np.abs(k[sl])
        elif isinstance(j, ComplexJoint):
            d = np.abs(np.diag(j.kc_matrix(k[sl])))
            iu = np.triu_indices(d.size)
            out[sl] = np.sqrt(d[iu[0]] * d[iu[1]])
        else:
            out[sl] = float(np.max(np.abs(np.diag(j.matrix(k[sl])))))
        start += j.n_params
    return np.where(out > 0, out, 1.0)


def case_weights(model: CondensedModel, cands: Candidates, cases: LoadMatrix | None = None) -> np.ndarray:
    """``W`` ``(n_condensed_cases, n_L)``: each designable case as a combination of the unit
    cases of the one condensation (superposition). By default the candidate loads (``value`` at
    one DOF); ``cases`` gives any other load cases instead (e.g. an existing test's), whose DOFs
    must all be candidate load DOFs."""
    index = {c: i for i, c in enumerate(model.c.cases)}
    units = dict(zip(cands.load_dofs, cands.unit_loads().cases))
    if cases is None:
        W = np.zeros((len(index), len(cands.cases)))
        for n, members in enumerate(cands.cases):
            for i in members:
                W[index[units[cands.loads[i].dof]], n] += cands.loads[i].value
        return W
    missing = [d for d in cases.dofs if d not in units]
    if missing:
        raise DesignError(f"load DOFs {missing[:5]} of the given cases are not candidate load DOFs")
    V = cases.values.toarray()
    W = np.zeros((len(index), cases.n_cases))
    for i, d in enumerate(cases.dofs):
        W[index[units[d]]] += V[i]
    return W


def _unit_rows(model: CondensedModel, cands: Candidates, k: np.ndarray,
               W: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(u, dudk)``: per designable case (:func:`case_weights`) and sensor, the predicted reading
    ``(n_L, n_S)`` and its sensitivities ``(n_L, n_S, p)`` (eq. 18; a reference DOF's subtracted)."""
    W = case_weights(model, cands) if W is None else W
    r = model.response(k)
    sens = model.sensitivities(k, r)
    dofs = [s.dof for s in cands.sensors]
    U = model.pick(r, dofs)                                   # (n_S, L)
    dU = model.pick_sensitivities(sens, dofs)                 # (p, n_S, L)
    has_ref = np.array([s.ref_dof is not None for s in cands.sensors])
    if has_ref.any():
        refs = [s.ref_dof for s in cands.sensors if s.ref_dof is not None]
        U[has_ref] -= model.pick(r, refs)
        dU[:, has_ref] -= model.pick_sensitivities(sens, refs)
    u = (U @ W).T                                             # (n_L, n_S)
    dudk = np.transpose(dU @ W, (2, 1, 0))                    # (n_L, n_S, p)
    return u, dudk


def candidate_sigma(model: CondensedModel, cands: Candidates, k: np.ndarray, noise: NoiseConfig,
                    W: np.ndarray | None = None) -> np.ndarray:
    """``(n_L, n_S)`` planned sigma: the sensor's own, or the noise model at the prediction of
    ``k`` (module docstring), floors over every candidate sensor of the case as ``blackbox
    simulate`` takes them over every measured DOF."""
    u_rel, _ = _unit_rows(model, cands, k, W)
    plain = Candidates(cands.loads, tuple(CandidateSensor(s.grid, s.component) for s in cands.sensors))
    u_abs, _ = _unit_rows(model, plain, k, W)
    nL, nS = u_abs.shape
    case = np.repeat(np.arange(nL), nS)
    kinds = np.tile([1 if s.component >= 4 else 0 for s in cands.sensors], nL)
    try:
        sigma = noise_sigma(u_abs.ravel(), kinds, case, noise).reshape(nL, nS)
        rel = np.array([s.reference_grid is not None for s in cands.sensors])
        if rel.any():
            mask = np.tile(rel, nL)
            sigma.ravel()[mask] = noise_sigma(u_rel.ravel()[mask], kinds[mask], case[mask], noise)
    except ValueError as exc:
        raise DesignError(f"the noise model gives sigma = 0 for a candidate sensor that reads 0: {exc}; "
                          "give that sensor a sigma in the candidates file") from None
    given = np.array([np.nan if s.sigma is None else s.sigma for s in cands.sensors])
    return np.where(np.isfinite(given)[None, :], given[None, :], sigma)


@dataclass(frozen=True, eq=False)
class Discrimination:
    """The simple model fitted to the complex prior over every candidate: whitened differences
    ``r`` ``(n_L, n_S)`` and simple-model sensitivities ``g_s`` ``(n_L, n_S, p_s)``."""
    r: np.ndarray
    g_s: np.ndarray
    k_simple: np.ndarray


@dataclass(frozen=True, eq=False)
class CandidateSpace:
    """Everything a plan's criterion needs, for ``D`` parameter draws (``D = 1`` without
    ``--robust``): ``g`` ``(D, n_L, n_S, p)`` whitened sensitivities, ``u`` ``(n_L, n_S)`` the
    prior's predicted readings, ``sigma`` ``(n_L, n_S)``, ``size`` ``(p,)``."""
    candidates: Candidates
    k: np.ndarray
    g: np.ndarray
    u: np.ndarray
    sigma: np.ndarray
    size: np.ndarray
    log_mask: np.ndarray
    names: tuple[tuple[str, str], ...]
    confidence: float = 0.95
    discrimination: tuple[Discrimination, ...] = ()

    @property
    def n_loads(self) -> int:
        return self.g.shape[1]

    @property
    def n_sensors(self) -> int:
        return self.g.shape[2]

    @property
    def p(self) -> int:
        return self.g.shape[3]

    @property
    def z(self) -> float:
        return float(stats.norm.ppf(0.5 + self.confidence / 2.0))


def candidate_space(model: CondensedModel, cands: Candidates, k: np.ndarray, noise: NoiseConfig, *,
                    draws: np.ndarray | None = None, sigma: np.ndarray | None = None,
                    confidence: float = 0.95, cases: LoadMatrix | None = None) -> CandidateSpace:
    """The whitened sensitivities of every (load, sensor) pair at ``k`` (and at every row of
    ``draws``, when given: the robust design's parameter draws), with the planned ``sigma``
    (default :func:`candidate_sigma` at ``k``). With ``draws`` the prior point is draw 0 (what
    :func:`predict` reports) and the criterion averages over it and the draws. ``cases``: other
    load cases in place of the candidate loads (:func:`case_weights`), e.g. to predict what an
    existing test gives."""
    k = np.asarray(k, float)
    W = case_weights(model, cands, cases)
    sigma = candidate_sigma(model, cands, k, noise, W) if sigma is None else np.asarray(sigma, float)
    points = [k] if draws is None else [k] + list(np.atleast_2d(draws))
    g = []
    for kd in points:
        _, dudk = _unit_rows(model, cands, kd, W)
        g.append(dudk / sigma[:, :, None])
    u, _ = _unit_rows(model, cands, k, W)
    joints = model.assembly.joints
    log_mask = np.concatenate([np.full(j.n_params, isinstance(j, SimpleJoint)) for j in joints])
    names = tuple((j.name, n) for j in joints for n in j.param_names)
    return CandidateSpace(cands, k, np.stack(g), u, sigma, parameter_size(joints, k), log_mask, names,
                          confidence)


def discrimination_space(space: CandidateSpace, complex_model: CondensedModel, k_complex: np.ndarray,
                         simple_model: CondensedModel, *, draws: np.ndarray | None = None) -> CandidateSpace:
    """``space`` with the simple-vs-complex differences of :class:`Discrimination` for the
    complex prior ``k_complex`` (and each row of ``draws``). The simple model is fitted once to
    the complex prediction over every candidate row with the planned sigma
    (:func:`blackbox.identification.identify`, noise-free data)."""
    from blackbox.identification import identify

    cands = space.candidates
    out = []
    points = [np.asarray(k_complex, float)] + ([] if draws is None else list(np.atleast_2d(draws)))
    k0_s = np.concatenate([j.initial_params(1.0) for j in simple_model.assembly.joints])
    for kc in points:
        u_c, _ = _unit_rows(complex_model, cands, kc)
        obs = plan_observations(cands, range(len(cands.cases)), range(len(cands.sensors)), u_c,
                                space.sigma)
        pcm = CondensedModel(plan_condensed(complex_model.c, cands, range(len(cands.cases))),
                             list(simple_model.assembly.joints), simple_model.K_deck)
        # start: the simple springs of the complex prior's stiffest diagonal, a scale-free guess
        scale = float(np.median(parameter_size(complex_model.assembly.joints, kc)))
        fit = identify(pcm, obs, k0_s * scale, profile=False, max_iterations=100)
        u_s, dudk_s = _unit_rows(simple_model, cands, fit.k)
        r = (u_c - u_s) / space.sigma
        if not np.any(np.abs(r) > 1e-9):
            raise DesignError("the complex prior is a simple joint (both models predict the same "
                              "response): nothing to discriminate. Give --prior a complex "
                              "identification's result.json or a truth with a coupled K_C")
        out.append(Discrimination(r, dudk_s / space.sigma[:, :, None], fit.k))
    return replace(space, discrimination=tuple(out))


def prior_draws(k: np.ndarray, std: np.ndarray, log_mask: np.ndarray, n: int, seed: int = 0,
                admissible=None) -> np.ndarray:
    """``n`` draws of the prior: springs log-normal (``log k ~ N(log k0, (std/k0)^2)``), other
    parameters normal; a draw that ``admissible`` rejects is drawn again (at most 100 times)."""
    rng = np.random.default_rng(seed)
    k, std = np.asarray(k, float), np.asarray(std, float)
    std = np.where(np.isfinite(std), std, 0.0)
    out = []
    for _ in range(int(n)):
        for _try in range(100):
            e = rng.standard_normal(k.size)
            with np.errstate(divide="ignore", invalid="ignore"):
                kd = np.where(log_mask, k * np.exp(e * std / np.where(k != 0, np.abs(k), 1.0)), k + e * std)
            if admissible is None or admissible(kd):
                break
        else:
            raise DesignError("no admissible draw of the prior in 100 tries: its uncertainty is too "
                              "large for a robust design")
        out.append(kd)
    return np.array(out)


# --------------------------------------------------------------------------------------------
# information and criteria
# --------------------------------------------------------------------------------------------
def information(space: CandidateSpace, loads: Sequence[int], sensors: Sequence[int], draw: int = 0) -> np.ndarray:
    """``F(L, S) = sum g g^T`` over the plan's rows (natural parameters)."""
    G = space.g[draw][np.ix_(list(loads), list(sensors))].reshape(-1, space.p)
    return G.T @ G


def _relative_widths(rel_std: np.ndarray, log_mask: np.ndarray, z: float) -> np.ndarray:
    """``(ci_high - ci_low) / size`` of the linearised interval: ``2 sinh(z s)`` in log space
    for a spring (``s = std / k``), ``2 z s`` otherwise."""
    with np.errstate(over="ignore"):
        return np.where(log_mask, 2.0 * np.sinh(np.minimum(z * rel_std, 700.0)), 2.0 * z * rel_std)


class _Evaluator:
    """Criterion of many plans at once from per-load information blocks (relative units)."""

    def __init__(self, space: CandidateSpace, name: str):
        if name not in CRITERIA:
            raise DesignError(f"criterion must be one of {', '.join(CRITERIA)}; got {name!r}")
        if name == "discrimination" and not space.discrimination:
            raise DesignError("criterion 'discrimination' needs the complex prior's differences "
                              "(discrimination_space)")
        self.space, self.name = space, name
        gs = space.g * space.size                              # relative units: theta = k / size
        self.gs = gs
        full = np.einsum("dlsp,dlsq->dpq", gs, gs)
        p = space.p
        self.ridge = RIDGE * float(np.mean(np.trace(full, axis1=1, axis2=2))) / p * np.eye(p)
        if name == "discrimination":
            self.disc = space.discrimination
            self.disc_scale = np.array([float(np.sum(d.r ** 2)) for d in self.disc])

    # per-load sufficient statistics for a sensor set -----------------------------------------
    def blocks(self, sensors: Sequence[int]):
        S = list(sensors)
        if self.name == "discrimination":
            out = []
            for d in self.disc:
                r, gs = d.r[:, S], d.g_s[:, S]
                out.append((np.einsum("ls,ls->l", r, r), np.einsum("lsp,ls->lp", gs, r),
                            np.einsum("lsp,lsq->lpq", gs, gs)))
            return out
        g = self.gs[:, :, S]
        return np.einsum("dlsp,dlsq->dlpq", g, g)               # (D, n_L, p, p)

    def sensor_blocks(self, loads: Sequence[int]):
        """The same statistics per sensor, summed over the chosen ``loads`` (for sensor swaps)."""
        L = list(loads)
        if self.name == "discrimination":
            out = []
            for d in self.disc:
                r, gs = d.r[L], d.g_s[L]
                out.append((np.einsum("ls,ls->s", r, r), np.einsum("lsp,ls->sp", gs, r),
                            np.einsum("lsp,lsq->spq", gs, gs)))
            return out
        g = self.gs[:, L]
        return np.einsum("dlsp,dlsq->dspq", g, g)               # (D, n_S, p, p)

    def plan_sum(self, blocks, loads: Sequence[int]):
        L = list(loads)
        if self.name == "discrimination":
            return [(a[L].sum(0), b[L].sum(0), M[L].sum(0)) for a, b, M in blocks]
        return blocks[:, L].sum(1)                               # (D, p, p)

    def add(self, base, blocks, idx: np.ndarray, sign: float = 1.0):
        """The plan sums of ``base`` with each load of ``idx`` added (``sign`` -1: removed)."""
        if self.name == "discrimination":
            return [(a0 + sign * a[idx], b0 + sign * b[idx], M0 + sign * M[idx])
                    for (a0, b0, M0), (a, b, M) in zip(base, blocks)]
        return base[:, None] + sign * blocks[:, idx]              # (D, B, p, p)

    def value(self, sums, ridge: bool = True) -> np.ndarray:
        """The criterion (lower is better) of a batch of plan sums (mean over the draws)."""
        if self.name == "discrimination":
            vals = []
            for (a, b, M), s in zip(sums, self.disc_scale):
                a, b, M = np.atleast_1d(a), np.atleast_2d(b), M.reshape((-1,) + M.shape[-2:])
                # no ridge here: the projection residual is exact at any rank, a ridge would
                # overrate a plan that leaves some simple-model direction barely determined
                x = np.einsum("bpq,bq->bp", np.linalg.pinv(M, rcond=PINV_RCOND, hermitian=True), b)
                vals.append(-(a - np.einsum("bp,bp->b", b, x)) / s)    # -lambda / r^T r of all candidates
            return np.mean(vals, axis=0)
        A = sums + (self.ridge if ridge else 0.0)
        if A.ndim == 3:
            A = A[:, None]
        with np.errstate(all="ignore"):
            if self.name == "d_optimal":
                sign, logdet = np.linalg.slogdet(A)
                v = np.where(sign > 0, -logdet, np.inf)
                return np.mean(v, axis=0)
            try:
                C = np.linalg.inv(A)
            except np.linalg.LinAlgError:
                return np.full(A.shape[1], np.inf)
            var = np.diagonal(C, axis1=-2, axis2=-1)
            if self.name == "a_optimal":
                v = np.where(np.all(var > 0, axis=-1), var.sum(-1), np.inf)
            else:
                w = _relative_widths(np.sqrt(np.abs(var)), self.space.log_mask, self.space.z)
                v = np.where(np.all(var > 0, axis=-1), w.max(-1), np.inf)
        return np.mean(v, axis=0)


def criterion(space: CandidateSpace, name: str, loads: Sequence[int], sensors: Sequence[int]) -> float:
    """The criterion of one plan without the ridge (``inf`` when a parameter is not determined;
    ``discrimination``: ``-lambda`` over the ``r^T r`` of every candidate row)."""
    ev = _Evaluator(space, name)
    return float(np.atleast_1d(ev.value(ev.plan_sum(ev.blocks(sensors), loads), ridge=False))[0])


# --------------------------------------------------------------------------------------------
# greedy selection and Fedorov exchange
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Plan:
    """Chosen candidate indices (into ``Candidates.cases`` / ``.sensors``) and the criterion."""
    loads: tuple[int, ...]
    sensors: tuple[int, ...]
    criterion: str
    value: float
    exchanges: int = 0


def _better(v: float, than: float) -> bool:
    """``v`` improves on ``than`` by more than rounding (either sign: -log det, -lambda)."""
    return v < than - 1e-9 * abs(than)


def _exchange(ev: "_Evaluator", L: list[int], S: list[int], nL: int, nS: int, ridge: bool,
              max_rounds: int) -> tuple[list[int], list[int], float, int]:
    """Fedorov exchange from ``(L, S)``: per round the best load swap, then the best sensor swap
    (when sensors are budgeted), until no swap improves."""
    current = float(ev.value(ev.plan_sum(ev.blocks(S), L), ridge)[0])
    swaps = 0
    for _ in range(int(max_rounds)):
        improved = False
        blocks = ev.blocks(S)                                  # loads: swap out L[pos], swap in j
        rest = np.array([i for i in range(nL) if i not in L])
        best = (current, None, None)
        for pos in range(len(L) if rest.size else 0):
            vals = ev.value(ev.add(ev.plan_sum(blocks, L[:pos] + L[pos + 1:]), blocks, rest), ridge)
            j = int(np.argmin(vals))
            if _better(float(vals[j]), best[0]):
                best = (float(vals[j]), pos, int(rest[j]))
        if best[1] is not None:
            L[best[1]] = best[2]
            current, improved, swaps = best[0], True, swaps + 1
        if len(S) < nS:                                        # sensors: swap out S[pos], swap in t
            sblocks = ev.sensor_blocks(L)
            out_s = np.array([t for t in range(nS) if t not in S])
            best = (current, None, None)
            for pos in range(len(S)):
                vals = ev.value(ev.add(ev.plan_sum(sblocks, S[:pos] + S[pos + 1:]), sblocks, out_s), ridge)
                j = int(np.argmin(vals))
                if _better(float(vals[j]), best[0]):
                    best = (float(vals[j]), pos, int(out_s[j]))
            if best[1] is not None:
                S[best[1]] = best[2]
                current, improved, swaps = best[0], True, swaps + 1
        if not improved:
            break
    return L, S, current, swaps


def optimise(space: CandidateSpace, n_loads: int, n_sensors: int | None = None,
             name: str = "max_relative_ci_width", max_rounds: int = MAX_EXCHANGE_ROUNDS,
             restarts: int = RESTARTS, seed: int = 0) -> Plan:
    """Greedy forward selection of ``n_loads`` loads with every sensor, backward elimination of
    sensors down to ``n_sensors`` (default: all), then Fedorov exchange of loads and sensors,
    best improving swap first, until none improves (at most ``max_rounds`` rounds): first with
    the ridge (to reach a plan that determines every parameter), then without it (the exact
    criterion). The exchange is repeated from ``restarts`` random plans (seeded), the best kept:
    the widest-interval criterion is not smooth and a single exchange can stop at a swap-local
    optimum."""
    nL, nS = space.n_loads, space.n_sensors
    n_sensors = nS if n_sensors is None else int(n_sensors)
    if not 1 <= int(n_loads) <= nL:
        raise DesignError(f"--loads must be 1..{nL} (the candidate cases), got {n_loads}")
    if not 1 <= n_sensors <= nS:
        raise DesignError(f"--sensors must be 1..{nS} (the candidate sensors), got {n_sensors}")
    ev = _Evaluator(space, name)
    S = list(range(nS))
    L: list[int] = []
    blocks = ev.blocks(S)
    for _ in range(int(n_loads)):                              # greedy loads
        rest = np.array([i for i in range(nL) if i not in L])
        vals = ev.value(ev.add(ev.plan_sum(blocks, L), blocks, rest))
        L.append(int(rest[int(np.argmin(vals))]))
    sblocks = ev.sensor_blocks(L)
    while len(S) > n_sensors:                                  # backward sensors
        vals = ev.value(ev.add(ev.plan_sum(sblocks, S), sblocks, np.array(S), -1.0))
        S.remove(S[int(np.argmin(vals))])
    rng = np.random.default_rng(seed)
    starts = [(L, S)] + [(rng.choice(nL, int(n_loads), replace=False).tolist(),
                          rng.choice(nS, n_sensors, replace=False).tolist()) for _ in range(int(restarts))]
    best, swaps = None, 0
    for L0, S0 in starts:
        L1, S1, _, n1 = _exchange(ev, list(L0), list(S0), nL, nS, True, max_rounds)
        L1, S1, v, n2 = _exchange(ev, L1, S1, nL, nS, False, max_rounds)
        swaps += n1 + n2
        if best is None or _better(v, best[2]) or (not math.isfinite(best[2]) and math.isfinite(v)):
            best = (sorted(L1), sorted(S1), v)
    L, S = best[0], best[1]
    return Plan(tuple(L), tuple(S), name, criterion(space, name, L, S), swaps)


def exhaustive(space: CandidateSpace, n_loads: int, name: str = "max_relative_ci_width",
               max_plans: int = 200_000) -> Plan:
    """The best plan of ``n_loads`` loads with every sensor by trying every combination (the
    yardstick of :func:`optimise` on small candidate sets; at most ``max_plans`` combinations)."""
    from itertools import combinations

    count = math.comb(space.n_loads, int(n_loads))
    if count > max_plans:
        raise DesignError(f"{count} plans of {n_loads} loads out of {space.n_loads}: more than {max_plans}")
    ev = _Evaluator(space, name)
    S = list(range(space.n_sensors))
    blocks = ev.blocks(S)
    best, best_val = None, math.inf
    combos = np.array(list(combinations(range(space.n_loads), int(n_loads))))
    for chunk in np.array_split(combos, max(1, len(combos) // 5000)):
        if name == "discrimination":
            sums = [(a[chunk].sum(1), b[chunk].sum(1), M[chunk].sum(1)) for a, b, M in blocks]
        else:
            sums = blocks[:, chunk].sum(2)
        vals = ev.value(sums, ridge=False)
        j = int(np.argmin(vals))
        if vals[j] < best_val:
            best, best_val = chunk[j], float(vals[j])
    L = sorted(int(i) for i in best)
    return Plan(tuple(L), tuple(S), name, criterion(space, name, L, S))


def random_plans(space: CandidateSpace, n_loads: int, n_sensors: int | None, n: int,
                 seed: int = 0) -> list[Plan]:
    """``n`` plans of the same size drawn at random (loads, and sensors when budgeted), evaluated
    with the default criterion (the yardstick of a design)."""
    rng = np.random.default_rng(seed)
    nS = space.n_sensors if n_sensors is None else int(n_sensors)
    out = []
    for _ in range(int(n)):
        L = sorted(rng.choice(space.n_loads, size=int(n_loads), replace=False).tolist())
        S = sorted(rng.choice(space.n_sensors, size=nS, replace=False).tolist())
        out.append(Plan(tuple(L), tuple(S), "max_relative_ci_width",
                        criterion(space, "max_relative_ci_width", L, S)))
    return out


# --------------------------------------------------------------------------------------------
# what a plan predicts
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Prediction:
    """Predicted uncertainty of a plan at the prior: std, linearised intervals (log-space for
    springs), relative widths ``(ci_high - ci_low) / size``; ``inf`` / ``nan`` where not
    identifiable (:func:`blackbox.fitting.statistics.covariance`)."""
    names: tuple[tuple[str, str], ...]
    value: np.ndarray
    std: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    relative_width: np.ndarray
    identifiable: np.ndarray
    rank: int
    size: np.ndarray

    @property
    def max_relative_width(self) -> float:
        return float(np.max(self.relative_width))

    @property
    def median_relative_width(self) -> float:
        return float(np.median(self.relative_width))

    @property
    def geometric_mean_2std(self) -> float:
        """Chapter 5's width: the geometric mean over the parameters of ``2 std / size``."""
        return float(np.exp(np.mean(np.log(2.0 * self.std / self.size)))) if np.all(np.isfinite(self.std)) \
            else math.inf

    def to_json(self) -> list[dict]:
        def num(v):
            v = float(v)
            return v if math.isfinite(v) else None
        return [{"joint": j, "name": n, "value": num(v), "std": num(s), "ci_low": num(lo), "ci_high": num(hi),
                 "relative_width": num(w), "identifiable": bool(ok)}
                for (j, n), v, s, lo, hi, w, ok in zip(self.names, self.value, self.std, self.ci_low,
                                                       self.ci_high, self.relative_width, self.identifiable)]


def predict(space: CandidateSpace, loads: Sequence[int], sensors: Sequence[int]) -> Prediction:
    """The plan's covariance at the prior, from the pivoted QR of its whitened rows (the same
    :func:`blackbox.fitting.statistics.covariance` as the identification, columns scaled by the
    parameters' sizes)."""
    J = space.g[0][np.ix_(list(loads), list(sensors))].reshape(-1, space.p)
    c = covariance(J, space.size)
    lin, _ = linear_intervals(space.k, c.std, space.z, space.log_mask, c.identifiable)
    width = np.where(c.identifiable, (lin[:, 1] - lin[:, 0]) / space.size, np.inf)
    return Prediction(space.names, space.k.copy(), c.std, lin[:, 0], lin[:, 1], width, c.identifiable,
                      c.rank, space.size)


@dataclass(frozen=True, eq=False)
class DesignCurve:
    """Predicted widths against the number of load cases: designed (``optimise`` at each size)
    and random plans (median and 10-90 % band over ``n_random`` draws)."""
    n_cases: tuple[int, ...]
    designed_max: np.ndarray
    designed_median: np.ndarray
    random_max: np.ndarray          # (n, 3): 10 %, median, 90 % of the random plans' widest width
    random_median: np.ndarray       # (n, 3): the same of their median (over parameters) width
    n_random: int

    def to_json(self) -> dict:
        def num(v):
            v = float(v)
            return v if math.isfinite(v) else None
        return {"n_cases": list(self.n_cases), "n_random": self.n_random,
                "designed_max_relative_width": [num(v) for v in self.designed_max],
                "designed_median_relative_width": [num(v) for v in self.designed_median],
                "random_max_relative_width": [[num(v) for v in r] for r in self.random_max],
                "random_median_relative_width": [[num(v) for v in r] for r in self.random_median]}


def design_curve(space: CandidateSpace, n_max: int, n_sensors: int | None, name: str,
                 n_random: int = 50, seed: int = 0, final: Plan | None = None,
                 restarts: int = 0, final_random: Sequence["Prediction"] | None = None) -> DesignCurve:
    """:class:`DesignCurve` for 1..``n_max`` load cases; ``final``: the plan already designed
    for ``n_max`` (the curve's last point), the others with ``restarts`` random starts (default
    none: greedy + exchange only, a curve costs ``n_max`` designs). ``final_random``: the random
    plans of size ``n_max`` already predicted (the report's yardstick), so that the curve's last
    point and the report give the same random-plan median; else drawn with seed ``seed + n``."""
    ns, dmax, dmed, rmax, rmed = [], [], [], [], []
    for n in range(1, int(n_max) + 1):
        plan = final if final is not None and n == int(n_max) else \
            optimise(space, n, n_sensors, name, restarts=restarts, seed=seed)
        pr = predict(space, plan.loads, plan.sensors)
        ns.append(n)
        dmax.append(pr.max_relative_width)
        dmed.append(pr.median_relative_width)
        if final_random is not None and n == int(n_max):
            widths = list(final_random)
        else:
            widths = [predict(space, rp.loads, rp.sensors) for rp in random_plans(space, n, n_sensors, n_random,
                                                                                   seed + n)]
        mx = np.array([w.max_relative_width for w in widths])
        md = np.array([w.median_relative_width for w in widths])
        with np.errstate(invalid="ignore"):                    # inf - inf of undetermined plans
            rmax.append(np.percentile(mx, [10, 50, 90]))
            rmed.append(np.percentile(md, [10, 50, 90]))
    return DesignCurve(tuple(ns), np.array(dmax), np.array(dmed), np.array(rmax), np.array(rmed), int(n_random))


# --------------------------------------------------------------------------------------------
# a plan as a condensed model and observations (for simulation and identification)
# --------------------------------------------------------------------------------------------
def plan_condensed(c: Condensed, cands: Candidates, loads: Sequence[int], prefix: str = "D") -> Condensed:
    """The condensation of the plan's cases by superposition: case ``D{n}`` is candidate case
    ``loads[n-1]`` (its loads' ``value`` times the unit columns of the one batched run). ``c``
    is the condensation of the candidates' unit loads."""
    W = case_weights(_Columns(c), cands)[:, list(loads)]
    return replace(c, cases=tuple(f"{prefix}{n + 1}" for n in range(W.shape[1])),
                   U_B0=c.U_B0 @ W, U_O0=c.U_O0 @ W)


class _Columns:
    """A condensation seen as :func:`case_weights` needs it (``.c.cases``)."""

    def __init__(self, c: Condensed):
        self.c = c


def plan_observations(cands: Candidates, loads: Sequence[int], sensors: Sequence[int], values: np.ndarray,
                      sigma: np.ndarray, prefix: str = "D") -> Observations:
    """Rows of the plan (case-major, the cases of :func:`plan_condensed`) with ``values`` and
    ``sigma`` taken from ``(n_L, n_S)`` arrays over every candidate."""
    loads, sensors = list(loads), list(sensors)
    ci = np.repeat(np.arange(len(loads)), len(sensors))
    li = np.repeat(loads, len(sensors))
    si = np.tile(sensors, len(loads))
    sens = cands.sensors
    refs = tuple(sens[j].ref_dof for j in si)
    return Observations(tuple(sens[j].dof for j in si), ci, np.asarray(values)[li, si],
                        np.asarray(sigma)[li, si], tuple(f"{prefix}{n + 1}" for n in range(len(loads))),
                        refs if any(r is not None for r in refs) else ())


def simulate_plan(model: CondensedModel, cands: Candidates, plan: Plan, k_true: np.ndarray, sigma: np.ndarray,
                  k0: np.ndarray, n: int, seed: int = 0, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Run the planned test ``n`` times in the condensed space: readings of the truth ``k_true``
    (superposition of the one condensation) plus Gaussian noise of the planned ``sigma``, each
    identified from ``k0`` (:func:`blackbox.identification.identify`, linearised intervals; no
    solver run). Returns the estimates ``(n, p)`` and the realised relative widths ``(n, p)``
    (``(ci_high - ci_low) / size``, size at ``k_true``; ``nan`` for a fit that did not converge)."""
    from blackbox.identification import identify

    pc = plan_condensed(model.c, cands, plan.loads)
    pm = CondensedModel(pc, list(model.assembly.joints), model.K_deck)
    u_true, _ = _unit_rows(model, cands, np.asarray(k_true, float))
    obs = plan_observations(cands, plan.loads, plan.sensors, u_true, sigma)
    size = parameter_size(model.assembly.joints, k_true)
    rng = np.random.default_rng(seed)
    est, widths = [], []
    for _ in range(int(n)):
        y = obs.values + obs.sigma * rng.standard_normal(len(obs))
        r = identify(pm, obs.with_values(y), k0, profile=False, confidence=confidence, max_iterations=100)
        ok = r.converged and bool(r.identifiable.all())
        est.append(r.k if ok else np.full(r.k.shape, np.nan))
        widths.append((r.ci_high - r.ci_low) / size if ok else np.full(r.k.shape, np.nan))
    return np.array(est), np.array(widths)
