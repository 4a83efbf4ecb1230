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


def test_the_perfect_image_is_the_scene_on_an_ideal_pixel():
    sensor = small()
    shot = sensor.expose("ramp")
    truth = gt.truth(shot)
    t = sensor.transfer
    np.testing.assert_array_equal(truth.perfect_e, shot.perfect_e.astype(np.float32))
    expect = np.clip(t.black_level_dn + t.gain_dn_per_e * np.minimum(shot.perfect_e, sensor.config.sensor.full_well_e),
                     0, t.max_code)
    np.testing.assert_allclose(truth.perfect_dn, expect, rtol=1e-6)
