"""What an identification returns: :class:`IdentificationResult` (the estimate, its
uncertainty, the fit statistics of :class:`blackbox.fitting.statistics.FitStatistics`, the
hold-out prediction of :class:`~blackbox.fitting.statistics.HoldoutStats`) and the iteration
history of :class:`IterationRecord`. Reports are written elsewhere (``blackbox.reports.identify``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from blackbox.fitting.statistics import FitStatistics, HoldoutStats

__all__ = ["IterationRecord", "HoldoutStats", "IdentificationResult"]


@dataclass(frozen=True, eq=False)
class IterationRecord:
    """One accepted iterate: ``phase`` is ``"start"``, ``"fixed-point"``, ``"newton"`` or
    ``"restart"`` (a Newton phase again from springs that ended trapped at 0 or rigid, kept
    because it ends lower)."""
    iteration: int
    phase: str
    k: np.ndarray
    objective: float            # chi2 at k
    damping: float = 0.0        # Levenberg-Marquardt lambda of the accepted step



@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """The estimate, its uncertainty and the fit statistics (scipy ``OptimizeResult`` /
    lmfit ``MinimizerResult`` in spirit; a report is written elsewhere)."""
    k: np.ndarray
    param_names: tuple[str, ...]
    param_joint: tuple[str, ...]
    std: np.ndarray                     # inf for a parameter that is not identifiable
    ci_low: np.ndarray                  # at `confidence` by `ci_method`; nan if not identifiable
    ci_high: np.ndarray
    confidence: float
    ci_method: str
    linear_ci: np.ndarray               # (n_params, 2) linearised (log-space for springs)
    identifiable: np.ndarray            # bool per parameter
    rank: int
    covariance: np.ndarray              # natural parameters; nan rows/cols if not identifiable
    correlation: np.ndarray
    covariance_scale: float             # 1, or max(1, reduced_chi2) with scale_covariance
    converged: bool
    status: int
    message: str
    iterations: int
    n_fixed_point: int
    n_newton: int
    history: tuple[IterationRecord, ...]
    n_obs: int
    n_params: int
    chi2: float
    reduced_chi2: float
    rms_residual: float
    aic: float
    bic: float
    residuals: np.ndarray               # standardized, per observation row
    predicted: np.ndarray
    holdout: HoldoutStats | None
    profile_ci: np.ndarray | None       # (n_params, 2)
    bootstrap_ci: np.ndarray | None     # (n_params, 2)
    bootstrap_samples: np.ndarray | None
    warnings: tuple[str, ...]

    @property
    def success(self) -> bool:
        return self.converged

    @property
    def statistics(self) -> FitStatistics:
        """The fit statistics as one object (the same numbers as the fields)."""
        return FitStatistics(self.n_obs, self.n_params, self.chi2, self.reduced_chi2, self.rms_residual,
                             self.aic, self.bic)

    def to_json_dict(self, solver_info: dict) -> dict:
        """The content of ``result.json`` (non-finite numbers become ``null``)."""
        params = []
        for i in range(self.n_params):
            p = {"joint": self.param_joint[i], "name": self.param_names[i], "value": _num(self.k[i]),
                 "std": _num(self.std[i]), "ci_low": _num(self.ci_low[i]),
                 "ci_high": _num(self.ci_high[i]), "identifiable": bool(self.identifiable[i])}
            p["linear_ci"] = [_num(v) for v in self.linear_ci[i]]
            if self.profile_ci is not None:
                p["profile_ci"] = [_num(v) for v in self.profile_ci[i]]
            if self.bootstrap_ci is not None:
                p["bootstrap_ci"] = [_num(v) for v in self.bootstrap_ci[i]]
            params.append(p)
        h = self.holdout
        return {
            "converged": bool(self.converged),
            "iterations": int(self.iterations),
            "parameters": params,
            "fit": {"n_obs": self.n_obs, "n_params": self.n_params, "chi2": _num(self.chi2),
                    "reduced_chi2": _num(self.reduced_chi2), "rms_residual": _num(self.rms_residual),
                    "aic": _num(self.aic), "bic": _num(self.bic)},
            "holdout": {"cases": list(h.cases) if h else [], "rms_error": _num(h.rms_error) if h else None,
                        "chi2": _num(h.chi2) if h else None, "n_obs": h.n_obs if h else 0},
            "solver": dict(solver_info),
            "status": int(self.status),
            "message": self.message,
            "confidence": self.confidence,
            "ci_method": self.ci_method,
            "identifiable": [bool(v) for v in self.identifiable],
            "rank": int(self.rank),
            "covariance_scale": _num(self.covariance_scale),
            "correlation": [[_num(v) for v in row] for row in self.correlation],
            "iterations_by_phase": {"fixed-point": self.n_fixed_point, "newton": self.n_newton},
            "history": [{"iteration": r.iteration, "phase": r.phase, "objective": _num(r.objective),
                         "damping": _num(r.damping), "k": [_num(v) for v in r.k]} for r in self.history],
            "warnings": list(self.warnings),
        }


def _num(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None
