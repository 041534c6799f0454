"""Former wiring of ``blackbox diagnose``, now :mod:`blackbox.commands.diagnose` (the command),
:mod:`blackbox.diagnosis.decks` (the edited decks) and :mod:`blackbox.reports.diagnose` (report
and plots). Kept for old callers: :func:`run_diagnose` runs the command and writes its output
folder; :func:`prepare` writes the edited decks into ``out_dir/decks``."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

from blackbox.commands.diagnose import DiagnosisResult, Prepared, run
from blackbox.commands.diagnose import prepare as _prepare
from blackbox.commands.output import check_out, write_output
from blackbox.diagnosis.decks import SplitDeck, constrained_grids, element_deck, members_at, split_deck
from blackbox.diagnosis.document import diagnosis_document
from blackbox.reports.diagnose import diagnosis_plots, diagnosis_report

__all__ = ["run_diagnose", "prepare", "Prepared", "DiagnosisResult", "SplitDeck", "members_at",
           "constrained_grids", "element_deck", "split_deck", "diagnosis_document", "diagnosis_report",
           "diagnosis_plots"]


def run_diagnose(study_dir: Path, out_dir: Path, *, adapter_name: str | None = None, alpha: float = 0.01,
                 max_steps: int = 5, refit_top: int = 6, max_joint_candidates: int = 300,
                 effects: Sequence[str] | None = None, plots: bool = True,
                 progress: Callable[[str], None] | None = None) -> DiagnosisResult:
    """``blackbox diagnose STUDY --out DIR``: :func:`blackbox.commands.diagnose.run`, then its
    files written into ``out_dir`` (checked before the work)."""
    check_out(out_dir, "diagnose")
    result = run(study_dir, adapter=adapter_name, alpha=alpha, max_steps=max_steps, refit_top=refit_top,
                 max_joint_candidates=max_joint_candidates, effects=effects, plots=plots, progress=progress)
    write_output(out_dir, "diagnose", result.write)
    return result


def prepare(study_dir: Path, out_dir: Path, *, adapter_name: str | None = None, max_joint_candidates: int = 300,
            effects: Sequence[str] | None = None, say: Callable[[str], None] | None = None) -> Prepared:
    """:func:`blackbox.commands.diagnose.prepare` with the edited decks in ``out_dir/decks``."""
    decks = Path(out_dir) / "decks"
    decks.mkdir(parents=True, exist_ok=True)
    return _prepare(study_dir, decks, adapter=adapter_name, max_joint_candidates=max_joint_candidates,
                    effects=effects, say=say)
