"""``blackbox bench``: the analogue of Table 3.3, measured in one run on this machine.

Each method drives the *same* identification (the Levenberg-Marquardt core of
:mod:`blackbox.fitting.lm` in the coordinates of ``blackbox identify``, the same start, the same
measurements, the same stopping rule) to convergence; only the way predictions
and sensitivities are obtained differs:

* ``blackbox``  -- black-box condensation (one batched adapter run, n_B + L right-hand sides)
  and analytic derivatives in the condensed space (eq. 18): no further solver run;
* ``standard``  -- standard condensation from the reference solver's assembled matrices
  (eq. 13-14, one factorization of K_II) and the same analytic derivatives; only for adapters
  that expose their matrices (the reference solver);
* ``forward``   -- no condensation: the joint put into the full model as springs, the whole
  structure re-solved for the prediction and once more per parameter (eq. 6);
* ``central``   -- the same with central differences (eq. 7): 2 runs per parameter.

Wall time covers everything from building the adapter to convergence, so that assembly and
factorization are counted where they happen (the in-process solver reuses the deck parsed when
the study was loaded; an external code reads its deck in every run, which is counted).
"""

from __future__ import annotations

import json
import platform
import time
from dataclasses import dataclass
import os
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from blackbox import sensitivity as S
from blackbox.fitting.lm import LMResult, levenberg_marquardt
from blackbox.identification.problem import JointCoordinates
from blackbox.joints import JointModel
from blackbox.standard import standard_condense
from blackbox.study import Study, load_study
from blackbox.adapters import make_adapter_for
from blackbox.parallel import Executor, SerialExecutor, pack_study, scratch, unpack_study
from blackbox.declared import declared_model

CASES = {"cube-simple": "cube", "cube-complex": "cube_complex", "car-simple": "car",
         "car-complex": "car_complex"}
METHODS = ("blackbox", "standard", "forward", "central")


class _BenchProblem:
    """The weighted least-squares problem of one method for :func:`blackbox.fitting.lm.levenberg_marquardt`:
    the method's ``predict(k)`` and ``jacobian(k, f)``, the measurements with their sigma, and the
    identification's coordinates (log k for springs, logm K_C for complex joints), so that every
    method drives the same estimator. Without the springs' floor of ``blackbox identify``: the
    full-model methods put the springs into the deck, and a spring at the floor (1e-6 of the
    joint's stiffest) makes that structure a mechanism to the solver's check; in log k a spring
    the data want at 0 only gets small."""

    def __init__(self, predict: Callable[[np.ndarray], np.ndarray],
                 jacobian: Callable[[np.ndarray, np.ndarray], np.ndarray],
                 y: np.ndarray, sigma: np.ndarray, joints: list[JointModel]):
        self._predict, self._jacobian = predict, jacobian
        self.y = np.asarray(y, dtype=float)
        self.weights = 1.0 / np.asarray(sigma, dtype=float)
        self.coordinates = JointCoordinates(joints)
        self.bounds = None
        self.n_params = self.coordinates.p
        self._slices = [(j, sl) for j, sl in zip(joints, _slices(joints))]

    def admissible(self, k: np.ndarray) -> bool:
        if not np.all(np.isfinite(k)) or np.max(np.abs(k)) > 1e150:
            return False
        return all(j.is_admissible(k[sl], strict=True) for j, sl in self._slices)

    def predict(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        try:
            f = self._predict(k)
        except np.linalg.LinAlgError:                  # singular: reported as non-finite
            f = np.full(self.y.shape, np.nan)
        return f, f

    def jacobian(self, k: np.ndarray, f: np.ndarray) -> np.ndarray:
        return self._jacobian(k, f)


def _slices(joints: list[JointModel]) -> list[slice]:
    out, start = [], 0
    for j in joints:
        out.append(slice(start, start + j.n_params))
        start += j.n_params
    return out


def fit(predict: Callable[[np.ndarray], np.ndarray], jacobian: Callable[[np.ndarray, np.ndarray], np.ndarray],
        y: np.ndarray, sigma: np.ndarray, k0: np.ndarray, joints: list[JointModel],
        max_iterations: int = 40, xtol: float = 1e-6, ftol: float = 1e-9) -> LMResult:
    """Weighted least squares from ``k0`` by the core of :mod:`blackbox.fitting.lm`, one Jacobian
    per iteration (see :class:`_BenchProblem`)."""
    prob = _BenchProblem(predict, jacobian, y, sigma, joints)
    return levenberg_marquardt(prob, prob.coordinates.to_coords(np.asarray(k0, dtype=float)),
                               max_iterations=max_iterations, xtol=xtol, ftol=ftol)


class _Rows:
    """Gathers measured rows (absolute or relative to a reference DOF) from a response array
    ``(n_dofs, L)`` (or ``(p, n_dofs, L)``) over the label list ``dofs``: precomputed indices."""

    def __init__(self, study: Study, dofs: list[tuple[int, int]]):
        m = study.measurements
        idx = {d: i for i, d in enumerate(dofs)}
        cases = study.loads.cases
        self.ci = np.array([cases.index(c) for c in m.cases])
        self.row = np.array([idx[d] for d in m.dofs])
        refs = m.refs or (None,) * len(m)
        self.has_ref = np.array([r is not None for r in refs])
        self.ref = np.array([idx[r] if r is not None else 0 for r in refs])

    def __call__(self, U: np.ndarray) -> np.ndarray:
        out = U[..., self.row, self.ci]
        if self.has_ref.any():
            out = out - np.where(self.has_ref, U[..., self.ref, self.ci], 0.0)
        return out


def run_method(study: Study, method: str, adapter_name: str) -> dict:
    """One row of the benchmark: wall time, solver runs, right-hand sides, iterations."""
    t0 = time.perf_counter()
    adapter = make_adapter_for(study, adapter_name, cache=False)
    declared = declared_model(study)
    joints = list(declared.joints)
    m = study.measurements
    observed = m.all_dofs
    k0 = declared.k0
    runs0, rhs0 = adapter.stats.runs, adapter.stats.right_hand_sides
    extra = {}
    if method in ("blackbox", "standard"):
        if method == "blackbox":
            cm = declared.condense(adapter, observed)
        else:
            if not hasattr(adapter, "stiffness"):
                return {"skipped": f"adapter {adapter.name!r} exposes no assembled matrices"}
            boundary = list(dict.fromkeys([d for j in joints for d in j.dofs] + list(observed)))
            c = standard_condense(adapter, study.loads, boundary)
            cm = declared.condensed_model(c)
            extra = {"factorizations": 1, "standard_rhs": c.right_hand_sides}
        gather = _Rows(study, list(cm.c.boundary) + list(cm.c.observed))

        def predict(k):
            r = cm.response(k)
            return gather(np.vstack([r.U_B, r.U_O]))

        def jacobian(k, f):
            dB, dO = cm.sensitivities(k)
            return gather(np.concatenate([dB, dO], axis=1)).T
    else:
        if declared.rigid_pairs():
            return {"skipped": "rigid branch pairs are a penalty in the condensed space; the "
                               "full-model methods have no such tie"}
        deck_joints = [(j, np.full(j.n_params, ks)) for j, ks in
                       zip(declared_model(study, "simple").joints, declared.deck_stiffness) if ks]
        rel_step = 1e-3 if adapter.name == "mystran" else 1e-6   # MYSTRAN prints 7 digits
        gather = _Rows(study, observed)

        def predict(k):
            return gather(S.full_response(adapter, joints, k, study.loads, observed, deck_joints))

        sizes = np.concatenate([np.full(j.n_params, i) for i, j in enumerate(joints)])

        def jacobian(k, f):
            # step relative to the joint's largest parameter: a small off-diagonal K_C entry
            # perturbed relative to itself would change the response below round-off
            scale = np.array([np.max(np.abs(k[sizes == sizes[p]])) for p in range(len(k))])
            cols = []
            for p in range(len(k)):
                h = rel_step * max(scale[p], 1e-300)
                kp = k.copy()
                kp[p] += h
                if method == "forward":
                    cols.append((predict(kp) - f) / h)
                else:
                    km = k.copy()
                    km[p] -= h
                    cols.append((predict(kp) - predict(km)) / (2 * h))
            return np.stack(cols, axis=1)
    gn = fit(predict, jacobian, m.values, m.sigma, k0, joints)
    wall = time.perf_counter() - t0
    runs = adapter.stats.runs - runs0
    rhs = adapter.stats.right_hand_sides - rhs0
    if method == "standard":
        runs, rhs = 0, extra["standard_rhs"]
    return {"wall_s": wall, "solver_runs": runs, "right_hand_sides": rhs, "iterations": gn.iterations,
            "converged": gn.converged, "chi2": gn.chi2, "k": gn.k.tolist(), **extra}


def run_bench(fixtures: Path, adapters: list[str], cases: list[str], repeat: int = 1,
              progress=print) -> list[dict]:
    rows = []
    for case in cases:
        study = load_study(fixtures / CASES[case], need_measurements=True)
        for adapter in adapters:
            results = {}
            for method in METHODS:
                best = None
                # best of `repeat` for in-process adapters; an external code's run times are long
                # enough that one measurement is representative (and repeating would be slow)
                for _ in range(repeat if adapter == "reference" else 1):
                    res = run_method(study, method, adapter)
                    if "skipped" in res:
                        best = res
                        break
                    if best is None or res["wall_s"] < best["wall_s"]:
                        best = res
                results[method] = best
                if "skipped" not in best:
                    progress(f"  {case:13s} {adapter:9s} {method:9s} {best['wall_s']:8.3f} s  "
                             f"runs {best['solver_runs']:4d}  rhs {best['right_hand_sides']:5d}  "
                             f"iterations {best['iterations']}")
            base = results["blackbox"]
            for method, res in results.items():
                if "skipped" in res:
                    continue
                # same estimate: every parameter within 1e-3 of the largest of the fit (the
                # complex model's small off-diagonal entries are judged on the joint's scale)
                kr, kb = np.asarray(res["k"]), np.asarray(base["k"])
                same = bool(np.max(np.abs(kr - kb)) <= 1e-3 * np.max(np.abs(kb)))
                rows.append({"case": case, "method": method, "adapter": adapter, "wall_s": res["wall_s"],
                             "solver_runs": res["solver_runs"], "right_hand_sides": res["right_hand_sides"],
                             "iterations": res["iterations"], "converged": res["converged"],
                             "same_estimate_as_blackbox": bool(same),
                             "chi2_to_blackbox": res["chi2"] / base["chi2"],
                             "ratio_to_blackbox": res["wall_s"] / base["wall_s"]})
    return rows


@dataclass(frozen=True)
class BenchResult:
    """The benchmark's rows (``bench.json``) and how they were measured."""
    rows: list[dict]
    meta: dict
    command: str = "bench"

    def write(self, out: Path) -> list[str]:
        from blackbox.reports.bench import bench_markdown

        (Path(out) / "bench.json").write_text(json.dumps(self.rows, indent=2))
        (Path(out) / "bench.md").write_text(bench_markdown(self.rows, self.meta))
        return ["bench.json", "bench.md"]


def run(fixtures: Path, adapters: list[str], cases: list[str], repeat: int = 1, *, command: str = "blackbox bench",
        progress=print, executor=None) -> BenchResult:
    """Every method on every case and adapter; ``repeat``: best of that many timings (in-process).
    ``executor`` (:mod:`blackbox.parallel`) with several workers runs one task per case and adapter."""
    import os

    if repeat < 1:
        raise ValueError(f"repeat must be at least 1, got {repeat}")
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise ValueError(f"unknown bench case(s) {unknown}; known: {', '.join(CASES)}")
    if executor is not None and executor.workers > 1:      # one task per (case, adapter) on the cluster
        rows = bench_rows(Path(fixtures), adapters, cases, repeat, executor=executor)
    else:
        rows = run_bench(Path(fixtures), adapters, cases, repeat, progress=progress)
    meta = {"machine": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
            "date": time.strftime("%Y-%m-%d %H:%M:%S"), "repeat": repeat, "command": command}
    return BenchResult(rows, meta)


# --------------------------------------------------------------------------------------------
# blackbox bench: one task per (case, adapter)
# --------------------------------------------------------------------------------------------
def _bench_task(args) -> list[dict]:
    """The rows of one (case, adapter) of :func:`run_bench`, on a worker,
    from the case's fixture folder rebuilt there."""
    pkg, case, adapter, repeat = args
    with scratch("blackbox-bench-") as tmp:
        unpack_study(pkg, tmp)
        return run_bench(tmp, [adapter], [case], repeat, progress=lambda s: None)


def bench_rows(fixtures: str | os.PathLike, adapters: Sequence[str], cases: Sequence[str], repeat: int = 1, *,
               executor: Executor | None = None) -> list[dict]:
    """``blackbox bench``'s rows (:func:`run_bench`, same order) with
    one task per (case, adapter): every method of a case runs in the same task, one after the
    other, so its ``ratio_to_blackbox`` compares timings taken on the same worker. Tasks that
    run at the same time share the machine: on a loaded machine the absolute times grow (run
    serially, or one worker per core, for the published table)."""
    executor = executor or SerialExecutor()
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise ValueError(f"unknown bench case(s) {unknown}; known: {', '.join(CASES)}")
    packs = {c: pack_study(Path(fixtures) / CASES[c]) for c in cases}
    tasks = [(packs[c], c, a, int(repeat)) for c in cases for a in adapters]
    return [row for part in executor.map(_bench_task, tasks) for row in part]
