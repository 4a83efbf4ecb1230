"""From raw to picture: calibration, defect correction, crosstalk compensation, demosaicing, DNG."""


import numpy as np
import pytest
import tifffile
from conftest import Z, assert_close, cli, quiet_config, temporal_variance_se
from scipy import stats

from cmosnoise import CmosnoiseError, Sensor, calibration, load_config, noise_budget, scene, white_pixels
from cmosnoise.config import ProcessingSection
from cmosnoise.io.dng import write_dng
from cmosnoise.isp.process import Processor


def processor_for(sensor, master=None, **settings):
    return Processor(ProcessingSection(**settings), sensor.raw_info(), master)


def patch_means(img, shape):
    return np.array([img[r, c].reshape(-1, img.shape[-1] if img.ndim == 3 else 1).mean(axis=0)
                     for r, c in scene.colorchecker_patches(shape)])


CASES = [("none", "bilinear")] + [(p, m) for p in ["RGGB", "BGGR", "GRBG", "GBRG"] for m in ["bilinear", "malvar2004", "menon2007"]]


@pytest.mark.parametrize("pattern,method", CASES)  # a monochrome sensor is not demosaiced
def test_noise_free_raw_processes_back_to_the_scene(pattern, method):
    shape = (240, 360)
    cfg = quiet_config(sensor={"width": shape[1], "height": shape[0], "cfa": pattern})
    sensor = Sensor(cfg)
    raw = sensor.expose("colorchecker").frame(0)
    out = processor_for(sensor, demosaic=method).render(raw).astype(np.float64)
    truth = scene.colorchecker(shape)
    # the error bound: half an ADC step (in scene-linear units) times the steepest sRGB slope
    # over the scene's levels, in 8-bit codes, plus the final rounding (0.5) and the LUT's 0.05
    t = sensor.transfer
    white_e = cfg.exposure.peak_rate_e_per_s * cfg.exposure.integration_time_s
    half_step = 0.5 / t.gain_dn_per_e / white_e
    darkest = truth.min()
    slope = (scene.linear_to_srgb(darkest + half_step) - scene.linear_to_srgb(darkest)) / half_step
    bound = 255 * half_step * slope + 0.5 + 0.05
    if pattern == "none":
        expected = scene.linear_to_srgb(truth @ scene.LUMINANCE) * 255
        assert np.abs(out - expected).max() <= bound  # pixel by pixel: no demosaicing
    else:
        expected = scene.linear_to_srgb(truth) * 255
        err = np.abs(patch_means(out, shape) - patch_means(expected, shape))
        assert err.max() <= bound, f"largest patch error {err.max():.2f} codes (bound {bound:.2f})"


@pytest.mark.parametrize("pattern", ["RGGB", "BGGR", "GRBG", "GBRG"])
def test_bilinear_demosaicing_is_colour_demosaicings(pattern):
    """The in-house bilinear (for a fast start) gives colour-demosaicing's result, edges included."""
    import colour_demosaicing as cd

    from cmosnoise.isp.reconstruction import bilinear

    img = np.random.default_rng(3).uniform(0, 4095, (37, 50))
    expected = cd.demosaicing_CFA_Bayer_bilinear(img, pattern)
    np.testing.assert_allclose(bilinear(img, pattern), expected, rtol=1e-6, atol=1e-3)

@pytest.mark.parametrize("half", [True, False], ids=["half-size", "full-size"])
@pytest.mark.parametrize("pattern", ["RGGB", "BGGR", "GRBG", "GBRG"])
def test_picture_in_one_pass_is_the_step_by_step_one(pattern, half):
    """The compiled pictures, half size (the page's, after every slider move: superpixel) and full size
    (every run's preview.png: bilinear demosaicing, edges mirrored), have the bits of black level,
    demosaicing, crosstalk compensation, white balance and sRGB done one by one, on even and odd sizes, for
    raw codes (pre view) and calibrated float images, with and without a matrix; Processor uses them in
    both views."""
    from cmosnoise.isp import reconstruction as rc

    rng = np.random.default_rng(11)
    # pictures of 128 x 129 pixels or more: enough values that an operation done in another order (one ulp
    # off) moves some 8-bit code across its lookup-table step, so the comparison sees it
    raw = rng.integers(0, 4096, (256, 258), dtype=np.uint16)  # codes below black and above white clip
    cal = rng.normal(800, 900, (257, 259)).astype(np.float32)
    mix = np.array([[1.3, -0.2, -0.1], [-0.15, 1.25, -0.1], [-0.05, -0.3, 1.35]])
    gains = np.array([1.9, 1.0, 1.4])
    steps, one_pass = (rc.superpixel, rc.superpixel_srgb8) if half else (rc.demosaic, rc.bilinear_srgb8)
    for img, offset in ((raw, 64.0), (cal, 0.0)):
        for matrix in (None, mix):
            rgb = steps((img.astype(np.float32) - np.float32(offset)) / np.float32(3000.0), pattern)
            rgb = rc.apply_matrix(rgb, matrix) if matrix is not None else rgb
            ref = rc.encode_srgb8(rgb * gains.astype(np.float32))
            shape = (img.shape[0] // 2, img.shape[1] // 2) if half else img.shape
            assert ref.shape == shape + (3,) and len(np.unique(ref)) > 200
            assert np.array_equal(one_pass(img, pattern, offset, 3000.0, matrix, gains), ref)
    if not half:
        with pytest.raises(ValueError, match="too small"):
            rc.bilinear_srgb8(raw[:4], pattern, 64.0, 3000.0, None, gains)
    sensor = Sensor(load_config(extra={"sensor": {"width": 64, "height": 48, "cfa": pattern}}), seed=2)
    frame = sensor.expose().frame(0)
    master = frame.astype(np.float32) * 0 + 70  # a flat master dark: the full view's path too
    for pre in (True, False):
        proc = processor_for(sensor, master, dark_frames=4)
        expected = rc.encode_srgb8(proc.linear_rgb(proc.cfa_image(frame, pre), half=half))
        assert np.array_equal(proc.render(frame, pre=pre, half=half), expected)


def _delta_e(rgb8_a, rgb8_b):
    import colour

    def lab(x):
        return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(np.asarray(x) / 255.0))

    return colour.delta_E(lab(rgb8_a), lab(rgb8_b), method="CIE 2000")


def test_crosstalk_compensation_restores_colorchecker_colours():
    shape = (240, 360)
    cfg = quiet_config(crosstalk={"enabled": True}, sensor={"width": shape[1], "height": shape[0], "cfa": "RGGB"})
    sensor = Sensor(cfg)
    raw = sensor.expose("colorchecker").frame(0)
    truth = patch_means(scene.linear_to_srgb(scene.colorchecker(shape)) * 255, shape)
    on = patch_means(processor_for(sensor).render(raw).astype(float), shape)
    off = patch_means(processor_for(sensor, crosstalk_compensation=False).render(raw).astype(float), shape)
    de_on, de_off = _delta_e(on, truth), _delta_e(off, truth)
    print(f"\ncolorchecker mean dE2000: compensation on {de_on.mean():.2f} (max {de_on.max():.2f}), "
          f"off {de_off.mean():.2f} (max {de_off.max():.2f})")
    assert de_on.max() < 1.0  # below a just-noticeable difference
    assert de_off.mean() > 3.0  # visibly desaturated
    # desaturated: the chroma of the coloured patches drops without compensation
    def chroma(x):
        return x.max(axis=1) - x.min(axis=1)

    assert np.all(chroma(off[:18]) <= chroma(truth[:18]) + 1.5)


def test_dark_calibration_leaves_only_temporal_noise():
    n = 16
    cfg = load_config(overrides=["sensor.temperature_c=65", "exposure.integration_time_s=0.25",
                                 "sensor.width=640", "sensor.height=480"])
    sensor = Sensor(cfg, seed=1)
    master = calibration.master_dark(sensor.dark_frames(n))
    raw = sensor.expose("flat:0").frame(0)
    before = calibration.subtract_black(raw, sensor.transfer.black_level_dn).astype(np.float64)
    after = processor_for(sensor, master, dark_frames=n).cfa_image(raw).astype(np.float64)
    temporal = noise_budget.budget(sensor, 0.0)["temporal_total_dn"] ** 2
    expected = temporal * (1 + 1 / n)  # the frame's noise plus what is left in the master dark
    se = temporal_variance_se(sensor, 1) * (1 + 1 / n)
    assert_close(after.var(), expected, se, "residual spatial variance after dark calibration")
    assert before.var() > 20 * expected  # the DCNU dominated before


def _defects_after(method, sensor, shot, raw, master):
    k = sensor.transfer.gain_dn_per_e
    p = processor_for(sensor, master, dark_frames=8, defects={"method": method})
    residual = p.cfa_image(raw) - shot.photo_mean_e * k
    bad = np.abs(residual) > 150 * k  # 6 sigma of photon + dark shot + read noise (~25 e-)
    return bad.sum(), white_pixels.count_couplets(bad, sensor.cfa)


@pytest.mark.slow
def test_median_removes_single_white_pixels_but_not_couplets_and_the_map_removes_both():
    cfg = load_config(preset="paper-fig9-5m")
    sensor = Sensor(cfg, seed=0)
    shot = sensor.expose()
    raw = shot.frame(0)
    master = calibration.master_dark(sensor.dark_frames(8))
    bad0, couplets0 = _defects_after("off", sensor, shot, raw, master)
    bad_med, couplets_med = _defects_after("median", sensor, shot, raw, master)
    bad_map, couplets_map = _defects_after("map", sensor, shot, raw, master)
    print(f"\nfig9-5m after dark calibration: off {bad0} defects / {couplets0} couplets; "
          f"median {bad_med} / {couplets_med}; map {bad_map} / {couplets_map}")
    singles0 = bad0 - 2 * couplets0
    singles_med = bad_med - 2 * couplets_med
    assert couplets0 >= 10 and singles0 > 1000
    # Requirements on the correctors, not estimates (measured: 2528 singles and 19 couplets, 31 and 18
    # after the median, none after the map): the median replaces a lone defect by its neighbours (95 % of
    # singles at least; what stays sits on scene detail the 3x3 median cannot follow) and cannot see a
    # pair, whose partner is in its window (70 % of couplets stay at least)
    assert singles_med <= 0.05 * singles0
    assert couplets_med >= 0.7 * couplets0
    # The map names every white pixel, so what stays is the 6-sigma residual's false alarms: a normal tail
    # of 2e-9 a pixel, 0.01 expected over 5 Mpixel; Poisson at the Z-sigma level allows none
    n = raw.size
    assert couplets_map == 0 and bad_map <= stats.poisson.isf(2 * stats.norm.sf(Z), n * 2 * stats.norm.sf(6))


@pytest.mark.parametrize("pattern", ["RGGB", "GBRG", "none"])
def test_dng_reads_back_through_rawpy(tmp_path, pattern):
    rawpy = pytest.importorskip("rawpy")
    cfg = load_config(overrides=[f"sensor.cfa={pattern}", "sensor.width=96", "sensor.height=64"])
    sensor = Sensor(cfg)
    raw = sensor.expose().frame(0)
    p = processor_for(sensor)
    write_dng(tmp_path / "f.dng", raw, pattern, 64, 4095, p.mixing)
    with rawpy.imread(str(tmp_path / "f.dng")) as r:
        np.testing.assert_array_equal(r.raw_image, raw)
        assert r.black_level_per_channel == [64] * 4 and r.white_level == 4095
        if pattern != "none":
            desc = r.color_desc.decode()
            seen = "".join(desc[i] for i in r.raw_pattern.ravel())
            assert seen == pattern
            assert r.postprocess().shape == (64, 96, 3)  # LibRaw decodes it
        else:
            assert r.num_colors == 1


def test_simulate_writes_processed_outputs_and_dngs(tmp_path):
    from cmosnoise.app.run import simulate

    cfg = load_config(preset="paper-fig9-vga", overrides=["run.frames=3", "run.dng=true", "sensor.width=160", "sensor.height=120"])
    s = simulate(cfg, tmp_path / "o")
    names = sorted(p.name for p in (tmp_path / "o").iterdir())
    assert names == ["config.yaml", "dng", "master_dark.tiff", "preview.png", "processed.mp4", "processed.png", "raw.tiff", "summary.json"]
    assert sorted(p.name for p in (tmp_path / "o" / "dng").iterdir()) == [f"frame_{k:06d}.dng" for k in range(3)]
    import imageio.v2 as iio2

    assert iio2.get_reader(tmp_path / "o" / "processed.mp4").count_frames() == 3
    assert s["processing"]["dark_frames"] == 8 and s["processing"]["defects"] == "median"


def test_simulate_says_what_the_processing_left_as_the_sweep_counts_it(tmp_path):
    """`simulate --process` prints (and summary.json holds) the pixels more than 150 e- off the scene after dark
    calibration and correction, and the couplets among them: the paper's Fig. 9 count, which the sweep's
    residual_defects and couplets_after_correction and the docs' figures take from the same function. At 65 C
    the median corrector leaves pixels that the defect map removes."""
    import json

    args = ["simulate", "--preset", "paper-fig9-vga", "--set", "sensor.temperature_c=65", "--set",
            "exposure.integration_time_s=0.25", "--set", "sensor.width=320", "--set", "sensor.height=240"]
    said = {}
    for method in ("median", "map"):
        r = cli(*args, "--set", f"processing.defects.method={method}", "--out", tmp_path / method)
        assert r.returncode == 0, r.stderr
        said[method] = json.loads((tmp_path / method / "summary.json").read_text())["processing"]["left"]
        line = next(x for x in r.stdout.splitlines() if x.startswith("processing left"))
        assert line == (f"processing left {said[method]['pixels']} pixels more than 150 e- off the scene in frame 0, "
                        f"{said[method]['couplets']} couplets among them (8 dark frames, defects {method})")
    assert said["median"]["pixels"] > said["map"]["pixels"] and said["map"]["couplets"] == 0
    assert said["median"]["pixels"] >= 2 * said["median"]["couplets"]
    # the same count by hand from the API
    cfg = load_config(preset="paper-fig9-vga", overrides=["sensor.temperature_c=65", "exposure.integration_time_s=0.25",
                                                          "sensor.width=320", "sensor.height=240"])
    sensor = Sensor(cfg)
    shot = sensor.expose()
    master = calibration.master_dark(sensor.dark_frames(8))
    out = processor_for(sensor, master, dark_frames=8, defects={"method": "median"}).cfa_image(shot.frame(0))
    k = sensor.transfer.gain_dn_per_e
    bad = np.abs(out - shot.photo_mean_e * k) > 150 * k
    assert said["median"]["pixels"] == int(bad.sum())
    assert said["median"]["couplets"] == white_pixels.count_couplets(bad, sensor.cfa)


def test_process_command_reproduces_the_simulators_processing(tmp_path):
    import imageio.v3 as iio

    from cmosnoise.app.run import simulate

    cfg = load_config(preset="paper-fig9-vga", overrides=["sensor.width=160", "sensor.height=120"])
    simulate(cfg, tmp_path / "sim")
    r = cli("process", tmp_path / "sim" / "raw.tiff",
                        "--dark", tmp_path / "sim" / "master_dark.tiff", "--set", "processing.defects.method=median",
                        "--out", tmp_path / "proc")
    assert r.returncode == 0, r.stderr
    np.testing.assert_array_equal(iio.imread(tmp_path / "proc" / "processed.png"), iio.imread(tmp_path / "sim" / "processed.png"))


MINE = ("import numpy as np\n"
        "CALLS = []\n"
        "def flat(raw, meta):\n"
        "    CALLS.append((raw.shape, meta['cfa'], meta['black_level_dn']))\n"
        "    return np.full(raw.shape, meta['black_level_dn'] + 7.0)\n"
        "def wrong(raw):\n"
        "    return raw[1:]\n")


def test_ones_own_corrector_runs_in_the_chain_in_raw_dn(tmp_path, monkeypatch):
    """A corrector named by processing.defects.corrector (or --corrector) takes raw DN, black included, and gives
    raw DN back: one that returns black + 7 everywhere leaves 7 DN above black in the CFA image, after the
    built-in method, in the API, `simulate --corrector` and `process --corrector` alike."""
    import imageio.v3 as iio

    (tmp_path / "mine_fix.py").write_text(MINE)
    monkeypatch.syspath_prepend(str(tmp_path))
    import mine_fix

    sensor = Sensor({"sensor": {"width": 32, "height": 24}, "processing": {"defects": {"method": "median",
                                                                                        "corrector": "mine_fix:flat"}}})
    proc = Processor(sensor.config.processing, sensor.raw_info())
    raw = sensor.expose("photo").frame(0)
    assert np.array_equal(proc.cfa_image(raw), np.full(raw.shape, 7.0, np.float32))
    assert mine_fix.CALLS[-1] == ((24, 32), "RGGB", float(sensor.transfer.black_level_dn))
    assert np.array_equal(proc.cfa_image(raw, pre=True), raw.astype(np.float32) - sensor.transfer.black_level_dn)
    # a callable given to the Processor, and the same through the commands
    given = Processor(ProcessingSection(), sensor.raw_info(), corrector=lambda r, m: r * 0 + m["black_level_dn"])
    assert not given.cfa_image(raw).any()
    r = cli("-q", "simulate", "--preset", "paper-fig9-vga", "--set", "sensor.width=64", "--set", "sensor.height=48",
            "--corrector", "mine_fix:flat", "--out", tmp_path / "sim", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    picture = iio.imread(tmp_path / "sim" / "processed.png")
    assert picture.std() == 0  # one flat grey: the corrector's frame
    r = cli("-q", "process", tmp_path / "sim" / "raw.tiff", "--corrector", "mine_fix:flat", "--out",
            tmp_path / "proc", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert iio.imread(tmp_path / "proc" / "processed.png").std() == 0


COUNTING = """
import os

def fix(raw, meta):
    with open(os.environ["CORRECTOR_CALLS"], "a") as fh:
        fh.write("x")
    return raw
"""


@pytest.mark.parametrize("frames", [1, 3])
def test_simulate_corrects_each_frame_once(tmp_path, monkeypatch, frames):
    """Frame 0's corrected CFA image feeds its picture, its video frame and the count of defects left: one's own
    corrector runs once a frame (it ran twice on frame 0)."""
    (tmp_path / "counting_fix.py").write_text(COUNTING)
    monkeypatch.syspath_prepend(str(tmp_path))
    calls = tmp_path / "calls"
    monkeypatch.setenv("CORRECTOR_CALLS", str(calls))
    r = cli("-q", "simulate", "--set", "sensor.width=64", "--set", "sensor.height=48", "--frames", str(frames),
            "--corrector", "counting_fix:fix", "--out", tmp_path / "sim", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert calls.read_text() == "x" * frames


@pytest.mark.parametrize("settings", [{}, {"demosaic": "malvar2004"}, {"white_balance": {"mode": "grey_world"}},
                                      {"defects": {"method": "median"}}])
@pytest.mark.parametrize("half", [False, True])
def test_a_picture_from_its_corrected_cfa_image_is_the_raw_frames(settings, half):
    sensor = Sensor({"sensor": {"width": 96, "height": 64}})
    raw = sensor.expose("photo").frame(0)
    one, other = processor_for(sensor, **settings), processor_for(sensor, **settings)
    for _ in range(2):  # grey world's gains are set by the first picture: the second takes the one-pass loop
        assert np.array_equal(one.render(raw, half=half), other.render_cfa(other.cfa_image(raw), half=half))


@pytest.mark.parametrize("spec, needle", [
    ("nosuchmodule_xyz:f", "processing.defects.corrector 'nosuchmodule_xyz:f': cannot load it"),
    ("justaname", "expected module:function"),
    ("mine_fix:wrong", "processing.defects.corrector 'mine_fix:wrong' returned shape (23, 32)"),
])
def test_a_bad_corrector_is_one_line(tmp_path, spec, needle):
    (tmp_path / "mine_fix.py").write_text(MINE)
    r = cli("simulate", "--set", "sensor.width=32", "--set", "sensor.height=24", "--corrector", spec,
            "--out", tmp_path / "o", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "o").exists()


def _run(*args):
    return cli(*args)


@pytest.mark.parametrize("case,needle", [
    ("float", "pixel type float32 is not raw data"),
    ("4d", "is not raw frames"),
    ("darksize", "master dark is 20 x 30 but the raw frames are 40 x 60"),
    ("demosaic", "processing.demosaic = 'ahd'"),
    ("nometa", "does not record cfa, black_level_dn, bits"),
    ("mapnodark", "needs a master dark"),
])
def test_process_bad_input_is_one_clear_line(tmp_path, case, needle):
    good = (np.arange(40 * 60) % 4000).reshape(40, 60).astype(np.uint16)
    meta = {"cfa": "RGGB", "black_level_dn": 64, "bits": 12}
    path = tmp_path / "raw.tiff"
    args = []
    if case == "float":
        tifffile.imwrite(path, good.astype(np.float32), metadata=meta)
    elif case == "4d":
        tifffile.imwrite(path, np.zeros((2, 2, 40, 60), np.uint16), metadata=meta)
    else:
        tifffile.imwrite(path, good, metadata=meta if case != "nometa" else None)
    if case == "darksize":
        tifffile.imwrite(tmp_path / "dark.tiff", np.zeros((20, 30), np.uint16))
        args = ["--dark", tmp_path / "dark.tiff"]
    if case == "demosaic":
        args = ["--set", "processing.demosaic=ahd"]
    if case == "mapnodark":
        args = ["--set", "processing.defects.method=map"]
    r = _run("process", path, *args, "--out", tmp_path / "out")
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


def test_raw_reader_takes_2d_and_3d_codes_and_refuses_other_data(tmp_path):
    import tifffile

    from cmosnoise.io.raw_tiff import RawTiffReader

    tifffile.imwrite(tmp_path / "one.tif", np.zeros((4, 6), np.uint16))
    tifffile.imwrite(tmp_path / "three.tif", np.arange(72, dtype=np.uint8).reshape(3, 4, 6), photometric="minisblack")
    tifffile.imwrite(tmp_path / "float.tif", np.zeros((5, 4, 6), np.float64))
    with RawTiffReader(tmp_path / "one.tif") as r:
        assert len(r) == 1 and r.shape == (4, 6)
    with RawTiffReader(tmp_path / "three.tif") as r:
        frames = list(r)
        assert len(frames) == 3 and frames[2].dtype == np.uint16 and frames[2][0, 0] == 48
    with pytest.raises(CmosnoiseError, match="not raw data"):
        RawTiffReader(tmp_path / "float.tif")


@pytest.mark.parametrize("method", ["bilinear", "malvar2004", "menon2007"])
@pytest.mark.parametrize("pattern", ["RGGB", "GBRG"])
def test_demosaicing_leaves_no_colour_fringe_on_the_border(pattern, method):
    """A grey flat field demosaics to grey everywhere, the outermost rows and columns included."""
    from cmosnoise.isp.reconstruction import demosaic
    from cmosnoise.model import cfa

    levels = np.array([0.3, 0.6, 0.45])  # a neutral grey seen through channels of different responsivity
    img = levels[cfa.channel_map(pattern, (24, 30))]
    rgb = demosaic(img, pattern, method)
    np.testing.assert_allclose(rgb, np.broadcast_to(levels, rgb.shape), atol=1e-6)
