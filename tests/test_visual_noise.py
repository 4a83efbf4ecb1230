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
