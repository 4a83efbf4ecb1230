"""Light in lux (#60): radiometric closure against an independent integral and colour-hdri, the spectral path
against the RGB path, the ColorChecker from its reflectance spectra, and bad light in one line.

The independent integrals here are the test's own: colour-science's tables at 1 nm (its own interpolation of the
5 nm illuminants and charts), the formulas of docs/model.md section 2b written out again, a plain Riemann sum. The
model integrates at 5 nm with the trapezoid rule; the two agree to well under the 0.5 % the issue asks."""

import colour
import numpy as np
import pytest
from conftest import cli

from cmosnoise import Sensor, load_config
from cmosnoise.errors import CmosnoiseError
from cmosnoise.model import light, scene
from cmosnoise.model.focal_plane import axis_illuminance_lux, focal_plane
from cmosnoise.model.spec import resolve

#: every noise stage off, no ADC: the exposure's mean is the light alone
QUIET = ["shot_noise.enabled=false", "source_follower.enabled=false", "row_noise.enabled=false",
         "column_noise.enabled=false", "dark_current.enabled=false", "prnu.enabled=false",
         "crosstalk.enabled=false", "adc.enabled=false"]
H, C = 6.62607015e-34, 299792458.0


def _config(*sets, quiet=True):
    return load_config(overrides=(QUIET if quiet else []) + ["light.enabled=true"] + list(sets))


def _independent_electrons(lux, reflectance, f_number, transmittance, seconds, pitch_um, qe_of_nm,
                           illuminant="D65", magnification=0.0):
    """Photo-electrons per pixel, integrated at 1 nm from colour-science's tables: the camera equation of ISO 12232
    (E_image = pi L T / (4 N^2 (1 + m)^2)) and photons lambda / (h c)."""
    shape = colour.SpectralShape(380, 780, 1)
    sd = colour.SDS_ILLUMINANTS[illuminant].copy().align(shape)
    wl, power = np.asarray(sd.wavelengths), np.asarray(sd.values)
    ybar = np.asarray(colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape).values[:, 1])
    irradiance = power * lux / (683.0 * np.sum(power * ybar))  # W m^-2 nm^-1, 1 nm steps
    radiance = reflectance * irradiance / np.pi
    image = np.pi * radiance * transmittance / (4 * f_number**2 * (1 + magnification) ** 2)
    photons = image * wl * 1e-9 / (H * C) * (pitch_um * 1e-6) ** 2 * seconds
    return float(np.sum(photons * qe_of_nm(wl)))


@pytest.mark.parametrize("lux, f_number, seconds, qe", [(100, 2.8, 0.03, 0.5), (5, 2.0, 1 / 30, 0.8),
                                                         (1000, 8.0, 0.002, 0.35)])
def test_a_grey_card_collects_the_independently_integrated_electrons(lux, f_number, seconds, qe):
    c = _config(f"light.illuminance_lux={lux}", f"optics.f_number={f_number}", f"exposure.integration_time_s={seconds}",
                f"sensor.quantum_efficiency={qe}", "sensor.pixel_pitch_um=2.2", "sensor.cfa=none",
                "sensor.width=32", "sensor.height=24")
    got = float(Sensor(c).expose("flat:0.18").photo_mean_e.mean())
    want = _independent_electrons(lux, 0.18, f_number, 0.9, seconds, 2.2, lambda wl: np.full_like(wl, qe))
    assert got == pytest.approx(want, rel=0.005)


def test_a_spectral_qe_and_an_incandescent_light_close_too():
    # the Nikon D5100's relative sensitivities (colour-science's NPL set) scaled to a peak QE of 0.6, under CIE A
    msds = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    top = msds.values.max()
    c = _config("light.illuminance_lux=50", "light.illuminant=A", "light.spectral_qe=Nikon 5100 (NPL)",
                "light.qe_peak=0.6", "sensor.width=32", "sensor.height=24")
    shot = Sensor(c).expose("flat:1")
    for ch, (r, col) in enumerate([(0, 0), (0, 1), (1, 1)]):  # RGGB: R, G, B
        def qe(wl, ch=ch):
            return np.interp(wl, msds.wavelengths, msds.values[:, ch]) * 0.6 / top
        want = _independent_electrons(50, 1.0, 2.8, 0.9, 0.03, 2.2, qe, illuminant="A")
        assert float(shot.photo_mean_e[r::2, col::2].mean()) == pytest.approx(want, rel=0.005), ch


def test_the_sanity_figure_of_the_references_comes_out():
    # imaging-chain-references.md section 1: about 14 000 photons per lux-second per square micrometre (D65), so an
    # 18 % grey card at 100 lux, f/2.8, 30 ms on a 2.2 um pixel receives about 1 150 photons
    c = _config("light.illuminance_lux=100", "sensor.quantum_efficiency=1", "optics.transmittance=1")
    photons = focal_plane(c).white_e_per_s[1] * 0.03 * 0.18
    assert photons == pytest.approx(1150, rel=0.02)


@pytest.mark.parametrize("f_number, seconds, magnification, luminance", [(8, 1 / 250, 0.0, 4000), (2.8, 0.03, 0.1, 57.3),
                                                                         (1.4, 1.0, 0.5, 2.0)])
def test_the_focal_plane_exposure_is_colour_hdris(f_number, seconds, magnification, luminance):
    c = _config(f"light.luminance_cd_m2={luminance}", f"optics.f_number={f_number}",
                f"optics.magnification={magnification}", "sensor.quantum_efficiency=0.5")
    ours = axis_illuminance_lux(c) * seconds
    focal = 0.05  # the thin lens: the image distance is f (1 + m)
    colour_hdri = pytest.importorskip("colour_hdri")  # the [test] extra's: the suite collects without it
    theirs = colour_hdri.focal_plane_exposure(luminance, f_number, seconds, focal, focal * (1 + magnification), 0.0,
                                              T=0.9, f_v=1.0, theta=0.0)
    assert ours == pytest.approx(float(theirs), rel=0.01)


def test_the_non_paraxial_equation_is_isetcams():
    c = _config("light.illuminance_lux=100", "optics.f_number=2", "optics.camera_equation=non_paraxial",
                "sensor.quantum_efficiency=0.5")
    assert axis_illuminance_lux(c) == pytest.approx(np.pi * (100 / np.pi) * 0.9 / (1 + 4 * 2**2), rel=1e-12)


def test_a_grey_through_the_spectral_path_is_the_rgb_path_with_the_integrated_responsivities():
    c = _config("light.illuminance_lux=20", "light.spectral_qe=Nikon 5100 (NPL)", "light.qe_peak=0.55",
                "light.illuminant=FL2", "sensor.width=64", "sensor.height=48")
    spec = resolve(c)
    rates = spec.focal_plane.white_e_per_s
    assert spec.channel_responsivity == pytest.approx(tuple(rates / rates.mean()), rel=1e-15)
    sensor = Sensor(c)
    spectral = sensor.scene_signal("flat:0.3")  # each pixel's rate, e-/s (the focal plane's unit with light in lux)
    rgb = scene.to_cfa(np.full((48, 64, 3), 0.3), "RGGB", rates)
    assert np.allclose(spectral, rgb, rtol=4e-16, atol=0)
    # and in electrons: 0.3 of each channel's rate for the integration time
    e = sensor.expose("flat:0.3").photo_mean_e
    assert float(e[0::2, 0::2].mean()) == pytest.approx(0.3 * rates[0] * 0.03, rel=1e-6)
    assert float(e[1::2, 1::2].mean()) == pytest.approx(0.3 * rates[2] * 0.03, rel=1e-6)


def test_colorchecker_patches_are_the_integrals_of_reflectance_illuminant_and_qe():
    c = _config("light.illuminance_lux=300", "light.spectral_qe=Nikon 5100 (NPL)", "light.qe_peak=0.5",
                "sensor.width=240", "sensor.height=160")
    shot = Sensor(c).expose("colorchecker")
    msds = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    top = msds.values.max()
    charts = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    for (rows, cols), sd in zip(scene.colorchecker_patches((160, 240)), charts.values()):
        refl = sd.copy().align(colour.SpectralShape(380, 780, 1))
        patch = shot.photo_mean_e[rows, cols]
        for ch, (r, col) in enumerate([(0, 0), (0, 1), (1, 1)]):
            def qe(wl, ch=ch):
                return np.interp(wl, msds.wavelengths, msds.values[:, ch]) * 0.5 / top
            want = _independent_electrons(300, np.asarray(refl.values), 2.8, 0.9, 0.03, 2.2, qe)
            got = float(patch[(rows.start + r) % 2::2, (cols.start + col) % 2::2].mean())
            assert got == pytest.approx(want, rel=0.005), (sd.name, ch)


def test_an_rgb_picture_is_mixed_by_the_light_before_it_is_resampled():
    c = _config("light.illuminance_lux=100", "light.spectral_qe=Nikon 5100 (NPL)", "light.qe_peak=0.5",
                "sensor.width=80", "sensor.height=60")
    spec = resolve(c)
    img = scene.load_file(scene.bundled_photo_path())
    a = scene.render("photo", (60, 80), light=spec.light)
    b = scene.render("photo", (60, 80))
    assert np.allclose(a, b @ spec.light.mix.T, rtol=1e-9, atol=1e-12)
    assert img.ndim == 3 and not np.allclose(a, b)  # the mix does change colours


def test_light_off_keeps_the_peak_rate_and_the_bits():
    c = load_config(overrides=["light.enabled=false", "light.illuminance_lux=100"])  # given but off: nothing changes
    spec = resolve(c)
    assert spec.light is None and spec.peak_rate_e_per_s == 100000.0
    assert np.array_equal(Sensor(c).expose("photo").frame(0), Sensor(load_config()).expose("photo").frame(0))


@pytest.mark.parametrize("sets, needle", [
    (["light.illuminance_lux=-3"], "light.illuminance_lux"),
    (["light.illuminance_lux=10", "optics.f_number=0.3"], "optics.f_number"),
    (["light.illuminance_lux=10", "light.illuminance_lux=10", "light.luminance_cd_m2=3"], "give the light once"),
    (["light.illuminance_lux=10", "light.illuminant=D66"], "light.illuminant = 'D66' is not known"),
    (["light.illuminance_lux=10", "light.illuminant=blackbody:20"], "blackbody:KELVIN"),
    (["light.illuminance_lux=10", "light.spectral_qe=[[400, 0.5], [500, 1.4]]"], "in [0, 1]"),
    (["light.illuminance_lux=10", "light.spectral_qe=[[500, 0.5], [400, 0.4]]"], "increasing"),
    (["light.illuminance_lux=10", "light.spectral_qe=[[900, 0.5], [1000, 0.4]]"], "do not overlap"),
    (["light.illuminance_lux=10", "light.spectral_qe=Nikon 5100 (NPL)"], "light.qe_peak"),
    (["light.illuminance_lux=10", "sensor.quantum_efficiency=0.5", "light.ir_cut_nm=350"], "do not overlap"),
])
def test_bad_light_is_one_line_naming_the_key(sets, needle):
    with pytest.raises(CmosnoiseError, match=needle.replace("[", r"\[").replace("(", r"\(")) as info:
        _ = resolve(load_config(overrides=["light.enabled=true"] + sets)).light
    assert "\n" not in str(info.value)


def test_bad_light_on_the_command_line_is_one_line(tmp_path):
    r = cli("simulate", "-o", str(tmp_path / "run"), "--set", "light.enabled=true", "--set",
            "light.illuminance_lux=10", "--set", "light.illuminant=D66", "--set", "sensor.quantum_efficiency=0.5")
    assert r.returncode != 0 and "Traceback" not in r.stderr and "light.illuminant" in r.stderr
    assert not (tmp_path / "run").exists()


def test_an_illuminant_and_a_qe_from_csv_files(tmp_path):
    (tmp_path / "flat.csv").write_text("nm,power\n380,1\n780,1\n")
    (tmp_path / "qe.csv").write_text("# wavelength, QE\n380 0.5\n780 0.5\n")
    c = _config("light.illuminance_lux=10", f"light.illuminant={tmp_path / 'flat.csv'}",
                f"light.spectral_qe={tmp_path / 'qe.csv'}")
    li = focal_plane(c).light
    assert li.rates_e_per_s[0] == li.rates_e_per_s[2] and np.allclose(li.mix, li.mix[0])
    e = light.illuminant_spectrum("E")  # the equal-energy illuminant closes the same way
    assert np.allclose(e[1], e[1][0])


def test_light_leaves_numpys_print_options_as_they_were():
    # colour-science's import sets numpy's legacy printing (12 digits) for the whole process; a CSV written after a
    # light run lost digits through it. cmosnoise.colour_lib puts the options back.
    before = np.get_printoptions()
    focal_plane(_config("light.illuminance_lux=3", "sensor.quantum_efficiency=0.4"))
    from cmosnoise.isp import reconstruction

    reconstruction.demosaic(np.ones((8, 8), np.float32), "RGGB", "malvar2004")
    assert np.get_printoptions() == before


def test_characterize_reports_its_light_axis_in_lux_seconds(tmp_path):
    import json

    sets = ["light.enabled=true", "light.illuminance_lux=100", "sensor.quantum_efficiency=0.5", "sensor.width=96",
            "sensor.height=64"]
    args = [a for s in sets for a in ("--set", s)]
    r = cli("characterize", *args, "--steps", "12", "--stack-frames", "4", "--out", tmp_path / "c")
    assert r.returncode == 0, r.stderr
    data = json.loads((tmp_path / "c" / "characterization.json").read_text())
    h = np.asarray(data["series"]["focal_plane_lux_s"])
    fp = focal_plane(load_config(overrides=sets))
    # a white at this light gives its peak rate at fp.focal_plane_lux lux: each step's electrons over that ratio
    electrons = np.asarray(data["series"]["mu_p"]) * 0.5
    assert np.allclose(h, electrons * fp.focal_plane_lux / fp.peak_rate_e_per_s, rtol=1e-12)
    assert (np.diff(h) > 0).all() and data["light"]["illuminant"] == "D65"


def test_a_run_with_light_says_what_a_white_gives(tmp_path):
    import json

    r = cli("-q", "simulate", "--set", "light.enabled=true", "--set", "light.illuminance_lux=50", "--set",
            "sensor.quantum_efficiency=0.6", "--set", "sensor.width=64", "--set", "sensor.height=48",
            "--out", tmp_path / "run")
    assert r.returncode == 0, r.stderr
    got = json.loads((tmp_path / "run" / "summary.json").read_text())["light"]
    c = load_config(tmp_path / "run" / "config.yaml")
    fp = focal_plane(c)
    assert got["illuminance_lux"] == 50 and got["illuminant"] == "D65" and got["f_number"] == 2.8
    assert got["focal_plane_lux"] == pytest.approx(axis_illuminance_lux(c), rel=1e-12)
    assert got["white_e"] == pytest.approx(list(fp.white_e_per_s * 0.03), rel=1e-12)


def test_a_multispectral_cube_is_each_pixels_spectrum_through_the_light_and_the_qe(tmp_path):
    # a cube of two halves: the ColorChecker's "red" patch's spectrum and a flat 0.5. Each pixel's channels are
    # its spectrum's integral with the light and the channel's QE over a white's (the chart's own integral,
    # light.reflectance_channels), so the flat half reads 0.5 of each channel's white and the red half the red
    # patch's channels of the spectral ColorChecker
    wl, refl = light.colorchecker_reflectances()
    red = refl[14]
    cube = np.empty((48, 64, wl.size))
    cube[:, :32] = red
    cube[:, 32:] = 0.5
    np.savez(tmp_path / "cube.npz", reflectance=cube, wavelengths_nm=wl)
    c = _config("light.illuminance_lux=100", "light.spectral_qe=Nikon 5100 (NPL)", "light.qe_peak=0.5",
                "sensor.width=64", "sensor.height=48")
    signal = Sensor(c).scene_signal(str(tmp_path / "cube.npz"))
    fp = focal_plane(c)
    want_red = fp.light.reflectance_channels(red[None, :], wl)[0] * fp.cfa_gain
    assert signal[0, 0] == pytest.approx(want_red[0], rel=1e-9) and signal[1, 1] == pytest.approx(want_red[2], rel=1e-9)
    assert signal[0, 33] == pytest.approx(0.5 * fp.cfa_gain[1], rel=1e-12)
    with pytest.raises(CmosnoiseError, match="needs light in lux"):
        Sensor(load_config(overrides=["sensor.width=64", "sensor.height=48"])).scene_signal(str(tmp_path / "cube.npz"))
    np.savez(tmp_path / "bad.npz", cube=cube)
    with pytest.raises(CmosnoiseError, match="'reflectance'") as info:
        Sensor(c).scene_signal(str(tmp_path / "bad.npz"))
    assert "\n" not in str(info.value)


def test_without_a_qe_the_default_sensor_has_a_measured_cameras_spectra():
    # neither light.spectral_qe nor sensor.quantum_efficiency: the Nikon D5100's three spectra at a peak of 0.65, so
    # the channels differ (colour) and a flat grey's green collects what those spectra give, not a flat QE's 3.6x
    fp = focal_plane(load_config(overrides=["light.enabled=true", "light.illuminance_lux=10"]))
    assert abs(fp.light.qe.max() - light.DEFAULT_QE_PEAK) < 1e-12
    assert len({round(float(v), 6) for v in fp.white_e_per_s}) == 3
    flat = focal_plane(load_config(overrides=["light.enabled=true", "light.illuminance_lux=10",
                                              f"sensor.quantum_efficiency={light.DEFAULT_QE_PEAK}"]))
    assert 3.0 < flat.white_e_per_s[1] / fp.white_e_per_s[1] < 4.5
