"""The declared model of a study: what every command fits, built in one place.

A study declares its joints (grids, model, start value, rigid branch pairs, springs already in
the deck) and its identification options (hold-out cases, confidence, iteration limits).
:func:`declared_model` turns that into a :class:`DeclaredModel`; ``identify``, ``compare``,
``diagnose``, ``simulate`` and ``bench`` all build their condensed model through
:meth:`DeclaredModel.condensed_model`, so the same parameters give the same response in each.

Rigid branch pairs (Sec. 2.2, last paragraph): a pair named in ``rigid_pairs`` is tied by a
penalty of ``RIGID_FACTOR`` times the stiffest rotational stiffness the structure offers at the
joint, carried as a *negative* deck stiffness (``dK = K_J(k) - K_deck``). The joint matrices stay
linear in ``k`` and every scheme (fixed point included) stays exact. A simple model loses the
pair's springs; a complex model keeps its ``K_C`` and gets the same tie, because the pair's
rigidity is a property of the structure, not of the joint model chosen to fit it.

Also here: the one record of what the solver cost (:class:`SolverCost`) and the readers of a
simulated study's truth (``truth.toml`` for ``simulate``, ``truth.json`` written by it).
"""

from __future__ import annotations

import copy
import itertools
import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np
from pydantic import ValidationError

from blackbox.condensation import Condensed, CondensedModel, condense
from blackbox.errors import StudyError
from blackbox.joints import (PLANES, ComplexJoint, JointModel, SimpleJoint, actual_joint_stub_kc, make_joint,
                             spring_network)
from blackbox.study import Study, joint_branches, read_text, study_file
from solver_adapters.protocol import (Deck, DofLabel, LoadMatrix, ScalarSpring, SolverAdapter, Spring,
                                     UnstableStructureError)

if TYPE_CHECKING:
    from blackbox.identification import Observations
    from blackbox.simulation import TruthConfig

__all__ = ["RIGID_FACTOR", "SolverCost", "FitOptions", "DeclaredModel", "declared_model",
           "joint_model", "constrained_springs", "deck_with_springs", "rigid_pair_penalty", "read_truth",
           "read_truth_record", "truth_values", "truth_joints", "stub_params"]

RIGID_FACTOR = 1e6
"""A rigid pair's penalty: 1e6 times the stiffest rotational stiffness the structure offers at
the joint (1 / smallest flexibility there). Rigid to ~1e-6 of the relative rotation, while the
condensed system keeps ~10 digits in double precision."""


# --------------------------------------------------------------------------------------------
# what the solver cost
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SolverCost:
    """Solver runs of a command: batches actually solved, right-hand sides, wall time, and the
    batches read back from the run cache instead of being solved."""
    adapter: str
    runs: int = 0
    right_hand_sides: int = 0
    wall_s: float = 0.0
    cached_batches: int = 0

    @classmethod
    def of(cls, adapter: SolverAdapter) -> "SolverCost":
        """What ``adapter`` has done so far (its ``stats``; cache hits when it is cached)."""
        st = adapter.stats
        cache = getattr(adapter, "cache_stats", None)
        return cls(adapter.name, int(st.runs), int(st.right_hand_sides), float(st.wall_s),
                   int(cache.hits) if cache is not None else 0)

    @classmethod
    def of_batch(cls, c: Condensed, adapter: SolverAdapter, before: "SolverCost") -> "SolverCost":
        """The cost of the one batched run that made ``c`` (``before``: :meth:`of` just before it).
        A batch read back from the cache counts its right-hand sides but no run."""
        hits = cls.of(adapter).cached_batches - before.cached_batches
        rhs = c.right_hand_sides if c.solver_runs or not hits else len(c.boundary) + len(c.cases)
        return cls(adapter.name, c.solver_runs, rhs, c.wall_s, hits)

    def __add__(self, other: "SolverCost") -> "SolverCost":
        name = self.adapter if self.adapter == other.adapter else f"{self.adapter}+{other.adapter}"
        return SolverCost(name, self.runs + other.runs, self.right_hand_sides + other.right_hand_sides,
                          self.wall_s + other.wall_s, self.cached_batches + other.cached_batches)

    def since(self, earlier: "SolverCost") -> "SolverCost":
        """The cost between ``earlier`` and this record of the same adapter."""
        return SolverCost(self.adapter, self.runs - earlier.runs,
                          self.right_hand_sides - earlier.right_hand_sides,
                          self.wall_s - earlier.wall_s, self.cached_batches - earlier.cached_batches)

    def to_json(self) -> dict:
        return {"runs": self.runs, "right_hand_sides": self.right_hand_sides, "wall_s": self.wall_s,
                "adapter": self.adapter, "cached_batches": self.cached_batches}


# --------------------------------------------------------------------------------------------
# options and the declared model
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FitOptions:
    """The study's ``[identification]`` options that the estimator takes."""
    fixed_point: bool = True
    max_iterations: int = 30                 # as [identification] max_iterations
    confidence: float = 0.95
    bootstrap: int = 0
    profile: bool = True

    def kwargs(self, **overrides) -> dict:
        out = {"fixed_point": self.fixed_point, "max_iterations": self.max_iterations,
               "confidence": self.confidence, "bootstrap": self.bootstrap, "profile": self.profile}
        out.update(overrides)
        return out


@dataclass(frozen=True, eq=False)
class DeclaredModel:
    """A study's joints as models, with start values, deck springs, rigid pairs and options."""
    study: Study
    joints: tuple[JointModel, ...]
    k0: np.ndarray
    options: FitOptions
    holdout: tuple[str, ...] = ()
    deck_stiffness: tuple[float, ...] = field(default=())

    @property
    def boundary(self) -> list[DofLabel]:
        """The joints' DOFs, joint after joint (the condensation's boundary)."""
        return [d for j in self.joints for d in j.dofs]

    @property
    def param_labels(self) -> list[tuple[str, str]]:
        return [(j.name, n) for j in self.joints for n in j.param_names]

    @property
    def n_params(self) -> int:
        return int(sum(j.n_params for j in self.joints))

    def deck_matrix(self) -> np.ndarray | None:
        """``K_deck`` of the simple-model springs of ``deck_stiffness`` already in the deck."""
        blocks = []
        for j, ks in zip(self.joints, self.deck_stiffness):
            s = SimpleJoint(j.name, tuple(j.grids))
            blocks.append(s.matrix(np.full(s.n_params, ks)))
        if not any(np.any(b) for b in blocks):
            return None
        n = sum(b.shape[0] for b in blocks)
        K = np.zeros((n, n))
        i = 0
        for b in blocks:
            K[i:i + b.shape[0], i:i + b.shape[0]] = b
            i += b.shape[0]
        return K

    def K_deck(self, c: Condensed) -> np.ndarray | None:
        """What the deck already holds between the joints' DOFs, over ``c.boundary`` (which holds
        the joints' DOFs in any order, possibly among others): the deck springs minus the
        rigid-pair penalty (a negative deck stiffness adds the penalty to ``dK``). ``None`` when
        neither is declared."""
        index = {d: i for i, d in enumerate(c.boundary)}
        n = len(c.boundary)
        K = np.zeros((n, n))
        found = False
        for j, ks in zip(self.joints, self.deck_stiffness):
            if ks:
                s = SimpleJoint(j.name, tuple(j.grids))
                idx = np.array([index[d] for d in j.dofs])
                K[np.ix_(idx, idx)] += s.matrix(np.full(s.n_params, ks))
                found = True
        rigid = rigid_pair_penalty(c, self.joints, self.rigid_pairs())
        if rigid is not None:
            K -= rigid
            found = True
        added = c.added_stiffness()                  # reference springs the condensation added
        if added is not None:
            K += added
            found = True
        return K if found else None

    def reference_springs(self) -> tuple[list[ScalarSpring], dict[str, float]]:
        """Reference springs across every joint the deck does not already couple
        (``deck_stiffness`` 0): the simple model's springs (those that can act), each of the
        joint's ``initial`` stiffness, and ``{joint: stiffness}``. Added to the solver's deck when
        the structure with its joints released is a mechanism (:meth:`condense`)."""
        springs, used = [], {}
        initial = {jc.name: float(jc.initial) for jc in self.study.config.joints}
        for j, ks in zip(self.joints, self.deck_stiffness):
            if ks:
                continue
            ref = SimpleJoint(j.name, tuple(j.grids),
                              constrained_springs=constrained_springs(self.study.deck, j.grids))
            if not ref.n_params:
                continue
            k = initial.get(j.name, 1.0e3)
            springs += spring_network(ref, np.full(ref.n_params, k))
            used[j.name] = k
        return springs, used

    def rigid_pairs(self) -> dict[str, tuple[tuple[int, int], ...]]:
        """Branch pairs (1-based) declared rigid, per joint name."""
        out = {}
        for jc in self.study.config.joints:
            if jc.rigid_pairs:
                out[jc.name] = tuple((jc.grids.index(a) + 1, jc.grids.index(b) + 1) for a, b in jc.rigid_pairs)
        return out

    def condensed_model(self, c: Condensed) -> CondensedModel:
        """The declared model on a condensation whose boundary holds the joints' DOFs (checked
        first: :meth:`check_boundary_held`)."""
        self.check_boundary_held(c)
        return CondensedModel(c, list(self.joints), self.K_deck(c))

    def check_boundary_held(self, c: Condensed) -> None:
        """:class:`StudyError` when a joint DOF did not move under its own unit load although the
        deck does not constrain it: the solver removed it. That is AUTOSPC (NASTRAN's SOL 101
        default, in the reference solver and MYSTRAN too): it constrains a component no element
        of the deck gives stiffness, which is right for the deck alone but not for the structure,
        where the joint's springs would hold it. The condensation would then take the joint DOF
        as fixed and every estimate would be wrong without a sign; the structure must hold each
        joint DOF by its own members (a branch member pinned at the joint, for example, does not
        hold the branch's rotation). A DOF the deck's SPC or GRID PS constrains is fixed on
        purpose and passes."""
        index = {d: i for i, d in enumerate(c.boundary)}
        fixed = _deck_constrained(self.study.deck)
        scale = float(np.max(np.abs(np.diag(c.G_BB)), initial=0.0))
        for j in self.joints:
            gone = [d for d in j.dofs if d in index and d not in fixed
                    and not abs(c.G_BB[index[d], index[d]]) > 0.0]
            if gone and scale > 0.0:
                raise StudyError(
                    f"joint {j.name!r}: DOF(s) {gone[:8]} (grid, component) do not move under a load "
                    f"there although the deck does not constrain them: the solver removed them, as "
                    f"AUTOSPC (NASTRAN's default) does with a component no element of the deck gives "
                    f"stiffness. Only the joint's springs would hold them, which the deck alone does not "
                    f"have; the black-box condensation needs every joint DOF held by the structure's own "
                    f"members (e.g. no pin flag on a branch member's end at the joint)",
                    file=str(self.study.deck_path))

    def condense(self, adapter: SolverAdapter, observed: Sequence[DofLabel] | None = None,
                 loads: LoadMatrix | None = None) -> CondensedModel:
        """The one batched run (unit loads at the joints' DOFs plus the load cases), then
        :meth:`condensed_model`. ``observed`` defaults to every DOF the measurements need.

        When the structure with its joints released is a mechanism (a joint is the structure's
        only support, e.g. a column on a base joint), the run is repeated with
        :meth:`reference_springs` across the joints and those springs are accounted for exactly
        (``blackbox.condensation``, "Reference springs"); a mechanism that remains is a
        :class:`StudyError` naming the joints and the DOFs that move."""
        if observed is None:
            observed = self.study.measurements.all_dofs if self.study.measurements is not None else []
        loads = loads if loads is not None else self.study.loads
        try:
            c = condense(adapter, loads, self.boundary, list(observed))
        except UnstableStructureError as exc:
            springs, used = self.reference_springs()
            if not springs:
                raise
            try:
                c = condense(adapter, loads, self.boundary, list(observed), springs=springs)
            except UnstableStructureError as still:
                raise self._mechanism_error(still, used) from None
        return self.condensed_model(c)

    def _mechanism_error(self, exc: UnstableStructureError, used: dict[str, float]) -> StudyError:
        """The structure stays a mechanism with reference springs across ``used``: say which
        joints' DOFs move (the solver's list, when it gives one) and what that means."""
        moving = set(exc.dofs)
        parts = []
        for j in self.joints:
            mine = [d for d in j.dofs if d in moving]
            if mine:
                shown = ", ".join(f"{g}:{c}" for g, c in mine[:12])
                parts.append(f"joint {j.name!r} moves at {shown} (grid:component)")
        if parts:
            where = ("; ".join(parts) + ": springs across a joint only join its branches' rotations, so the "
                     "branches together must still be held by the structure (a support the joint needs is "
                     "missing, e.g. the footing grid clamped in translation only)")
        elif moving:
            where = "no joint DOF is among the DOFs that move: a support or a tie elsewhere is missing"
        else:
            where = ("the solver does not say which DOFs move: a support or tie is missing, at a joint (one "
                     "whose branches together nothing else holds) or elsewhere")
        names = ", ".join(f"{n!r} ({k:g})" for n, k in used.items())
        return StudyError(f"the structure is a mechanism with its joints released, and it still is with "
                          f"reference springs across joint(s) {names}: {where}. The solver said: {exc}",
                          file=str(self.study.deck_path))

    def observations(self, cases: Sequence[str] | None = None) -> tuple["Observations", "Observations | None"]:
        """The study's measurements as fit rows and hold-out rows (``None`` without hold-out)."""
        from blackbox.identification import Observations

        if self.study.measurements is None:
            raise StudyError("measurements.csv not found (needed for this command)", file=str(self.study.root))
        obs = Observations.from_measurements(self.study.measurements, list(cases or self.study.loads.cases))
        return obs.split(list(self.holdout)) if self.holdout else (obs, None)

    def with_holdout(self, holdout: Sequence[str]) -> "DeclaredModel":
        return DeclaredModel(self.study, self.joints, self.k0, self.options, tuple(holdout), self.deck_stiffness)


def _deck_constrained(deck) -> set[DofLabel]:
    """Every (grid, component) an SPC/SPC1 set of the deck or a GRID PS constrains."""
    out = {(g, int(c)) for s in deck.spc1s for g in s.grids for c in s.components}
    out |= {(g.id, int(c)) for g in deck.grids.values() for c in g.ps}
    return out


def joint_model(study: Study, name: str, model: str) -> JointModel:
    """Joint ``name`` of the study as a ``model`` joint, its rigid pairs applied (a simple model
    has no springs for them)."""
    jc = next((j for j in study.config.joints if j.name == name), None)
    if jc is None:
        raise StudyError(f"no joint {name!r} in the study ({[j.name for j in study.config.joints]})",
                         file=str(study.root / "study.toml"))
    opts = {}
    if model == "simple":
        if jc.rigid_pairs:                        # grid pairs -> branch numbers
            opts["rigid_pairs"] = tuple((jc.grids.index(a) + 1, jc.grids.index(b) + 1) for a, b in jc.rigid_pairs)
        held = constrained_springs(study.deck, jc.grids)
        if held:
            opts["constrained_springs"] = held
    return make_joint(jc.name, jc.grids, model, **opts)


def deck_with_springs(deck: Deck, springs: Sequence[ScalarSpring]) -> Deck:
    """A copy of ``deck`` with ``springs`` written in as CELAS2 cards (element IDs above every
    element ID of the deck): the deck the solver ran when a condensation added them."""
    out = copy.deepcopy(deck)
    eid = out.max_element_id()
    for s in springs:
        eid += 1
        g2, c2 = (int(s.b[0]), int(s.b[1])) if s.b is not None else (0, 0)
        out.springs[eid] = Spring(eid, int(s.a[0]), int(s.a[1]), g2, c2, k=float(s.k), card="CELAS2")
    return out


def constrained_springs(deck, grids: Sequence[int]) -> tuple[tuple[str, int, int], ...]:
    """The simple-model springs ``(plane, i, j)`` of a joint on ``grids`` that join two rotation
    components the deck's supports fix (SPC/SPC1 or GRID PS on both branch grids: a planar
    model's out-of-plane rotations). They cannot act, so they are no parameters."""
    fixed = _deck_constrained(deck)
    out = []
    for i, j in itertools.combinations(range(1, len(grids) + 1), 2):
        for p, c in zip(PLANES, (4, 5, 6)):
            if (grids[i - 1], c) in fixed and (grids[j - 1], c) in fixed:
                out.append((p, i, j))
    return tuple(out)


def declared_model(study: Study, model: str | None = None) -> DeclaredModel:
    """The study's declared model; ``model`` ("simple" | "complex") overrides every joint's."""
    joints, k0 = [], []
    for jc in study.config.joints:
        jm = joint_model(study, jc.name, model or jc.model)
        if jm.n_params == 0 and isinstance(jm, SimpleJoint) and jm.constrained_springs:
            raise StudyError(f"joint {jc.name!r}: the deck's supports fix both ends of every spring of the joint "
                             f"(SPC/GRID PS on the rotations of grids {jc.grids}), so the joint has no parameter "
                             "that could act; free a rotation or remove the joint", file=str(study.root / "study.toml"))
        if jm.n_params == 0:
            raise StudyError(f"joint {jc.name!r}: every branch pair is declared rigid, so the joint has no "
                             "parameter to identify; remove a pair from rigid_pairs, or the joint itself "
                             "(tie its branches in the deck)", file=str(study.root / "study.toml"))
        joints.append(jm)
        k0.append(jm.initial_params(jc.initial))
    cfg = study.config.identification
    options = FitOptions(fixed_point=cfg.fixed_point, max_iterations=cfg.max_iterations,
                         confidence=cfg.confidence, bootstrap=cfg.bootstrap, profile=cfg.profile)
    return DeclaredModel(study, tuple(joints), np.concatenate(k0) if k0 else np.zeros(0), options,
                         tuple(cfg.holdout_cases), tuple(float(jc.deck_stiffness) for jc in study.config.joints))


def rigid_pair_penalty(c: Condensed, joints: Sequence[JointModel],
                       pairs: dict[str, tuple[tuple[int, int], ...]] | None = None) -> np.ndarray | None:
    """The rigid-pair penalty over ``c.boundary`` (``None`` when no pair is rigid).

    ``pairs`` gives each joint's rigid branch pairs; by default a simple joint's own
    ``rigid_pairs``. The penalty of joint ``j`` is ``RIGID_FACTOR / min diag(G_BB)`` over its
    rotations: stiff against what the structure offers there."""
    index = {d: i for i, d in enumerate(c.boundary)}
    n = len(c.boundary)
    out = np.zeros((n, n))
    found = False
    for j in joints:
        jp = pairs.get(j.name, ()) if pairs is not None else getattr(j, "rigid_pairs", ())
        if not jp:
            continue
        idx = np.array([index[d] for d in j.dofs])
        scale = RIGID_FACTOR / float(np.min(np.diag(c.G_BB)[idx[3:]]))
        out[np.ix_(idx, idx)] += SimpleJoint(j.name, tuple(j.grids), tuple(jp)).rigid_penalty_matrix(scale)
        found = True
    return out if found else None


# --------------------------------------------------------------------------------------------
# truths of simulated studies
# --------------------------------------------------------------------------------------------
def read_truth(path: Path) -> "TruthConfig":
    """``truth.toml`` of ``blackbox simulate``."""
    from blackbox.simulation import TruthConfig

    try:
        return TruthConfig.model_validate(tomllib.loads(read_text(path)))
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"not valid TOML: {exc}", file=str(path)) from None
    except ValidationError as exc:
        msgs = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors())
        raise StudyError(msgs, file=str(path)) from None


def read_truth_record(study: Study) -> dict | None:
    """``truth.json`` written by ``blackbox simulate`` into a study (``None`` for real data)."""
    p = study.root / "truth.json"
    if not p.exists() and not p.is_symlink():
        return None
    study_file(study.root, "truth.json")
    try:
        rec = json.loads(read_text(p))
    except json.JSONDecodeError as exc:
        raise StudyError(f"not valid JSON: {exc}", file=str(p)) from None
    if not isinstance(rec, dict):
        raise StudyError("expected a JSON object", file=str(p))
    return rec


def truth_values(study: Study) -> dict[str, float] | None:
    """``{"joint.param": value}`` of a simulated study's truth (``None`` for real data)."""
    rec = read_truth_record(study)
    if not rec:
        return None
    return {f"{q['joint']}.{q['name']}": float(q["value"]) for q in rec.get("parameters", [])} or None


def stub_params(study: Study, joint: ComplexJoint, length: float) -> np.ndarray:
    """Complex-model parameters of the stub "actual joint" (Section 5.4.1) for this deck."""
    br = joint_branches(study.deck, joint.grids)
    b0 = br[0]
    K_C = actual_joint_stub_kc([b.direction for b in br], length, b0.E, b0.G, b0.A, b0.I2, b0.I1,
                               b0.J, [b.orientation for b in br])
    return joint.params_from_kc(K_C)


def truth_joints(study: Study, truth: "TruthConfig", truth_path: Path) -> tuple[list[JointModel], np.ndarray]:
    """The joint models and parameters of a ``truth.toml``."""
    by_name = {j.name: j for j in study.config.joints}
    models, params = [], []
    for tj in truth.joints:
        if tj.name not in by_name:
            raise StudyError(f"truth joint {tj.name!r} is not a joint of the study "
                             f"({sorted(by_name)})", file=str(truth_path))
        jm = joint_model(study, tj.name, tj.model)
        given = [x is not None for x in (tj.value, tj.values, tj.stub_length)]
        if sum(given) != 1:
            raise StudyError(f"truth joint {tj.name!r}: give exactly one of value, values, stub_length",
                             file=str(truth_path))
        if tj.values is not None:
            k = jm.from_dict(tj.values)
        elif tj.stub_length is not None:
            if not isinstance(jm, ComplexJoint):
                raise StudyError(f"truth joint {tj.name!r}: stub_length needs model = \"complex\"",
                                 file=str(truth_path))
            k = stub_params(study, jm, tj.stub_length)
        else:
            k = jm.initial_params(tj.value)
        models.append(jm)
        params.append(k)
    return models, (np.concatenate(params) if params else np.zeros(0))
