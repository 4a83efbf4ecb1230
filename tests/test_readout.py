"""Stages 6 to 8: source follower (thermal + flicker), row noise, column noise and VFPN."""

import numpy as np
import pytest
from conftest import Z, assert_close, quiet_config, smoothed_std_se, temporal_variance_se
from scipy import stats

from cmosnoise import CmosnoiseError, Sensor, load_config, noise_budget
from cmosnoise.model.physics import flicker_model
from cmosnoise.model.spec import resolve


def dark_stack(cfg, frames, seed=0, scene="flat:0"):
    shot = Sensor(cfg, seed=seed).expose(scene)
    return np.stack([shot.frame(k, detail=True).electrons for k in range(frames)]).astype(np.float64)


# ------------------------------------------------------------------ flicker
def test_flicker_sigma_map_is_gumbel_body_plus_uniform_tail_with_configured_ppm():
    cfg = quiet_config(
        source_follower={"enabled": True, "thermal_sigma_e": 0.5,
                         "flicker": {"enabled": True, "gumbel_loc_e": 0.8, "gumbel_scale_e": 0.25,
                                     "tail": {"ppm_above": 300, "threshold_e": 4.0, "max_e": 12.0}}},
        sensor={"width": 1000, "height": 1000, "cfa": "none"},
    )
    sigma = Sensor(cfg, seed=1).fixed_pattern.flicker_sigma.astype(np.float64).ravel()
    n, p = sigma.size, 300e-6
    count = (sigma > 4.0).sum()
    assert abs(count - n * p) <= Z * np.sqrt(n * p * (1 - p))
    model = flicker_model(cfg)
    assert stats.kstest(sigma, lambda x: model.cdf(x)).pvalue > 1e-6
    body = sigma[sigma < 3.0]  # the body, where the tail's share is ~1e-4 of the pixels
    loc, scale = stats.gumbel_r.fit(body)
    assert_close(loc, 0.8, 1.1 * 0.25 / np.sqrt(body.size), "gumbel loc")  # asymptotic se of the MLE
    assert_close(scale, 0.25, 0.78 * 0.25 / np.sqrt(body.size), "gumbel scale")


def test_measured_per_pixel_temporal_sigma_fits_the_configured_gumbel():
    loc, scale, thermal = 0.8, 0.25, 0.5
    cfg = quiet_config(
        source_follower={"enabled": True, "thermal_sigma_e": thermal,
                         "flicker": {"enabled": True, "gumbel_loc_e": loc, "gumbel_scale_e": scale, "tail": None}},
        sensor={"width": 80, "height": 80, "cfa": "none"},
    )
    frames = 400
    e = dark_stack(cfg, frames, seed=2)
    s2 = e.var(axis=0, ddof=1).ravel()
    flicker = np.sqrt(np.maximum(s2 - thermal**2, 0))  # thermal removed in quadrature
    # KS against gumbel_r: the estimator's own spread (sqrt(2/(F-1)) of s^2, ~4 % of sigma)
    # is small beside the Gumbel's spread, so a correct stage passes and a wrong family fails
    assert stats.kstest(flicker, stats.gumbel_r(loc, scale).cdf).pvalue > 1e-6
    assert stats.kstest(flicker, stats.norm(flicker.mean(), flicker.std()).cdf).pvalue < 1e-6
    # the frame-to-frame values of one pixel are normal with that pixel's sigma
    sigma = np.sqrt(thermal**2 + Sensor(cfg, seed=2).fixed_pattern.flicker_sigma.astype(np.float64) ** 2)
    z = (e / sigma).ravel()
    assert stats.kstest(z[:500_000], stats.norm().cdf).pvalue > 1e-6


def test_unreachable_flicker_ppm_is_rejected():
    with pytest.raises(CmosnoiseError, match="source_follower.flicker.tail.ppm_above = 0.001.*reachable"):
        resolve(load_config(overrides=["source_follower.flicker.tail={ppm_above: 0.001, threshold_e: 1.0, max_e: 5}"]))


def test_thermal_noise_alone_is_normal_with_configured_sigma():
    cfg = quiet_config(source_follower={"enabled": True, "thermal_sigma_e": 3.0, "flicker": {"enabled": False}},
                       sensor={"width": 300, "height": 300, "cfa": "none"})
    e = dark_stack(cfg, 4).ravel()
    assert_close(e.std(ddof=1), 3.0, 3.0 / np.sqrt(2 * (e.size - 1)), "thermal sigma")
    assert stats.kstest(e, stats.norm(0, 3).cdf).pvalue > 1e-6


# ------------------------------------------------------------------ rows
def test_row_noise_is_one_value_per_row_per_frame():
    cfg = quiet_config(row_noise={"enabled": True, "sigma_e": 2.0}, source_follower={"enabled": True, "thermal_sigma_e": 1.5, "flicker": {"enabled": False}},
                       sensor={"width": 200, "height": 300, "cfa": "none"})
    shot = Sensor(cfg, seed=3).expose("flat:0")
    d0, d1 = shot.frame(0, detail=True), shot.frame(1, detail=True)
    rn = d0.contributions["row_noise"]
    assert np.all(rn == rn[:, :1]) and not np.array_equal(rn, d1.contributions["row_noise"])
    frames = 200
    e = np.stack([shot.frame(k, detail=True).electrons for k in range(frames)]).astype(np.float64)
    row_means = e.mean(axis=2)  # (frames, rows)
    v = row_means.var(axis=0, ddof=1).mean()
    expected = 2.0**2 + 1.5**2 / 200
    assert_close(v, expected, expected * np.sqrt(2 / ((frames - 1) * 300)), "variance of row means")


def test_fixed_row_offsets_are_fixed():
    cfg = quiet_config(row_noise={"enabled": True, "sigma_e": 0.0, "fixed_sigma_e": 5.0}, sensor={"width": 10, "height": 3000, "cfa": "none"})
    s = Sensor(cfg, seed=4)
    off = s.fixed_pattern.row_offset.ravel().astype(np.float64)
    assert_close(off.std(ddof=1), 5.0, 5.0 / np.sqrt(2 * (off.size - 1)), "row offsets")
    shot = s.expose("flat:0")
    np.testing.assert_array_equal(shot.frame(0, detail=True).electrons, shot.frame(5, detail=True).electrons)


# ------------------------------------------------------------------ columns
def test_column_sigma_map_follows_gumbel():
    cfg = quiet_config(column_noise={"enabled": True, "temporal": {"gumbel_loc_e": 0.6, "gumbel_scale_e": 0.2}, "vfpn_sigma_e": 0},
                       sensor={"width": 20000, "height": 2, "cfa": "none"})
    sig = Sensor(cfg, seed=5).fixed_pattern.column_sigma.ravel().astype(np.float64)
    assert stats.kstest(sig, stats.gumbel_r(0.6, 0.2).cdf).pvalue > 1e-6
    assert stats.kstest(sig, stats.norm(sig.mean(), sig.std()).cdf).pvalue < 1e-6


def test_measured_column_temporal_noise_follows_the_columns_sigma():
    cfg = quiet_config(column_noise={"enabled": True, "temporal": {"gumbel_loc_e": 1.0, "gumbel_scale_e": 0.3}, "vfpn_sigma_e": 0},
                       source_follower={"enabled": True, "thermal_sigma_e": 1.0, "flicker": {"enabled": False}},
                       sensor={"width": 1500, "height": 20, "cfa": "none"})
    frames = 300
    sensor = Sensor(cfg, seed=6)
    e = dark_stack(cfg, frames, seed=6)
    col_means = e.mean(axis=1)  # (frames, cols)
    v = col_means.var(axis=0, ddof=1) - 1.0 / 20  # thermal's share of a column mean removed
    true = sensor.fixed_pattern.column_sigma.ravel().astype(np.float64) ** 2
    # per column: (F-1) s^2 / var ~ chi2(F-1); pooled, the ratio is 1 within sqrt(2/(F-1)/C)
    ratio = ((v + 1.0 / 20) / (true + 1.0 / 20)).mean()
    assert_close(ratio, 1.0, np.sqrt(2 / (frames - 1) / true.size), "column variance ratio")
    est = np.sqrt(np.maximum(v, 0))
    assert stats.kstest(est, stats.gumbel_r(1.0, 0.3).cdf).pvalue > 1e-6


def test_vfpn_is_fixed_same_for_same_seed_and_has_configured_sigma():
    cfg = quiet_config(column_noise={"enabled": True, "temporal": {"enabled": False}, "vfpn_sigma_e": 6.0},
                       source_follower={"enabled": True, "thermal_sigma_e": 2.0, "flicker": {"enabled": False}},
                       sensor={"width": 4000, "height": 30, "cfa": "none"})
    a, b = Sensor(cfg, seed=7), Sensor(cfg, seed=7)
    np.testing.assert_array_equal(a.fixed_pattern.vfpn, b.fixed_pattern.vfpn)
    shot = a.expose("flat:0")
    c0 = shot.frame(0, detail=True).contributions["column_noise"]
    c9 = shot.frame(9, detail=True).contributions["column_noise"]
    np.testing.assert_allclose(c0, c9, atol=1e-5)  # the same pattern in every frame (float32 (n + v) - n)
    frames = 20
    e = np.stack([shot.frame(k, detail=True).electrons for k in range(frames)]).astype(np.float64)
    col = e.mean(axis=(0, 1))  # frame-averaged column means
    n = col.size
    expected = np.sqrt(36 + 4 / (30 * frames))  # thermal left in a column mean of 30 x 20 samples
    assert_close(col.std(ddof=1), expected, expected / np.sqrt(2 * (n - 1)), "VFPN std")
    # switching column temporal noise on does not change the VFPN offsets
    cfg2 = load_config(extra={**cfg.to_dict(), "column_noise": {**cfg.to_dict()["column_noise"], "temporal": {"enabled": True}}})
    np.testing.assert_array_equal(Sensor(cfg2, seed=7).fixed_pattern.vfpn, a.fixed_pattern.vfpn)


def test_column_gain_mismatch_scales_the_signal_per_column():
    cfg = quiet_config(column_noise={"enabled": True, "temporal": {"enabled": False}, "vfpn_sigma_e": 0, "gain_sigma_pct": 5.0},
                       sensor={"width": 3000, "height": 4, "cfa": "none"},
                       exposure={"integration_time_s": 0.01, "peak_rate_e_per_s": 100000})
    sensor = Sensor(cfg, seed=8)
    e = sensor.expose("flat:1.0").frame(0, detail=True).electrons.astype(np.float64)
    g = e.mean(axis=0) / 1000.0
    np.testing.assert_allclose(g, sensor.fixed_pattern.column_gain.ravel(), rtol=1e-5)
    assert_close(g.std(ddof=1), 0.05, 0.05 / np.sqrt(2 * (g.size - 1)), "column gain std")


# ------------------------------------------------------------------ the total
def test_total_dark_temporal_noise_matches_two_frame_difference_in_e_and_dn():
    cfg = load_config(overrides=["scene.source=flat:0"])
    sensor = Sensor(cfg, seed=9)
    shot = sensor.expose()
    pairs = 10
    measured_dn2 = np.mean([np.var(shot.frame(2 * i).astype(np.float64) - shot.frame(2 * i + 1)) / 2 for i in range(pairs)])
    b = noise_budget.budget(sensor, 0.0)
    k = sensor.transfer.gain_dn_per_e
    se = temporal_variance_se(sensor, pairs)
    assert_close(measured_dn2, b["temporal_total_dn"] ** 2, se, "dark temporal variance, DN^2")
    assert_close(measured_dn2 / k**2, b["temporal_total_e"] ** 2, se / k**2, "dark temporal variance, e-^2")
    assert b["dominant_temporal"] == "thermal"


def test_summary_lists_each_sources_contribution(tmp_path):
    from cmosnoise.app.run import simulate

    cfg = load_config(overrides=["scene.source=flat:0", "run.frames=6"])
    s = simulate(cfg, tmp_path / "o")
    dark = s["noise_budget"]["dark"]["temporal_rms_e"]
    for src in ["thermal", "flicker", "row", "column", "dark_shot", "quantization"]:
        assert dark[src] > 0
    tn = s["temporal_noise"]
    # 5 consecutive pairs of 6 frames; consecutive pairs share a frame, which at most
    # doubles the variance of their mean: allow sqrt(2) times the independent-pair se
    se = np.sqrt(2) * temporal_variance_se(Sensor(cfg), 5)
    assert_close(tn["rms_dn"] ** 2, tn["predicted_rms_dn"] ** 2, se, "summary temporal noise, DN^2")
    assert s["noise_budget"]["scene_mean"]["dominant_temporal"] == "thermal"


# ------------------------------------------------------------------ the budget where pixels clip
@pytest.mark.parametrize("level", [0.3, 0.99, 1.02, 1.3])
def test_budget_follows_frames_through_the_full_well_and_the_top_code(level):
    """Near saturation the budget once said 99.5 e- where frames measured 82.8, and 101 vs 16.3 above it."""
    cfg = load_config(extra={"sensor": {"width": 320, "height": 240}})
    sensor = Sensor(cfg, seed=0).with_exposure(integration_time_s=level * 10000 / 100000 / 0.98)
    shot = sensor.expose("flat:1")
    b = noise_budget.budget(sensor, float(shot.photo_mean_e.mean()))
    a, c = (shot.frame(k).astype(np.float64) for k in (0, 1))
    k = sensor.transfer.gain_dn_per_e
    tv = np.var(a - c) / 2
    measured_e = np.sqrt(tv) / k
    # Sampling error of the two estimates, from the n pixels of one frame pair. The temporal variance
    # v = var(a - c)/2 has relative standard error sqrt(2/n) from independent pixels, plus the row and
    # column noise, shared along a row (column): their variance is estimated from only `rows` (`cols`)
    # draws, standard error var_row sqrt(2/rows). The fixed-pattern variance var((a + c)/2) - v/2 carries
    # var((a + c)/2) sqrt(2/n) and v/2 sqrt(2/n). Both in e-^2, carried to e- by d sqrt(x) = dx / (2 sqrt(x)).
    rows, cols = a.shape
    n = a.size
    dark = b["temporal_rms_e"]
    v_e = tv / k**2
    se_v = np.sqrt(2 / n * v_e**2 + 2 / rows * dark.get("row", 0.0) ** 4 + 2 / cols * dark.get("column", 0.0) ** 4)
    fixed_e2 = max(np.var((a + c) / 2) - tv / 2, 0.0) / k**2
    se_f = np.sqrt(2 / n) * (np.var((a + c) / 2) / k**2 + v_e / 2)
    fixed = np.sqrt(fixed_e2)
    # Below the clips (level 0.3) the budget is exact: sampling error alone. Where pixels clip, the budget
    # treats the charge as normal (not Poisson) and the two clips in sequence as clipped normals: an
    # approximation, not sampling. Its error, measured here at 0.99, 1.02 and 1.3 of the full well, is at
    # most 3 % of the temporal noise + 0.3 e- (the top code's quantization), 1.8 points of the top-code
    # fraction and 4 % of the fixed pattern + 0.2 e-; the allowance is that, rounded up (noise_budget.clipped_moments
    # says so).
    clips = level > 0.9
    allow_t, allow_top, allow_f = (0.04 * measured_e + 0.35, 0.025, 0.05 * fixed + 0.25) if clips else (0, 0, 0)
    assert abs(b["temporal_total_e"] - measured_e) <= Z * se_v / (2 * measured_e) + allow_t, (b["temporal_total_e"], measured_e)
    top = noise_budget.clipping(sensor, float(shot.photo_mean_e.mean()))["top_code_fraction"]
    measured_top = np.mean(a >= sensor.transfer.max_code)
    # a fraction of n pixels: binomial standard error (pixels clip independently given their means)
    assert abs(top - measured_top) <= Z * np.sqrt(max(top * (1 - top), 1 / n) / n) + allow_top
    assert abs(b["fixed_pattern_total_e"] - fixed) <= Z * se_f / (2 * max(fixed, 1e-9)) + allow_f, (b["fixed_pattern_total_e"], fixed)


def test_budget_prnu_is_what_frames_show_after_crosstalk():
    """With the default kernel frames show 0.79 of the gain map's sigma; the budget once counted it whole."""
    cfg = quiet_config(prnu={"enabled": True, "sigma_pct": 2.0}, crosstalk={"enabled": True},
                       sensor={"width": 400, "height": 300, "cfa": "none"}, exposure={"integration_time_s": 0.05})
    sensor = Sensor(cfg, seed=2)
    shot = sensor.expose("flat:1")
    mean = float(shot.photo_mean_e.mean())
    frame = shot.frame(0).astype(np.float64)  # no temporal noise on: the frame is the fixed pattern (and 1/12 DN^2)
    k = sensor.transfer.gain_dn_per_e
    inner = frame[2:-2, 2:-2]  # away from the edges, where the kernel loses charge off the array
    measured = np.sqrt(max(np.var(inner) - 1 / 12, 0.0)) / k / mean
    predicted = noise_budget.budget(sensor, mean)["fixed_pattern_rms_e"]["prnu"] / mean
    # neighbours share gains through the kernel: the standard error of a smoothed field's spread
    se = smoothed_std_se(measured, inner.size, np.array(cfg.crosstalk.kernel_pct) / 100)
    assert abs(predicted - measured) <= Z * se, (predicted, measured)
    assert predicted == pytest.approx(0.02 * 0.79, rel=0.03)  # sqrt(sum k^2) / sum k of the default kernel


def test_summary_warns_when_pixels_clip(tmp_path):
    from conftest import cli

    r = cli("simulate", "--set", "sensor.temperature_c=150", "--set", "sensor.width=64", "--set", "sensor.height=48",
            "--frames", "2", "--out", tmp_path / "hot")
    assert r.returncode == 0 and "warning:" in r.stdout and "top code" in r.stdout
    import json

    s = json.loads((tmp_path / "hot" / "summary.json").read_text())
    assert s["warnings"] and s["noise_budget"]["scene_mean"]["clipped_fraction"] > 0.5
    r = cli("simulate", "--set", "sensor.width=64", "--set", "sensor.height=48", "--out", tmp_path / "ok")
    assert json.loads((tmp_path / "ok" / "summary.json").read_text())["warnings"] == []
