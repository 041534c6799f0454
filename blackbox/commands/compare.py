"""``blackbox compare``: Chapter 6 on a study folder (wiring, reports and plots).

1. One solver run condenses the structure on the joints' boundary DOFs (plus every measured
   DOF); both joint models are identified on it (:func:`blackbox.comparison.identify_both`).
2. The MDSE loadings (eq. 34-35) of the isolated joint and of the joint in the structure, the
   strain energies, their relative difference and the joint displacements
   (:func:`blackbox.comparison.compare_joints`).
3. The "11-case study" (Tables 6.6-6.7, Figure 6.3): when the study was written by
   ``blackbox simulate`` (it has ``truth.json``), the assembly MDSE loading becomes a new load
   case ``MDSE`` at the joint DOFs, its measurements are simulated from the same truth (same
   noise and measured DOFs, seed + 1) in a copy of the study, ``DIR/with_mdse/``, and both
   models are identified again -- on the first condensation extended by superposition
   (:func:`blackbox.comparison.append_case`: a load at boundary DOFs needs no solver run). Real
   data (no ``truth.json``): the MDSE loading is written as ``mdse_loads.csv``, the recommended
   next experiment.
"""

from __future__ import annotations

import csv
import io
import json
import math
import shutil
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from blackbox import comparison as cmp
from blackbox.comparison import Stage
from blackbox.commands.common import as_study, copy_study, study_adapter
from blackbox.condensation import Condensed
from blackbox.declared import DeclaredModel, SolverCost, declared_model, joint_model, read_truth_record
from blackbox.errors import StudyError
from blackbox.identification import IdentificationResult
from blackbox.joints import ComplexJoint, JointModel, complex_param_names, simple_to_complex_params
from blackbox.simulation import TruthConfig
from blackbox.study import Study, load_study, study_file
from solver_adapters.protocol import SolverAdapter

__all__ = ["CompareResult", "Stage", "run", "truth_toml", "mdse_cases"]


MDSE_LABEL = "MDSE"


# --------------------------------------------------------------------------------------------
# the two identifications
# --------------------------------------------------------------------------------------------
def _fit(simple: DeclaredModel, complex_: DeclaredModel, condensed: Condensed, truth) -> Stage:
    """Both models on one condensation, compared at their MDSE loadings."""
    obs, hold = simple.observations(condensed.cases)
    K_deck = simple.K_deck(condensed)            # deck springs and rigid pairs: the same for both
    opts = simple.options.kwargs()
    fits = cmp.identify_both(condensed, list(simple.joints), list(complex_.joints), obs, simple.k0, complex_.k0,
                             K_deck, hold, **opts)
    comps = cmp.compare_joints(condensed, list(simple.joints), fits.simple.k, list(complex_.joints),
                               fits.complex.k, K_deck, truth)
    unc = cmp.energy_uncertainty(condensed, fits, comps, K_deck, confidence=opts["confidence"])
    return Stage(len(simple.study.measurements), tuple(simple.study.loads.cases), fits, comps, unc)


# --------------------------------------------------------------------------------------------
# truth.json (written by blackbox simulate)
# --------------------------------------------------------------------------------------------
def _truth_joints(study: Study, rec: dict | None) -> dict[str, tuple[JointModel, np.ndarray]]:
    """``{joint: (model, k)}`` of the truth's joint models (a deck truth has none)."""
    if not rec:
        return {}
    by_joint: dict[str, dict[str, float]] = {}
    for q in rec.get("parameters", []):
        by_joint.setdefault(q["joint"], {})[q["name"]] = float(q["value"])
    out = {}
    for jc in study.config.joints:
        vals = by_joint.get(jc.name)
        if not vals:
            continue
        model = "complex" if set(vals) == set(complex_param_names(len(jc.grids))) else "simple"
        try:
            jm = joint_model(study, jc.name, model)
            out[jc.name] = (jm, jm.from_dict(vals))
        except ValueError:
            continue            # a truth that does not fit this joint: compared without it
    return out


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, float):
        if not math.isfinite(v):
            raise StudyError(f"cannot write the non-finite number {v!r} to a truth file")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"no TOML form for {type(v).__name__}")


def truth_toml(cfg: TruthConfig) -> str:
    """A truth TOML that :func:`blackbox.declared.read_truth` reads back as ``cfg``."""
    lines = [f"seed = {cfg.seed}", f"force_scale = {_toml_value(float(cfg.force_scale))}"]
    if cfg.deck is not None:
        lines.append(f"deck = {_toml_value(cfg.deck)}")
    for table, obj in (("noise", cfg.noise), ("measure", cfg.measure)):
        lines += ["", f"[{table}]"]
        for k, v in obj.model_dump().items():
            if v is not None:
                lines.append(f"{k} = {_toml_value(v)}")
    for j in cfg.joints:
        lines += ["", "[[joints]]", f"name = {_toml_value(j.name)}", f"model = {_toml_value(j.model)}"]
        for k in ("value", "stub_length"):
            if getattr(j, k) is not None:
                lines.append(f"{k} = {_toml_value(float(getattr(j, k)))}")
        if j.values is not None:
            lines.append("[joints.values]")
            lines += [f"{k} = {_toml_value(float(v))}" for k, v in j.values.items()]
    return "\n".join(lines) + "\n"


def _truth_deck_refused(study: Study, rec: dict | None) -> str | None:
    """Why the truth deck that truth.json names may not be read (it lies outside the study in a
    folder the user has not allowed: :func:`blackbox.study.study_file`), else None."""
    deck = (rec or {}).get("deck")
    if not deck:
        return None
    base = Path(rec.get("truth_file") or study.root).parent
    try:
        study_file(study.root, base / deck, f"the truth deck {deck!r} of truth.json")
    except StudyError as exc:
        return str(exc)
    return None


def _mdse_truth(rec: dict, study: Study, truth: dict, cases: list[str]) -> TruthConfig:
    """The truth of ``truth.json`` measuring only ``cases``, seed + 1."""
    deck = rec.get("deck")
    if deck:
        base = Path(rec.get("truth_file") or study.root).parent
        # a path truth.json gives: read only inside the study or a folder the user allows
        deck_path = study_file(study.root, base / deck, f"the truth deck {deck!r} of truth.json",
                               named_in=study.root / "truth.json")
        if not deck_path.is_file():
            raise StudyError(f"truth deck {deck!r} of truth.json not found at {deck_path}",
                             file=str(study.root / "truth.json"))
        deck = str(deck_path)
    joints = [{"name": n, "model": m.model_name, "values": m.to_dict(k)} for n, (m, k) in truth.items()]
    try:
        return TruthConfig.model_validate({
            "seed": int(rec.get("seed", 0)) + 1, "deck": deck, "joints": joints,
            "noise": rec.get("noise", {}), "force_scale": rec.get("force_scale", 1.0),
            "measure": {**rec.get("measure", {}), "cases": cases}})
    except ValueError as exc:
        raise StudyError(f"truth.json cannot be re-used for the MDSE case: {exc}",
                         file=str(study.root / "truth.json")) from None


# --------------------------------------------------------------------------------------------
# the MDSE load case
# --------------------------------------------------------------------------------------------
def mdse_cases(stage: Stage, joints: list[JointModel]) -> list[tuple[str, float, list]]:
    """``[(label, scale, [(grid, component, value), ...])]``: each joint's assembly MDSE loading
    (moments) scaled so that the largest joint rotation it causes equals the largest joint
    rotation of the study's own load cases (both with the complex fit): a case of the study's
    size, whatever the units of its loads. Scale to 3 significant digits. Label ``MDSE``
    (``MDSE_<joint>`` with several joints)."""
    U = stage.fits.complex_model.response(stage.fits.complex.k).U_B
    boundary = stage.fits.complex_model.c.boundary
    out = []
    for jc, j in zip(stage.joints, joints):
        rows = [boundary.index(d) for d in j.rotation_dofs]
        r_study = float(np.abs(U[rows]).max())
        r_mdse = float(np.abs(jc.assembly.displacements["complex"]).max())
        scale = float(f"{r_study / r_mdse:.3g}") if r_mdse > 0 and r_study > 0 else 1.0
        label = MDSE_LABEL if len(stage.joints) == 1 else f"{MDSE_LABEL}_{jc.name}"
        while label in stage.cases:
            label += "_new"
        out.append((label, scale, [(g, c, float(scale * v)) for (g, c), v in zip(jc.assembly.dofs, jc.assembly.load)]))
    return out


def _loads_rows_csv(cases, header: bool) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    if header:
        w.writerow(["case", "grid", "component", "value"])
    for label, _, rows in cases:
        for g, c, v in rows:
            w.writerow([label, g, c, repr(v)])
    return buf.getvalue()


def _with_mdse_folder(study: Study, dst: Path, cases) -> None:
    """A copy of the study in ``dst`` whose loads.csv has the MDSE case(s) appended."""
    copy_study(study, dst, skip=("measurements.csv", "truth.json"))
    text = (study.root / "loads.csv").read_text(encoding="utf-8-sig")
    if text and not text.endswith("\n"):
        text += "\n"
    (dst / "loads.csv").write_text(text + _loads_rows_csv(cases, header=False))


def _stage_with_mdse(study: Study, first: Stage, condensed: Condensed, simple: DeclaredModel,
                     complex_: DeclaredModel, truth, rec, dst: Path, adapter, cases, log) -> tuple[Stage, dict]:
    """Simulate the MDSE case(s) from the same truth into ``dst`` and fit both models again."""
    from blackbox.commands import simulate

    _with_mdse_folder(study, dst, cases)
    labels = [label for label, _, _ in cases]
    cfg = _mdse_truth(rec, study, truth, labels)
    (dst / "truth_mdse.toml").write_text(truth_toml(cfg))
    sim = simulate.run(dst, dst / "truth_mdse.toml", adapter=adapter)
    base = study.measurements
    base_refs = base.refs or (None,) * len(base)
    rows = [(c, g, comp, float(v), float(s_), None if r is None else r[0])
            for c, (g, comp), v, s_, r in zip(base.cases, base.dofs, base.values, base.sigma, base_refs)]
    merged_sim = simulate.SimulateResult(study, rows + list(sim.rows), {})
    (dst / "measurements.csv").write_text(merged_sim.measurements_csv())
    merged = dict(rec)
    merged["cases"] = list(rec.get("cases", [])) + labels
    merged["mdse"] = {"cases": labels, "seed": cfg.seed, "n_measurements": sim.n_measurements,
                      "truth_file": "truth_mdse.toml"}
    merged["n_measurements"] = int(rec.get("n_measurements", 0)) + sim.n_measurements
    (dst / "truth.json").write_text(json.dumps(merged, indent=2))
    study2 = load_study(dst, need_measurements=True)
    log(f"with_mdse: {len(study2.measurements)} measurements ({sim.n_measurements} simulated "
        f"for {labels}, seed {cfg.seed})")
    simple2, complex2 = declared_model(study2, "simple"), declared_model(study2, "complex")

    c2, runs = condensed, 0
    index = {d: i for i, d in enumerate(condensed.boundary)}
    for label, _, rows_ in cases:
        F = np.zeros(len(condensed.boundary))
        for g, c, v in rows_:
            F[index[(g, c)]] = v
        c2 = cmp.append_case(c2, F, label)
    known = set(condensed.boundary) | set(condensed.observed)
    if c2.cases != study2.loads.cases or not set(study2.measurements.all_dofs) <= known:
        ad2 = study_adapter(study2, adapter)
        c2 = complex2.condense(ad2).c
        runs = c2.solver_runs
    stage = _fit(simple2, complex2, c2, truth)
    fixed = {jc.name: (jc.isolated.load, jc.assembly.load) for jc in first.joints}
    again = cmp.compare_joints(c2, list(simple2.joints), stage.fits.simple.k, list(complex2.joints),
                               stage.fits.complex.k, simple2.K_deck(c2), truth, loads=fixed)
    stage = replace(stage, fixed_load=again)
    info = {"folder": "with_mdse", "cases": labels, "seed": cfg.seed,
            "simulation_solver_runs": sim.record["solver_runs"], "identification_solver_runs": runs}
    return stage, info


# --------------------------------------------------------------------------------------------
# JSON
# --------------------------------------------------------------------------------------------
def _num(v):
    v = float(v)
    return v if math.isfinite(v) else None


def _clean(obj):
    """JSON-safe: non-finite numbers become null, numpy scalars plain numbers."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return _num(obj)
    return obj


def _model_json(r: IdentificationResult, joints: list[JointModel], solver: dict) -> dict:
    d = r.to_json_dict(solver)
    keep = ("converged", "iterations", "parameters", "fit", "holdout", "status", "message",
            "confidence", "ci_method", "rank", "warnings")
    out = {k: d[k] for k in keep}
    kc = []
    i = 0
    for j in joints:
        k = r.k[i:i + j.n_params]
        i += j.n_params
        kcv = k if isinstance(j, ComplexJoint) else simple_to_complex_params(j, k)
        names = complex_param_names(j.n_branches)
        kc.append({"joint": j.name, "K_C": {n: float(v) for n, v in zip(names, kcv)}})
    out["clamped_stiffness"] = kc
    return out


def _changes(before: IdentificationResult, after: IdentificationResult, joints: list[JointModel]) -> dict:
    d = after.k - before.k
    with np.errstate(divide="ignore", invalid="ignore"):
        pct = 100.0 * d / np.abs(before.k)
    diag = []
    i = 0
    for j in joints:
        sl = slice(i, i + j.n_params)
        i += j.n_params
        K = cmp.clamped_stiffness(j, before.k[sl])
        diag.append(np.full(j.n_params, float(np.max(np.abs(np.diag(K))))))
    pdiag = 100.0 * np.abs(d) / np.concatenate(diag)
    finite = np.abs(pct[np.isfinite(pct)])
    return {"parameters": [{"joint": jn, "name": n, "before": float(a), "after": float(b),
                            "change_percent": _num(p), "change_percent_of_largest_diagonal": _num(q)}
                           for jn, n, a, b, p, q in zip(before.param_joint, before.param_names, before.k,
                                                        after.k, pct, pdiag)],
            "max_abs_change_percent": _num(np.max(finite)) if finite.size else None,
            "median_abs_change_percent": _num(np.median(finite)) if finite.size else None,
            "max_change_percent_of_largest_diagonal": _num(np.max(pdiag))}


def _stage_json(stage: Stage, complex_j, simple_j, solver) -> dict:
    f = stage.fits
    joints = []
    for j, u in zip(stage.joints, stage.uncertainty):
        d = j.to_json()
        for key in ("isolated", "assembly"):
            d[key]["strain_energy"]["uncertainty"] = u[key]
        joints.append(d)
    out = {"joints": joints,
           "models": {"simple": _model_json(f.simple, simple_j, solver),
                      "complex": _model_json(f.complex, complex_j, solver)},
           "complex_start": f.complex_start,
           "model_selection": cmp.likelihood_ratio(f)}
    if stage.fixed_load is not None:
        out["under_first_mdse_loading"] = [j.to_json() for j in stage.fixed_load]
    return out


# --------------------------------------------------------------------------------------------
# the command
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class CompareResult:
    """Both models, their comparison, and (simulated studies) the refit with the MDSE case."""
    study: Study
    document: dict                     # comparison.json
    first: Stage
    second: Stage | None
    simple: DeclaredModel
    complex: DeclaredModel
    mdse_cases: list
    solver: SolverCost
    workdir: tempfile.TemporaryDirectory | None = None    # holds with_mdse/ until written
    command: str = "compare"

    @property
    def ok(self) -> bool:
        return all(m["converged"] for m in self.document["models"].values())

    def write(self, out: Path) -> list[str]:
        from blackbox.reports.compare import comparison_plots, comparison_report

        out = Path(out)
        files = ["comparison.json", "mdse_loads.csv"]
        (out / "mdse_loads.csv").write_text(_loads_rows_csv(self.mdse_cases, header=True))
        (out / "comparison.json").write_text(json.dumps(_clean(self.document), indent=2, allow_nan=False))
        plots = comparison_plots(self.first, self.second, out)
        (out / "report.md").write_text(comparison_report(self.document, self.first, self.second,
                                                         list(self.complex.joints), list(self.simple.joints), plots))
        if self.workdir is not None:
            shutil.copytree(Path(self.workdir.name) / "with_mdse", out / "with_mdse")
            files.append("with_mdse/")
        return files + ["report.md", *plots]


def run(study: Study | str | Path, *, adapter: str | SolverAdapter | None = None,
        log: Callable[[str], None] = lambda s: None) -> CompareResult:
    """Fit the simple and the complex joint model from one solver run and compare them (Chapter 6)."""
    study = as_study(study, need_measurements=True)
    if not study.config.joints:
        raise StudyError("study.toml declares no [[joints]] to compare", file=str(study.root / "study.toml"))
    ad = study_adapter(study, adapter)
    simple, complex_ = declared_model(study, "simple"), declared_model(study, "complex")
    log(f"compare {study.name}: joints {[j.name for j in complex_.joints]}, {len(study.measurements)} "
        f"measurements, adapter {ad.name!r}")
    before = SolverCost.of(ad)
    c = complex_.condense(ad).c
    cost = SolverCost.of_batch(c, ad, before)
    solver = cost.to_json()
    rec = read_truth_record(study)
    truth = _truth_joints(study, rec)
    first = _fit(simple, complex_, c, truth)
    for name, r in (("simple", first.fits.simple), ("complex", first.fits.complex)):
        log(f"  {name:7s}: {'converged' if r.converged else 'NOT converged'} in {r.iterations} iterations, "
            f"reduced chi2 = {r.reduced_chi2:.4g}, BIC = {r.bic:.6g}")
    cases = mdse_cases(first, list(complex_.joints))
    simple_j, complex_j = list(simple.joints), list(complex_.joints)

    j0 = first.joints[0]
    result = {
        "study": study.name, "study_dir": study.root.name,
        "mdse_load": j0.isolated.load.tolist(),
        "strain_energy": {"complex": j0.isolated.energies["complex"], "simple": j0.isolated.energies["simple"],
                          "relative_difference": j0.isolated.relative_difference},
        "note": ("mdse_load and strain_energy: isolated joint (branch n clamped) of the first joint "
                 f"{j0.name!r}, E = 1/2 F^T K_C^-1 F; per joint and for the assembly see 'joints'"),
        "solver": solver, "truth": {n: m.to_dict(k) for n, (m, k) in truth.items()} or None,
        **_stage_json(first, complex_j, simple_j, solver),
        "mdse_load_case": {"file": "mdse_loads.csv", "scaling": (
            "the assembly MDSE loading times a scale that makes its largest joint rotation equal "
            "the largest joint rotation of the study's load cases (complex fit)"),
            "cases": [{"case": label, "scale": sc, "rows": [[g, cc, v] for g, cc, v in rows]}
                      for label, sc, rows in cases]},
    }
    second, workdir = None, None
    refused = _truth_deck_refused(study, rec)
    if rec is not None and not (truth or rec.get("deck")):
        result["with_mdse"] = {"available": False, "recommendation": (
            "truth.json's joint parameters do not fit the declared joints (e.g. springs for a pair "
            "declared rigid), so the MDSE case cannot be simulated from that truth: apply the MDSE "
            "loading of mdse_loads.csv as the next experiment instead")}
    elif rec is not None and refused:
        log(f"  the MDSE case is not simulated: {refused}")
        result["with_mdse"] = {"available": False, "recommendation": (
            f"the MDSE case was not simulated: {refused}. Run compare again with that folder allowed, or "
            f"apply the MDSE loading of mdse_loads.csv as the next experiment instead")}
    elif rec is not None:
        workdir = tempfile.TemporaryDirectory(prefix="blackbox-compare-")
        second, info = _stage_with_mdse(study, first, c, simple, complex_, truth, rec,
                                        Path(workdir.name) / "with_mdse", adapter, cases, log)
        result["with_mdse"] = {"available": True, **info, **_stage_json(second, complex_j, simple_j, solver),
                               "parameter_changes": {m: _changes(getattr(first.fits, m), getattr(second.fits, m),
                                                                 simple_j if m == "simple" else complex_j)
                                                     for m in ("simple", "complex")}}
    else:
        result["with_mdse"] = {"available": False, "recommendation": (
            "no truth.json (real measurements): apply the MDSE loading of mdse_loads.csv to the "
            "structure as the next experiment, add its measurements and run compare again")}
    return CompareResult(study, result, first, second, simple, complex_, cases, cost, workdir)
