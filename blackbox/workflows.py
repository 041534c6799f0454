"""Workflows behind the commands: study folder + adapter + method modules.

This is wiring: it may read decks (joint geometry) and choose adapters. The numerical work is in
the method modules (condensation, joints, identification, simulate), which see the solver only
through ``solver_adapters.protocol``.
"""

from __future__ import annotations

import json
import shutil
import tomllib
from contextvars import ContextVar
from typing import TYPE_CHECKING
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from blackbox import simulate as sim
from blackbox.condensation import CondensedModel, condense
from blackbox.errors import StudyError
from blackbox.joints import ComplexJoint, JointModel, SimpleJoint, actual_joint_stub_kc, joint_dofs, make_joint
from blackbox.study import Study, joint_branches, load_study
from solver_adapters.protocol import DofLabel, LoadMatrix, SolverAdapter

if TYPE_CHECKING:
    from blackbox.identification import IdentificationResult, Observations


from blackbox.adapters import ADAPTER_CACHE, make_adapter_for  # noqa: E402,F401


def study_deck(study: Study):
    """The study's parsed deck (read once by :func:`blackbox.study.load_study`)."""
    return study.deck


def study_joints(study: Study, model: str | None = None) -> list[JointModel]:
    """The study's joints as models (``model`` overrides every joint's declared model)."""
    out = []
    for j in study.config.joints:
        opts = {}
        if (model or j.model) == "simple" and j.rigid_pairs:     # grid pairs -> branch numbers
            opts = {"rigid_pairs": tuple((j.grids.index(a) + 1, j.grids.index(b) + 1)
                                         for a, b in j.rigid_pairs)}
        out.append(make_joint(j.name, j.grids, model or j.model, **opts))
    return out


def deck_matrix(study: Study, joints: list[JointModel]) -> np.ndarray | None:
    """``K_deck`` over the joints' DOFs: simple-model springs of ``deck_stiffness`` in the deck."""
    blocks = []
    for jm, jc in zip(joints, study.config.joints):
        s = SimpleJoint(jc.name, tuple(jc.grids))
        blocks.append(s.matrix(np.full(s.n_params, jc.deck_stiffness)))
    if not any(np.any(b) for b in blocks):
        return None
    n = sum(b.shape[0] for b in blocks)
    K = np.zeros((n, n))
    i = 0
    for b in blocks:
        K[i:i + b.shape[0], i:i + b.shape[0]] = b
        i += b.shape[0]
    return K


def stub_params(study: Study, joint: ComplexJoint, length: float) -> np.ndarray:
    """Complex-model parameters of the stub "actual joint" (Section 5.4.1) for this deck."""
    br = joint_branches(study_deck(study), joint.grids)
    b0 = br[0]
    K_C = actual_joint_stub_kc([b.direction for b in br], length, b0.E, b0.G, b0.A, b0.I2, b0.I1,
                               b0.J, [b.orientation for b in br])
    return joint.params_from_kc(K_C)


# --------------------------------------------------------------------------------------------
# simulate
# --------------------------------------------------------------------------------------------
def read_truth(path: Path) -> sim.TruthConfig:
    try:
        return sim.TruthConfig.model_validate(tomllib.loads(Path(path).read_text()))
    except FileNotFoundError:
        raise StudyError("truth file not found", file=str(path)) from None
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"not valid TOML: {exc}", file=str(path)) from None
    except ValidationError as exc:
        msgs = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors())
        raise StudyError(msgs, file=str(path)) from None


def truth_joints(study: Study, truth: sim.TruthConfig, truth_path: Path) -> tuple[list[JointModel], np.ndarray]:
    by_name = {j.name: j for j in study.config.joints}
    models, params = [], []
    for tj in truth.joints:
        if tj.name not in by_name:
            raise StudyError(f"truth joint {tj.name!r} is not a joint of the study "
                             f"({sorted(by_name)})", file=str(truth_path))
        jm = make_joint(tj.name, by_name[tj.name].grids, tj.model)
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


def _measured_dofs(study: Study, m: sim.MeasureConfig) -> list[DofLabel]:
    dofs: list[DofLabel] = []
    if m.joint:
        for j in study.config.joints:
            dofs += joint_dofs(j.grids)
    dofs += [tuple(d) for d in m.away]
    dofs += [(g, c) for g in m.away_grids for c in range(1, 7)]
    return list(dict.fromkeys(dofs))


def simulate_study(study_dir: Path, truth_path: Path, out_dir: Path, adapter_name: str | None = None) -> dict:
    """``blackbox simulate``: a copy of the study with simulated ``measurements.csv``."""
    study = load_study(study_dir)
    truth = read_truth(truth_path)
    m = truth.measure
    cases = list(m.cases) or list(study.loads.cases)
    unknown = [c for c in cases if c not in study.loads.cases]
    if unknown:
        raise StudyError(f"measure.cases {unknown} are not load cases of the study", file=str(truth_path))
    loads = study.loads.select([study.loads.cases.index(c) for c in cases])
    true_loads = LoadMatrix(loads.dofs, loads.values * truth.force_scale, loads.cases)
    dofs = _measured_dofs(study, m)
    if not dofs:
        raise StudyError("nothing to measure: set measure.joint = true or list measure.away",
                         file=str(truth_path))
    deck = study_deck(study)
    grids_known = set(deck.grids)
    bad = [d for d in dofs if d[0] not in grids_known or not 1 <= d[1] <= 6]
    if bad:
        raise StudyError(f"measured DOFs {bad[:5]} are not in the deck", file=str(truth_path))
    branches = {}
    extra: list[DofLabel] = []
    if m.averaging_points:
        for j in study.config.joints:
            for b in joint_branches(deck, j.grids):
                bar = deck.cbars[b.eid]
                other = bar.gb if bar.ga == b.grid else bar.ga
                branches[b.grid] = (b, other)
                extra += [(b.grid, c) for c in range(1, 7)] + [(other, c) for c in range(1, 7)]
    if m.reference_grid is not None:
        extra += [(m.reference_grid, c) for c in range(1, 7)]
    needed = list(dict.fromkeys(dofs + extra))

    adapter = make_adapter_for(study, adapter_name)
    if truth.deck:
        truth_deck = (Path(truth_path).parent / truth.deck).resolve()
        tadapter = make_adapter_for(study, adapter_name, deck=truth_deck)
        U = tadapter.solve(true_loads, needed).values
        k_true, names = np.zeros(0), []
    else:
        joints, k_true = truth_joints(study, truth, truth_path)
        boundary = [d for j in joints for d in j.dofs]
        model = CondensedModel(condense(adapter, true_loads, boundary, needed), joints)
        U = model.pick(model.response(k_true), needed)
        names = [(j.name, n) for j in joints for n in j.param_names]
    row = {d: i for i, d in enumerate(needed)}
    rng = np.random.default_rng(truth.seed)
    if m.reference_grid is not None:     # the reference grid itself is measured absolutely
        dofs = [(m.reference_grid, c) for c in range(1, 7)] + [d for d in dofs if d[0] != m.reference_grid]
    if m.reference_grid is not None and m.averaging_points:
        raise StudyError("measure.averaging_points and measure.reference_grid cannot be combined",
                         file=str(truth_path))
    rows = sim.simulate_rows(U, row, len(cases), dofs, truth.noise, rng, m.reference_grid)
    dof_rows, ci, true, kinds = rows.dofs, rows.case_index, rows.true, rows.kinds
    values, sigma = rows.values.copy(), rows.sigma.copy()
    case_rows = [cases[j] for j in ci]
    refs = [None if r is None else r[0] for r in rows.refs]
    if m.averaging_points:
        s = np.arange(m.averaging_points) * m.averaging_spacing
        xyz = {g.id: np.array(g.xyz, float) for g in deck.grids.values()}
        rot_scale = np.array([np.abs(true[(ci == j) & (kinds == 1)]).max(initial=0.0) for j in range(len(cases))])
        for g, (b, other) in branches.items():
            ua = U[[row[(g, c)] for c in range(1, 7)], :]
            ub = U[[row[(other, c)] for c in range(1, 7)], :]
            samples = sim.member_end_rotation_samples(ua, ub, xyz[g], xyz[other], np.array(b.orientation), s)
            mean, s_mean = sim.averaged_rotation(samples, truth.noise, rng, rot_scale)
            for i, (d, j) in enumerate(zip(dof_rows, ci)):
                if d[0] == g and d[1] >= 4:
                    values[i], sigma[i] = mean[d[1] - 4, j], s_mean[d[1] - 4, j]

    out_dir = Path(out_dir)
    if out_dir.resolve() == Path(study_dir).resolve():
        raise StudyError("--out must be a new folder, not the study itself", file=str(out_dir))
    if out_dir.exists():
        shutil.rmtree(out_dir)
    shutil.copytree(study_dir, out_dir, ignore=shutil.ignore_patterns("measurements.csv", "truth.json"))
    with (out_dir / "measurements.csv").open("w") as fh:
        relative = any(r is not None for r in refs)
        fh.write("case,grid,component,value,sigma" + (",reference_grid\n" if relative else "\n"))
        for c, (g, comp), v, s_, rg in zip(case_rows, dof_rows, values, sigma, refs):
            tail = ("," + ("" if rg is None else str(rg))) if relative else ""
            fh.write(f"{c},{g},{comp},{float(v)!r},{float(s_)!r}{tail}\n")
    record = {"truth_file": str(truth_path), "seed": truth.seed, "force_scale": truth.force_scale,
              "noise": truth.noise.model_dump(), "measure": truth.measure.model_dump(),
              "deck": truth.deck, "parameters": [{"joint": j, "name": n, "value": float(v)}
                                                for (j, n), v in zip(names, k_true)],
              "n_measurements": len(values), "cases": cases,
              "solver_runs": adapter.stats.runs}
    (out_dir / "truth.json").write_text(json.dumps(record, indent=2))
    return record


# --------------------------------------------------------------------------------------------
# identify
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class IdentifyRun:
    """Everything one identification produced, for the CLI, the reports and other workflows."""
    study: Study
    joints: list[JointModel]
    model: CondensedModel
    fit_obs: Observations
    holdout_obs: Observations | None
    result: IdentificationResult
    solver: dict


def condensed_for_study(study: Study, adapter: SolverAdapter, joints: list[JointModel],
                        observed: list[DofLabel], loads: LoadMatrix | None = None) -> CondensedModel:
    """The one batched run: unit loads at the joints' DOFs plus the study's load cases."""
    boundary = [d for j in joints for d in j.dofs]
    c = condense(adapter, loads or study.loads, boundary, observed)
    K_deck = deck_matrix(study, joints)
    rigid = rigid_pair_penalty(c, joints)
    if rigid is not None:
        # A rigid branch pair (Sec. 2.2, last paragraph) is a very stiff spring that is not a
        # parameter: carried as a *negative* deck stiffness, since dK = K_J(k) - K_deck. Then the
        # joint matrices stay linear in k and every scheme (fixed point included) stays exact.
        K_deck = (np.zeros_like(rigid) if K_deck is None else K_deck) - rigid
    return CondensedModel(c, joints, K_deck)


RIGID_FACTOR = 1e6
"""A rigid pair's penalty: 1e6 times the stiffest rotational stiffness the structure offers at
the joint (1 / smallest flexibility there). Rigid to ~1e-6 of the relative rotation, while the
condensed system keeps ~10 digits in double precision."""


def rigid_pair_penalty(c, joints: list[JointModel]) -> np.ndarray | None:
    index = {d: i for i, d in enumerate(c.boundary)}
    n = len(c.boundary)
    out = np.zeros((n, n))
    found = False
    for j in joints:
        if not getattr(j, "rigid_pairs", ()):
            continue
        idx = np.array([index[d] for d in j.dofs])
        rot = idx[3:]
        scale = RIGID_FACTOR / float(np.min(np.diag(c.G_BB)[rot]))
        out[np.ix_(idx, idx)] += j.rigid_penalty_matrix(scale)
        found = True
    return out if found else None


def identify_study(study: Study, adapter: SolverAdapter, *, model: str | None = None,
                   progress=None, **options) -> IdentifyRun:
    """``blackbox identify``: condense once, then estimate (Chapter 4)."""
    from blackbox.identification import Observations, identify

    if not study.config.joints:
        raise StudyError("study.toml declares no [[joints]] to identify", file=str(study.root / "study.toml"))
    if study.measurements is None:
        raise StudyError("measurements.csv not found (needed to identify)", file=str(study.root))
    joints = study_joints(study, model)
    observed = study.measurements.all_dofs
    cm = condensed_for_study(study, adapter, joints, observed)
    obs = Observations.from_measurements(study.measurements, cm.c.cases)
    cfg = study.config.identification
    hold = None
    fit_obs = obs
    if cfg.holdout_cases:
        fit_obs, hold = obs.split(cfg.holdout_cases)
    k0 = np.concatenate([j.initial_params(jc.initial) for j, jc in zip(joints, study.config.joints)])
    opts = dict(fixed_point=cfg.fixed_point, max_iterations=cfg.max_iterations,
                confidence=cfg.confidence, bootstrap=cfg.bootstrap, profile=cfg.profile)
    opts.update(options)
    result = identify(cm, fit_obs, k0, holdout=hold, callback=progress, **opts)
    solver = {"runs": cm.c.solver_runs, "right_hand_sides": cm.c.right_hand_sides,
              "wall_s": cm.c.wall_s, "adapter": adapter.name}
    cache = getattr(adapter, "cache_stats", None)
    if cache is not None:                 # a batch served from the cache made no solver run
        solver["cached_batches"] = cache.hits
        if cache.hits:
            solver["right_hand_sides"] = sum(len(j.dofs) for j in joints) + study.loads.n_cases
    return IdentifyRun(study, joints, cm, fit_obs, hold, result, solver)


def truth_of(study: Study) -> dict[str, float] | None:
    """``{"joint.param": value}`` from a ``truth.json`` written by ``blackbox simulate``."""
    p = study.root / "truth.json"
    if not p.exists():
        return None
    rec = json.loads(p.read_text())
    return {f"{q['joint']}.{q['name']}": q["value"] for q in rec.get("parameters", [])} or None
