"""ISO 12233 e-SFR (#61) against the analytic MTF of a Gaussian blur sampled by square pixels of 100 % fill, its
MTF50's bias under noise, and bad edges in one line."""

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import ndtr
from scipy.stats import norm

from cmosnoise.analysis import sfr
from cmosnoise.errors import CmosnoiseError
from cmosnoise.model import charts


def blurred_edge(shape, angle_deg, sigma, low=0.1, high=0.4, sub=48):
    """A straight edge through the centre, tilted ``angle_deg`` from vertical, blurred by a Gaussian of ``sigma``
    pixels, each pixel the mean over its square: exact across the edge (the integral of the normal CDF,
    u Phi(u) + phi(u)), ``sub`` samples down each pixel."""
    rows, cols = shape
    t, cth = np.tan(np.radians(angle_deg)), np.cos(np.radians(angle_deg))
    s = sigma / cth  # the blur's width along a row

    def psi(u):
        return u * ndtr(u) + norm.pdf(u)

    c = np.arange(cols)[None, :]
    y = (np.arange(rows)[:, None] + (np.arange(sub)[None, :] + 0.5) / sub).reshape(-1, 1)
    xe = cols / 2 + (y - rows / 2) * t
    v = s * (psi((c + 1 - xe) / s) - psi((c - xe) / s))
    return low + (high - low) * v.reshape(rows, sub, cols).mean(axis=1)


def analytic(f, sigma):
    return np.exp(-2 * np.pi**2 * sigma**2 * f**2) * np.sinc(f)


@pytest.mark.parametrize("sigma", [0.3, 0.6, 1.0, 2.0])
@pytest.mark.parametrize("angle", [5.0, -5.0, 8.0])
def test_the_sfr_of_a_gaussian_blurred_edge_is_the_analytic_mtf(sigma, angle):
    r = sfr.esfr(blurred_edge((120, 120), angle, sigma))
    m = r.frequency <= 0.5
    assert np.abs(r.sfr[m] - analytic(r.frequency[m], sigma)).max() < 0.02
    assert r.angle_deg == pytest.approx(angle, abs=0.05)
    want50 = brentq(lambda f: analytic(f, sigma) - 0.5, 1e-4, 2.0) if sigma > 0 else None
    assert r.mtf50 == pytest.approx(want50, rel=0.01)
    assert r.mtf_nyquist == pytest.approx(analytic(0.5, sigma), abs=0.02)


def test_an_ideal_edge_has_the_pixels_sinc_and_a_dark_to_light_edge_the_same():
    img = charts.edge((100, 100), 5.0, 0.1, 0.4)[..., 0]
    r = sfr.esfr(img)
    m = r.frequency <= 0.5
    assert np.abs(r.sfr[m] - np.sinc(r.frequency[m])).max() < 0.02
    flipped = sfr.esfr(img[:, ::-1])  # light on the left
    assert flipped.mtf50 == pytest.approx(r.mtf50, rel=1e-3) and flipped.angle_deg == pytest.approx(-5.0, abs=0.05)
    assert 0 < r.above_nyquist < 0.5


def test_mtf50s_bias_at_snr_50_is_under_2_percent():
    # SNR 50: the edge's step over the noise's sigma. 24 seeds; the bias is the mean's distance from the analytic
    # MTF50, its standard error about 1 % / sqrt(24) of the spread seen (some 1 %): the 2 % bound is many of them
    sigma = 1.0
    clean = blurred_edge((100, 100), 5.0, sigma)
    want = brentq(lambda f: analytic(f, sigma) - 0.5, 1e-4, 2.0)
    got = [sfr.esfr(clean + np.random.default_rng(seed).normal(0, 0.3 / 50, clean.shape)).mtf50 for seed in range(24)]
    assert abs(np.mean(got) / want - 1) < 0.02
    assert np.std(got) / want < 0.05  # and it is a measurement, not a constant


@pytest.mark.parametrize("img, region, needle", [
    (np.full((40, 40), 0.3), None, "contrast"),
    (charts.edge((40, 40), 5.0, 0.30, 0.36)[..., 0], None, "contrast"),
    (charts.edge((40, 40), 5.0)[..., 0], (0, 50, 0, 40), "not inside"),
    (charts.edge((40, 40), 0.2)[..., 0], None, "degrees from vertical"),
    (charts.edge((6, 40), 5.0)[..., 0], None, "at least 8 rows"),
    (np.zeros((3, 4, 5)), None, "2-D"),
])
def test_bad_edges_are_one_line(img, region, needle):
    with pytest.raises(CmosnoiseError, match=needle) as info:
        sfr.esfr(img, region)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("pattern", ["RGGB", "GBRG", "none"])
def test_the_raw_channels_mtf_of_an_edge_through_no_lens_is_the_pixels_sinc(pattern):
    # the edge drawn by exact area shares, sampled by a mosaic's pixels: the green pixels' two grids (every pixel of
    # a monochrome sensor) are images of it through the pixel's square, MTF sinc(f) in the sensor's cycles per
    # pixel up to Nyquist, within test_sfr's 0.02 (the e-SFR's own accuracy against analytic MTFs)
    from cmosnoise.model import charts as charts_mod

    img = charts_mod.edge((200, 240), 5.0, 0.1, 0.4)[..., 0]
    r = sfr.raw_channel(img, pattern, charts_mod.truth("edge", img.shape)["region"])
    band = r.frequency <= 0.5
    assert np.abs(r.sfr[band] - np.sinc(r.frequency[band])).max() < 0.02
    assert r.mtf_nyquist == pytest.approx(2 / np.pi, abs=0.02)


def test_the_sfrs_standard_error_is_its_spread_over_noise_draws():
    # 200 draws of white noise on a blurred edge: the SFR's standard deviation over them at each frequency against
    # the mean of the estimate each draw makes from its own pixels. A standard deviation from n = 200 draws has a
    # relative standard error 1 / sqrt(2 (n - 1)) = 5 %: 5 of them is 25 %, the tolerance. Only where the signal
    # stands above the noise (the estimate is the magnitude's first-order spread; far below it the Rician spread is
    # narrower); MTF50's error (the SFR's over the slope) likewise
    from scipy.ndimage import gaussian_filter

    base = gaussian_filter(charts.edge((120, 100), 5.0, 0.1, 0.4)[..., 0], 0.7)
    rng = np.random.default_rng(7)
    freqs = [0.1, 0.25, 0.5]
    values, ses, m50, m50_se = [], [], [], []
    for _ in range(200):
        r = sfr.esfr(base + rng.normal(0.0, 0.01, base.shape))
        values.append(np.interp(freqs, r.frequency, r.sfr))
        ses.append([r.se_at(f) for f in freqs])
        m50.append(r.mtf50)
        m50_se.append(r.mtf50_se)
    ratio = np.std(values, axis=0, ddof=1) / np.mean(ses, axis=0)
    assert np.all(np.abs(ratio - 1) < 0.25), ratio
    assert abs(np.std(m50, ddof=1) / np.mean(m50_se) - 1) < 0.25
    # no noise: what is left is the ESF's curvature between bin centres (the residual is taken from a linear
    # interpolation), under a tenth of the noisy draws' error
    assert sfr.esfr(base).se_at(0.25) < 0.1 * np.mean(ses, axis=0)[1]
