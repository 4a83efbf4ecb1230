"""Fitting the dark-current stage from a rate map (issue 14, first part): family selection and the tail."""

import math

import numpy as np
import pytest

from cmosnoise import Sensor, load_config, noise_budget
from cmosnoise.analysis import fit

from conftest import Z


@pytest.mark.parametrize("temperature", [25, 45, 65])
def test_family_selection_picks_the_configured_family_on_a_vga_map(temperature):
    """The default points: logistic at 25 C, inverse Gaussian at 45 C, lognormal at 65 C (VGA, seed 1)."""
    sensor = Sensor(load_config(extra={"sensor": {"temperature_c": temperature}}), seed=1)
    state = sensor.dark_state
    fits = fit.select_family(sensor.dark_rate, state.threshold)
    assert fits[0].family == state.family
    assert fits[1].aic - fits[0].aic > 10  # not a coin toss: exp(-5) relative likelihood for the runner-up
    # the chosen fit's mean and std: within 5 standard errors of the configured body's (n = 50 000 pixels);
    # the std's standard error sigma sqrt((kurtosis - 1) / 4n) (these bodies are far from normal at 45 and 65 C)
    from scipy import stats

    n = fits[0].n
    x = sensor.dark_rate[sensor.dark_rate < state.threshold].astype(np.float64)
    kurt = stats.kurtosis(x, fisher=False)
    assert abs(fits[0].mean - state.mean) <= Z * state.std / math.sqrt(n)
    assert abs(fits[0].std - state.std) <= Z * state.std * math.sqrt((kurt - 1) / (4 * n))


def test_family_selection_picks_normal_when_the_truth_is_normal():
    cfg = load_config(extra={"dark_current": {"points": [{"temperature_c": 25, "distribution": "normal",
                                                          "mean_e_per_s": 40.0, "std_e_per_s": 5.0}]}})
    sensor = Sensor(cfg, seed=2)
    fits = fit.select_family(sensor.dark_rate)
    assert fits[0].family == "normal"
    assert fits[0].mean == pytest.approx(40.0, abs=Z * 5 / math.sqrt(fits[0].n))


def test_tail_ppm_and_maximum_from_the_map():
    sensor = Sensor(load_config(extra={"sensor": {"temperature_c": 65}}), seed=3)
    state = sensor.dark_state
    body = fit.select_family(sensor.dark_rate, state.threshold)[0]
    t = fit.tail(sensor.dark_rate, state.threshold, body)
    n = sensor.dark_rate.size
    expected = state.expected_ppm_above()
    se = math.sqrt(expected * 1e-6 * (1 - expected * 1e-6) / n) * 1e6  # binomial count of the tail
    assert abs(t["ppm_above"] - expected) <= Z * se
    assert 0 < t["max_e_per_s"] <= state.tail_max * 1.05 + state.mean


def test_rate_map_from_dark_stacks_is_unbiased_with_the_predicted_noise():
    """The per-pixel slope over three exposure times: mean error 0, variance from the temporal noise."""
    cfg = load_config(extra={"sensor": {"width": 160, "height": 120, "temperature_c": 45}})
    sensor = Sensor(cfg, seed=4)
    k = sensor.transfer.gain_dn_per_e
    times, frames = [0.1, 0.3, 0.5], 16
    means = []
    for j, t in enumerate(times):  # frames of their own per exposure time (the same k would share its noise)
        dark = sensor.with_exposure(t).expose("flat:0")
        means.append(np.mean([dark.frame(100 * j + i).astype(np.float64) for i in range(frames)], axis=0))
    est = fit.rate_map_from_stacks(means, times, k)
    err = est - sensor.dark_rate
    tc = np.array(times) - np.mean(times)
    w = tc / np.sum(tc * tc)
    # per pixel, var(mean_i) = (read^2 + rate t_i + 1/(12 K^2)) / frames in e-^2; row and column noise add
    # common parts, left out of the variance check by looking at the pixel-to-pixel spread around the mean
    tv = noise_budget.temporal_variances(sensor, 0.0)
    read = sum(v for name, v in tv.items() if name not in ("dark_shot", "row", "column"))
    var_pix = sum(wi**2 * (read + sensor.dark_rate.astype(np.float64) * ti) / frames for wi, ti in zip(w, times))
    n = err.size
    assert abs(err.mean()) <= Z * math.sqrt(np.mean(var_pix) / n + (tv.get("row", 0) + tv.get("column", 0)) * np.sum(w**2) / frames)
    # the spread around the mean: the pixel part, plus the row and column noise (one draw per row or column)
    shared = np.sum(w**2) / frames
    rows, cols = sensor.shape
    row_v, col_v = tv.get("row", 0) * shared, tv.get("column", 0) * shared
    predicted = np.mean(var_pix) + row_v + col_v
    se = math.sqrt(2 * np.mean(var_pix**2) / n + 2 * row_v**2 / rows + 2 * col_v**2 / cols)
    assert abs(np.var(err) - predicted) <= Z * se, (np.var(err), predicted, se)
    with pytest.raises(Exception, match="two or more distinct"):
        fit.rate_map_from_stacks(means[:1], times[:1], k)


def test_fit_command_round_trip_from_an_emva_data_set(tmp_path):
    """Frames of simulated sensors, exported as EMVA 1288 data sets and fitted back (5 seeds): each 95 % interval
    holds the configured K, black level, dark mean and std in at least 4 of the 5 (P(3 or fewer) = 2 % for a true
    95 % interval); the family is the configured one every time; simulate runs the fitted configuration."""
    import json

    import yaml
    from conftest import cli

    size = ["--set", "sensor.width=192", "--set", "sensor.height=144", "--set", "sensor.cfa=none"]
    truth = load_config()
    k = Sensor(load_config(extra={"sensor": {"cfa": "none"}})).transfer.gain_dn_per_e
    expected = {"system_gain_K_dn_per_e": k, "black_level_dn": truth.adc.black_level_dn,
                "dark_current.mean_e_per_s": 8.0, "dark_current.std_e_per_s": 2.5}
    covered = {name: 0 for name in expected}
    for seed in range(1, 6):
        r = cli("-q", "characterize", *size, "--seed", str(seed), "--out", tmp_path / f"c{seed}",
                "--emva-export", tmp_path / f"emva{seed}")
        assert r.returncode == 0, r.stderr
        r = cli("fit", "--frames-from", tmp_path / f"emva{seed}", "--temperature", "25", "--cfa", "none",
                "--out", tmp_path / f"f{seed}")
        assert r.returncode == 0, r.stderr
        assert "not fitted" in r.stdout + r.stderr  # what the data cannot give is said, never silently kept
        p = json.loads((tmp_path / f"f{seed}" / "fit.json").read_text())["parameters"]
        # what a dark frame's mean holds at zero exposure: the black level plus the mean fixed offsets (VFPN, rows)
        fp = Sensor(load_config(extra={"sensor": {"width": 192, "height": 144, "cfa": "none"}}), seed=seed).fixed_pattern
        offsets = sum(float(np.mean(m)) for m in (fp.vfpn, fp.row_offset) if m is not None)
        expected["black_level_dn"] = truth.adc.black_level_dn + k * offsets
        for name, value in expected.items():
            lo, hi = p[name]["ci95"]
            covered[name] += lo <= value <= hi
        assert p["dark_current.family"]["value"] == "logistic"
        assert p["full_well_e"]["value"] == pytest.approx(truth.sensor.full_well_e, rel=0.01)
    assert all(n >= 4 for n in covered.values()), covered
    cfg = yaml.safe_load((tmp_path / "f1" / "config.yaml").read_text())
    assert cfg["dark_current"]["points"][0]["distribution"] == "logistic" and cfg["sensor"]["width"] == 192
    r = cli("simulate", "--config", tmp_path / "f1" / "config.yaml", "--out", tmp_path / "s")
    assert r.returncode == 0, r.stderr
    (tmp_path / "bad.txt").write_text("not a descriptor\n")
    r = cli("fit", "--frames-from", tmp_path / "bad.txt", "--out", tmp_path / "g")
    assert r.returncode == 2 and "Traceback" not in r.stderr and not (tmp_path / "g").exists()
