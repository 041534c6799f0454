"""``blackbox identify STUDY``: condense once, then estimate the joint parameters (Chapter 4).

:func:`run` returns an :class:`IdentifyResult`; its :meth:`~IdentifyResult.write` puts
``result.json``, ``report.md`` and the plots into a folder.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from blackbox.commands.common import as_study, study_adapter
from blackbox.condensation import CondensedModel
from blackbox.declared import DeclaredModel, SolverCost, declared_model, truth_values
from blackbox.errors import StudyError
from blackbox import identification
from blackbox.identification import IdentificationResult, Observations
from blackbox.study import Study
from solver_adapters.protocol import SolverAdapter

__all__ = ["IdentifyResult", "run"]


@dataclass(frozen=True, eq=False)
class IdentifyResult:
    """Everything one identification produced."""
    study: Study
    declared: DeclaredModel
    model: CondensedModel
    fit_obs: Observations
    holdout_obs: Observations | None
    result: IdentificationResult
    solver: SolverCost
    command: str = "identify"

    @property
    def joints(self):
        return list(self.declared.joints)

    @property
    def ok(self) -> bool:
        """Converged with every parameter identifiable."""
        return bool(self.result.converged) and bool(self.result.identifiable.all())

    def to_json(self) -> dict:
        return self.result.to_json_dict(self.solver.to_json())

    def write(self, out: Path) -> list[str]:
        from blackbox.reports.identify import fit_report, identification_plots

        out = Path(out)
        r = self.result
        (out / "result.json").write_text(json.dumps(self.to_json(), indent=2))
        truth = truth_values(self.study)
        plots = identification_plots(r, self.fit_obs, out, truth=truth)
        text = fit_report(r, title=f"Identification of {self.study.name}", solver=self.solver.to_json(), truth=truth)
        if plots:
            text += "\n" + "\n\n".join(f"![{Path(p).stem}]({p})" for p in plots) + "\n"
        else:
            text += "\nNo plots: matplotlib is not installed (`pip install 'blackbox-joints[plots]'`).\n"
        (out / "report.md").write_text(text)
        return ["result.json", "report.md", *plots]


def run(study: Study | str | Path, *, adapter: str | SolverAdapter | None = None, model: str | None = None,
        progress: Callable | None = None, stages: Callable[[str], None] | None = None,
        executor=None, **options) -> IdentifyResult:
    """Identify the study's joints: one batched solver run, then the estimation in the condensed
    space. ``model`` overrides every joint's declared model; ``options`` override the study's
    ``[identification]`` options (``fixed_point``, ``max_iterations``, ``confidence``,
    ``bootstrap``, ``profile``, and the estimator's own keywords). ``progress(record)`` hears of
    every iteration, ``stages(message)`` of the long stages after it (profiles, bootstrap).
    ``executor`` (:class:`blackbox.parallel.Executor`, ``--workers``/``--scheduler``): where the
    bootstrap refits of ``[identification] bootstrap = N`` run (the same samples as serially)."""
    study = as_study(study, need_measurements=True)
    if not study.config.joints:
        raise StudyError("study.toml declares no [[joints]] to identify", file=str(study.root / "study.toml"))
    declared = declared_model(study, model)
    ad = study_adapter(study, adapter)
    before = SolverCost.of(ad)
    cm = declared.condense(ad)
    fit_obs, hold = declared.observations(cm.c.cases)
    result = identification.identify(cm, fit_obs, declared.k0, holdout=hold, callback=progress,
                                     progress=stages, executor=executor, **declared.options.kwargs(**options))
    return IdentifyResult(study, declared, cm, fit_obs, hold, result, SolverCost.of_batch(cm.c, ad, before))
