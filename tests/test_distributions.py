"""``blackbox.distributions`` (scipy.special closed forms) against ``scipy.stats`` itself, to
1e-12 relative: the same special functions underneath, so only rounding may differ (quantiles
from the inverse incomplete gamma's iteration: 1e-12 relative leaves it two orders of margin)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from blackbox import distributions as d


@pytest.mark.parametrize("k", [1, 2, 3, 9, 40, 500, 4439])
def test_chi2(k):
    x = np.array([1e-3, 0.5, 1.0, k * 0.5, k, 2.0 * k + 10.0])
    np.testing.assert_allclose(d.chi2_sf(x, k), stats.chi2.sf(x, k), rtol=1e-12)
    q = np.array([1e-6, 0.005, 0.5, 0.995])
    np.testing.assert_allclose(d.chi2_ppf(q, k), stats.chi2.ppf(q, k), rtol=1e-12)
    np.testing.assert_allclose(d.chi2_isf(q, k), stats.chi2.isf(q, k), rtol=1e-12)
    big = np.array([k + 50.0, 10.0 * k + 3000.0])     # the second underflows the sf itself
    np.testing.assert_allclose(d.log10_chi2_sf(big[:1], k), stats.chi2.logsf(big[:1], k) / np.log(10), rtol=1e-10)
    exact = stats.chi2.logsf(big[1], k) / np.log(10)
    got = d.log10_chi2_sf(big[1:], k)[0]
    assert np.isfinite(got) and (not np.isfinite(exact) or abs(got - exact) < 1e-2 * abs(exact))


@pytest.mark.parametrize("df", [1, 3, 10, 200])
def test_t_and_normal(df):
    q = np.array([0.001, 0.025, 0.5, 0.975, 0.9995])
    np.testing.assert_allclose(d.t_ppf(q, df), stats.t.ppf(q, df), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(d.norm_ppf(q), stats.norm.ppf(q), rtol=1e-12, atol=1e-15)
    x = np.array([-3.0, 0.0, 1.96, 8.0])
    np.testing.assert_allclose(d.norm_sf(x), stats.norm.sf(x), rtol=1e-12)
