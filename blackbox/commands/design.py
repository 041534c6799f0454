"""``blackbox design STUDY --candidates FILE``: choose the load cases and sensors of a test.

:func:`run` condenses the study once with a unit load at every candidate load DOF (the joint
boundary in the same batch, the candidate sensors as observed DOFs), then chooses the plan in
the condensed space (:mod:`blackbox.experiment_design`) and returns a :class:`DesignResult`; its
:meth:`~DesignResult.write` puts ``design.json``, ``loads.csv``, ``measurements_template.csv``,
``report.md`` and the plot into a folder.

**Candidates file**: CSV ``kind,grid,component,value,sigma[,reference_grid[,case]]``.
``kind = load``: a load of ``value`` (N or N*m) that can be applied at ``(grid, component)``; one
designed case is one such load, unless the row names a ``case``: load rows with the same ``case``
label form one candidate case, applied together (e.g. the multi-force cases a rig can set up).
``kind = sensor``: a DOF that can be read, ``sigma`` its standard deviation (absolute, the
reading's units) or blank for the study's noise model; ``reference_grid`` (blank:
absolute) reads it relative to that grid's same component (Sec. 5.2). ``value`` of a sensor row
and ``sigma`` of a load row are ignored (leave them blank), as are ``reference_grid`` of a load
row and ``case`` of a sensor row.

**The noise model of a blank sigma** (:func:`noise_model`), in this order: the ``noise`` of a
simulated study's ``truth.json``; else the study's measurements: ``relative`` = the median of
``sigma / |value|`` over its rows, ``floor`` = 0.02 (``blackbox simulate``'s default); else
``blackbox simulate``'s default (5 %, floor 0.02). :func:`blackbox.experiment_design.candidate_sigma` applies
it to the prior's predicted readings.

**Prior**: the study's start values (``initial``), or ``--prior``: an earlier ``result.json`` (its
values, and its ``std`` for ``--robust``) or a ``truth.toml`` (its joints; no uncertainty).
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from blackbox import experiment_design as D
from blackbox.commands.common import as_study, study_adapter
from blackbox.condensation import CondensedModel
from blackbox.declared import DeclaredModel, SolverCost, declared_model, read_truth, read_truth_record, truth_joints
from blackbox.errors import StudyError
from blackbox.joints import ComplexJoint, SimpleJoint
from blackbox.simulation import NoiseConfig
from blackbox.study import Study
from solver_adapters.protocol import SolverAdapter

__all__ = ["DesignResult", "run", "read_candidates", "noise_model", "read_prior", "DEFAULT_DRAWS", "N_RANDOM"]

DEFAULT_DRAWS = 10          # --robust: parameter draws the criterion is averaged over
N_RANDOM = 50               # random plans per size, the yardstick of the report
CANDIDATES_HEADER = ("kind", "grid", "component", "value", "sigma")


# --------------------------------------------------------------------------------------------
# inputs
# --------------------------------------------------------------------------------------------
def read_candidates(path: str | Path, grids: set[int] | None = None) -> D.Candidates:
    """The candidates CSV (module docstring); every rejection names the file, line and column."""
    from solver_adapters.errors import TableFormatError
    from solver_adapters import tables

    path = Path(path)
    loads, sensors = [], []
    try:
        for line, rec in tables.rows(path, CANDIDATES_HEADER, ("reference_grid", "case")):
            kind = rec["kind"].lower()
            g = tables.parse_int(rec["grid"], path, line, "grid")
            c = tables.parse_int(rec["component"], path, line, "component")
            if not 1 <= c <= 6:
                raise StudyError(f"component must be 1..6, got {c}", file=str(path), line=line, column="component")
            if grids is not None and g not in grids:
                raise StudyError(f"grid {g} is not in the deck", file=str(path), line=line, column="grid")
            if kind == "load":
                if not rec["value"]:
                    raise StudyError("a load row needs its value (the magnitude that can be applied)",
                                     file=str(path), line=line, column="value")
                v = tables.parse_float(rec["value"], path, line, "value")
                if v == 0.0:
                    raise StudyError("a load of value 0 tells nothing", file=str(path), line=line, column="value")
                loads.append(D.CandidateLoad(g, c, v, rec.get("case") or None))
            elif kind == "sensor":
                s = None
                if rec["sigma"]:
                    s = tables.parse_float(rec["sigma"], path, line, "sigma")
                    if s <= 0:
                        raise StudyError(f"sigma must be positive (or blank for the noise model), got {s!r}",
                                         file=str(path), line=line, column="sigma")
                ref = None
                if rec.get("reference_grid"):
                    ref = tables.parse_int(rec["reference_grid"], path, line, "reference_grid")
                    if grids is not None and ref not in grids:
                        raise StudyError(f"reference grid {ref} is not in the deck", file=str(path), line=line,
                                         column="reference_grid")
                    if ref == g:
                        raise StudyError("a grid cannot be read relative to itself", file=str(path), line=line,
                                         column="reference_grid")
                sensors.append(D.CandidateSensor(g, c, s, ref))
            else:
                raise StudyError(f"kind must be 'load' or 'sensor', got {rec['kind']!r}", file=str(path),
                                 line=line, column="kind")
    except TableFormatError as exc:
        raise StudyError(exc.message, file=exc.file, line=exc.line, column=exc.column) from None
    try:
        return D.Candidates(tuple(loads), tuple(sensors))
    except D.DesignError as exc:
        raise StudyError(str(exc), file=str(path)) from None


def noise_model(study: Study) -> tuple[NoiseConfig, str]:
    """The noise model of a blank sigma and where it came from (module docstring)."""
    rec = read_truth_record(study)
    if rec and isinstance(rec.get("noise"), dict):
        try:
            return NoiseConfig(**rec["noise"]), "truth.json of the simulated study"
        except (TypeError, ValueError) as exc:
            raise StudyError(f"noise of truth.json is not a noise model: {exc}", file=str(study.root / "truth.json"))
    m = study.measurements
    if m is not None:
        ok = (np.abs(m.values) > 0) & np.isfinite(m.sigma)      # a blank sigma (estimated later) says nothing
        if ok.any():
            rel = float(np.median(m.sigma[ok] / np.abs(m.values[ok])))
            return NoiseConfig(relative=rel), f"median relative sigma of measurements.csv ({rel:.4g}), floor 0.02"
    return NoiseConfig(), "default (5 % of each reading, floor 0.02): the study has no measurements"


def start_value_warning(declared: DeclaredModel) -> str:
    """What a design from the study's start values (no ``--prior``) is worth, and what a pilot
    test or ``--robust`` buys (figures: ``benchmarks/design_prior.py``, docs/design.md)."""
    starts = []
    for j, (a, b) in zip(declared.joints, zip(np.cumsum([0] + [j.n_params for j in declared.joints])[:-1],
                                               np.cumsum([j.n_params for j in declared.joints]))):
        vals = np.unique(declared.k0[a:b])
        starts.append(f"{j.name} = {vals[0]:g}" if vals.size == 1 else f"{j.name}: {vals.min():g}..{vals.max():g}")
    return ("the prior is only the study's start value (" + ", ".join(starts) + "): the plan is chosen and "
            "its widths predicted as if the joint were that stiff. On the car fixture, whose start is 10 "
            "times below the truth, such predictions were 0.17 to 6.5 times the realised widths and the "
            "plan's widest realised interval 44 % (predicted 26 %). Identify a pilot test first and give "
            "its result.json as --prior: there the predictions were 0.86 to 1.23 times the realised ones "
            "and the plan's widest interval 9.5 %; --robust with it also averages the choice over the "
            "pilot's uncertainty (docs/design.md)")


def read_prior(declared: DeclaredModel, path: str | Path | None) -> tuple[np.ndarray, np.ndarray | None, str]:
    """``(k, std or None, description)`` of the prior (module docstring)."""
    labels = declared.param_labels
    if path is None:
        return declared.k0.copy(), None, "study.toml initial values"
    path = Path(path)
    if not path.is_file():
        raise StudyError("--prior: no such file", file=str(path))
    if path.suffix.lower() == ".toml":
        try:
            truth = read_truth(path)
            joints, k = truth_joints(declared.study, truth, path)
        except tomllib.TOMLDecodeError as exc:
            raise StudyError(f"not valid TOML: {exc}", file=str(path)) from None
        got = [(j.name, n) for j in joints for n in j.param_names]
        if got != labels:
            raise StudyError(f"--prior names parameters {got[:4]}... but the design's model has {labels[:4]}...; "
                             "give the same joints and models (or --model)", file=str(path))
        return np.asarray(k, float), None, f"truth {path.name}"
    try:
        rec = json.loads(path.read_text())
        params = {(p["joint"], p["name"]): p for p in rec["parameters"]}
    except (ValueError, KeyError, TypeError) as exc:
        raise StudyError(f"--prior is not a result.json with parameters: {exc}", file=str(path)) from None
    missing = [f"{j}.{n}" for j, n in labels if (j, n) not in params]
    if missing:
        raise StudyError(f"--prior lacks parameters {missing[:5]} of the design's model (identify with the same "
                         "joints and models, or use --model)", file=str(path))
    k = np.array([float(params[lab]["value"]) for lab in labels])
    z = 1.959963984540054      # 95 %: an interval without std gives std = width / (2 z)
    std = []
    for lab in labels:
        p = params[lab]
        if p.get("std") is not None and math.isfinite(float(p["std"])):
            std.append(float(p["std"]))
        elif p.get("ci_low") is not None and p.get("ci_high") is not None:
            std.append((float(p["ci_high"]) - float(p["ci_low"])) / (2 * z))
        else:
            std.append(math.nan)
    return k, np.array(std), f"result {path.name}"


# --------------------------------------------------------------------------------------------
# the result
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class DesignResult:
    """The chosen plan, what it predicts, the random plans of its size and the width curve."""
    study: Study
    declared: DeclaredModel
    model: CondensedModel
    space: D.CandidateSpace
    plan: D.Plan
    prediction: D.Prediction
    random: tuple[D.Prediction, ...]
    curve: D.DesignCurve
    noise: NoiseConfig
    noise_source: str
    prior_source: str
    robust_draws: int
    solver: SolverCost
    notes: tuple[str, ...] = field(default=())
    command: str = "design"

    @property
    def candidates(self) -> D.Candidates:
        return self.space.candidates

    @property
    def chosen_loads(self) -> list[tuple[str, int, int, float]]:
        """``(case, grid, component, value)`` of the plan's cases, ``D1, D2, ...``."""
        c = self.candidates
        return [(f"D{n + 1}", c.loads[i].grid, c.loads[i].component, c.loads[i].value)
                for n, case in enumerate(self.plan.loads) for i in c.cases[case]]

    @property
    def random_median_width(self) -> float:
        return float(np.median([r.max_relative_width for r in self.random]))

    def template_rows(self) -> list[tuple[str, int, int, float, int | None]]:
        """``(case, grid, component, planned sigma, reference grid)`` of every planned reading."""
        c = self.candidates
        return [(f"D{n + 1}", c.sensors[j].grid, c.sensors[j].component, float(self.space.sigma[i, j]),
                 c.sensors[j].reference_grid)
                for n, i in enumerate(self.plan.loads) for j in self.plan.sensors]

    def to_json(self) -> dict:
        c = self.candidates
        val = self.plan.value
        return {
            "criterion": self.plan.criterion,
            "criterion_value": val if math.isfinite(val) else None,
            "loads": [{"case": cs, "grid": g, "component": k, "value": v} for cs, g, k, v in self.chosen_loads],
            "candidate_cases": [c.case_label(n) for n in self.plan.loads],
            "sensors": [{"grid": c.sensors[j].grid, "component": c.sensors[j].component,
                         "reference_grid": c.sensors[j].reference_grid} for j in self.plan.sensors],
            "predicted": self.prediction.to_json(),
            "predicted_summary": {"max_relative_width": _num(self.prediction.max_relative_width),
                                  "median_relative_width": _num(self.prediction.median_relative_width),
                                  "geometric_mean_2std": _num(self.prediction.geometric_mean_2std),
                                  "rank": self.prediction.rank, "confidence": self.space.confidence},
            "random_plans": {"n": len(self.random), "median_max_relative_width": _num(self.random_median_width),
                             "median_geometric_mean_2std": _num(float(np.median(
                                 [r.geometric_mean_2std for r in self.random])))},
            "curve": self.curve.to_json(),
            "candidates": {"loads": len(c.loads), "cases": len(c.cases), "sensors": len(c.sensors)},
            "prior": {"source": self.prior_source, "robust_draws": self.robust_draws},
            "noise": {"source": self.noise_source, **self.noise.model_dump()},
            "exchanges": self.plan.exchanges,
            "solver": self.solver.to_json(),
            "notes": list(self.notes),
        }

    def write(self, out: Path) -> list[str]:
        from blackbox.reports.design import design_plot, design_report

        out = Path(out)
        (out / "design.json").write_text(json.dumps(self.to_json(), indent=2))
        with (out / "loads.csv").open("w") as fh:
            fh.write("case,grid,component,value\n")
            fh.writelines(f"{cs},{g},{k},{float(v)!r}\n" for cs, g, k, v in self.chosen_loads)
        rows = self.template_rows()
        relative = any(r[4] is not None for r in rows)
        with (out / "measurements_template.csv").open("w") as fh:
            fh.write("case,grid,component,value,sigma" + (",reference_grid" if relative else "") + "\n")
            for cs, g, k, s, ref in rows:
                tail = ("," + ("" if ref is None else str(ref))) if relative else ""
                fh.write(f"{cs},{g},{k},,{s!r}{tail}\n")
        plots = design_plot(self, out)
        text = design_report(self, plots)
        (out / "report.md").write_text(text)
        return ["design.json", "loads.csv", "measurements_template.csv", "report.md", *plots]


def _num(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


# --------------------------------------------------------------------------------------------
# the command
# --------------------------------------------------------------------------------------------
def run(study: Study | str | Path, candidates: str | Path | D.Candidates, *, n_loads: int = 6,
        n_sensors: int | None = None, criterion: str = "max_relative_ci_width",
        prior: str | Path | None = None, robust: bool = False, draws: int = DEFAULT_DRAWS,
        model: str | None = None, adapter: str | SolverAdapter | None = None, n_random: int = N_RANDOM,
        seed: int = 0) -> DesignResult:
    """Design a test of ``n_loads`` cases and ``n_sensors`` sensors (default: every candidate
    sensor) on ``study`` from ``candidates`` (a file or :class:`~blackbox.experiment_design.Candidates`).
    One solver run; everything else in the condensed space."""
    study = as_study(study)
    if not study.config.joints:
        raise StudyError("study.toml declares no [[joints]] to design a test for", file=str(study.root / "study.toml"))
    if criterion not in D.CRITERIA:
        raise StudyError(f"--criterion must be one of {', '.join(D.CRITERIA)}, got {criterion!r}")
    grids = set(study.deck.grids)
    cands = candidates if isinstance(candidates, D.Candidates) else read_candidates(candidates, grids)
    bad = [d for d in cands.load_dofs + cands.observed if d[0] not in grids]
    if bad:
        raise StudyError(f"candidate DOFs {bad[:5]} are not in the deck")
    if not 1 <= int(n_loads) <= len(cands.cases):
        raise StudyError(f"--loads must be 1..{len(cands.cases)} (the candidate cases), got {n_loads}")
    if n_sensors is not None and not 1 <= int(n_sensors) <= len(cands.sensors):
        raise StudyError(f"--sensors must be 1..{len(cands.sensors)} (the candidate sensors), got {n_sensors}")
    declared = declared_model(study, model)
    joint_dofs = set(declared.boundary)
    k, std, prior_source = read_prior(declared, prior)
    notes = []
    if robust and (std is None or not np.all(np.isfinite(std))):
        raise StudyError("--robust needs the prior's uncertainty: give --prior an earlier result.json "
                         "whose parameters have a std (or an interval)")
    if prior is None:
        notes.append(start_value_warning(declared))
    if any(d in joint_dofs for d in cands.load_dofs):
        notes.append("some candidate loads act on the joint's own DOFs")
    noise, noise_source = noise_model(study)

    ad = study_adapter(study, adapter)
    before = SolverCost.of(ad)
    cm = declared.condense(ad, observed=cands.observed, loads=cands.unit_loads())
    cost = SolverCost.of_batch(cm.c, ad, before)

    ks = None
    if robust:
        joints = declared.joints
        log_mask = np.concatenate([np.full(j.n_params, isinstance(j, SimpleJoint)) for j in joints])
        slices = np.cumsum([0] + [j.n_params for j in joints])

        def admissible(kd: np.ndarray) -> bool:           # the identification's own rule
            return all(j.is_admissible(kd[a:b], strict=True) for j, a, b in zip(joints, slices[:-1], slices[1:]))

        ks = D.prior_draws(k, std, log_mask, draws, seed, admissible)
    try:
        space = D.candidate_space(cm, cands, k, noise, draws=ks, confidence=declared.options.confidence)
        if criterion == "discrimination":
            if not all(isinstance(j, ComplexJoint) for j in declared.joints):
                raise StudyError("--criterion discrimination needs the complex model's prior: use --model complex "
                                 "(and --prior a complex identification's result.json or a truth)")
            simple = declared_model(study, "simple").condensed_model(cm.c)
            space = D.discrimination_space(space, cm, k, simple, draws=ks)
        plan = D.optimise(space, n_loads, n_sensors, criterion, seed=seed)
        pred = D.predict(space, plan.loads, plan.sensors)
        # one sample of random plans of the design's size: the report's yardstick and the curve's
        # last point are the same plans, so they give the same median
        rnd = tuple(D.predict(space, r.loads, r.sensors)
                    for r in D.random_plans(space, n_loads, n_sensors, n_random, seed + int(n_loads)))
        curve = D.design_curve(space, n_loads, n_sensors, criterion, n_random=n_random, seed=seed, final=plan,
                               final_random=rnd)
    except D.DesignError as exc:
        raise StudyError(str(exc)) from None
    if not pred.identifiable.all():
        notes.append(f"the plan does not determine every parameter (rank {pred.rank} of {len(k)}): "
                     "add load cases or sensors")
    return DesignResult(study, declared, cm, space, plan, pred, rnd, curve, noise, noise_source, prior_source,
                        int(draws) if robust else 0, cost, tuple(notes))
