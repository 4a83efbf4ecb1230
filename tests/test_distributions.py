"""The body distributions (model.distributions) are scipy.stats' own, computed without importing scipy.stats."""

import subprocess
import sys

import numpy as np
import pytest
from scipy import integrate, stats

from cmosnoise.model.distributions import FAMILIES, body, gumbel
from cmosnoise.model.heavy_tail import integral_of_sf

#: a restated formula may differ from scipy's by a reordering of a few operations: 16 units in the last place
ULPS = 16 * np.finfo(np.float64).eps
PARAMS = [(8.0, 2.5), (320.0, 130.0), (50.0, 18.0), (150.0, 60.0), (3.0, 2.9), (1.0, 0.1), (7.3, 0.77)]


@pytest.mark.filterwarnings("ignore:Error in function boost")  # scipy's inverse Gaussian at q = 1 - 1e-13 too
@pytest.mark.parametrize("family", FAMILIES)
def test_quantiles_survival_and_moments_are_scipy_stats_bit_for_bit(family):
    """ppf, sf, mean and std equal the frozen scipy.stats distribution's, at the support's ends too;
    everything else is scipy's own object.

    The standardized formulas are restated here (scipy's private ``_ppf`` and ``_sf`` are not an API), in
    scipy's order of operations: today they agree bit for bit. A later scipy may reorder a formula, so the
    test allows what a reordering of a few floating-point operations can change: 16 ulps (rtol 16 eps).
    """
    rng = np.random.default_rng(5)
    q = np.r_[0.0, 1e-13, 1e-5, 0.5, 1 - 1e-13, 1.0, rng.random(300)]
    for mean, std in PARAMS + [(float(m), float(s)) for m, s in zip(rng.uniform(1, 500, 10), rng.uniform(0.1, 300, 10))]:
        d = body(family, mean, std)
        ref = d.scipy
        x = np.r_[np.nan, -1.0, 0.0, np.linspace(1e-3, 6 * mean + 20 * std, 1001)]
        np.testing.assert_allclose(d.ppf(q), ref.ppf(q), rtol=ULPS, atol=0, equal_nan=True, err_msg=f"{mean, std}")
        np.testing.assert_allclose(d.sf(x), ref.sf(x), rtol=ULPS, atol=0, equal_nan=True, err_msg=f"{mean, std}")
        np.testing.assert_allclose([d.ppf(0.3), d.sf(mean), d.mean(), d.std()],
                                   [ref.ppf(0.3), ref.sf(mean), ref.mean(), ref.std()], rtol=ULPS, atol=0)
        np.testing.assert_allclose([d.mean(), d.std()], [mean, std], rtol=1e-12)
    assert d.pdf(mean) == ref.pdf(mean) and d.logpdf(mean) == ref.logpdf(mean)  # handed to scipy.stats


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


def test_a_run_does_not_import_scipy_stats():
    """Making a sensor, its frames and a run's summary leave scipy.stats and scipy.integrate unimported:
    together they take about 0.6 s, a third of a run's start-up (see the README's Speed section)."""
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
