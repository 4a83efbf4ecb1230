"""The lens (#60): PSFs that sum to 1 and put the Airy ring where diffraction does, a blur whose tiles are the
whole's crop bit for bit (a 50 MP sensor's included), relative illumination against its law and its SNR, and the
test charts with their truth."""

import math

import numpy as np
import pytest
from scipy.fft import next_fast_len
from scipy.special import jn_zeros

from cmosnoise import Sensor, load_config
from cmosnoise.errors import CmosnoiseError
from cmosnoise.model import charts, optics, scene, tiles

QUIET = ["shot_noise.enabled=false", "source_follower.enabled=false", "row_noise.enabled=false",
         "column_noise.enabled=false", "dark_current.enabled=false", "prnu.enabled=false",
         "crosstalk.enabled=false", "adc.enabled=false"]


# ------------------------------------------------------------------ PSFs
@pytest.mark.parametrize("wavelength_um, f_number", [(0.55, 2.8), (0.45, 8.0), (0.7, 1.4)])
def test_the_airy_patterns_first_dark_ring_is_at_1_22_lambda_n(wavelength_um, f_number):
    ring = 1.22 * wavelength_um * f_number
    r = np.linspace(0.5 * ring, 1.5 * ring, 200001)
    first_min = r[np.argmin(optics.airy(r, wavelength_um, f_number))]
    exact = jn_zeros(1, 1)[0] / np.pi * wavelength_um * f_number  # 1.2197 lambda N
    assert first_min == pytest.approx(exact, abs=1e-5 * ring) and first_min == pytest.approx(ring, rel=0.001)


@pytest.mark.parametrize("psf, extra", [("gaussian", ["optics.psf_sigma_px=0.3"]), ("gaussian", ["optics.psf_sigma_px=3"]),
                                        ("diffraction", ["optics.f_number=1.4"]), ("diffraction", ["optics.f_number=16"]),
                                        ("diffraction", ["optics.f_number=4", "light.enabled=true",
                                                         "light.illuminance_lux=10", "sensor.quantum_efficiency=0.5"])])
def test_every_psf_kernel_sums_to_one_is_odd_and_centred(psf, extra):
    k = optics.psf_kernels(load_config(overrides=[f"optics.psf={psf}"] + extra))
    assert k.shape[0] == 3 and k.shape[1] == k.shape[2] and k.shape[1] % 2 == 1
    assert np.allclose(k.sum(axis=(1, 2)), 1.0, rtol=0, atol=1e-12) and (k >= 0).all()
    for ch in range(3):  # symmetric about its centre: the picture is not shifted
        assert np.allclose(k[ch], k[ch][::-1, ::-1], atol=1e-15)


def test_the_diffraction_kernels_widen_with_wavelength_and_f_number():
    k = optics.psf_kernels(load_config(overrides=["optics.psf=diffraction", "optics.f_number=8"]))
    centre = k.shape[1] // 2
    assert k[0, centre, centre] < k[1, centre, centre] < k[2, centre, centre]  # red (610 nm) widest, blue narrowest
    wide = optics.psf_kernels(load_config(overrides=["optics.psf=diffraction", "optics.f_number=16"]))
    assert wide[1, wide.shape[1] // 2, wide.shape[1] // 2] < k[1, centre, centre]


def test_the_gaussian_kernel_has_its_sigma():
    k = optics.gaussian_kernel(1.7)
    x = np.arange(k.shape[0]) - k.shape[0] // 2
    line = k.sum(axis=0)
    # the variance of the pixel-integrated Gaussian is sigma^2 + 1/12 (a uniform pixel added); the kernel ends at
    # 5 sigma here (radius ceil(4 sigma) + 1), which drops 2e-5 of the variance
    assert np.sum(line * x**2) == pytest.approx(1.7**2 + 1 / 12, rel=5e-5)


def test_a_psf_file_is_read_and_bad_ones_are_one_line(tmp_path):
    good = np.zeros((5, 5))
    good[2, 2], good[2, 3] = 3.0, 1.0
    np.save(tmp_path / "psf.npy", good)
    k = optics.psf_kernels(load_config(overrides=[f"optics.psf={tmp_path / 'psf.npy'}"]))
    assert k[0, 2, 2] == 0.75 and k.sum() == pytest.approx(3.0)
    np.save(tmp_path / "cube.npy", np.ones((3, 3, 3)))
    nan = good.copy()
    nan[0, 0] = np.nan
    np.save(tmp_path / "nan.npy", nan)
    for name, needle in [("cube.npy", "2-D"), ("nan.npy", "finite")]:
        with pytest.raises(CmosnoiseError, match=needle) as info:
            optics.psf_kernels(load_config(overrides=[f"optics.psf={tmp_path / name}"]))
        assert "optics.psf" in str(info.value) and "\n" not in str(info.value)
    with pytest.raises(CmosnoiseError, match="give none, diffraction, gaussian"):
        optics.psf_kernels(load_config(overrides=["optics.psf=airy"]))


#: float32's unit roundoff
U32 = np.finfo(np.float32).eps / 2


def fft32_sigma(x_rms: float, n: int) -> float:
    """The standard deviation of the rounding error of a float32 FFT convolution (forward transform, product with
    the kernel's spectrum, inverse transform) of a signal of RMS ``x_rms`` over ``n`` points.

    An FFT's RMS relative error grows as ``u sqrt(log2 n)`` (Schatzman 1996, "Accuracy of the discrete Fourier
    transform and the fast Fourier transform", SIAM J. Sci. Comput. 17, 1150), taken here with a constant of 1 for
    each of the two transforms; the product adds one rounding (the spectrum of a kernel of non-negative weights
    summing to 1 has modulus <= 1, so it does not grow the error): ``u sqrt(2 log2 n + 1) x_rms``.
    """
    return U32 * math.sqrt(2 * math.log2(n) + 1) * x_rms


def _transform_points(side_rows: int, side_cols: int) -> int:
    """The points of a block's transform: each side with its margins, at the FFT's fast length."""
    return next_fast_len(side_rows, real=True) * next_fast_len(side_cols, real=True)


def test_a_point_through_the_blur_is_the_pixel_integrated_gaussian():
    # a Gaussian PSF of sigma 1.2 px integrated over each pixel is the outer product of differences of the normal
    # CDF across the pixels' edges (normalised over the kernel's radius, ceil(4 sigma) + 1 = 6). Its 13 x 13 kernel
    # is convolved directly (engine/convolve.py): at a lone pixel of 1 each product is 1 times the weight rounded
    # to float32 and every other term is an exact 0, so each value is the weight to one float32 rounding (u); a
    # monochrome sensor then takes the luminance of three equal channels (weights summing to 1, a few 2^-53 of
    # the value). Seen: 5.2e-8 of the value at most.
    from scipy.special import ndtr

    sigma = 1.2
    c = load_config(overrides=QUIET + ["optics.psf=gaussian", f"optics.psf_sigma_px={sigma}", "sensor.cfa=none",
                                       "sensor.width=40", "sensor.height=30"])
    assert optics.direct(optics.psf_kernels(c))
    signal = Sensor(c).scene_signal("spot")
    r = 6
    line = np.diff(ndtr((np.arange(-r, r + 2) - 0.5) / sigma))
    want = np.outer(line, line) / line.sum() ** 2
    got = signal[15 - r:15 + r + 1, 20 - r:20 + r + 1]
    bound = (U32 + 8 * 2.0**-53) * want
    assert (np.abs(got - want) <= bound).all()
    assert np.abs(got - want).max() > 0  # single precision: the bound is what is tested
    outside = np.ones(signal.shape, bool)
    outside[15 - r:15 + r + 1, 20 - r:20 + r + 1] = False
    assert (signal[outside] == 0).all()  # nothing beyond the kernel's radius
    assert abs(signal.sum() - 1.0) <= U32 + 1e-15


@pytest.mark.parametrize("sigma", [1.0, 2.0])
def test_a_slanted_edge_through_a_gaussian_psf_has_the_kernels_analytic_mtf(sigma):
    # The edge chart's pixels are the exact area shares of a step (MTF sinc(f), test_sfr's ideal edge); the lens
    # convolves them with the Gaussian averaged over each pixel (docs/model.md 2b), whose discrete transform is,
    # by Poisson's summation, D(f) = sum_m G(f + m) sinc(f + m), G(f) = exp(-2 pi^2 sigma^2 f^2) the Gaussian's
    # transform. So ISO 12233's e-SFR of the sensor's edge is sinc(f) D(f) up to Nyquist, within the 0.02 that
    # test_sfr holds the e-SFR to against analytic MTFs. Seen: 0.003 (sigma 1) and 0.006 (sigma 2).
    # A camera integrating the continuous blurred image over each pixel would give G(f) sinc(f): the kernel's
    # pixel average on a scene already sampled at the pixel pitch adds the pixel's aperture once more, 0.028 at
    # sigma 1 (docs/model.md says so). A point-sampled kernel fails this test at sigma 1 (checked); at sigma 2
    # the two differ by less than the e-SFR's own 0.02.
    from cmosnoise.analysis import sfr

    c = load_config(overrides=QUIET + ["optics.psf=gaussian", f"optics.psf_sigma_px={sigma}", "sensor.cfa=none",
                                       "sensor.width=160", "sensor.height=120"])
    assert optics.direct(optics.psf_kernels(c))
    r = sfr.esfr(Sensor(c).scene_signal("edge")[20:100, 40:120])
    band = r.frequency <= 0.5
    f = r.frequency[band]
    want = np.sinc(f) * sum(np.exp(-2 * np.pi**2 * sigma**2 * (f + m) ** 2) * np.sinc(f + m) for m in range(-3, 4))
    assert np.abs(r.sfr[band] - want).max() < 0.02


@pytest.mark.parametrize("source", ["photo", "edge"])
def test_the_blur_is_the_exact_convolution_to_single_precision_and_its_mosaic_is_to_cfas(source):
    # the blocks' float32 transforms against SciPy's double-precision convolution of the whole picture (its edge
    # pixels repeated): each value within 6 sigma of the transforms' rounding (fft32_sigma, the picture's largest
    # value bounding any block's RMS; past 6 sigma a Gaussian error has odds of 2e-9 a value, 0.005 over these
    # 2.3 million) plus the picture's own rounding to float32 (u times its largest value: the kernel's weights are
    # non-negative and sum to 1). Seen: 4.6e-7 against a bound of 2.3e-6. And the mosaic made block by block
    # (through the CFA as each block is made) is to_cfa of the blurred picture, bit for bit, for a resampled photo
    # (its planes transposed) and a chart (drawn as an image)
    import scipy.signal

    shape = (700, 1100)  # blocks of 512 cut both axes
    draw = scene.prepare(source, shape)
    kernels = optics.psf_kernels(load_config(overrides=["optics.psf=diffraction", "optics.f_number=8"]))
    assert not optics.direct(kernels)  # 39 x 39: FFT blocks
    rgb = optics.blur(draw, shape, kernels)
    picture, m = draw(), kernels.shape[1] // 2
    exact = np.stack([scipy.signal.fftconvolve(np.pad(picture[..., c], m, mode="edge"), kernels[c], mode="valid")
                      for c in range(3)], axis=-1)
    n = _transform_points(optics.BLOCK + 2 * m, optics.BLOCK + 2 * m)
    bound = 6 * fft32_sigma(picture.max(), n) + U32 * picture.max()
    assert np.abs(rgb - np.clip(exact, 0, None)).max() <= bound
    for pattern in ("RGGB", "GBRG", "none"):
        for region in (None, (3, 600, 5, 1001)):
            part = rgb if region is None else rgb[region[0]:region[1], region[2]:region[3]]
            got = optics.blur_cfa(draw, shape, kernels, pattern, (0.9, 1.0, 0.8), region)
            assert np.array_equal(got, scene.to_cfa(part, pattern, (0.9, 1.0, 0.8))), (pattern, region)


@pytest.mark.parametrize("source", ["photo", "edge"])
def test_a_small_kernel_is_convolved_directly_within_five_single_precision_roundings(source):
    # f/2.8 at 2.2 um: a 13 x 13 kernel, convolved directly (engine/convolve.py). Every term is non-negative
    # (the picture and the kernel are), and each carries at most five float32 roundings: the picture's value, the
    # weight, their product and the two additions of its group of four; the groups' float64 total adds k^2 2^-53
    # of the value. So each value is within 5u (plus that) of the exact convolution, relative to itself: a bound
    # that holds for every value, not in probability. SciPy's direct double-precision convolution (ndimage,
    # edge pixels repeated) is the reference; its own error is some k^2 2^-53 of the value too. Seen: 3.3u and
    # 2.3u at most. The mosaic is to_cfa of the blurred picture, bit for bit, for every CFA phase and a region at odd
    # corners, and a region's values are the whole's
    from scipy import ndimage

    shape = (301, 453)
    draw = scene.prepare(source, shape)
    kernels = optics.psf_kernels(load_config(overrides=["optics.psf=diffraction", "optics.f_number=2.8"]))
    assert kernels.shape[1] == 13 and optics.direct(kernels)
    rgb = optics.blur(draw, shape, kernels)
    picture = draw()
    exact = np.stack([ndimage.convolve(picture[..., c], kernels[c], mode="nearest") for c in range(3)], axis=-1)
    slack = (5 + 2 * 13**2 * 2.0**-53 / U32) * U32
    assert (np.abs(rgb - exact) <= slack * exact + 1e-300).all()
    assert np.abs(rgb - exact).max() > 0  # single precision, not double: the bound is what is tested
    for pattern in ("RGGB", "GBRG", "BGGR", "GRBG", "none"):
        for region in (None, (3, 250, 5, 401)):
            part = rgb if region is None else rgb[region[0]:region[1], region[2]:region[3]]
            got = optics.blur_cfa(draw, shape, kernels, pattern, (0.9, 1.0, 0.8), region)
            assert np.array_equal(got, scene.to_cfa(part, pattern, (0.9, 1.0, 0.8))), (pattern, region)


@pytest.mark.parametrize("k", [3, 5, 7, 13, 25])
def test_the_direct_convolutions_compiled_loop_is_its_numpy_specification_bit_for_bit(k):
    # engine/convolve.py: the compiled loop against mosaic_numpy (what runs while a background compile builds
    # it), on random pictures and lopsided kernels of each size (k mod 4 = 1 and 3: the last rows one at a time),
    # even and odd numbers of rows and columns, every CFA phase and a single channel
    from cmosnoise.engine import convolve

    rng = np.random.default_rng(k)
    for rows, cols in [(97, 131), (100, 70)]:
        m = k // 2
        planes = rng.random((3, cols + 2 * m, rows + 2 * m)).astype(np.float32)
        kernels = rng.random((3, k, k)) ** 3
        kernels /= kernels.sum(axis=(1, 2), keepdims=True)
        for cells in ([[0, 1], [1, 2]], [[1, 2], [0, 1]], [[2, 2], [2, 2]]):
            cells, gain = np.array(cells), np.array([0.83, 1.0, 1.21])
            got = convolve.mosaic(planes, kernels, cells, gain, np.empty((rows, cols)))
            want = convolve.mosaic_numpy(planes, kernels, cells, gain, np.empty((rows, cols)))
            assert np.array_equal(got.view(np.uint64), want.view(np.uint64)), (rows, cols, cells.tolist())
    # and both are the convolution (not the correlation: the kernels are lopsided): each pixel's own channel of
    # SciPy's double-precision convolution of the window, within the four float32 roundings of each term (the
    # weight, the product, the group's two additions; the planes are float32 already)
    from scipy import ndimage

    window = np.empty_like(planes)  # the last case's, 100 x 70: the window's rows back in order from the halves
    window[:, :, np.r_[0:rows + 2 * m:2, 1:rows + 2 * m:2]] = planes
    cells = np.array([[0, 1], [1, 2]])
    got = convolve.mosaic(planes, kernels, cells, np.ones(3), np.empty((rows, cols)))
    exact = [ndimage.convolve(window[c].T.astype(np.float64), kernels[c])[m:rows + m, m:cols + m] for c in range(3)]
    for a in range(2):
        for b in range(2):
            e = exact[cells[a, b]][a::2, b::2]
            assert (np.abs(got[a::2, b::2] - e) <= (4 + 1e-6) * U32 * e).all(), (a, b)


# ------------------------------------------------------------------ tiles keep their bits
@pytest.mark.parametrize(("source", "f_number"), [("photo", 11), ("edge", 11), ("colorchecker", 11), ("photo", 2.8)])
def test_with_optics_every_tile_is_that_rectangle_of_the_whole_frame(source, f_number):
    # 300 x 530 crosses the FFT blocks of 256 in both axes; tiles of 96 straddle them. At f/2.8 the kernel is
    # 13 x 13 and convolved directly, at f/11 it is 53 x 53 and convolved by FFT blocks
    cfg = load_config(overrides=["optics.psf=diffraction", f"optics.f_number={f_number}",
                                 "optics.relative_illumination=cos4", "optics.focal_length_mm=1.5",
                                 "sensor.width=530", "sensor.height=300"])
    assert optics.direct(optics.psf_kernels(cfg)) == (f_number < 5)
    whole = Sensor(cfg).expose(source).frame(0)
    tiling = tiles.Tiling(cfg, 96, source)
    for region in tiling.regions:
        r0, r1, c0, c1 = region
        raw = next(tiling.frames(region, 1))
        assert np.array_equal(raw, whole[r0:r1, c0:c1]), region


@pytest.mark.parametrize("sigma_px", [2, 7])
def test_a_tile_of_a_50_mp_sensor_is_the_crop_of_a_larger_part_bit_for_bit(sigma_px):
    # a 50 MP sensor (8688 x 5792): the blur of one tile against that of a part four blocks wide around it; the
    # whole frame is the union of such parts (the blocks are fixed to the sensor), so this is its crop. A kernel
    # of sigma 2 (19 x 19) is convolved directly, one of sigma 7 (59 x 59) by FFT blocks
    shape = (5792, 8688)
    cfg = load_config(overrides=["optics.psf=gaussian", f"optics.psf_sigma_px={sigma_px}", "sensor.width=8688",
                                 "sensor.height=5792"])
    draw = scene.prepare("photo", shape)
    kernels = optics.psf_kernels(cfg)
    assert optics.direct(kernels) == (sigma_px < 5)
    big = (2048, 3072, 4096, 5120)
    part = optics.blur(draw, shape, kernels, big)
    for tile in [(2100, 2400, 4200, 4500), (2048, 2304, 4350, 4700), (2500, 3000, 4097, 4300)]:
        got = optics.blur(draw, shape, kernels, tile)
        assert np.array_equal(got, part[tile[0] - big[0]:tile[1] - big[0], tile[2] - big[2]:tile[3] - big[2]]), tile


def test_the_blur_conserves_light_away_from_the_edges():
    c = load_config(overrides=QUIET + ["optics.psf=diffraction", "optics.f_number=5.6", "sensor.width=300",
                                       "sensor.height=280"])
    blurred = Sensor(c).scene_signal("siemens")
    sharp = Sensor(load_config(overrides=QUIET + ["sensor.width=300", "sensor.height=280"])).scene_signal("siemens")
    inner = (slice(40, -40), slice(40, -40))
    assert blurred[inner].mean() == pytest.approx(sharp[inner].mean(), rel=2e-3)
    assert blurred[inner].std() < sharp[inner].std()  # the spokes' contrast drops near the centre


# ------------------------------------------------------------------ relative illumination
def test_cos4_is_the_field_angles_fourth_power():
    c = load_config(overrides=["optics.relative_illumination=cos4", "optics.focal_length_mm=2",
                               "sensor.pixel_pitch_um=2.2", "sensor.width=640", "sensor.height=480"])
    ri = optics.relative_illumination(c, (480, 640))
    h = np.hypot(239.5, 319.5) * 2.2e-3  # the corner pixel's centre, mm
    assert ri[0, 0] == pytest.approx(np.cos(np.arctan(h / 2.0)) ** 4, rel=1e-12)
    assert ri.max() == pytest.approx(1.0, abs=1e-5) and ri[240, 320] > ri[0, 320] > ri[0, 0]


def test_a_relative_illumination_table_is_interpolated_and_bad_ones_refused(tmp_path):
    (tmp_path / "ri.csv").write_text("height_mm,ri\n0,1\n1,0.5\n")
    c = load_config(overrides=[f"optics.relative_illumination={tmp_path / 'ri.csv'}", "sensor.pixel_pitch_um=2.2"])
    ri = optics.relative_illumination(c, (480, 640))
    h = np.hypot(239.5, 319.5) * 2.2e-3
    assert ri[0, 0] == pytest.approx(1 - 0.5 * h, rel=1e-12)
    (tmp_path / "bad.csv").write_text("0,1\n1,1.5\n")
    with pytest.raises(CmosnoiseError, match=r"optics.relative_illumination .*\(0, 1\]"):
        optics.relative_illumination(load_config(overrides=[f"optics.relative_illumination={tmp_path / 'bad.csv'}"]),
                                     (10, 10))


def test_lens_shading_takes_the_corners_light_and_their_snr_by_its_square_root():
    # shot noise alone, float e-: the corner's mean over the centre's is the relative illumination's (times a QE
    # ratio of 1); the SNR ratio is its square root. Blocks of 64 x 64 pixels over 8 frames: the mean ratio's
    # standard error is about sqrt(2 / (4096 * 8 * 3000)) = 5e-5, the SNR ratio's about
    # sqrt(2 / (4096 * 7)) * sqrt(2) / 2 = 0.6 %; the tolerances are 5 of them.
    sets = QUIET + ["shot_noise.enabled=true", "optics.relative_illumination=cos4", "optics.focal_length_mm=1.0",
                    "sensor.cfa=none", "sensor.width=512", "sensor.height=384", "exposure.peak_rate_e_per_s=100000"]
    c = load_config(overrides=sets)
    shot = Sensor(c, seed=3).expose("flat:1")
    frames = np.stack(list(shot.frames(8))).astype(np.float64)
    ri = optics.relative_illumination(c, (384, 512))
    centre, corner = (slice(160, 224), slice(224, 288)), (slice(0, 64), slice(0, 64))
    want = ri[corner].mean() / ri[centre].mean()
    assert want < 0.6  # a real effect: the corner gets under 60 % of the centre's light
    got = frames[:, corner[0], corner[1]].mean() / frames[:, centre[0], centre[1]].mean()
    assert got == pytest.approx(want, abs=5 * 5e-5)

    def snr(block):
        x = frames[:, block[0], block[1]]
        return x.mean() / np.sqrt(x.var(axis=0, ddof=1).mean())
    assert snr(corner) / snr(centre) == pytest.approx(np.sqrt(want), rel=5 * 0.006)


def test_optics_off_changes_no_bit():
    base = Sensor(load_config()).expose("photo").frame(0)
    same = Sensor(load_config(overrides=["optics.f_number=1.4", "optics.focal_length_mm=3"])).expose("photo").frame(0)
    assert np.array_equal(base, same)


# ------------------------------------------------------------------ charts
def test_the_slanted_edge_is_the_exact_area_share():
    shape = (64, 80)
    img = charts.edge(shape, 5.0, 0.0, 1.0)[..., 0]
    # each row's sum is the length of the row to the right of the line, integrated over the row's height
    t = np.tan(np.radians(5.0))
    for r in (0, 17, 63):
        x_mid = 40 + (r + 0.5 - 32) * t  # the edge's mean position across row r
        assert img[r].sum() == pytest.approx(80 - x_mid, abs=1e-12)
    # a fine-grid integral of a few pixels near the edge
    for r, c in [(10, 38), (40, 41), (55, 42)]:
        y, x = np.meshgrid(r + (np.arange(400) + 0.5) / 400, c + (np.arange(400) + 0.5) / 400, indexing="ij")
        share = (x > 40 + (y - 32) * t).mean()
        assert img[r, c] == pytest.approx(share, abs=2e-3)
    assert np.array_equal(charts.edge(shape, region=(5, 30, 20, 70)), charts.edge(shape)[5:30, 20:70])


def test_chart_truths_say_where_the_parts_are():
    t = charts.truth("greys:12", (240, 600))
    img = charts.greys((240, 600), 12)
    for (r0, r1, c0, c1), level in zip(t["patches"], t["levels"]):
        assert np.all(img[r0:r1, c0:c1] == level)
    assert t["levels"][0] == 1.0 and t["levels"][-1] == pytest.approx(1e-3)
    e = charts.truth("edge:-7:0.2:0.8", (100, 200))
    assert (e["angle_deg"], e["low"], e["high"]) == (-7.0, 0.2, 0.8)
    cc = charts.truth("colorchecker", (160, 240))
    assert len(cc["patches"]) == 24 and cc["names"][18] == "white 9.5"
    for bad in ["edge:0", "edge:5:0.5:0.5", "greys:1", "edge:a"]:
        with pytest.raises(CmosnoiseError, match="scene"):
            scene.render(bad, (20, 20))
    with pytest.raises(CmosnoiseError, match="not a chart"):
        charts.truth("photo", (20, 20))


# ------------------------------------------------------------------ chief-ray angle
QUIET_XT = [s for s in QUIET if not s.startswith("crosstalk")]
LEAN = ["optics.chief_ray_angle=[[0, 0], [1, 30]]", "crosstalk.kernel_at_angle_pct=[[0.6, 4, 1.9], [3, 76, 8], [0.6, 4, 1.9]]"]


def _spot_at(r, c, shape=(480, 640)):
    a = np.zeros(shape)
    a[r, c] = 1.0
    return a


def test_with_the_angle_zero_or_taken_back_the_frames_keep_their_bits():
    base = Sensor(load_config()).expose("photo").frame(0)
    for extra in (["optics.chief_ray_angle=[[0, 0], [5, 0]]"], LEAN + ["optics.microlens_compensation=1"],
                  ["optics.chief_ray_angle=[[0, 0], [5, 20]]"]):  # an angle, but nothing that reads it
        assert np.array_equal(Sensor(load_config(overrides=extra)).expose("photo").frame(0), base), extra


def test_leaning_crosstalk_keeps_the_charge_and_leans_outward():
    c = load_config(overrides=QUIET_XT + LEAN + ["sensor.cfa=none", "exposure.peak_rate_e_per_s=1e6"])
    sensor = Sensor(c)
    perfect = np.random.default_rng(2).random(sensor.shape) * 1000
    after, mean = sensor.photo_response(perfect)  # float64: the sums differ by rounding alone
    # pixel sum for pixel sum: the lean only moves charge (the default kernel keeps 100 %)
    assert mean.sum() == pytest.approx(after.sum(), rel=1e-12) and not np.allclose(mean, after)
    for (r, col), direction in [((240, 600), (0, 1)), ((240, 40), (0, -1)), ((460, 320), (1, 0)), ((20, 320), (-1, 0))]:
        out = sensor.expose(_spot_at(r, col)).photo_mean_e.astype(np.float64)
        rr, cc = np.indices(out.shape)
        shift = ((rr * out).sum() / out.sum() - r, (cc * out).sum() / out.sum() - col)
        # outward along the spot's direction from the centre (its other coordinate is half a pixel off the axis)
        along = int(np.argmax(np.abs(direction)))
        assert shift[along] * direction[along] > 0.05 and abs(shift[1 - along]) < 0.01 * abs(shift[along]), shift
        assert out.sum() == pytest.approx(1e6 * 0.03, rel=1e-6)  # the spot's charge, all of it, around it
    # next to the centre (its centre half a pixel off each axis: h = 1.556 um, 0.0467 degrees) the spread is all but
    # symmetric: shares a = b = 0.0467 / 20 * cos 45 along the columns and the rows; the right neighbour gets
    # 4.5 + 3.5 a - 0.5 b %, the left 4.5 - 1.5 a - 0.5 b % (the kernels' differences)
    out = sensor.expose(_spot_at(240, 320)).photo_mean_e
    a = np.hypot(0.5, 0.5) * 2.2e-3 * 30 / 20 * np.sqrt(0.5)
    assert out[240, 321] / out[240, 319] == pytest.approx((4.5 + 3.5 * a - 0.5 * a) / (4.5 - 1.5 * a - 0.5 * a),
                                                          rel=1e-5)


def test_the_angle_costs_each_channel_its_own_qe():
    c = load_config(overrides=QUIET + ["optics.chief_ray_angle=[[0, 0], [0.88, 30]]",
                                       "optics.angle_relative_qe=[[0, 1, 1, 1], [30, 0.7, 0.8, 0.9]]",
                                       "sensor.width=640", "sensor.height=480"])
    signal = Sensor(c).scene_signal("flat:1")
    seen = optics.incidence(c, (480, 640))
    corner_angle = seen[0][0, 0]
    for (r, col), ch in [((0, 0), 0), ((0, 1), 1), ((1, 1), 2)]:
        want = np.interp(seen[0][r, col], [0, 30], [1, [0.7, 0.8, 0.9][ch]])
        assert signal[r, col] == pytest.approx(want, rel=1e-12)
    half = load_config(overrides=QUIET + ["optics.chief_ray_angle=[[0, 0], [0.88, 30]]",
                                          "optics.angle_relative_qe=[[0, 1], [30, 0.7]]",
                                          "optics.microlens_compensation=0.5"])
    assert Sensor(half).scene_signal("flat:1")[0, 0] == pytest.approx(1 - 0.3 * corner_angle / 2 / 30, rel=1e-12)


def test_with_a_leaning_kernel_every_tile_is_that_rectangle_of_the_whole_frame():
    cfg = load_config(overrides=LEAN + ["optics.angle_relative_qe=[[0, 1, 1, 1], [30, 0.7, 0.8, 0.9]]",
                                        "sensor.width=200", "sensor.height=150"])
    whole = Sensor(cfg).expose("photo").frame(0)
    tiling = tiles.Tiling(cfg, 64, "photo")
    for region in tiling.regions:
        r0, r1, c0, c1 = region
        assert np.array_equal(next(tiling.frames(region, 1)), whole[r0:r1, c0:c1]), region


@pytest.mark.parametrize("sets, needle", [
    (["crosstalk.kernel_at_angle_pct=[[1, 4, 1], [4, 70, 4], [1, 4, 1]]"], "same sum"),
    (["optics.chief_ray_angle=[[0, 0]]"], "at least two rows"),
    (["optics.chief_ray_angle=[[1, 0], [0, 10]]", "optics.angle_relative_qe=[[0, 1], [30, 0.5]]"], "increasing"),
    (["optics.chief_ray_angle=[[0, 0], [1, 10]]", "optics.angle_relative_qe=[[0, 1], [30, 1.5]]"], r"\(0, 1\]"),
])
def test_bad_chief_ray_tables_are_one_line(sets, needle):
    with pytest.raises(CmosnoiseError, match=needle) as info:
        Sensor(load_config(overrides=sets + ["sensor.width=32", "sensor.height=24"])).expose("flat:0.5")
    assert "\n" not in str(info.value)


def test_the_compiled_lean_is_four_spreads_of_signed_charge():
    # the definition (docs/model.md 2b): each pixel spreads with k0 + |a| D(sign a) + |b| D(sign b); spread is linear,
    # so it is four spreads of the charge weighted by each sign's share. The compiled scatter (and its NumPy
    # fallback) adds the same terms in another order: equal to rounding
    import cmosnoise.engine.stencil as stencil
    from cmosnoise.model.stages import crosstalk

    rng = np.random.default_rng(0)
    q = rng.random((90, 120)) * 1000
    a, b = rng.uniform(-1, 1, q.shape), rng.uniform(-1, 1, q.shape)
    leans = crosstalk.lean_kernels(crosstalk.kernel_fractions([[0.9, 4.5, 0.9], [4.5, 78.4, 4.5], [0.9, 4.5, 0.9]]),
                                   crosstalk.kernel_fractions([[0.6, 4, 1.9], [3, 76, 8], [0.6, 4, 1.9]]))
    right, left, down, up = leans
    want = (crosstalk.spread(q * np.clip(a, 0, None), right) + crosstalk.spread(q * np.clip(-a, 0, None), left)
            + crosstalk.spread(q * np.clip(b, 0, None), down) + crosstalk.spread(q * np.clip(-b, 0, None), up))
    got = crosstalk.lean(q, leans, a, b)
    assert np.allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
    assert abs(got.sum()) < 1e-9 * q.sum()  # it only moves charge
    # each value's terms are added in an order fixed by the sensor's rows: a band of rows from row 31 gives the
    # whole's bits away from its edges, and so does one thread
    band = crosstalk.lean(q[31:71], leans, a[31:71], b[31:71], row0=31)
    assert np.array_equal(band[1:-1], got[32:70])
    threads = stencil.numba.get_num_threads()
    try:
        stencil.numba.set_num_threads(1)
        assert np.array_equal(crosstalk.lean(q, leans, a, b), got)
    finally:
        stencil.numba.set_num_threads(threads)
    numba = stencil.numba
    try:
        stencil.numba = None
        assert np.allclose(crosstalk.lean(q, leans, a, b), want, rtol=0, atol=1e-12 * np.abs(want).max())
    finally:
        stencil.numba = numba


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_lean_made_from_the_field_is_the_lean_of_its_maps_bit_for_bit(dtype):
    # optics.leaning_charge makes each pixel's shares where it scatters its charge (engine/lens.leaning_spread);
    # the same bits as crosstalk.lean of optics.lean_weights' maps, whole and for regions at odd corners (row0),
    # for a float32 charge (as an exposure's) and a float64 one; and with the compiled loops off, the maps' path
    from cmosnoise.engine import lens
    from cmosnoise.model.stages import crosstalk

    c = load_config(overrides=LEAN + ["optics.chief_ray_angle=[[0, 0], [0.1, 12], [0.25, -20]]",
                                      "optics.microlens_compensation=0.3", "sensor.width=131", "sensor.height=97",
                                      "sensor.pixel_pitch_um=1.4"])
    shape = (97, 131)
    leans = crosstalk.lean_kernels(crosstalk.kernel_fractions(c.crosstalk.kernel_pct),
                                   crosstalk.kernel_fractions(c.crosstalk.kernel_at_angle_pct))
    q = (np.random.default_rng(4).random(shape) * 1000).astype(dtype)
    assert lens.ready()
    for region in ((0, 97, 0, 131), (3, 50, 7, 91), (48, 97, 64, 131)):
        r0, r1, c0, c1 = region
        part = q[r0:r1, c0:c1]
        want = crosstalk.lean(part, leans, *optics.lean_weights(c, shape, region), row0=r0)
        got = optics.leaning_charge(part, c, shape, region, leans)
        assert np.array_equal(got.view(np.uint64), want.view(np.uint64)), region
    off = load_config(overrides=["sensor.width=131", "sensor.height=97"])
    assert optics.leaning_charge(q, off, shape, (0, 97, 0, 131), leans) is None


FIELDS = [["optics.relative_illumination=cos4", "optics.focal_length_mm=0.4"],
          ["optics.relative_illumination=cos4", "optics.chief_ray_angle=[[0, 0], [0.1, 12], [0.2, 25]]",
           "optics.microlens_compensation=0.3", "optics.angle_relative_qe=[[0, 1], [20, 0.7]]"],
          ["optics.chief_ray_angle=[[0, 0], [0.05, -10], [0.15, -25]]",
           "optics.angle_relative_qe=[[0, 1, 0.9, 0.95], [5, 0.9, 0.8, 0.7], [20, 0.6, 0.5, 0.4]]"],
          ["optics.relative_illumination=TABLE", "optics.chief_ray_angle=[[0.02, 3], [0.1, 25]]",
           "optics.angle_relative_qe=[[0, 1, 0.9, 0.95], [10, 0.9, 0.8, 0.7]]"]]


@pytest.mark.parametrize("pattern", ["RGGB", "GBRG", "none"])
@pytest.mark.parametrize("sets", FIELDS, ids=["cos4", "cos4+angle", "angle per channel", "table+angle"])
def test_the_compiled_field_factors_are_the_specifications_bits(tmp_path, pattern, sets):
    # engine/lens.py computes relative illumination, the angle's QE loss and the leaning shares pixel by pixel;
    # optics' NumPy maps are the specification: equal bit for bit on an odd size (a pixel on the axis, h = 0),
    # on regions at odd corners (the CFA's phase), and on image heights beyond each table's ends
    from cmosnoise.engine import lens

    (tmp_path / "ri.csv").write_text("height_mm,ri\n0.01,1\n0.08,0.8\n0.12,0.55\n")
    sets = [s.replace("TABLE", str(tmp_path / "ri.csv")) for s in sets]
    c = load_config(overrides=sets + [f"sensor.cfa={pattern}", "sensor.width=131", "sensor.height=97",
                                      "sensor.pixel_pitch_um=1.4", "crosstalk.kernel_at_angle_pct="
                                      "[[0.6, 4, 1.9], [3, 76, 8], [0.6, 4, 1.9]]"])
    assert lens.ready()
    shape = (97, 131)
    for region in (None, (3, 50, 7, 91), (48, 97, 64, 131)):
        r0, r1, c0, c1 = (0, 97, 0, 131) if region is None else region
        signal = np.random.default_rng(r0 + c0).random((r1 - r0, c1 - c0))
        want = signal.copy()
        for factor in (optics.relative_illumination(c, shape, region), optics.angle_qe(c, pattern, shape, region)):
            if factor is not None:
                want = want * factor
        assert np.array_equal(optics.shade(signal.copy(), c, pattern, shape, region), want), region
        seen, got = optics.incidence(c, shape, region), optics.lean_weights(c, shape, region)
        if seen is None:
            assert got is None
            continue
        share = np.clip(seen[0] / c.crosstalk.reference_angle_deg, -1.0, 1.0)
        assert np.array_equal(got[0], share * seen[1]) and np.array_equal(got[1], share * seen[2]), region
