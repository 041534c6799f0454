"""Statistical identification of joint parameters (Chapter 4, Sec. 4.2-4.4, eq. 19-32).

* :mod:`~blackbox.identification.observations` -- the measured rows (:class:`Observations`);
* :mod:`~blackbox.identification.problem` -- the problem in the condensed space (prediction,
  eq. 18 Jacobian) and its coordinates (log k, matrix log of ``K_C``, the springs' floor);
* :mod:`~blackbox.identification.fixed_point` -- the fixed-point start (eq. 22-29);
* :mod:`~blackbox.identification.newton` -- Gauss-Newton (eq. 30-32) on the core of
  :mod:`blackbox.fitting.lm`;
* :mod:`~blackbox.identification.uncertainty` -- covariance and identifiability, linearised and
  profile-likelihood intervals, parametric bootstrap (Sec. 4.4);
* :mod:`~blackbox.identification.fitting` -- :func:`identify`, which runs them in turn;
* :mod:`~blackbox.identification.result` -- :class:`IdentificationResult`.
"""

from blackbox.fitting.lm import STATUS_MESSAGES
from blackbox.fitting.statistics import FitStatistics, HoldoutStats
from blackbox.identification.fitting import identify
from blackbox.identification.observations import Observations
from blackbox.identification.problem import JointCoordinates, SpringFloor
from blackbox.identification.result import IdentificationResult, IterationRecord

# The internals that tests and scripts import from ``blackbox.identification`` (the problem, the
# coordinates, the fixed point and Gauss-Newton phases, the uncertainty helpers), kept importable here.
from blackbox.fitting.lm import solve_damped as _lsq  # noqa: F401
from blackbox.identification.fitting import _check_inputs, _estimate  # noqa: F401
from blackbox.identification.fixed_point import FP_FLOORS as _FP_FLOORS, FP_STALL as _FP_STALL  # noqa: F401
from blackbox.identification.fixed_point import (_admissible_fixed_point, _admissible_on_segment,  # noqa: F401
                                                 _FixedPoint, _relative_step)
from blackbox.identification.newton import _Fit, _newton  # noqa: F401
from blackbox.identification.problem import SPRING_FLOOR as _SPRING_FLOOR, MatrixLog, _Problem  # noqa: F401
from blackbox.identification.uncertainty import _covariance, _profile_ci, _root_through_origin  # noqa: F401

__all__ = ["Observations", "IterationRecord", "HoldoutStats", "FitStatistics", "IdentificationResult",
           "identify", "STATUS_MESSAGES", "JointCoordinates", "SpringFloor"]
