"""Visual luminance noise and banding visibility (#61): zero without noise, rising with it, the analytic
CSF-weighted integral for white noise, invariant to where the patch is, and the paper's Fig. 10 statement: 6 e- of
column FPN is visible in low light and not in bright light."""

import math

import numpy as np
import pytest
from scipy.integrate import dblquad

from cmosnoise import Sensor, load_config
from cmosnoise.analysis import visual_noise as vn
from cmosnoise.errors import CmosnoiseError


def test_a_noise_free_patch_has_no_visual_noise_and_more_noise_more():
    assert vn.visual_luminance_noise(np.full((64, 80), 0.4))["sigma_l"] == 0.0
    base = np.random.default_rng(1).normal(0, 1, (128, 128))
    values = [vn.visual_luminance_noise(0.18 + s * base)["sigma_l"] for s in (0.001, 0.002, 0.004, 0.008)]
    assert all(b > a for a, b in zip(values, values[1:])) and values[0] > 0


def test_white_luminance_noise_gives_the_analytic_csf_weighted_integral():
    # L* white noise of sigma s (small: L* is linear over it): the weighted variance is s^2 times the CSF's mean
    # square over the frequency square [-1/2, 1/2]^2 cycles/pixel. The estimate's own spread: 512^2 values of a
    # smooth-spectrum field, well under 1 %; the bound is 2 %.
    ppd_rows, shape = 1080, (512, 512)
    grey, sd = 0.18, 0.001
    y = grey + np.random.default_rng(7).normal(0, sd, shape)
    got = vn.visual_luminance_noise(y, rows=ppd_rows)
    ppd = got["pixels_per_degree"]
    mean_sq, _ = dblquad(lambda fy, fx: vn.csf(math.hypot(fx, fy) * ppd) ** 2, -0.5, 0.5, -0.5, 0.5)
    s_l = 116 / 3 * grey ** (-2 / 3) * sd
    assert got["sigma_l"] == pytest.approx(s_l * math.sqrt(mean_sq), rel=0.02)
    assert got["sigma_l_unweighted"] == pytest.approx(s_l, rel=0.02)
    # the threshold unit is the same integral for 3 % noise on the grey
    assert vn.threshold_sigma_l(ppd_rows, shape) == pytest.approx(
        116 / 3 * grey ** (-2 / 3) * 0.03 * grey * math.sqrt(mean_sq), rel=0.01)


def test_visual_noise_does_not_depend_on_where_the_patch_is():
    y = 0.3 + np.random.default_rng(3).normal(0, 0.01, (96, 128))
    a = vn.visual_luminance_noise(y)["sigma_l"]
    assert vn.visual_luminance_noise(np.roll(y, (17, 40), axis=(0, 1)))["sigma_l"] == pytest.approx(a, rel=1e-12)


def test_the_papers_fig10_vfpn_is_visible_in_low_light_and_not_in_bright_light():
    # paper-fig10-vfpn: sigma_VFPN = 6 e- on bands of 78, 312, 1250 and 5000 e- (white 5000 e-), shot noise on.
    # The tolerance is the metric's own spread over sensor instances: the darkest band's visibility less 5 of its
    # standard deviations is above the threshold (1), the brightest band's plus 5 below it.
    seen = {0: [], 3: []}
    for seed in range(6):
        sensor = Sensor(load_config(preset="paper-fig10-vfpn"), seed=seed)
        t = sensor.transfer
        e = (sensor.expose().frame(0).astype(float) - t.black_level_dn) / t.gain_dn_per_e
        y = np.clip(e / 5000.0, 0, None)
        for band in seen:
            r0, r1 = band * 120 + 4, (band + 1) * 120 - 4
            seen[band].append(vn.banding(y[r0:r1], "columns", rows=480)["visibility"])
    dark, bright = np.array(seen[0]), np.array(seen[3])
    assert dark.mean() - 5 * dark.std(ddof=1) > 1.0
    assert bright.mean() + 5 * bright.std(ddof=1) < 1.0
    # and without the VFPN the dark band's columns are not visible (shot noise alone, averaged down the columns)
    plain = Sensor(load_config(preset="paper-fig10-vfpn", overrides=["column_noise.enabled=false"]), seed=0)
    e = (plain.expose().frame(0).astype(float) - 64) / plain.transfer.gain_dn_per_e
    assert vn.banding(np.clip(e[4:116] / 5000.0, 0, None), rows=480)["visibility"] < 1.0


@pytest.mark.parametrize("kwargs, needle", [({"picture_height_cm": 0}, "viewing conditions"),
                                            ({"viewing_distance_cm": -5}, "viewing conditions"),
                                            ({"axis": "diagonal"}, "axis")])
def test_bad_viewing_conditions_are_one_line(kwargs, needle):
    with pytest.raises(CmosnoiseError, match=needle) as info:
        vn.banding(np.full((16, 16), 0.2), **kwargs)
    assert "\n" not in str(info.value)
    with pytest.raises(CmosnoiseError, match="2-D patch"):
        vn.visual_luminance_noise(np.zeros(10))


# ------------------------------------------------------------------ colour visual noise (#74)
def _grey(noise=None, shape=(128, 128)):
    rgb = np.full((*shape, 3), 0.18)
    return rgb if noise is None else rgb + noise


@pytest.mark.parametrize("variant", vn.VARIANTS)
def test_a_noise_free_patch_has_no_colour_visual_noise_and_more_noise_has_more(variant):
    assert vn.visual_noise(_grey(), variant)["value"] == 0.0
    base = np.random.default_rng(2).normal(0, 1, (128, 128, 3))
    values = [vn.visual_noise(_grey(s * base), variant)["value"] for s in (0.001, 0.002, 0.004, 0.008)]
    assert values[0] > 0 and all(b > a for a, b in zip(values, values[1:])), values


def test_iso15739_of_luminance_noise_has_no_chroma_and_its_luminance_part_is_the_csf_integral():
    # pure luminance white noise: each pixel's R, G and B the same multiple of the grey, so XYZ stays on the white's
    # chromaticity, C1 = C2 = 0 exactly under E (the sRGB matrix's own white adapted by Bradford), u* = v* = 0 up to
    # the float64 sums' rounding. Its sigma(L*) is the analytic CSF-weighted integral (the luminance CSF at ISO
    # 15739:2013's scale, 3 at its peak) of white L* noise: within 2 % (512^2 values of a smooth spectrum: the
    # estimate's own spread is well under 1 %)
    grey, sd, shape = 0.18, 0.001, (512, 512)
    n = np.random.default_rng(7).normal(0, sd, shape)[..., None]
    view = vn.print_viewing(1080)
    r = vn.visual_noise(grey * (1 + n / grey) * np.ones(3), "iso15739_2013", view)
    assert r["sigma_u"] < 1e-9 and r["sigma_v"] < 1e-9
    ppd = view.pixels_per_degree
    mean_sq, _ = dblquad(lambda fy, fx: (3 * vn.csf(math.hypot(fx, fy) * ppd)) ** 2, -0.5, 0.5, -0.5, 0.5)
    s_l = 116 / 3 * grey ** (-2 / 3) * sd
    assert r["sigma_l"] == pytest.approx(s_l * math.sqrt(mean_sq), rel=0.02)
    assert vn.csf_chroma(0.0, "C1") == 1.0 and vn.csf_chroma(0.0, "C2") == 1.0


def test_chroma_noise_at_constant_luminance_raises_every_colour_variant():
    # R and B moved against each other so that Y = 0.2126 R + 0.7152 G + 0.0722 B stays the grey's
    c = np.random.default_rng(5).normal(0, 0.004, (128, 128))
    chroma = _grey()
    chroma[..., 0] += c
    chroma[..., 2] -= c * 0.2126 / 0.0722
    y = chroma @ np.array([0.2126, 0.7152, 0.0722])
    assert np.abs(y - 0.18).max() < 1e-15
    assert vn.visual_luminance_noise(y)["sigma_l"] < 1e-9  # the luminance metric does not see it
    for variant in vn.VARIANTS:
        assert vn.visual_noise(chroma, variant)["value"] > 0.01, variant


def test_scielabs_filters_sum_to_one_and_a_noise_free_patch_has_an_infinite_vsnr():
    for c in range(3):
        assert float(vn.scielab_filter(0.0, c)) == pytest.approx(1.0, abs=1e-15)
        # sampled on a fine grid, the filter's kernel sums to its response at 0
        f = np.fft.fftfreq(4096, 1 / 400.0)  # 400 samples per degree, a kernel 10 degrees wide
        kernel = np.fft.ifft(vn.scielab_filter(np.abs(f), c)).real
        assert kernel.sum() == pytest.approx(1.0, abs=1e-12)
    r = vn.visual_noise(_grey(), "scielab")
    assert r["vsnr"] == math.inf and r["value"] == 0.0


def test_bad_variants_and_viewing_conditions_are_one_line():
    for call, needle in [(lambda: vn.visual_noise(_grey(), "iso15739"), "variant = 'iso15739' is not known"),
                         (lambda: vn.display_viewing(0.0), "display_pixel_pitch_mm = 0.0"),
                         (lambda: vn.print_viewing(480, -1), "picture_height_cm = -1"),
                         (lambda: vn.visual_noise(np.zeros((8, 8)), "cpiq"), "(rows, cols, 3)")]:
        with pytest.raises(CmosnoiseError, match=needle.replace("(", r"\(").replace(")", r"\)")) as info:
            call()
        assert "\n" not in str(info.value)


# ------------------------------------------------------------------ banding of lines only (#74)
def test_white_noise_alone_reads_no_lines_within_the_estimators_spread():
    # no lines: the groups' cross estimate of the lines' variance is 0 in expectation, its standard error
    # estimate_se (derived in visual_noise.banding: 2K/(K-1) s^4 rho2 / n); 5 of them bound it. The old reading
    # (the line means' own variance, noise and all) stays as sigma_l_with_noise
    for seed in range(5):
        y = 0.18 + np.random.default_rng(seed).normal(0, 0.004, (256, 256))
        for axis in ("columns", "rows"):
            b = vn.banding(y, axis, rows=480)
            assert b["sigma_l"] ** 2 <= 5 * b["estimate_se"], (seed, axis)
            assert b["sigma_l_with_noise"] > 2 * b["sigma_l"]


def test_a_line_pattern_reads_what_the_line_means_read_without_noise():
    # lines far above the noise: the cross estimate is their filtered variance, as the line means' own is
    x = np.arange(256)
    lines = 0.003 * np.sin(2 * np.pi * x / 9.0)[None, :]
    y = 0.18 + lines + np.random.default_rng(3).normal(0, 0.0003, (256, 256))
    b = vn.banding(y, "columns", rows=480)
    clean = vn.banding(0.18 + np.broadcast_to(lines, (256, 256)), "columns", rows=480)
    assert b["sigma_l"] == pytest.approx(clean["sigma_l_with_noise"], rel=0.02)
    assert clean["sigma_l"] == pytest.approx(clean["sigma_l_with_noise"], rel=1e-9)
    # and the display reads it at its own pixels per degree
    d = vn.banding(y, "columns", viewing=vn.display_viewing())
    assert d["viewing"] == "display" and d["pixels_per_degree"] == pytest.approx(
        1 / math.degrees(2 * math.atan(0.0254 / 120)), rel=1e-12)
