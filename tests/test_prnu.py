"""Stage 2: PRNU gain map, fixed and Normal(1, sigma)."""

import numpy as np
import pytest
from conftest import Z, assert_close, quiet_config, smoothed_std_se
from scipy import stats

from cmosnoise import Sensor, load_config
from cmosnoise.model.seeds import fixed_key
from cmosnoise.model.spec import resolve
from cmosnoise.model.stages.prnu import gain_map


def test_gain_map_is_normal_with_configured_sigma():
    g = gain_map((0, 400, 0, 500), 500, 3.0, fixed_key(1, "prnu")).astype(np.float64).ravel()
    n = g.size
    assert_close(g.mean(), 1.0, 0.03 / np.sqrt(n), "mean gain")
    assert_close(g.std(ddof=1), 0.03, 0.03 / np.sqrt(2 * (n - 1)), "gain std")
    assert stats.kstest(g, stats.norm(1, 0.03).cdf).pvalue > 1e-6


def test_gain_map_is_clipped_at_zero():
    g = gain_map((0, 300, 0, 300), 300, 80.0, fixed_key(2, "prnu"))
    assert g.min() == 0.0
    frac0 = (g == 0).mean()
    p = stats.norm(1, 0.8).cdf(0)
    assert_close(frac0, p, np.sqrt(p * (1 - p) / g.size), "fraction clipped")


def test_paper_fig3_preset_frame_average_has_10_pct_spatial_std():
    cfg = load_config(preset="paper-fig3-prnu", overrides=["shot_noise.enabled=true"])
    assert cfg.sensor.width == 14 and cfg.prnu.sigma_pct == 10
    sensor = Sensor(cfg, seed=3)
    raw = sensor.capture(frames=400).astype(np.float64)
    t = sensor.transfer
    img = t.to_electrons(raw.mean(axis=0))
    n = img.size
    mean = img.mean()
    assert_close(mean, 1000.0, 100 / np.sqrt(n) + np.sqrt(1000 / 400 / n), "mean e-")
    rel = img.std(ddof=1) / mean
    # shot noise in a 400-frame average adds sqrt(1000/400) e- in quadrature; quantization ~ 2.5 e-/sqrt(12)/20
    expected = np.sqrt(0.10**2 + (1000 / 400) / 1000**2)
    assert_close(rel, expected, expected / np.sqrt(2 * (n - 1)), "PRNU of the frame average")


def test_prnu_is_fixed_across_frames_and_same_for_same_seed():
    cfg = load_config(preset="paper-fig3-prnu")
    a = Sensor(cfg, seed=5).capture(frames=3)
    b = Sensor(cfg, seed=5).capture(frames=3)
    c = Sensor(cfg, seed=6).capture(frames=1)
    assert np.array_equal(a, b)
    assert np.array_equal(a[0], a[2])  # shot noise off: PRNU alone, fixed
    assert not np.array_equal(a[0], c[0])


def test_data_sheet_prnu_solves_the_gain_map_sigma_and_frames_show_it():
    """prnu.measured_pct is the PRNU after crosstalk: a flat field's relative spread equals it."""
    from cmosnoise import CmosnoiseError

    cfg = quiet_config(prnu={"enabled": True, "measured_pct": 1.5}, crosstalk={"enabled": True},
                       sensor={"width": 400, "height": 300, "cfa": "RGGB"}, exposure={"integration_time_s": 0.05})
    # each pixel's charge is sum_j k_j g_j over its 3 x 3 neighbours (one kernel for every colour): with
    # independent gains its relative spread is sigma * sqrt(sum k^2) / sum k, so the gain map's sigma is
    # 1.5 % over that factor (the solve in physics.py reads the weights off crosstalk.apply instead)
    k = np.array(cfg.crosstalk.kernel_pct, dtype=np.float64)
    assert cfg.prnu.sigma_pct == pytest.approx(1.5 / (np.sqrt(np.sum(k**2)) / np.sum(k)), rel=1e-6)
    shot = Sensor(cfg, seed=4).expose("flat:1")
    inner = shot.photo_mean_e[2:-2, 2:-2].astype(np.float64)
    seen = 100 * inner.std() / inner.mean()
    # neighbours share gains through the kernel: the standard error of a smoothed field's spread
    se = smoothed_std_se(seen, inner.size, np.array(cfg.crosstalk.kernel_pct) / 100)
    assert abs(seen - 1.5) <= Z * se, seen
    with pytest.raises(CmosnoiseError, match="give one of them"):
        resolve(load_config(overrides=["prnu.measured_pct=0.79", "prnu.sigma_pct=2"]))
    off = quiet_config(prnu={"enabled": True, "measured_pct": 1.5}, sensor={"width": 8, "height": 8})
    assert off.prnu.sigma_pct == pytest.approx(1.5)  # no crosstalk: what is measured is the gain map
