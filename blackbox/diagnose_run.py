"""``blackbox diagnose``: the wiring around :mod:`blackbox.diagnose` (decks, adapters, outputs).

Three decks go through the study's adapter, each in one batched run (the solver stays a black box):

1. the study's deck: the declared model's condensation and identification (``identify``);
2. ``decks/elements.bdf``: every member alone, clamped at end a -> each member's ``K_e``;
3. ``decks/split.bdf``: the study's deck with every connection a candidate could make flexible
   cut and bridged by springs ``K0`` (:func:`split_deck`): each support component grounded by a
   CELAS2 instead of its SPC, each declared joint's RBE2 translation tie replaced by CELAS2s, and
   each grid where >= 2 members meet (not a joint, not constrained, not in an RBE2 or spring)
   split into one grid per member, tied by an RBE2 CM=123 as the study's joints are, rotations
   bridged by CELAS2s. ``K0`` = the smaller of the two members' diagonal stiffness at that DOF
   (supports: the sum over the members at the grid), so the cut is as stiff as the structure
   there and the rigid state is recovered well conditioned.

Member refits add a run of the split deck per round with unit loads at the short-listed members'
ends. Outputs: ``diagnosis.json`` (CONTRACT.md section 3), ``report.md``, ``residual_map_before.png``,
``residual_map_after.png``, ``candidates.png``, ``steps.png`` and the edited decks in ``decks/``.
"""

from __future__ import annotations

import copy
import json
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from blackbox import diagnose as dg
from blackbox.report import pyplot
from blackbox.identification import Observations, identify
from blackbox.study import Study, joint_branches, load_study
from blackbox.workflows import condensed_for_study, deck_matrix, make_adapter_for, study_joints
from solver_adapters.bdf_write import write_deck
from solver_adapters.deck import CBar, Deck, Grid, Rbe2, Spc1, Spring
from solver_adapters.protocol import DofLabel


# --------------------------------------------------------------------------------------------
# deck queries and edits
# --------------------------------------------------------------------------------------------
def members_at(deck: Deck) -> dict[int, list[int]]:
    """Grid -> EIDs of the CBARs ending there (ascending)."""
    out: dict[int, list[int]] = {}
    for b in sorted(deck.cbars.values(), key=lambda b: b.eid):
        out.setdefault(b.ga, []).append(b.eid)
        out.setdefault(b.gb, []).append(b.eid)
    return out


def constrained_grids(deck: Deck) -> dict[int, str]:
    """Grid -> its constrained components (every SPC1 set and GRID PS)."""
    out: dict[int, set] = {}
    for s in deck.spc1s:
        for g in s.grids:
            out.setdefault(g, set()).update(s.components)
    for g in deck.grids.values():
        if g.ps:
            out.setdefault(g.id, set()).update(g.ps)
    return {g: "".join(sorted(c)) for g, c in out.items()}


def element_deck(deck: Deck) -> tuple[Deck, dict[int, tuple[int, int]]]:
    """Every CBAR alone (same EID, PID, orientation; G0 turned into a vector), end a clamped."""
    e = Deck(pbars=dict(deck.pbars), mat1s=dict(deck.mat1s))
    members = {}
    for i, eid in enumerate(sorted(deck.cbars)):
        b = deck.cbars[eid]
        ga, gb = 2 * i + 1, 2 * i + 2
        e.grids[ga] = Grid(ga, deck.grids[b.ga].xyz)
        e.grids[gb] = Grid(gb, deck.grids[b.gb].xyz)
        x = b.x if b.g0 is None else tuple(np.subtract(deck.grids[b.g0].xyz, deck.grids[b.ga].xyz).tolist())
        e.cbars[eid] = CBar(eid, b.pid, ga, gb, x=tuple(float(v) for v in x))
        members[eid] = (ga, gb)
    e.spc1s = [Spc1(1, "123456", tuple(ga for ga, _ in members.values()))]
    return e, members


def _kdiag(K_e: dict, deck: Deck, eid: int, grid: int, comp: int) -> float:
    b = deck.cbars[eid]
    end = 0 if b.ga == grid else 1
    return float(K_e[eid][6 * end + comp - 1, 6 * end + comp - 1])


def _complete_graph_basis(n: int, k_ref: np.ndarray) -> np.ndarray:
    """Compliance per unit parameter of equal springs between every pair of ``n`` branches, per
    axis, in coordinates 'branch i relative to branch 1' (i = 2..n), pairs ordered axis-major:
    ``D_p = (I + 1 1^T) / (n k_ref_p)`` (the inverse of the reduced Laplacian ``n I - 1 1^T``)."""
    m = n - 1
    block = (np.eye(m) + np.ones((m, m))) / n
    out = np.zeros((3, 3 * m, 3 * m))
    for p in range(3):
        out[p, p * m:(p + 1) * m, p * m:(p + 1) * m] = block / k_ref[p]
    return out


@dataclass
class SplitDeck:
    deck: Deck
    pairs: list[dg.Pair]
    connections: list[dg.Effect]
    member_dofs: dict[int, tuple[DofLabel, ...]]
    split_grids: dict[int, tuple[int, ...]]         # original grid -> branch grids (branch 1 first)


def split_deck(deck: Deck, study: Study, K_e: dict, joint_grids: list[int]) -> SplitDeck:
    """The edited deck of the module docstring and the candidate connections it makes possible."""
    d = copy.deepcopy(deck)
    next_grid = max(d.grids) + 1
    next_eid = max(list(d.cbars) + list(d.rbe2s) + list(d.springs) + [0]) + 1
    at = members_at(deck)
    pairs: list[dg.Pair] = []
    effects: list[dg.Effect] = []
    split: dict[int, tuple[int, ...]] = {}

    def spring(k0, g1, c1, g2=0, c2=0):
        nonlocal next_eid
        d.springs[next_eid] = Spring(next_eid, g1, c1, g2, c2, k=float(k0), card="CELAS2")
        next_eid += 1

    # undeclared joints: one grid per member, translations tied (RBE2 CM=123), rotations on K0
    for g in joint_grids:
        eids = at[g]
        branches = [g]
        for eid in eids[1:]:
            ng = next_grid
            next_grid += 1
            d.grids[ng] = Grid(ng, d.grids[g].xyz)
            b = d.cbars[eid]
            d.cbars[eid] = replace(b, ga=ng if b.ga == g else b.ga, gb=ng if b.gb == g else b.gb)
            branches.append(ng)
        d.rbe2s[next_eid] = Rbe2(next_eid, g, "123", tuple(branches[1:]))
        next_eid += 1
        split[g] = tuple(branches)
        idx, k_ref = [], []
        for c in (4, 5, 6):
            ks = []
            for i in range(1, len(eids)):
                k0 = min(_kdiag(K_e, deck, eids[i], g, c), _kdiag(K_e, deck, eids[0], g, c))
                spring(k0, branches[i], c, g, c)
                idx.append(len(pairs))
                pairs.append(dg.Pair((branches[i], c), (g, c), k0))
                ks.append(k0)
            k_ref.append(float(np.mean(ks)))
        k_ref = np.array(k_ref)
        effects.append(dg.Effect("undeclared_joint", (g,), (f"kx_{g}", f"ky_{g}", f"kz_{g}"),
                                 pairs=tuple(idx), basis=_complete_graph_basis(len(eids), k_ref), k_ref=k_ref))

    # declared joints: the RBE2 translation tie replaced by springs
    for jc in study.config.joints:
        g1, others = jc.grids[0], set(jc.grids[1:])
        ties = [r for r in d.rbe2s.values() if r.gn == g1 and others & set(r.gm)]
        if not ties or any(sorted(r.cm) != ["1", "2", "3"] for r in ties):
            continue
        for r in ties:
            gm = tuple(x for x in r.gm if x not in others)
            if gm:
                d.rbe2s[r.eid] = replace(r, gm=gm)
            else:
                del d.rbe2s[r.eid]
        br = {b.grid: b.eid for b in joint_branches(deck, jc.grids)}
        idx, k_ref = [], []
        for c in (1, 2, 3):
            ks = []
            for gi in jc.grids[1:]:
                k0 = min(_kdiag(K_e, deck, br[gi], gi, c), _kdiag(K_e, deck, br[g1], g1, c))
                spring(k0, gi, c, g1, c)
                idx.append(len(pairs))
                pairs.append(dg.Pair((gi, c), (g1, c), k0))
                ks.append(k0)
            k_ref.append(float(np.mean(ks)))
        k_ref = np.array(k_ref)
        effects.append(dg.Effect("joint_translation", (jc.name,),
                                 (f"ktx_{jc.name}", f"kty_{jc.name}", f"ktz_{jc.name}"), pairs=tuple(idx),
                                 basis=_complete_graph_basis(len(jc.grids), k_ref), k_ref=k_ref))

    # supports: SPC components replaced by grounded springs
    in_rbe2 = {g for r in deck.rbe2s.values() for g in (r.gn, *r.gm)}
    for g, comps in sorted(constrained_grids(deck).items()):
        if g in in_rbe2 or g not in at:
            continue
        new_spc = []
        for s in d.spc1s:
            if g in s.grids:
                rest = tuple(x for x in s.grids if x != g)
                if rest:
                    new_spc.append(replace(s, grids=rest))
                left = "".join(c for c in s.components if c not in comps)
                if left:
                    new_spc.append(Spc1(s.sid, left, (g,)))
            else:
                new_spc.append(s)
        d.spc1s = new_spc
        if d.grids[g].ps:
            d.grids[g] = replace(d.grids[g], ps="")
        idx, ks = [], []
        for c in comps:
            k0 = sum(_kdiag(K_e, deck, eid, g, int(c)) for eid in at[g])
            spring(k0, g, int(c))
            idx.append(len(pairs))
            pairs.append(dg.Pair((g, int(c)), None, k0))
            ks.append(k0)
        k_ref = np.array(ks)
        basis = np.zeros((len(ks), len(ks), len(ks)))
        for q in range(len(ks)):
            basis[q, q, q] = 1.0 / k_ref[q]
        effects.append(dg.Effect("support_flexibility", (g,), tuple(f"ks_{g}_{c}" for c in comps),
                                 pairs=tuple(idx), basis=basis, k_ref=k_ref))
    member_dofs = {eid: tuple((b.ga, c) for c in range(1, 7)) + tuple((b.gb, c) for c in range(1, 7))
                   for eid, b in d.cbars.items()}
    return SplitDeck(d, pairs, effects, member_dofs, split)


def undeclared_joint_grids(deck: Deck, study: Study) -> list[int]:
    """Grids where >= 2 members meet that could be an undeclared flexible joint: not a declared
    joint's grid, not constrained, not in an RBE2, no scalar spring."""
    at = members_at(deck)
    joint = {g for j in study.config.joints for g in j.grids}
    fixed = set(constrained_grids(deck))
    in_rbe2 = {g for r in deck.rbe2s.values() for g in (r.gn, *r.gm)}
    sprung = {g for s in deck.springs.values() for g in (s.g1, s.g2) if g}
    return [g for g in sorted(at) if len(at[g]) >= 2 and g not in joint | fixed | in_rbe2 | sprung]


def _preselect(grids: list[int], limit: int, deck: Deck, residual_rms: dict[int, float]) -> list[int]:
    """At most ``limit`` candidate grids: those nearest the residual concentration (each grid's
    score is the largest measured-grid RMS discounted by exp(-distance / median member length))."""
    if len(grids) <= limit:
        return grids
    xyz = {g.id: np.array(g.xyz) for g in deck.grids.values()}
    lengths = [np.linalg.norm(xyz[b.ga] - xyz[b.gb]) for b in deck.cbars.values()]
    ell = float(np.median(lengths)) or 1.0
    meas = [(xyz[g], v) for g, v in residual_rms.items() if g in xyz]

    def score(g):
        return max((v * math.exp(-np.linalg.norm(xyz[g] - p) / ell) for p, v in meas), default=0.0)
    return sorted(sorted(grids, key=score, reverse=True)[:limit])


# --------------------------------------------------------------------------------------------
# the command
# --------------------------------------------------------------------------------------------
@dataclass
class Prepared:
    """Everything the loop needs, after the runs on the study's, the element and the split deck."""
    study: Study
    deck: Deck
    log: list
    fit_obs: Observations
    hold_obs: Observations | None
    holdout: list[str]
    declared_holdout: bool
    joints: list
    boundary: list[DofLabel]
    K_deck: np.ndarray | None
    ident: object
    K_e: dict
    element_asymmetry: float
    split: SplitDeck
    base: dg.SplitBase
    candidates: list[dg.Effect]
    adapter_name: str


@dataclass
class DiagnoseRun:
    study: Study
    diagnosis: dg.Diagnosis
    document: dict
    deck: Deck
    files: list[str]
    prepared: Prepared


def prepare(study_dir: Path, out_dir: Path, *, adapter_name: str | None = None,
            max_joint_candidates: int = 300, effects: tuple[str, ...] = dg.EFFECTS, say=None) -> Prepared:
    """Read the study, fit the declared model, run the element and the split deck, list candidates."""
    say = say or (lambda msg: None)
    unknown = sorted(set(effects) - set(dg.EFFECTS))
    if unknown:
        raise ValueError(f"unknown effect kind(s) {unknown}; known: {', '.join(dg.EFFECTS)}")
    study = load_study(study_dir, need_measurements=True)
    deck = study.deck
    out_dir = Path(out_dir)
    (out_dir / "decks").mkdir(parents=True, exist_ok=True)
    log: list[dg.RunRecord] = []

    # ---- observations, hold-out ----------------------------------------------------------------
    meas = study.measurements
    obs = Observations.from_measurements(meas, study.loads.cases)
    measured_cases = [obs.case_labels[c] for c in dict.fromkeys(obs.case_index.tolist())]
    declared_holdout = list(study.config.identification.holdout_cases)
    holdout = declared_holdout or dg.default_holdout(measured_cases)
    fit_obs, hold_obs = obs.split(holdout) if holdout else (obs, None)

    # ---- 1. the declared model on the study's deck ---------------------------------------------
    joints = study_joints(study)
    boundary = [d for j in joints for d in j.dofs]
    K_deck = deck_matrix(study, joints)
    adapter = make_adapter_for(study, adapter_name)
    ident = None
    if joints:
        t1 = time.perf_counter()
        cm = condensed_for_study(study, adapter, joints, meas.all_dofs)
        log.append(dg.RunRecord("declared model: condensation", study.deck_path.name,
                                cm.c.right_hand_sides, time.perf_counter() - t1))
        cfg = study.config.identification
        k0 = np.concatenate([j.initial_params(jc.initial) for j, jc in zip(joints, study.config.joints)])
        ident = identify(cm, fit_obs, k0, holdout=hold_obs, profile=False, fixed_point=cfg.fixed_point,
                         max_iterations=cfg.max_iterations)
        say(f"declared model: reduced chi2 = {ident.reduced_chi2:.4g} ({ident.n_obs} rows, "
            f"{ident.n_params} parameters)")

    # ---- 2. member stiffness from the element deck ---------------------------------------------
    edeck, emembers = element_deck(deck)
    epath = out_dir / "decks" / "elements.bdf"
    epath.write_text(write_deck(edeck, "large"))
    K_e, e_asym = dg.element_stiffness(make_adapter_for(study, adapter_name, deck=epath), emembers, log,
                                       deck=epath.name)

    # ---- 3. the split deck ---------------------------------------------------------------------
    grids = undeclared_joint_grids(deck, study) if "undeclared_joint" in effects else []
    if len(grids) > max_joint_candidates and ident is not None:
        rms: dict[int, float] = {}
        for (g, _), z in zip(fit_obs.dofs, ident.residuals):
            rms[g] = rms.get(g, 0.0) + z * z
        grids = _preselect(grids, max_joint_candidates, deck, {g: math.sqrt(v) for g, v in rms.items()})
    sd = split_deck(deck, study, K_e, grids)
    spath = out_dir / "decks" / "split.bdf"
    spath.write_text(write_deck(sd.deck, "large"))
    sadapter = make_adapter_for(study, adapter_name, deck=spath)
    o_dofs = list(dict.fromkeys(list(meas.all_dofs)))
    member_ends = [d for dofs in sd.member_dofs.values() for d in dofs]
    say(f"split deck: {len(sd.pairs)} cut DOF pairs, {len(sd.connections)} connection candidates")
    base = dg.SplitBase(sadapter, study.loads, sd.pairs, list(dict.fromkeys(boundary + o_dofs)),
                        list(dict.fromkeys(boundary + o_dofs + member_ends)), log, deck=spath.name)

    # ---- candidates ----------------------------------------------------------------------------
    cands: list[dg.Effect] = [e for e in sd.connections if e.kind in effects]
    if "joint_coupling" in effects:
        cands += [dg.Effect("joint_coupling", (j.name,), joint=j.name) for j in joints
                  if j.model_name == "simple"]
    if "member_stiffness" in effects:
        cands += [dg.Effect("member_stiffness", (eid,), (f"alpha_{eid}",), dofs=sd.member_dofs[eid], K_e=K_e[eid])
                  for eid in sorted(K_e)]
    cases = study.loads.cases
    if "load_scale" in effects:
        fitted = [obs.case_labels[c] for c in fit_obs.cases]
        cands.append(dg.Effect("load_scale", tuple(cases), ("s_all",), cases=tuple(range(len(cases)))))
        if len(fitted) > 1:
            cands += [dg.Effect("load_scale", (c,), (f"s_{c}",), cases=(cases.index(c),)) for c in fitted]
    if "sensor_gain" in effects:
        cands += [dg.Effect("sensor_gain", (g,), (f"g_{g}",), grid=g)
                  for g in dict.fromkeys(d[0] for d in fit_obs.dofs)]
    return Prepared(study, deck, log, fit_obs, hold_obs, holdout, bool(declared_holdout), joints, boundary,
                    K_deck, ident, K_e, e_asym, sd, base, cands, adapter.name)


def run_diagnose(study_dir: Path, out_dir: Path, *, adapter_name: str | None = None, alpha: float = 0.01,
                 max_steps: int = 5, refit_top: int = 6, max_joint_candidates: int = 300,
                 effects: tuple[str, ...] = dg.EFFECTS, plots: bool = True, progress=None) -> DiagnoseRun:
    """``blackbox diagnose STUDY --out DIR`` (see the module docstring)."""
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    if max_steps < 0 or refit_top < 1:
        raise ValueError(f"max_steps must be >= 0 and refit_top >= 1, got {max_steps!r}, {refit_top!r}")
    out_dir = Path(out_dir)
    pr = prepare(study_dir, out_dir, adapter_name=adapter_name, max_joint_candidates=max_joint_candidates,
                 effects=effects, say=say)

    def progress_step(step):
        a = step.added
        say(f"  added {a.effect.label()[:70]}: reduced chi2 {step.before.reduced_chi2:.4g} -> "
            f"{step.after.reduced_chi2:.4g}, delta BIC {a.delta_bic:.4g}")

    xyz = {int(g): tuple(v) for g, v in pr.base.adapter.grid_xyz().items()}
    k_start = pr.ident.k if pr.ident is not None else np.zeros(0)
    diag = dg.diagnose(pr.base, pr.boundary, pr.K_deck, pr.joints, k_start, pr.fit_obs, pr.hold_obs,
                       pr.candidates, alpha=alpha, refit_top=refit_top, max_steps=max_steps,
                       declared_prediction=pr.ident.predicted if pr.ident is not None else None,
                       xyz=xyz, progress=progress_step)
    log = pr.log
    runs = {"runs": len(log), "right_hand_sides": sum(r.right_hand_sides for r in log),
            "solver_wall_s": sum(r.wall_s for r in log), "adapter": pr.adapter_name,
            "by_run": [r.__dict__ for r in log], "element_flexibility_asymmetry": pr.element_asymmetry,
            "split_pairs": len(pr.split.pairs), "split_condition": pr.base.condition,
            "split_symmetry_error": pr.base.symmetry_error}
    doc = diagnosis_document(pr.study, diag, runs, pr.holdout, pr.declared_holdout, pr.ident)
    doc["wall_s"] = time.perf_counter() - t0
    (out_dir / "diagnosis.json").write_text(json.dumps(doc, indent=2))
    files = ["diagnosis.json"]
    if plots:
        files += diagnosis_plots(diag, pr.deck, pr.split, out_dir)
    (out_dir / "report.md").write_text(diagnosis_report(pr.study, doc, files))
    files.append("report.md")
    return DiagnoseRun(pr.study, diag, doc, pr.deck, files, pr)


# --------------------------------------------------------------------------------------------
# diagnosis.json
# --------------------------------------------------------------------------------------------
def _num(v):
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _where(e: dg.Effect) -> list:
    return [w if isinstance(w, str) else int(w) for w in e.where]


def _stats(fit: dg.Fit, band) -> dict:
    lo, hi = dg.chi2_band(fit.n_obs - fit.n_params)
    return {"reduced_chi2": _num(fit.reduced_chi2), "rms_residual": _num(fit.rms_residual),
            "holdout_rms": _num(fit.holdout_rms), "bic": _num(fit.bic), "chi2": _num(fit.chi2),
            "n_obs": fit.n_obs, "n_params": fit.n_params, "holdout_chi2": _num(fit.holdout_chi2),
            "holdout_n_obs": fit.holdout_n, "band_99": [_num(lo), _num(hi)],
            "in_band": bool(lo <= fit.reduced_chi2 <= hi)}


def _candidate(c: dg.CandidateScore) -> dict:
    out = {"effect": c.effect.kind, "where": _where(c.effect), "delta_bic": _num(c.delta_bic),
           "p_value": _num(c.p_value), "log10_p_value": _num(c.log10_p), "score": _num(c.score),
           "df": c.df, "p_value_bonferroni": _num(c.p_adjusted), "delta_bic_method": c.delta_bic_method}
    if c.refit is not None:
        out.update({"refit": True, "lr": _num(c.lr), "lr_p_value": _num(c.lr_p_value),
                    "lr_p_value_bonferroni": _num(c.lr_p_adjusted), "reduced_chi2": _num(c.refit.reduced_chi2),
                    "holdout_delta_chi2": _num(c.holdout_delta_chi2), "decision": c.reason})
    return out


def _joint_params(fit: dg.Fit) -> dict:
    out = {}
    for j, sl in zip(fit.spec.joints, fit.spec.joint_slices()):
        out[j.name] = {"model": j.model_name,
                       "parameters": {n: {"value": _num(v), "std": _num(s)}
                                      for n, v, s in zip(j.param_names, fit.x[sl], fit.std[sl])}}
    return out


def diagnosis_document(study: Study, diag: dg.Diagnosis, runs: dict, holdout: list[str],
                       declared_holdout: bool, ident) -> dict:
    first = diag.steps[0].scores if diag.steps else ()
    added = []
    for s in diag.steps:
        if s.added is None:
            continue
        e = s.added.effect
        added.append({"effect": e.kind, "where": _where(e),
                      "parameters": dg.effect_parameters(s.after, e),
                      "delta_bic": _num(s.added.delta_bic), "lr_p_value": _num(s.added.lr_p_value)})
    steps = []
    for i, s in enumerate(diag.steps):
        steps.append({
            "step": i + 1,
            "before": _stats(s.before, diag.band),
            "after": _stats(s.after, diag.band),
            "added": None if s.added is None else {"effect": s.added.effect.kind, "where": _where(s.added.effect),
                                                   "parameters": dg.effect_parameters(s.after, s.added.effect)},
            "candidates": [_candidate(c) for c in s.scores[:25]],
            "n_candidates": len(s.scores),
            "joint_parameters_before": _joint_params(s.before),
            "joint_parameters_after": _joint_params(s.after),
            "residual_structure_before": _trim(s.structure_before),
            "residual_structure_after": _trim(s.structure_after),
            "solver_runs": s.runs,
        })
    return {
        "study": study.name,
        "before": _stats(diag.declared, diag.band),
        "candidates": [_candidate(c) for c in first],
        "added": added,
        "after": _stats(diag.final, diag.band),
        "steps": steps,
        "stop_reason": diag.stop_reason,
        "joint_parameters": {"declared": _joint_params(diag.declared), "final": _joint_params(diag.final)},
        "holdout": {"cases": list(holdout), "declared_in_study": declared_holdout},
        "settings": {"alpha": diag.alpha, "multiplicity": "Bonferroni over the candidates scored per round",
                     "band": "99% band of chi2(n - p) / (n - p)", "candidates_by_effect": diag.n_candidates},
        "identify_check": None if ident is None else {
            "reduced_chi2": _num(ident.reduced_chi2), "converged": bool(ident.converged),
            "nesting_error_sigma": _num(diag.nesting_error)},
        "solver": runs,
        "warnings": list(diag.warnings),
        "method_wall_s": diag.wall_s,
    }


def _trim(st: dict) -> dict:
    return {"per_case": st["per_case"], "per_component": st["per_component"],
            "worst_grids": st["worst_grids"], "grid_map": st["grid_map"]}


# --------------------------------------------------------------------------------------------
# report.md
# --------------------------------------------------------------------------------------------
def _g(v, digits: int = 4) -> str:
    return "n/a" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{digits}g}"


def diagnosis_report(study: Study, doc: dict, files: list[str]) -> str:
    b, a = doc["before"], doc["after"]
    out = [f"# Diagnosis of {study.name}", "",
           "Declared model fitted, standardized residuals tested against the declared noise, candidate "
           "effects scored against the residual (score test), the best few refitted (likelihood ratio, "
           f"BIC); an effect is added when its LR p-value x the number of candidates scored is below "
           f"{doc['settings']['alpha']:g}, BIC improves and hold-out prediction does not get worse.", "",
           "## Before and after", "",
           "| | reduced chi2 | 99% band | RMS residual | hold-out RMS | BIC | parameters |",
           "|---|---|---|---|---|---|---|"]
    for name, s in (("declared", b), ("final", a)):
        out.append(f"| {name} | {_g(s['reduced_chi2'])} | [{_g(s['band_99'][0])}, {_g(s['band_99'][1])}] | "
                   f"{_g(s['rms_residual'])} | {_g(s['holdout_rms'])} | {_g(s['bic'], 7)} | {s['n_params']} |")
    out += ["", f"Hold-out cases: {', '.join(doc['holdout']['cases']) or 'none'}"
            + ("" if doc["holdout"]["declared_in_study"] else " (chosen here: every 5th measured case)") + ".",
            f"Stopped: {doc['stop_reason']}.", ""]
    out += ["## Effects added", ""]
    if not doc["added"]:
        out.append("None: the residuals are explained by the declared model and noise.")
    for i, e in enumerate(doc["added"], 1):
        out += [f"### {i}. {e['effect']} at {', '.join(map(str, e['where']))}", "",
                f"delta BIC {_g(e['delta_bic'])}, LR p-value {_g(e['lr_p_value'], 3)}", "",
                "| parameter | value | std |", "|---|---|---|"]
        out += [f"| {p['name']} | {_g(p['value'])} | {_g(p['std'], 3)} |" for p in e["parameters"]]
        out.append("")
    out += ["## Steps", "", "| step | added | reduced chi2 before -> after | hold-out RMS before -> after | "
            "BIC before -> after | runs |", "|---|---|---|---|---|---|"]
    for s in doc["steps"]:
        ad = "none" if s["added"] is None else f"{s['added']['effect']} @ {', '.join(map(str, s['added']['where']))}"
        out.append(f"| {s['step']} | {ad} | {_g(s['before']['reduced_chi2'])} -> {_g(s['after']['reduced_chi2'])} | "
                   f"{_g(s['before']['holdout_rms'])} -> {_g(s['after']['holdout_rms'])} | "
                   f"{_g(s['before']['bic'], 7)} -> {_g(s['after']['bic'], 7)} | {s['solver_runs']} |")
    for s in doc["steps"]:
        out += ["", f"### Round {s['step']}: candidates (best 15 of {s['n_candidates']} by score p-value)", "",
                "| effect | where | score | df | log10 p | delta BIC | decision |", "|---|---|---|---|---|---|---|"]
        for c in s["candidates"][:15]:
            out.append(f"| {c['effect']} | {', '.join(map(str, c['where']))[:40]} | {_g(c['score'])} | {c['df']} | "
                       f"{_g(c['log10_p_value'])} | {_g(c['delta_bic'])} ({'refit' if c.get('refit') else 'score'}) | "
                       f"{c.get('decision', '')} |")
        rs = s["residual_structure_before"]
        out += ["", "Where the residual concentrated before this round (chi2/n per group; the noise gives 1):", "",
                "| grid | n | chi2/n | p |", "|---|---|---|---|"]
        out += [f"| {w['grid']} | {w['n']} | {_g(w['chi2_per_n'])} | {_g(w['p_value'], 3)} |"
                for w in rs["worst_grids"][:6]]
        out += ["", "| component | " + " | ".join(rs["per_component"]) + " |",
                "|---|" + "---|" * len(rs["per_component"]),
                "| chi2/n | " + " | ".join(_g(v["chi2_per_n"]) for v in rs["per_component"].values()) + " |"]
        cases = sorted(rs["per_case"].items(), key=lambda kv: -kv[1]["chi2_per_n"])[:6]
        out += ["", "Cases with the largest chi2/n: " + ", ".join(f"{k} {_g(v['chi2_per_n'])}" for k, v in cases)]
    out += ["", "## Joint parameters", "", "| joint | parameter | declared fit | final |", "|---|---|---|---|"]
    dj, fj = doc["joint_parameters"]["declared"], doc["joint_parameters"]["final"]
    for name, jd in dj.items():
        final = fj.get(name, {}).get("parameters", {})
        for pn, pv in jd["parameters"].items():
            out.append(f"| {name} | {pn} | {_g(pv['value'])} | {_g(final.get(pn, {}).get('value'))} |")
        if fj.get(name, {}).get("model") != jd["model"]:
            out.append(f"| {name} | (now {fj[name]['model']} model: see diagnosis.json) | | |")
    sv = doc["solver"]
    out += ["", "## Solver", "", f"{sv['runs']} runs, {sv['right_hand_sides']} right-hand sides, "
            f"{_g(sv['solver_wall_s'], 3)} s in the solver (adapter {sv['adapter']}); whole command "
            f"{_g(doc.get('wall_s'), 3)} s.", "", "| purpose | deck | right-hand sides | wall s |", "|---|---|---|---|"]
    out += [f"| {r['purpose']} | {r['deck']} | {r['right_hand_sides']} | {_g(r['wall_s'], 3)} |" for r in sv["by_run"]]
    ic = doc.get("identify_check")
    if ic:
        out += ["", f"The split deck reproduces the declared model to {_g(ic['nesting_error_sigma'], 2)} sigma "
                f"(rigid state of {sv['split_pairs']} cut pairs, condition {_g(sv['split_condition'], 2)})."]
    if doc["warnings"]:
        out += ["", "## Warnings", ""] + [f"- {w}" for w in doc["warnings"]]
    pics = [f for f in files if f.endswith(".png")]
    if pics:
        out += ["", "## Plots", ""] + [f"![{p[:-4]}]({p})" for p in pics]
    else:
        out += ["", "(no plots: install matplotlib)"]
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------------------------
# plots
# --------------------------------------------------------------------------------------------
def _grid_rms(obs_dofs, r) -> dict[int, float]:
    acc: dict[int, list] = {}
    for d, z in zip(obs_dofs, r):
        acc.setdefault(d[0], []).append(z * z)
    return {g: math.sqrt(float(np.mean(v))) for g, v in acc.items()}


def diagnosis_plots(diag: dg.Diagnosis, deck: Deck, sd: SplitDeck, out_dir: Path) -> list[str]:
    plt = pyplot()
    if plt is None:
        return []
    from matplotlib import colors
    written = []
    xyz = {g.id: np.array(g.xyz) for g in deck.grids.values()}
    segs = [(xyz[b.ga], xyz[b.gb]) for b in deck.cbars.values()]
    steps = diag.steps
    dofs = steps[0].structure_before if steps else None
    rms_before = {int(k): v["rms"] for k, v in (dofs["per_grid"].items() if dofs else [])}
    last = steps[-1].structure_after if steps else None
    rms_after = {int(k): v["rms"] for k, v in (last["per_grid"].items() if last else [])}
    vmax = max([1.0] + list(rms_before.values()) + list(rms_after.values()))
    norm = colors.LogNorm(vmin=0.5, vmax=max(vmax, 2.0))
    marks = [(s.added.effect.kind, s.added.effect.where) for s in steps if s.added is not None]
    for name, rms, title in (("residual_map_before.png", rms_before, "declared model"),
                             ("residual_map_after.png", rms_after, "after the added effects")):
        fig = plt.figure(figsize=(8, 6.5))
        ax = fig.add_subplot(projection="3d")
        for a, b in segs:
            ax.plot(*zip(a, b), color="0.6", lw=0.8)
        gs = [g for g in rms if g in xyz]
        if gs:
            P = np.array([xyz[g] for g in gs])
            sc = ax.scatter(P[:, 0], P[:, 1], P[:, 2], c=[max(rms[g], 0.5) for g in gs], cmap="inferno_r",
                            norm=norm, s=40, depthshade=False, edgecolors="k", linewidths=0.3)
            fig.colorbar(sc, ax=ax, shrink=0.6, label="RMS standardized residual per grid (noise = 1)")
            for g in sorted(gs, key=lambda g: -rms[g])[:5]:
                if rms[g] > 1.5:
                    ax.text(*xyz[g], f" {g}", fontsize=7)
        for kind, where in marks:
            pts = []
            if kind in ("undeclared_joint", "support_flexibility", "sensor_gain"):
                pts = [xyz[int(w)] for w in where if int(w) in xyz]
            elif kind == "member_stiffness":
                b = deck.cbars[int(where[0])]
                pts = [(xyz[b.ga] + xyz[b.gb]) / 2]
            for p in pts:
                ax.scatter(*p, marker="*", s=220, color="tab:blue", depthshade=False)
                ax.text(*p, f"  {kind}", fontsize=7, color="tab:blue")
        span = np.ptp(np.array(list(xyz.values())), axis=0)
        ax.set_box_aspect(np.maximum(span, 0.05 * span.max()))
        ax.set_title(f"Residual map: {title}")
        fig.tight_layout()
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        written.append(name)
    if steps:
        sc = [c for c in steps[0].scores if c.df > 0][:25]
        fig, ax = plt.subplots(figsize=(8, max(3.5, 0.28 * len(sc) + 1.5)))
        kinds = sorted({c.effect.kind for c in sc})
        cmap = plt.get_cmap("tab10")
        y = np.arange(len(sc))[::-1]
        val = [min(-c.log10_p, 300.0) for c in sc]
        ax.barh(y, val, color=[cmap(kinds.index(c.effect.kind)) for c in sc])
        ax.set_yticks(y, [f"{c.effect.kind} @ {', '.join(map(str, c.effect.where))[:24]}" for c in sc], fontsize=7)
        thr = -math.log10(diag.alpha / max(len(steps[0].scores), 1))
        ax.axvline(thr, color="k", ls="--", lw=1, label=f"Bonferroni threshold ({len(steps[0].scores)} candidates)")
        for yi, c in zip(y, sc):
            if c.refit is not None:
                ax.text(min(-c.log10_p, 300.0), yi, f" dBIC {c.delta_bic:.3g}", va="center", fontsize=6)
        ax.set_xscale("symlog", linthresh=10)
        ax.set_xlabel("-log10 p (score test)")
        ax.set_title("Candidate ranking, round 1")
        ax.legend(fontsize=7, loc="lower right")
        fig.tight_layout()
        fig.savefig(out_dir / "candidates.png", dpi=110)
        plt.close(fig)
        written.append("candidates.png")
        fits = [steps[0].before] + [s.after for s in steps if s.added is not None]
        labels = ["declared"] + [s.added.effect.kind for s in steps if s.added is not None]
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.5))
        a1.semilogy(range(len(fits)), [f.reduced_chi2 for f in fits], "o-")
        lo, hi = diag.band
        a1.axhspan(lo, hi, color="0.85", label="99% band")
        a1.set_xticks(range(len(fits)), labels, rotation=20, fontsize=7)
        a1.set_ylabel("reduced chi2")
        a1.legend(fontsize=7)
        if all(f.holdout_rms is not None for f in fits):
            a2.semilogy(range(len(fits)), [f.holdout_rms for f in fits], "o-", color="tab:orange")
        a2.set_xticks(range(len(fits)), labels, rotation=20, fontsize=7)
        a2.set_ylabel("hold-out RMS prediction error")
        fig.tight_layout()
        fig.savefig(out_dir / "steps.png", dpi=110)
        plt.close(fig)
        written.append("steps.png")
    return written
