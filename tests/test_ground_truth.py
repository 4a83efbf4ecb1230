"""The ground truth is what it claims: frames average to the expected raw, the mask is the defects placed."""

import numpy as np
import pytest
from conftest import Z

from cmosnoise import Sensor
from cmosnoise.analysis import ground_truth as gt
from cmosnoise.model.stages import defects

DEFECTS = {"enabled": True, "dead_ppm": 5000, "stuck_ppm": 5000, "low_gain_ppm": 5000, "high_gain_ppm": 5000,
           "clusters": {"ppm": 2000}, "columns": {"offset_ppm": 20000, "gain_ppm": 20000, "stuck_ppm": 10000},
           "rows": {"offset_ppm": 20000, "gain_ppm": 10000, "stuck_ppm": 5000}}


def small(**over):
    cfg = {"sensor": {"width": 96, "height": 80}, "defects": DEFECTS,
           "source_follower": {"rts": {"enabled": True, "ppm": 20000, "cds": False}},
           "dark_current": {"rts": {"enabled": True, "ppm": 20000}}}
    cfg.update(over)
    return Sensor(cfg)


@pytest.mark.slow
def test_the_mean_of_2000_frames_converges_to_the_expected_raw():
    # a ramp from dark to past the full well: the black level, the mid range and both clips
    sensor = small(exposure={"integration_time_s": 0.03, "peak_rate_e_per_s": 6e5})
    shot = sensor.expose("ramp")
    truth = gt.truth(shot)
    n = 2000
    total = np.zeros(sensor.shape)
    square = np.zeros(sensor.shape)
    slow = (truth.mask & (gt.MASK_BITS["telegraph"] | gt.MASK_BITS["blinking"])) > 0
    grand = np.zeros(n)  # each frame's mean departure from the truth over the pixels
    for k in range(n):
        f = shot.frame(k).astype(np.float64)
        total += f
        square += f * f
        grand[k] = np.mean((f - truth.expected_raw)[~slow])
    mean = total / n
    sd = np.sqrt(np.maximum(square / n - mean**2, 0.0) * n / (n - 1))
    # each pixel's mean has standard error sd / sqrt(n) (sd: its own sample sd over the frames). The stationary
    # random telegraph pixels are left out (their states persist over frames); a near-deterministic pixel
    # (stuck, clipped) has sd ~ 0: its mean must equal the expectation to within the quantizer's spread, so sd is
    # taken at least 0.3 DN. The largest |z| of N pixels is below Z + sqrt(2 ln N) (a union bound).
    se = np.maximum(sd, 0.3) / np.sqrt(n)
    z = (mean - truth.expected_raw) / se
    bound = Z + np.sqrt(2 * np.log(sensor.shape[0] * sensor.shape[1]))
    assert np.abs(z[~slow]).max() < bound, np.unravel_index(np.abs(z * ~slow).argmax(), z.shape)
    # no bias over the pixels: the frames are independent, so the grand mean's standard error is the sd of the
    # per-frame means over sqrt(n) (the row and column noise a frame's pixels share included)
    assert abs(grand.mean()) < Z * grand.std(ddof=1) / np.sqrt(n)
    clipped = truth.expected_raw >= sensor.transfer.max_code - 0.5
    assert clipped.any() and (~clipped).any()


def test_the_mask_is_the_defects_placed():
    sensor = small()
    d = sensor.fixed_pattern.defects
    m = gt.mask(sensor)
    cols = sensor.shape[1]
    for kind in (defects.DEAD, defects.STUCK, defects.LOW_GAIN, defects.HIGH_GAIN):
        want = np.zeros(sensor.shape, bool)
        index = d.kind_of(kind)[0].astype(np.int64)
        want[index // cols, index % cols] = True
        assert np.array_equal((m & kind) > 0, want), kind
    want = np.zeros(sensor.shape, bool)
    want[d.cluster_index.astype(np.int64) // cols, d.cluster_index.astype(np.int64) % cols] = True
    assert np.array_equal((m & gt.MASK_BITS["cluster"]) > 0, want)
    assert np.array_equal(np.nonzero(((m & gt.MASK_BITS["bad_column"]) > 0).all(axis=0))[0], d.columns.index)
    assert np.array_equal(np.nonzero(((m & gt.MASK_BITS["bad_row"]) > 0).all(axis=1))[0], d.rows.index)
    white = sensor.dark_rate > gt.white_threshold(sensor)
    assert np.array_equal((m & gt.MASK_BITS["white"]) > 0, white)
    # a region's mask is that region of the whole one (couplets across its edge included)
    assert np.array_equal(gt.mask(sensor, (13, 61, 7, 90)), m[13:61, 7:90])


BRIGHT = {"exposure": {"integration_time_s": 0.03, "peak_rate_e_per_s": 6e5}}


@pytest.mark.parametrize("over", [
    {}, BRIGHT, {"read_noise": {"enabled": True, "distribution": "normal", "scale_dn": 0.3}},
    # the ADC's top below the full well, as LED's virtual cameras have it: the top code within reach of a wide
    # noise (the clipped normal)
    {**BRIGHT, "adc": {"gain_dn_per_e": 4.0}},
    # the full well 1 DN below the top code: the clipped charge's readout within 2 DN of it (the sum over codes;
    # 3655 of its pixels)
    {**BRIGHT, "adc": {"gain_dn_per_e": 0.4035}},
    # no temporal noise at all, the top below the full well: the quantizer's rint at the top (7240 pixels)
    {**BRIGHT, "adc": {"gain_dn_per_e": 4.0}, "shot_noise": {"enabled": False}, "row_noise": {"enabled": False},
     "column_noise": {"enabled": False}, "source_follower": {"enabled": False, "rts": {"enabled": False}}}],
    ids=["plain", "bright", "fine-read", "top-below-fw", "fw-at-top", "top-noiseless"])
def test_the_compiled_passes_give_the_numpy_paths_bits(over, monkeypatch):
    """The pixels far from a clip take one compiled pass (ground_truth._far_pixels), those near one another
    (_near_pixels); without numba the NumPy functions make every pixel. The same bits: clips reached (a bright
    ramp: the full well, and the ADC's top code where it lies below the full well), and below 1 DN of noise
    (the quantizer's sum over codes)."""
    shot = small(**over).expose("ramp")
    compiled = gt.expected_raw(shot)
    monkeypatch.setattr(gt, "_far_pixels", None)
    assert np.array_equal(compiled, gt.expected_raw(shot))


def test_the_near_pixels_shortcuts_are_taken_by_the_cases_held_to_the_numpy_bits():
    """_near_pixels' shortcuts (a pixel 10 sigma and 2 codes above the top code, from bounds alone; the full
    well out of reach, its case weighed by an exact 0; the charge 9 sigma below the full well, untruncated) are
    taken by pixels of the "top-below-fw" case above, so that test holds them to the NumPy path's bits; where the
    first is taken, the NumPy path gives the top code."""
    from cmosnoise.analysis import noise_budget

    shot = small(**{**BRIGHT, "adc": {"gain_dn_per_e": 4.0}}).expose("ramp")
    sensor, t = shot.sensor, shot.sensor.transfer
    terms = noise_budget.readout_terms(sensor, exposure=shot)
    p = {k: np.broadcast_to(np.asarray(terms[k], np.float64), sensor.shape)
         for k in ("mean_n", "shot", "read", "col_read", "row_off", "col_off", "gain")}
    out, near = np.empty(sensor.shape, np.float32), np.zeros(sensor.shape, bool)
    gt._far_pixels(*p.values(), terms["fw"], terms["top"], float(t.gain_dn_per_e), float(t.black_level_dn),
                   float(t.max_code), out, near)
    above, out_of_reach, far_below = [], 0, 0
    for i, j in zip(*np.nonzero(near)):
        mn, sh = p["mean_n"][i, j], p["shot"][i, j]
        if gt._above_top(mn, sh, p["read"][i, j], p["col_read"][i, j], p["row_off"][i, j], p["col_off"][i, j],
                         p["gain"][i, j], terms["fw"], float(t.gain_dn_per_e), float(t.black_level_dn),
                         float(t.max_code)):
            above.append((i, j))
        elif terms["fw"] - mn > 8.5 * np.sqrt(sh):
            out_of_reach += 1
            s = np.sqrt(max(sh, 1e-300))
            far_below += gt._far_below_fw((terms["fw"] - mn) / s, mn, s)
    assert len(above) > 0 and out_of_reach > 0 and far_below > 0, (len(above), out_of_reach, far_below)
    # the whole formula (the NumPy path's, before stuck pixels read their code) gives them the top code
    idx = tuple(np.array(above).T)
    assert np.all(gt._codes(noise_budget.near_moments(sensor, terms, idx, codes=True), t) == t.max_code)


def test_far_below_the_full_well_the_truncation_is_exactly_none():
    """Where _far_below_fw holds (a >= 9 sigma below the full well, mean > 0.05 sigma), the NumPy path's
    truncated normal (noise_budget._truncated_below) and full-well weight (1 - ndtr) are exactly (mn, sh) and 0,
    as the shortcut takes them: over means from 0.05 sigma to 1e6 e-, sigmas from 1e-3 to 1e3 e- and a from 9 to
    40, edges included, not one differs in a bit. Just inside the bound (a = 8), the weight is not 0."""
    from cmosnoise.analysis import noise_budget

    rng = np.random.default_rng(9)
    s = np.concatenate([10 ** rng.uniform(-3, 3, 200000), [1e-3, 1.0, 1e3]])
    a = np.concatenate([rng.uniform(9.0, 40.0, 200000), [9.0, 9.0, 9.0]])
    mn = np.concatenate([s[:-3] * 10 ** rng.uniform(np.log10(0.05), 6, 200000), np.nextafter(0.05 * s[-3:], 1)])
    mn = np.minimum(mn, 1e6)
    sh = s * s
    fw = mn + a * np.sqrt(sh)
    a_pix = (fw - mn) / np.sqrt(sh)
    take = np.array([gt._far_below_fw(x, m, q) for x, m, q in zip(a_pix, mn, np.sqrt(sh))])
    assert take.mean() > 0.99, take.mean()  # the draws are where the shortcut is taken (a rounds within 1e-15)
    m_b, v_b = noise_budget._truncated_below(mn[take], sh[take], fw[take])
    assert np.array_equal(m_b, mn[take]) and np.array_equal(v_b, sh[take])
    assert np.all(1.0 - noise_budget._cdf(a_pix[take]) == 0.0)
    assert 1.0 - noise_budget._cdf(8.0) > 0.0


def test_the_expected_code_series_are_the_sum_over_codes():
    """adc.expected_code's Fourier series (0.25 to 1 DN of noise) and codes' tails (below) against the plain
    sum over 25 codes of n P(round(x) = n), near code 10 where that sum's rounding is a few 1e-15: within 2e-14
    (the truncation of either series is below 1e-17 DN); the compiled pass's per-pixel form gives the same."""
    from scipy.special import ndtr

    from cmosnoise.model.stages.adc import expected_code

    rng = np.random.default_rng(5)
    mu = np.concatenate([rng.uniform(10, 11, 20000), [10.0, 10.5, 11.0]])
    sd = np.concatenate([rng.uniform(0.0, 1.0, 20000), [0.25, np.nextafter(0.25, 0), 0.999]])
    centre = np.round(mu)
    plain = sum((centre + d) * (ndtr((centre + d + 0.5 - mu) / sd) - ndtr((centre + d - 0.5 - mu) / sd))
                for d in range(-12, 13))
    got = expected_code(mu, sd)
    assert np.abs(got - plain).max() < 2e-14
    one = np.array([gt._expected_code(m, s) for m, s in zip(mu[:2000], sd[:2000])])
    assert np.abs(one - got[:2000]).max() < 2e-14


def test_the_perfect_image_is_the_scene_on_an_ideal_pixel():
    sensor = small()
    shot = sensor.expose("ramp")
    truth = gt.truth(shot)
    t = sensor.transfer
    np.testing.assert_array_equal(truth.perfect_e, shot.perfect_e.astype(np.float32))
    expect = np.clip(t.black_level_dn + t.gain_dn_per_e * np.minimum(shot.perfect_e, sensor.config.sensor.full_well_e),
                     0, t.max_code)
    np.testing.assert_allclose(truth.perfect_dn, expect, rtol=1e-6)


def test_an_adc_in_a_wider_range_has_its_expected_codes_a_step_apart():
    """With a 10-bit ADC written in 16 bits (codes 64 DN apart) and less noise than a step, the quantizer's
    pattern is most of what a pixel's mean shows: 400 frames average to the expected raw within the same bound
    as above (each pixel's mean within Z standard errors plus the union bound over the pixels)."""
    sensor = Sensor({"sensor": {"width": 48, "height": 40}, "adc": {"bits": 10, "output_bits": 16},
                     "exposure": {"integration_time_s": 0.03, "peak_rate_e_per_s": 6e5}})
    shot = sensor.expose("ramp")
    expected = gt.expected_raw(shot)
    assert sensor.transfer.step == 64 and expected.max() > sensor.transfer.max_code - 64
    n = 400
    frames = np.stack([shot.frame(k) for k in range(n)]).astype(np.float64)
    slow = (gt.mask(sensor) & (gt.MASK_BITS["telegraph"] | gt.MASK_BITS["blinking"])) > 0
    se = np.maximum(frames.std(axis=0, ddof=1), 0.3 * 64) / np.sqrt(n)
    z = (frames.mean(axis=0) - expected) / se
    assert np.abs(z[~slow]).max() < Z + np.sqrt(2 * np.log(expected.size))
    # the pattern is there: the expectation is not the mean code (it departs by up to half a step)
    e = shot.perfect_e.astype(np.float64)
    assert np.abs(expected - (sensor.transfer.black_level_dn + sensor.transfer.gain_dn_per_e * e)).max() > 8
