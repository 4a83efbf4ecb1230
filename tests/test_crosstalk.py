"""Stage 3: diffusion crosstalk kernel on the mean."""

import numpy as np
import pytest
from conftest import quiet_config

from cmosnoise import Sensor, crosstalk, load_config
from cmosnoise.model.cfa import masks


def test_single_lit_pixel_spreads_exactly_as_the_kernel_says():
    cfg = load_config(preset="paper-fig4-crosstalk")
    shot = Sensor(cfg).expose()
    mu = shot.mean_charge_e
    peak = cfg.exposure.peak_rate_e_per_s * cfg.exposure.integration_time_s
    k = np.array(cfg.crosstalk.kernel_pct) / 100
    np.testing.assert_allclose(mu[3:6, 3:6], k * peak, rtol=1e-6)
    outside = mu.copy()
    outside[3:6, 3:6] = 0
    assert np.all(outside == 0)
    assert mu[4, 4] / peak == pytest.approx(0.784, rel=1e-6)


def test_raw_frame_of_fig4_preset_reads_the_kernel():
    cfg = load_config(preset="paper-fig4-crosstalk")
    sensor = Sensor(cfg)
    raw = sensor.capture()[0]
    e = sensor.transfer.to_electrons(raw)
    peak = cfg.exposure.peak_rate_e_per_s * cfg.exposure.integration_time_s
    k = np.array(cfg.crosstalk.kernel_pct) / 100
    # 16-bit ADC: one DN is 10000/65535 e-, rounding error at most half of that
    np.testing.assert_allclose(e[3:6, 3:6], k * peak, atol=0.5 * 10000 / 65535 + 1e-6)


def test_per_colour_kernel_follows_the_colour_where_charge_was_generated():
    kr = np.array([[0, 0.5, 0], [0, 0.5, 0], [0, 0, 0]])  # red charge: half goes up
    kg = np.array([[0, 0, 0], [0, 1.0, 0], [0, 0, 0]])
    kb = np.array([[0, 0, 0], [0, 0.9, 0], [0, 0, 0]])  # blue: 10 % lost
    mu = np.zeros((8, 8), np.float32)
    mu[4, 4] = 100  # RGGB: (even, even) is red
    mu[5, 5] = 100  # blue
    mu[4, 5] = 100  # green
    out = crosstalk.apply(mu, {"R": kr, "G": kg, "B": kb}, "RGGB")
    assert out[4, 4] == pytest.approx(50) and out[3, 4] == pytest.approx(50)
    assert out[5, 5] == pytest.approx(90)
    assert out[4, 5] == pytest.approx(100)
    assert out.sum() == pytest.approx(290)


def test_charge_is_conserved_up_to_the_kernel_sum():
    rng = np.random.default_rng(0)
    mu = np.zeros((40, 40), np.float32)
    mu[5:-5, 5:-5] = rng.uniform(0, 1000, (30, 30))
    k = np.array([[1, 3, 1], [3, 80, 3], [1, 3, 1]]) / 100
    out = crosstalk.apply(mu, k)
    assert out.sum() == pytest.approx(mu.sum() * k.sum(), rel=1e-5)


@pytest.mark.parametrize("lit", [(0, 2), (4, 2), (2, 0), (2, 4), (0, 0), (4, 4)])
def test_edges_reflect_the_charge_that_would_leave(lit):
    """A lit pixel on the border with a lopsided kernel: what would leave the array comes back into it.

    Every other edge rule gives something else here (zero padding or a
    mirrored-source convolution keeps 80 or 64 e- at a corner, wrapping moves it across).
    """
    mu = np.zeros((5, 5), np.float32)
    mu[lit] = 100.0
    k = np.array([[0, 0.2, 0], [0, 0.7, 0.1], [0, 0, 0]])  # 20 % one row up, 10 % one column right
    out = crosstalk.apply(mu, k)
    r, c = lit
    up_stays = r == 0
    right_stays = c == 4
    assert out[lit] == pytest.approx(70.0 + 20.0 * up_stays + 10.0 * right_stays)
    if not up_stays:
        assert out[r - 1, c] == pytest.approx(20.0)
    if not right_stays:
        assert out[r, c + 1] == pytest.approx(10.0)
    assert out.sum() == pytest.approx(100.0)


def test_lopsided_kernel_conserves_the_charge_it_keeps():
    mu = np.random.default_rng(1).uniform(0, 1000, (37, 41)).astype(np.float64)
    k = np.array([[0.05, 0.2, 0.0], [0.0, 0.6, 0.1], [0.0, 0.0, 0.02]])
    assert crosstalk.apply(mu, k).sum() == pytest.approx(mu.sum() * k.sum(), rel=1e-12)


def test_mixing_matrix_of_uniform_kernel():
    k = np.array([[0.9, 4.5, 0.9], [4.5, 78.4, 4.5], [0.9, 4.5, 0.9]]) / 100
    m = crosstalk.channel_mixing_matrix(k, "RGGB")
    # column j: a flat field in channel j alone. Red charge: R keeps 78.4 %;
    # every G pixel has 2 red edge neighbours; every B pixel 4 red corners.
    np.testing.assert_allclose(m[:, 0], [0.784, 2 * 0.045, 4 * 0.009])
    # green charge: R and B have 4 green edge neighbours; G keeps 78.4 % + 4 green corners
    np.testing.assert_allclose(m[:, 1], [4 * 0.045, 0.784 + 4 * 0.009, 4 * 0.045])
    # charge conservation per 2 x 2 tile (1 R, 2 G, 1 B pixels)
    counts = np.array([1, 2, 1])
    np.testing.assert_allclose(counts @ m, counts * k.sum())


def test_crosstalk_switched_off_leaves_the_mean():
    cfg = quiet_config(sensor={"width": 16, "height": 16})
    shot = Sensor(cfg).expose("ramp")
    np.testing.assert_array_equal(shot.mean_charge_e, shot.perfect_e)


def test_cfa_masks_partition_the_sensor():
    m = masks("GBRG", (4, 6))
    assert (m.sum(axis=0) == 1).all()
    assert m[1, 0, 0] and m[2, 0, 1] and m[0, 1, 0] and m[1, 1, 1]


def test_the_compiled_spread_is_ndimage_bit_for_bit():
    """engine/stencil.py replaces ndimage.convolve over the padded array: the same bits on random arrays of both
    float dtypes, tiny and odd shapes, and kernels lopsided, with zeros and with a weight below DBL_EPSILON
    (ndimage leaves such a point out of its footprint)."""
    from scipy import ndimage

    from cmosnoise.engine.stencil import framed_convolve

    rng = np.random.default_rng(0)
    kernels = [np.array([[0.9, 4.5, 0.9], [4.5, 78.4, 4.5], [0.9, 4.5, 0.9]]) / 100, rng.random((3, 3)) / 5,
               np.array([[0, 1, 0], [2, 80, 3], [0, 0.5, 0]]) / 100,
               np.array([[1e-20, 0.1, 0.0], [0.3, 0.5, 0.01], [0.0, 0, 0.02]])]
    for k in kernels:
        for shape in [(1, 1), (1, 5), (2, 2), (5, 1), (7, 9), (64, 48), (301, 457), (256, 257)]:  # compiled: >= 2**16
            for dtype in (np.float64, np.float32):
                x = (rng.random(shape) * 1000).astype(dtype)
                want = ndimage.convolve(np.pad(x, 1), np.asarray(k, dtype), mode="constant")
                got = framed_convolve(x, k)
                assert got.dtype == want.dtype and np.array_equal(got, want), (shape, dtype)
