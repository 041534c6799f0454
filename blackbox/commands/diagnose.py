"""``blackbox diagnose STUDY``: find what the declared model lacks, add it, report before and after.

:func:`run` checks the options, reads the study and runs three decks through the study's adapter
(:func:`prepare_study`), each in one batched run:

1. the study's deck: the declared model's condensation and identification
   (:meth:`blackbox.declared.DeclaredModel.condense`, rigid pairs included, and
   :func:`blackbox.identification.identify`);
2. the element deck: every member alone, clamped at end a -> each member's ``K_e``;
3. the split deck: the study's deck cut by every selected connection family and bridged by ``K0``
   springs (:func:`blackbox.diagnosis.decks.split_deck`), with unit loads at the joint boundary and
   the measured DOFs, unit pair loads and the study's load cases.

The edited decks are run from a temporary folder, removed afterwards; their text is kept. Then
the loop of :mod:`blackbox.diagnosis.search`.

Run 2 has six right-hand sides however many members (:func:`blackbox.diagnosis.runs.element_flexibility`).
On a large model the candidates are capped (``max_joint_candidates`` undeclared-joint grids,
``max_member_candidates`` members, those nearest the declared fit's residual beyond; by default
every member up to :data:`MEMBER_GRIDS` end grids): the cap bounds run 3's right-hand sides and
rows, and the document says how many were left out.

With an executor of more than one worker (``run(..., executor=...)``, ``--workers N``), run 1 is
a task on the cluster (it carries the study folder in memory, :func:`blackbox.parallel.pack_study`,
and builds its adapter where it runs: no shared file system is needed) and runs while run 2 goes
here (one solver run: cutting six right-hand sides into chunks would only repeat the deck's
assembly). Run 3 is not independent of them: the split deck's ``K0`` springs come from run 2's
``K_e``, and when a cap applies its cuts and rows are chosen by run 1's residuals. It runs here, on
the client (whose adapter the loop keeps using for later columns), as soon as its inputs are in --
while run 1 is still on its worker when nothing in it needs the declared fit -- an external
solver's runs in column chunks over the workers (:func:`blackbox.parallel.use_executor`; each
chunk carries the deck's text). The solver's answers are the serial run's. The declared fit and
the candidates run here as serially; the loop's refits of a round go to the workers when that
pays (:func:`blackbox.diagnosis.search.refits_pay`: the split base sent once per round), else
here. :func:`run` returns a :class:`DiagnosisResult`; its
:meth:`~DiagnosisResult.write` puts ``diagnosis.json``, ``report.md``, the plots and the edited
decks (``decks/elements.bdf``, ``decks/split.bdf``) into a folder.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import functools
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from blackbox.adapters import make_adapter_for
from blackbox.commands.common import as_study
from blackbox.condensation import CondensedModel
from blackbox.declared import DeclaredModel, SolverCost, declared_model, deck_with_springs
from blackbox.diagnosis.decks import SplitDeck, cards_at, element_deck, member_ends, split_deck, unmodelled_notes
from blackbox.diagnosis.document import diagnosis_document, verdict_detail
from blackbox.diagnosis.effects import (CandidateContext, CandidateLimit, Effect, MemberStiffness, PDelta, Preload,
                                       RigidEndZone, families)
from blackbox.diagnosis.effects.load_scale import case_scales
from blackbox.diagnosis.effects.p_delta import axial_forces
from blackbox.diagnosis.effects.undeclared_joint import UndeclaredJoint, joint_candidate_grids
from blackbox.diagnosis.exchange import better, brief, exchange_pays, swapped_pair, with_sigmas_exchanged
from blackbox.diagnosis.runs import RunRecord, element_stiffness
from blackbox.diagnosis.search import Diagnosis, diagnose
from blackbox.diagnosis.split import SplitBase
from blackbox.errors import DiagnosisError, EditedDeckError
from blackbox.identification import IdentificationResult, Observations, identify
from blackbox.identification.fit_sigma import predict_rows
from blackbox.parallel import Executor, StudyPackage, pack_study, use_executor
from blackbox.study import Study, preload_matrix, read_load_groups
from solver_adapters.bdf_write import write_deck
from solver_adapters.deck import Deck
from solver_adapters.protocol import DofLabel, SolverAdapter, UnstableStructureError
from solver_adapters.subprocess import owned_tempdir

__all__ = ["DiagnosisResult", "Prepared", "PrepareTask", "Remote", "run", "prepare", "prepare_study",
           "prepare_run", "check_options", "MAX_JOINT_CANDIDATES", "MAX_MEMBER_CANDIDATES",
           "MEMBER_GRIDS", "member_cap"]

TEMP_PREFIX = "blackbox-diagnose-"
"""Name prefix of the temporary folder of one diagnose run (the decks it writes)."""

MAX_JOINT_CANDIDATES = 100
"""Undeclared-joint grids considered at most (those nearest the declared fit's residual beyond).
Each costs ``3 (n - 1)`` right-hand sides of the split run (12 for a grid of 5 members): 100
grids are ~1,200 right-hand sides, ~4 minutes of MYSTRAN on a 1e5-DOF body (docs/parallel.md);
a frame of up to 100 such grids (the fixtures, a 1e3-DOF body) has all of them considered."""

MAX_MEMBER_CANDIDATES = 300
"""Members considered for ``member_stiffness`` on a large model (those nearest the residual), when
``max_member_candidates`` is not given and the members' end grids are more than
:data:`MEMBER_GRIDS`. Each member adds its 12 end DOFs to the split run's reported rows and one
candidate (one hypothesis of the round's Bonferroni correction); a member far from every sensor
changes nothing it can see."""

MEMBER_GRIDS = 1000
"""Up to this many member end grids (6,000 rows of the split run, a 50 MB dense block at 1,000
right-hand sides), every member is considered: a cap counted in members would leave out a
member of a 400-member storey frame whose rows cost nothing next to its cut pairs. Beyond (the
1e5-DOF body: 16,635 grids, 3.2 GB for every member), :data:`MAX_MEMBER_CANDIDATES`."""


def member_cap(deck: Deck, requested: int | None) -> int:
    """The members considered at most: ``requested`` when given, else every member when their
    end grids are at most :data:`MEMBER_GRIDS`, else :data:`MAX_MEMBER_CANDIDATES`."""
    if requested is not None:
        return requested
    members = [*deck.cbars, *deck.rods]
    grids = {g for e in members for g in member_ends(deck, e)}
    return len(members) if len(grids) <= MEMBER_GRIDS else MAX_MEMBER_CANDIDATES


# --------------------------------------------------------------------------------------------
# the three decks' runs and the candidates
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Prepared:
    """The study, its declared model (with the diagnosis's hold-out), the declared fit, the
    members' stiffness, the split run and the candidates; ``decks``: ``(file name, text)`` of the
    edited decks; ``log``: every solver run so far (the loop appends its own)."""
    study: Study
    declared: DeclaredModel
    fit_obs: Observations
    hold_obs: Observations | None
    holdout: tuple[str, ...]
    declared_holdout: bool
    K_deck: np.ndarray | None
    ident: IdentificationResult | None
    K_e: dict[int, np.ndarray]
    element_asymmetry: float
    split: SplitDeck
    base: SplitBase
    candidates: tuple[Effect, ...]
    decks: tuple[tuple[str, str], ...]
    log: list[RunRecord]
    declared_cost: SolverCost
    element_adapter: SolverAdapter
    limits: tuple[CandidateLimit, ...] = ()
    """The families that considered fewer candidates than the study offers (their caps)."""
    declared_condensed: CondensedModel | None = None
    """The declared model on run 1's condensation: its predictions at any joint parameters."""
    holdout_candidates: tuple[Effect, ...] = ()
    """Effects in a hold-out case the hold-out check may read a case it does not predict as."""
    context: CandidateContext | None = None
    """What the candidates were listed from (listed again from other sigmas: :func:`exchanged`)."""

    @property
    def deck(self) -> Deck:
        return self.study.deck

    @property
    def joints(self) -> list:
        return list(self.declared.joints)

    @property
    def boundary(self) -> list[DofLabel]:
        return self.declared.boundary

    @property
    def adapter_name(self) -> str:
        return self.base.adapter.name

    def solver_cost(self) -> SolverCost:
        """What the three decks' runs cost so far (the declared condensation, the element run,
        the split runs). Right-hand sides count every batch, solved or read back from the cache
        (as :meth:`SolverCost.of_batch` counts the condensation's)."""
        cost = self.declared_cost + SolverCost.of(self.element_adapter) + SolverCost.of(self.base.adapter)
        return dataclasses.replace(cost, right_hand_sides=sum(r.right_hand_sides for r in self.log))


def _residual_rms(obs: Observations, r: np.ndarray) -> dict[int, float]:
    acc: dict[int, float] = {}
    for (g, _), z in zip(obs.dofs, r):
        acc[g] = acc.get(g, 0.0) + z * z
    return {g: math.sqrt(v) for g, v in acc.items()}


# --------------------------------------------------------------------------------------------
# run 1 on a cluster
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PrepareTask:
    """What travels to a worker for run 1 (``kind="declared"``: the declared model's
    condensation on the study's deck): the study folder in memory, the adapter's name, the
    client's cache folder (None: no cache) and the consent for an external command."""
    kind: str
    package: StudyPackage
    adapter: str | None
    cache: str | None
    trust_command: bool


def prepare_run(task: PrepareTask):
    """Run 1 where the task runs (a worker): rebuild the study folder, build the adapter there,
    run it. Returns ``(Condensed, SolverCost)`` (the identification stays on the client, as
    serially)."""
    from blackbox.adapters import ADAPTER_CACHE, TRUST_COMMAND
    from blackbox.commands.batch import _cache_for_worker
    from blackbox.parallel import scratch, unpack_study
    from blackbox.study import load_study

    cache, _ = _cache_for_worker(task.cache)
    tokens = (ADAPTER_CACHE.set(cache), TRUST_COMMAND.set(bool(task.trust_command)))
    try:
        with scratch() as tmp:
            study = load_study(unpack_study(task.package, tmp / "study"), need_measurements=True)
            if task.kind == "declared":
                adapter = make_adapter_for(study, task.adapter)
                before = SolverCost.of(adapter)
                # the same boundary and observed DOFs as the client's: both come from the study's files
                cm = declared_model(study).condense(adapter)
                return cm.c, SolverCost.of_batch(cm.c, adapter, before)
            raise ValueError(f"unknown prepare task {task.kind!r}")
    finally:
        ADAPTER_CACHE.reset(tokens[0])
        TRUST_COMMAND.reset(tokens[1])


@dataclass(frozen=True)
class Remote:
    """How :func:`prepare_study` sends run 1 to a cluster: the executor and what the task
    carries (see :class:`PrepareTask`)."""
    executor: Executor
    package: StudyPackage
    adapter: str | None
    cache: str | None
    trust_command: bool

    @classmethod
    def of(cls, study: Study, executor: Executor, adapter: str | None) -> "Remote":
        """The study packed once, the cache and consent the command would use here
        (:data:`blackbox.adapters.ADAPTER_CACHE`, :data:`~blackbox.adapters.TRUST_COMMAND`), the
        cache as an absolute folder of the client (a worker uses it when it sees it)."""
        from blackbox.adapters import ADAPTER_CACHE, TRUST_COMMAND
        from solver_adapters.cache import CACHE_DIRNAME

        c = ADAPTER_CACHE.get()
        cache = str(Path(study.root).absolute() / CACHE_DIRNAME) if c is True else (
            str(Path(c).absolute()) if c else None)
        return cls(executor, pack_study(study.root), adapter, cache, TRUST_COMMAND.get())

    def task(self, kind: str) -> PrepareTask:
        return PrepareTask(kind, self.package, self.adapter, self.cache, self.trust_command)


def _split_needs_declared_fit(deck: Deck, dm: DeclaredModel, fams, max_joint_candidates: int,
                              max_member_candidates: int) -> bool:
    """Whether the split run depends on the declared fit: when there is one and a capped family
    has more candidates than its cap, the fit's residuals choose them -- the undeclared-joint
    grids the split deck cuts (:meth:`UndeclaredJoint.cut`), the members whose end DOFs it
    reports (:meth:`MemberStiffness.split_rows`; :meth:`RigidEndZone.split_rows`, the members at
    the grids chosen as undeclared joints are)."""
    if not dm.joints:
        return False
    declared = {g for j in dm.joints for g in j.grids}
    return (((UndeclaredJoint in fams or RigidEndZone in fams)
             and len(joint_candidate_grids(deck, declared)) > max_joint_candidates)
            or (MemberStiffness in fams and len(deck.cbars) + len(deck.rods) > max_member_candidates))


def prepare_study(study: Study, adapter_for: Callable[[Path | None], SolverAdapter], deck_dir: Path, *,
                  max_joint_candidates: int = MAX_JOINT_CANDIDATES,
                  max_member_candidates: int | None = None, effects: Sequence[str] | None = None,
                  say: Callable[[str], None] | None = None, remote: Remote | None = None,
                  include_grids: Sequence[int] = ()) -> Prepared:
    """Fit the declared model, run the element and the split deck (written into ``deck_dir``),
    list the candidates of the families ``effects`` (default: all), at most
    ``max_joint_candidates`` undeclared-joint grids and ``max_member_candidates`` members (those
    nearest the declared fit's residual beyond; :attr:`Prepared.limits` says so), the grids
    ``include_grids`` beside the cap.
    ``adapter_for(path)``: the adapter for the deck at ``path`` (``None``: the study's own deck).
    ``remote``: run 1 as a task of its executor, the split runs in column chunks over it
    (module docstring); runs 2 and 3 stay on ``adapter_for``."""
    say = say or (lambda msg: None)
    fams = families(effects)
    if study.measurements is None:
        raise DiagnosisError(f"study {study.name!r} has no measurements.csv: nothing to diagnose")
    deck = study.deck
    if not deck.cbars:
        raise DiagnosisError(f"the deck of study {study.name!r} has no CBAR members: the diagnosis "
                             "builds its edited decks from members")
    max_member_candidates = member_cap(deck, max_member_candidates)
    deck_dir = Path(deck_dir)
    log: list[RunRecord] = []

    # ---- observations, hold-out ----------------------------------------------------------------
    dm = declared_model(study)
    obs = Observations.from_measurements(study.measurements, study.loads.cases)
    declared_holdout = tuple(dm.holdout)
    fit_obs, hold_obs = dm.observations(study.loads.cases)

    decks = []
    edeck, emembers, etips = element_deck(deck)
    epath = deck_dir / "elements.bdf"
    decks.append((epath.name, write_deck(edeck, "large")))
    epath.write_text(decks[-1][1])

    # the deck the split run cuts: the study's, plus the reference springs run 1 had to add
    # across the joints when they are the structure's only support (DeclaredModel.condense);
    # K_deck counts them, so the diagnosis sees what a deck with those springs written in sees
    held = {"deck": deck}
    # the declared permanent load (p_delta): its axial forces once the split run is in
    preload = preload_matrix(study.config) if PDelta in fams else None
    held["preload"] = Preload(preload) if preload is not None else None

    def fit_declared(c) -> tuple[np.ndarray, IdentificationResult, RunRecord]:
        """The declared model's identification on run 1's condensation (here, as serially)."""
        if c.added_springs:
            held["deck"] = deck_with_springs(deck, c.added_springs)
        cm = dm.condensed_model(c)
        held["condensed"] = cm
        rec = RunRecord("declared model: condensation", study.deck_path.name, cost.right_hand_sides, c.wall_s)
        ident = identify(cm, fit_obs, dm.k0, holdout=hold_obs, **dm.options.kwargs(profile=False, bootstrap=0))
        say(f"declared model: reduced chi2 = {ident.reduced_chi2:.4g} ({ident.n_obs} rows, "
            f"{ident.n_params} parameters)")
        return dm.K_deck(c), ident, rec       # deck springs minus the rigid-pair penalty

    ident, K_deck = None, None
    with concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="diagnose-declared") as pool:
        pending = None
        if remote is None:
            # ---- 1. the declared model on the study's deck ---------------------------------------
            adapter = adapter_for(None)
            cost = SolverCost(adapter.name)
            if dm.joints:
                before = SolverCost.of(adapter)
                cm = dm.condense(adapter)
                cost = SolverCost.of_batch(cm.c, adapter, before)
                K_deck, ident, rec = fit_declared(cm.c)
                log.append(rec)
        else:
            # run 1 on a worker, waited for in a thread of this process (executor.map blocks),
            # so that runs 2 and 3 go here while it is still going
            cost = None             # run 1's cost arrives with its answer (collect_declared)
            if dm.joints:
                pending = pool.submit(remote.executor.map, prepare_run, [remote.task("declared")])
        # ---- 2. member stiffness from the element deck -------------------------------------------
        # six right-hand sides however many members: one solver run, never cut into chunks (each
        # chunk would repeat the reading and assembly of the whole deck)
        eadapter = adapter_for(epath)
        K_e, e_asym = element_stiffness(eadapter, emembers, log, deck=epath.name, tips=etips)
        if cost is None:
            cost = SolverCost(eadapter.name)

        def collect_declared() -> None:
            """Run 1's answer in (remote): the fit, its record first in the log as serially."""
            nonlocal pending, K_deck, ident, cost
            if pending is None:
                return
            c, cost = pending.result()[0]
            pending = None
            K_deck, ident, rec = fit_declared(c)
            log.insert(0, rec)

        if _split_needs_declared_fit(deck, dm, fams, max_joint_candidates, max_member_candidates):
            collect_declared()

        # ---- 3. the split deck -----------------------------------------------------------------
        def context() -> CandidateContext:
            return CandidateContext(held["deck"], tuple(dm.joints), K_e, fit_obs, tuple(study.loads.cases),
                                    _residual_rms(fit_obs, ident.residuals) if ident is not None else None,
                                    max_joint_candidates, read_load_groups(study.root / "loads.csv"),
                                    case_scales=(case_scales(fit_obs.case_index, fit_obs.values, fit_obs.sigma,
                                                             ident.predicted, fit_obs.case_labels)
                                                 if ident is not None else None),
                                    max_member_candidates=max_member_candidates, measured=obs,
                                    loads=study.loads, sequential=study.config.measurements.sequential,
                                    preload=held["preload"], include=frozenset(include_grids))
        # without the fit yet, the cuts and the rows do not read the residuals (checked above)
        def split_run():
            sctx = context()
            sd = split_deck(held["deck"], K_e, fams, sctx)
            spath = deck_dir / "split.bdf"
            text = write_deck(sd.deck, "large")
            spath.write_text(text)
            boundary = dm.boundary
            o_dofs = list(dict.fromkeys(list(study.measurements.all_dofs)))
            # rows the families' candidates need (the considered members' ends), in the deck's order
            extra_rows = [d for fam in fams for d in fam.split_rows(sctx, sd)]
            for lim in sctx.limits.values():
                say(f"  {lim.sentence()}")
            say(f"split deck: {len(sd.pairs)} cut DOF pairs, {len(sd.connections)} connection candidates")
            sadapter = adapter_for(spath)
            if remote is not None:
                # an external solver's split runs (this one and the loop's later columns) cut into
                # column chunks, one solver process per worker (blackbox.parallel.use_executor)
                sadapter = use_executor(sadapter, remote.executor)
            # unit loads the families' candidates need beyond those (the loaded grids' components)
            extra_units = [d for fam in fams for d in fam.split_columns(sctx, sd)]
            base = SplitBase(sadapter, study.loads, sd.pairs, list(dict.fromkeys(boundary + o_dofs + extra_units)),
                             list(dict.fromkeys(boundary + o_dofs + extra_rows)), log, deck=spath.name)
            return sctx, sd, base, (spath.name, text)

        try:
            sctx, sd, base, split_text = split_run()
        except UnstableStructureError:
            # run 1 still on a worker: whether it needed reference springs is known only now
            if pending is None:
                raise
            collect_declared()
            if held["deck"] is deck:
                raise
            sctx, sd, base, split_text = split_run()
        decks.append(split_text)
        collect_declared()
        if preload is not None:
            held["preload"] = axial_forces(base, sd.member_dofs, K_e, held["deck"], preload, dm.boundary, K_deck,
                                           dm.joints, ident.k if ident is not None else np.zeros(0), log)

    # ---- candidates (with the declared fit's residuals, as serially) ----------------------------
    ctx = context()
    cands = list(sd.connections)
    hold_cands = []
    for fam in fams:
        cands += fam.candidates(ctx, sd)
        if hold_obs is not None and len(hold_obs):
            hold_cands += fam.holdout_candidates(ctx, sd)
    limits = {**sctx.limits, **ctx.limits}
    return Prepared(study, dm, fit_obs, hold_obs, tuple(dm.holdout), bool(declared_holdout), K_deck, ident,
                    K_e, e_asym, sd, base, tuple(cands), tuple(decks), log, cost, eadapter,
                    tuple(limits.values()), held.get("condensed"), tuple(hold_cands), ctx)


# --------------------------------------------------------------------------------------------
# the command
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class DiagnosisResult:
    """Everything one diagnosis produced: the loop's :class:`Diagnosis`, what it was prepared
    from, the edited decks' text, the solver cost and the whole command's wall time."""
    study: Study
    diagnosis: Diagnosis
    prepared: Prepared
    decks: tuple[tuple[str, str], ...]
    solver: SolverCost
    wall_s: float
    plots: bool = True
    command: str = "diagnose"

    def solver_json(self) -> dict:
        """``diagnosis.json``'s ``solver``: the cost record, every run, the split run's checks."""
        pr = self.prepared
        return {**self.solver.to_json(), "by_run": [r.to_json() for r in self.diagnosis.runs],
                "element_flexibility_asymmetry": pr.element_asymmetry, "split_pairs": len(pr.split.pairs),
                "split_condition": pr.base.condition, "split_symmetry_error": pr.base.symmetry_error}

    @functools.cached_property
    def document(self) -> dict:
        """``diagnosis.json`` (:mod:`blackbox.diagnosis.document`)."""
        pr = self.prepared
        doc = diagnosis_document(self.study.name, self.diagnosis, self.solver_json(), list(pr.holdout),
                                 pr.declared_holdout, pr.ident, limits=pr.limits)
        doc["wall_s"] = self.wall_s
        doc["notes"] = unmodelled_notes(pr.deck)     # what a deck with shells/solids leaves aside
        return doc

    def to_json(self) -> dict:
        return self.document

    def write(self, out: Path) -> list[str]:
        from blackbox.reports.diagnose import diagnosis_plots, diagnosis_report
        from blackbox.reports.response import amplitude_before_after, before_after_plots

        out = Path(out)
        (out / "diagnosis.json").write_text(json.dumps(self.document, indent=2))
        files = ["diagnosis.json"]
        d, fo = self.diagnosis, self.prepared.fit_obs
        same_rows = len(d.declared.residuals) == len(fo) == len(d.final.residuals)
        if self.plots:
            files += diagnosis_plots(self.diagnosis, self.prepared.deck, out)
            if same_rows:       # the fitted rows measured and predicted, before and after
                files += before_after_plots(self.study.loads, fo, d.declared.predicted, d.final.predicted, out)
        text = diagnosis_report(self.study, self.document, files)
        if same_rows:
            text += amplitude_before_after(fo.values, fo.sigma, d.declared.residuals, d.final.residuals)
        (out / "report.md").write_text(text)
        files.append("report.md")
        (out / "decks").mkdir()
        for name, text in self.decks:
            (out / "decks" / name).write_text(text)
            files.append(f"decks/{name}")
        return files


def exchanged(diag: Diagnosis, pr: Prepared, search: Callable[[Prepared], Diagnosis],
              effects: Sequence[str] | None, say: Callable[[str], None]) -> tuple[Diagnosis, Prepared]:
    """The diagnosis again with two exchanged cases' sigmas exchanged too, when it added a
    ``case_swap`` whose fit reads better so and that search is the better one
    (:mod:`blackbox.diagnosis.exchange`); else ``diag`` and ``pr`` as they are. The candidates
    are listed again from the same context with the exchanged sigmas; the split run's columns
    are reused (no solver run but the loop's own)."""
    pair = swapped_pair(diag, added=True)
    if pair is None or pr.context is None:
        return diag, pr
    obs2 = with_sigmas_exchanged(pr.fit_obs, *pair)
    if obs2 is None or not exchange_pays(diag, pr.fit_obs, obs2):
        return diag, pr
    say(f"the readings of cases {pair[0]} and {pair[1]} are exchanged and fit better with their sigmas "
        "exchanged too: searching again on that reading of the data")
    ctx = dataclasses.replace(pr.context, fit_obs=obs2, limits={})
    cands = list(pr.split.connections)
    for fam in families(effects):
        cands += fam.candidates(ctx, pr.split)
    pr2 = dataclasses.replace(pr, fit_obs=obs2, candidates=tuple(cands), context=ctx)
    again = search(pr2)
    if not better(diag, again, pair):
        say(f"  kept the first search (BIC {diag.final.bic:.6g}; with the sigmas exchanged {again.final.bic:.6g})")
        return dataclasses.replace(diag, other_search=brief(again, pair, True, False)), pr
    say(f"  kept the search with the sigmas exchanged (BIC {diag.final.bic:.6g} -> {again.final.bic:.6g})")
    return dataclasses.replace(again, sigmas_exchanged=pair, other_search=brief(diag, pair, False, True)), pr2


def capped_member_ends(diag: Diagnosis, pr: Prepared) -> list[int]:
    """The end grids of the member factors in ``diag``'s final model that could be joints (an
    undeclared joint or rigid end zones there) but that the joint cap left out of those
    candidates. A member factor and the joint at its end are explanations the data may hardly
    tell apart; with the joint never offered, the member would win by default."""
    capped = {lim.kind for lim in pr.limits} & {"undeclared_joint", "rigid_end_zone"}
    if not capped:
        return []
    offered = {int(w) for e in pr.candidates if e.kind in capped for w in e.where_json()
               if not isinstance(w, str)}
    deck = pr.deck
    eligible = set(joint_candidate_grids(deck, {g for j in pr.joints for g in j.grids}))
    out = []
    for e in diag.final.spec.effects:
        if e.kind != "member_stiffness":
            continue
        for eid in e.where_json():
            for g in member_ends(deck, int(eid)):
                if g in eligible and g not in offered and g not in out:
                    out.append(int(g))
    return out


def joint_at(diag: Diagnosis, grids: Sequence[int]) -> list[int]:
    """The grids of ``grids`` where ``diag``'s final model has an undeclared joint or rigid end
    zones."""
    found = {int(w) for e in diag.final.spec.effects if e.kind in ("undeclared_joint", "rigid_end_zone")
             for w in e.where_json() if not isinstance(w, str)}
    return [g for g in grids if g in found]


def load_magnitudes(loads) -> tuple[float, float]:
    """The study's typical force and moment: the median magnitude of its nonzero force and moment
    entries (1 for a kind it has none of) -- the size of the load cases a report proposes."""
    F = loads.values.tocsr()
    comps = np.array([c for _, c in loads.dofs], dtype=int)
    out = []
    for kind in (comps <= 3, comps >= 4):
        vals = np.abs(F[np.flatnonzero(kind)].data) if kind.any() else np.zeros(0)
        vals = vals[vals > 0]
        out.append(float(np.median(vals)) if vals.size else 1.0)
    return out[0], out[1]


def _nesting_cards(pr: Prepared, rows) -> str:
    """What a nesting failure involves: the study deck's cards at the grids where the split
    deck differs most, and where the split deck was cut (the edits that can make it another
    structure)."""
    grids = list(dict.fromkeys(g for g, *_ in rows))[:3]
    parts = [f"cards at grid {g}: {', '.join(cards_at(pr.deck, g)) or 'none'}" for g in grids]
    cuts: dict[str, list] = {}
    for e in pr.split.connections:
        cuts.setdefault(e.kind, []).extend(e.where_json())
    if cuts:
        parts.append("the split deck cuts " + "; ".join(
            f"{k} at {', '.join(map(str, v[:12]))}{' ...' if len(v) > 12 else ''}" for k, v in cuts.items()))
    return ("; ".join(parts) + ". A diagnosis on this split deck would describe another structure, so "
            "none is made; the deck editing does not handle something in this deck: please report it "
            "with the deck")


def check_options(alpha: float, max_steps: int, refit_top: int, max_joint_candidates: int,
                  effects: Sequence[str] | None, max_member_candidates: int | None = None) -> None:
    """The options' errors, before any work."""
    if not 0.0 < alpha < 1.0:
        raise DiagnosisError(f"alpha must be in (0, 1), got {alpha!r}")
    if max_steps < 0 or refit_top < 1:
        raise DiagnosisError(f"max_steps must be >= 0 and refit_top >= 1, got {max_steps!r}, {refit_top!r}")
    if max_joint_candidates < 0 or (max_member_candidates is not None and max_member_candidates < 0):
        raise DiagnosisError(f"max_joint_candidates and max_member_candidates must be >= 0, got "
                             f"{max_joint_candidates!r}, {max_member_candidates!r}")
    families(effects)                          # unknown effect kinds: DiagnosisError


def prepare(study: Study | str | Path, deck_dir: Path, *, adapter: str | None = None,
            max_joint_candidates: int = MAX_JOINT_CANDIDATES, max_member_candidates: int | None = None,
            effects: Sequence[str] | None = None, say: Callable[[str], None] | None = None,
            executor: Executor | None = None, include_grids: Sequence[int] = ()) -> Prepared:
    """:func:`prepare_study` with the study's adapter (or the one named) on each deck; the edited
    decks are written into ``deck_dir``, which must exist while the result's split run is used
    (member refits run it again). ``executor`` with more than one worker: run 1 on it and
    run 3 in column chunks over it (module docstring); otherwise everything here, one run after
    the other."""
    study = as_study(study, need_measurements=True)
    remote = Remote.of(study, executor, adapter) if executor is not None and executor.workers > 1 else None
    return prepare_study(study, lambda path: make_adapter_for(study, adapter, deck=path), deck_dir,
                         max_joint_candidates=max_joint_candidates, max_member_candidates=max_member_candidates,
                         effects=effects, say=say, remote=remote, include_grids=include_grids)


def run(study: Study | str | Path, *, adapter: str | None = None, alpha: float = 0.01, max_steps: int = 5,
        refit_top: int = 6, max_joint_candidates: int = MAX_JOINT_CANDIDATES,
        max_member_candidates: int | None = None, effects: Sequence[str] | None = None,
        plots: bool = True, progress: Callable[[str], None] | None = None,
        executor: Executor | None = None) -> DiagnosisResult:
    """Diagnose the study (module docstring). ``alpha``: the family-wise significance level of
    the whole search (alpha spending over rounds, Bonferroni within a round over the candidates
    and their variant upgrades; :mod:`blackbox.diagnosis.search`); ``max_steps``: effects added
    at most; ``refit_top``: candidates refitted per round; ``max_joint_candidates``,
    ``max_member_candidates``: undeclared-joint grids and members considered at most (those
    nearest the residual beyond; the document's ``settings.candidates_limited`` and a warning
    say how many were left out); ``effects``:
    the families to consider (default: every registered one); ``plots``: whether
    :meth:`DiagnosisResult.write` draws the plots; ``progress(message)``; ``executor``: where
    the declared condensation, the split runs' column chunks and, when that pays, the loop's
    refits go (default: serially here; module docstring)."""
    t0 = time.perf_counter()
    check_options(alpha, max_steps, refit_top, max_joint_candidates, effects, max_member_candidates)
    say = progress or (lambda msg: None)
    study = as_study(study, need_measurements=True)

    def progress_step(step):
        a = step.added
        say(f"  added {a.effect.label()[:70]}: reduced chi2 {step.before.reduced_chi2:.4g} -> "
            f"{step.after.reduced_chi2:.4g}, delta BIC {a.delta_bic:.4g}")
        for e, _ in step.removed:
            say(f"  removed {e.label()[:70]}: the addition made it unnecessary")

    # a marked temporary folder: one a killed diagnose left behind is removed by the next one
    with owned_tempdir(TEMP_PREFIX) as tmp:
        pr = prepare(study, Path(tmp), adapter=adapter, max_joint_candidates=max_joint_candidates,
                     max_member_candidates=max_member_candidates, effects=effects, say=say, executor=executor)
        xyz = {int(g): tuple(v) for g, v in pr.base.adapter.grid_xyz().items()}
        ident = pr.ident

        def search(pr: Prepared) -> Diagnosis:
            try:
                return diagnose(pr.base, pr.boundary, pr.K_deck, pr.joints,
                                ident.k if ident is not None else np.zeros(0), pr.fit_obs, pr.hold_obs,
                                pr.candidates, alpha=alpha, refit_top=refit_top, max_steps=max_steps,
                                declared_prediction=ident.predicted if ident is not None else None,
                                xyz=xyz, progress=progress_step, executor=executor,
                                load_magnitudes=load_magnitudes(study.loads), holdout_loads=pr.holdout_candidates,
                                declared_predict=(functools.partial(predict_rows, pr.declared_condensed, pr.fit_obs)
                                                  if pr.declared_condensed is not None else None))
            except EditedDeckError as exc:
                raise EditedDeckError(f"{exc}. {_nesting_cards(pr, exc.rows)}", exc.rows) from None

        diag = search(pr)
        diag, pr = exchanged(diag, pr, search, effects, say)
        earlier = None                  # the cost of a search that was not kept
        ends = capped_member_ends(diag, pr)
        if ends:
            say(f"the member factor(s) kept end at grid(s) {', '.join(map(str, ends))}, which the joint cap "
                "left out of the undeclared-joint and rigid-end-zone candidates: searching again with them")
            tmp2 = Path(tmp) / "member_ends"
            tmp2.mkdir()
            pr2 = prepare(study, tmp2, adapter=adapter, max_joint_candidates=max_joint_candidates,
                          max_member_candidates=max_member_candidates, effects=effects, say=say,
                          executor=executor, include_grids=ends)
            again = search(pr2)
            again, pr2 = exchanged(again, pr2, search, effects, say)
            where = ", ".join(map(str, ends))
            found = joint_at(again, ends)
            if found:
                say(f"  kept the second search: it finds a joint at {', '.join(map(str, found))}")
                note = (f"the first search kept a member factor ending at grid(s) {where}, which the joint cap "
                        f"had left out of the joint candidates; searched again with them, it finds a joint "
                        f"there (the first search's result: {', '.join(e.label() for e in diag.final.spec.effects)})")
                diag, pr, other = again, pr2, pr
            else:
                say("  kept the first search: the second finds no joint at those grids")
                note = (f"the member factor(s) kept end at grid(s) {where}, which the joint cap had left out of "
                        "the joint candidates; searched again with them, no joint is found there")
                other = pr2
            diag = dataclasses.replace(diag, warnings=diag.warnings + (note,))
            earlier = other.solver_cost()
        say(f"verdict: {diag.verdict}: {verdict_detail(diag)}")
        cost = pr.solver_cost() if earlier is None else pr.solver_cost() + earlier
    return DiagnosisResult(study, diag, pr, pr.decks, cost, time.perf_counter() - t0, plots)
