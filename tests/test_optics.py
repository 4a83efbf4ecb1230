"""The lens (#60, #73): PSFs on the optical image's fine grid that sum to 1 and put the Airy ring where diffraction
does, an optical image whose pixels are its integral over each aperture and whose tiles are the whole's crop bit
for bit (a 50 MP sensor's included), relative illumination against its law and its SNR, and the test charts with
their truth."""

import numpy as np
import pytest
from scipy.special import jn_zeros

from cmosnoise import Sensor, load_config
from cmosnoise.errors import CmosnoiseError
from cmosnoise.model import cfa, charts, optics, scene, tiles
from cmosnoise.model.focal_plane import TERM_TOLERANCE, focal_plane

QUIET = ["shot_noise.enabled=false", "source_follower.enabled=false", "row_noise.enabled=false",
         "column_noise.enabled=false", "dark_current.enabled=false", "prnu.enabled=false",
         "crosstalk.enabled=false", "adc.enabled=false"]


# ------------------------------------------------------------------ PSFs on the fine grid
@pytest.mark.parametrize("wavelength_um, f_number", [(0.55, 2.8), (0.45, 8.0), (0.7, 1.4)])
def test_the_airy_patterns_first_dark_ring_is_at_1_22_lambda_n(wavelength_um, f_number):
    ring = 1.22 * wavelength_um * f_number
    r = np.linspace(0.5 * ring, 1.5 * ring, 200001)
    first_min = r[np.argmin(optics.airy(r, wavelength_um, f_number))]
    exact = jn_zeros(1, 1)[0] / np.pi * wavelength_um * f_number  # 1.2197 lambda N
    assert first_min == pytest.approx(exact, abs=1e-5 * ring) and first_min == pytest.approx(ring, rel=0.001)


def test_the_encircled_energy_is_the_patterns_own_integral_and_its_otf_is_goodmans():
    # Rayleigh's closed form against the pattern integrated numerically (2 pi r dr over 4 (l N)^2 / pi), at the
    # first three dark rings (83.8, 91.0 and 93.8 % of the light, Born and Wolf 8.5.2) and at 40 rings; and the
    # OTF's two ends: 1 at 0, 0 from the cut-off 1 / (lambda N) on
    from scipy.integrate import quad

    lam, n = 0.55, 4.0
    for r_um, want in [(z * lam * n / np.pi, w) for z, w in zip(jn_zeros(1, 3), (0.838, 0.910, 0.938))]:
        got = float(optics.encircled_energy(r_um, [lam], [1.0], n))
        assert got == pytest.approx(want, abs=1e-3)
        integral = quad(lambda r: 2 * np.pi * r * optics.airy(r, lam, n), 0, r_um, limit=200)[0]
        assert got == pytest.approx(integral / (4 * (lam * n) ** 2 / np.pi), rel=1e-7)
    assert float(optics.diffraction_otf(0.0, [lam], [1.0], n)) == 1.0
    assert float(optics.diffraction_otf(1 / (lam * n), [lam], [1.0], n)) == 0.0


@pytest.mark.parametrize("psf, extra", [("gaussian", ["optics.psf_sigma_px=0.3"]), ("gaussian", ["optics.psf_sigma_px=3"]),
                                        ("diffraction", ["optics.f_number=1.4"]), ("diffraction", ["optics.f_number=16"]),
                                        ("diffraction", ["optics.f_number=4", "light.enabled=true",
                                                         "light.illuminance_lux=10", "sensor.quantum_efficiency=0.5"])])
def test_every_psf_sums_to_one_is_odd_and_centred(psf, extra):
    fp = focal_plane(load_config(overrides=[f"optics.psf={psf}"] + extra))
    core = fp.psf.core
    assert core.shape[0] == 3 and core.shape[1] == core.shape[2] and core.shape[1] % 2 == 1
    # the core and the halo hold every electron
    assert np.allclose(core.sum(axis=(1, 2)) + fp.psf.halo_share, 1.0, rtol=0, atol=1e-12) and (core >= 0).all()
    for ch in range(3):  # symmetric about its centre: the picture is not shifted
        assert np.allclose(core[ch], core[ch][::-1, ::-1], atol=1e-15)
        assert np.allclose(core[ch], core[ch].T, atol=1e-15)
    if psf == "diffraction":  # the halo holds what the core's 95 % radius and its taper leave: 5 to 8 %
        assert ((fp.psf.halo_share > 0.05) & (fp.psf.halo_share < 0.08)).all()


def test_the_diffraction_psf_widens_with_wavelength_and_f_number():
    # on the pixels' own grid (k = 1), where the cores are small (the separable split of a large one is slow)
    fp = focal_plane(load_config(overrides=["optics.psf=diffraction", "optics.f_number=4", "optics.oversample=1"]))
    c = fp.psf.core.shape[1] // 2
    core = fp.psf.core
    assert core[0, c, c] < core[1, c, c] < core[2, c, c]  # red (610 nm) widest, blue narrowest
    wide = focal_plane(load_config(overrides=["optics.psf=diffraction", "optics.f_number=8", "optics.oversample=1"]))
    w = wide.psf.core.shape[1] // 2
    assert wide.psf.core[1, w, w] < core[1, c, c]


def test_the_gaussian_psf_has_its_sigma():
    # point-sampled on a grid of 1 / k pixel: by Poisson's summation its variance is sigma^2 up to
    # exp(-2 pi^2 (sigma k)^2) (nothing here); cut at 4 sigma, a truncated normal's: sigma^2 (1 - 8 phi(4) /
    # (2 Phi(4) - 1)), phi and Phi the standard normal's density and CDF
    from scipy.stats import norm

    sigma, k = 1.7, 2
    core = optics.gaussian_psf(sigma, k).core[0]
    x = (np.arange(core.shape[0]) - core.shape[0] // 2) / k
    line = core.sum(axis=0)
    want = sigma**2 * (1 - 8 * norm.pdf(4) / (2 * norm.cdf(4) - 1))
    assert np.sum(line * x**2) == pytest.approx(want, rel=2e-3)  # the cut falls between samples: within 1/(4 sigma k)


def test_a_psf_file_is_binned_onto_the_fine_grid_and_bad_ones_are_one_line(tmp_path):
    good = np.zeros((9, 9))
    good[4, 4], good[4, 5] = 3.0, 1.0
    np.save(tmp_path / "psf.npy", good)
    fp = focal_plane(load_config(overrides=[f"optics.psf={tmp_path / 'psf.npy'}"]))
    assert fp.k == 1 and fp.psf.core[0, 4, 4] == 0.75 and fp.psf.core.sum() == pytest.approx(3.0)
    # sampled at a third of a 2.2 um pixel: each fine cell of k = 3 is one sample; of k = 1, three by three
    third = [f"optics.psf={tmp_path / 'psf.npy'}", f"optics.psf_sampling_um={2.2 / 3}"]
    assert focal_plane(load_config(overrides=third + ["optics.oversample=3"])).psf.core[0, 4, 4] == 0.75
    binned = focal_plane(load_config(overrides=third + ["optics.oversample=1"])).psf.core[0]
    assert binned.shape == (3, 3) and binned[1, 1] == 1.0  # nine samples in three cells: both in the centre one
    with pytest.raises(CmosnoiseError, match="do not divide into the fine grid") as info:
        focal_plane(load_config(overrides=[f"optics.psf={tmp_path / 'psf.npy'}", "optics.oversample=2"]))
    assert "optics.oversample = 2" in str(info.value) and "\n" not in str(info.value)
    np.save(tmp_path / "cube.npy", np.ones((3, 3, 3)))
    nan = good.copy()
    nan[0, 0] = np.nan
    np.save(tmp_path / "nan.npy", nan)
    np.save(tmp_path / "huge.npy", np.full((9, 9), 1e308))  # a sum that overflows: its scale is free
    np.save(tmp_path / "zero.npy", np.zeros((9, 9)))
    np.save(tmp_path / "objects.npy", np.array([[1, None]], dtype=object), allow_pickle=True)
    (tmp_path / "short.npy").write_bytes((tmp_path / "psf.npy").read_bytes()[:200])
    flat = focal_plane(load_config(overrides=[f"optics.psf={tmp_path / 'huge.npy'}"])).psf.core  # #79: not black
    assert np.isfinite(flat).all() and np.allclose(flat.sum(axis=(1, 2)), 1.0)
    for name, needle in [("cube.npy", "2-D"), ("nan.npy", "finite"), ("zero.npy", "somewhere above 0"),
                         ("objects.npy", "holds object"), ("short.npy", "truncated")]:
        with pytest.raises(CmosnoiseError, match=needle) as info:
            focal_plane(load_config(overrides=[f"optics.psf={tmp_path / name}"]))
        assert "optics.psf" in str(info.value) and "\n" not in str(info.value)
    with pytest.raises(CmosnoiseError, match="give none, diffraction, gaussian"):
        focal_plane(load_config(overrides=["optics.psf=airy"]))


def test_a_point_through_a_gaussian_lens_is_the_gaussian_integrated_over_the_pixel():
    # a spot (one pixel lit) on a monochrome sensor, through a Gaussian of sigma 1.2 px on a grid of k = 2 (the
    # PSF point-sampled there, normalised over 4 sigma): each pixel collects the PSF's light over its four cells,
    # its own cells' light spread too: the discrete convolution of the pixel's 2 x 2 cells with the sampled
    # Gaussian, summed over the pixels' 2 x 2 cells, written here from the samples alone. Float64 sums of a few
    # hundred terms: within 1e-15 of each value's scale
    sigma, k = 1.2, 2
    c = load_config(overrides=QUIET + ["optics.psf=gaussian", f"optics.psf_sigma_px={sigma}", "sensor.cfa=none",
                                       "sensor.width=40", "sensor.height=30", f"optics.oversample={k}"])
    signal = Sensor(c).scene_signal("spot")
    half = int(np.ceil(4 * sigma * k))
    g = np.exp(-0.5 * (np.arange(-half, half + 1) / (sigma * k)) ** 2)
    g /= g.sum()
    box = np.convolve(np.convolve(g, np.ones(k)), np.ones(k) / k)  # a lit pixel's k cells, then a pixel's k cells
    # the lit pixel's first cell is at 2 * 15 (rows) and 2 * 20 (columns): pixel i's first cell at 2 i
    offsets = np.arange(box.size) - half - (k - 1)
    line_r = np.zeros(30)
    line_c = np.zeros(40)
    for d, v in zip(offsets, box):
        if d % k == 0:
            line_r[15 + d // k] += v
            line_c[20 + d // k] += v
    want = np.outer(line_r, line_c)
    assert np.abs(signal - want).max() <= 1e-15
    assert signal.sum() == pytest.approx(1.0, abs=1e-14)  # the light is kept


@pytest.mark.parametrize("source", ["photo", "edge"])
@pytest.mark.slow
def test_the_separable_terms_are_the_fine_grids_own_convolution_within_their_tolerance(source):
    # the optical image made explicitly on the fine grid (the scene's cells convolved with the PSF's core and halo,
    # scipy's direct convolution of the cells drawn with their edge cells repeated) against the separable terms'
    # irradiance: the terms are within TERM_TOLERANCE of each core's peak (their construction) and the halo is
    # exact, so each cell is within TERM_TOLERANCE x peak x (the core's cells) x (the scene's largest value)
    from scipy import ndimage

    c = load_config(overrides=QUIET + ["optics.psf=diffraction", "optics.f_number=4", "sensor.width=60",
                                       "sensor.height=44"])
    fp = focal_plane(c)
    draw = fp.prepare(source, c.scene)
    got = fp.irradiance(draw)
    cells = np.asarray(draw((0, fp.fine_shape[0], 0, fp.fine_shape[1])), float)
    for ch in range(3):
        psf = fp.psf
        sigma = psf.halo_sigma_cells[ch]
        half = int(np.ceil(optics.GAUSS_SIGMAS * sigma))
        gl = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma) ** 2)
        gl /= gl.sum()
        kernel = np.outer(gl, gl) * psf.halo_share[ch]
        m = psf.core.shape[1] // 2
        kernel[half - m:half + m + 1, half - m:half + m + 1] += psf.core[ch]
        want = ndimage.convolve(cells[..., ch], kernel, mode="nearest") * fp.cfa_gain[ch]
        bound = TERM_TOLERANCE * psf.core[ch].max() * psf.core[ch].size * cells.max() * fp.cfa_gain[ch]
        assert np.abs(got[..., ch] - want).max() <= bound, ch


def test_the_optical_image_integrated_over_each_pixel_is_what_the_pixel_gets_and_the_light_is_kept():
    # the irradiance on the fine grid summed over each pixel's k x k cells (a full aperture) is the pixel's
    # signal: the same linear operation in another order of float64 sums (within 1e-13 of the values); over the
    # sensor it is the light that came through the lens (a spot far from the edges: nothing is lost past them)
    c = load_config(overrides=QUIET + ["optics.psf=diffraction", "optics.f_number=2.8", "sensor.width=64",
                                       "sensor.height=48", "sensor.cfa=RGGB"])
    fp = focal_plane(c)
    k = fp.k
    draw = fp.prepare("spot", c.scene)
    fine = fp.irradiance(draw)
    pixel = fp.pixel_signal(draw, "RGGB", shade=False)
    summed = fine.reshape(48, k, 64, k, 3).mean(axis=(1, 3))
    cells = cfa.tile("RGGB")
    want = np.empty((48, 64))
    for a in range(2):
        for b in range(2):
            want[a::2, b::2] = summed[a::2, b::2, cells[a, b]]
    assert np.abs(pixel - want).max() <= 1e-13 * pixel.max()
    assert summed.sum(axis=(0, 1)) == pytest.approx(fp.cfa_gain, rel=1e-12)  # each channel's light, all of it


@pytest.mark.parametrize("psf", ["diffraction", "gaussian"])
def test_a_flat_field_is_unchanged_by_a_psf_away_from_the_border(psf):
    # every kernel sums to 1 (core and halo), so a flat field stays flat to float64 rounding
    c = load_config(overrides=QUIET + [f"optics.psf={psf}", "optics.f_number=8", "optics.psf_sigma_px=1.5",
                                       "sensor.width=160", "sensor.height=120"])
    sharp = Sensor(load_config(overrides=QUIET + ["sensor.width=160", "sensor.height=120"])).scene_signal("flat:0.4")
    blurred = Sensor(c).scene_signal("flat:0.4")
    assert np.abs(blurred - sharp).max() <= 1e-12


# ------------------------------------------------------------------ tiles keep their bits
@pytest.mark.parametrize(("source", "f_number"), [("photo", 11), ("edge", 11), ("colorchecker", 11), ("photo", 2.8),
                                                  ("zoneplate:0.9", 2.8)])
def test_with_optics_every_tile_is_that_rectangle_of_the_whole_frame(source, f_number):
    cfg = load_config(overrides=["optics.psf=diffraction", f"optics.f_number={f_number}",
                                 "optics.relative_illumination=cos4", "optics.focal_length_mm=1.5",
                                 "sensor.width=530", "sensor.height=300"])
    whole = Sensor(cfg).expose(source).frame(0)
    tiling = tiles.Tiling(cfg, 96, source)
    for region in tiling.regions:
        r0, r1, c0, c1 = region
        raw = next(tiling.frames(region, 1))
        assert np.array_equal(raw, whole[r0:r1, c0:c1]), region


@pytest.mark.parametrize("sigma_px", [2, pytest.param(7, marks=pytest.mark.slow)])  # 7 px: 50 s, the full suite's
def test_a_tile_of_a_50_mp_sensor_is_the_crop_of_a_larger_part_bit_for_bit(sigma_px):
    # a 50 MP sensor (8688 x 5792): the signal of a tile against that of a part of 3000 x 1000 pixels around it
    # (the bands of the columns' pass start at the region's first row: tiles cut them elsewhere)
    cfg = load_config(overrides=["optics.psf=gaussian", f"optics.psf_sigma_px={sigma_px}", "sensor.width=8688",
                                 "sensor.height=5792", "optics.oversample=2"])
    fp = focal_plane(cfg)
    draw = fp.prepare("photo", cfg.scene)
    big = (2048, 3072, 3000, 6000)
    part = fp.pixel_signal(draw, "RGGB", big)
    for tile in [(2100, 2400, 4200, 4500), (2048, 2304, 4350, 4700), (2500, 3000, 4097, 4300)]:
        got = fp.pixel_signal(draw, "RGGB", tile)
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
