"""A raw photograph as the scene (#60): its mosaic re-shot at its own gain and black level with the noise off gives
its own codes back; its colours and size are checked; a .npy mosaic and the tiles take it too."""

import numpy as np
import pytest
import tifffile
from conftest import cli

from cmosnoise import Sensor, load_config
from cmosnoise.errors import CmosnoiseError
from cmosnoise.io.dng import write_dng
from cmosnoise.model import raw_scene, tiles

QUIET = {"shot_noise": {"enabled": False}, "source_follower": {"enabled": False}, "row_noise": {"enabled": False},
         "column_noise": {"enabled": False}, "dark_current": {"enabled": False}, "prnu": {"enabled": False},
         "crosstalk": {"enabled": False}}


def _photograph(tmp_path, cfa="GRBG", shape=(96, 128), black=64.0, white=4095):
    """A DNG of a noisy photograph (another sensor's), every code at or above the black level."""
    codes = Sensor({"sensor": {"width": shape[1], "height": shape[0], "cfa": cfa},
                    "adc": {"black_level_dn": black}}, seed=5).expose("photo").frame(0)
    codes = np.maximum(codes, np.uint16(black))
    write_dng(tmp_path / "photo.dng", codes, cfa, black, white)
    return codes


def _same_camera(shape, cfa, black, white, extra=None):
    """A sensor whose scene white is the photograph's white level at K = 1 DN/e-, nothing else added."""
    t = 0.01
    return load_config(extra={**QUIET, "sensor": {"width": shape[1], "height": shape[0], "cfa": cfa,
                                                  "full_well_e": 1e6},
                              "exposure": {"integration_time_s": t, "peak_rate_e_per_s": (white - black) / t},
                              "adc": {"bits": 12, "black_level_dn": black, "gain_dn_per_e": 1.0}, **(extra or {})})


def test_a_raw_photograph_re_shot_at_its_own_gain_and_black_level_gives_its_codes(tmp_path):
    codes = _photograph(tmp_path)
    photo = raw_scene.read(tmp_path / "photo.dng")
    assert photo.pattern == "GRBG" and photo.white == 4095 and np.all(photo.black == 64)
    c = _same_camera(codes.shape, "GRBG", 64.0, 4095)
    again = Sensor(c).expose(str(tmp_path / "photo.dng")).frame(0)
    assert np.array_equal(again, codes)


def test_a_raw_photograph_in_less_light_on_another_gain_keeps_its_colours(tmp_path):
    codes = _photograph(tmp_path, cfa="RGGB")
    c = load_config(extra={"sensor": {"width": 128, "height": 96, "cfa": "RGGB"},
                           "exposure": {"peak_rate_e_per_s": 2000}})  # 60 e- at white: a dark, noisy shot
    shot = Sensor(c).expose(str(tmp_path / "photo.dng"))
    want = (codes.astype(float) - 64) / (4095 - 64) * 2000 * 0.03
    assert np.allclose(shot.perfect_e, want, rtol=1e-6, atol=1e-4)
    # the red pixels of the photograph stay the red pixels: R over G in the perfect image is the photograph's
    r, g = want[0::2, 0::2].mean(), want[0::2, 1::2].mean()
    assert shot.perfect_e[0::2, 0::2].mean() / shot.perfect_e[0::2, 1::2].mean() == pytest.approx(r / g, rel=1e-6)


def test_a_npy_mosaic_with_its_levels_and_a_window_of_a_raw(tmp_path):
    codes = _photograph(tmp_path, cfa="BGGR")
    np.save(tmp_path / "mosaic.npy", codes)
    c = _same_camera(codes.shape, "BGGR", 64.0, 4095,
                     {"scene": {"source": str(tmp_path / "mosaic.npy"), "raw_cfa": "BGGR", "raw_black_dn": 64,
                                "raw_white_dn": 4095}})
    assert np.array_equal(Sensor(c).expose().frame(0), codes)
    # a window at an odd corner sees another pattern: the sensor must say it
    w = _same_camera((40, 50), "GRBG", 64.0, 4095, {"scene": {"window": [1, 0]}})
    part = Sensor(w).expose(str(tmp_path / "photo.dng")).frame(0)
    assert np.array_equal(part, codes[1:41, 0:50])
    with pytest.raises(CmosnoiseError, match="sensor.cfa=GRBG"):
        Sensor(_same_camera((40, 50), "BGGR", 64.0, 4095, {"scene": {"window": [1, 0]}})).expose(
            str(tmp_path / "photo.dng"))


def test_a_raw_scene_in_tiles_is_the_whole(tmp_path):
    codes = _photograph(tmp_path, cfa="RGGB", shape=(100, 150))
    c = load_config(extra={"sensor": {"width": 150, "height": 100, "cfa": "RGGB"}})
    whole = Sensor(c).expose(str(tmp_path / "photo.dng")).frame(0)
    tiling = tiles.Tiling(c, 48, str(tmp_path / "photo.dng"))
    for region in tiling.regions:
        r0, r1, c0, c1 = region
        assert np.array_equal(next(tiling.frames(region, 1)), whole[r0:r1, c0:c1]), region
    assert codes.shape == whole.shape


def test_simulate_takes_a_raw_photograph(tmp_path):
    _photograph(tmp_path)
    r = cli("simulate", "--scene", tmp_path / "photo.dng", "--set", "sensor.width=128", "--set", "sensor.height=96",
            "--set", "sensor.cfa=GRBG", "--out", tmp_path / "run")
    assert r.returncode == 0, r.stderr
    assert tifffile.imread(tmp_path / "run" / "raw.tiff").shape[-2:] == (96, 128)


@pytest.mark.parametrize("make, needle", [
    (lambda p: np.save(p / "x.npy", np.zeros((4, 4, 3))), "one 2-D array"),
    (lambda p: np.save(p / "x.npy", np.full((4, 4), 5.0)), "white level"),
])
def test_bad_npy_mosaics_are_one_line(tmp_path, make, needle):
    make(tmp_path)
    with pytest.raises(CmosnoiseError, match=needle) as info:
        raw_scene.read(tmp_path / "x.npy", "RGGB", 10.0)
    assert "\n" not in str(info.value)


def test_a_raw_photograph_refuses_a_lens(tmp_path):
    _photograph(tmp_path)
    c = load_config(extra={"sensor": {"width": 128, "height": 96, "cfa": "GRBG"},
                           "optics": {"relative_illumination": "cos4"}})
    with pytest.raises(CmosnoiseError, match="already went through its own lens"):
        Sensor(c).expose(str(tmp_path / "photo.dng"))


def test_a_data_set_crops_raw_photographs_and_checks_their_colours(tmp_path):
    from cmosnoise.app import dataset as ds

    codes = _photograph(tmp_path, cfa="RGGB", shape=(96, 128))
    recipe = ds.Recipe(samples=2, crop=(32, 48), seed=3, cameras=("sony-imx900@gain_db=0",),
                       sources=(str(tmp_path / "photo.dng"),), light_e=(500.0, 500.0))
    sources = ds.Sources()
    for i in range(2):
        arrays, columns = ds.make_sample(recipe, i, sources)
        r, c = int(columns["window_row"]), int(columns["window_col"])
        want = (codes[r:r + 32, c:c + 48].astype(float) - 64) / (4095 - 64)
        # the perfect image (in DN: the black level plus K times the photo-electrons) is the photograph's crop
        perfect = np.asarray(arrays["perfect_dn"], np.float64).reshape(32, 48)
        slope, offset = np.polyfit(want.ravel(), perfect.ravel(), 1)
        assert slope > 0 and np.abs(perfect - (slope * want + offset)).max() < 1e-4 * slope
    write_dng(tmp_path / "grbg.dng", codes, "GRBG", 64.0, 4095)
    bad = ds.Recipe(samples=1, crop=(32, 48), seed=3, cameras=("sony-imx900@gain_db=0",),
                    sources=(str(tmp_path / "grbg.dng"),), light_e=(500.0, 500.0))
    with pytest.raises(CmosnoiseError, match="has the colour filters GRBG"):
        ds.make_sample(bad, 0, ds.Sources())


def test_a_data_set_refuses_light_in_lux_on_top_of_its_own_light():
    from cmosnoise.app import dataset as ds

    recipe = ds.Recipe(samples=1, crop=(32, 48), seed=3, cameras=("sony-imx900@gain_db=0",), sources=("photo",),
                       light_e=(500.0, 500.0), overrides=("light.enabled=true", "light.illuminance_lux=10"))
    with pytest.raises(CmosnoiseError, match="leave light in lux off"):
        ds.settings(recipe, 0)


def test_a_dng_without_a_colour_filter_array_is_one_line(tmp_path):
    # a linear DNG (PhotometricInterpretation LinearRaw, three samples a pixel): LibRaw reads it, with no CFA
    codes = (np.random.default_rng(0).random((32, 48, 3)) * 4000).astype(np.uint16)
    tags = [(50706, 1, 4, (1, 4, 0, 0), True), (50708, 2, 0, "linear test", True), (50717, 3, 1, (4095,), True)]
    tifffile.imwrite(tmp_path / "linear.dng", codes, photometric=34892, extratags=tags, planarconfig="contig")
    with pytest.raises(CmosnoiseError, match="no 2 x 2 Bayer colour filter array") as info:
        raw_scene.read(tmp_path / "linear.dng")
    assert "\n" not in str(info.value)
