"""Training data in the denoising field's conventions (#78): exposures set by each camera's own saturation so the
clean signal does not clip, the exposure ratio recorded, Bayer packing and Bayer-preserving flips for any phase,
and a shuffled read of a data set that costs what an ordered one does."""

import numpy as np
import pytest
from conftest import cli

from cmosnoise.app import dataset as ds
from cmosnoise.errors import CmosnoiseError
from cmosnoise.model import cfa

CAMERAS = ("sony-a7s2", "sony-imx900", "led")


def _columns(folder) -> dict:
    cols: dict = {}
    for _, c in ds.read(folder):
        for k, v in c.items():
            cols.setdefault(k, []).extend(list(v))
    return {k: np.asarray(v) for k, v in cols.items()}


def test_the_default_exposure_does_not_clip_on_any_camera_or_gain(tmp_path):
    # 120 samples over the three cameras' gain tables (ISO 100 to 25600 of the a7S II among them): the bound is 1 %
    # of samples with more than 1 % of their pixels at the white level; none is seen (the old default, 50 to
    # 5000 e- whatever the gain, clipped 13 of 500)
    folder = tmp_path / "d"
    args = [a for cam in CAMERAS for a in ("--camera", cam)]
    r = cli("-q", "dataset", "-n", "120", "--crop", "32", *args, "--shard-size", "60", "--out", folder)
    assert r.returncode == 0, r.stderr
    c = _columns(folder)
    assert (c["clipped_share"] > 0.01).sum() <= 1, c["clipped_share"].max()
    assert set(c["camera"]) == {"sony-a7s2", "sony-imx900", "led-virtual"}
    # the level is log-uniform over the default range; the ratio is the reference level over it
    assert 0.003 <= c["level"].min() and c["level"].max() <= 0.9
    assert np.allclose(c["ratio"], 0.9 / c["level"]) and c["ratio"].max() > 30
    # the charge at the white is the level of each camera's own saturation at its gain
    sat = c["light_e"] / c["level"]
    a7 = c["camera"] == "sony-a7s2"
    assert np.ptp(sat[a7]) > 0  # one camera's saturation moves with its gain (the ADC's range in e-)


def test_light_in_electrons_is_still_taken_and_clipping_is_recorded(tmp_path):
    folder = tmp_path / "d"
    r = cli("-q", "dataset", "-n", "4", "--crop", "32", "--camera", "sony-a7s2@iso=25600", "--light",
            "5000:5000", "--out", folder)
    assert r.returncode == 0, r.stderr
    c = _columns(folder)
    assert np.allclose(c["light_e"], 5000.0) and (c["level"] > 1).all() and (c["clipped_share"] > 0.1).all()


@pytest.mark.parametrize("args, needle", [
    (["--level", "0:0.5"], "--level 0:0.5"),
    (["--level", "0.5:2"], "--allow-clipping"),
    (["--level", "0.6:0.5"], "LOW <= HIGH"),
    (["--reference-level", "0"], "--reference-level"),
])
def test_bad_exposures_are_one_line(tmp_path, args, needle):
    r = cli("dataset", "-n", "2", "--crop", "16", *args, "--out", tmp_path / "d")
    assert r.returncode == 2 and needle in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("pattern", cfa.BAYER_PATTERNS)
def test_pack_unpack_and_a_bayer_preserving_flip_keep_every_pixels_colour(pattern):
    rng = np.random.default_rng(1)
    x = rng.integers(0, 4096, (3, 8, 12)).astype(np.uint16)  # a batch of three mosaics
    assert np.array_equal(cfa.unpack(cfa.pack(x, pattern), pattern), x)
    colours = cfa.channel_map(pattern, (8, 12))
    assert [set(np.unique(c)) for c in cfa.pack(colours, pattern)] == [{0}, {1}, {1}, {2}]  # R, Gr, Gb, B
    for axis in ("rows", "columns"):
        flipped = cfa.bayer_flip(colours, pattern, axis)
        assert np.array_equal(flipped, cfa.channel_map(pattern, flipped.shape))  # each pixel its own colour
        values = cfa.bayer_flip(x, pattern, axis)
        assert values.shape[1:] == flipped.shape  # and the values go with their pixels
    crop, phase = cfa.bayer_crop(x, pattern, 1, 0, 4, 4)
    assert phase == cfa.crop_pattern(pattern, 1, 0) and np.array_equal(crop, x[:, 1:5, 0:4])


def test_bad_phases_and_shapes_are_one_line():
    for call, needle in [(lambda: cfa.pack(np.zeros((4, 4)), "RGBG"), "a Bayer phase is one of"),
                         (lambda: cfa.pack(np.zeros((5, 4)), "RGGB"), "even number"),
                         (lambda: cfa.unpack(np.zeros((3, 2, 2)), "RGGB"), "4 channels"),
                         (lambda: cfa.bayer_flip(np.zeros((4, 4)), "RGGB", "diagonal"), "axis"),
                         (lambda: cfa.bayer_crop(np.zeros((4, 4)), "RGGB", 3, 0, 4, 4), "not inside")]:
        with pytest.raises(CmosnoiseError, match=needle) as info:
            call()
        assert "\n" not in str(info.value)


def test_a_shuffled_epoch_reads_each_sample_alone(tmp_path, monkeypatch):
    # an HDF5 shard holds one sample a chunk: a shuffled epoch reads each sample's own chunks once and decodes no
    # shard whole, so it costs what an ordered epoch does (the reader kept only the last shard it decoded, and a
    # shuffled epoch of 500 samples took 81 s against 2 s in order)
    pytest.importorskip("torch")
    from cmosnoise.torch import ShardDataset

    folder = tmp_path / "d"
    assert cli("-q", "dataset", "-n", "12", "--crop", "16", "--shard-size", "4", "--out", folder).returncode == 0
    data = ShardDataset(folder)
    ordered = [data.sample(i) for i in range(len(data))]
    whole, alone = [], []
    real_shard, real_sample = ds.read_shard, ds.read_sample
    monkeypatch.setattr(ds, "read_shard", lambda p: whole.append(p) or real_shard(p))
    monkeypatch.setattr(ds, "read_sample", lambda p, at: alone.append((p, at)) or real_sample(p, at))
    order = np.random.default_rng(0).permutation(len(data))
    shuffled = {int(i): data.sample(int(i)) for i in order}
    assert whole == [] and len(alone) == len(data)
    for i, (arrays, columns) in enumerate(ordered):
        assert all(np.array_equal(arrays[k], shuffled[i][0][k]) for k in ds.ARRAYS)
        assert columns["sample"] == shuffled[i][1]["sample"] == i


@pytest.mark.parametrize("camera", ["sony-imx900", "sony-a7s2"])
def test_a_named_camera_at_60_c_shows_its_white_pixels_in_the_mask(camera):
    # 2048 x 2048 pixels at 60 C for 1 s: the mask's white pixels are as many as the dark-current model expects
    # above its threshold (the assumed tail's 50 ppm, moved with the temperature, and the body's pixels above it),
    # within 5 standard deviations of the binomial count
    from cmosnoise import Sensor, load_config
    from cmosnoise.analysis import ground_truth as gt

    c = load_config(preset=camera, overrides=["sensor.width=2048", "sensor.height=2048", "sensor.temperature_c=60",
                                              "exposure.integration_time_s=1"])
    sensor = Sensor(c, seed=3)
    mask = gt.mask(sensor)
    seen = int(((mask & gt.MASK_BITS["white"]) > 0).sum())
    p = sensor.dark_state.expected_ppm_above() * 1e-6
    want, sd = p * mask.size, (p * (1 - p) * mask.size) ** 0.5
    assert 50e-6 <= p < 200e-6 and abs(seen - want) < 5 * sd, (seen, want, sd)


def test_a_temperature_on_a_camera_without_dark_current_says_so(tmp_path):
    r = cli("dataset", "-n", "2", "--crop", "16", "--camera", "led", "--temperature", "50:60", "--out", tmp_path / "d")
    assert r.returncode == 0, r.stderr
    said = [x for x in (r.stdout + r.stderr).splitlines() if "--temperature" in x]
    assert len(said) == 1 and "no dark-current model" in said[0] and "led" in said[0], r.stdout + r.stderr
