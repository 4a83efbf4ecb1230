"""SNR against illuminance (#61): the simulated curve of a grey patch matches the noise model's prediction within
sampling error, and SNR10 lies where the model puts it."""

import math

import numpy as np
import pytest

from cmosnoise import load_config
from cmosnoise.analysis import snr_light
from cmosnoise.errors import CmosnoiseError

CAMERA = ["light.enabled=true", "light.spectral_qe=Nikon 5100 (NPL)", "light.qe_peak=0.55",
          "exposure.integration_time_s=0.033333", "light.illuminance_lux=1"]


def _tolerance(curve, i):
    """5 standard errors of a measured SNR: the mean's (noise / sqrt(pixels x frames), relative to the signal) and
    the temporal sigma's (sqrt(1 / (2 dof)), dof = pixels x (frames - 1)), added in quadrature."""
    n, k = curve["pixels"], curve["frames"]
    snr = curve["snr_predicted"][i]
    rel_mean = 1 / (snr * math.sqrt(n * k))
    rel_sd = math.sqrt(1 / (2 * n * (k - 1)))
    return 5 * math.hypot(rel_mean, rel_sd)


def test_the_measured_snr_curve_is_the_noise_models():
    curve = snr_light.snr_curve(load_config(overrides=CAMERA), [0.3, 1, 3, 10, 30, 100, 300, 1000], frames=12)
    for i, lux in enumerate(curve["lux"]):
        got, want = curve["snr_measured"][i], curve["snr_predicted"][i]
        assert got == pytest.approx(want, rel=_tolerance(curve, i)), lux
    assert curve["snr_predicted"] == sorted(curve["snr_predicted"])  # more light, more SNR
    assert curve["signal_e"][-1] / curve["signal_e"][0] == pytest.approx(1000 / 0.3, rel=1e-6)  # e- in proportion


def test_snr10_lies_where_the_model_puts_it():
    c = load_config(overrides=CAMERA)
    want = snr_light.predicted_crossing_lux(c, 10.0)
    grid = list(want * np.array([0.6, 0.8, 1.0, 1.25, 1.6]))
    curve = snr_light.snr_curve(c, grid, frames=12)
    # the lux's relative error: the SNR's (5 standard errors) over the slope of ln SNR against ln lux, which for
    # SNR = s / sqrt(s + r^2) (s the photo-charge) is 1 - s / (2 (s + r^2)), at least 1/2; plus the straight-line
    # interpolation's in ln-ln, at most h^2 / 8 times the curve's |second derivative| r^2 s / (2 (s + r^2)^2) <= 1/8,
    # over the same slope (h = ln 1.25, the grid's step)
    interpolation = math.log(1.25) ** 2 / 8 / 8
    assert curve["snr10_lux"] == pytest.approx(want, rel=(_tolerance(curve, 2) + interpolation) / 0.5)
    assert curve["snr10_lux_predicted"] == pytest.approx(want, rel=1e-9)
    assert curve["f_number"] == 2.8 and curve["integration_time_s"] == 0.033333


def test_snr_against_lux_needs_light_and_good_values():
    with pytest.raises(CmosnoiseError, match="light.enabled"):
        snr_light.snr_curve(load_config(), [1, 10])
    with pytest.raises(CmosnoiseError, match="increasing"):
        snr_light.snr_curve(load_config(overrides=CAMERA), [10, 1])
    with pytest.raises(CmosnoiseError, match="frames"):
        snr_light.snr_curve(load_config(overrides=CAMERA), [1, 10], frames=1)
    assert snr_light.crossing_lux([1, 2], [3, 4], 10) is None
