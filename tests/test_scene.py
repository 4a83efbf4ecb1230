"""Stage 1: scenes, decoding, resampling, CFA sampling."""

import numpy as np
import pytest
from conftest import quiet_config

from cmosnoise import CmosnoiseError, Sensor, scene


def test_srgb_round_trip_and_known_values():
    v = np.linspace(0, 1, 1001)
    np.testing.assert_allclose(scene.linear_to_srgb(scene.srgb_to_linear(v)), v, atol=1e-12)
    assert scene.srgb_to_linear(np.array(0.5)) == pytest.approx(0.21404, abs=1e-5)


def test_area_resampling_conserves_mean_light_and_is_exact_for_integer_factors():
    rng = np.random.default_rng(0)
    img = rng.uniform(0, 1, (300, 400, 3))
    out = scene.resample(img, (90, 120))  # factor 3.33
    np.testing.assert_allclose(out.mean(axis=(0, 1)), img.mean(axis=(0, 1)), rtol=1e-12)
    out2 = scene.resample(img, (150, 200))
    np.testing.assert_allclose(out2, img.reshape(150, 2, 200, 2, 3).mean(axis=(1, 3)), rtol=1e-12)


def test_upsampling_is_bilinear_and_keeps_flat_fields():
    img = np.full((10, 20, 3), 0.3)
    np.testing.assert_allclose(scene.resample(img, (37, 71)), 0.3)


def test_8bit_png_is_decoded_as_srgb(tmp_path):
    import imageio.v3 as iio

    a = np.full((20, 30, 3), 128, np.uint8)
    iio.imwrite(tmp_path / "s.png", a)
    lin = scene.load_file(tmp_path / "s.png")
    np.testing.assert_allclose(lin, scene.srgb_to_linear(np.array(128 / 255)), rtol=1e-12)


def test_npy_and_16bit_tiff_are_linear_scaled_by_max_or_given_scale(tmp_path):
    import tifffile

    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    np.save(tmp_path / "s.npy", a)
    np.testing.assert_allclose(scene.load_file(tmp_path / "s.npy")[..., 0], a / 11)
    np.testing.assert_allclose(scene.load_file(tmp_path / "s.npy", scale=22)[..., 1], a / 22)
    b = (np.arange(12).reshape(3, 4) * 1000).astype(np.uint16)
    tifffile.imwrite(tmp_path / "s.tif", b)
    np.testing.assert_allclose(scene.load_file(tmp_path / "s.tif")[..., 2], b / 11000)


def test_bad_scene_files_are_clear_errors(tmp_path):
    with pytest.raises(CmosnoiseError, match="no such file"):
        scene.load_file(tmp_path / "missing.png")
    (tmp_path / "junk.png").write_text("not an image")
    with pytest.raises(CmosnoiseError, match="cannot be read"):
        scene.load_file(tmp_path / "junk.png")
    a = np.ones((4, 4))
    a[1, 1] = np.nan
    np.save(tmp_path / "nan.npy", a)
    with pytest.raises(CmosnoiseError, match="NaN"):
        scene.load_file(tmp_path / "nan.npy")
    np.save(tmp_path / "neg.npy", -a)
    with pytest.raises(CmosnoiseError):
        scene.load_file(tmp_path / "neg.npy")
    with pytest.raises(CmosnoiseError, match="outside"):
        scene.render("flat:1.5", (4, 4))


def test_cfa_sampling_keeps_each_pixels_channel_and_responsivity():
    rgb = np.zeros((4, 4, 3))
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 0.1, 0.2, 0.3
    out = scene.to_cfa(rgb, "GRBG", (1.0, 0.5, 2.0))
    assert out[0, 0] == pytest.approx(0.1) and out[0, 1] == pytest.approx(0.1)  # G, R
    assert out[1, 0] == pytest.approx(0.6) and out[1, 1] == pytest.approx(0.1)  # B, G
    mono = scene.to_cfa(rgb, "none")
    assert mono[0, 0] == pytest.approx(0.2126 * 0.1 + 0.7152 * 0.2 + 0.0722 * 0.3)


@pytest.mark.parametrize("name", ["photo", "ramp", "colorchecker", "zoneplate", "siemens", "spot", "flat:0.25"])
def test_builtin_scenes_render_at_any_size_in_range(name):
    for shape in [(48, 64), (121, 77)]:
        img = scene.render(name, shape)
        assert img.shape == (*shape, 3)
        assert np.isfinite(img).all() and img.min() >= 0 and img.max() <= 1


def test_photo_electrons_scale_with_peak_rate_and_time():
    cfg = quiet_config(exposure={"integration_time_s": 0.5, "peak_rate_e_per_s": 2000}, sensor={"cfa": "none"})
    shot = Sensor(cfg).expose("flat:0.3")
    np.testing.assert_allclose(shot.perfect_e, 0.3 * 2000 * 0.5, rtol=1e-6)


def test_the_compiled_interleave_moves_values_only():
    """resample's planes go into the (rows, cols, 3) image by a blocked compiled copy (engine/layout.py): the
    same values as NumPy's transpose, at sizes that are not multiples of its blocks."""
    from cmosnoise.engine.layout import interleave_transposed

    rng = np.random.default_rng(2)
    planes = [rng.random((333, 517)) for _ in range(3)]  # 172 161 values a plane: the compiled path
    assert np.array_equal(interleave_transposed(planes), np.stack([p.T for p in planes], axis=-1))
    small = [rng.random((5, 7))]
    assert np.array_equal(interleave_transposed(small), small[0].T[..., None])


@pytest.mark.parametrize("pattern", ["RGGB", "BGGR", "GRBG", "GBRG", "none"])
def test_a_resampled_picture_through_the_cfa_is_the_three_channel_path_bit_for_bit(pattern):
    """Resampled.cfa applies the columns' weights only for each pixel's own channel (engine/resample.py, compiled
    above 65 536 pixels): the same bits as to_cfa of the full RGB resampling, growing and shrinking, for the whole
    and for regions at even and odd corners."""
    rng = np.random.default_rng(11)
    resp = (0.83, 1.0, 1.21)
    for img, shape in [(rng.random((40, 60, 3)), (301, 451)),     # grown: linear interpolation
                       (rng.random((900, 700, 3)), (333, 259)),   # shrunk: area averaging
                       (rng.random((20, 30, 3)), (20, 30))]:      # the same size
        picture = scene.Resampled(img, shape)
        for region in [None, (0, shape[0], 1, shape[1] - 2), (4, shape[0] - 3, 6, shape[1] // 2)]:
            got = picture.cfa(pattern, resp, region)
            want = scene.to_cfa(picture(region), pattern, resp)
            assert got.dtype == want.dtype and got.shape == want.shape
            assert np.array_equal(got.view(np.uint64), want.view(np.uint64)), (shape, region)


def test_a_sensor_takes_a_picture_through_the_cfa_without_its_full_size_rgb():
    """Sensor.scene_signal of a picture (the photo) equals to_cfa of scene.render, bit for bit, whole and in a window."""
    cfg = {"sensor": {"width": 640, "height": 480, "cfa": "GBRG"}}
    whole = Sensor(cfg).scene_signal("photo")
    want = scene.to_cfa(scene.render("photo", (480, 640)), "GBRG", Sensor(cfg).spec.channel_responsivity)
    assert np.array_equal(whole, want)
    part = Sensor(cfg, window=(100, 400, 40, 333)).scene_signal("photo")
    assert np.array_equal(part, whole[100:400, 40:333])


@pytest.mark.parametrize("pattern", ["RGGB", "GBRG", "none"])
def test_a_windows_cfa_signal_is_the_copied_windows(pattern):
    """window_cfa reads each pixel's channel from the source where it lies: the same bits as to_cfa of the
    window's copy (what a data set's crops go through)."""
    img = scene.source_image("photo", (300, 400))
    for corner, shape in [((0, 0), (300, 400)), ((17, 33), (128, 96)), ((1, 2), (5, 7))]:
        got = scene.window_cfa(img, corner, shape, pattern, (0.9, 1.0, 1.1))
        want = scene.to_cfa(scene.window_of(img, corner, shape), pattern, (0.9, 1.0, 1.1))
        assert np.array_equal(got.view(np.uint64), want.view(np.uint64))
    with pytest.raises(CmosnoiseError, match="leaves the source"):
        scene.window_cfa(img, (290, 0), (20, 20), pattern)


def test_the_compiled_cfa_pick_is_numpys_strided_product():
    """to_cfa's compiled pass (engine/layout.cfa_pick, above 65 536 pixels) equals the 2 x 2 cell's strided
    products bit for bit: float64 and float32 images, a non-contiguous view, a broadcast flat field."""
    from cmosnoise.engine.layout import cfa_pick

    rng = np.random.default_rng(4)
    cell, gain = np.array([[1, 0], [2, 1]]), np.array([0.83, 1.0, 1.21])
    images = [rng.random((301, 457, 3)), rng.random((300, 400, 3)).astype(np.float32),
              rng.random((700, 500, 3))[::2, 1::2], np.broadcast_to(np.array([0.2, 0.5, 0.7]), (333, 444, 3))]
    for rgb in images:
        want = np.empty(rgb.shape[:2])
        for (i, j), ch in np.ndenumerate(cell):
            want[i::2, j::2] = rgb[i::2, j::2, ch] * gain[ch]
        got = cfa_pick(rgb, cell, gain)
        assert got.dtype == np.float64 and np.array_equal(got.view(np.uint64), want.view(np.uint64))
