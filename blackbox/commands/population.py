"""``blackbox population STUDY...``: many specimens of one joint design, pooled into one population.

Every study is one specimen (its own deck, loads, measurements and noise) and one task of an
:class:`~blackbox.parallel.Executor` (serial, or a Dask cluster with ``--workers`` /
``--scheduler``): the task rebuilds the study where it runs (:func:`blackbox.parallel.pack_study`),
makes the study's one batched solver run (the condensation, through the study's solver cache),
and computes there, in the condensed space, the specimen's estimate and its likelihood of every
joint parameter (:func:`blackbox.population.specimen.fit_specimen`). The client then fits the
population (:func:`blackbox.population.fit.fit_population`): no further solver run.

The studies must declare the same joints (names, simple model) so that their parameters are the
same; a study that cannot be read, whose solver fails, or that differs is reported with every
other such study in one message, and nothing is written (a population needs all its specimens).
"""

from __future__ import annotations

import json
import math
import tomllib
import os
import socket
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from blackbox.errors import PopulationError, StudyError
from blackbox.parallel import Executor, SerialExecutor, StudyPackage, TaskFailure, pack_study, scratch, unpack_study
from blackbox.population.fit import OUTLIER_ALPHA, PopulationFit, fit_population
from blackbox.population.likelihood import TabulatedLikelihood
from blackbox.population.specimen import SpecimenFit
from solver_adapters.protocol import SolverError

__all__ = ["SpecimenTask", "SpecimenOutcome", "PopulationResult", "run", "specimen_task", "simulate_specimens"]

_Z95 = 1.959963984540054


@dataclass(frozen=True)
class SpecimenTask:
    """What travels to a worker for one specimen."""
    name: str
    package: StudyPackage
    adapter: str | None = None
    cache: str | None = None
    trust_command: bool = False


@dataclass(frozen=True)
class SpecimenOutcome:
    """What comes back: the specimen's fit (None when it failed), its labels, the solver's cost."""
    name: str
    origin: str
    status: str                             # ok | bad_input | solver_failure | error
    message: str = ""
    param_joint: tuple[str, ...] = ()
    param_names: tuple[str, ...] = ()
    confidence: float = 0.95
    fit: SpecimenFit | None = field(default=None, repr=False)
    solver: dict = field(default_factory=dict)
    wall_s: float = 0.0
    worker: str = ""


def specimen_task(task: SpecimenTask) -> SpecimenOutcome:
    """One specimen where the task runs: load the study, condense it (one solver run), fit it and
    tabulate its likelihoods. Never raises for the study's own failures: they are its status."""
    from blackbox.adapters import ADAPTER_CACHE, TRUST_COMMAND, make_adapter_for
    from blackbox.commands.batch import _cache_for_worker, _status_of
    from blackbox.declared import SolverCost, declared_model
    from blackbox.population.specimen import fit_specimen
    from blackbox.study import load_study

    t0 = time.perf_counter()
    where = f"{socket.gethostname()}:{os.getpid()}"
    cache, _ = _cache_for_worker(task.cache)
    tokens = (ADAPTER_CACHE.set(cache), TRUST_COMMAND.set(bool(task.trust_command)))
    try:
        with scratch() as tmp:
            root = unpack_study(task.package, tmp / "study")
            try:
                study = load_study(root, need_measurements=True)
                if not study.config.joints:
                    raise StudyError("study.toml declares no [[joints]]", file="study.toml")
                complex_ = [j.name for j in study.config.joints if j.model != "simple"]
                if complex_:
                    raise PopulationError(f"joint(s) {complex_} use the complex model: the population models "
                                          "the simple model's springs (log-normal); set model = \"simple\"")
                declared = declared_model(study)
                ad = make_adapter_for(study, task.adapter)
                before = SolverCost.of(ad)
                cm = declared.condense(ad)
                cost = SolverCost.of_batch(cm.c, ad, before)
                fit_obs, _ = declared.observations(cm.c.cases)
                fit = fit_specimen(cm, fit_obs, declared.k0, max_iterations=max(declared.options.max_iterations, 50))
            except Exception as exc:
                status = _status_of(exc)
                msg = f"{type(exc).__name__}: {exc}"
                if status == "error":
                    msg += "\n" + traceback.format_exc(limit=8)
                return SpecimenOutcome(task.name, task.package.origin, status, msg,
                                       wall_s=time.perf_counter() - t0, worker=where)
    finally:
        ADAPTER_CACHE.reset(tokens[0])
        TRUST_COMMAND.reset(tokens[1])
    asm = cm.assembly
    return SpecimenOutcome(task.name, task.package.origin, "ok", "", tuple(asm.param_joint), tuple(asm.param_names),
                           float(study.config.identification.confidence), fit, cost.to_json(),
                           time.perf_counter() - t0, where)


# --------------------------------------------------------------------------------------------
# the result
# --------------------------------------------------------------------------------------------
def _num(v) -> float | None:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


@dataclass(frozen=True, eq=False)
class PopulationResult:
    """The specimens, the population fit and how the command ran."""
    outcomes: tuple[SpecimenOutcome, ...]
    fit: PopulationFit
    executor: str
    wall_s: float
    specimen_wall_s: float
    population_wall_s: float
    command: str = "population"

    @property
    def names(self) -> list[str]:
        return [o.name for o in self.outcomes]

    @property
    def undetermined(self) -> list[str]:
        """Parameters whose centre or spread the data do not bound."""
        return [f"{j}.{n}" for j, n, P in zip(self.fit.param_joint, self.fit.param_names, self.fit.parameters)
                if not P.determined]

    def open_sides(self, j: int) -> tuple[list[str], list[str]]:
        """The specimens whose likelihood of parameter ``j`` stays flat toward 0 (the spring may
        vanish) and toward rigid (it may be as stiff as the structure allows), by name."""
        low, high = [], []
        for o in self.outcomes:
            L = o.fit.likelihoods[j]
            if isinstance(L, TabulatedLikelihood):
                if L.left_slope == 0.0:
                    low.append(o.name)
                if L.right_slope == 0.0:
                    high.append(o.name)
        return low, high

    @property
    def not_converged(self) -> list[str]:
        return [o.name for o in self.outcomes if not o.fit.converged]

    @property
    def ok(self) -> bool:
        return not self.undetermined and not self.not_converged

    def _open_note(self, j: int) -> list[str]:
        low, high = self.open_sides(j)
        out = []
        if low:
            out.append(f"the data of {', '.join(low)} do not bound it from below (the spring may be 0 there): "
                       "the population's spread is then bounded only by the other specimens")
        if high:
            out.append(f"the data of {', '.join(high)} do not bound it from above (rigid relative to the structure "
                       "is possible there)")
        return out

    def solver_totals(self) -> dict:
        keys = ("runs", "right_hand_sides", "cached_batches")
        out = {k: int(sum(o.solver.get(k, 0) for o in self.outcomes)) for k in keys}
        out["wall_s"] = float(sum(o.solver.get("wall_s", 0.0) for o in self.outcomes))
        out["adapter"] = ", ".join(sorted({str(o.solver.get("adapter", "")) for o in self.outcomes}))
        return out

    def to_json(self) -> dict:
        f = self.fit
        params = []
        for j, (joint, name, P) in enumerate(zip(f.param_joint, f.param_names, f.parameters)):
            lo, hi = P.centre_ci
            slo, shi = P.spread_ci
            params.append({
                "joint": joint, "name": name, "center": _num(P.centre), "center_ci_low": _num(lo),
                "center_ci_high": _num(hi), "spread": _num(P.spread), "spread_ci_low": _num(slo),
                "spread_ci_high": _num(shi), "n_specimens": P.n_specimens, "determined": bool(P.determined),
                "log_sd": _num(P.tau), "log_sd_ci": [_num(v) for v in P.tau_ci],
                "specimens_share_value": {"statistic": _num(P.common_statistic), "df": max(P.n_specimens - 1, 0),
                                          "p_value": _num(P.common_p)},
                "centre_dof": _num(P.dof), "notes": list(P.notes) + self._open_note(j)})
        specimens = []
        for s, o in enumerate(self.outcomes):
            sp = []
            for j, (joint, name) in enumerate(zip(f.param_joint, f.param_names)):
                L = o.fit.likelihoods[j]
                val, low, high = (np.exp(f.shrunk[j, s]) if np.all(np.isfinite(f.shrunk[j, s]))
                                  else (math.nan,) * 3)
                alone = o.fit.interval(j)
                sp.append({"joint": joint, "name": name, "value": _num(val), "ci_low": _num(low),
                           "ci_high": _num(high), "identifiable": bool(L.informative),
                           "source": ("specimen and population" if L.informative else
                                      "population only: this specimen's data do not determine it"),
                           "alone": {"value": _num(o.fit.k[j]) if L.informative else None,
                                     "ci_low": _num(alone[0]), "ci_high": _num(alone[1])},
                           "likelihood": ("exact profile" if isinstance(L, TabulatedLikelihood)
                                          else "quadratic (checked)" if L.informative else "none")})
            specimens.append({"study": o.name, "folder": o.origin, "converged": bool(o.fit.converged),
                              "reduced_chi2": _num(o.fit.reduced_chi2), "n_obs": o.fit.n_obs,
                              "solver": dict(o.solver), "warnings": list(o.fit.warnings), "parameters": sp})
        d = f.differ
        differ = {"p_value": _num(d.p_value), "statistic": _num(d.statistic), "df": d.df,
                  "chi2_pooled": _num(d.chi2_pooled), "chi2_separate": _num(d.chi2_separate),
                  "pooled_fit_converged": bool(d.converged),
                  "test": "likelihood ratio: one common set of joint parameters for every specimen (pooled fit) "
                          "against each specimen's own; chi2 with df = sum of the specimens' ranks - the pooled "
                          "rank"} if d is not None else None
        outliers = []
        for ol in f.outliers:
            P = ol.others
            outliers.append({"study": self.outcomes[ol.specimen].name, "joint": f.param_joint[ol.parameter],
                             "name": f.param_names[ol.parameter], "statistic": _num(ol.statistic),
                             "p_value": _num(ol.p_value), "p_adjusted": _num(ol.p_adjusted),
                             "others": {"center": _num(P.centre), "center_ci_low": _num(P.centre_ci[0]),
                                        "center_ci_high": _num(P.centre_ci[1]), "spread": _num(P.spread),
                                        "spread_ci_low": _num(P.spread_ci[0]),
                                        "spread_ci_high": _num(P.spread_ci[1])}})
        warnings = []
        for o in self.outcomes:
            if not o.fit.converged:
                warnings.append(f"{o.name}: the specimen's estimate did not converge; its likelihood is taken "
                                "about the last point")
        for p in params:
            for n in p["notes"]:
                warnings.append(f"{p['joint']}.{p['name']}: {n}")
        return {
            "parameters": params,
            "specimens": specimens,
            "specimens_differ": differ,
            "outliers": outliers,
            "outlier_test": {"alpha": f.alpha, "tests": f.n_outlier_tests,
                             "method": "leave-one-out: each specimen's likelihood against the population of the "
                                       "others (externally studentised residual, Student t with S - 2 degrees of "
                                       "freedom), Bonferroni over every specimen and parameter tested"},
            "confidence": f.confidence,
            "method": {
                "population": "log-normal per parameter: log k of each specimen ~ N(log center, tau^2), "
                              "spread = sqrt(exp(tau^2) - 1)",
                "specimen_likelihood": "each specimen's profile likelihood of log k from its condensed model "
                                       "(exact where the quadratic approximation fails the check)",
                "spread": "Paule-Mandel estimate and Q-profile interval of the deviance D(tau) ~ chi2(S - 1)",
                "center": "maximum marginal likelihood at the estimated spread, Hartung-Knapp interval "
                          "(Student t, Kish-effective degrees of freedom)",
                "specimens": "posterior median and equal-tailed interval of each specimen under the population, "
                             "flat priors on the centre and the spread"},
            "n_specimens": len(self.outcomes),
            "solver": self.solver_totals(),
            "executor": self.executor,
            "wall_s": {"total": self.wall_s, "specimens": self.specimen_wall_s,
                       "population": self.population_wall_s},
            "warnings": warnings,
        }

    def write(self, out: Path) -> list[str]:
        from blackbox.reports.population import population_markdown, population_plots

        out = Path(out)
        doc = self.to_json()
        (out / "population.json").write_text(json.dumps(doc, indent=2))
        plots = population_plots(self, out)
        (out / "report.md").write_text(population_markdown(self, doc, plots))
        return ["population.json", "report.md", *plots]


# --------------------------------------------------------------------------------------------
# the command
# --------------------------------------------------------------------------------------------
def _names(folders: Sequence[Path]) -> list[str]:
    from blackbox.commands.batch import _names as batch_names
    return batch_names(folders)


def run(studies: Sequence[str | Path], *, executor: Executor | None = None, adapter: str | None = None,
        cache: bool | str | Path | None = None, trust_command: bool | None = None, confidence: float | None = None,
        alpha: float = OUTLIER_ALPHA, say: Callable[[str], None] | None = None) -> PopulationResult:
    """Fit the population of the specimens ``studies`` (module docstring). ``confidence``: of
    every interval (default: the studies' ``[identification] confidence`` when they agree);
    ``alpha``: the outlier test's family-wise level. ``cache``, ``trust_command``: as
    :func:`blackbox.commands.batch.run`."""
    from blackbox.adapters import ADAPTER_CACHE, TRUST_COMMAND

    folders = [Path(s) for s in studies]
    if len(folders) < 2:
        raise PopulationError(f"a population needs at least 2 studies (specimens), got {len(folders)}")
    if confidence is not None and not 0.0 < confidence < 1.0:
        raise PopulationError(f"--confidence must be in (0, 1), got {confidence!r}")
    if not 0.0 < alpha < 1.0:
        raise PopulationError(f"--alpha must be in (0, 1), got {alpha!r}")
    say = say or (lambda msg: None)
    executor = executor or SerialExecutor()
    cache = ADAPTER_CACHE.get() if cache is None else cache
    trust = TRUST_COMMAND.get() if trust_command is None else bool(trust_command)
    names = _names(folders)
    tasks, unreadable = [], []
    for folder, name in zip(folders, names):
        try:
            pkg = pack_study(folder)
        except (OSError, ValueError, KeyError) as exc:
            unreadable.append(f"{folder}: {exc}")
            continue
        c = (str(Path(pkg.origin) / ".blackbox_cache") if cache is True
             else str(Path(cache).absolute()) if cache else None)
        tasks.append(SpecimenTask(name, pkg, adapter, c, trust))
    if unreadable:
        raise StudyError("cannot read " + "; ".join(unreadable))
    say(f"population: {len(tasks)} specimens on {executor.description}")
    t0 = time.perf_counter()
    results = executor.map(specimen_task, tasks, errors="return")
    t_spec = time.perf_counter() - t0
    outcomes: list[SpecimenOutcome] = []
    failed: dict[str, list[str]] = {}
    for task, res in zip(tasks, results):
        if isinstance(res, TaskFailure):
            res = SpecimenOutcome(task.name, task.package.origin, "error", str(res))
        outcomes.append(res)
        if res.status != "ok":
            failed.setdefault(res.status, []).append(f"{res.name} ({res.origin}): {res.message.strip()}")
    if failed:
        text = " | ".join(f"{status}: " + "; ".join(lines) for status, lines in failed.items())
        if "error" in failed:
            raise RuntimeError(text)
        if "bad_input" in failed:
            raise PopulationError(text)
        raise SolverError(text)
    first = outcomes[0]
    for o in outcomes[1:]:
        if (o.param_joint, o.param_names) != (first.param_joint, first.param_names):
            raise PopulationError(
                f"study {o.name!r} ({o.origin}) has the joint parameters "
                f"{[f'{j}.{n}' for j, n in zip(o.param_joint, o.param_names)]}, study {first.name!r} has "
                f"{[f'{j}.{n}' for j, n in zip(first.param_joint, first.param_names)]}: the specimens of one "
                "design must declare the same joints")
    if confidence is None:
        levels = sorted({o.confidence for o in outcomes})
        if len(levels) > 1:
            raise PopulationError(f"the studies' [identification] confidence differ ({levels}); give --confidence")
        confidence = levels[0]
    say(f"  population fit of {len(first.param_names)} parameter(s) from {len(outcomes)} specimens")
    t1 = time.perf_counter()
    fit = fit_population([o.fit for o in outcomes], first.param_joint, first.param_names, confidence=confidence,
                         alpha=alpha)
    t_pop = time.perf_counter() - t1
    return PopulationResult(tuple(outcomes), fit, executor.description, time.perf_counter() - t0, t_spec, t_pop)



# --------------------------------------------------------------------------------------------
# specimens simulated from a population (tests, benchmark, worked example)
# --------------------------------------------------------------------------------------------
def _toml_value(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v)


def simulate_specimens(study: str | Path, out: str | Path, n: int, centre, spread, *, seed: int = 1,
                   prefix: str = "specimen", noise: dict | None = None, measure: dict | None = None,
                   outliers: dict[int, dict[str, float]] | None = None) -> list[Path]:
    """``n`` specimen studies of one joint design, simulated from a log-normal population: copies
    of ``study`` in ``out/<prefix>_01`` ... whose measurements ``blackbox simulate`` makes (the
    study's noise model and measured DOFs from its ``truth.toml`` when it has one, else 5 % on
    the joints' DOFs; ``noise``/``measure`` override them) at joint parameters drawn per specimen
    and per parameter from ``log k ~ N(log centre, log(1 + spread^2))`` (``centre``/``spread``:
    one value or one per parameter of the study's declared model; seeded by ``seed``).
    ``outliers``: ``{specimen index: {"JOINT.name": factor}}`` multiplies those parameters of
    that specimen (a specimen that does not belong). ``out/population_truth.json`` records the population and
    every specimen's truth. Returns the folders."""
    from blackbox.commands import simulate
    from blackbox.declared import declared_model
    from blackbox.study import load_study

    study = Path(study)
    st = load_study(study)
    dm = declared_model(st)
    labels = dm.param_labels
    p = len(labels)
    centre = np.broadcast_to(np.asarray(centre, float), (p,))
    spread = np.broadcast_to(np.asarray(spread, float), (p,))
    tau = np.sqrt(np.log1p(spread ** 2))
    rng = np.random.default_rng(seed)
    base = {}
    if (study / "truth.toml").is_file():
        base = tomllib.loads((study / "truth.toml").read_text())
    noise = noise if noise is not None else base.get("noise", {"relative": 0.05})
    measure = measure if measure is not None else base.get("measure", {"joint": True})
    out = Path(out)
    taken = [out / f"{prefix}_{s + 1:02d}" for s in range(n) if (out / f"{prefix}_{s + 1:02d}").exists()]
    if taken:
        raise PopulationError(f"{taken[0]} exists already: give a new folder (nothing is overwritten)")
    out.mkdir(parents=True, exist_ok=True)
    folders, record = [], []
    for s in range(n):
        k = np.exp(np.log(centre) + tau * rng.standard_normal(p))
        for label, factor in (outliers or {}).get(s, {}).items():
            key = tuple(label.split(".", 1))
            if key not in labels:
                raise PopulationError(f"outliers: {label!r} is not a parameter of the study ({labels})")
            k[labels.index(key)] *= factor
        lines = [f"seed = {seed * 1000 + s}", ""]
        for jname in dict.fromkeys(j for j, _ in labels):
            vals = {name: float(v) for (j, name), v in zip(labels, k) if j == jname}
            lines += ["[[joints]]", f'name = "{jname}"', 'model = "simple"',
                      "values = {" + ", ".join(f"{a} = {b!r}" for a, b in vals.items()) + "}", ""]
        lines += ["[noise]"] + [f"{a} = {_toml_value(b)}" for a, b in noise.items()] + [""]
        lines += ["[measure]"] + [f"{a} = {_toml_value(b)}" for a, b in measure.items()] + [""]
        folder = out / f"{prefix}_{s + 1:02d}"
        truth = out / f".{prefix}_{s + 1:02d}.truth.toml"
        truth.write_text("\n".join(lines))
        res = simulate.run(st, truth)
        folder.mkdir()
        res.write(folder)
        truth.unlink()
        folders.append(folder)
        record.append({"study": folder.name, "parameters": [{"joint": j, "name": nm, "value": float(v)}
                                                            for (j, nm), v in zip(labels, k)]})
    (out / "population_truth.json").write_text(json.dumps(
        {"source": str(study), "seed": seed, "parameters": [
            {"joint": j, "name": nm, "center": float(c), "spread": float(sp)}
            for (j, nm), c, sp in zip(labels, centre, spread)], "specimens": record}, indent=2))
    return folders
