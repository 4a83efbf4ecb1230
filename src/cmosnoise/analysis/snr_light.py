"""Signal-to-noise ratio against illuminance: the SNR curve of a grey patch from 0.1 to 10 000 lux, SNR10 and SNR1.

For a configuration with light in lux (:mod:`cmosnoise.model.light`), at each illuminance a flat field of
reflectance ``reflectance`` (0.18, the reference grey) is exposed and ``frames`` frames are drawn. The SNR is the
raw green channel's, in electrons: the patch's mean photo-charge over its **temporal** noise (each pixel's standard
deviation over the frames, their variances averaged over the green pixels), the noise a picture of a still scene
shows from frame to frame. The model's own prediction, from the same sensor instance, is the exposure's mean green
photo-charge over the square root of :func:`cmosnoise.analysis.noise_budget.temporal_variances` plus
:func:`~cmosnoise.analysis.noise_budget.after_gain_variances` at that charge.

**SNR10** (SNR1) is the illuminance at which the SNR reaches 10 (1): on the predicted curve, found exactly (the
photo-charge is proportional to the illuminance); on the measured one, interpolated linearly in log SNR against
log lux between the two illuminances around it. Both are stated with the f-number and exposure time they hold at
(the mobile-camera practice; Sony's SNR1s states F1.4, 1/60 s and 3200 K).

Examples
--------
>>> from cmosnoise import load_config
>>> from cmosnoise.analysis import snr_light
>>> c = load_config(overrides=["light.enabled=true", "light.illuminance_lux=1", "sensor.quantum_efficiency=0.5"])
>>> curve = snr_light.snr_curve(c, [1, 10, 100], frames=4, shape=(32, 48))
>>> [round(s, 1) for s in curve["snr_predicted"]]
[1.5, 6.8, 22.7]
"""

from __future__ import annotations

import math

import numpy as np

from ..config import merge_updates
from ..errors import CmosnoiseError
from ..estimators import snr
from ..model.sensor import Sensor
from . import noise_budget

__all__ = ["snr_curve", "crossing_lux", "predicted_crossing_lux", "noise_based_speed", "NOISE_SPEED_SNR",
           "NOISE_SPEED_K"]

#: ISO 12232's signal-to-noise ratios of the noise-based speeds: the first "excellent" picture and the first
#: "acceptable" one (judged on prints of about 70 sensor pixels per cm seen from 25 cm; ISO 12232:2019, note 3 of
#: the noise-based speed's clause, read in the AS ISO 12232:2019 excerpt)
NOISE_SPEED_SNR = {"excellent": 40.0, "acceptable": 10.0}
#: K of ISO 12232's noise-based speed S = K / H, lux-seconds: it places the exposures at a mid-tone, about an
#: 18 % grey of a 160:1 scene (the same excerpt's note 1 names K; its value 10 is read in JPEG XL's
#: enc_photon_noise.cc, "ISO = 10 lx s / H", not in the standard's own formula)
NOISE_SPEED_K = 10.0


def _sensor(config, lux: float, shape, seed: int) -> Sensor:
    c = merge_updates(config, {"light": {"illuminance_lux": float(lux)},
                               "sensor": {"height": int(shape[0]), "width": int(shape[1])}})
    return Sensor(c, seed=seed)


def _green(a: np.ndarray, pattern: str) -> np.ndarray:
    """The green pixels (a monochrome sensor: all of them), (frames, n)."""
    if pattern == "none":
        return a.reshape(a.shape[0], -1)
    from ..model import cfa as cfa_mod

    mask = cfa_mod.channel_map(pattern, a.shape[1:]) == 1
    return a[:, mask]


def measured_snr(sensor: Sensor, shot, stack: np.ndarray) -> float:
    """The measured SNR of a grey patch's frames: the green pixels' mean photo-charge (their mean less the
    exposure's mean dark charge) over their temporal noise (each pixel's variance over the frames, averaged).

    Parameters
    ----------
    sensor : Sensor
        The sensor that made the frames.
    shot : Exposure
        Their exposure (its mean dark charge is taken out of the signal).
    stack : (frames, rows, cols) array, DN
        Raw frames, at least 2.

    Returns
    -------
    float
    """
    t = sensor.transfer
    green = (_green(np.asarray(stack, np.float64), sensor.cfa) - t.black_level_dn) / t.gain_dn_per_e
    return snr(float(green.mean() - _dark_mean(sensor, shot)), math.sqrt(float(green.var(axis=0, ddof=1).mean())))


def predicted_snr(sensor: Sensor, shot) -> tuple[float, float]:
    """The noise model's signal and noise of the exposure's green pixels (e-): their mean photo-charge, and the
    square root of :func:`~cmosnoise.analysis.noise_budget.temporal_variances` plus
    :func:`~cmosnoise.analysis.noise_budget.after_gain_variances` at that charge.

    Parameters
    ----------
    sensor : Sensor
    shot : Exposure

    Returns
    -------
    (float, float)
        Signal and noise, e-.
    """
    return _predicted(sensor, shot)


def _predicted(sensor: Sensor, shot) -> tuple[float, float]:
    """(mean green photo-charge, its predicted temporal noise), e-."""
    signal = float(_green(np.asarray(shot.photo_mean_e)[None], sensor.cfa).mean())
    var = sum(noise_budget.temporal_variances(sensor, signal).values())
    var += sum(noise_budget.after_gain_variances(sensor).values())
    return signal, math.sqrt(var)


def snr_curve(config, lux, frames: int = 8, shape=(96, 128), reflectance: float = 0.18, seed: int = 0) -> dict:
    """The measured and predicted SNR of a grey patch at each illuminance (see the module docstring).

    Parameters
    ----------
    config : Config
        With ``light.enabled`` (its illuminance is replaced by each of ``lux``).
    lux : sequence of float
        Illuminances, lux, increasing.
    frames : int
        Frames drawn at each, at least 2.
    shape : (rows, cols)
        The patch's size: a sensor of this size is simulated (the sensor's own size does not matter to a flat field).
    reflectance : float
        The patch's reflectance, 0 to 1.
    seed : int
        The sensor instance.

    Returns
    -------
    dict
        ``lux``, ``signal_e`` and ``noise_e`` (predicted, e-), ``snr_predicted``, ``snr_measured`` (lists),
        ``f_number``, ``integration_time_s``, ``reflectance``, ``frames``, ``pixels`` (green pixels measured),
        ``snr10_lux`` and ``snr1_lux`` (measured, interpolated; None outside the curve), ``snr10_lux_predicted``
        and ``snr1_lux_predicted``.
    """
    if not config.light.enabled:
        raise CmosnoiseError("SNR against illuminance needs light in lux: set light.enabled=true (and the light's "
                             "spectrum and the lens)")
    lux = [float(v) for v in lux]
    if not lux or any(v <= 0 for v in lux) or any(b <= a for a, b in zip(lux, lux[1:])):
        raise CmosnoiseError(f"lux = {lux}: give increasing illuminances above 0")
    if int(frames) < 2:
        raise CmosnoiseError(f"frames = {frames}: the temporal noise needs at least 2")
    if not 0 < reflectance <= 1:
        raise CmosnoiseError(f"reflectance = {reflectance:g}: give a reflectance in (0, 1]")
    out = {"lux": lux, "signal_e": [], "noise_e": [], "snr_predicted": [], "snr_measured": [],
           "f_number": config.optics.f_number, "integration_time_s": config.exposure.integration_time_s,
           "reflectance": reflectance, "frames": int(frames)}
    for v in lux:
        sensor = _sensor(config, v, shape, seed)
        shot = sensor.expose(f"flat:{reflectance!r}")
        stack = np.stack(list(shot.frames(int(frames))))
        signal, noise = _predicted(sensor, shot)
        out["signal_e"].append(signal)
        out["noise_e"].append(noise)
        out["snr_predicted"].append(snr(signal, noise))
        out["snr_measured"].append(measured_snr(sensor, shot, stack))
        out["pixels"] = int(_green(stack[:1], sensor.cfa).shape[1])
    for target in (10.0, 1.0):
        key = f"snr{target:g}_lux"
        out[key] = crossing_lux(out["lux"], out["snr_measured"], target)
        out[key + "_predicted"] = predicted_crossing_lux(config, target, shape, reflectance, seed)
    return out


def _dark_mean(sensor: Sensor, shot) -> float:
    """The green pixels' mean dark charge (e-): the measured signal is the photo-charge alone."""
    if shot.dark_mean_e is None:
        return 0.0
    return float(_green(np.asarray(shot.dark_mean_e)[None], sensor.cfa).mean())


def crossing_lux(lux, snr, target: float = 10.0) -> float | None:
    """Where a measured SNR curve first reaches ``target``: linear in log SNR against log lux between the two
    illuminances around it; None if it never does within the curve.

    Parameters
    ----------
    lux, snr : sequences of float
        The curve.
    target : float
        The SNR, e.g. 10 or 1.

    Returns
    -------
    float or None
        lux.
    """
    x, y = np.log(np.asarray(lux, float)), np.asarray(snr, float)
    for i in range(1, len(y)):
        if y[i - 1] < target <= y[i] and y[i - 1] > 0:
            if not math.isfinite(y[i]):  # no noise from here on: the crossing lies at the interval's end
                return float(math.exp(x[i]))
            a, b = math.log(y[i - 1]), math.log(y[i])
            return float(math.exp(x[i - 1] + (math.log(target) - a) * (x[i] - x[i - 1]) / (b - a)))
    return None


def crossing_side(lux, snr, target: float = 10.0) -> str | None:
    """Where a curve that does not cross ``target`` stands: ``"below"`` (it is at or above it already at the lowest
    illuminance), ``"beyond"`` (below it at the highest), or None (it crosses: :func:`crossing_lux`).

    Parameters
    ----------
    lux, snr : sequences of float
    target : float

    Returns
    -------
    str or None
    """
    if crossing_lux(lux, snr, target) is not None or not len(snr):
        return None
    return "below" if float(snr[0]) >= target else "beyond"


def predicted_crossing_lux(config, target: float = 10.0, shape=(96, 128), reflectance: float = 0.18,
                           seed: int = 0) -> float:
    """The illuminance at which the model's SNR reaches ``target`` (the photo-charge is proportional to the lux).

    Parameters
    ----------
    config : Config
        With ``light.enabled``.
    target : float
        The SNR.
    shape : (rows, cols)
        The sensor simulated.
    reflectance : float
        The patch's reflectance.
    seed : int
        The sensor instance.

    Returns
    -------
    float
        lux.
    """
    from scipy.optimize import brentq

    sensor = _sensor(config, 1.0, shape, seed)
    per_lux = _predicted(sensor, sensor.expose(f"flat:{reflectance!r}"))[0]

    def excess(log_lux):
        s = per_lux * math.exp(log_lux)
        var = sum(noise_budget.temporal_variances(sensor, s).values())
        var += sum(noise_budget.after_gain_variances(sensor).values())
        return (s / math.sqrt(var) if var > 0 else math.inf) - target

    if sum(noise_budget.temporal_variances(sensor, per_lux * 1e-6).values()) + sum(
            noise_budget.after_gain_variances(sensor).values()) == 0:
        return 0.0  # no noise at any light: any light at all reaches every SNR
    return float(math.exp(brentq(excess, math.log(1e-6), math.log(1e7))))


def dynamic_range(config, shape=(96, 128), reflectance: float = 0.18, seed: int = 0,
                  snr1_lux: float | None = None) -> dict:
    """ISO 15739's dynamic range as the references state it: the largest unclipped scene luminance over the
    luminance at which the SNR is 1, scene-referred. Both are illuminances of the same patch here (the ratio of
    illuminances is the ratio of its luminances): where the patch's green pixels reach saturation on average
    (their mean photo-charge and dark charge at the sensor's saturation: the full well, or the ADC's top if it
    clips first) over the model's SNR1 (the raw green SNR, :func:`predicted_crossing_lux`). The wording of ISO 15739 itself was not read: this is the form
    ``shared/imaging-chain-references.md`` gives, beside EMVA 1288's (saturation over the smallest detectable
    signal, photons at the sensor) that ``characterize`` reports.

    Parameters
    ----------
    config : Config
        With ``light.enabled``.
    shape : (rows, cols)
        The sensor simulated.
    reflectance : float
        The patch's reflectance.
    seed : int
        The sensor instance.
    snr1_lux : float, optional
        The model's SNR1 where the caller has it (:func:`predicted_crossing_lux` at 1), else computed.

    Returns
    -------
    dict
        ``saturation_lux``, ``snr1_lux``, ``ratio`` and ``db`` (20 log10 of the ratio).
    """
    sensor = _sensor(config, 1.0, shape, seed)
    shot = sensor.expose(f"flat:{reflectance!r}")
    sat = max(sensor.saturation_e - _dark_mean(sensor, shot), 0.0) / _predicted(sensor, shot)[0]
    low = predicted_crossing_lux(config, 1.0, shape, reflectance, seed) if snr1_lux is None else snr1_lux
    ratio = sat / low if low > 0 else math.inf
    return {"saturation_lux": sat, "snr1_lux": low, "ratio": ratio,
            "db": 20 * math.log10(ratio) if 0 < ratio < math.inf else None}


def noise_based_speed(config, lux, snr, reflectance: float = 0.18) -> dict:
    """ISO 12232's noise-based speeds of a measured SNR curve: ``S = K / H`` (:data:`NOISE_SPEED_K`), ``H`` the
    focal-plane exposure (lux-seconds) at which the patch's SNR first reaches 40 ("excellent") and 10
    ("acceptable"), :data:`NOISE_SPEED_SNR`.

    ``H`` is the patch's focal-plane illuminance on the optical axis (the camera equation the configuration
    chooses, :func:`cmosnoise.model.focal_plane.axis_illuminance_lux`, of a luminance ``reflectance x lux / pi``)
    times the integration time. The crossing is :func:`crossing_lux`'s. ISO 12232 takes an incremental SNR (the
    output's slope against exposure times the exposure, over the noise): for a linear output whose black is
    subtracted, as ``quality``'s luminance, that is its mean over its noise. For a colour camera the standard adds
    the noise of the colour-difference signals to the luminance's; their weights were not read, so a colour
    camera's speed here counts the luminance noise alone (an upper bound of the standard's).

    Parameters
    ----------
    config : Config
        The sensor, its lens (``optics``) and exposure time.
    lux : sequence of float
        Illuminances on the scene, lux, increasing.
    snr : sequence of float
        The SNR at each.
    reflectance : float
        The patch's reflectance.

    Returns
    -------
    dict
        For each of ``excellent`` and ``acceptable``: ``{"snr": 40 or 10, "lux": scene illuminance or None,
        "exposure_lux_s": H or None, "speed": S or None}`` (None where the curve does not reach it), and
        ``lux_s_per_lux``: H per lux on the scene.

    Examples
    --------
    >>> from cmosnoise import load_config
    >>> from cmosnoise.analysis.snr_light import noise_based_speed
    >>> c = load_config(overrides=["optics.f_number=2", "exposure.integration_time_s=0.01"])
    >>> s = noise_based_speed(c, [1.0, 100.0, 10000.0], [1.0, 10.0, 100.0])
    >>> round(s["acceptable"]["lux"], 6), round(s["acceptable"]["speed"], 1)
    (100.0, 987.7)
    """
    from ..model.focal_plane import axis_illuminance_lux

    # the camera equation's one place: a white's focal-plane illuminance under 1 lux, times the patch and the time
    at_one_lux = merge_updates(config, {"light": {"illuminance_lux": 1.0, "luminance_cd_m2": None}})
    per_lux = axis_illuminance_lux(at_one_lux) * reflectance * config.exposure.integration_time_s
    out = {"lux_s_per_lux": per_lux}
    for name, target in NOISE_SPEED_SNR.items():
        at = crossing_lux(lux, snr, target)
        h = None if at is None else at * per_lux
        out[name] = {"snr": target, "lux": at, "exposure_lux_s": h, "speed": None if not h else NOISE_SPEED_K / h,
                     "side": crossing_side(lux, snr, target)}
    return out
