"""`cmosnoise quality`: the metric registry through the charts at each illuminance, its outputs and --compare."""

import csv
import io
import json
import math

import numpy as np
import pytest
from conftest import cli

from cmosnoise import load_config
from cmosnoise.analysis import quality, snr_light

#: small charts: the tests' speed (the metrics' estimates are then noisier than a run's defaults)
SMALL = {"flat": (96, 96), "edge": (96, 96), "colorchecker": (120, 180)}
BASE = ["sensor.quantum_efficiency=0.6", "sensor.width=640", "sensor.height=480"]


def _measure(overrides=(), lux=(1.0, 10.0, 100.0), seed=0, **kw):
    return quality.measure(load_config(overrides=[*BASE, *overrides]), lux, frames=4, sizes=SMALL, seed=seed, **kw)


def test_every_metric_of_the_table_is_measured_at_each_illuminance_and_more_light_is_better():
    r = _measure()
    assert list(r["metrics"]) == [m.name for m in quality.METRICS]
    assert all(len(v) == 3 for v in r["metrics"].values())
    snr, vn = r["metrics"]["snr_green"], r["metrics"]["visual_noise_l"]
    assert vn[0] > vn[1] > vn[2]
    # the raw green SNR is snr_light's estimator on the same sensor and frames (the same seed and patch size):
    # the same numbers, and the same SNR10 (tests/test_snr_light.py holds that estimator to the model)
    curve = snr_light.snr_curve(quality.with_light(load_config(overrides=BASE))[0], r["lux"], frames=4,
                                shape=SMALL["flat"])
    assert snr == curve["snr_measured"] and r["snr10_lux"] == curve["snr10_lux"]
    # against the model: each pixel's variance over 4 frames has 3 degrees of freedom, averaged over the N green
    # pixels its relative standard error is sqrt(2 / (3 N)), the SNR's half that; the mean's share is
    # 1 / (SNR sqrt(4 N)). Within 5 of them at each illuminance
    n = SMALL["flat"][0] * SMALL["flat"][1] // 2
    for m, p in zip(snr, r["metrics"]["snr_green_predicted"]):
        assert abs(m / p - 1) < 5 * (0.5 * math.sqrt(2 / (3 * n)) + 1 / (p * math.sqrt(4 * n))), (m, p)
    # the photo-charge grows tenfold from 10 to 100 lux: SNR = s / sqrt(s + c) grows by sqrt(10) (shot noise
    # alone) to 10 (read noise alone); the ratio of two measured SNRs has sqrt(2) times one's relative error
    rel = 5 * math.sqrt(2) * 0.5 * math.sqrt(2 / (3 * n))
    assert math.sqrt(10) * (1 - rel) < snr[2] / snr[1] < 10 * (1 + rel)
    assert r["light_switched_on"] and (r["f_number"], r["illuminant"]) == (2.8, "D65")
    assert r["picture_rows"] == 480 and r["visual_threshold_l"] > 0


def test_two_runs_that_differ_in_nothing_the_charts_see_differ_by_exactly_nothing():
    """The same seed gives the same random numbers wherever the parameters agree: a change the charts do not see
    (the video's frame rate) leaves every metric's bits."""
    a = _measure(lux=(10.0,))
    b = _measure(["processing.video_fps=24"], lux=(10.0,))
    assert a["metrics"] == b["metrics"]


@pytest.mark.slow
def test_a_hot_sensor_is_clearly_noisier_in_low_light_through_the_command(tmp_path):
    r = cli("-q", "quality", *sum((["--set", s] for s in BASE), []), "--compare-set", "sensor.temperature_c=65",
            "--lux", "1,100", "--frames", "3", "--instances", "3", "--out", tmp_path / "q")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "q" / "quality.json").read_text())
    d = doc["difference"]["visual_noise_l"]
    # at 1 lux the dark current of 65 C (16 x 25 C's) adds noise beyond the instances' spread, and the increase is
    # itself visible (above the just-detectable visual noise); at 100 lux it is not
    threshold = doc["a"]["visual_threshold_l"]
    assert d[0]["clear"] and d[0]["mean"] > threshold
    assert abs(d[1]["mean"]) < threshold
    assert doc["b"]["metrics"]["snr_green"][0] < doc["a"]["metrics"]["snr_green"][0]


@pytest.mark.slow
def test_the_outputs_iterate_the_table_so_a_new_metric_is_one_row(tmp_path, monkeypatch):
    """A metric added to METRICS (one function, one row) reaches quality.json, quality.csv, the console and the
    report without any other change."""
    extra = quality.Metric("grey_mean", "grey's mean luminance", "", "higher", "flat",
                           lambda c: float(c.luminance["flat"].mean()), "a test's row")
    monkeypatch.setattr(quality, "METRICS", [*quality.METRICS, extra])
    monkeypatch.setattr(quality, "BY_NAME", {m.name: m for m in quality.METRICS})
    r = cli("quality", *sum((["--set", s] for s in BASE), []), "--lux", "10,30", "--frames", "2",
            "--out", tmp_path / "q")
    assert r.returncode == 0, r.stderr
    out = tmp_path / "q"
    doc = json.loads((out / "quality.json").read_text())
    assert doc["a"]["metrics"]["grey_mean"] == pytest.approx([0.18, 0.18], abs=1e-9)  # brought there exactly
    header = next(csv.reader(io.StringIO((out / "quality.csv").read_text())))
    assert header == ["lux"] + [f"A:{m.name}" for m in quality.METRICS]
    page = (out / "report.html").read_text()
    assert "grey&#x27;s mean luminance" in page or "grey's mean luminance" in page
    assert "grey's mean luminance" in r.stdout
    for name in ("snr.png", "visual_noise.png", "mtf.png", "colorchecker.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_an_edge_or_a_patch_that_reaches_saturation_is_not_measured_and_says_so():
    r = _measure(lux=(10.0, 3000.0))
    assert r["metrics"]["mtf50"][0] is not None and r["metrics"]["mtf50"][1] is None
    assert r["metrics"]["colour_de2000_mean"][1] is None
    assert any("3000 lux: the edge's bright side reaches saturation" in n for n in r["notes"])
    assert r["sfr"]["lux"] == 10.0  # the curve of the brightest illuminance it holds at


def test_one_qe_for_all_channels_is_named_beside_the_colour_error():
    r = _measure(lux=(30.0,))  # BASE: a flat QE of 0.6 at every wavelength
    assert any(n.startswith("a flat QE") and "times the electrons" in n for n in r["notes"])
    one = _measure(["light.spectral_qe=[[380, 0.5], [780, 0.5]]"], lux=(30.0,))
    assert any("one QE spectrum for every colour channel" in n for n in one["notes"])
    nikon = _measure(["light.enabled=true", "light.illuminance_lux=1", "light.spectral_qe=Nikon 5100 (NPL)",
                      "light.qe_peak=0.6", "light.ir_cut_nm=680"], lux=(300.0,))
    assert not any("one QE spectrum" in n for n in nikon["notes"]) and not nikon["light_switched_on"]
    # a camera's own spectra tell the patches apart: the error is a few units, not the tens of one spectrum's
    assert nikon["metrics"]["colour_de2000_mean"][0] < 5 < r["metrics"]["colour_de2000_mean"][0]


@pytest.mark.parametrize("args, needle", [
    (["--lux", "10,1"], "give increasing illuminances from 0.001"),
    (["--lux", "ten"], "--lux 'ten': give illuminances in lux"),
    (["--picture-height-cm", "-1"], "viewing conditions"),
    (["--compare-set", "sensor.temperature_c=65", "--instances", "1"], "--instances"),
])
def test_bad_input_is_one_line_and_no_folder(tmp_path, args, needle):
    r = cli("quality", *sum((["--set", s] for s in BASE), []), *args, "--out", tmp_path / "q")
    assert r.returncode == 2 and needle in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not (tmp_path / "q").exists()


def test_the_greys_luminance_is_brought_to_18_percent_after_the_dark_clamp():
    """At 65 C and 1 lux the dark signal is above the photo-signal; the optical-black clamp takes its mean
    out, so the grey's output luminance is the photo-signal's, scaled to 0.18 (an auto-exposure's level)."""
    cfg = load_config(overrides=[*BASE, "sensor.temperature_c=65"])
    cfg, _ = quality.with_light(cfg)
    cap = quality.capture(cfg, 1.0, 4, SMALL)
    y = cap.luminance["flat"]
    assert abs(float(y.mean()) - 0.18) < 1e-9
    dark = float(np.mean(cap.shots["flat"].dark_mean_e))
    photo = float(np.mean(cap.shots["flat"].photo_mean_e))
    assert dark > photo


def test_the_iso_15739_dynamic_range_is_saturation_over_the_snr1_signal():
    """With shot noise and one read noise sigma alone, SNR = s / sqrt(s + sigma^2 + q) reaches 1 at
    s1 = (1 + sqrt(1 + 4 (sigma^2 + q))) / 2 e- (q: the quantizer's 1/12 DN^2 in e-^2); the grey saturates at the
    full well (the ADC's range is wider): the ratio of their illuminances is FW / s1 exactly."""
    from conftest import quiet_config

    from cmosnoise.analysis import snr_light

    cfg = quiet_config(shot_noise={"enabled": True}, source_follower={"enabled": True, "thermal_sigma_e": 3.0,
                                                                      "flicker": {"enabled": False}},
                       sensor={"full_well_e": 8000, "quantum_efficiency": 0.5},
                       adc={"bits": 14, "full_scale_e": 9000},
                       light={"enabled": True, "illuminance_lux": 10})
    dr = snr_light.dynamic_range(cfg)
    k = (2**14 - 1 - 64) / 9000
    s1 = (1 + math.sqrt(1 + 4 * (9.0 + 1 / 12 / k**2))) / 2
    assert dr["ratio"] == pytest.approx(8000 / s1, rel=1e-6)
    assert dr["db"] == pytest.approx(20 * math.log10(8000 / s1), rel=1e-6)


def test_the_iso_12232_noise_speed_is_ten_lux_seconds_over_the_exposure_at_snr_40_and_10():
    """A monochrome sensor with shot noise alone (and the quantizer's q = 1/12 DN^2 in e-^2): one picture's SNR
    is s / sqrt(s + q), s the grey's photo-charge, which reaches 40 at s40 = (1600 + sqrt(1600^2 + 6400 q)) / 2
    and 10 at s10 likewise; s is proportional to the lux, so the illuminances are s40 / (s per lux) and the
    speeds 10 / H, H = the grey's focal-plane exposure there (the camera equation times the integration time).

    The measured SNR: the patch's n pixels' variance in each of F frames, averaged, has relative standard error
    sqrt(2 / (F (n - 1))); the SNR half that, and the crossing's lux, proportional to SNR^2 here, the whole of it.
    log SNR is linear in log lux but for q / s < 1e-4 of curvature, far inside that. Within 5 of them."""
    from conftest import quiet_config

    cfg = quiet_config(shot_noise={"enabled": True}, sensor={"cfa": "none", "quantum_efficiency": 0.5},
                       light={"enabled": True, "illuminance_lux": 1.0})
    frames, lux = 4, (1.0, 10.0, 100.0, 1000.0, 10000.0)
    r = quality.measure(cfg, lux, frames=frames, sizes=SMALL, metrics=["snr_luminance_picture"])
    cap = quality.capture(cfg, 1.0, 2, SMALL, charts_=("flat",))
    r0, r1 = cap.patch()[0].start, cap.patch()[0].stop
    c0, c1 = cap.patch()[1].start, cap.patch()[1].stop
    n = (r1 - r0) * (c1 - c0)
    per_lux = float(np.mean(cap.shots["flat"].photo_mean_e[r0:r1, c0:c1]))  # e- of the grey at 1 lux
    k = cap.sensors["flat"].transfer.gain_dn_per_e
    q = 1 / 12 / k**2
    op = cfg.optics
    h_per_lux = (math.pi * op.transmittance / (4 * op.f_number**2)) * 0.18 / math.pi * cfg.exposure.integration_time_s
    rel = 5 * math.sqrt(2 / (frames * (n - 1)))
    ns = r["noise_speed"]
    assert ns["lux_s_per_lux"] == pytest.approx(h_per_lux, rel=1e-12)
    for name, target in (("excellent", 40.0), ("acceptable", 10.0)):
        s_t = (target**2 + math.sqrt(target**4 + 4 * target**2 * q)) / 2
        expected_lux = s_t / per_lux
        assert ns[name]["snr"] == target
        assert abs(ns[name]["lux"] / expected_lux - 1) < rel, (name, ns[name], expected_lux)
        assert ns[name]["speed"] == pytest.approx(10.0 / (ns[name]["lux"] * h_per_lux), rel=1e-12)
    # at 10 000 lux the grey clips: its noise is not measured (not an SNR of the clip's zero noise), and said
    assert r["metrics"]["snr_luminance_picture"][-1] is None
    assert any("10000 lux: the grey patch reaches saturation" in n for n in r["notes"]), r["notes"]
    # a curve that does not reach 40 gives no S40
    short = quality.measure(cfg, lux[:2], frames=frames, sizes=SMALL, metrics=["snr_luminance_picture"])
    assert short["noise_speed"]["excellent"]["speed"] is None


def test_the_threshold_search_finds_each_instances_crossing():
    """The largest column FPN at which column banding stays below 1 JND at 10 lux: each sensor instance keeps its
    random numbers as the FPN moves, so its banding is one curve, close to a line in the FPN (the threshold plot
    shows it), and 12 bisection steps put the crossing within 1/4096 of the interval: the banding there is the
    limit within the curve's rise over the whole interval divided by 4096 (the ADC's rounding adds a jitter
    well below that)."""
    cfg = load_config(overrides=BASE)
    r = quality.threshold(cfg, "column_noise.vfpn_sigma_e", 0.0, 20.0, "banding_columns", 1.0, 10.0, instances=3,
                          frames=3, sizes=SMALL)
    assert r["below_at"] == "low" and all(x is not None for x in r["crossings"])
    for s, x in enumerate(r["crossings"]):
        c = quality.merge_updates(quality.with_light(cfg)[0], {"column_noise": {"vfpn_sigma_e": x}})
        again = quality.BY_NAME["banding_columns"].compute(quality.capture(c, 10.0, 3, SMALL, s, charts_=("flat",)))
        pts = r["points"][s]  # sorted by value: the interval's ends first and last
        assert abs(again - 1.0) <= abs(pts[-1][1] - pts[0][1]) / 2**12, (again, pts[0], pts[-1])
    assert r["min"] <= r["mean"] <= r["max"] and r["se"] > 0
    # more light allows more FPN. The lines' banding (the noise's share taken out) scales as sigma / signal, so the
    # crossing is at sigma* proportional to the lux: x(100) / x(10) = 10 per instance. What is left of the noise
    # is a cross term of the lines with it, relative to the lines' banding about f0 / sqrt(columns) (f0 the noise's
    # own banding over the unit, the line means' noise at no FPN: sigma_l_with_noise; 48 columns in the patch),
    # which moves a crossing by about that: 5 of those, both illuminances', is the tolerance
    brighter = quality.threshold(cfg, "column_noise.vfpn_sigma_e", 0.0, 40.0, "banding_columns", 1.0, 100.0,
                                 instances=2, frames=3, sizes=SMALL)

    def noise_banding(lux, seed):
        cap = quality.capture(quality.merge_updates(quality.with_light(cfg)[0], {"column_noise": {"vfpn_sigma_e": 0}}),
                              lux, 3, SMALL, seed, charts_=("flat",))
        y = cap.mean_luminance["flat"][cap.banding_patch()]
        b = quality.visual_noise.banding(np.clip(y, 0, None), "columns", viewing=cap.print_view)
        return b["sigma_l_with_noise"] / b["threshold_sigma_l"]

    for s in range(2):
        f10, f100 = noise_banding(10.0, s), noise_banding(100.0, s)
        expected = r["crossings"][s] * 10
        wobble = math.hypot(f10, f100) / math.sqrt(48)
        assert abs(brighter["crossings"][s] / expected - 1) < 5 * wobble, (brighter["crossings"][s], expected)


@pytest.mark.slow
def test_the_threshold_command_says_its_sentence_and_refuses_what_it_cannot_search(tmp_path):
    sets = sum((["--set", s] for s in BASE), [])
    r = cli("quality", *sets, "--find", "column_noise.vfpn_sigma_e=0:20", "--until", "banding_columns=1",
            "--lux", "10", "--instances", "2", "--frames", "2", "--out", tmp_path / "t")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("the largest column_noise.vfpn_sigma_e at which column banding, print stays below 1 "
                               "JND")
    doc = json.loads((tmp_path / "t" / "threshold.json").read_text())
    assert doc["mean"] > 0 and (tmp_path / "t" / "threshold.png").exists()
    # nothing to cross: said, not invented
    r = cli("quality", *sets, "--find", "column_noise.vfpn_sigma_e=0:0.1", "--until", "banding_columns=1",
            "--lux", "10", "--instances", "2", "--frames", "2", "--out", tmp_path / "none")
    assert r.returncode == 0 and "does not cross 1 JND" in r.stdout, r.stdout
    for args, needle in ((["--find", "column_noise.vfpn_sigma_e=0:20"], "--find and --until go together"),
                         (["--find", "x", "--until", "banding_columns=1"], "give KEY=LOW:HIGH"),
                         (["--find", "a.b=0:1", "--until", "sharpness=1"], "'sharpness' is not a metric"),
                         (["--find", "column_noise.vfpn_sigma_e=0:20", "--until", "banding_columns=1", "--lux",
                           "1,10"], "at one illuminance")):
        r = cli("quality", *sets, *args, "--out", tmp_path / "bad")
        assert r.returncode == 2 and needle in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert not (tmp_path / "bad").exists()


def test_a_corrector_leaves_fewer_defects_than_none():
    """The defects metric counts what the processing's correction leaves of the truth's defects: without a
    correction every visible defect is left; the median corrector takes nearly all the isolated ones."""
    from cmosnoise.analysis import ground_truth, scoring

    base = [*BASE, "defects.enabled=true", "defects.dead_ppm=2000", "defects.stuck_ppm=2000"]
    per_mp = SMALL["flat"][0] * SMALL["flat"][1] / 1e6
    off = _measure([*base, 'processing.defects.method="off"'], lux=(100.0,))["metrics"]["defects_left_per_mp"][0]
    med = _measure([*base, "processing.defects.method=median"], lux=(100.0,))["metrics"]["defects_left_per_mp"][0]
    # off: the output is the frame, so every visible defect is left, exactly the count scoring finds visible
    cfg, _ = quality.with_light(load_config(overrides=[*base, 'processing.defects.method="off"']))
    cap = quality.capture(cfg, 100.0, 4, SMALL, charts_=("flat",))
    frame = cap.raw["flat"][0].astype(float)
    seen = scoring.defects_left(frame, frame, ground_truth.expected_raw(cap.shots["flat"]),
                                ground_truth.mask(cap.sensors["flat"]), cap.sensors["flat"].cfa)
    visible = sum(v["visible"] for v in seen.values())
    assert off * per_mp == pytest.approx(visible) and visible > 20  # 4000 ppm of 9216 pixels: about 37 placed
    # median: a defect survives when 4 or more of its 8 same-colour neighbours are defects too (C(8,4) p^4 =
    # 1.8e-8 at p = 0.004: none expected here), or when its departure sits at the detection threshold, where the
    # visibility's and the corrector's robust sigmas (each over about a thousand pixels) can disagree: a rare
    # case, taken as a Poisson count of mean 1 at most, so at most 1 + 5 sqrt(1) = 6 left
    assert med * per_mp <= 6 and med < off


# ------------------------------------------------------------------ verdicts a target can rest on (#74)
NO_LINES = ["row_noise.enabled=false", "column_noise.enabled=false"]


@pytest.mark.slow
def test_without_line_noise_the_default_sensor_shows_no_banding_at_any_light():
    # row and column noise off: what is left is isotropic (shot, pixel FPN), which the lines-only estimate takes
    # out. Its spread without lines is banding()'s estimate_se: each reading's squared sigma within 5 of it, and
    # every reading under 0.3 JND at 1, 10 and 100 lux over 5 sensor instances (the 1024 x 1024 flat's middle 896^2,
    # eight frames as the command takes them: 5 standard errors of the estimate are at most about 0.06 JND^2 there)
    cfg = quality.with_light(load_config(overrides=NO_LINES))[0]
    for seed in range(5):
        for lux in (1.0, 10.0, 100.0):
            cap = quality.capture(cfg, lux, 8, None, seed, charts_=("flat",))
            y = cap.mean_luminance["flat"][cap.banding_patch()]
            for axis in ("columns", "rows"):
                b = quality.visual_noise.banding(y, axis, viewing=cap.print_view)
                assert b["sigma_l"] ** 2 <= 5 * b["estimate_se"], (seed, lux, axis, b)
                assert b["visibility"] < 0.3, (seed, lux, axis, b["visibility"])


def test_the_default_sensors_colour_noise_is_larger_in_less_light():
    r = quality.measure(load_config(), [1.0, 100.0], frames=4, sizes=SMALL,
                        metrics=["visual_noise_iso15739", "visual_noise_scielab", "visual_noise_cpiq", "vsnr_scielab"])
    m = r["metrics"]
    for name in ("visual_noise_iso15739", "visual_noise_scielab", "visual_noise_cpiq"):
        assert m[name][0] > 2 * m[name][1] > 0, (name, m[name])
    assert m["vsnr_scielab"][0] < m["vsnr_scielab"][1]
    assert r["viewing"]["print"]["viewing"] == "print" and r["viewing"]["display"]["viewing"] == "display"
    assert r["colour_reference"]["reference"] == "spectral" and "Bradford" in r["colour_reference"]["adaptation"]


def test_every_measurement_works_without_any_noise(tmp_path):
    # every noise source and the ADC off: no SNR divides by a zero noise (an infinite SNR is null in JSON, a
    # vSNR says it is infinite), the MTF and the colour error are measured
    off = ["shot_noise.enabled=false", "source_follower.enabled=false", "row_noise.enabled=false",
           "column_noise.enabled=false", "dark_current.enabled=false", "prnu.enabled=false", "adc.enabled=false"]
    r = quality.measure(load_config(overrides=off), [10.0], frames=2, sizes=SMALL)
    assert r["metrics"]["snr_green"] == [None] and r["snr10_lux_side"] == "below"
    assert r["metrics"]["mtf50"][0] > 0 and r["metrics"]["mtf50_raw"][0] > 0
    assert r["metrics"]["colour_de2000_mean"][0] is not None and r["metrics"]["visual_noise_iso15739"] == [0.0]
    sets = [a for s in off + ["sensor.width=64", "sensor.height=48"] for a in ("--set", s)]
    run = cli("-q", "simulate", "-n", "2", *sets, "--out", tmp_path / "s")
    assert run.returncode == 0 and "Traceback" not in run.stderr, run.stderr
    doc = json.loads((tmp_path / "s" / "summary.json").read_text())
    assert doc["key_figures"]["dynamic_range"] is None and doc["key_figures"]["read_noise_e"] == 0.0


def test_a_setting_that_does_nothing_is_said_and_an_illuminance_switches_light_on(tmp_path):
    r = cli("-q", "simulate", "--set", "light.illuminance_lux=200", "--set", "dark_current.rts.ppm=50", "--set",
            "sensor.pixel_pitch_um=1.0", "--set", "sensor.width=64", "--set", "sensor.height=48", "--out",
            tmp_path / "s")
    assert r.returncode == 0, r.stderr
    notes = [line for line in r.stderr.splitlines() if line.startswith("cmosnoise: note:")]
    assert any("light in lux switched on" in n for n in notes)
    assert any("dark_current.rts.ppm set while dark_current.rts.enabled is false" in n for n in notes)
    assert any("sensor.pixel_pitch_um = 1.0: the dark current is per pixel" in n for n in notes)
    assert json.loads((tmp_path / "s" / "summary.json").read_text()).get("light") is not None


def test_the_read_noise_in_electrons_sets_the_thermal_part():
    # source_follower.read_noise_e: thermal^2 = total^2 - the expected other parts; an instance's own noise budget
    # (its maps' sampling: each map's mean square over 1e6 pixels, within a part in a thousand) gives it back
    import math as m

    from cmosnoise import Sensor
    from cmosnoise.analysis import figures_of_merit
    from cmosnoise.errors import CmosnoiseError

    c = load_config(overrides=["source_follower.read_noise_e=2.5", "sensor.width=1024", "sensor.height=1024"])
    got = figures_of_merit.key_figures(Sensor(c, seed=1))["read_noise_e"]
    assert got == pytest.approx(2.5, rel=2e-3)
    with pytest.raises(CmosnoiseError, match="already give") as info:
        Sensor(load_config(overrides=["source_follower.read_noise_e=0.3"]))
    assert "\n" not in str(info.value) and "at least" in str(info.value)
    del m


@pytest.mark.slow
def test_quality_with_no_options_runs_and_writes_every_metric(tmp_path):
    # the default sensor (its light switched on, its measured spectra) at the default illuminances
    r = cli("-q", "quality", "--out", tmp_path / "q")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "q" / "quality.json").read_text())
    assert set(doc["a"]["metrics"]) == {m.name for m in quality.METRICS}
    assert all(any(v is not None for v in vals) for vals in doc["a"]["metrics"].values())
