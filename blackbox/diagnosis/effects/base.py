"""What every effect family is: a candidate effect nested in the declared model at a known value.

A family is a small frozen dataclass, registered by its ``kind``
(:func:`blackbox.diagnosis.effects.registry.register`); one instance is one candidate (a support
at grid 1, member 88...). Everything that differs between families lives on the class:

* **listing** -- :meth:`Effect.cut` edits the split deck (connections the split run must cut) and
  returns the candidates that cut makes possible; :meth:`Effect.candidates` lists the others once
  the split run is done, :meth:`Effect.split_rows` says which DOFs that run must report for them.
  All read a :class:`CandidateContext`. A family with more candidates than its cap considers
  those nearest the declared fit's residual (:meth:`CandidateContext.nearest_residual`) and says
  so (:class:`CandidateLimit`).
* **parameters** -- :attr:`Effect.names`, :attr:`Effect.nominal` (the value at which the effect is
  absent: the declared model), :attr:`Effect.bounds`, :attr:`Effect.one_sided` (the nested value
  is a bound, so the score test is one-sided).
* **the augmented model** -- at most one way in, each a hook with an empty default:
  :meth:`Effect.joint_models` (the joints change model: coupling), :meth:`Effect.stiffness_terms`
  (``dK += (x_q - nominal_q) K_q`` on some DOFs: members) or the nonlinear pair
  :meth:`Effect.stiffness_matrix` / :meth:`Effect.stiffness_derivatives` (``dK += dK(x)`` on
  some DOFs, 0 at the nominal point: rigid end zones), :attr:`Effect.cut_pairs` with
  :attr:`Effect.compliance_basis` (a released cut of the split deck: connections) and
  :meth:`Effect.output_rows` (a factor on some measured rows: load scales, sensor gains) or
  :meth:`Effect.offset_rows` (an offset added to some measured rows: sensor offsets).
* **scoring and refits** -- :meth:`Effect.scored_columns`, :meth:`Effect.batch_columns`
  (a whole family scored without augmenting the model: members by reciprocity),
  :meth:`Effect.refit_starts`, :meth:`Effect.refit_columns`, :meth:`Effect.trimmed`.
* **variants** -- :attr:`Effect.variant` names the parameterisation of a family that offers
  several at one place (nested: each richer variant equals the simpler one at a known point);
  candidates are listed at their simplest variant and :meth:`Effect.richer` gives the richer
  ones with their nested starts, which the search refits and keeps only when the data support
  them (:func:`blackbox.diagnosis.search.refine`).
* **reports** -- :meth:`Effect.where_json`, :meth:`Effect.label`, :meth:`Effect.parameters`,
  :meth:`Effect.marker_points`, :attr:`Effect.summary`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar, Sequence

import numpy as np

from blackbox.joints import SimpleJoint
from solver_adapters.protocol import DofLabel

if TYPE_CHECKING:
    from blackbox.diagnosis.decks import SplitDeck, SplitEditor
    from blackbox.diagnosis.effects.p_delta import Preload
    from blackbox.diagnosis.fit import Fit
    from blackbox.diagnosis.model import AugmentedModel, ModelSpec, ObsMap, State
    from blackbox.identification import Observations
    from blackbox.joints import JointModel
    from solver_adapters.protocol import Deck, LoadMatrix

__all__ = ["CandidateContext", "CandidateLimit", "Effect", "FreeOffsets", "JointCaseEffect", "OnChannel", "ReadsAnother",
           "SetAsideEffect", "Share", "finite_or_none", "kept_parameters", "proximity", "takes_readings"]


@dataclass(frozen=True)
class CandidateLimit:
    """A family that considers fewer candidates than the study offers: how many it considered, of
    how many, how it chose them and the option that raises the limit (reported, never silent)."""
    kind: str
    considered: int
    available: int
    chosen_by: str
    option: str

    def to_json(self) -> dict:
        return {"effect": self.kind, "considered": self.considered, "available": self.available,
                "chosen_by": self.chosen_by, "option": self.option}

    def sentence(self) -> str:
        return (f"{self.kind}: {self.considered} of {self.available} candidates considered ({self.chosen_by})"
                + (f"; raise {self.option} to consider more" if self.option else ""))


@dataclass(frozen=True, eq=False)
class CandidateContext:
    """What families list their candidates from: the study's deck, the declared joints (in the
    study's order), each member's black-box stiffness ``K_e``, the fitted rows, the load cases,
    the per-grid RMS of the declared fit's whitened residuals (``None`` without a declared fit),
    the cap on undeclared-joint candidates, each case's group from the optional ``group``
    column of ``loads.csv`` (empty without it), from the declared fit each fitted case's
    least-squares scale of its predicted responses (``None`` without a declared fit), and the cap
    on member candidates. A family that applies a cap records it in ``limits`` (:meth:`note_limit`).
    For the families whose joint stiffness depends on the case or on a permanent load: every
    measured row (fitted and hold-out), the load cases, whether they are one test's steps in
    time order, and the declared permanent load with the members' axial forces under it."""
    deck: "Deck"
    joints: tuple["JointModel", ...]
    K_e: dict[int, np.ndarray]
    fit_obs: "Observations"
    cases: tuple[str, ...]
    residual_rms: dict[int, float] | None
    max_joint_candidates: int
    groups: dict[str, str] = field(default_factory=dict)
    case_scales: dict[str, tuple[float, float]] | None = None   # fitted case -> (scale - 1, std) of
                                                                # its responses in the declared fit
    max_member_candidates: int = 300
    limits: dict[str, CandidateLimit] = field(default_factory=dict)
    measured: "Observations | None" = None      # every measured row, fitted and hold-out (what
                                                # is known of each case beforehand: its amplitude)
    loads: "LoadMatrix | None" = None           # the study's load cases, in loads.csv's order
    sequential: bool = False                    # the cases are the steps of one test in time order
                                                # (study.toml [measurements] sequential)
    preload: "Preload | None" = None            # the declared permanent load and its axial forces
    include: frozenset = frozenset()            # keys a capped family considers whatever the cap
                                                # (the ends of a member factor the search accepted)

    def note_limit(self, limit: CandidateLimit) -> None:
        self.limits[limit.kind] = limit

    def nearest_residual(self, points: dict, limit: int) -> list:
        """At most ``limit`` keys of ``points`` (``{key: xyz}``, in their order): those nearest the
        declared fit's residual concentration. Each point scores the largest per-grid residual RMS
        of a measured grid discounted by ``exp(-distance / median member length)``; without a
        declared fit (no joints) every measured grid weighs 1 (nearest the sensors). Ties keep
        the order of ``points``. Keys in :attr:`include` are taken beside the ``limit``."""
        keys = list(points)
        if len(keys) <= limit:
            return keys
        forced = {i for i, k in enumerate(keys) if k in self.include}
        deck = self.deck
        xyz = {g.id: np.array(g.xyz) for g in deck.grids.values()}
        lengths = [np.linalg.norm(xyz[b.ga] - xyz[b.gb]) for b in deck.cbars.values()]
        ell = float(np.median(lengths)) if lengths else 1.0
        ell = ell or 1.0
        weights = self.residual_rms if self.residual_rms is not None else \
            {int(g): 1.0 for g, _ in self.fit_obs.dofs}
        meas = [(xyz[g], v) for g, v in weights.items() if g in xyz]
        if not meas:
            return [k for i, k in enumerate(keys) if i < limit or i in forced]
        P = np.array([p for p, _ in meas])
        w = np.array([v for _, v in meas])
        X = np.array([np.asarray(points[k], float) for k in keys])
        score = proximity(X, P, w, ell)
        chosen = set(np.argsort(-score, kind="stable")[:limit].tolist()) | forced
        return [k for i, k in enumerate(keys) if i in chosen]


def takes_readings(e: "Effect") -> bool:
    """Whether ``e``'s parameters are offsets that each take readings wholly (a bad channel's,
    a bad case's, an outlier's): those readings then say nothing of the model or the noise."""
    return isinstance(e, SetAsideEffect) or e.kind == "outlier"


def proximity(X: np.ndarray, P: np.ndarray, w: np.ndarray, ell: float) -> np.ndarray:
    """Each point of ``X`` (n, 3) scored by how near it is to weighted points ``P`` (m, 3) with
    weights ``w``: ``max_j w_j exp(-|x - p_j| / ell)`` (the order of "nearest the residual")."""
    score = np.zeros(len(X))
    for a in range(0, len(X), 4096):               # blocks: (points x weighted points) distances
        d = np.linalg.norm(X[a:a + 4096, None, :] - P[None, :, :], axis=2)
        score[a:a + 4096] = np.max(w[None, :] * np.exp(-d / ell), axis=1)
    return score


def kept_parameters(x_effect, at_nested: float) -> np.ndarray | None:
    """Which of a refitted effect's per-part parameters stay (:meth:`Effect.trimmed`): those that
    ended above ``at_nested`` (their nested bound, 0, is where the part has no effect), and at
    least the largest; ``None`` when every one stays."""
    x = np.asarray(x_effect)
    keep = x > at_nested
    if not np.any(keep):
        keep[int(np.argmax(x))] = True
    return None if np.all(keep) else keep


def finite_or_none(v) -> float | None:
    """``float(v)``, or ``None`` when it is not finite (JSON has no inf/nan)."""
    v = float(v)
    return v if math.isfinite(v) else None


@dataclass(frozen=True, eq=False)
class Effect:
    """One candidate effect: ``where`` it acts and the names of its parameters."""
    kind: ClassVar[str] = ""
    summary: ClassVar[str] = ""

    where: tuple
    names: tuple[str, ...] = ()
    variant: str = ""           # the parameterisation ("" for a family with only one)

    # ---- listing ------------------------------------------------------------------------------
    @classmethod
    def cut(cls, editor: "SplitEditor", ctx: CandidateContext) -> list["Effect"]:
        """Cut what this family's candidates release in the split deck; return those candidates."""
        return []

    @classmethod
    def candidates(cls, ctx: CandidateContext, split: "SplitDeck") -> list["Effect"]:
        """Candidates that need no cut, listed after the split deck is built."""
        return []

    @classmethod
    def split_rows(cls, ctx: CandidateContext, split: "SplitDeck") -> tuple[DofLabel, ...]:
        """DOFs the split run must report for this family's candidates, beyond those it always
        reports (the joint boundary, the measured DOFs, both sides of every cut pair)."""
        return ()

    @classmethod
    def holdout_candidates(cls, ctx: CandidateContext, split: "SplitDeck") -> list["Effect"]:
        """Effects of this family in a hold-out case, which the search never fits: what the
        hold-out check tries a case it does not predict as (a load turned or misplaced there)."""
        return []

    @classmethod
    def split_columns(cls, ctx: CandidateContext, split: "SplitDeck") -> tuple[DofLabel, ...]:
        """DOFs the split run must load one by one for this family's candidates, beyond the
        joint boundary and the measured DOFs (the split run's own unit loads)."""
        return ()

    # ---- identity and parameters ------------------------------------------------------------------
    @property
    def key(self) -> tuple:
        return (self.kind, tuple(self.where))

    @property
    def n_params(self) -> int:
        return len(self.names)

    @property
    def nominal(self) -> np.ndarray:
        """The parameters at which the effect is absent (the model it extends, exactly)."""
        return np.ones(self.n_params)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.full(self.n_params, 0.2), np.full(self.n_params, 5.0)

    @property
    def one_sided(self) -> np.ndarray:
        """Parameters whose nested value is a bound (score test over a cone)."""
        return np.zeros(self.n_params, bool)

    def applicable(self, spec: "ModelSpec") -> bool:
        """Whether the effect can still be added to ``spec``."""
        return True

    @classmethod
    def refresh(cls, pool: list["Effect"], fit: "Fit", om: "ObsMap", labels: Sequence[str]) -> list["Effect"]:
        """The candidates of a new round: ``pool`` with those of this family that depend on the
        current fit re-listed from it (default: unchanged; load-scale groups found from the data
        are re-found from each round's residuals)."""
        return pool

    # ---- how the effect enters the augmented model -------------------------------------------------
    def joint_models(self, spec: "ModelSpec", x: np.ndarray) -> tuple[tuple["JointModel", ...], np.ndarray]:
        """The joints after adding the effect and their parameters (default: unchanged)."""
        return spec.joints, x[:spec.joint_params]

    @property
    def stiffness_dofs(self) -> tuple[DofLabel, ...]:
        """DOFs of the split deck on which :meth:`stiffness_terms` act."""
        return ()

    def stiffness_terms(self) -> list[tuple[int, np.ndarray]]:
        """``[(q, K_q)]``: ``dK += (x_q - nominal_q) K_q`` over :attr:`stiffness_dofs`."""
        return []

    def stiffness_matrix(self, x_effect: np.ndarray) -> np.ndarray | None:
        """A stiffness change nonlinear in the effect's parameters: ``dK(x_effect)`` over
        :attr:`stiffness_dofs` (``(n_dofs, n_dofs)``, exactly 0 at :attr:`nominal`), added to
        the linear :meth:`stiffness_terms`; ``None`` (default): none."""
        return None

    def stiffness_derivatives(self, x_effect: np.ndarray) -> np.ndarray | None:
        """``d dK / dx_q`` of :meth:`stiffness_matrix` at ``x_effect``: ``(n_params, n_dofs, n_dofs)``."""
        return None

    @property
    def load_dofs(self) -> tuple[DofLabel, ...]:
        """DOFs at which the effect changes the study's loads (:meth:`load_change`); their
        unit-load columns must be in the split run (:meth:`split_columns`)."""
        return ()

    def load_change(self, x_effect: np.ndarray, cases: Sequence[str]) -> np.ndarray:
        """``(len(load_dofs), len(cases))``: what the effect adds to the study's loads at
        :attr:`load_dofs` in each of ``cases`` (the split run's case labels), exactly 0 at
        :attr:`nominal`. The structure's response follows by linearity."""
        raise NotImplementedError

    def load_change_derivatives(self, x_effect: np.ndarray, cases: Sequence[str]) -> np.ndarray:
        """``d load_change / dx_q``: ``(n_params, len(load_dofs), len(cases))``."""
        raise NotImplementedError

    @property
    def case_joint(self) -> str | None:
        """The declared joint whose stiffness this effect makes depend on the load case (a gap:
        softer on one side; a joint softer at larger amplitude), or ``None``. The joint's
        parameters ``k_i`` then act as ``phi_ic k_i`` in case ``c``, :meth:`case_factors` giving
        ``phi``; several such effects on one joint multiply their factors."""
        return None

    def case_factors(self, rel: np.ndarray, x_effect: np.ndarray,
                     cases: Sequence[str] | None = None) -> np.ndarray:
        """``phi`` ``(joint params, cases)`` from each spring's relative rotation ``rel`` (same
        shape: branch ``i`` minus branch ``j`` about the spring's axis) in each case, or from
        what is known of each case beforehand: ``cases`` are the labels of ``rel``'s columns
        (``None``: not known)."""
        return np.ones_like(rel)

    def case_factor_derivatives(self, rel: np.ndarray, x_effect: np.ndarray,
                                cases: Sequence[str] | None = None) -> np.ndarray:
        """``d phi / d x_effect``: ``(n_params, joint params, cases)``, the sides held fixed."""
        return np.zeros((self.n_params, *rel.shape))

    @property
    def cut_pairs(self) -> tuple[int, ...]:
        """Indices of the split deck's cut pairs this effect releases (compliance form)."""
        return ()

    @property
    def compliance_basis(self) -> np.ndarray | None:
        """``(n_params, m, m)``: compliance per unit parameter over :attr:`cut_pairs`."""
        return None

    @property
    def acts_on_output(self) -> bool:
        """True when the parameters only scale predictions (:meth:`output_rows`) or offset them
        (:meth:`offset_rows`), no structure."""
        return False

    def output_rows(self, om: "ObsMap") -> list[tuple[int, np.ndarray]]:
        """``[(q, rows)]``: the predictions at ``rows`` (a mask over ``om``) are multiplied by ``x_q``."""
        return []

    def offset_rows(self, om: "ObsMap") -> list[tuple[int, np.ndarray]]:
        """``[(q, rows)]``: ``x_q`` is added to the predictions at ``rows`` (after the factors):
        a mask or indices, or float weights over every row of ``om`` (``x_q`` times each)."""
        return []

    def mix_rows(self, om: "ObsMap", o_index: dict) -> list[tuple]:
        """``[(q, rows, terms)]`` or ``[(q, rows, terms, cases)]``: the predictions at ``rows``
        (indices into ``om``) read, in part ``x_q``, a source instead of their own DOF:
        ``f += x_q (source - f)``, the source ``sum(w * U[idx, case])`` over ``terms = [(idx, w)]``
        (observed-DOF indices per row, ``o_index``, and weights), minus the row's reference DOF
        when it has one, in the row's own case or in ``cases`` (a column of ``U`` per row: the
        readings of another case). Applied before the factors and offsets
        (:meth:`ObsMap.source`)."""
        return []

    @property
    def source_dofs(self) -> tuple[DofLabel, ...]:
        """DOFs a mix reads beyond the measured ones (the augmented model must observe them)."""
        return ()

    of_data: ClassVar[bool] = False
    """Whether the effect is a defect of the test data (a reading, a channel, a sensor, a load
    cell or its set-up) rather than of the structure's model: reported as "the data, not the
    structure"."""

    # ---- scoring and refits -----------------------------------------------------------------------
    def scored_columns(self, before: "ModelSpec", after: "ModelSpec") -> tuple[np.ndarray, np.ndarray]:
        """Columns of ``after``'s Jacobian that the score test of this effect uses, and which of
        them are one-sided (default: the effect's own parameters, appended last)."""
        return np.arange(before.n_params, after.n_params), self.one_sided

    @classmethod
    def sparse_columns(cls, model: "AugmentedModel", st: "State", x: np.ndarray, om: "ObsMap",
                       effects: Sequence["Effect"]) -> list[tuple[np.ndarray, np.ndarray]] | None:
        """Unwhitened score columns of candidates NOT in ``model``, each as ``(rows, values)``
        over the few rows it touches (a reading, a channel; ``values`` of shape ``(len(rows),
        n_params)`` for several parameters), or ``None``: for families with thousands of
        candidates, whose dense columns would not fit."""
        return None

    @classmethod
    def batch_columns(cls, model: "AugmentedModel", st: "State", x: np.ndarray, om: "ObsMap",
                      effects: Sequence["Effect"]) -> np.ndarray | None:
        """Unwhitened score columns ``(n_obs, len(effects))`` of candidates NOT in ``model``
        without building their augmented models, or ``None`` (score each by augmentation)."""
        return None

    def refit_columns(self) -> tuple[DofLabel, ...]:
        """Unit-load columns of the split run that a refit of this effect needs."""
        return ()

    @property
    def screen_point(self) -> np.ndarray | None:
        """Parameters at which the effect is wholly present, where the search evaluates the
        candidate's chi2 exactly (every other parameter held) before it decides what to refit
        (:func:`blackbox.diagnosis.search.screen`): a score at the nested point cannot see an
        effect that is small to first order and large when complete (a stiff brace left out:
        halving it changes little, removing it everything). ``None`` (default): the score alone.
        Needs :meth:`refit_columns`."""
        return None

    def screen_points(self) -> list[tuple["Effect", np.ndarray]]:
        """``(effect, parameters)``: every way the screen evaluates the candidate wholly present
        (:func:`blackbox.diagnosis.search.screen` keeps the largest drop). Default: this effect
        at :attr:`screen_point`, when it has one. An entry may be another variant of the same
        candidate (same :attr:`key`), one the score of this variant cannot point to (a member's
        section turned about its axis: its plane-1 and plane-2 changes cancel in one factor)."""
        return [] if self.screen_point is None else [(self, self.screen_point)]

    def started_at_screen(self, which: int = 0) -> "Effect":
        """This candidate with its refit also started at entry ``which`` of
        :meth:`screen_points` (the search asks when the screen shows more than the score: the
        effect is large only when complete); default: itself."""
        return self

    def refit_starts(self, x2: np.ndarray, step: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                     first: int) -> list[np.ndarray]:
        """Starts of the refit: the nested point ``x2`` and one score step from it (the effect's
        parameters are ``x2[first:]``)."""
        starts = [x2]
        if self.n_params and np.all(np.isfinite(step)):
            xs = x2.copy()
            xs[first:] = np.clip(x2[first:] + step, lo[first:], hi[first:])
            starts.append(xs)
        return starts

    def rejection(self, x_effect: np.ndarray) -> str | None:
        """Why a refit that ended at ``x_effect`` does not describe this effect (a "sign flip"
        whose factor stayed positive), or ``None``; such a refit is not accepted. By default: a
        parameter held at a bound other than its nested value (a load scale or a sensor gain at
        its limit): the data push it beyond any plausible value, so the effect is absorbing a
        misfit it does not describe. Kinds whose bound is a physical state say so in their own
        (a member missing, a connection released)."""
        x = np.asarray(x_effect, float)
        lo, hi = self.bounds
        nom = self.nominal
        for q, name in enumerate(self.names):
            for b, side in ((hi[q], "upper"), (lo[q], "lower")):
                if np.isfinite(b) and b != nom[q] and abs(x[q] - b) <= 1e-9 * max(abs(b), 1.0):
                    return (f"{name} ends at its {side} bound {b:g}: beyond any plausible value, the effect "
                            "absorbs a misfit it does not describe")
        return None

    def trimmed(self, x_effect: np.ndarray) -> "Effect | None":
        """After a refit: the effect with parameters that ended at their nested bound removed, or
        ``None`` when every parameter stays."""
        return None

    def capped(self, x_effect: np.ndarray) -> "Effect | None":
        """After a refit that ended with a parameter at a bound :meth:`rejection` calls
        implausible: the effect with that parameter's bound brought back to the plausible point
        its refit started from (a screen point), or ``None`` when there is none. The search keeps
        the capped refit when the data do not tell the two apart
        (:func:`blackbox.diagnosis.search.refit_candidate`): the parameter then ran loose to the
        bound, it was not pushed."""
        return None

    @property
    def hypothesis(self) -> object:
        """What this candidate is one hypothesis of, in the search's multiplicity count: itself
        (its key) by default; candidates chosen from the data as one family (load-scale groups
        found from the case scales) share one, and their test accounts for the choice
        (:meth:`selection_log_sf`)."""
        return self.key

    def selection_log_sf(self, t: float) -> float | None:
        """The natural log of the p-value of a likelihood ratio ``t`` (already divided by the
        misfit factor) for a candidate that the data chose among others of its family, or
        ``None`` for a candidate fixed before the data were seen (the plain chi2 test)."""
        return None

    @property
    def variant_tests(self) -> int:
        """How many variant-against-variant LR tests refining this candidate can make (counted
        in the search's multiplicity control)."""
        return 0

    def richer(self, x_effect: np.ndarray) -> list[tuple["Effect", np.ndarray]]:
        """The richer variants of this effect at the same place, each with its parameters at the
        nested point (where it predicts exactly what this effect predicts at ``x_effect``);
        empty for the richest variant or a family with one parameterisation."""
        return []

    # ---- reports ----------------------------------------------------------------------------------
    def where_json(self) -> list:
        return [w if isinstance(w, str) else int(w) for w in self.where]

    def details_json(self) -> dict:
        """Keys beside ``where`` that locate the effect further (a sensor's component) or name
        its parameterisation (``variant``)."""
        return {"variant": self.variant} if self.variant else {}

    def findings(self, fit: "Fit") -> dict:
        """What the fitted values say beyond the parameters (a channel's readings drift over
        the test), for the report; empty by default."""
        return {}

    def set_aside_rows(self, om: "ObsMap") -> np.ndarray | None:
        """Rows of ``om`` whose readings this effect declares unusable in every case (a bad
        channel's), which a hold-out check then leaves out; ``None`` (default): none."""
        return None

    def holdout_scale_free(self, hold: "ObsMap") -> bool:
        """Whether the hold-out cases judge this effect with each case's own scale of its
        predicted responses taken out (:func:`blackbox.diagnosis.search.scale_profiled`): an
        effect on the loads of fitted cases only, which changes the hold-out prediction only
        through the structure's refit, and whose defect the hold-out cases may share unseen (a
        load cell of a test day that also ran hold-out cases). ``False`` (default)."""
        return False

    def subsumes(self, other: "Effect") -> bool:
        """Whether ``other``, already in the model, describes nothing this effect does not (an
        offset of a channel whose every reading this effect sets aside): it leaves the model
        when this effect enters, so no two parameters describe one thing."""
        return False

    def label(self) -> str:
        v = f" ({self.variant})" if self.variant else ""
        return f"{self.kind} @ {', '.join(map(str, self.where))}{v}"

    def in_fit(self, fit: "Fit") -> tuple["Effect", slice]:
        """``(effect, slice)``: this effect as ``fit`` holds it (same key; its variant may be a
        refined one) and its parameters' slice of ``fit.x`` (it must be part of ``fit``)."""
        i = next(i for i, e in enumerate(fit.spec.effects) if e.key == self.key)
        return fit.spec.effects[i], fit.spec.effect_slices()[i]

    def parameters(self, fit: "Fit") -> list[dict]:
        """``[{name, value, std, ...}]`` of this effect in ``fit`` (it must be part of it)."""
        e, sl = self.in_fit(fit)
        return [{"name": n, "value": float(v), "std": finite_or_none(s)}
                for n, v, s in zip(e.names, fit.x[sl], fit.std[sl])]

    def marker_points(self, xyz: dict[int, np.ndarray], deck: "Deck") -> list[np.ndarray]:
        """Where to mark the effect on a residual map (none by default)."""
        return []


class OnChannel:
    """What an effect on one measurement channel (``component`` of grid ``where[0]``) reports:
    the component is part of its key, its details and its label, and it is marked at its grid.
    Mixed into an :class:`Effect` dataclass that declares ``component``."""

    @property
    def grid(self) -> int:
        return int(self.where[0])

    @property
    def key(self) -> tuple:
        return (self.kind, tuple(self.where), self.component)

    def details_json(self) -> dict:
        return {"component": self.component}

    def label(self) -> str:
        return f"{self.kind} @ {self.grid} component {self.component}"

    def marker_points(self, xyz, deck):
        return [xyz[self.grid]] if self.grid in xyz else []


class Share:
    """What an effect whose one parameter ``t`` is the share of a whole defect (0 nested, 1 the
    whole defect: two channels swapped, a sensor or a load on the neighbouring grid) does on top
    of :class:`Effect`: its refit also starts at the whole defect, and a share below 1/2 (mostly
    as declared) or above 3/2 (more than the defect can explain) is no defect of its kind. The
    share is nested at 0, one-sided and bounded to [0, 2]. Mixed into an :class:`Effect`
    dataclass that says how its share reads (:meth:`share_read`), what a low share is
    (:attr:`not_low`) and what the whole defect is called (:attr:`summary_noun`)."""
    not_low = ""
    summary_noun = ""

    def share_read(self, t: float) -> str:
        raise NotImplementedError

    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(1)

    @property
    def bounds(self):
        # beyond 1 (unphysical) only so that a defect of exactly 1 is an interior optimum with an
        # interval on both sides; a refit beyond 1.5 is rejected (rejection)
        return np.zeros(1), np.full(1, 2.0)

    @property
    def one_sided(self) -> np.ndarray:
        return np.ones(1, bool)

    def refit_starts(self, x2, step, lo, hi, first):
        whole = x2.copy()
        whole[first:] = 1.0
        return super().refit_starts(x2, step, lo, hi, first) + [whole]

    def rejection(self, x_effect: np.ndarray) -> str | None:
        t = float(np.asarray(x_effect)[0])
        if t < 0.5:
            return f"{self.share_read(t)}: {self.not_low}"
        if t > 1.5:
            return f"{self.share_read(t)}: more than {self.summary_noun} can explain"
        return None


class ReadsAnother(Share):
    """A :class:`Share` that channels read: the share of another DOF's displacement, or another
    case's, that they read (two channels swapped, a sensor on the neighbouring grid, two cases
    exchanged). It acts on the readings only, where it reads (:meth:`Effect.mix_rows`, one
    parameter), from which its score columns follow."""

    @property
    def acts_on_output(self) -> bool:
        return True

    @classmethod
    def sparse_columns(cls, model, st, x, om, effects):
        # the one parameter's column: (source - own reading) on the mixed rows, times the factors
        o_index = {d: i for i, d in enumerate(model.o_dofs)}
        mult = model.multiplier(x, om)
        U = st.U_O
        own = om.pick(U)
        out = []
        for e in effects:
            rows_all, vals_all = [], []
            for _, rows, terms, *cases in e.mix_rows(om, o_index):
                rows_all.append(rows)
                vals_all.append(mult[rows] * (om.source(U, rows, terms, cases[0] if cases else None) - own[rows]))
            out.append((np.concatenate(rows_all) if rows_all else np.zeros(0, int),
                        np.concatenate(vals_all) if vals_all else np.zeros(0)))
        return out


class JointCaseEffect(Effect):
    """An effect that makes a declared simple-model joint's stiffness depend on the load case
    (``where``: the joint's name; a gap, softening with amplitude, unloading): offered while
    that joint is in the model, and its :attr:`case_joint`."""

    def applicable(self, spec) -> bool:
        return any(j.name == self.where[0] and isinstance(j, SimpleJoint) for j in spec.joints)

    @property
    def case_joint(self) -> str | None:
        return str(self.where[0])


class FreeOffsets:
    """What an effect whose parameters are offsets added to readings declares: nested at 0,
    unbounded, acting on the output only. Mixed into an :class:`Effect` dataclass."""

    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(self.n_params)

    @property
    def bounds(self):
        return np.full(self.n_params, -np.inf), np.full(self.n_params, np.inf)

    @property
    def acts_on_output(self) -> bool:
        return True


@dataclass(frozen=True, eq=False)
class SetAsideEffect(FreeOffsets, Effect):
    """An effect that sets readings aside (a bad channel, a bad case): one free offset per group
    of rows (:meth:`offset_rows`, disjoint masks), nested at 0 and unbounded. ``readings`` and
    ``sigmas``: each group's reading when the candidate was listed (the mean of repeats) and that
    mean's standard deviation, from which :meth:`findings` reads the model's own prediction
    (``reading - offset``: the offset makes the group's residual zero)."""
    readings: tuple[float, ...] = ()
    sigmas: tuple[float, ...] = ()

    @staticmethod
    def grouped_readings(obs: "Observations", outer, inner) -> dict:
        """``{outer key: {inner key: (mean, sigma of the mean)}}`` of the rows of ``obs``, each
        key a function of ``(grid, component, case label)``; repeats are averaged by their
        weights ``1 / sigma^2``."""
        labels = obs.case_labels
        per: dict = {}
        for (g, c), ci, v, sg in zip(obs.dofs, obs.case_index, obs.values, obs.sigma):
            key = (int(g), int(c), labels[int(ci)])
            per.setdefault(outer(*key), {}).setdefault(inner(*key), []).append((float(v), float(sg)))
        out: dict = {}
        for k, groups in per.items():
            out[k] = {}
            for j, vals in groups.items():
                v = np.array(vals)
                w = 1.0 / v[:, 1] ** 2
                out[k][j] = (float(np.sum(w * v[:, 0]) / np.sum(w)), float(1.0 / np.sqrt(np.sum(w))))
        return out

    @classmethod
    def sparse_columns(cls, model, st, x, om, effects):
        out = []
        for e in effects:
            masks = np.array([m for _, m in e.offset_rows(om)], bool).reshape(e.n_params, -1)
            rows = np.flatnonzero(masks.any(axis=0))
            out.append((rows, masks[:, rows].T.astype(float)))
        return out

    def model_readings(self, fit: "Fit") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(readings, the model's prediction of them, sigmas)`` in ``fit``, which holds this effect."""
        y = np.array(self.readings)
        return y, y - fit.x[self.in_fit(fit)[1]], np.array(self.sigmas)
