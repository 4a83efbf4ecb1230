"""The optical image (#73): the system MTF of a slanted edge against Fourier optics' ``OTF(f) sinc(a f)``, detail
finer than a pixel aliasing where a camera shows it, the four-spot filter's MTF, the fine grid's k, the separable
terms and their compiled loops.

The truths are written here from the formulas, not from the code under test: the diffraction OTF of a circular
pupil (Goodman) averaged over the photo-electron spectrum (D65 from colour-science's table, a flat QE, photons
lambda / hc), the pixel aperture's ``|sinc(a f)|`` (a the aperture's side, ``pitch sqrt(fill factor)``), a
Gaussian's ``exp(-2 pi^2 sigma^2 f^2)``, a four-spot filter's ``|cos(pi d f)|``. The tolerances are the issue's:
2 % on MTF50 and 0.02 on the MTF at Nyquist; ISO 12233's e-SFR meets analytic MTFs within 0.02 (tests/test_sfr.py),
which bounds what the measurement itself adds.
"""

import colour
import numpy as np
import pytest

from cmosnoise import Sensor, load_config
from cmosnoise.analysis import sfr
from cmosnoise.engine import resample, separable
from cmosnoise.model import charts, optics
from cmosnoise.model.focal_plane import focal_plane

QUIET = ["shot_noise.enabled=false", "source_follower.enabled=false", "row_noise.enabled=false",
         "column_noise.enabled=false", "dark_current.enabled=false", "prnu.enabled=false",
         "crosstalk.enabled=false", "adc.enabled=false"]
#: a monochrome sensor of flat QE under D65: its photo-electron spectrum is D65's photons, 380 to 780 nm
MONO_LIGHT = ["sensor.cfa=none", "light.enabled=true", "light.illuminance_lux=100", "sensor.quantum_efficiency=0.5"]


def _spectrum() -> tuple[np.ndarray, np.ndarray]:
    """D65's photons (power times wavelength) at 5 nm from 380 to 780 nm, as weights summing to 1."""
    d65 = colour.SDS_ILLUMINANTS["D65"]
    wl = np.arange(380, 781, 5.0)
    w = np.interp(wl, d65.wavelengths, d65.values) * wl
    return wl, w / w.sum()


def _airy_mtf(f_px: np.ndarray, pitch_um: float, f_number: float, fill_factor: float) -> np.ndarray:
    """OTF(f) |sinc(a f)|: the circular pupil's OTF averaged over the spectrum, times the aperture's."""
    wl, w = _spectrum()
    x = np.clip(np.abs(f_px)[:, None] / pitch_um * wl[None, :] * 1e-3 * f_number, 0, 1)
    otf = (2 / np.pi * (np.arccos(x) - x * np.sqrt(1 - x * x)) * w).sum(axis=1)
    return otf * np.abs(np.sinc(np.sqrt(fill_factor) * f_px))


def _edge_sfr(sets: list[str]) -> sfr.SfrResult:
    sensor = Sensor(load_config(overrides=QUIET + ["sensor.width=240", "sensor.height=200"] + sets))
    return sfr.esfr(sensor.scene_signal("edge"), charts.truth("edge", sensor.shape)["region"])


def _check(r: sfr.SfrResult, want: np.ndarray) -> tuple[float, float]:
    mtf50 = sfr.mtf50(r.frequency, want)
    return r.mtf50 / mtf50 - 1, r.mtf_nyquist - float(np.interp(0.5, r.frequency, want))


# ------------------------------------------------------------------ the system MTF
#: the issue's lenses: (pixel pitch um, f-number), each at fill factors 1 and 0.5. Seen: MTF50 within 1.2 % and the
#: MTF at Nyquist within 0.0055 of the truth (docs/model.md's table, docs/readme_numbers.py focal_plane_mtf)
#: The default lens and two others stay in the fast tier; f/8 (a large core on a fine grid) and the 1 um pixel at
#: f/2.8 take some 3 to 5 s each and run in the full suite.
LENSES = [(2.2, 2.8), (2.2, 4.0), pytest.param(2.2, 8.0, marks=pytest.mark.slow),
          pytest.param(1.0, 2.8, marks=pytest.mark.slow), (1.0, 4.0)]


@pytest.mark.parametrize("fill_factor", [1.0, 0.5])
@pytest.mark.parametrize("pitch_um, f_number", LENSES)
def test_an_edge_through_the_diffraction_psf_has_the_systems_mtf(pitch_um, f_number, fill_factor):
    r = _edge_sfr(MONO_LIGHT + ["optics.psf=diffraction", f"optics.f_number={f_number}",
                                f"sensor.pixel_pitch_um={pitch_um}", f"light.fill_factor={fill_factor}"])
    err50, err_nyq = _check(r, _airy_mtf(r.frequency, pitch_um, f_number, fill_factor))
    assert abs(err50) < 0.02 and abs(err_nyq) < 0.02, (err50, err_nyq)


@pytest.mark.parametrize("sigma_px", [0.3, 1.0, 2.0])
def test_an_edge_through_a_gaussian_psf_has_its_mtf_times_the_pixels(sigma_px):
    r = _edge_sfr(["sensor.cfa=none", "optics.psf=gaussian", f"optics.psf_sigma_px={sigma_px}"])
    want = np.exp(-2 * np.pi**2 * sigma_px**2 * r.frequency**2) * np.abs(np.sinc(r.frequency))
    err50, err_nyq = _check(r, want)
    assert abs(err50) < 0.02 and abs(err_nyq) < 0.02, (err50, err_nyq)


def test_a_smaller_aperture_alone_raises_the_mtf_to_its_sinc():
    # no PSF: auto takes the k at which the aperture of side sqrt(0.5) pixel is resolved on the fine grid (3); its
    # MTF is |sinc(0.707 f)| (0.80 at Nyquist, where the full pixel's is 0.64)
    assert focal_plane(load_config(overrides=["light.fill_factor=0.5"])).k == 3
    r = _edge_sfr(["sensor.cfa=none", "light.fill_factor=0.5"])
    err50, err_nyq = _check(r, np.abs(np.sinc(np.sqrt(0.5) * r.frequency)))
    assert abs(err_nyq) < 0.02 and r.mtf_nyquist > 0.75


@pytest.mark.parametrize("separation_px", [1.0, 0.7])
def test_the_four_spot_filters_mtf_is_its_cosine(separation_px):
    # the birefringent four-spot filter: two spots d apart along each axis, MTF |cos(pi d f)| per axis; through a
    # diffraction PSF at f/4 on 2.2 um pixels
    pitch = 2.2
    r = _edge_sfr(MONO_LIGHT + ["optics.psf=diffraction", "optics.f_number=4", f"sensor.pixel_pitch_um={pitch}",
                                f"optics.olpf={separation_px * pitch}"])
    want = _airy_mtf(r.frequency, pitch, 4.0, 1.0) * np.abs(np.cos(np.pi * separation_px * r.frequency))
    band = r.frequency <= 0.5
    assert np.abs(r.sfr[band] - want[band]).max() < 0.02


# ------------------------------------------------------------------ aliasing
def _row_frequency(img: np.ndarray, row: int, col0: int, width: int) -> float:
    """The centroid of a row segment's power spectrum (cycles per pixel), over a few rows about ``row``: the
    segment's mean removed, a Hann window, zero-padded to 4096."""
    seg = img[row - 2:row + 3, col0:col0 + width].astype(np.float64)
    seg = (seg - seg.mean(axis=1, keepdims=True)) * np.hanning(width)[None, :]
    power = (np.abs(np.fft.rfft(seg, 4096, axis=1)) ** 2).sum(axis=0)
    f = np.fft.rfftfreq(4096)
    return float((f * power).sum() / power.sum())


@pytest.mark.parametrize("f0", [0.7, 0.85])
def test_a_zone_plate_above_nyquist_appears_at_one_minus_its_frequency(f0):
    # zoneplate:1 on a 400 x 400 monochrome sensor: the local frequency along the middle row is x / 200 cycles per
    # pixel at x pixels from the centre. A 32-pixel segment about x0 = 200 f0 holds a chirp of f0 +- 0.08; the
    # sensor's pixels sample it at 1 - f0 (the alias a camera shows): the spectrum's centroid within 0.02 (the
    # chirp's spread is symmetric about it; a Hann window's leakage and the frame's quantization are far below)
    sensor = Sensor(load_config(overrides=QUIET + ["sensor.cfa=none", "sensor.width=400", "sensor.height=400"]))
    frame = sensor.expose("zoneplate:1").frame(0)
    x0 = int(200 + 200 * f0)
    got = _row_frequency(frame, 200, x0 - 16, 32)
    assert got == pytest.approx(1 - f0, abs=0.02)
    # the same below Nyquist reads f itself
    assert _row_frequency(frame, 200, 200 + 60 - 16, 32) == pytest.approx(0.3, abs=0.02)


def test_the_four_spot_filter_takes_the_aliasing_and_the_false_colour_away():
    # a Bayer sensor under a zone plate to 1 cycle per pixel: above Nyquist the demosaiced picture shows false
    # colour (R - G and B - G vary where a grey scene has none); a four-spot filter of one pixel's separation (its
    # first zero at Nyquist) takes most of it: under 40 % of it left, and under two thirds of the aliased
    # luminance (seen: 30 % and 52 %; no noise: the figures are the same in every run)
    from cmosnoise.isp import reconstruction

    def picture(extra):
        sets = QUIET + ["sensor.width=320", "sensor.height=320", "optics.psf=diffraction", "optics.f_number=2"] + extra
        sensor = Sensor(load_config(overrides=sets))
        rgb = reconstruction.demosaic(sensor.scene_signal("zoneplate:1").astype(np.float32), "RGGB", "malvar2004")
        y, x = np.mgrid[0:320, 0:320] - 159.5
        ring = (np.hypot(x, y) > 160 * 0.6) & (np.hypot(x, y) < 160 * 0.95) & (np.abs(y) < 40)
        chroma = np.hypot(rgb[..., 0] - rgb[..., 1], rgb[..., 2] - rgb[..., 1])[ring]
        return float(chroma.std()), float(rgb[..., 1][ring].std())

    plain_c, plain_l = picture([])
    olpf_c, olpf_l = picture(["optics.olpf=2.2"])
    assert plain_c > 0.02  # false colour there to take
    assert olpf_c < 0.4 * plain_c and olpf_l < plain_l / 1.5


# ------------------------------------------------------------------ the fine grid
@pytest.mark.parametrize(("sets", "k"), [([], 1), (["optics.psf=diffraction", "optics.f_number=2.8"], 3),
                                         pytest.param(["optics.psf=diffraction", "optics.f_number=8"], 2,
                                                      marks=pytest.mark.slow),
                                         pytest.param(["optics.psf=diffraction", "optics.f_number=16"], 1,
                                                      marks=pytest.mark.slow),
                                         (["optics.psf=gaussian", "optics.psf_sigma_px=2"], 1),
                                         (["optics.psf=gaussian", "optics.psf_sigma_px=0.3"], 3),
                                         (["optics.oversample=4"], 4),
                                         (["light.fill_factor=0.5"], 3), (["optics.olpf=2.2"], 2)])
def test_auto_takes_the_smallest_k_that_samples_the_psf_at_nyquist(sets, k):
    fp = focal_plane(load_config(overrides=sets))
    assert fp.k == k
    if fp.psf is not None and "optics.oversample=4" not in sets:  # the alias bound holds at k, not at k - 1
        assert optics.alias_error(fp.psf, k, 1.0) <= optics.ALIAS_LIMIT
        if k > 1:
            assert optics.alias_error(fp.psf, k - 1, 1.0) > optics.ALIAS_LIMIT


def test_with_k_one_and_no_lens_the_signal_is_the_scenes_bit_for_bit():
    base = Sensor(load_config()).expose("photo").frame(0)
    one = Sensor(load_config(overrides=["optics.oversample=1"])).expose("photo").frame(0)
    assert np.array_equal(base, one)
    # and the scene's CFA signal itself: the same products (to_cfa through the trivial focal plane)
    c = load_config(overrides=["sensor.width=64", "sensor.height=48"])
    from cmosnoise.model import scene

    want = scene.cfa_signal(scene.prepare("colorchecker", (48, 64)), "RGGB", (1.0, 1.0, 1.0))
    assert np.array_equal(Sensor(c).scene_signal("colorchecker"), want)


def test_an_oversampled_chart_keeps_its_light_and_its_edge():
    # the edge drawn on a grid 3 times finer, each fine cell its exact area share, integrated over each pixel's
    # cells: the pixel's own exact share (to float64 rounding: the ramp integrals' differences at coordinates of
    # some 300 cells lose 300 x 2^-52 = 7e-14 each)
    coarse = Sensor(load_config(overrides=QUIET + ["sensor.width=96", "sensor.height=64"])).scene_signal("edge")
    fine = Sensor(load_config(overrides=QUIET + ["sensor.width=96", "sensor.height=64", "optics.oversample=3"])
                  ).scene_signal("edge")
    assert np.abs(fine - coarse).max() <= 1e-12


def test_bad_oversampling_and_filters_are_one_line():
    from cmosnoise.errors import CmosnoiseError

    for sets, needle in [(["optics.oversample=0"], "optics.oversample = 0"),
                         (["optics.oversample=5"], "from 1 to 4"), (["optics.oversample=two"], "optics.oversample"),
                         (["optics.olpf=-1"], "optics.olpf = -1"), (["optics.olpf=inf"], "optics.olpf"),
                         (["optics.olpf=nan"], "optics.olpf")]:
        with pytest.raises(CmosnoiseError, match=needle) as info:
            load_config(overrides=sets)
        assert "\n" not in str(info.value)


def test_cos4_takes_the_image_distance_when_the_lens_magnifies():
    # tan(theta) = h / (f (1 + m)): at m = 1 a corner's field angle is that of a lens of twice the focal length
    c = load_config(overrides=["optics.relative_illumination=cos4", "optics.focal_length_mm=2",
                               "optics.magnification=1", "sensor.width=640", "sensor.height=480"])
    ri = optics.relative_illumination(c, (480, 640))
    h = np.hypot(239.5, 319.5) * 2.2e-3
    assert ri[0, 0] == pytest.approx(np.cos(np.arctan(h / 4.0)) ** 4, rel=1e-12)


# ------------------------------------------------------------------ the separable terms and their loops
def test_the_jacobi_svd_is_the_decomposition_and_its_terms_meet_their_tolerance():
    rng = np.random.default_rng(4)
    for shape in [(7, 5), (5, 9), (21, 21)]:
        a = rng.random(shape)
        u, s, vt = separable.svd(a)
        assert np.abs((u * s) @ vt - a).max() < 1e-13 * np.abs(a).max()
        assert np.allclose(s, np.linalg.svd(a, compute_uv=False), rtol=1e-12)
    core = focal_plane(load_config(overrides=["optics.psf=diffraction", "optics.f_number=2.8"])).psf.core[1]
    rows, cols = separable.terms(core, 1e-4)
    approx = sum(np.outer(r, c) for r, c in zip(rows, cols))
    assert np.abs(approx - core).max() <= 1e-4 * core.max()
    assert abs(approx.sum() - core.sum()) <= 1e-15 and len(rows) <= 8


@pytest.mark.skipif(separable._rotations is None, reason="needs numba")
def test_the_compiled_jacobi_rotations_are_the_specifications_bits_and_their_sums_are_fsums():
    """The compiled rotations (every sum by CPython's fsum algorithm) give the NumPy specification's columns and
    rotations bit for bit, on random matrices and PSF cores; each sum is math.fsum's, on sums that cancel, that
    span 40 decades and that need fsum's half-even step (1e-16 + 1 + 1e16)."""
    import math

    rng = np.random.default_rng(11)
    partials = np.empty(400)
    for n in (1, 2, 3, 17, 60, 150):
        for trial in range(40):
            a = rng.normal(size=n) * 10.0 ** rng.integers(-20, 20, n)
            b = a if trial % 3 == 0 else rng.normal(size=n) * 10.0 ** rng.integers(-20, 20, n)
            if trial % 3 == 1:  # products that cancel in pairs, the rest small: the exact sum is what is left
                a, b = np.concatenate([a, a, a[:1] * 1e-30]), np.concatenate([b, -b, b[:1]])
            got, want = separable._fsum_products(a, b, partials), math.fsum((a * b).tolist())
            assert got == want and math.copysign(1, got) == math.copysign(1, want), (n, got, want)
    assert separable._fsum_products(np.array([1e-16, 1.0, 1e16]), np.ones(3), partials) == math.fsum(
        [1e-16, 1.0, 1e16])
    cores = [focal_plane(load_config(overrides=["optics.psf=diffraction", "optics.f_number=4"])).psf.core[c]
             for c in (0, 2)]
    for a in [rng.random((7, 5)), rng.normal(size=(30, 30)), rng.normal(size=(40, 13)), *cores]:
        cols, v = separable._rotations_numpy(a)
        c_arr, v_arr = np.ascontiguousarray(a.T), np.eye(a.shape[1])
        separable._rotations(c_arr, v_arr, separable._SWEEPS, separable._ORTHOGONAL)
        assert np.array_equal(c_arr, np.array(cols)) and np.array_equal(v_arr, np.array(v)), a.shape


def test_the_optical_images_compiled_loops_are_their_numpy_specifications_bit_for_bit(monkeypatch):
    import scipy.sparse as sp

    rng = np.random.default_rng(9)
    x = rng.random((90, 300))
    rows = sp.random(201, 90, density=0.05, random_state=3, format="csr")
    got = resample.rows_transposed(x, rows, np.empty((300, 201)))
    want = (rows @ x)[resample.parity_order(201)].T
    assert np.array_equal(got, want)
    planes = rng.random((3, 500, 201)) - 0.2  # negative sums too: taken as 0
    columns = [sp.random(150, 500, density=0.02, random_state=c, format="csr") for c in range(3)]
    cell, gain = np.array([[0, 1], [1, 2]]), np.array([0.9, 1.0, 1.1])
    compiled = resample.mosaic_transposed(planes, columns, cell, gain)
    monkeypatch.setattr(resample, "compiled", lambda *a: False)  # the specification
    spec = resample.mosaic_transposed(planes, columns, cell, gain)
    assert np.array_equal(compiled, spec) and (compiled >= 0).all()
    assert np.array_equal(resample.rows_transposed(x, rows, np.empty((300, 201))), want)
