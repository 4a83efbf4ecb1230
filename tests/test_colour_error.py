"""Colour error (#61): CIEDE2000 after a least-squares colour matrix, below 0.5 with the noise off and an exact
matrix, equal to colour-science's delta_E on the patch means, and larger where the camera's filters are real."""

import colour
import numpy as np
import pytest

from cmosnoise import Sensor, load_config
from cmosnoise.analysis import colour_error
from cmosnoise.errors import CmosnoiseError
from cmosnoise.model import charts

QUIET = ["shot_noise.enabled=false", "source_follower.enabled=false", "row_noise.enabled=false",
         "column_noise.enabled=false", "dark_current.enabled=false", "prnu.enabled=false"]


def _camera(sets, shape=(240, 360)):
    c = load_config(overrides=QUIET + [f"sensor.width={shape[1]}", f"sensor.height={shape[0]}"] + sets)
    sensor = Sensor(c)
    raw = sensor.expose("colorchecker").frame(0)
    patches = charts.truth("colorchecker", shape)["patches"]
    return colour_error.mosaic_patch_means(raw, sensor.cfa, patches, sensor.transfer.black_level_dn)


def test_noise_off_and_an_exact_matrix_give_under_half_a_jnd():
    # light in e-/s: the camera's channels are sRGB's times the responsivities, mixed by crosstalk: a linear map,
    # so the least-squares matrix is exact (the ADC's rounding is all that is left)
    cam = _camera(["sensor.channel_responsivity=[0.6, 1.0, 0.8]", "adc.gain_dn_per_e=0.5"])
    r = colour_error.colour_error(cam)
    assert r["mean_de2000"] < 0.5 and r["max_de2000"] < 1.0


def test_the_error_is_colour_sciences_delta_e_on_the_patch_means():
    cam = _camera(["light.enabled=true", "light.illuminance_lux=300", "light.spectral_qe=Nikon 5100 (NPL)",
                   "light.qe_peak=0.5"])
    r = colour_error.colour_error(cam)
    ref = colour_error.reference_linear_srgb()
    space = colour.RGB_COLOURSPACES["sRGB"]

    def lab(x):
        return colour.XYZ_to_Lab(colour.RGB_to_XYZ(x, space, apply_cctf_decoding=False))

    theirs = colour.delta_E(lab(np.clip(cam @ r["matrix"].T, 0, None)), lab(ref), method="CIE 2000")
    assert np.allclose(r["de2000"], theirs, rtol=1e-12, atol=1e-12)
    # a real camera's filters are not a linear map of sRGB (the Luther condition): a measurable error remains
    assert 0.5 < r["mean_de2000"] < 10


def test_bad_patches_are_one_line():
    with pytest.raises(CmosnoiseError, match="outside"):
        colour_error.mosaic_patch_means(np.zeros((10, 10)), "RGGB", [(0, 20, 0, 5)])
    with pytest.raises(CmosnoiseError, match=r"\(n, 3\)"):
        colour_error.fit_matrix(np.zeros((24, 2)), np.zeros((24, 3)))
