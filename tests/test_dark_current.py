"""Stage 4: dark-current non-uniformity, temperature, dark shot noise, white pixels and couplets."""

import json

import numpy as np
import pytest
from conftest import Z, assert_close, cli, quiet_config
from scipy import stats

from cmosnoise import CmosnoiseError, Sensor, dark_current, load_config, noise_budget, white_pixels
from cmosnoise.model.distributions import body
from cmosnoise.model.heavy_tail import variates
from cmosnoise.model.physics import dark_points
from cmosnoise.model.units import aa_to_e_per_s, na_per_cm2_to_e_per_s


def dark_cfg(points, shape=(1000, 1000), temperature=25.0, **extra):
    return quiet_config(
        dark_current={"enabled": True, "points": points},
        sensor={"width": shape[1], "height": shape[0], "temperature_c": temperature, "cfa": "none", **extra},
    )


FAMILIES = [
    # mean and std chosen so that clipping at 0 is negligible (P(body < 0) < 1e-12)
    ("logistic", 25, 100, 8),
    ("inverse_gaussian", 45, 60, 20),
    ("lognormal", 65, 500, 200),
    ("normal", 30, 100, 10),
    ("gamma", 40, 60, 15),
]


@pytest.mark.parametrize("family,temp,mean,std", FAMILIES)
def test_body_has_configured_moments_and_family_shape(family, temp, mean, std):
    cfg = dark_cfg([{"temperature_c": temp, "distribution": family, "mean_e_per_s": mean, "std_e_per_s": std}],
                   temperature=temp)
    m = Sensor(cfg, seed=1).fixed_pattern.dark_rate.astype(np.float64).ravel()
    n = m.size
    d = body(family, mean, std)
    kurt = float(d.stats(moments="k"))  # excess kurtosis: sets the standard error of the std
    assert_close(m.mean(), mean, std / np.sqrt(n), f"{family} mean")
    assert_close(m.std(ddof=1), std, std * np.sqrt((kurt + 2) / (4 * n)), f"{family} std")
    assert stats.kstest(m, d.cdf).pvalue > 1e-6
    if family != "normal":
        assert stats.kstest(m, stats.norm(mean, std).cdf).pvalue < 1e-12


def test_negative_body_values_are_clipped_at_zero():
    cfg = dark_cfg([{"temperature_c": 25, "distribution": "normal", "mean_e_per_s": 1, "std_e_per_s": 1}], shape=(300, 300))
    m = Sensor(cfg).fixed_pattern.dark_rate
    p0 = stats.norm(1, 1).cdf(0)
    assert m.min() == 0
    frac = (m == 0).mean()
    assert abs(frac - p0) <= Z * np.sqrt(p0 * (1 - p0) / m.size)


def _count_above(cfg):
    sensor = Sensor(cfg, seed=2)
    state = sensor.fixed_pattern.dark_state
    rate = sensor.fixed_pattern.dark_rate
    return (rate > state.threshold).sum(), rate.size, state


@pytest.mark.parametrize("preset", ["paper-fig9-vga", "paper-fig9-5m"])
def test_fig9_presets_give_4000_ppm_above_250_aA(preset):
    cfg = load_config(preset=preset)
    count, n, state = _count_above(cfg)
    assert state.threshold == pytest.approx(aa_to_e_per_s(250))
    p = 4000e-6
    assert abs(count - n * p) <= Z * np.sqrt(n * p * (1 - p)), f"{count / n * 1e6:.0f} ppm"


def test_units_aA_and_nA_per_cm2_convert():
    assert aa_to_e_per_s(1) == pytest.approx(6.241509, rel=1e-6)
    # 1 nA/cm^2 on a 2.2 um pixel: 1e-9 A/cm^2 * 4.84e-8 cm^2 / q = 302.09 e-/s
    assert na_per_cm2_to_e_per_s(1, 2.2) == pytest.approx(302.09, rel=1e-4)
    a = dark_cfg([{"temperature_c": 25, "distribution": "normal", "mean_aA": 16, "std_e_per_s": 1}], shape=(4, 4))
    b = dark_cfg([{"temperature_c": 25, "distribution": "normal", "mean_nA_per_cm2": 1, "std_e_per_s": 1}], shape=(4, 4),
                 pixel_pitch_um=2.2)
    assert dark_points(a)[0].mean == pytest.approx(16 * 6.241509, rel=1e-6)
    assert dark_points(b)[0].mean == pytest.approx(302.09, rel=1e-4)


def test_unreachable_ppm_is_rejected_with_the_reachable_range():
    point = {"temperature_c": 65, "distribution": "lognormal", "mean_e_per_s": 500, "std_e_per_s": 200,
             "tail": {"ppm_above": 100, "threshold_aA": 250, "max_e_per_s": 80000}}
    with pytest.raises(CmosnoiseError) as info:
        dark_cfg([point])
    msg = str(info.value)
    assert "dark_current.points[0].tail.ppm_above = 100" in msg and "reachable is 825.6 to" in msg


def test_rate_given_twice_or_not_at_all_is_rejected():
    with pytest.raises(CmosnoiseError, match="give mean once"):
        dark_cfg([{"temperature_c": 25, "distribution": "normal", "mean_e_per_s": 1, "mean_aA": 1, "std_e_per_s": 1}])
    with pytest.raises(CmosnoiseError, match="missing std"):
        dark_cfg([{"temperature_c": 25, "distribution": "normal", "mean_e_per_s": 1}])


# ------------------------------------------------------------------ temperature
def _default_points():
    return dark_points(load_config())


def test_between_points_each_pixel_follows_its_own_exponential_law():
    pts = _default_points()
    u = variates((50, 60), np.random.default_rng(1))
    lo, hi = pts[0].model().values(*u), pts[1].model().values(*u)
    s = dark_current.at_temperature(pts, 35.0)
    assert s.between and s.w == pytest.approx(0.5) and s.family == "logistic to inverse_gaussian"
    floor_lo, floor_hi = 1e-6 * pts[0].mean, 1e-6 * pts[1].mean
    expected = np.sqrt(np.maximum(lo, floor_lo) * np.maximum(hi, floor_hi))  # the geometric mean at w = 1/2
    np.testing.assert_allclose(s.values(*u), expected, rtol=1e-12)
    assert s.mean == pytest.approx(np.sqrt(8.0 * 50.0))  # the described parameters: log-interpolated
    at45 = dark_current.at_temperature(pts, 45.0)  # at a point: that point's model exactly
    assert not at45.between and at45.family == "inverse_gaussian"
    np.testing.assert_array_equal(at45.values(*u), hi)


def _quantiles_and_ppm(pts, t, u, thr=40.0):
    r = dark_current.at_temperature(pts, t).values(*u)
    return np.percentile(r, [1, 50, 99.9]), (r > thr).mean() * 1e6


@pytest.mark.parametrize("t", [25.0, 35.0, 45.0, 55.0, 65.0])
def test_map_is_continuous_in_temperature_at_every_point_and_midpoint(t):
    """The old model switched family at the midpoint: the median dropped 5 %, the ppm above 40 e-/s doubled."""
    pts = _default_points()
    u = variates((300, 400), np.random.default_rng(2))
    (qa, pa), (qb, pb) = (_quantiles_and_ppm(pts, t + d, u) for d in (-1e-6, 1e-6))
    # Deterministic, no sampling: a continuous law moves each pixel by its own slope times the step. The
    # slope is bounded by the secant over +-0.5 C (a jump at t would be in the secant too, and then a step
    # of 2e-6 C would still show all of it); 4 times the secant leaves room for the curvature of
    # exp(a + b T) over 1 C (b <= 0.2 /C: e**0.2 < 1.25). So a step h may move a pixel by at most
    # 4 h |secant|, plus 8 ulps of the value for the arithmetic.
    ulps = 8 * np.finfo(np.float64).eps
    lo_sec, hi_sec = (dark_current.at_temperature(pts, t + d).values(*u) for d in (-0.5, 0.5))
    secant = np.abs(hi_sec - lo_sec)  # per C
    (ql, _), (qh, _) = (_quantiles_and_ppm(pts, t + d, u) for d in (-0.5, 0.5))
    assert np.all(np.abs(qb - qa) <= 4 * 2e-6 * np.abs(qh - ql) + ulps * np.abs(qa)), (qa, qb)
    # only pixels within 4 h |secant| of the threshold can cross it in a step h
    r0 = dark_current.at_temperature(pts, t).values(*u)
    can_cross = (np.abs(r0 - 40.0) <= 4 * 2e-6 * secant + ulps * 40.0).sum()
    assert abs(pa - pb) <= can_cross / u[0].size * 1e6
    ra = dark_current.at_temperature(pts, t - 1e-3).values(*u)
    rb = dark_current.at_temperature(pts, t + 1e-3).values(*u)
    # the one designed step: below the lowest point, pixels the body clips at 0 stay 0; from it up they
    # start at the floor, 1e-6 of that point's body mean (model.md, stage 5)
    floor = np.where(ra == 0, 1e-6 * pts[0].mean, 0.0)
    assert np.all(np.abs(rb - ra) <= 4 * 2e-3 * secant + ulps * np.abs(ra) + floor)


def _no_draw():
    raise AssertionError("the pixels' variates were drawn although no pixel can cool")


def test_every_pixel_warms_with_the_default_points():
    pts = _default_points()
    u = variates((200, 300), np.random.default_rng(3))
    rates = np.stack([dark_current.at_temperature(pts, t).values(*u) for t in np.linspace(15, 75, 121)])
    step = np.diff(rates, axis=0)
    assert np.all(step >= 0)
    assert np.all(step[rates[:-1] > 0] > 0)  # strictly, except pixels the logistic body clips at 0 below 25 C
    assert dark_current.cooling_fraction(pts, _no_draw) == 0.0  # ordered points: decided without drawing pixels


@pytest.mark.slow
def test_expected_ppm_between_points_matches_the_map():
    pts = _default_points()
    u = variates((1000, 1000), np.random.default_rng(4))
    for t, thr in [(35.0, 40.0), (40.0, 60.0), (55.0, 400.0)]:
        s = dark_current.at_temperature(pts, t)
        p = s.expected_ppm_above(thr) * 1e-6
        measured = (s.values(*u) > thr).mean()
        assert abs(measured - p) <= Z * np.sqrt(p * (1 - p) / u[0].size), (t, measured, p)  # binomial


def test_points_that_cross_are_reported_as_cooling_pixels(tmp_path):
    points = [
        {"temperature_c": 25, "distribution": "normal", "mean_e_per_s": 10, "std_e_per_s": 5},
        {"temperature_c": 45, "distribution": "normal", "mean_e_per_s": 40, "std_e_per_s": 1},
    ]
    u = variates((100, 100), np.random.default_rng(5))
    assert dark_current.cooling_fraction(dark_points(dark_cfg(points)), _no_draw) == 0.0  # 10 + 5 z > 40 + z: z > 7.5
    points[0]["std_e_per_s"] = 20
    frac = dark_current.cooling_fraction(dark_points(dark_cfg(points)), lambda: u)
    expected = float(stats.norm.sf(30 / 19))  # 10 + 20 z > 40 + z where z > 30 / 19
    assert abs(frac - expected) <= Z * np.sqrt(expected * (1 - expected) / u[0].size)
    cfg = dark_cfg(points, shape=(48, 64), temperature=35.0)
    (tmp_path / "c.yaml").write_text(cfg.to_yaml())
    r = cli("simulate", "--config", tmp_path / "c.yaml", "--scene", "flat:0", "--frames", "1", "--out", tmp_path / "o")
    assert r.returncode == 0, r.stderr
    d = json.loads((tmp_path / "o" / "summary.json").read_text())["dark_current"]
    assert d["cooling_fraction"] > 0 and "cool" in d["warning"]


def test_outside_points_the_doubling_laws_apply():
    pts = _default_points()
    at65 = dark_current.at_temperature(pts, 65.0)
    at79 = dark_current.at_temperature(pts, 79.0, doubling_c=7.0, tail_doubling_c=10.0)
    assert at79.mean == pytest.approx(at65.mean * 4)
    assert at79.std == pytest.approx(at65.std * 4)
    assert at79.tail_max == pytest.approx(at65.tail_max * 2**1.4)
    assert at79.tail_fraction == at65.tail_fraction
    at11 = dark_current.at_temperature(pts, 11.0)
    assert at11.mean == pytest.approx(8.0 / 4)


def test_map_mean_follows_temperature_through_the_sensor():
    means = {}
    for t in [20, 25, 35, 45, 65, 72]:
        cfg = load_config(overrides=[f"sensor.temperature_c={t}", "sensor.width=200", "sensor.height=200"])
        means[t] = Sensor(cfg, seed=3).fixed_pattern.dark_rate.mean()
    assert means[20] < means[25] < means[35] < means[45] < means[65] < means[72]


def test_white_pixels_stay_in_place_and_body_keeps_rank_across_temperature_and_exposure():
    no_tails = [{k: v for k, v in p.items() if k != "tail"} for p in load_config().to_dict()["dark_current"]["points"]]
    body, tail, fulls = {}, {}, {}
    for t in [25, 35, 45, 65, 75]:
        size = [f"sensor.temperature_c={t}", "sensor.width=500", "sensor.height=400"]
        full = Sensor(load_config(overrides=size), seed=4).fixed_pattern.dark_rate.astype(np.float64)
        body[t] = Sensor(load_config(overrides=size, extra={"dark_current": {"points": no_tails}}), seed=4).fixed_pattern.dark_rate
        tail[t] = full - body[t]  # the same seed draws the same body: the difference is there only for tail pixels
        fulls[t] = full
    members = {t: tail[t] > 1e-3 for t in tail}
    assert 0 < members[25].sum() < members[75].sum()
    temps = sorted(tail)
    for lo, hi in zip(temps, temps[1:]):
        assert np.all(members[hi][members[lo]]), f"a white pixel at {lo} C is gone at {hi} C"
        both = members[lo]
        assert np.all(fulls[hi][both] > fulls[lo][both])  # and every white pixel gets leakier
        pos = (body[lo] > 0) & (body[hi] > 0)
        order = np.argsort(body[lo][pos], kind="stable")
        # body ranks kept, to the map's float32 rounding: pixels tied at lo (within one float32 ulp, their
        # order lost to the stable sort) part at hi by their relative gap times the power the log-interpolated
        # body raises it to (about 1 to 2 between the default points), plus one ulp of rounding at hi: 3 ulps
        # at most (measured: 2), 4 allowed; a pixel out of rank by one per cent breaks it by 1e5
        ranked = body[hi][pos][order]
        assert np.all(np.diff(ranked.astype(np.float64)) >= -4 * np.spacing(ranked[1:]).astype(np.float64))
    # the map does not depend on the exposure time
    a = Sensor(load_config(overrides=["sensor.width=64", "sensor.height=64"]), seed=5).fixed_pattern.dark_rate
    b = Sensor(load_config(overrides=["sensor.width=64", "sensor.height=64", "exposure.integration_time_s=2"]), seed=5).fixed_pattern.dark_rate
    np.testing.assert_array_equal(a, b)


# ------------------------------------------------------------------ dark shot noise
def test_dark_shot_noise_variance_equals_mean_dark_charge():
    cfg = quiet_config(
        dark_current={"enabled": True, "shot_noise": True,
                      "points": [{"temperature_c": 65, "distribution": "lognormal", "mean_e_per_s": 300, "std_e_per_s": 100}]},
        sensor={"width": 64, "height": 64, "temperature_c": 65, "cfa": "none", "full_well_e": 1e6},
        exposure={"integration_time_s": 0.5},
    )
    sensor = Sensor(cfg, seed=6)
    shot = sensor.expose("flat:0")
    frames = 60
    e = np.stack([shot.frame(k, detail=True).electrons for k in range(frames)]).astype(np.float64)
    mu = shot.dark_mean_e.astype(np.float64)
    var = e.var(axis=0, ddof=1)
    ratio = (var / mu).mean()
    se = np.sqrt(np.mean(2 / (frames - 1) + 1 / (frames * mu)) / mu.size)
    assert_close(ratio, 1.0, se, "dark variance / dark mean")
    # with dark shot noise off the dark charge is the same every frame
    cfg_off = cfg.model_copy(update={"dark_current": cfg.dark_current.model_copy(update={"shot_noise": False})})
    shot = Sensor(cfg_off, seed=6).expose("flat:0")
    np.testing.assert_array_equal(shot.frame(0, detail=True).electrons, shot.frame(1, detail=True).electrons)


# ------------------------------------------------------------------ couplets
def test_couplets_are_same_colour_neighbours():
    m = np.zeros((10, 10), bool)
    m[2, 2] = m[2, 4] = True  # two R pixels 2 apart: a couplet
    assert white_pixels.count_couplets(m, "RGGB") == 1
    m = np.zeros((10, 10), bool)
    m[2, 2] = m[3, 3] = True  # R and B diagonal: different colours
    assert white_pixels.count_couplets(m, "RGGB") == 0
    m = np.zeros((10, 10), bool)
    m[2, 3] = m[3, 4] = True  # G and G diagonal: a couplet
    assert white_pixels.count_couplets(m, "RGGB") == 1
    m = np.zeros((10, 10), bool)
    m[2, 2] = m[4, 4] = True  # R and R diagonal 2 away: a couplet
    assert white_pixels.count_couplets(m, "RGGB") == 1
    m = np.zeros((10, 10), bool)
    m[2, 3] = m[4, 5] = True  # G and G diagonal 2 away: not among G's 8 nearest
    assert white_pixels.count_couplets(m, "RGGB") == 0
    m = np.zeros((10, 10), bool)
    m[2, 2] = m[3, 3] = True
    assert white_pixels.count_couplets(m, "none") == 1
    pairs = white_pixels.couplet_pairs(m, "none")
    assert pairs.tolist() == [[[2, 2], [3, 3]]]


@pytest.mark.parametrize("pattern", ["RGGB", "BGGR", "GRBG", "GBRG", "none"])
def test_neighbour_pairs_closed_form_counts_every_pair(pattern):
    """The closed form equals the couplets of an all-white array, odd and even sizes, down to 1 x 1."""
    for shape in [(1, 1), (1, 6), (2, 2), (3, 3), (4, 7), (7, 4), (9, 10), (37, 51)]:
        assert white_pixels.neighbour_pairs(shape, pattern) == white_pixels.count_couplets(np.ones(shape, bool), pattern)


@pytest.mark.parametrize("pattern", ["RGGB", "GBRG", "none"])
def test_expected_couplets_for_random_placement(pattern):
    rng = np.random.default_rng(7)
    shape, p = (200, 300), 0.01
    counts = [white_pixels.count_couplets(rng.random(shape) < p, pattern) for _ in range(200)]
    # the expectation given the realised density, averaged over realisations ~ n_pairs p^2
    expected = white_pixels.expected_couplets(shape, pattern, p)
    # every possible pair: the couplets of an all-white array (counted by shifting masks, not the closed form);
    # without a CFA, the 8-neighbour pairs of 200 x 300: 200*299 + 199*300 + 2*199*299 = 238 502
    every_pair = white_pixels.count_couplets(np.ones(shape, bool), pattern)
    assert pattern != "none" or every_pair == 238_502
    assert expected == pytest.approx(every_pair * p**2, rel=1e-12)
    se = np.std(counts, ddof=1) / np.sqrt(len(counts))
    assert_close(np.mean(counts), expected, se, "couplets at random")


def test_more_couplets_at_5mp_than_vga_on_the_same_scene():
    counts, pairs = {}, {}
    for preset in ["paper-fig9-vga", "paper-fig9-5m"]:
        sensor = Sensor(load_config(preset=preset), seed=8)
        r = white_pixels.report(sensor.fixed_pattern.dark_rate, sensor.fixed_pattern.dark_state.threshold, sensor.cfa)
        counts[preset] = r["couplets"]
        pairs[preset] = white_pixels.neighbour_pairs(sensor.shape, sensor.cfa)
        # the count is what random placement at the realised density predicts (Poisson error)
        assert abs(r["couplets"] - r["couplets_expected_random"]) <= Z * np.sqrt(r["couplets_expected_random"])
    # at the same ppm the expected count scales with the number of neighbour pairs: 16.46 times more at 5 MP.
    # both counts are near-Poisson, so C5 - r Cv has variance about C5 + r^2 Cv
    ratio = pairs["paper-fig9-5m"] / pairs["paper-fig9-vga"]
    assert ratio == pytest.approx(16.46, abs=0.01)
    c5, cv = counts["paper-fig9-5m"], counts["paper-fig9-vga"]
    sd = np.sqrt(c5 + ratio**2 * cv)  # plug-in Poisson variances
    assert abs(c5 - ratio * cv) <= Z * sd, (c5, cv, ratio)
    assert c5 > 5 * cv  # the paper's point, and far inside the bound above


def test_report_from_a_dark_raw_frame_finds_the_maps_white_pixels():
    cfg = load_config(preset="paper-fig9-vga", overrides=["scene.source=flat:0"])
    sensor = Sensor(cfg, seed=9)
    raw = sensor.expose().frame(0)
    t = sensor.transfer
    rate = white_pixels.dark_rate_from_raw(raw, t.black_level_dn, t.gain_dn_per_e, cfg.exposure.integration_time_s)
    thr = sensor.fixed_pattern.dark_state.threshold
    from_raw = white_pixels.report(rate, thr, sensor.cfa)
    from_map = white_pixels.report(sensor.fixed_pattern.dark_rate, thr, sensor.cfa)
    # the frame's temporal noise moves pixels across the threshold: only those within Z sigma of it, sigma
    # the budget's dark temporal noise at the threshold's charge (its dark shot noise at thr t), in e-/s
    t_int = cfg.exposure.integration_time_s
    b = noise_budget.budget(sensor, 0.0)
    sigma = np.sqrt(b["temporal_total_e"] ** 2 - b["temporal_rms_e"].get("dark_shot", 0.0) ** 2 + thr * t_int) / t_int
    near = (np.abs(sensor.fixed_pattern.dark_rate - thr) < Z * sigma).sum()
    assert abs(from_raw["white_pixels"] - from_map["white_pixels"]) <= near
    assert from_raw["white_pixels"] > 1000


def test_summary_reports_dark_current_figures(tmp_path):
    from cmosnoise.app.run import simulate

    s = simulate(load_config(preset="paper-fig9-vga"), tmp_path / "o")
    d = s["dark_current"]
    assert d["temperature_c"] == 65 and d["threshold_aA"] == pytest.approx(250)
    assert d["ppm_expected"] == pytest.approx(4000, rel=1e-6)
    assert abs(d["map"]["ppm"] - 4000) <= Z * np.sqrt(4000e-6 / (640 * 480)) * 1e6
    for key in ["white_pixels", "couplets", "couplets_expected_random"]:
        assert key in d["frame0"] and key in d["map"]
    assert d["map_median_e_per_s"] < d["map_mean_e_per_s"]  # the tail pulls the mean up


def test_a_fixed_white_threshold_counts_at_every_temperature_against_the_same_rate(tmp_path):
    """dark_current.white_threshold_* (--white-threshold) replaces the nearest point's tail threshold in every count;
    without it each temperature counts against its own point's (100 e-/s at 25 C, 1560 e-/s = 250 aA at 65 C)."""
    from cmosnoise.analysis import figures_of_merit as fom

    shape = (400, 500)
    n = shape[0] * shape[1]
    for t, own in ((25, 100.0), (65, aa_to_e_per_s(250))):
        default = Sensor(load_config(overrides=[f"sensor.temperature_c={t}", f"sensor.width={shape[1]}",
                                                f"sensor.height={shape[0]}"]), seed=3)
        fixed = Sensor(load_config(overrides=[f"sensor.temperature_c={t}", f"sensor.width={shape[1]}",
                                              f"sensor.height={shape[0]}", "dark_current.white_threshold_aA=250"]), seed=3)
        d, f = fom.dark_current(default), fom.dark_current(fixed)
        assert d["threshold_e_per_s"] == pytest.approx(own) and f"({t:g} C)" in d["threshold_source"]
        assert f["threshold_e_per_s"] == pytest.approx(aa_to_e_per_s(250))
        assert f["threshold_source"] == "fixed by dark_current.white_threshold_aA = 250"
        np.testing.assert_array_equal(default.dark_rate, fixed.dark_rate)  # the map is the same: only the count moves
        assert f["map"]["white_pixels"] == int((fixed.dark_rate > aa_to_e_per_s(250)).sum())
        # the count is Binomial(n, p) with p the model's exceedance at the fixed threshold: within Z of its sd
        p = f["ppm_expected"] / 1e6
        assert abs(f["map"]["white_pixels"] - n * p) <= Z * np.sqrt(n * p * (1 - p))
    # the same unit converted: e-/s and aA give the same count; two units at once are refused
    a = Sensor(load_config(overrides=["dark_current.white_threshold_e_per_s=500"]), seed=1)
    assert fom.dark_map(a)["threshold_e_per_s"] == 500
    with pytest.raises(CmosnoiseError, match="white_threshold once"):
        load_config(overrides=["dark_current.white_threshold_e_per_s=500", "dark_current.white_threshold_aA=80"])
    # on the command line, with the unit; the summary and the line say which threshold counted
    r = cli("simulate", "--set", "sensor.width=64", "--set", "sensor.height=48", "--white-threshold", "250aA",
            "--frames", "1", "--out", tmp_path / "o")
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())["dark_current"]
    assert summary["threshold_aA"] == pytest.approx(250) and summary["threshold_source"].startswith("fixed")
    assert "white pixels:" in r.stdout and "fixed by dark_current.white_threshold_aA = 250" in r.stdout
    r = cli("simulate", "--set", "sensor.width=64", "--set", "sensor.height=48", "--frames", "1",
            "--out", tmp_path / "d")
    assert "nearest characterization point's (25 C) tail threshold; --white-threshold fixes one" in r.stdout
    for bad in ("12x", "-3", "nan", "250 mA"):
        r = cli("simulate", "--white-threshold", bad, "--out", tmp_path / "bad")
        assert r.returncode == 2 and "--white-threshold" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_readme_white_pixel_snippet_runs_on_what_tifffile_reads(tmp_path):
    """docs/sensor/dark-current.md's Python snippet, on a real run's raw.tiff (a (frames, rows, cols) stack)."""
    import tifffile

    out = tmp_path / "dark"
    r = cli("simulate", "--scene", "flat:0", "--frames", "4", "--set", "exposure.integration_time_s=0.25",
            "--set", "sensor.width=64", "--set", "sensor.height=48", "--out", out)
    assert r.returncode == 0, r.stderr
    raw = tifffile.imread(out / "raw.tiff")
    assert raw.shape == (4, 48, 64)
    rate = white_pixels.dark_rate_from_raw(raw, black_level_dn=64, gain_dn_per_e=0.4031, integration_time_s=0.25)
    rep = white_pixels.report(rate, threshold=1560.4, pattern="RGGB")
    assert rate.shape == (48, 64)
    # the four frames' mean rate is the sensor's dark map plus temporal noise: the snippet's count is the
    # map's, but for pixels within Z sigma of the threshold (sigma: the budget's dark temporal noise of a
    # four-frame mean at the threshold's charge, in e-/s)
    cfg = load_config(overrides=["scene.source=flat:0", "exposure.integration_time_s=0.25",
                                 "sensor.width=64", "sensor.height=48"])
    sensor = Sensor(cfg, seed=cfg.seed)
    dark_map, b = sensor.fixed_pattern.dark_rate, noise_budget.budget(sensor, 0.0)
    var = b["temporal_total_e"] ** 2 - b["temporal_rms_e"].get("dark_shot", 0.0) ** 2 + 1560.4 * 0.25
    near = (np.abs(dark_map - 1560.4) < Z * np.sqrt(var / 4) / 0.25).sum()
    assert abs(rep["white_pixels"] - int((dark_map > 1560.4).sum())) <= near
    assert white_pixels.couplet_pairs(rate > 1560.4, "RGGB").shape[1:] == (2, 2)
    with pytest.raises(CmosnoiseError, match="one \\(rows, cols\\) map"):
        white_pixels.report(raw, 10.0, "RGGB")


def test_frame0_white_pixels_do_not_count_photon_shot_noise(tmp_path):
    """The lit default run once reported 125 374 white pixels in frame 0 (408 118 ppm): photon shot noise."""
    args = ["--set", "sensor.width=320", "--set", "sensor.height=240", "--seed", "3"]
    assert cli("simulate", *args, "--out", tmp_path / "lit").returncode == 0
    assert cli("simulate", *args, "--scene", "flat:0", "--out", tmp_path / "dark").returncode == 0
    lit = json.loads((tmp_path / "lit" / "summary.json").read_text())["dark_current"]
    dark = json.loads((tmp_path / "dark" / "summary.json").read_text())["dark_current"]
    assert lit["frame0"]["method"].startswith("lit frame") and dark["frame0"]["method"].startswith("dark frame")
    n_map = lit["map"]["white_pixels"]
    assert n_map > 0
    # frame 0 counts a pixel when it stands Z sigma above the threshold's charge: a lower bound of the map's
    # count, but for false alarms of pixels under the threshold, at most the normal tail beyond Z sigma each
    # (2.9e-7); over the 76 800 pixels, Poisson with mean 0.022, allowed up to its Z-sigma quantile
    false_alarms = stats.poisson.isf(2 * stats.norm.sf(Z), 320 * 240 * stats.norm.sf(Z))
    assert lit["frame0"]["white_pixels"] <= n_map + false_alarms
    assert dark["frame0"]["white_pixels"] <= n_map + false_alarms
    # a long dark exposure, where white pixels stand far above the noise: frame 0 finds most of the map's
    assert cli("simulate", *args, "--scene", "flat:0", "--set", "exposure.integration_time_s=2",
               "--set", "sensor.full_well_e=1e6", "--out", tmp_path / "long").returncode == 0
    summary = json.loads((tmp_path / "long" / "summary.json").read_text())
    long = summary["dark_current"]
    assert long["frame0"]["white_pixels"] <= long["map"]["white_pixels"] + false_alarms
    # the count the rule should give: pixel i counts with probability P(d_i + noise > thr t + 5 sigma), where
    # d_i = rate_i t is its dark charge (Poisson, taken as normal: d_i is hundreds of e- near the threshold) and
    # sigma^2 the budget's dark temporal variance (whose dark shot part is the mean pixel's: each pixel has its own d_i);
    # the count is a sum of Bernoullis
    cfg = load_config(overrides=["sensor.width=320", "sensor.height=240", "exposure.integration_time_s=2",
                                 "sensor.full_well_e=1e6", "scene.source=flat:0"])
    sensor = Sensor(cfg, seed=3)
    t, thr = 2.0, sensor.dark_state.threshold
    d = sensor.dark_rate.astype(np.float64) * t
    var = summary["noise_budget"]["dark"]["temporal_total_e"] ** 2
    p = stats.norm.sf((thr * t + 5 * np.sqrt(var) - d) / np.sqrt(var - d.mean() + d))
    expected, sd = p.sum(), np.sqrt(np.sum(p * (1 - p)))
    assert expected > 0.5 * long["map"]["white_pixels"]  # the case is one where frame 0 can see them
    assert abs(long["frame0"]["white_pixels"] - expected) <= Z * sd, (long["frame0"]["white_pixels"], expected, sd)


def test_couplets_are_counted_as_their_definition_says():
    """Couplets from the white pixels' coordinates (white_pixels.pairs_at, what every count calls) against the
    definition checked pair by pair: two white pixels of one colour that are neighbours in their colour plane
    (R and B: a step of 2 along a row, a column or a diagonal; G: also a step of 1 on a diagonal; a monochrome
    sensor: the 8 neighbours), on random masks of every pattern, dense enough that couplets touch and chain."""
    from cmosnoise.model import cfa

    rng = np.random.default_rng(4)
    for pattern in ("RGGB", "BGGR", "GRBG", "GBRG", "none"):
        mask = rng.random((23, 31)) < 0.15
        r, c = np.nonzero(mask)
        colour = cfa.channel_map(pattern, mask.shape)
        expected = 0
        for i in range(r.size):
            for j in range(i + 1, r.size):
                dr, dc = abs(int(r[i]) - int(r[j])), abs(int(c[i]) - int(c[j]))
                if colour[r[i], c[i]] != colour[r[j], c[j]]:
                    continue
                if pattern == "none":
                    near = max(dr, dc) == 1
                elif colour[r[i], c[i]] == 1:  # green: a quincunx, its neighbours at 1 diagonal step or 2 straight
                    near = (dr, dc) in {(1, 1), (0, 2), (2, 0)}
                else:
                    near = (dr, dc) in {(0, 2), (2, 0), (2, 2)}
                expected += near
        assert expected > 10 and white_pixels.count_couplets(mask, pattern) == expected, pattern
