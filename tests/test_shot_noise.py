"""Stage 5: shot noise is Poisson in the collected charge; crosstalk does not smooth it."""

import numpy as np
import pytest
from conftest import assert_close, quiet_config
from scipy import stats

from cmosnoise import Sensor
from cmosnoise.engine.samplers import Stream
from cmosnoise.model.stages.shot_noise import collect


def _stack(sensor, scene, frames):
    shot = sensor.expose(scene)
    return np.stack([shot.frame(k, detail=True).electrons for k in range(frames)]).astype(np.float64), shot


def test_flat_field_variance_equals_mean_per_pixel():
    cfg = quiet_config(
        shot_noise={"enabled": True}, sensor={"width": 64, "height": 48, "cfa": "none"},
        exposure={"integration_time_s": 0.01, "peak_rate_e_per_s": 50000},
    )
    frames = 60
    e, shot = _stack(Sensor(cfg, seed=1), "flat:0.4", frames)
    mu = 200.0
    assert np.allclose(shot.mean_charge_e, mu)
    var = e.var(axis=0, ddof=1)
    # each pixel: (F-1) s^2 / mu ~ chi2(F-1) for Poisson (normal limit at mu=200);
    # the per-pixel statistics must follow that law (KS), and their pooled mean is 1.
    q = ((frames - 1) * var / mu).ravel()
    assert stats.kstest(q, stats.chi2(frames - 1).cdf).pvalue > 1e-6
    ratio = (var / mu).mean()
    # var(s^2/mu) = 2/(F-1) + 1/(F mu) (Poisson excess kurtosis 1/mu), averaged over P pixels
    se = np.sqrt((2 / (frames - 1) + 1 / (frames * mu)) / q.size)
    assert_close(ratio, 1.0, se, "variance / mean")
    assert_close(e.mean(), mu, np.sqrt(mu / e.size), "mean charge")


def test_crosstalk_does_not_smooth_shot_noise_on_a_structured_scene():
    cfg = quiet_config(
        shot_noise={"enabled": True}, crosstalk={"enabled": True},
        sensor={"width": 64, "height": 64, "cfa": "RGGB"},
        exposure={"integration_time_s": 0.01, "peak_rate_e_per_s": 80000},
    )
    frames = 80
    e, shot = _stack(Sensor(cfg, seed=2), "zoneplate", frames)
    mu = shot.mean_charge_e.astype(np.float64)
    assert mu.std() > 0.2 * mu.mean()  # a structured scene
    ok = mu > 50  # chi-square approximation of the Poisson sample variance
    var = e.var(axis=0, ddof=1)
    ratio = (var[ok] / mu[ok]).mean()
    se = np.sqrt(np.mean(2 / (frames - 1) + 1 / (frames * mu[ok])) / ok.sum())
    assert_close(ratio, 1.0, se, "variance / post-crosstalk mean")
    # the paper's MATLAB order (blur after the draw) would give sum(k^2) ~ 0.62
    k = np.array(cfg.crosstalk.kernel_pct) / 100
    assert abs(ratio - (k**2).sum()) > 20 * se


def test_temporal_mean_follows_post_crosstalk_mean():
    cfg = quiet_config(shot_noise={"enabled": True}, crosstalk={"enabled": True}, sensor={"width": 32, "height": 32})
    e, shot = _stack(Sensor(cfg, seed=3), "ramp", 100)
    mu = shot.mean_charge_e.astype(np.float64)
    z = (e.mean(axis=0) - mu) / np.sqrt(mu / 100)
    # standardised frame means are N(0, 1): check their spread and centre
    assert_close(z.mean(), 0.0, 1 / np.sqrt(z.size), "mean z")
    assert_close(z.var(ddof=1), 1.0, np.sqrt(2 / (z.size - 1)), "var z")


def test_full_well_clips_charge():
    rng = Stream((11, 12), 0)  # a counter-based stream (key, frame)
    n = collect(np.full((50, 50), 5000.0, np.float32), None, 4000.0, rng)
    assert n.max() == 4000.0 and (n == 4000.0).all()
    n = collect(np.full((200, 200), 3990.0, np.float32), None, 4000.0, rng)
    # P(Poisson(3990) > 4000) ~ 0.43 (normal approximation, continuity corrected)
    p = stats.poisson(3990).sf(4000)
    frac = (n == 4000).mean()
    assert_close(frac, p + stats.poisson(3990).pmf(4000), np.sqrt(p * (1 - p) / n.size), "clipped fraction")
    assert n.max() == 4000.0


def test_exact_mean_enters_without_noise_and_is_clipped():
    exact = np.array([[10.5, 20000.0]], np.float32)
    n = collect(None, exact, 10000.0, None)
    assert n.tolist() == [[10.5, 10000.0]]


def test_gaussian_approximation_has_poisson_moments():
    rng = Stream((51, 52), 0)
    lam = np.full(200_000, 5000.0)
    n = collect(lam, None, 1e9, rng, gaussian_above_e=1000.0).astype(np.float64)
    assert_close(n.mean(), 5000.0, np.sqrt(5000 / n.size), "mean")
    assert_close(n.var(), 5000.0, 5000 * np.sqrt(2 / n.size), "variance")
    assert np.all(n == np.round(n))  # whole electrons


def test_shot_noise_values_are_poisson_chi_square():
    """Low mean, where the normal approximation is poor: chi-square goodness of fit to Poisson(3)."""
    rng = Stream((91, 92), 0)
    n = collect(np.full(100_000, 3.0), None, 1e9, rng).astype(int)
    ks = np.arange(0, 10)
    observed = np.array([(n == k).sum() for k in ks[:-1]] + [(n >= ks[-1]).sum()])
    p = np.append(stats.poisson(3).pmf(ks[:-1]), stats.poisson(3).sf(ks[-1] - 1))
    chi2 = ((observed - n.size * p) ** 2 / (n.size * p)).sum()
    assert stats.chi2(len(ks) - 1).sf(chi2) > 1e-6


def test_normal_approximation_threshold_has_a_floor():
    """Below 100 e- the rounded normal is biased (var/mean 0.93 at 2 e-): the configuration refuses it, and says why."""
    from cmosnoise import CmosnoiseError, load_config

    with pytest.raises(CmosnoiseError, match=r"shot_noise\.gaussian_above_e.*100"):
        load_config(overrides=["shot_noise.gaussian_above_e=20"])
    assert load_config(overrides=["shot_noise.gaussian_above_e=100"]).shot_noise.gaussian_above_e == 100
