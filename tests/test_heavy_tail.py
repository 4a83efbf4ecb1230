"""docs/model.md section 4: body + uniform tail, tail fraction solved from ppm above a threshold."""

import numpy as np
import pytest
from conftest import Z
from scipy import stats

from cmosnoise.model.distributions import body
from cmosnoise.model.heavy_tail import HeavyTail, UnreachablePpm


def binomial_ok(count, n, p):
    return abs(count - n * p) <= Z * np.sqrt(n * p * (1 - p))


@pytest.mark.parametrize("family,mean,std,ppm,thr,tmax", [
    ("lognormal", 500, 200, 4000, 1560.38, 80000),
    ("logistic", 8, 2.5, 50, 100, 2000),
    ("gamma", 3.0, 1.0, 20000, 6.0, 20.0),  # the body alone gives 7056 ppm above 6
])
def test_ppm_above_threshold_matches_within_binomial_error(family, mean, std, ppm, thr, tmax):
    h = HeavyTail.from_ppm(body(family, mean, std), ppm, thr, tmax)
    assert h.ppm_above(thr) == pytest.approx(ppm, rel=1e-6)
    n = 2_000_000
    v = h.rvs(n, np.random.default_rng(1))
    assert binomial_ok((v > thr).sum(), n, ppm * 1e-6)


def test_the_tail_is_uniform_up_to_its_maximum():
    b = body("normal", 10, 1)
    h = HeavyTail(b, 0.01, 1000.0)
    v = h.rvs(1_000_000, np.random.default_rng(2))
    tail = v[v > 20] - 10  # clear of the body; minus the body mean
    assert binomial_ok(len(tail), 1_000_000, 0.01 * (1000 - 10) / 1000)
    # tail values beyond the body: uniform on (10, 1000) within the body's spread
    inner = tail[(tail > 20) & (tail < 980)]
    assert stats.kstest(inner, stats.uniform(20, 960).cdf).pvalue > 1e-6
    # the largest value: the tail's top plus the body's largest excursion among 1e6 draws, which
    # exceeds norm.isf(1e-7 / n) (about 7.0 sigma) with probability 1e-7
    assert v.max() <= 1000 + 10 + stats.norm.isf(1e-7 / v.size)


def test_survival_function_agrees_with_samples():
    h = HeavyTail(body("inverse_gaussian", 50, 18), 0.002, 7000.0)
    v = h.rvs(1_000_000, np.random.default_rng(3))
    for x in [30, 60, 120, 500, 3000]:
        p = float(h.sf(x))
        assert binomial_ok((v > x).sum(), v.size, p), x


def test_unreachable_ppm_names_the_reachable_range():
    b = body("lognormal", 500, 200)
    with pytest.raises(UnreachablePpm) as info:
        HeavyTail.from_ppm(b, 100, 1560.38, 80000)  # the body alone gives ~826 ppm
    assert info.value.low_ppm == pytest.approx(825.5, rel=1e-3)
    assert "reachable is 825.5 to" in str(info.value)  # threshold 1560.38 here, 1560.377 (250 aA) in the config test
    with pytest.raises(UnreachablePpm, match="reachable"):
        HeavyTail.from_ppm(body("normal", 10, 1), 600_000, 600.0, 1000.0)  # even f = 1 gives 40 %


def test_values_keep_ranks_and_nest_tails_when_parameters_change():
    rng = np.random.default_rng(4)
    u = rng.random((3, 200_000))
    a = HeavyTail(body("logistic", 8, 2.5), 5e-4, 2000).values(*u)
    b = HeavyTail(body("lognormal", 320, 130), 2e-3, 25000).values(*u)
    # tail membership as the code gives it: the value above the same pixel's body alone
    in_a = a - HeavyTail(body("logistic", 8, 2.5), 0.0, 0.0).values(*u) > 0
    in_b = b - HeavyTail(body("lognormal", 320, 130), 0.0, 0.0).values(*u) > 0
    assert abs(in_a.mean() - 5e-4) <= Z * np.sqrt(5e-4 / u.shape[1]) and abs(in_b.mean() - 2e-3) <= Z * np.sqrt(2e-3 / u.shape[1])
    assert np.all(in_b[in_a])  # nested tail sets: a larger fraction adds pixels, never removes them
    # the body keeps every pixel's rank (pixels clipped to 0 under the logistic tie)
    keep = ~in_b & (a > 0)
    order = np.argsort(a[keep], kind="stable")
    assert np.all(np.diff(b[keep][order]) >= 0)
