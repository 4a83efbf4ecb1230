"""EMVA 1288 view of simulated frames: temporal dark noise, DSNU (with its column part) and PRNU."""

import numpy as np
from conftest import assert_close, quiet_config, std_se_with_noise, temporal_variance_se
from scipy import signal

from cmosnoise import Sensor, emva, load_config, noise_budget
from cmosnoise.model.scene import steps_levels


def stack(shot, frames, first=0):
    return np.stack([shot.frame(k) for k in range(first, first + frames)])


def test_emva_temporal_dark_noise_matches_the_budget():
    cfg = load_config(overrides=["sensor.width=800", "sensor.height=600"])
    sensor = Sensor(cfg, seed=1)
    frames = 16
    dark = stack(sensor.expose("flat:0"), frames)
    measured = emva.temporal_variance_stack(dark)
    predicted = noise_budget.budget(sensor, 0.0)["temporal_total_dn"] ** 2
    assert_close(measured, predicted, temporal_variance_se(sensor, frames - 1), "EMVA temporal dark variance")


def test_emva_dsnu_column_part_is_the_vfpn_and_pixel_part_the_dcnu():
    frames, t_int = 16, 0.5
    cfg = load_config(overrides=["sensor.width=2000", "sensor.height=200", "column_noise.vfpn_sigma_e=3.0",
                                 f"exposure.integration_time_s={t_int}", "sensor.temperature_c=45"])
    sensor = Sensor(cfg, seed=2)
    rows, cols = sensor.shape
    k = sensor.transfer.gain_dn_per_e
    dark = stack(sensor.expose("flat:0"), frames)
    d = emva.dsnu(dark)
    dcnu_var = float(np.var(sensor.fixed_pattern.dark_rate.astype(np.float64) * t_int))
    temporal_var = noise_budget.budget(sensor, 0.0)["temporal_total_e"] ** 2
    # a column mean carries the pixel-level pattern and the averaged temporal noise of its rows
    col_noise = (dcnu_var + temporal_var / frames) / rows
    col_e = d["column"] / k
    assert_close(col_e, 3.0, std_se_with_noise(9.0, col_noise, cols), "DSNU column part vs vfpn_sigma_e")
    realized = float(np.var(sensor.fixed_pattern.vfpn.astype(np.float64), ddof=1))
    # against the instance's own offsets only the column-mean noise remains: se of var(o + e) - w
    se_var = np.sqrt((4 * realized * col_noise + 2 * col_noise**2) / cols)
    assert_close(col_e**2, realized, se_var, "DSNU column part vs this sensor's offsets")
    # pixel part: the DCNU map; errors from the averaged temporal noise's cross term with it, from the temporal
    # variance estimated in the stack and subtracted, and from the column-variance estimate it is separated from.
    # Pixel i's temporal variance v_i holds its own dark shot noise (its mean dark charge d_i): the white pixels
    # carry both the largest offsets and the largest noise, so the sums run pixel by pixel, not over means.
    # cross term: sum_i 2 (d_i - mean) e_i / N with Var(e_i) = v_i / L; estimate: sum_i s_i^2 / (N L), Var(s_i^2)
    # = 2 v_i^2 / (L - 1) for normal e (the Poisson excess adds v_i / L, below 1 % here).
    d_e = sensor.fixed_pattern.dark_rate.astype(np.float64) * t_int
    v = temporal_var - d_e.mean() + d_e
    n = rows * cols
    se_cross = np.sqrt(4 * np.sum((d_e - d_e.mean()) ** 2 * v) / frames) / n
    se_resid = np.sqrt(np.sum(2 * v**2 / (frames - 1))) / (frames * n)
    se_pix = np.sqrt(se_cross**2 + se_resid**2 + se_var**2)
    assert_close((d["pixel"] / k) ** 2, dcnu_var, se_pix, "DSNU pixel part")
    # no fixed row component is configured: the row part is zero within the noise of row means
    se_row = np.sqrt(2 / (rows - 1)) * (dcnu_var + temporal_var / frames) / cols
    assert_close((d["row"] / k) ** 2, 0.0, se_row, "fixed row part")


def test_emva_prnu_matches_the_configured_sigma():
    cfg = quiet_config(prnu={"enabled": True, "sigma_pct": 2.0}, shot_noise={"enabled": True},
                       source_follower={"enabled": True}, sensor={"width": 500, "height": 400, "cfa": "none"},
                       exposure={"integration_time_s": 0.01, "peak_rate_e_per_s": 500000})
    sensor = Sensor(cfg, seed=3)
    frames, mu = 20, 5000.0  # half the full well
    bright = stack(sensor.expose("flat:1.0"), frames)
    dark = stack(sensor.expose("flat:0"), frames)
    p = emva.prnu(bright, dark)
    n = 500 * 400
    prnu_var = (0.02 * mu) ** 2
    temporal = (mu + cfg.source_follower.thermal_sigma_e**2) / frames
    # the realised gain map (n pixels) plus the averaged temporal noise's cross term, relative to mu
    se = std_se_with_noise(prnu_var, temporal, n) / mu
    assert_close(p, 0.02, se, "EMVA PRNU")


def test_emva_prnu_with_crosstalk_is_reduced_by_the_kernel():
    cfg = quiet_config(prnu={"enabled": True, "sigma_pct": 3.0}, crosstalk={"enabled": True},
                       sensor={"width": 400, "height": 400, "cfa": "none"})
    sensor = Sensor(cfg, seed=4)
    bright = stack(sensor.expose("flat:1.0"), 2)
    dark = stack(sensor.expose("flat:0"), 2)
    k = np.array(cfg.crosstalk.kernel_pct) / 100
    expected = 0.03 * np.sqrt((k**2).sum()) / k.sum()  # the kernel averages neighbouring gains
    # neighbouring pixels now share gains: the variance estimate has the se of
    # n / sum(rho^2) independent pixels, rho the kernel's normalised autocorrelation
    rho = signal.correlate2d(k, k) / (k**2).sum()
    n_eff = 400 * 400 / (rho**2).sum()
    se = expected / np.sqrt(2 * n_eff)
    se = np.hypot(se, (1 / 12) ** 0.5 / sensor.transfer.gain_dn_per_e / 3000 / np.sqrt(400 * 400))  # quantization
    assert_close(emva.prnu(bright, dark), expected, se, "PRNU after crosstalk")


def test_fig10_vfpn_is_plain_at_low_light_and_hard_to_see_at_high_light():
    cfg = load_config(preset="paper-fig10-vfpn")
    assert cfg.column_noise.vfpn_sigma_e == 6.0 and cfg.shot_noise.enabled
    sensor = Sensor(cfg, seed=5)
    shot = sensor.expose()
    e = sensor.transfer.to_electrons(shot.frame(0))
    rows, cols = e.shape
    levels = steps_levels(4) * cfg.exposure.peak_rate_e_per_s * cfg.exposure.integration_time_s
    band_rows = rows // 4
    q = 1 / (12 * sensor.transfer.gain_dn_per_e**2)
    contrast = []
    for i, level in enumerate(levels):
        band = e[i * band_rows + 2 : (i + 1) * band_rows - 2]
        col = band.mean(axis=0)
        noise = (level + q) / band.shape[0]  # shot noise and quantization left in a column mean
        pattern = np.sqrt(max(col.var(ddof=1) - noise, 0))
        assert_close(pattern, 6.0, std_se_with_noise(36.0, noise, cols), f"column pattern at {level:.0f} e-")
        contrast.append(pattern / level)
    # relative contrast of the stripes: ~8 % in the darkest band (plain to see), ~0.1 % in the brightest
    assert contrast[0] > 0.04 and contrast[-1] < 0.003
    assert all(a > b for a, b in zip(contrast, contrast[1:]))


def test_spatial_column_part_is_not_fooled_by_temporal_column_noise():
    """A column noise that changes from frame to frame is temporal: the column part is the fixed pattern only.

    EMVA 1288's correction (pixel noise / (L rows)) leaves sigma_ct^2 / L of temporal column noise in the
    column part; the stack's own column-mean variance removes it. Fixed column pattern of variance 4 DN^2,
    temporal column noise 9 DN^2, white noise 1 DN^2, L = 4 frames of 200 x 300.
    """
    rng = np.random.default_rng(11)
    L, rows, cols = 4, 200, 300
    fixed = 2.0 * rng.standard_normal(cols)
    stack = (100 + fixed[None, None, :] + 3.0 * rng.standard_normal((L, 1, cols))
             + rng.standard_normal((L, rows, cols)))
    v = emva.spatial_variances(stack)
    truth = float(np.var(fixed, ddof=1))
    # se: the column means' temporal residual (9 + 1/rows) / L per column, crossed with the pattern
    tau = (9.0 + 1.0 / rows) / L
    se = np.sqrt(4 * truth * tau / cols + 2 * tau**2 / cols)
    assert abs(v["column"] - truth) <= 5 * se
    assert v["column"] - truth > -5 * se and abs(v["column"] + 9.0 / L - truth) > 5 * se  # the old bias would show
