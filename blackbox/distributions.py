"""The few distribution functions the commands need, from ``scipy.special`` closed forms.

``scipy.stats`` costs about 0.5 s of CPU to import (it pulls in ``scipy.spatial`` and much
else), more than a small identification takes; these are the textbook identities it evaluates
itself (Abramowitz & Stegun 26.4.19, 26.7.1; ``scipy.special`` is loaded by ``scipy.sparse``
anyway):

* chi-square with ``k`` degrees of freedom: ``sf(x) = Q(k/2, x/2)``, the regularised upper
  incomplete gamma function; ``ppf(q) = 2 P^-1(k/2, q)``, ``isf(q) = 2 Q^-1(k/2, q)``;
* Student's t: ``ppf`` is ``stdtrit``; the standard normal: ``ppf`` is ``ndtri``, ``sf(x)`` is
  ``ndtr(-x)``.

``tests/test_distributions.py`` checks each against ``scipy.stats`` to 1e-12 relative.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

__all__ = ["chi2_sf", "chi2_ppf", "chi2_isf", "log10_chi2_sf", "t_ppf", "norm_ppf", "norm_sf"]


def chi2_sf(x, k):
    """``P(X > x)`` for ``X ~ chi2(k)``."""
    return special.gammaincc(np.asarray(k, float) / 2.0, np.maximum(np.asarray(x, float), 0.0) / 2.0)


def chi2_ppf(q, k):
    """The ``q`` quantile of ``chi2(k)``."""
    return 2.0 * special.gammaincinv(np.asarray(k, float) / 2.0, q)


def chi2_isf(q, k):
    """The value exceeded with probability ``q`` under ``chi2(k)``."""
    return 2.0 * special.gammainccinv(np.asarray(k, float) / 2.0, q)


def log10_chi2_sf(x, k: int):
    """``log10 chi2.sf(x, k)``, finite however large ``x``: where ``Q`` underflows, the leading
    term of its asymptotic series, ``Q(a, y) ~ y^(a-1) e^-y / Gamma(a)`` (``a = k/2``,
    ``y = x/2``; relative error ``(a-1)/y``, below 1e-2 wherever ``Q`` underflows)."""
    x = np.asarray(x, float)
    a = k / 2.0
    with np.errstate(divide="ignore"):
        v = np.log(special.gammaincc(a, np.maximum(x, 0.0) / 2.0))
    bad = ~np.isfinite(v)
    if np.any(bad):
        y = x[bad] / 2.0 if x.ndim else x / 2.0
        tail = (a - 1.0) * np.log(y) - y - special.gammaln(a)
        if x.ndim:
            v[bad] = tail
        else:
            v = tail
    return v / math.log(10.0)


def t_ppf(q, df):
    """The ``q`` quantile of Student's t with ``df`` degrees of freedom."""
    return special.stdtrit(df, q)


def norm_ppf(q):
    """The ``q`` quantile of the standard normal."""
    return special.ndtri(q)


def norm_sf(x):
    """``P(Z > x)`` for a standard normal ``Z``."""
    return special.ndtr(-np.asarray(x, float))
