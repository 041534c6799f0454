"""``blackbox compare``: Chapter 6 on a study folder (wiring, reports and plots).

1. One solver run condenses the structure on the joints' boundary DOFs (plus every measured
   DOF); both joint models are identified on it (:func:`blackbox.compare.identify_both`).
2. The MDSE loadings (eq. 34-35) of the isolated joint and of the joint in the structure, the
   strain energies, their relative difference and the joint displacements
   (:func:`blackbox.compare.compare_joints`).
3. The "11-case study" (Tables 6.6-6.7, Figure 6.3): when the study was written by
   ``blackbox simulate`` (it has ``truth.json``), the assembly MDSE loading becomes a new load
   case ``MDSE`` at the joint DOFs, its measurements are simulated from the same truth (same
   noise and measured DOFs, seed + 1) in a copy of the study, ``DIR/with_mdse/``, and both
   models are identified again -- on the first condensation extended by superposition
   (:func:`blackbox.compare.append_case`: a load at boundary DOFs needs no solver run). Real
   data (no ``truth.json``): the MDSE loading is written as ``mdse_loads.csv``, the recommended
   next experiment.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from blackbox import compare as cmp
from blackbox.condensation import condense
from blackbox.errors import StudyError
from blackbox.identification import IdentificationResult, Observations
from blackbox.joints import (ComplexJoint, JointModel, SimpleJoint, complex_param_names, make_joint,
                             simple_to_complex_params)
from blackbox.simulate import TruthConfig
from blackbox.study import Study, load_study
from blackbox.workflows import deck_matrix, make_adapter_for, simulate_study, study_joints

MDSE_LABEL = "MDSE"


@dataclass(frozen=True, eq=False)
class Stage:
    """One identification of both models and its comparison."""
    study: Study
    fits: cmp.ModelFits
    joints: list[cmp.JointComparison]
    uncertainty: list[dict]                                # cmp.energy_uncertainty, per joint
    fixed_load: list[cmp.JointComparison] | None = None   # under an earlier stage's MDSE loadings


# --------------------------------------------------------------------------------------------
# the two identifications
# --------------------------------------------------------------------------------------------
def _observations(study: Study, cases) -> tuple[Observations, Observations | None]:
    obs = Observations.from_measurements(study.measurements, cases)
    hold = study.config.identification.holdout_cases
    return obs.split(hold) if hold else (obs, None)


def _options(study: Study) -> dict:
    c = study.config.identification
    return dict(fixed_point=c.fixed_point, max_iterations=c.max_iterations, confidence=c.confidence,
                bootstrap=c.bootstrap, profile=c.profile)


def _fit(study: Study, condensed, simple_j, complex_j, truth) -> Stage:
    obs, hold = _observations(study, condensed.cases)
    k0s = np.concatenate([j.initial_params(jc.initial) for j, jc in zip(simple_j, study.config.joints)])
    k0c = np.concatenate([j.initial_params(jc.initial) for j, jc in zip(complex_j, study.config.joints)])
    K_deck = deck_matrix(study, complex_j)
    fits = cmp.identify_both(condensed, simple_j, complex_j, obs, k0s, k0c, K_deck, hold, **_options(study))
    comps = cmp.compare_joints(condensed, simple_j, fits.simple.k, complex_j, fits.complex.k, K_deck, truth)
    unc = cmp.energy_uncertainty(condensed, fits, comps, K_deck, confidence=study.config.identification.confidence)
    return Stage(study, fits, comps, unc)


# --------------------------------------------------------------------------------------------
# truth.json (written by blackbox simulate)
# --------------------------------------------------------------------------------------------
def _truth_record(study: Study) -> dict | None:
    p = study.root / "truth.json"
    if not p.exists():
        return None
    try:
        return json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise StudyError(f"not valid JSON: {exc}", file=str(p)) from None


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
            jm = make_joint(jc.name, jc.grids, model)
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
    """A truth TOML that :func:`blackbox.workflows.read_truth` reads back as ``cfg``."""
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


def _mdse_truth(rec: dict, study: Study, truth: dict, cases: list[str]) -> TruthConfig:
    """The truth of ``truth.json`` measuring only ``cases``, seed + 1."""
    deck = rec.get("deck")
    if deck:
        base = Path(rec.get("truth_file") or study.root).parent
        deck_path = (base / deck).resolve()
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
        while label in stage.study.loads.cases:
            label += "_new"
        out.append((label, scale, [(g, c, float(scale * v)) for (g, c), v in zip(jc.assembly.dofs, jc.assembly.load)]))
    return out


def _write_loads_fragment(path: Path, cases) -> None:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["case", "grid", "component", "value"])
        for label, _, rows in cases:
            for g, c, v in rows:
                w.writerow([label, g, c, repr(v)])


def _read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="") as fh:
        rows = [r for r in csv.reader(fh) if r and any(x.strip() for x in r)]
    return [h.strip() for h in rows[0]], rows[1:]


def _merge_measurements(base: Path, extra: Path, out: Path) -> None:
    h1, r1 = _read_csv(base)
    h2, r2 = _read_csv(extra)
    header = max(h1, h2, key=len)
    with out.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in r1 + r2:
            w.writerow(list(r) + [""] * (len(header) - len(r)))


def _with_mdse_folder(study: Study, out: Path, cases) -> Path:
    """``out/with_mdse``: a copy of the study whose loads.csv has the MDSE case(s) appended."""
    dst = out / "with_mdse"
    if dst.exists():
        shutil.rmtree(dst)
    skip = {out.resolve()}

    def ignore(folder, names):          # never copy the output folder into itself (--out inside STUDY)
        return [n for n in names if n in (".blackbox_cache", "measurements.csv")
                or (Path(folder) / n).resolve() in skip]

    shutil.copytree(study.root, dst, ignore=ignore)
    try:
        study.deck_path.relative_to(study.root.resolve())
    except ValueError:                                   # the deck lives outside the study folder
        toml = dst / "study.toml"
        text = toml.read_text().replace(json.dumps(study.config.solver.deck), json.dumps(str(study.deck_path)))
        text = text.replace(f"'{study.config.solver.deck}'", json.dumps(str(study.deck_path)))
        toml.write_text(text)
    with (dst / "loads.csv").open("a", newline="") as fh:
        if not (study.root / "loads.csv").read_text().endswith("\n"):
            fh.write("\n")
        w = csv.writer(fh)
        for label, _, rows in cases:
            for g, c, v in rows:
                w.writerow([label, g, c, repr(v)])
    return dst


def _stage_with_mdse(study: Study, first: Stage, condensed, simple_j, complex_j, truth, rec, out: Path,
                     adapter_name, cases, log) -> tuple[Stage, dict]:
    dst = _with_mdse_folder(study, out, cases)
    cfg = _mdse_truth(rec, study, truth, [label for label, _, _ in cases])
    (dst / "truth_mdse.toml").write_text(truth_toml(cfg))
    with tempfile.TemporaryDirectory(prefix="blackbox-mdse-") as tmp:
        sim_rec = simulate_study(dst, dst / "truth_mdse.toml", Path(tmp) / "sim", adapter_name)
        _merge_measurements(study.root / "measurements.csv", Path(tmp) / "sim" / "measurements.csv",
                            dst / "measurements.csv")
    merged = dict(rec)
    merged["cases"] = list(rec.get("cases", [])) + [label for label, _, _ in cases]
    merged["mdse"] = {"cases": [label for label, _, _ in cases], "seed": cfg.seed,
                      "n_measurements": sim_rec["n_measurements"], "truth_file": str(dst / "truth_mdse.toml")}
    merged["n_measurements"] = int(rec.get("n_measurements", 0)) + int(sim_rec["n_measurements"])
    (dst / "truth.json").write_text(json.dumps(merged, indent=2))
    study2 = load_study(dst, need_measurements=True)
    log(f"with_mdse: {len(study2.measurements)} measurements ({sim_rec['n_measurements']} simulated "
        f"for {[label for label, _, _ in cases]}, seed {cfg.seed}) -> {dst}")

    c2, runs = condensed, 0
    index = {d: i for i, d in enumerate(condensed.boundary)}
    for label, _, rows in cases:
        F = np.zeros(len(condensed.boundary))
        for g, c, v in rows:
            F[index[(g, c)]] = v
        c2 = cmp.append_case(c2, F, label)
    known = set(condensed.boundary) | set(condensed.observed)
    if c2.cases != study2.loads.cases or not set(study2.measurements.all_dofs) <= known:
        boundary = [d for j in complex_j for d in j.dofs]
        c2 = condense(make_adapter_for(study2, adapter_name), study2.loads, boundary,
                      study2.measurements.all_dofs)
        runs = c2.solver_runs
    stage = _fit(study2, c2, simple_j, complex_j, truth)
    fixed = {jc.name: (jc.isolated.load, jc.assembly.load) for jc in first.joints}
    K_deck = deck_matrix(study2, complex_j)
    again = cmp.compare_joints(c2, simple_j, stage.fits.simple.k, complex_j, stage.fits.complex.k,
                               K_deck, truth, loads=fixed)
    stage = Stage(study2, stage.fits, stage.joints, stage.uncertainty, again)
    info = {"folder": str(dst), "cases": [label for label, _, _ in cases], "seed": cfg.seed,
            "simulation_solver_runs": sim_rec["solver_runs"], "identification_solver_runs": runs}
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
def compare_study(study_dir: Path, out: Path, adapter_name: str | None = None,
                  log: Callable[[str], None] = lambda s: None) -> dict:
    """``blackbox compare STUDY --out DIR``: writes ``comparison.json``, ``report.md``, plots
    (and ``with_mdse/`` or ``mdse_loads.csv``); returns the JSON dictionary."""
    study = load_study(study_dir, need_measurements=True)
    if not study.config.joints:
        raise StudyError("study.toml declares no [[joints]] to compare", file=str(study.root / "study.toml"))
    out = Path(out)
    if out.resolve() == study.root.resolve():
        raise StudyError("--out must be a folder other than the study itself", file=str(out))
    adapter = make_adapter_for(study, adapter_name)
    simple_j, complex_j = study_joints(study, "simple"), study_joints(study, "complex")
    boundary = [d for j in complex_j for d in j.dofs]
    log(f"compare {study.name}: joints {[j.name for j in complex_j]}, {len(study.measurements)} "
        f"measurements, adapter {adapter.name!r}")
    c = condense(adapter, study.loads, boundary, study.measurements.all_dofs)
    solver = {"runs": c.solver_runs, "right_hand_sides": c.right_hand_sides, "wall_s": c.wall_s,
              "adapter": adapter.name}
    rec = _truth_record(study)
    truth = _truth_joints(study, rec)
    first = _fit(study, c, simple_j, complex_j, truth)
    for name, r in (("simple", first.fits.simple), ("complex", first.fits.complex)):
        log(f"  {name:7s}: {'converged' if r.converged else 'NOT converged'} in {r.iterations} iterations, "
            f"reduced chi2 = {r.reduced_chi2:.4g}, BIC = {r.bic:.6g}")
    out.mkdir(parents=True, exist_ok=True)
    cases = mdse_cases(first, complex_j)
    _write_loads_fragment(out / "mdse_loads.csv", cases)

    j0 = first.joints[0]
    result = {
        "study": study.name, "study_dir": str(study.root),
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
    second = None
    if rec is not None:
        second, info = _stage_with_mdse(study, first, c, simple_j, complex_j, truth, rec, out,
                                        adapter_name, cases, log)
        result["with_mdse"] = {"available": True, **info, **_stage_json(second, complex_j, simple_j, solver),
                               "parameter_changes": {m: _changes(getattr(first.fits, m), getattr(second.fits, m),
                                                                 simple_j if m == "simple" else complex_j)
                                                     for m in ("simple", "complex")}}
    else:
        result["with_mdse"] = {"available": False, "recommendation": (
            "no truth.json (real measurements): apply the MDSE loading of mdse_loads.csv to the "
            "structure as the next experiment, add its measurements and run compare again")}
    (out / "comparison.json").write_text(json.dumps(_clean(result), indent=2, allow_nan=False))
    plots = comparison_plots(first, second, out)
    (out / "report.md").write_text(comparison_report(result, first, second, complex_j, simple_j, plots))
    result["plots"] = plots
    return result


# --------------------------------------------------------------------------------------------
# report and plots
# --------------------------------------------------------------------------------------------
def _e(v, d: int = 4) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return f"{v:.{d}e}"


def _energy_table(m: cmp.MDSE, assembly: bool, unc: dict | None = None) -> list[str]:
    keys = [k for k in ("complex", "simple", "infinitely_flexible", "truth") if k in m.energies]
    t = m.truth_difference is not None
    out = ["| " + " | ".join(f"E_{k}" for k in keys) + " | R = (E_complex - E_simple)/E_complex |"
           + (" (E_truth - E_simple)/E_truth |" if t else "")
           + (" simple error / infinitely-flexible error |" if assembly else ""),
           "|" + "---|" * (len(keys) + 1 + t + assembly)]
    iv = ""
    if unc:
        lo, hi = unc["relative_difference_interval"]
        iv = f" [{100 * lo:.1f}, {100 * hi:.1f}]"
    row = "| " + " | ".join(_e(m.energies[k]) for k in keys) + f" | {100 * m.relative_difference:.2f} %{iv} |"
    if t:
        row += f" {100 * m.truth_difference:.2f} % |"
    if assembly:
        row += f" {100 * m.error_ratio():.1f} % |"
    return out + [row]


def _unc_note(u: dict | None) -> str:
    if not u:
        return ("No interval for R: a parameter is not identifiable, so the fitted energies are "
                "not bounded by these data.")
    return (f"R's interval: {100 * u['confidence']:g} % of R over {u['draws']} draws of both fits from "
            "their covariances, at this loading. R of *fitted* models contains their estimation "
            "error: a wide interval means the data do not yet separate coupling from noise.")


def _load_table(m: cmp.MDSE) -> list[str]:
    keys = list(m.displacements)
    out = ["| DOF | MDSE load | " + " | ".join(f"u ({k})" for k in keys) + " |", "|---|---|" + "---|" * len(keys)]
    for i, n in enumerate(m.names):
        mark = " **(dominant)**" if i == m.dominant else ""
        out.append(f"| {n} {m.dofs[i]} | {m.load[i]:+.4f}{mark} | "
                   + " | ".join(_e(m.displacements[k][i]) for k in keys) + " |")
    return out


def _params_table(stage: Stage, complex_j, simple_j, truth: dict | None, title: str) -> list[str]:
    f = stage.fits
    out = [title, ""] if title else []
    i_c = i_s = 0
    for cj, sj in zip(complex_j, simple_j):
        kc = f.complex.k[i_c:i_c + cj.n_params]
        lo, hi = f.complex.ci_low[i_c:i_c + cj.n_params], f.complex.ci_high[i_c:i_c + cj.n_params]
        ks = f.simple.k[i_s:i_s + sj.n_params]
        i_c += cj.n_params
        i_s += sj.n_params
        kcs = (simple_to_complex_params(sj, ks) if isinstance(sj, SimpleJoint)
               else cmp.clamped_stiffness(sj, ks)[np.triu_indices(3 * sj.n_branches - 3)])
        tv = truth.get(cj.name, {}) if truth else {}
        pct = f"{100 * f.complex.confidence:g}%"
        out += [f"Joint `{cj.name}`: K_C entries (branch {cj.n_branches} clamped), N*m/rad.", "",
                "| parameter | actual (truth) | complex estimate | " + pct + " interval | simple model (its K_C) |",
                "|---|---|---|---|---|"]
        for n, v, a, b, s in zip(cj.param_names, kc, lo, hi, kcs):
            t = _e(tv[n]) if n in tv else ""
            out.append(f"| {n} | {t} | {_e(v)} | [{_e(a, 3)}, {_e(b, 3)}] | {_e(s)} |")
        ls, hs = f.simple.ci_low[i_s - sj.n_params:i_s], f.simple.ci_high[i_s - sj.n_params:i_s]
        out += ["", "Simple-model springs: " + ", ".join(
            f"{n} = {_e(v, 3)} [{_e(a, 2)}, {_e(b, 2)}]" for n, v, a, b in zip(sj.param_names, ks, ls, hs)), ""]
    return out


def _fit_table(stage: Stage) -> list[str]:
    f = stage.fits
    out = ["| model | parameters | converged | reduced chi2 | BIC | RMS residual | hold-out RMS error | "
           "hold-out chi2 / n |", "|---|---|---|---|---|---|---|---|"]
    for name, r in (("simple", f.simple), ("complex", f.complex)):
        h = (f"{_e(r.holdout.rms_error, 3)} | {r.holdout.chi2 / max(r.holdout.n_obs, 1):.4g}" if r.holdout
             else "no hold-out cases | ")
        out.append(f"| {name} | {r.n_params} | {r.converged} | {r.reduced_chi2:.4g} | {r.bic:.6g} | "
                   f"{_e(r.rms_residual, 3)} | {h} |")
    lr = cmp.likelihood_ratio(f)
    out += ["", f"BIC prefers the **{lr['preferred_by_bic']}** model (delta BIC complex - simple = "
            f"{lr['delta_bic']:.4g}); likelihood ratio chi2_simple - chi2_complex = {lr['statistic']:.4g} "
            f"on {lr['dof']} degrees of freedom, p = {lr['p_value']:.3g} (approximate: springs at 0 "
            f"are on a bound). The complex fit started from the {f.complex_start}."]
    warn = [f"- {m}: {w}" for m, r in (("simple", f.simple), ("complex", f.complex)) for w in r.warnings]
    return out + ([""] + warn if warn else [])


def _stage_sections(stage: Stage, label: str, tables: dict[str, str]) -> list[str]:
    out = []
    for jc, unc in zip(stage.joints, stage.uncertainty):
        iso, asm = jc.isolated, jc.assembly
        out += [f"### Joint `{jc.name}` ({jc.n_branches} branches)", "",
                f"#### MDSE loading, isolated joint ({tables['load']})", "",
                f"Branch {jc.n_branches} clamped; largest eigenvalue of C_complex - C_simple = "
                f"{_e(float(iso.eigenvalues[0]))} rad/(N*m) (next {_e(float(iso.eigenvalues[1]))}). Dominant "
                f"DOF: **{iso.names[iso.dominant]}** ({100 * iso.dominant_share:.1f} % of the squared load).", "",
                *_load_table(iso), "",
                f"#### Strain energy, isolated joint ({tables['energy']})", "",
                *_energy_table(iso, False, unc["isolated"]), "", _unc_note(unc["isolated"]), "",
                f"#### Joint in the structure: MDSE loading, energies and displacements ({tables['assembly']})", "",
                f"Moments at the joint's rotation DOFs; joint `{jc.name}` simple, complex, or infinitely "
                f"flexible (K_J = 0), any other joint at its complex estimate. Dominant DOF: "
                f"**{asm.names[asm.dominant]}** ({100 * asm.dominant_share:.1f} %).", "",
                *_energy_table(asm, True, unc["assembly"]), "", *_load_table(asm), ""]
    if stage.fixed_load is not None:
        out += [f"#### Under the first MDSE loadings ({label})", ""]
        for jc in stage.fixed_load:
            out += [f"Joint `{jc.name}`, isolated:", "", *_energy_table(jc.isolated, False), "",
                    f"Joint `{jc.name}`, in the structure:", "", *_energy_table(jc.assembly, True), ""]
    return out


def comparison_report(result: dict, first: Stage, second: Stage | None, complex_j, simple_j,
                      plots: list[str]) -> str:
    s = result["solver"]
    truth = result.get("truth")
    out = [f"# Comparison of joint models: {result['study']} (Chapter 6)", "",
           f"Both models identified from the same {len(first.study.measurements)} measurements on one "
           f"condensation ({s['runs']} solver run, {s['right_hand_sides']} right-hand sides, adapter "
           f"{s['adapter']}). Energies are E = 1/2 F^T C F (eq. 35); the dissertation's tables list "
           "F^T C F = 2E. Units: N, m, rad.", "",
           "## Identified parameters (Table 6.1 / 6.8)", "",
           *_params_table(first, complex_j, simple_j, truth, ""),
           "## Fit statistics", "", *_fit_table(first), "",
           "## Comparison under the MDSE loading", "",
           *_stage_sections(first, "", {"load": "Table 6.2 / 6.9", "energy": "Table 6.3 / 6.10",
                                        "assembly": "Tables 6.4-6.5 / 6.11-6.12, Figure 6.2 / 6.4"})]
    if "energy_isolated.png" in plots:
        out += ["![isolated joint energies](energy_isolated.png)", "", "![assembly energies](energy_assembly.png)", ""]
    w = result["with_mdse"]
    out += ["## The MDSE loading as an additional load case (the 11-case study)", ""]
    if not w["available"]:
        out += [w["recommendation"] + ".", "", "```", Path(result["study_dir"]).name + " -> mdse_loads.csv:",
                *(f"{c['case']},{g},{cc},{v!r}" for c in result["mdse_load_case"]["cases"] for g, cc, v in c["rows"]),
                "```", ""]
    else:
        ch = w["parameter_changes"]
        scales = ", ".join(f"{c['scale']:g}" for c in result["mdse_load_case"]["cases"])
        out += [f"Case(s) {w['cases']} (the assembly MDSE loading times {scales}: its largest joint rotation "
                f"equals the largest of the study's cases) simulated from the same truth (seed {w['seed']}, "
                f"{w['simulation_solver_runs']} solver run for the simulation; the re-identification used "
                f"{w['identification_solver_runs']} more: the new case is a boundary load, added by "
                f"superposition) into `with_mdse/`.", "",
                *_params_table(second, complex_j, simple_j, truth,
                               "### Parameters with the MDSE case (Table 6.6 / 6.13)"),
                "Parameter changes (dissertation: < 2 % cube, < 3 % car): "
                + "; ".join(f"{m}: max {ch[m]['max_abs_change_percent']:.3g} %, median "
                            f"{ch[m]['median_abs_change_percent']:.3g} % of each value, max "
                            f"{ch[m]['max_change_percent_of_largest_diagonal']:.3g} % of the largest diagonal"
                            for m in ("simple", "complex")), "",
                "### Fit statistics with the MDSE case", "", *_fit_table(second), "",
                *_stage_sections(second, "Table 6.7 / 6.14 with the loading of Table 6.2",
                                 {"load": "recomputed", "energy": "Table 6.7 / 6.14",
                                  "assembly": "Figure 6.3 / 6.5"})]
        if "energy_isolated_mdse.png" in plots:
            out += ["![isolated joint energies, with MDSE](energy_isolated_mdse.png)", "",
                    "![assembly energies, with MDSE](energy_assembly_mdse.png)", ""]
    if not plots:
        out += ["(No plots: install matplotlib, `pip install 'blackbox-joints[plots]'`.)", ""]
    return "\n".join(out) + "\n"


def _energy_bars(plt, comps: list[cmp.JointComparison], unc: list[dict], which: str, path: Path,
                 title: str) -> None:
    keys = ["complex", "simple"] + (["infinitely_flexible"] if which == "assembly" else []) + \
        (["truth"] if "truth" in getattr(comps[0], which).energies else [])
    colors = {"complex": "tab:blue", "simple": "tab:orange", "infinitely_flexible": "0.6", "truth": "k"}
    fig, axes = plt.subplots(1, len(comps), figsize=(3.2 + 1.1 * len(keys), 3.8) if len(comps) == 1
                             else (2.6 * len(comps) + 2, 3.8), squeeze=False)
    for ax, jc, u in zip(axes[0], comps, unc):
        m = getattr(jc, which)
        vals = [m.energies[k] for k in keys]
        std = (u.get(which) or {}).get("energy_std", {})
        err = [std.get(k, 0.0) for k in keys]
        bars = ax.bar(range(len(keys)), vals, color=[colors[k] for k in keys], yerr=err, capsize=4,
                      error_kw={"elinewidth": 1})
        for b, v in zip(bars, vals):
            ax.annotate(f"{v:.3g}", (b.get_x() + b.get_width() / 2, v), ha="center", va="bottom", fontsize=8)
        ax.set_xticks(range(len(keys)), [k.replace("infinitely_flexible", "infinitely\nflexible") for k in keys],
                      fontsize=8)
        sub = f"R = {100 * m.relative_difference:.1f} %"
        if which == "assembly":
            sub += f", simple err / inf.-flex. err = {100 * m.error_ratio():.2g} %"
        ax.set_title(f"{jc.name}: {sub}\nMDSE load mostly {m.names[m.dominant]}", fontsize=9)
        ax.set_ylabel("strain energy 1/2 F^T C F (N*m)\nbars: +-1 std from the fits' covariances", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def comparison_plots(first: Stage, second: Stage | None, out: Path) -> list[str]:
    """Bar plots like Figures 6.2-6.5 (returns the file names; none without matplotlib)."""
    from blackbox.report import pyplot

    plt = pyplot()
    if plt is None:
        return []
    written = []
    for stage, suffix, tag in ((first, "", ""), (second, "_mdse", " (with the MDSE case)")):
        if stage is None:
            continue
        _energy_bars(plt, stage.joints, stage.uncertainty, "isolated", out / f"energy_isolated{suffix}.png",
                     f"Isolated joint under its MDSE loading (Table {'6.7 / 6.14' if suffix else '6.3 / 6.10'}){tag}")
        _energy_bars(plt, stage.joints, stage.uncertainty, "assembly", out / f"energy_assembly{suffix}.png",
                     "Joint in the structure under its MDSE loading "
                     f"(Figure {'6.3 / 6.5' if suffix else '6.2 / 6.4'}){tag}")
        written += [f"energy_isolated{suffix}.png", f"energy_assembly{suffix}.png"]
    return written
