"""The body distributions (model.distributions) are scipy.stats' own, computed without importing scipy.stats."""

import subprocess
import sys

import numpy as np
import pytest
from scipy import integrate, special, stats

from cmosnoise.model.distributions import FAMILIES, body, gumbel
from cmosnoise.model.heavy_tail import integral_of_sf

#: a restated formula may differ from scipy's by a reordering of a few operations: 16 units in the last place
ULPS = 16 * np.finfo(np.float64).eps
PARAMS = [(8.0, 2.5), (320.0, 130.0), (50.0, 18.0), (150.0, 60.0), (3.0, 2.9), (1.0, 0.1), (7.3, 0.77)]


@pytest.mark.filterwarnings("ignore:Error in function boost")  # scipy's inverse Gaussian at q = 1 - 1e-13 too
@pytest.mark.parametrize("family", FAMILIES)
def test_quantiles_survival_and_moments_are_scipy_stats(family):
    """ppf, sf, mean and std equal the frozen scipy.stats distribution's, at the support's ends too;
    everything else is scipy's own object.

    The standardized formulas are restated here (scipy's private ``_ppf`` and ``_sf`` are not an API), in
    scipy's order of operations: today they agree bit for bit. A later scipy may reorder a formula, so the
    test allows what a reordering of a few floating-point operations can change: 16 ulps (rtol 16 eps).
    The inverse Gaussian's quantile is solved here, not restated (scipy's is Boost's): its own test below.
    """
    rng = np.random.default_rng(5)
    q = np.r_[0.0, 1e-13, 1e-5, 0.5, 1 - 1e-13, 1.0, rng.random(300)]
    for mean, std in PARAMS + [(float(m), float(s)) for m, s in zip(rng.uniform(1, 500, 10), rng.uniform(0.1, 300, 10))]:
        d = body(family, mean, std)
        ref = d.scipy
        x = np.r_[np.nan, -1.0, 0.0, np.linspace(1e-3, 6 * mean + 20 * std, 1001)]
        if family != "inverse_gaussian":
            np.testing.assert_allclose(d.ppf(q), ref.ppf(q), rtol=ULPS, atol=0, equal_nan=True, err_msg=f"{mean, std}")
        np.testing.assert_allclose(d.sf(x), ref.sf(x), rtol=ULPS, atol=0, equal_nan=True, err_msg=f"{mean, std}")
        np.testing.assert_allclose([d.sf(mean), d.mean(), d.std()], [ref.sf(mean), ref.mean(), ref.std()],
                                   rtol=ULPS, atol=0)
        np.testing.assert_allclose([d.mean(), d.std()], [mean, std], rtol=1e-12)
    assert d.pdf(mean) == ref.pdf(mean) and d.logpdf(mean) == ref.logpdf(mean)  # handed to scipy.stats


@pytest.mark.filterwarnings("ignore:Error in function boost")
@pytest.mark.parametrize("mu", [1e-3, 0.0466, 0.13, 0.93, 3.0, 20.0])
def test_inverse_gaussian_quantile_solves_scipys_cdf(mu):
    """The inverse Gaussian's quantile (solved by Newton steps, model.distributions._invgauss_ppf) puts
    scipy.stats' public tail at q, to what float64 can resolve.

    The tail is the lower one for q <= 1/2 and the upper one above, as the solver's. Two errors are
    allowed, each in units of eps:
    - the rounding of x: the best float next to the true quantile has a tail off by ulp(x) f(x), relative
      eps * s with s = x f(x) / tail(x);
    - evaluating the tail, F = Phi(-z1) +- exp(2/mu) Phi(-z2), z1,2 = (x/mu -+ 1)/sqrt(x): a relative error
      eps in z moves log Phi(-z) by about z**2 eps (its log-slope), at most z2**2 eps for either term, and
      the upper tail's difference of the two magnifies that by kappa = (A + B) / |A - B|.
    So |tail(x)/q - 1| <= 32 eps (1 + s + kappa (1 + z2**2)): the largest measured ratio to the unscaled
    sum is 2 (mu = 0.0466 to 20), the factor 32 leaves 16 for another scipy's reordering; a quantile one
    part in 1e-12 off (an unconverged solve) breaks it by orders of magnitude in the body. Against
    scipy.stats' own (Boost's) quantile: 1e-12 relative from mu = 0.0466 up; at mu = 1e-3 Boost's is 3e-6
    off (a tail residual 1e6 times this bound), which is why this test judges by the tail.
    """
    eps = np.finfo(np.float64).eps
    q = np.r_[1e-13, 1e-9, 1e-5, 0.01, 0.3, 0.5, 0.5 + 1e-9, 0.7, 0.99, 1 - 1e-5, 1 - 1e-9,
              np.random.default_rng(2).random(200)]
    ref = stats.invgauss(mu)
    x = body("inverse_gaussian", mu, mu**1.5).ppf(q)  # mean mu, std mu**1.5: scipy's invgauss(mu), scale 1
    lower = q <= 0.5
    tail = np.where(lower, ref.cdf(x), ref.sf(x))
    s = x * ref.pdf(x) / tail
    z2 = (x / mu + 1) / np.sqrt(x)
    a, b = special.ndtr(-np.abs((x / mu - 1) / np.sqrt(x))), np.exp(2 / mu + special.log_ndtr(-z2))
    kappa = np.where(lower, 1.0, (a + b) / np.abs(a - b))
    np.testing.assert_array_less(np.abs(tail / np.where(lower, q, 1 - q) - 1),
                                 32 * eps * (1 + s + kappa * (1 + z2**2)))
    if mu >= 0.04:
        np.testing.assert_allclose(x, ref.ppf(q), rtol=1e-12, atol=0)


def test_gumbel_is_scipy_gumbel_r():
    g, ref = gumbel(0.8, 0.25), stats.gumbel_r(loc=0.8, scale=0.25)
    u = np.random.default_rng(1).random(10_000)
    assert np.array_equal(g.ppf(u), ref.ppf(u)) and np.array_equal(g.sf(5 * u - 1), ref.sf(5 * u - 1))
    assert g.mean() == ref.mean() and g.std() == ref.std()


def test_unknown_distribution_is_refused():
    from cmosnoise.model.distributions import Frozen

    with pytest.raises(ValueError, match="unknown distribution 'cauchy'"):
        Frozen("cauchy")


@pytest.mark.parametrize("family", FAMILIES)
def test_integral_of_the_survival_function_is_quads(family):
    """The heavy tail's integral of the body's sf (Gauss-Legendre cut at the body's quantiles) against
    scipy.integrate.quad told where the body lies; and against E[max(X, 0)] over the whole half-line."""
    for mean, std in PARAMS:
        d = body(family, mean, std)
        pts = [p for p in d.ppf([1e-9, 0.01, 0.5, 0.99, 1 - 1e-9])]
        for lo, hi in [(0.0, 5.0), (0.0, 40.0), (0.0, 600.0), (2.0, 5000.0), (100.0, 26000.0)]:
            inside = [p for p in pts if lo < p < hi]
            ref, err = integrate.quad(d.sf, lo, hi, points=inside or None, limit=500, epsabs=1e-13, epsrel=1e-12)
            assert integral_of_sf(d, lo, hi) == pytest.approx(ref, rel=1e-9, abs=1e-9 * std), (mean, std, lo, hi)
        top = float(d.ppf(1 - 1e-15)) * 4
        expected = d.expect(lambda v: np.maximum(v, 0.0), lb=float(d.ppf(1e-15)), ub=top)
        assert integral_of_sf(d, 0.0, top) == pytest.approx(expected, rel=1e-7)


@pytest.mark.slow
def test_a_run_does_not_import_scipy_stats():
    """Making a sensor, its frames and a run's summary leave scipy.stats and scipy.integrate unimported:
    together they take about 0.6 s, a third of a run's start-up (see docs/performance.md)."""
    code = (
        "import sys, tempfile\n"
        "from cmosnoise import load_config\n"
        "from cmosnoise.app.run import simulate\n"
        "cfg = load_config(extra={'sensor': {'width': 96, 'height': 64}, 'run': {'frames': 2}})\n"
        "with tempfile.TemporaryDirectory() as d:\n"
        "    simulate(cfg, d + '/out')\n"
        "print(sorted(m for m in ('scipy.stats', 'scipy.integrate', 'scipy.optimize') if m in sys.modules))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]", r.stdout
