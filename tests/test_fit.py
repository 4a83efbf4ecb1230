"""Fitting the dark-current stage from a rate map: family selection and the tail."""

import math

import numpy as np
import pytest
from conftest import Z

from cmosnoise import Sensor, load_config, noise_budget
from cmosnoise.analysis import fit_dark as fit
from cmosnoise.analysis import fit_photo


@pytest.mark.parametrize("family", ["logistic", "inverse_gaussian", "lognormal", "normal", "gamma"])
@pytest.mark.parametrize("threshold", [math.inf, 80.0])
def test_truncated_likelihood_is_scipys_for_every_family(family, threshold):
    """The fast likelihood (sufficient statistics) is scipy.stats' sum of logpdf minus n logcdf(threshold),
    for data of ``family`` evaluated under every family, near and far from the data's own mean and std."""
    from cmosnoise.model.distributions import FAMILIES, body

    x = body(family, 50.0, 12.0).rvs(4000, random_state=np.random.default_rng(7))
    x = x[(x < threshold) & (x > 0)]
    like = fit.TruncatedLikelihood(x, threshold)
    for other in FAMILIES:
        for mean, std in [(50.0, 12.0), (44.0, 8.0), (61.0, 21.0), (30.0, 26.0)]:
            d = body(other, mean, std)
            ref = float(np.sum(d.logpdf(x)) - x.size * (d.logcdf(threshold) if math.isfinite(threshold) else 0.0))
            assert like.loglik(other, mean, std) == pytest.approx(ref, rel=1e-10), (other, mean, std)
    assert like.loglik("gamma", -1.0, 5.0) == -math.inf  # a positive family with a mean of 0 or less
    assert fit.TruncatedLikelihood(np.array([-1.0, 2.0, 3.0])).loglik("lognormal", 2.0, 1.0) == -math.inf


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


def test_photon_transfer_weights_each_level_by_its_sampling_variance():
    """K from photon-transfer points drawn exactly as the fit assumes: each level's mean of per-pixel
    variances over n frames is its variance times chi-square(pixels * (n - 1)) / (pixels * (n - 1)), less
    the dark's drawn the same way. Over 2000 data sets K is unbiased, its spread is the weighted
    slope's (an unweighted slope's is twice as wide on this set), and the Student t interval holds K
    95 % of the time."""
    rng = np.random.default_rng(14)
    K, vd, pixels, trials = 0.4, 9.0, 50_000, 2000
    mu = np.array([150.0, 300, 600, 900, 1100, 1600, 2400, 3000])  # DN; saturation at 1600, fitted to 1120
    frames = np.array([2, 2, 2, 16, 2, 2, 2, 2])
    dark_frames = 48
    clip = np.array([1, 1, 1, 1, 1, 1, 0.4, 0.1])  # clipped pixels lose variance: saturation at the peak
    sigma2 = (K * mu + vd) * clip
    dof, ddof = pixels * (frames - 1), pixels * (dark_frames - 1)
    lin = slice(0, 5)
    w = 1 / ((K * mu[lin] + vd) ** 2 * 2 / dof[lin] + vd**2 * 2 / ddof)  # absolute sampling variances
    se_theory = math.sqrt(1 / np.sum(w * mu[lin] ** 2))
    ks, unweighted, hits = np.empty(trials), np.empty(trials), 0
    for i in range(trials):
        v = sigma2 * rng.chisquare(dof) / dof - vd * rng.chisquare(ddof, mu.size) / ddof
        unweighted[i] = np.sum(mu[lin] * v[lin]) / np.sum(mu[lin] ** 2)  # EMVA 1288's slope, on the same data
        r = fit_photo.photon_transfer(mu, v, frames=frames, dark_var=np.full(mu.size, vd), dark_frames=np.full(mu.size, dark_frames))
        assert r["fit_points"] == 5 and r["saturation_index"] == 5
        ks[i] = r["K"]
        hits += r["ci95"][0] <= K <= r["ci95"][1]
    assert abs(ks.mean() - K) <= Z * se_theory / math.sqrt(trials)
    assert abs(ks.var(ddof=1) / se_theory**2 - 1) <= Z * math.sqrt(2 / (trials - 1))
    assert abs(hits - 0.95 * trials) <= Z * math.sqrt(trials * 0.05 * 0.95), hits
    # docs/sensor/fit.md's claim: on such a set the unweighted slope is more than twice as noisy (its variance more than
    # four times; the ratio of two sample variances of 2000 is itself within a few per cent)
    assert unweighted.var(ddof=1) > 4 * ks.var(ddof=1)


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


@pytest.mark.slow
def test_fit_command_round_trip_from_an_emva_data_set(tmp_path):
    """Frames of simulated sensors, exported as EMVA 1288 data sets and fitted back (5 seeds): each 95 % interval
    holds the configured K, black level, dark mean and std and the QE in at least 4 of the 5 (P(3 or fewer) =
    2 % for a true 95 % interval); the family is the configured one every time; simulate runs the fitted
    configuration."""
    import json

    import yaml
    from conftest import cli

    size = ["--set", "sensor.width=192", "--set", "sensor.height=144", "--set", "sensor.cfa=none"]
    truth = load_config()
    k = Sensor(load_config(extra={"sensor": {"cfa": "none"}})).transfer.gain_dn_per_e
    expected = {"system_gain_K_dn_per_e": k, "black_level_dn": truth.adc.black_level_dn,
                "dark_current[25 C].mean_e_per_s": 8.0, "dark_current[25 C].std_e_per_s": 2.5,
                "quantum_efficiency": 1.0}  # characterize's photons are the photo-electrons: QE 1
    covered = {name: 0 for name in expected}
    for seed in range(1, 6):
        r = cli("-q", "characterize", *size, "--seed", str(seed), "--out", tmp_path / f"c{seed}",
                "--emva-export", tmp_path / f"emva{seed}")
        assert r.returncode == 0, r.stderr
        r = cli("fit", "--frames-from", tmp_path / f"emva{seed}", "--temperature", "25", "--cfa", "none",
                "--out", tmp_path / f"f{seed}", *([] if seed == 1 else ["--no-round-trip"]))
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
        assert p["dark_current[25 C].family"]["value"] == "logistic"
        assert p["full_well_e"]["value"] == pytest.approx(truth.sensor.full_well_e, rel=0.01)
    assert all(n >= 4 for n in covered.values()), covered
    cfg = yaml.safe_load((tmp_path / "f1" / "config.yaml").read_text())
    assert cfg["dark_current"]["points"][0]["distribution"] == "logistic" and cfg["sensor"]["width"] == 192
    r = cli("simulate", "--config", tmp_path / "f1" / "config.yaml", "--out", tmp_path / "s")
    assert r.returncode == 0, r.stderr
    (tmp_path / "bad.txt").write_text("not a descriptor\n")
    r = cli("fit", "--frames-from", tmp_path / "bad.txt", "--out", tmp_path / "g")
    assert r.returncode == 2 and "Traceback" not in r.stderr and not (tmp_path / "g").exists()


# ------------------------------------------------------------------ a manifest of stacks in TIFF, .npy and DNG
def _write_lab_data(folder, seed=3, size=(96, 128)):
    """A lab's data set from a simulated sensor: darks as .npy, flats as multi-page TIFF, one flat as DNG frames."""
    import tifffile
    import yaml

    from cmosnoise.io.dng import write_dng

    cfg = load_config(extra={"sensor": {"height": size[0], "width": size[1]}})
    s = Sensor(cfg, seed=seed)
    folder.mkdir(parents=True, exist_ok=True)
    frame, stacks = 0, []
    for t, n in [(0.005, 32), (0.25, 4), (0.5, 4), (1.0, 4)]:
        ex = s.with_exposure(t).expose("flat:0")
        np.save(folder / f"dark_{t:g}.npy", np.stack([ex.frame(frame + i) for i in range(n)]))
        frame += n
        stacks.append({"kind": "dark", "exposure_s": t, "files": [f"dark_{t:g}.npy"]})
    for j, lvl in enumerate([0.1, 0.2, 0.3, 0.45, 0.6, 0.75, 0.9, 1.1, 1.3]):
        ex = s.with_exposure(0.005, s.saturation_e * lvl / 0.005).expose("flat:1.0")
        n = 8 if lvl == 0.45 else 2
        frames = [ex.frame(frame + i) for i in range(n)]
        frame += n
        if lvl == 0.3:  # this level as DNG files, one frame each: CFA and black level from their metadata
            for i, f in enumerate(frames):
                write_dng(folder / f"flat03_{i}.dng", f, "RGGB", cfg.adc.black_level_dn, 4095)
            stacks.append({"kind": "flat", "exposure_s": 0.005, "level": lvl, "files": ["flat03_*.dng"]})
        else:
            tifffile.imwrite(folder / f"flat_{j}.tif", np.stack(frames))
            stacks.append({"kind": "flat", "exposure_s": 0.005, "level": lvl, "files": [f"flat_{j}.tif"]})
    (folder / "manifest.yaml").write_text(yaml.safe_dump({"bits": 12, "temperature_c": 25, "stacks": stacks}))
    return cfg, s


@pytest.mark.slow
def test_fit_reads_a_manifest_of_tiff_npy_and_dng_and_writes_config_json_report(tmp_path):
    import json

    import yaml
    from conftest import cli

    cfg, s = _write_lab_data(tmp_path / "lab")
    r = cli("fit", "--frames-from", tmp_path / "lab" / "manifest.yaml", "--out", tmp_path / "fit")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "fit" / "fit.json").read_text())
    P = doc["parameters"]
    assert doc["meta"]["cfa"] == "RGGB"  # from the DNG files' CFA pattern
    k = s.transfer.gain_dn_per_e
    lo, hi = P["system_gain_K_dn_per_e"]["ci95"]
    assert lo <= k <= hi
    for name in ("source_follower.thermal_sigma_e", "row_noise.sigma_e", "column_noise.vfpn_sigma_e",
                 "prnu.measured_pct", "dark_current[25 C].mean_e_per_s"):
        assert P[name]["ci95"] is not None and P[name]["method"], name
    assert "crosstalk" in doc["not_fitted"]  # what cannot be fitted is said, with what it needs
    assert doc["round_trip"] and all(set(row) >= {"parameter", "measured", "simulated"} for row in doc["round_trip"])
    html = (tmp_path / "fit" / "fit_report.html").read_text()
    assert "Photon transfer" in html and "Fig. 7" in html and "Figs. 5 and 6" in html and "data:image/png;base64," in html
    assert "http://" not in html and "https://" not in html  # self-contained
    fitted = yaml.safe_load((tmp_path / "fit" / "config.yaml").read_text())
    assert fitted["sensor"]["width"] == 128 and fitted["adc"]["bits"] == 12
    r = cli("simulate", "--config", tmp_path / "fit" / "config.yaml", "--out", tmp_path / "sim")
    assert r.returncode == 0, r.stderr


def _one_line_exit_2(r, *needles):
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    err = r.stderr.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    for n in needles:
        assert n in err, (n, err)


def test_fit_bad_input_gets_one_line_exit_2_and_no_output_folder(tmp_path):
    import yaml
    from conftest import cli

    _write_lab_data(tmp_path / "lab")
    lab = tmp_path / "lab"
    man = yaml.safe_load((lab / "manifest.yaml").read_text())

    def attempt(name, data, *needles):
        (lab / name).write_text(yaml.safe_dump(data))
        out = tmp_path / f"out_{name}"
        _one_line_exit_2(cli("fit", "--frames-from", lab / name, "--out", out), *needles)
        assert not out.exists()

    # mixed sizes
    np.save(lab / "small.npy", np.zeros((3, 10, 12), np.uint16))
    attempt("mixed.yaml", dict(man, stacks=man["stacks"] + [{"kind": "dark", "exposure_s": 2.0, "files": ["small.npy"]}]),
            "different frame sizes")
    # unreadable file
    (lab / "broken.tif").write_bytes(b"II*\x00garbage")
    attempt("broken.yaml", dict(man, stacks=[{"kind": "dark", "exposure_s": 1.0, "files": ["broken.tif"]}]), "broken.tif")
    # a missing file, a glob matching nothing, a wrong key
    attempt("missing.yaml", dict(man, stacks=[{"kind": "dark", "exposure_s": 1.0, "files": ["nope.npy"]}]), "no such file")
    attempt("glob.yaml", dict(man, stacks=[{"kind": "dark", "exposure_s": 1.0, "files": ["none_*.tif"]}]), "matches no file")
    attempt("key.yaml", dict(man, stacks=[{"kind": "dark", "exposure": 1.0, "files": ["dark_1.npy"]}]), "exposure")
    # a stack of one frame; too few flat levels for K (says which parameter and what it needs)
    np.save(lab / "one.npy", np.zeros((1, 96, 128), np.uint16))
    attempt("one.yaml", dict(man, stacks=[{"kind": "dark", "exposure_s": 1.0, "files": ["one.npy"]}]), "at least 2")
    darks = [st for st in man["stacks"] if st["kind"] == "dark"]
    attempt("nok.yaml", dict(man, stacks=darks), "system gain K", "at least 3")
    # an EMVA descriptor naming a missing file
    (tmp_path / "emva").mkdir()
    (tmp_path / "emva" / "EMVA1288_descriptor.txt").write_text("v 3.0\nn 12 128 96\nd 1000.0\ni images/gone.tif\n")
    _one_line_exit_2(cli("fit", "--frames-from", tmp_path / "emva", "--out", tmp_path / "o"), "missing file", "gone.tif")
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_fit_reads_another_tools_emva_data_set(tmp_path):
    """emva1288's own camera simulator and dataset generator (another tool: PNG or TIFF images, its descriptor
    name, Windows paths) make a data set; the fit finds the camera's K within its interval."""
    import json
    import subprocess
    import sys

    from conftest import cli

    code = (
        "import numpy as np, sys, json\n"
        "for n, f in {'asfarray': lambda a, dtype=float: np.asarray(a, dtype=dtype), 'int': int, 'float': float}.items():\n"
        "    hasattr(np, n) or setattr(np, n, f)\n"
        "from emva1288.camera.dataset_generator import DatasetGenerator\n"
        "np.random.seed(1)\n"
        "g = DatasetGenerator(steps=20, L=16, image_format='tiff', outdir=sys.argv[1], width=96, height=64, bit_depth=12, seed=1)\n"
        "print(json.dumps({'K': g.cam.K}))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code, str(tmp_path / "eg")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    k_true = json.loads(proc.stdout.strip().splitlines()[-1])["K"]
    r = cli("fit", "--frames-from", tmp_path / "eg", "--cfa", "none", "--out", tmp_path / "f")
    assert r.returncode == 0, r.stderr
    P = json.loads((tmp_path / "f" / "fit.json").read_text())["parameters"]
    lo, hi = P["system_gain_K_dn_per_e"]["ci95"]
    assert lo <= k_true <= hi, (k_true, lo, hi)
    assert (tmp_path / "f" / "fit_report.html").stat().st_size > 10_000


@pytest.mark.slow
def test_measure_then_fit_recovers_a_per_colour_crosstalk_kernel_from_spots(tmp_path):
    """`cmosnoise measure` writes a lab data set with a spot stack (single lit pixels); `fit` gives the 3 x 3
    sharing of each colour's charge. A spot shows the sharing, not the loss, so the truth is each kernel over its
    own sum, times the base's sum (100 % here). 27 elements, each 95 % interval: a true interval set misses more
    than 6 with probability 0.07 %."""
    import json

    import yaml
    from conftest import cli

    kernels = {"R": [[1, 6, 1], [6, 70, 6], [1, 6, 1]], "G": [[0.9, 4.5, 0.9], [4.5, 78.4, 4.5], [0.9, 4.5, 0.9]],
               "B": [[0.5, 2, 0.5], [2, 90, 2], [0.5, 2, 0.5]]}
    r = cli("-q", "measure", "--set", "sensor.width=192", "--set", "sensor.height=144", "--set",
            f"crosstalk.kernel_pct={json.dumps(kernels)}", "--long-frames", "8", "--levels", "12", "--out", tmp_path / "lab")
    assert r.returncode == 0, r.stderr
    assert any(st["kind"] == "spot" for st in yaml.safe_load((tmp_path / "lab" / "manifest.yaml").read_text())["stacks"])
    r = cli("fit", "--frames-from", tmp_path / "lab" / "manifest.yaml", "--no-round-trip", "--out", tmp_path / "fit")
    assert r.returncode == 0, r.stderr
    P = json.loads((tmp_path / "fit" / "fit.json").read_text())["parameters"]
    misses = 0
    for colour, k in kernels.items():
        truth = np.array(k, float) / np.sum(k) * 100
        ci = np.array(P[f"crosstalk.kernel_pct.{colour}"]["ci95_pct"])
        misses += int(np.sum((truth < ci[..., 0]) | (truth > ci[..., 1])))
    assert misses <= 6, misses
    fitted = yaml.safe_load((tmp_path / "fit" / "config.yaml").read_text())
    assert set(fitted["crosstalk"]["kernel_pct"]) == {"R", "G", "B"}
    assert "crosstalk" not in json.loads((tmp_path / "fit" / "fit.json").read_text())["not_fitted"]


def test_k_uncertainty_widens_the_parameters_in_electrons_only():
    """A parameter in e- or e-/s is a DN figure over K: its interval gains K's relative error in quadrature. K
    itself (DN per e-), percentages and ppm keep theirs."""
    from cmosnoise.analysis.fit import _include_gain_uncertainty
    from cmosnoise.analysis.fit_readout import Z95

    P = {"system_gain_K_dn_per_e": {"value": 0.4, "ci95": [0.39, 0.41], "method": "k"},
         "row_noise.sigma_e": {"value": 2.0, "ci95": [1.9, 2.2], "method": "r"},
         "dark_current[45 C].mean_e_per_s": {"value": 50.0, "ci95": [49.0, 51.0], "method": "d"},
         "dark_current[45 C].tail.ppm_above": {"value": 80.0, "ci95": [20.0, 200.0], "method": "p"},
         "prnu.sigma_pct": {"value": 1.0, "ci95": [0.99, 1.01], "method": "g"},
         "full_well_e": {"value": 9000.0, "ci95": None, "method": "f"}}
    before = {k: dict(v) for k, v in P.items()}
    _include_gain_uncertainty(P, 0.01)
    g = Z95 * 0.01 * 2.0
    assert P["row_noise.sigma_e"]["ci95"] == pytest.approx([2.0 - math.hypot(0.1, g), 2.0 + math.hypot(0.2, g)])
    assert P["dark_current[45 C].mean_e_per_s"]["ci95"] == pytest.approx([50 - math.hypot(1, Z95 / 2), 50 + math.hypot(1, Z95 / 2)])
    for name in ("system_gain_K_dn_per_e", "dark_current[45 C].tail.ppm_above", "prnu.sigma_pct", "full_well_e"):
        assert P[name] == before[name], name


def test_a_fitted_value_outside_the_schema_is_written_clipped_and_says_so():
    """No silent clipping: what the configuration cannot hold is written at its limit, and the parameter says
    what was written and why; a value inside is written as it is, with nothing added."""
    from cmosnoise.analysis.fit import _written

    P = {"prnu.sigma_pct": {"value": 130.0, "method": "m"}, "column_noise.gain_sigma_pct": {"value": 2.0, "method": "m"}}
    assert _written(P, "prnu.sigma_pct", 0.0, 100.0) == 100.0 and P["prnu.sigma_pct"]["written"] == 100.0
    assert "config.yaml has 100" in P["prnu.sigma_pct"]["method"]
    assert _written(P, "prnu.sigma_pct", 0.0, 100.0) == 100.0 and P["prnu.sigma_pct"]["method"].count("config.yaml") == 1
    assert _written(P, "column_noise.gain_sigma_pct", 0.0, 50.0) == 2.0
    assert P["column_noise.gain_sigma_pct"] == {"value": 2.0, "method": "m"}


@pytest.mark.slow
def test_a_14_bit_adc_in_a_16_bit_range_is_fitted_as_one(tmp_path):
    """The ZWO ASI294MM writes its 14-bit ADC's codes times 4 in 16 bits. `measure` of its preset (linear here:
    the photon-transfer K of a nonlinearity is another matter) and `fit` from it: the codes' spacing says 14 bits
    in 16, the quantizer's 4^2/12 DN^2 (not 1/12) comes out of the read noise, so its total holds the configured
    1.9 e- within its interval (with 1/12 it would sit at sqrt(1.9^2 + 16/12/4.545^2 - 1/12/4.545^2) = 1.916 e-,
    four half-widths out); and the preset's gain table, whose row would set K and the noise again, gives way to
    the fitted values."""
    import json

    import yaml
    from conftest import cli

    r = cli("-q", "measure", "--preset", "zwo-asi294mm", "--set", "sensor.width=160", "--set", "sensor.height=120",
            "--set", "nonlinearity.enabled=false", "--levels", "16", "--out", tmp_path / "lab")
    assert r.returncode == 0, r.stderr
    r = cli("fit", "--frames-from", tmp_path / "lab" / "manifest.yaml", "--preset", "zwo-asi294mm", "--no-round-trip",
            "--out", tmp_path / "fit")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "fit" / "fit.json").read_text())
    assert (doc["meta"]["bits"], doc["meta"]["output_bits"], doc["meta"]["step_dn"]) == (14, 16, 4)
    fitted = yaml.safe_load((tmp_path / "fit" / "config.yaml").read_text())
    assert (fitted["adc"]["bits"], fitted["adc"]["output_bits"]) == (14, 16)
    assert not fitted.get("gain_table") and fitted["sensor"].get("gain_db") is None
    total = doc["parameters"]["source_follower.read_noise_total_e"]
    lo, hi = total["ci95"]
    # the truth inside; what a 1/12 DN^2 quantizer would have left in the read noise (15/12 DN^2 more) outside
    assert lo <= 1.9 <= hi < math.sqrt(1.9**2 + 15 / 12 / 4.545**2), total
    k = doc["parameters"]["system_gain_K_dn_per_e"]
    assert k["ci95"][0] <= 4.545 <= k["ci95"][1], k
