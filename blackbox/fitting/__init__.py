"""Weighted least squares: one Levenberg-Marquardt core (:mod:`blackbox.fitting.lm`) and one
statistics module (:mod:`blackbox.fitting.statistics`) for every estimator of the package (the
identification of Chapter 4, the benchmark's methods, the refits of the diagnosis)."""

from blackbox.fitting.lm import (STATUS_MESSAGES, BoxBounds, LMIteration, LMResult, LogCoordinates,
                                 NaturalCoordinates, bounded_gauss_newton_step, levenberg_marquardt,
                                 solve_damped)
from blackbox.fitting.statistics import (Covariance, FitStatistics, HoldoutStats, chi2_band, covariance,
                                         plausibility_warning)

__all__ = ["STATUS_MESSAGES", "BoxBounds", "LMIteration", "LMResult", "LogCoordinates", "NaturalCoordinates",
           "bounded_gauss_newton_step", "levenberg_marquardt", "solve_damped", "Covariance", "FitStatistics",
           "HoldoutStats", "chi2_band", "covariance", "plausibility_warning"]
