"""The robust sigma every layer uses (cmosnoise.estimators): scipy's estimator, and a normal law's sigma."""

import numpy as np
import pytest
from scipy import stats

from cmosnoise.estimators import NORMAL_MAD, Z95, robust_centre, robust_sigma


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_robust_sigma_is_scipys_median_abs_deviation_in_the_values_precision(dtype):
    """The same operations as scipy.stats.median_abs_deviation(scale="normal"), NaN and inf left out:
    equal bit for bit (defect correction's thresholds, and so the pictures, depend on it)."""
    x = np.random.default_rng(1).normal(3.0, 2.0, 100_001).astype(dtype)
    x[::97], x[5] = np.nan, np.inf
    finite = x[np.isfinite(x)]
    assert robust_sigma(x) == float(stats.median_abs_deviation(finite, axis=None, scale="normal"))
    assert robust_centre(x)[0] == float(np.median(finite))


def test_robust_sigma_estimates_a_normal_laws_sigma_and_resists_outliers():
    """n normal draws, 1 % of them replaced by far outliers: the estimate is within 5 standard errors of what
    the estimator converges to.

    Without outliers it converges to sigma, with a standard error of sigma / (4 z phi(z) sqrt(n)) (z = the
    0.75 quantile: the variance of a sample median, p (1 - p) / (n f^2), for |X - m| at its median). A fraction
    eps of outliers above every value moves the half of the points within t of the centre to a half of the
    clean ones over (1 - eps): t = sigma * Phi^-1((1 + 0.5 / (1 - eps)) / 2) (the centre's own shift, 0.013
    sigma, changes that only in the second order), about 1.1 % above sigma.
    """
    n, sigma, eps = 200_000, 2.5, 0.01
    x = np.random.default_rng(7).normal(10.0, sigma, n)
    x[: int(eps * n)] = 1e6
    z = stats.norm.ppf(0.75)
    se = sigma / (4 * z * stats.norm.pdf(z) * np.sqrt(n))
    limit = sigma * stats.norm.ppf((1 + 0.5 / (1 - eps)) / 2) / z
    assert abs(robust_sigma(x) - limit) <= 5 * se
    clean = x[int(eps * n):]
    assert abs(robust_sigma(clean) - sigma) <= 5 * se
    assert pytest.approx(z, rel=1e-15) == NORMAL_MAD and pytest.approx(stats.norm.ppf(0.975), rel=1e-15) == Z95
