"""EMVA 1288 characterization recovers the configuration from frames alone."""

import math

import numpy as np
import pytest
from conftest import Z, cli, temporal_variance_se

from cmosnoise import Sensor, load_config, noise_budget, preset_names
from cmosnoise import characterize as ch
from cmosnoise.analysis import emva_evaluation as ev
from cmosnoise.analysis import emva_files
from cmosnoise.analysis.emva_reference import reference_results


@pytest.fixture(scope="module")
def default_run():
    sensor = Sensor(load_config(), seed=0)
    m = ch.measure(sensor, steps=40, stack_frames=16, keep_frames=True)
    return sensor, m, ev.evaluate(m), ch.model_values(sensor, m.stack_texp_s)


def _ols_coefficients(t):
    """Rows c such that (slope, intercept) = c @ y for an ordinary least-squares line."""
    x = np.column_stack([t, np.ones_like(t)])
    return np.linalg.solve(x.T @ x, x.T)


@pytest.mark.slow
def test_recovers_k_temporal_dark_noise_dark_current_dsnu_prnu(default_run):
    sensor, m, res, model = default_run
    k = model["system_gain_K_dn_per_e"]
    rows, cols = sensor.shape
    n = rows * cols
    # --- K: least squares through the origin of v = s2_y - s2_ydark against y = mu_y - mu_ydark.
    # Each v_i comes from one frame pair (1 dof per pixel), bright and dark: var(v_i) from the sampling
    # theory of the pair estimator, at the pixel's signal and dark current.
    y = m.mu_y - m.mu_ydark
    i_sat = res["saturation_index"]
    lin = np.nonzero((y <= 0.7 * y[i_sat]) & (np.arange(len(y)) < i_sat))[0]
    var_v = np.array([
        temporal_variance_se(sensor.with_exposure(m.texp_s[i]), 1, y[i] / k) ** 2
        + temporal_variance_se(sensor.with_exposure(m.texp_s[i]), 1) ** 2 for i in lin
    ])
    se_k = math.sqrt(np.sum(y[lin] ** 2 * var_v)) / np.sum(y[lin] ** 2)
    assert abs(res["system_gain_K_dn_per_e"] - k) <= Z * se_k
    # --- sigma_d: the intercept of s2_ydark against t
    c_slope, c_icpt = _ols_coefficients(m.texp_s)
    var_dark = np.array([temporal_variance_se(sensor.with_exposure(t), 1) ** 2 for t in m.texp_s])
    se_s0 = math.sqrt(np.sum(c_icpt**2 * var_dark))
    s0 = res["temporal_dark_noise_dn"] ** 2
    se_sigma_d = math.hypot(se_s0 / (2 * math.sqrt(s0 - 1 / 12) * k), res["temporal_dark_noise_e"] * se_k / k)
    assert abs(res["temporal_dark_noise_e"] - model["temporal_dark_noise_e"]) <= Z * se_sigma_d
    # --- dark current: slope of the dark mean against t. Each mean is over two frames of n pixels;
    # pixel terms average over n, row noise over the rows, column noise over the columns.
    def var_of_dark_mean(t):
        tv = noise_budget.temporal_variances(sensor.with_exposure(t), 0.0)
        pixel = sum(v for name, v in tv.items() if name not in ("row", "column"))
        return (pixel / n + tv.get("row", 0) / rows + tv.get("column", 0) / cols) * k**2 / 2

    var_mean = np.array([var_of_dark_mean(t) for t in m.texp_s])
    se_dc = math.sqrt(np.sum(c_slope**2 * var_mean)) / k
    assert abs(res["dark_current_mean_e_per_s"] - model["dark_current_mean_e_per_s"]) <= Z * se_dc
    # --- DSNU and PRNU from 16-frame stacks: the averaged temporal noise (tau / L per pixel) leaves a
    # cross term with the fixed pattern P: se(P) = sqrt(4 P tau / (L n) + 2 (tau / L)^2 / n)
    L = m.stack_bright.shape[0]
    tau_dark = noise_budget.budget(sensor.with_exposure(m.stack_texp_s), 0.0)["temporal_total_dn"] ** 2  # DN^2 per pixel
    p_dark = (model["dsnu_e"] * k) ** 2
    se_p = math.sqrt(4 * p_dark * tau_dark / (L * n) + 2 * (tau_dark / L) ** 2 / n)
    se_dsnu = math.hypot(se_p / (2 * math.sqrt(p_dark)) / k, model["dsnu_e"] * se_k / k)
    assert abs(res["dsnu_e"] - model["dsnu_e"]) <= Z * se_dsnu
    mu_b = m.stack_mu_p * model["quantum_efficiency"]
    tau_b = tau_dark + mu_b * k**2
    p_b = (model["prnu_pct"] / 100 * mu_b * k) ** 2
    se_pb = math.sqrt(4 * p_b * tau_b / (L * n) + 2 * (tau_b / L) ** 2 / n)
    se_prnu = 100 * se_pb / (2 * math.sqrt(p_b)) / (mu_b * k)
    assert abs(res["prnu_pct"] - model["prnu_pct"]) <= Z * se_prnu
    # and all within a few percent
    for key in ["system_gain_K_dn_per_e", "temporal_dark_noise_e", "dark_current_mean_e_per_s", "dsnu_e", "prnu_pct"]:
        assert res[key] == pytest.approx(model[key], rel=0.03), key


def test_saturation_snr_and_dynamic_range_are_consistent(default_run):
    sensor, m, res, model = default_run
    # EMVA's saturation is the mean at the variance maximum: below the full well, above 90 % of it
    assert 0.9 * model["saturation_capacity_e"] < res["saturation_capacity_e"] <= model["saturation_capacity_e"]


@pytest.mark.slow
def test_export_round_trips_and_the_reference_implementation_agrees(default_run, tmp_path):
    sensor, m, res, model = default_run
    descriptor = emva_files.export(m, tmp_path)
    again = ev.evaluate(emva_files.load(descriptor))
    for key in ["system_gain_K_dn_per_e", "temporal_dark_noise_e", "dsnu_e", "prnu_pct", "dark_current_mean_e_per_s"]:
        assert again[key] == pytest.approx(res[key], rel=1e-9), key
    pytest.importorskip("emva1288")
    ref = reference_results(descriptor)
    assert not hasattr(np, "asfarray") or np.__version__.startswith("1.")  # the numpy 2 shim never touches this process
    # the reference implementation computes the same EMVA quantities from the same frames; only its
    # choice of fit range differs slightly (seen: 0.001 %)
    for key in ["system_gain_K_dn_per_e", "temporal_dark_noise_e", "dsnu_e", "prnu_pct", "dark_current_mean_e_per_s"]:
        assert ref[key] == pytest.approx(res[key], rel=1e-3), key


def test_load_rejects_a_bad_descriptor(tmp_path):
    from cmosnoise import CmosnoiseError

    (tmp_path / "EMVA1288_descriptor.txt").write_text("v 3.0\nb 1000 abc\n")
    with pytest.raises(CmosnoiseError, match="line 2"):
        emva_files.load(tmp_path)
    with pytest.raises(CmosnoiseError, match="does not exist"):
        emva_files.load(tmp_path / "nothing.txt")


@pytest.mark.slow
def test_characterize_command_end_to_end(tmp_path):
    import json

    small = ["--set", "sensor.width=160", "--set", "sensor.height=120", "--steps", "12", "--stack-frames", "4"]
    r = cli("characterize", *small, "--out", tmp_path / "c",
                        "--emva-export", tmp_path / "e")
    assert r.returncode == 0, r.stderr
    assert "System gain K" in r.stdout and "DSNU1288" in r.stdout
    assert sorted(p.name for p in (tmp_path / "c").iterdir()) == ["characterization.json", "photon_transfer.png", "snr.png"]
    data = json.loads((tmp_path / "c" / "characterization.json").read_text())
    assert set(data["model"]) <= set(data["measured"])  # every model value has its measured partner
    assert (tmp_path / "e" / emva_files.DESCRIPTOR).exists()
    r = cli("characterize", "--frames-from", tmp_path / "e",
                        "--out", tmp_path / "c2")
    assert r.returncode == 0, r.stderr
    again = json.loads((tmp_path / "c2" / "characterization.json").read_text())
    assert again["measured"]["system_gain_K_dn_per_e"] == pytest.approx(data["measured"]["system_gain_K_dn_per_e"], rel=1e-9)
    r = cli("characterize", "--frames-from", tmp_path / "nowhere",
                        "--out", tmp_path / "c3")
    assert r.returncode == 2 and "does not exist" in r.stderr and "Traceback" not in r.stderr


# ------------------------------------------------------------------ every shipped preset
def _line_fit_se(t, var_y):
    """Standard errors of (slope, intercept) of an OLS line through points with variances var_y."""
    c_slope, c_icpt = _ols_coefficients(np.asarray(t))
    return math.sqrt(np.sum(c_slope**2 * var_y)), math.sqrt(np.sum(c_icpt**2 * var_y))


def _fixed_pattern_se(o: np.ndarray, tau: np.ndarray, frames: int) -> float:
    """Standard error of var(mean of L frames) - mean(tau) / L as an estimate of var(o).

    The frame mean is o + e with e of variance tau / L per pixel (its own tau, so heavy-tailed
    white pixels weigh as they should): the cross term gives 4 sum((o - mean o)^2 tau / L) / n^2,
    the noise's own variance 2 sum((tau / L)^2) / n^2.
    """
    n = o.size
    d = o - o.mean()
    # where the noise is well below a DN the quantizer is not dithered: its error is the same in every
    # frame (a fixed uniform of variance 1/12), so it does not average out over the L frames
    left = tau / frames + np.where(tau < 1 / 12 + 0.25, 1 / 12, 0.0)
    return float(math.sqrt(np.sum(4 * d**2 * left + 2 * left**2)) / n)


def _expected_dn(sensor, texp, photo_e=None):
    """Per-pixel expected raw value and temporal variance (DN, DN^2) at exposure ``texp`` (clips included)."""
    s = sensor.with_exposure(texp)
    k = s.transfer.gain_dn_per_e
    mo = noise_budget.clipped_moments(s, 0.0, photo_e=photo_e)
    return mo["mean"] * k, mo["var"] * k**2 + 1 / 12


#: what each preset's frames cannot give (shot noise off: no photon transfer, so no K and nothing in e-)
NO_K = {"paper-fig3-prnu", "paper-fig4-crosstalk"}


@pytest.mark.parametrize("preset", preset_names())
@pytest.mark.slow
def test_characterize_agrees_with_the_model_on_every_preset(preset):
    """Measured against the model within Z standard errors (sampling theory), or n/a with a reason.

    A preset above 2 MP is measured on its area halved in each direction until at most 2 MP are left (the
    standard errors follow the pixel count; the presets differ in their stages, not their size). Heavy-tailed presets (paper-fig9-*, paper-fig11-full) saturate white pixels in the longer dark
    exposures and in the stacks: the dark series is fitted where nothing nears saturation, DSNU is
    compared with the clipped expected image, PRNU leaves out the defect pixels.
    """
    cfg = load_config(preset=preset)
    if cfg.nonlinearity.enabled:  # the model values here are of a linear sensor; the data-sheet presets' curves are
        # held to their sheets' linearity error and K in tests/test_gain.py
        cfg = load_config(preset=preset, extra={"nonlinearity": {"enabled": False}})
    width, height = cfg.sensor.width, cfg.sensor.height
    while width * height > 2_000_000:  # halved until at most 2 MP (a 26 MP sensor: 1.6 MP, still "big")
        width, height = width // 2, height // 2
    if (width, height) != (cfg.sensor.width, cfg.sensor.height):
        cfg = load_config(preset=preset, extra={"sensor": {"width": width, "height": height},
                                                "nonlinearity": {"enabled": False}})
    sensor = Sensor(cfg, seed=3)
    big = sensor.shape[0] * sensor.shape[1] > 1_000_000
    m = ch.measure(sensor, steps=40, stack_frames=4 if big else 16)
    res = ev.evaluate(m)
    model = ch.model_values(sensor, m.stack_texp_s)
    k = model["system_gain_K_dn_per_e"]
    n = m.stack_dark[0].size
    L = m.stack_dark.shape[0]
    failures = []

    def check(key, meas, expect, se):
        if not abs(meas - expect) <= Z * se:
            failures.append(f"{key}: measured {meas:.6g}, model {expect:.6g}, {Z} se = {Z * se:.3g}")

    # PRNU (a ratio of DN, needs no K): the response map of the pixels kept, bright and dark stacks
    photo = sensor.with_exposure(m.stack_texp_s, sensor.saturation_e).expose("flat:1.0").photo_mean_e
    ob, tb = _expected_dn(sensor, m.stack_texp_s, photo_e=photo)
    od, td = _expected_dn(sensor, m.stack_texp_s)
    keep = ~ch.emva.defect_pixels(m.stack_bright, m.stack_dark, float(np.max(m.mu_y)))
    signal = ob - od
    p_b = model["prnu_pct"] / 100 * float(signal[keep].mean())
    se_p = _fixed_pattern_se(ob[keep], tb[keep], L) + _fixed_pattern_se(od[keep], td[keep], L)
    # sqrt of a variance near 0 is biased up by about its se: compare variances, in DN^2
    meas_v = (res["prnu_pct"] / 100 * (res["stack_mean_bright_dn"] - res["stack_mean_dark_dn"])) ** 2
    check("prnu (DN^2)", meas_v, p_b**2, se_p + 1e-12)
    assert res["prnu_excluded_pixels"] <= 0.02 * n

    if preset in NO_K:
        assert res["system_gain_K_dn_per_e"] is None and "system_gain_K_dn_per_e" in res["unavailable"]
        assert "shot noise" in res["unavailable"]["dsnu_e"]
        assert not failures, failures
        return
    assert not res["unavailable"], res["unavailable"]
    # K from the photon-transfer line, as in the default test
    y = m.mu_y - m.mu_ydark
    i_sat = res["saturation_index"]
    lin = np.nonzero((y <= 0.7 * y[i_sat]) & (np.arange(len(y)) < i_sat))[0]
    var_v = np.array([temporal_variance_se(sensor.with_exposure(m.texp_s[i]), 1, y[i] / k) ** 2
                      + temporal_variance_se(sensor.with_exposure(m.texp_s[i]), 1) ** 2 for i in lin])
    se_k = math.sqrt(np.sum(y[lin] ** 2 * var_v)) / np.sum(y[lin] ** 2)
    check("K", res["system_gain_K_dn_per_e"], k, se_k)
    # the dark series over the exposure times the evaluation used
    ok = np.arange(res["dark_fit_points"])
    assert np.all(m.max_ydark[ok] < m.mu_ydark[0] + 0.9 * (np.max(m.mu_y) - m.mu_ydark[0]))
    t = m.texp_s[ok]
    var_s2 = np.array([temporal_variance_se(sensor.with_exposure(ti), 1) ** 2 for ti in t])
    se_slope_v, se_icpt = _line_fit_se(t, var_s2)
    tv0 = noise_budget.temporal_variances(sensor, 0.0)
    q = sensor.transfer.quantization_var_dn2  # step^2 / 12: 1/12, or 16/12 for a 14-bit ADC written in 16 bits
    s0_model = sum(v for name, v in tv0.items() if name not in ("dark_shot", "photon_shot", "quantization")) * k**2 + q
    undithered = s0_model < 3 * q  # no temporal noise to dither the quantization: a dark frame's variance is 0, not q
    check("sigma_d^2 (DN^2)", res["temporal_dark_noise_dn"] ** 2, s0_model, se_icpt + (q if undithered else 0))
    rows, cols = sensor.shape

    def var_of_dark_mean(ti):
        tv = noise_budget.temporal_variances(sensor.with_exposure(ti), 0.0)
        pixel = sum(v for name, v in tv.items() if name not in ("row", "column"))
        return (pixel / n + tv.get("row", 0) / rows + tv.get("column", 0) / cols) * k**2 / 2

    se_slope_m, _ = _line_fit_se(t, np.array([var_of_dark_mean(ti) for ti in t]))
    rel_k = se_k / k  # the e- values divide by the measured K
    dc = model["dark_current_mean_e_per_s"]
    check("dark current (mean)", res["dark_current_mean_e_per_s"], dc, math.hypot(se_slope_m / k, dc * rel_k) + 1e-9)
    dv = model["dark_current_var_e_per_s"]
    check("dark current (variance)", res["dark_current_var_e_per_s"], dv,
          math.hypot(se_slope_v / k**2, dv * 2 * rel_k) + 1e-9)
    # DSNU against the clipped expected dark image, in DN^2 (a variance near 0 is compared as a variance)
    se_d = _fixed_pattern_se(od, td, L)
    check("dsnu^2 (DN^2)", (res["dsnu_e"] * res["system_gain_K_dn_per_e"]) ** 2, (model["dsnu_e"] * k) ** 2,
          math.hypot(se_d, (model["dsnu_e"] * k) ** 2 * 2 * rel_k) + 1e-12)
    # its column part: the column means of the expected image, noise of the column means per column
    oc = od.mean(axis=0)
    tau_c = np.full(cols, float(np.mean(td)) / rows)
    if sensor.fixed_pattern.column_sigma is not None:
        tau_c = tau_c + (sensor.fixed_pattern.column_sigma.ravel().astype(np.float64) * k) ** 2
    se_c = _fixed_pattern_se(oc, tau_c, L) + se_d / rows
    check("dsnu column^2 (DN^2)", (res["dsnu_column_e"] * res["system_gain_K_dn_per_e"]) ** 2,
          (model["dsnu_column_e"] * k) ** 2, se_c + 1e-12)
    # saturation, SNR max and dynamic range follow EMVA's definition of saturation: named, and below the model's
    for key in ("saturation_capacity_e", "snr_max", "dynamic_range_db"):
        assert key in ev.DEFINITION_NOTES
    assert 0.8 * model["saturation_capacity_e"] < res["saturation_capacity_e"] <= model["saturation_capacity_e"] * (1 + 5 * rel_k)
    assert not failures, failures


# ------------------------------------------------------------------ a cooled sensor's dark current
def _imx571(width=256, height=192):
    from cmosnoise.config.loading import deep_merge, preset_data

    data = deep_merge(preset_data("sony-imx571"), {"sensor": {"width": width, "height": height}})
    data.pop("description", None)
    return Sensor(data, seed=0)


def test_a_cooled_sensors_dark_current_is_resolved_by_a_dark_series_within_20_percent():
    """IMX571 at -9.6 C, 0.00054 e-/s (the lab report's median, the preset's mean). The photon-transfer series
    (to 1.3 s) cannot resolve it; the automatic dark series is chosen so that the slope's standard error is
    DARK_SERIES_REL_SE (4 %) of the model's dark current: 5 of them is the 20 % the issue asks, and the test
    holds the measured value to 5 standard errors of the model-derived SE, sqrt(var_pair / Sxx), around the
    instance's own mean rate (and to 20 % of the report's figure)."""
    sensor = _imx571()
    times = ch.dark_series_times(sensor)
    assert times is not None and times[-1] > 10 * ch.SERIES_END_S and len(times) == ch.DARK_SERIES_STEPS
    rate = ch.mean_dark_rate(sensor)
    sxx = float(np.sum((times - times.mean()) ** 2))
    se = math.sqrt(ch.frame_mean_variance_e2(sensor) / 2 / sxx)
    assert se == pytest.approx(ch.DARK_SERIES_REL_SE * rate, rel=1e-9)  # what the times were chosen for
    m = ch.measure(sensor, steps=16, stack_frames=2)
    res = ev.evaluate(m)
    assert res["dark_series_points"] == len(times) and res["unresolved"] == {}
    assert abs(res["dark_current_mean_e_per_s"] - rate) <= 5 * se, (res["dark_current_mean_e_per_s"], rate, se)
    assert abs(res["dark_current_mean_e_per_s"] / 0.00054 - 1) <= 0.20
    notes = ev.footnotes(res)
    assert any(n.startswith(f"dark current: from a dark series of {len(times)} pairs") for n in notes), notes
    cells = {label.strip(): mv for label, _, mv, _, _ in ev.table(res, ch.model_values(sensor, m.stack_texp_s))}
    assert cells["Dark current (from mean)"] not in ("0.00", "0") and float(cells["Dark current (from mean)"]) > 0


def test_a_dark_current_below_what_the_series_resolves_is_a_bound_that_contains_it():
    """Without the dark series the photon-transfer darks cannot resolve 0.00054 e-/s: the table prints "< bound"
    (the slope, or 0, plus DARK_RESOLVE_Z standard errors), the bound contains the truth, and the note says so;
    never "0.00"."""
    sensor = _imx571()
    m = ch.measure(sensor, steps=16, stack_frames=2, dark_exposures=None)
    res = ev.evaluate(m)
    assert set(res["unresolved"]) == {"dark_current_mean_e_per_s", "dark_current_var_e_per_s"}
    assert res["unresolved"]["dark_current_mean_e_per_s"] > ch.mean_dark_rate(sensor)
    cells = {label.strip(): mv for label, _, mv, _, _ in ev.table(res, None)}
    assert cells["Dark current (from mean)"].startswith("< "), cells
    assert any("below what this series resolves" in n and "--dark-exposures" in n for n in ev.footnotes(res))


def test_a_sensor_whose_dark_current_the_series_resolves_gets_no_dark_series_and_bad_times_are_refused():
    assert ch.dark_series_times(Sensor(load_config(), seed=0)) is None  # 8 e-/s: the photon-transfer darks do
    assert ch.dark_series_times(Sensor({"sensor": {"width": 64, "height": 48}, "dark_current": {"enabled": False}})) \
        is None
    for bad in ([1, 2], [1, 1, 2], [0, 1, 2], [1, float("nan"), 3]):
        with pytest.raises(ch.CmosnoiseError, match="dark_exposures"):
            ch.measure(Sensor({"sensor": {"width": 32, "height": 24}}), steps=8, stack_frames=2, dark_exposures=bad)
    r = cli("characterize", "--dark-exposures", "1,2", "--out", "unused")
    assert r.returncode == 2 and "--dark-exposures '1,2'" in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_characterize_takes_dark_exposures_and_writes_the_dark_series(tmp_path):
    r = cli("characterize", "--preset", "sony-imx571", "--set", "sensor.width=128", "--set", "sensor.height=96",
            "--steps", "8", "--stack-frames", "2", "--dark-exposures", "100,200,400,800", "--out", tmp_path / "c")
    assert r.returncode == 0, r.stderr
    import json

    d = json.loads((tmp_path / "c" / "characterization.json").read_text())
    assert d["series"]["dark_series"]["texp_s"] == [100, 200, 400, 800]
    assert d["measured"]["dark_series_longest_s"] == 800 and "from a dark series of 4 pairs" in r.stdout


# ------------------------------------------------------------------ K defined: small-signal and photon-transfer
def test_the_small_signal_k_estimator_is_exact_on_the_models_own_curves():
    """No noise: y = K f(x), v = K^2 f'(x)^2 x on the series below 70 % of saturation, for a 0.5 % and a -1 / +0.6 %
    linearity error: K0 comes back to 1e-4, while the photon-transfer slope is several % off."""
    for le in ([-0.5, 0.5], [-1.0, 0.6]):
        s = Sensor({"sensor": {"width": 64, "height": 48}, "nonlinearity": {"enabled": True,
                                                                               "linearity_error_pct": le}})
        c, k = s.spec.active_nonlinearity, s.transfer.gain_dn_per_e
        x = np.linspace(ch.SERIES_END_S / 40, ch.SERIES_END_S, 40) * s.saturation_e
        x = x[c.apply(x) <= 0.7 * c.apply(s.saturation_e)]
        y, v = k * c.apply(x), k**2 * np.array([c.slope(q) for q in x]) ** 2 * x
        k0, _ = ev.small_signal_gain(x, y, v, v + 1.0, np.ones_like(v))
        assert k0 == pytest.approx(k, rel=1e-4)
        assert abs(float(np.sum(y * v) / np.sum(y * y)) / k - 1) > 0.015
        assert ch.photon_transfer_gain(s, x) == pytest.approx(float(np.sum(y * v) / np.sum(y * y)), rel=1e-12)


@pytest.mark.parametrize("nonlinear", [True, False])
@pytest.mark.slow
def test_a_half_percent_nonlinearity_leaves_the_small_signal_k_within_half_a_percent(nonlinear):
    """512 x 384 pixels, 40 steps (20 below 70 % of saturation): K0's standard error is about 0.08 % of K (from
    the weighted residuals), so 0.5 % is over 5 of them; the test holds K0 to both. The photon-transfer K is held
    to the model's prediction of it (:func:`characterize.photon_transfer_gain`, 2.1 % above K at this
    linearity error) within 5 of its own standard errors, and the footnote names the difference."""
    nl = {"enabled": True, "linearity_error_pct": [-0.5, 0.5]} if nonlinear else {"enabled": False}
    s = Sensor({"sensor": {"width": 512, "height": 384}, "nonlinearity": nl}, seed=0)
    m = ch.measure(s, steps=40, stack_frames=2, dark_exposures=None)
    res = ev.evaluate(m)
    model = ch.model_values(s, m.stack_texp_s, series_e=m.mu_p)
    k = s.transfer.gain_dn_per_e
    k0, se0 = res["small_signal_gain_K_dn_per_e"], res["small_signal_gain_se_dn_per_e"]
    assert model["small_signal_gain_K_dn_per_e"] == k
    assert abs(k0 / k - 1) <= 0.005 and abs(k0 - k) <= Z * se0, (k0, se0, k)
    kp, sep = res["system_gain_K_dn_per_e"], res["system_gain_se_dn_per_e"]
    assert abs(kp - model["system_gain_K_dn_per_e"]) <= Z * sep, (kp, sep, model["system_gain_K_dn_per_e"])
    said = any(n.startswith("System gain K: the photon-transfer K") for n in ev.footnotes(res))
    assert said == nonlinear and (model["system_gain_K_dn_per_e"] / k - 1 > 0.015) == nonlinear


def test_a_linearity_error_read_where_the_adc_clips_first_is_said_by_the_configuration():
    r = cli("config", "--preset", "sony-imx571", "--set", "nonlinearity.coefficients=null", "--set",
            "nonlinearity.linearity_error_pct=[-0.5,0.5]")
    assert r.returncode == 0, r.stderr
    first = r.stdout.splitlines()[0]
    assert first.startswith("# note: nonlinearity.linearity_error_pct = [-0.5, 0.5] is defined on a series to the "
                            "full well (40000 e-); the ADC clips first, at 16358 e-"), first
    import yaml

    assert yaml.safe_load(r.stdout)["nonlinearity"]["linearity_error_pct"] == [-0.5, 0.5]  # still a configuration
    assert load_config().sensor.full_well_e and Sensor(load_config()).spec.notes == []
