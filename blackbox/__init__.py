"""Identify the stiffness of flexible joints in frame structures from measured static
displacements, using any finite-element code as a black box.

The public API, one function per command (each returns a typed result whose ``write(folder)``
writes the command's files)::

    >>> import blackbox
    >>> study = blackbox.load_study("fixtures/cube")
    >>> res = blackbox.identify(study, profile=False)
    >>> res.solver.runs, res.result.converged
    (1, True)

:func:`load_study`, :func:`identify`, :func:`compare`, :func:`diagnose`, :func:`simulate`,
:func:`design`; the method itself is in the modules named in the README's map of the
dissertation.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from blackbox.errors import BlackboxError, StudyError
from blackbox.study import Study, load_study

if TYPE_CHECKING:
    from blackbox.commands.compare import CompareResult
    from blackbox.commands.design import DesignResult
    from blackbox.commands.diagnose import DiagnosisResult
    from blackbox.commands.identify import IdentifyResult
    from blackbox.commands.simulate import SimulateResult

__all__ = ["Study", "load_study", "identify", "compare", "diagnose", "simulate", "design",
           "BlackboxError", "StudyError"]


def identify(study: Study | str | Path, **options) -> "IdentifyResult":
    """Identify the study's joints (``blackbox identify``): one batched solver run, then the
    estimate with its intervals. Options: ``adapter``, ``model``, and the study's
    ``[identification]`` options (``profile``, ``bootstrap``, ``confidence``, ...)."""
    from blackbox.commands.identify import run
    return run(study, **options)


def compare(study: Study | str | Path, **options) -> "CompareResult":
    """Simple against complex joint model and their MDSE loading (``blackbox compare``, Ch. 6)."""
    from blackbox.commands.compare import run
    return run(study, **options)


def diagnose(study: Study | str | Path, **options) -> "DiagnosisResult":
    """What the declared model lacks (``blackbox diagnose``): effects added, verdict, hotspots."""
    from blackbox.commands.diagnose import run
    return run(study, **options)


def simulate(study: Study | str | Path, truth: str | Path, **options) -> "SimulateResult":
    """Measurements simulated from a truth file (``blackbox simulate``, Sec. 5.2)."""
    from blackbox.commands.simulate import run
    return run(study, truth, **options)


def design(study: Study | str | Path, candidates: str | Path, **options) -> "DesignResult":
    """Choose load cases and sensors before the test (``blackbox design``)."""
    from blackbox.commands.design import run
    return run(study, candidates, **options)
