"""``blackbox identify STUDY``: condense once, then estimate the joint parameters (Chapter 4).

:func:`run` returns an :class:`IdentifyResult`; its :meth:`~IdentifyResult.write` puts
``result.json``, ``report.md`` and the plots into a folder.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from blackbox.commands.common import as_study, study_adapter
from blackbox.condensation import CondensedModel
from blackbox.declared import DeclaredModel, SolverCost, declared_model, truth_values
from blackbox.errors import StudyError
from blackbox.fitting.statistics import chi2_band
from blackbox import identification
from blackbox.identification import IdentificationResult, Observations
from blackbox.identification.fit_sigma import FitSigma, identify_with_fit_sigma, predict_rows
from blackbox.noise import NoiseModel
from blackbox.study import Study, select_cases
from solver_adapters.protocol import SolverAdapter

__all__ = ["IdentifyResult", "run"]


@dataclass(frozen=True, eq=False)
class IdentifyResult:
    """Everything one identification produced. ``fit_obs`` holds the rows fitted (the selected
    cases minus the hold-out), ``all_obs`` every measured row with the sigma used;
    ``fit_sigma``: the fit's own estimate of the sigma nobody gave (else None)."""
    study: Study
    declared: DeclaredModel
    model: CondensedModel
    fit_obs: Observations
    holdout_obs: Observations | None
    result: IdentificationResult
    solver: SolverCost
    command: str = "identify"
    all_obs: Observations | None = None
    selected: tuple[str, ...] = ()
    patterns: tuple[str, ...] = ()
    fit_sigma: FitSigma | None = None
    scaled: IdentificationResult | None = None
    """When the chi-square test fails with a given or declared sigma: the same fit with the
    covariance scaled by the reduced chi-square and Student's t (sigma scaled to the residuals),
    the intervals an experimentalist would quote if the misfit were noise."""

    @property
    def joints(self):
        return list(self.declared.joints)

    @property
    def ok(self) -> bool:
        """Converged with every parameter identifiable."""
        return bool(self.result.converged) and bool(self.result.identifiable.all())

    @property
    def noise(self) -> NoiseModel | None:
        return self.study.measurements.noise if self.study.measurements is not None else None

    @functools.cached_property
    def prediction(self) -> np.ndarray | None:
        """The identified model's prediction of every measured row (``all_obs``)."""
        if self.all_obs is None:
            return None
        return predict_rows(self.model, self.all_obs, self.result.k)

    @property
    def excluded(self) -> tuple[str, ...]:
        """Measured cases outside the case selection (predicted, never fitted)."""
        if not self.patterns or self.all_obs is None:
            return ()
        chosen = set(self.selected)
        return tuple(c for c in dict.fromkeys(self.all_obs.case_labels[i] for i in self.all_obs.case_index)
                     if c not in chosen)

    def sigma_json(self) -> dict:
        """``result.json`` ``sigma``: where the measurement errors came from."""
        noise = self.noise
        out = {"source": "given" if noise is None or not noise.estimated else "estimated",
               "chi2_test": self.fit_sigma is None}
        if noise is not None:
            out.update(noise.to_json())
        if self.scaled is not None:
            sc = self.scaled
            out["scaled_to_residuals"] = {
                "ratio": math.sqrt(sc.covariance_scale),
                "note": "the chi-square test failed: intervals with sigma scaled by sqrt(reduced chi-square) "
                        "and Student's t, as if the misfit were noise",
                "parameters": [{"joint": j, "name": n, "ci_low": _num(lo), "ci_high": _num(hi)}
                               for j, n, lo, hi in zip(sc.param_joint, sc.param_names, sc.ci_low, sc.ci_high)]}
        if self.fit_sigma is not None:
            out["fit"] = self.fit_sigma.to_json()
            out["note"] = ("sigma of rows nobody gave it was estimated from this fit's residuals: the reduced "
                           "chi-square is 1 by construction, the chi-square test of the model is off, the "
                           "intervals use Student's t")
        return out

    def selection_json(self) -> dict:
        ex = self.excluded
        out = {"patterns": list(self.patterns), "fitted_cases": len(set(self.selected) - set(self.declared.holdout)),
               "excluded_cases": len(ex), "excluded_rms_error": None}
        if ex and self.prediction is not None:
            o = self.all_obs
            m = np.isin(np.array([o.case_labels[i] for i in o.case_index]), ex)
            out["excluded_rms_error"] = float(np.sqrt(np.mean((o.values[m] - self.prediction[m]) ** 2)))
        return out

    def to_json(self) -> dict:
        doc = self.result.to_json_dict(self.solver.to_json())
        doc["sigma"] = self.sigma_json()
        doc["selection"] = self.selection_json()
        added = self.model.c.added_springs
        if added:
            doc["reference_springs"] = {"note": "added to the solver's deck across joints that are the structure's "
                                                "only support, accounted for exactly (K_deck)",
                                        "springs": [{"a": list(s.a), "b": list(s.b) if s.b is not None else None,
                                                     "k": s.k} for s in added]}
        held = {j.name: ["k" + p + str(i) + str(k) for p, i, k in getattr(j, "constrained_springs", ())]
                for j in self.declared.joints if getattr(j, "constrained_springs", ())}
        if held:
            doc["constrained_springs"] = held
        return doc

    def write(self, out: Path) -> list[str]:
        from blackbox.reports.identify import fit_report, identification_plots
        from blackbox.reports.response import measured_data_plots, measured_data_report

        out = Path(out)
        r = self.result
        (out / "result.json").write_text(json.dumps(self.to_json(), indent=2))
        truth = truth_values(self.study)
        plots = identification_plots(r, self.fit_obs, out, truth=truth)
        text = fit_report(r, title=f"Identification of {self.study.name}", solver=self.solver.to_json(), truth=truth)
        if self.all_obs is not None:
            plots += measured_data_plots(self, out)
            text += measured_data_report(self)
        if plots:
            text += "\n" + "\n\n".join(f"![{Path(p).stem}]({p})" for p in plots) + "\n"
        else:
            text += "\nNo plots: matplotlib is not installed (`pip install 'blackbox-joints[plots]'`).\n"
        (out / "report.md").write_text(text)
        return ["result.json", "report.md", *plots]


def run(study: Study | str | Path, *, adapter: str | SolverAdapter | None = None, model: str | None = None,
        progress: Callable | None = None, stages: Callable[[str], None] | None = None,
        executor=None, cases: Sequence[str] | None = None, **options) -> IdentifyResult:
    """Identify the study's joints: one batched solver run, then the estimation in the condensed
    space. ``model`` overrides every joint's declared model; ``cases`` (labels or glob patterns)
    the study's ``[identification] cases``: the cases fitted, the others only predicted;
    ``options`` override the study's ``[identification]`` options (``fixed_point``,
    ``max_iterations``, ``confidence``, ``bootstrap``, ``profile``, and the estimator's own
    keywords). ``progress(record)`` hears of every iteration, ``stages(message)`` of the long
    stages after it (profiles, bootstrap). ``executor`` (:class:`blackbox.parallel.Executor`,
    ``--workers``/``--scheduler``): where the bootstrap refits of ``[identification] bootstrap =
    N`` run (the same samples as serially).

    A measurement row without sigma gets one from its repeated readings or the declared
    accuracy (:mod:`blackbox.noise`, when the study was read), else from this fit
    (:func:`blackbox.identification.fit_sigma.identify_with_fit_sigma`)."""
    study = as_study(study, need_measurements=True)
    if not study.config.joints:
        raise StudyError("study.toml declares no [[joints]] to identify", file=str(study.root / "study.toml"))
    declared = declared_model(study, model)
    patterns = tuple(study.config.identification.cases if cases is None else cases)
    m = study.measurements
    selected = select_cases(m.cases, patterns, where="--cases" if cases is not None else
                            str(study.root / "study.toml"))
    ad = study_adapter(study, adapter)
    before = SolverCost.of(ad)
    cm = declared.condense(ad)
    all_obs = Observations.from_measurements(m, cm.c.cases, provisional_sigma=True)
    labels = np.array([all_obs.case_labels[i] for i in all_obs.case_index])
    in_sel = np.isin(labels, selected)
    held = in_sel & np.isin(labels, list(declared.holdout))
    fitted = in_sel & ~held
    if not fitted.any():
        raise StudyError(f"no measured case left to fit: the selection {list(patterns)} has "
                         f"{len(selected)} case(s), all held out", file=str(study.root / "study.toml"))
    fit_obs = all_obs.subset(fitted)
    hold = all_obs.subset(held) if held.any() else None
    fit_rows = m.fit_rows
    noise = m.noise
    kwargs = declared.options.kwargs(**options)
    fs = None
    if fit_rows[fitted].any():
        other = noise.effective_dof(fitted & ~fit_rows) if noise is not None else math.inf
        result, fs, fit_obs, hold = identify_with_fit_sigma(
            cm, fit_obs, declared.k0, fit_rows[fitted], holdout=hold, holdout_fit_rows=fit_rows[held],
            other_dof=other, callback=progress, progress=stages, executor=executor, **kwargs)
        sig = np.array(all_obs.sigma, float)
        kinds = np.array(["rotation" if c >= 4 else "translation" for _, c in all_obs.dofs])
        for kind, s in zip(fs.kinds, fs.sigma):
            sig[fit_rows & (kinds == kind)] = s
        all_obs = all_obs.with_sigma(sig)
    else:
        if hold is not None and fit_rows[held].any():
            raise StudyError("hold-out rows have no sigma and no fitted row estimates one: give sigma or a "
                             "declared accuracy", file=str(study.root / "measurements.csv"))
        dof = noise.effective_dof(fitted) if noise is not None else None
        result = identification.identify(cm, fit_obs, declared.k0, holdout=hold, callback=progress,
                                         progress=stages, executor=executor, sigma_dof=dof, **kwargs)
    scaled = None
    n_dof = result.n_obs - result.n_params
    if fs is None and n_dof > 0 and result.reduced_chi2 > chi2_band(n_dof, 0.99)[1] \
            and not kwargs.get("scale_covariance"):
        scaled = identification.identify(cm, fit_obs, result.k, holdout=hold, scale_covariance=True,
                                         **{**kwargs, "bootstrap": 0})
    return IdentifyResult(study, declared, cm, fit_obs, hold, result, SolverCost.of_batch(cm.c, ad, before),
                          all_obs=all_obs, selected=selected, patterns=patterns, fit_sigma=fs, scaled=scaled)


def _num(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None
