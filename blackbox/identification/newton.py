"""The Gauss-Newton phase of the identification (Sec. 4.3.2, eq. 30-32).

The safeguarded Levenberg-Marquardt iteration of :func:`blackbox.fitting.lm.levenberg_marquardt`
on :class:`~blackbox.identification.problem._Problem`: ``phi`` coordinates (log k for springs,
logm K_C for complex joints), the springs' floor as an active set, geodesic acceleration,
backtracking, Marquardt damping; ``chi2`` never increases. The accepted steps become the
``"newton"`` records of the identification's history.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from blackbox.fitting.lm import levenberg_marquardt
from blackbox.identification.problem import _Problem
from blackbox.identification.result import IterationRecord


@dataclass
class _Fit:
    phi: np.ndarray
    k: np.ndarray
    f: np.ndarray
    chi2: float
    status: int
    iterations: int


def _newton(prob: _Problem, phi0: np.ndarray, *, y: np.ndarray | None = None, free: np.ndarray | None = None,
            max_iterations: int, xtol: float, ftol: float, first_iteration: int = 1,
            history: list | None = None, callback: Callable | None = None) -> _Fit:
    """Damped Gauss-Newton (eq. 30-32) in ``phi`` over the ``free`` parameters, from ``phi0``
    (``y``: other data, e.g. a bootstrap replicate). With ``history`` every accepted step is
    appended as an :class:`IterationRecord` and passed to ``callback`` (a true return stops,
    status 5)."""
    def on_step(rec) -> bool:
        r = IterationRecord(rec.iteration, "newton", rec.k, rec.chi2, rec.damping)
        history.append(r)
        return bool(callback is not None and callback(r))

    res = levenberg_marquardt(prob, phi0, y=y, free=free, max_iterations=max_iterations, xtol=xtol, ftol=ftol,
                              callback=on_step if history is not None else None, first_iteration=first_iteration)
    return _Fit(res.x, res.k, res.f, res.chi2, res.status, res.iterations)
