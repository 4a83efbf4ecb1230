"""EMVA 1288 characterization of a simulated (or a real) sensor, from frames alone.

The measurement series follows EMVA 1288 with exposure-time variation under
a constant, uniform irradiation:

- a photon-transfer series: at each of ``steps`` exposure times up to beyond
  saturation, two bright and two dark frames;
- stacks of ``stack_frames`` bright frames (at ~50 % of saturation) and dark
  frames at the same exposure time, for the spatial statistics;
- where the photon-transfer series' exposure times (to 1.3 s) are too short to
  resolve the dark current (a cooled sensor: 0.0005 e-/s), a dark-current
  series of dark pairs at longer exposure times (EMVA 1288 takes the dark
  current from the dark mean's growth with exposure time; these are longer
  times for that fit, our choice, not the standard's): chosen from the model
  by :func:`dark_series_times`, or given.

The evaluation (:func:`cmosnoise.analysis.emva_evaluation.evaluate`) uses
nothing but those frames and the photon counts, as a lab would: the system gain K from the photon-transfer
curve, the temporal dark noise from the dark variance extrapolated to zero
exposure, the dark current from the dark mean's growth with exposure time,
the saturation capacity at the variance maximum, SNR max, dynamic range,
DSNU and PRNU. :func:`model_values` gives the same quantities as the
simulated sensor instance implies them, for the comparison table. The
descriptor files a lab exchanges are :mod:`.emva_files`'; the job that
writes the table and the curves is :mod:`cmosnoise.app.characterizing`.

The "photons" of a series are the photo-electrons generated per pixel over
the sensor's quantum efficiency (``sensor.quantum_efficiency``); without
one, the photo-electrons themselves (eta = 1 before crosstalk's loss to the
substrate and the PRNU gain map).

Examples
--------
>>> from cmosnoise import Sensor, characterize
>>> m = characterize.model_values(Sensor({"sensor": {"width": 64, "height": 48}}))
>>> round(m["system_gain_K_dn_per_e"], 4)      # what EMVA 1288 would measure: K, DN/e-
0.4031
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..errors import CmosnoiseError
from ..model.seeds import (
    SEQ_EMVA_BRIGHT,
    SEQ_EMVA_DARK,
    SEQ_EMVA_DARK_SERIES,
    SEQ_EMVA_STACK_BRIGHT,
    SEQ_EMVA_STACK_DARK,
)
from ..model.stages import adc, nonlinearity
from . import emva, noise_budget

if TYPE_CHECKING:
    from ..model.sensor import Sensor


#: fewest exposure times of a photon-transfer series: 3 of them below 70 % of saturation
MIN_STEPS = 8
#: exposure times of an automatic dark-current series
DARK_SERIES_STEPS = 8
#: the relative standard error of the dark current an automatic dark series aims at (4 %: 20 % is 5 of them)
DARK_SERIES_REL_SE = 0.04
#: the longest exposure an automatic dark series makes, s (an hour: longer than an astronomer's darks)
DARK_SERIES_MAX_S = 3600.0
#: the photon-transfer series' longest exposure time, s
SERIES_END_S = 1.3


@dataclass
class Measurement:
    """Frames reduced to what EMVA 1288 needs, plus (optionally) the frames themselves.

    Parameters
    ----------
    bits : int
        The ADC's bits.
    shape : (rows, cols)
    texp_s : (steps,) array
        The exposure time of each step, s.
    mu_p : (steps,) array
        Photons (photo-electrons generated) per pixel at each step.
    mu_y, mu_ydark : (steps,) arrays
        The mean of the two bright, and of the two dark, frames, DN.
    s2_y, s2_ydark : (steps,) arrays
        The temporal variance ``var(A - B) / 2``, bright and dark, DN^2.
    stack_texp_s, stack_mu_p : float
        The stacks' exposure time (s) and photons per pixel.
    stack_bright, stack_dark : (L, rows, cols) arrays, DN
        The bright and dark stacks.
    max_ydark : (steps,) array
        The brightest pixel of the two dark frames at each step, DN (to see white pixels saturate).
    frames : dict
        For export: name -> list of frames.
    dsnu_shortest_dn2 : float, optional
        The fixed pattern of the dark pair at the shortest exposure time (DN^2, :func:`dsnu_of_pair`): the pixel
        offsets' DSNU, with the least dark current in it.
    dark_texp_s, dark_mu_dn, dark_s2_dn2 : (n,) arrays, optional
        A dark-current series: exposure times (s), the mean (DN) and the temporal variance (DN^2) of a dark pair
        at each, over the pixels that stay below half the range at its longest exposure (None: no such series).
    dark_excluded : int
        The pixels the dark-current series leaves out (white pixels near saturation at its longest exposure).
    """

    bits: int
    shape: tuple[int, int]
    texp_s: np.ndarray
    mu_p: np.ndarray
    mu_y: np.ndarray
    mu_ydark: np.ndarray
    s2_y: np.ndarray
    s2_ydark: np.ndarray
    stack_texp_s: float
    stack_mu_p: float
    stack_bright: np.ndarray
    stack_dark: np.ndarray
    max_ydark: np.ndarray
    frames: dict = field(default_factory=dict)
    dsnu_shortest_dn2: float | None = None
    dark_texp_s: np.ndarray | None = None
    dark_mu_dn: np.ndarray | None = None
    dark_s2_dn2: np.ndarray | None = None
    dark_excluded: int = 0


def dsnu_of_pair(a: np.ndarray, b: np.ndarray) -> float:
    """The fixed-pattern variance of two frames of one exposure (DN^2): EMVA 1288's spatial variance of a stack
    (:func:`emva.spatial_variances`), here of two frames.

    Parameters
    ----------
    a, b : (rows, cols) arrays, DN
        Two frames of one exposure.

    Returns
    -------
    float
        DN^2.
    """
    return emva.spatial_variances(np.stack([a, b]))["total"]


def pair_stats(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(mean, temporal variance) of two frames of one exposure, DN and DN^2 (EMVA 1288's pair estimator).

    Parameters
    ----------
    a, b : (rows, cols) arrays, DN
        Two frames of one exposure.

    Returns
    -------
    (float, float)
        The mean, DN, and the temporal variance, DN^2.
    """
    return (float(a.mean()) + float(b.mean())) / 2, emva.temporal_variance(a, b)


def mean_dark_rate(sensor: Sensor) -> float:
    """The sensor instance's mean dark current, e-/s per pixel: its dark-rate map's mean plus the blinking pixels'
    mean rate (their step times their time high).

    Parameters
    ----------
    sensor : Sensor

    Returns
    -------
    float
        e-/s.
    """
    c, fp = sensor.config, sensor.fixed_pattern
    rate = 0.0 if fp.dark_rate is None else float(fp.dark_rate.astype(np.float64).mean())
    blinking = noise_budget.telegraph_moments(sensor).get("blinking")
    if blinking is not None:
        rate += float(blinking[1].sum()) / (sensor.shape[0] * sensor.shape[1] * c.exposure.integration_time_s)
    return rate


def frame_mean_variance_e2(sensor: Sensor) -> float:
    """The temporal variance of one dark frame's mean over its pixels, e-^2, as the model implies it.

    A pixel's own noise averages down with the pixel count, a row's or a column's with the rows or columns, the
    black level's error of the frame not at all.

    Parameters
    ----------
    sensor : Sensor

    Returns
    -------
    float
        e-^2.
    """
    rows, cols = sensor.shape
    per = {"row": rows, "column": cols, "black_level_frame": 1}
    return sum(v / per.get(name, rows * cols) for name, v in noise_budget.temporal_variances(sensor, 0.0).items())


def dark_series_times(sensor: Sensor, steps: int = DARK_SERIES_STEPS) -> np.ndarray | None:
    """Exposure times of a dark-current series that resolves the sensor's dark current, or None where the
    photon-transfer series' own dark pairs (to :data:`SERIES_END_S`) already do (or there is no dark current).

    The dark current is the slope of the dark pairs' mean against the exposure time. With ``steps`` equal steps
    to ``T`` its standard error is ``sqrt(var_pair / Sxx)``, ``var_pair`` the variance of a pair's mean
    (:func:`frame_mean_variance_e2` / 2) and ``Sxx = T^2 (steps^2 - 1) / (12 steps)``; ``T`` is chosen so that
    it is :data:`DARK_SERIES_REL_SE` of the model's dark current, at most :data:`DARK_SERIES_MAX_S`.

    Parameters
    ----------
    sensor : Sensor
    steps : int
        Exposure times in the series.

    Returns
    -------
    (steps,) array of s, or None
    """
    rate = mean_dark_rate(sensor)
    if not rate > 0:
        return None
    var_pair = frame_mean_variance_e2(sensor) / 2
    end = math.sqrt(var_pair * 12 * steps / (steps**2 - 1)) / (DARK_SERIES_REL_SE * rate)
    if end <= SERIES_END_S:
        return None
    end = min(end, DARK_SERIES_MAX_S)
    return np.linspace(end / steps, end, steps)


def _dark_times(dark_exposures) -> np.ndarray | None:
    if dark_exposures is None:
        return None
    t = np.asarray(dark_exposures, np.float64).ravel()
    if t.size < 3 or not np.all(np.isfinite(t)) or np.any(t <= 0) or t.size != np.unique(t).size:
        raise CmosnoiseError(f"dark_exposures = {list(map(float, t))}: expected 3 or more different exposure times "
                             "in seconds, each > 0")
    return np.sort(t)


def measure(sensor: Sensor, steps: int = 40, stack_frames: int = 16, keep_frames: bool = False,
            progress: Callable[[], None] | None = None, dark_exposures="auto") -> Measurement:
    """Run the EMVA 1288 measurement series on ``sensor`` (a :class:`cmosnoise.Sensor`).

    The irradiation is set so that saturation is reached at 1 s; exposure
    times run from 1/steps to 1.3 s. ``steps`` >= MIN_STEPS puts at least
    3 exposure times below 70 % of saturation, where K is fitted.

    Parameters
    ----------
    sensor : Sensor
        The sensor to measure.
    steps : int
        Exposure times in the photon-transfer series.
    stack_frames : int
        Frames of the dark and bright stacks (DSNU, PRNU).
    keep_frames : bool
        Keep the frames in the result (to write them as an EMVA 1288 data set).
    progress : callable, optional
        Called once per step.
    dark_exposures : "auto", None or sequence of float
        The dark-current series' exposure times, s: "auto" chooses them from the model
        (:func:`dark_series_times`; none where the photon-transfer series resolves the dark current), None makes
        no such series.

    Returns
    -------
    Measurement
    """
    if isinstance(dark_exposures, str) and dark_exposures == "auto":
        dark = dark_series_times(sensor)
    else:
        dark = _dark_times(dark_exposures)
    if not isinstance(steps, (int, np.integer)) or steps < MIN_STEPS:
        raise CmosnoiseError(f"steps = {steps!r}: the photon-transfer series needs at least {MIN_STEPS} exposure times")
    if not isinstance(stack_frames, (int, np.integer)) or stack_frames < 2:
        raise CmosnoiseError(f"stack_frames = {stack_frames!r}: a stack needs at least 2 frames")
    rate = sensor.saturation_e / 1.0  # photo-electrons per second per pixel at scene value 1
    texp = np.linspace(SERIES_END_S / steps, SERIES_END_S, steps)
    t50 = 0.5  # half of saturation
    return _series(sensor, texp, np.full(steps, rate), t50, rate, stack_frames, keep_frames, progress, dark)


def measure_like(sensor: Sensor, like: Measurement, keep_frames: bool = False,
                 progress: Callable[[], None] | None = None, dark_exposures=None) -> Measurement:
    """The measurement series of ``like`` (a lab's: its exposure times, photons per pixel and stack sizes) made on
    ``sensor``: each step's photons times the sensor's quantum efficiency (1 without one) are its photo-electrons.

    What a comparison with a measured data set needs: EMVA 1288's linearity
    error and saturation depend on where the series samples the response.

    Parameters
    ----------
    sensor : Sensor
        The sensor to measure.
    like : Measurement
        The series to repeat (:func:`cmosnoise.analysis.emva_files.load`).
    keep_frames : bool
        Keep the frames in the result.
    progress : callable, optional
        Called once per step.
    dark_exposures : None, "auto" or sequence of float
        A dark-current series besides ``like``'s (:func:`measure`); ``like``'s own when it has one.

    Returns
    -------
    Measurement
    """
    if isinstance(dark_exposures, str) and dark_exposures == "auto":
        dark = dark_series_times(sensor)
    else:
        dark = _dark_times(dark_exposures if dark_exposures is not None else like.dark_texp_s)
    qe = sensor.config.sensor.qe_mean() or 1.0
    texp = np.maximum(np.asarray(like.texp_s, np.float64), 1e-9)
    stack_t = max(float(like.stack_texp_s), 1e-9)
    return _series(sensor, texp, np.asarray(like.mu_p, np.float64) * qe / texp, stack_t,
                   float(like.stack_mu_p) * qe / stack_t, max(len(like.stack_dark), 2), keep_frames, progress, dark)


def _series(sensor: Sensor, texp: np.ndarray, rates: np.ndarray, stack_texp: float, stack_rate: float,
            stack_frames: int, keep_frames: bool, progress, dark_texp: np.ndarray | None = None) -> Measurement:
    """Bright and dark pairs at each exposure time ``texp`` under ``rates`` photo-electrons per second generated per
    pixel, and the two stacks; photons are the photo-electrons over the sensor's quantum efficiency."""
    t = sensor.transfer
    steps = texp.size
    mu_y, mu_yd, s2_y, s2_yd, max_yd = (np.zeros(steps) for _ in range(5))
    frames: dict = {}
    shortest = int(np.argmin(texp))
    dsnu_short = None
    for i, (ti, ri) in enumerate(zip(texp, rates)):
        s = sensor.with_exposure(ti, ri)
        bright = s.expose("flat:1.0", sequence=SEQ_EMVA_BRIGHT)
        dark = s.expose("flat:0", sequence=SEQ_EMVA_DARK)
        a, b = bright.frame(2 * i), bright.frame(2 * i + 1)
        da, db = dark.frame(2 * i), dark.frame(2 * i + 1)
        mu_y[i], s2_y[i] = pair_stats(a, b)
        mu_yd[i], s2_yd[i] = pair_stats(da, db)
        max_yd[i] = max(float(da.max()), float(db.max()))
        if i == shortest:
            dsnu_short = dsnu_of_pair(da, db)
        if keep_frames:
            frames[f"b_{i:03d}"] = [a, b]
            frames[f"d_{i:03d}"] = [da, db]
        if progress:
            progress()
    s = sensor.with_exposure(stack_texp, stack_rate)
    sb = s.expose("flat:1.0", sequence=SEQ_EMVA_STACK_BRIGHT)
    sd = s.expose("flat:0", sequence=SEQ_EMVA_STACK_DARK)
    stack_bright = np.stack(list(sb.frames(stack_frames)))
    stack_dark = np.stack(list(sd.frames(stack_frames)))
    if progress:
        progress()
    dark = (None, None, None, 0)
    if dark_texp is not None:
        dark = _dark_series(sensor, dark_texp, mu_yd[shortest] + 0.5 * (float(np.max(mu_y)) - mu_yd[shortest]),
                            progress)
    qe = sensor.config.sensor.qe_mean() or 1.0  # photo-electrons per photon
    return Measurement(
        t.bits, sensor.shape, texp, rates * texp / qe, mu_y, mu_yd, s2_y, s2_yd, stack_texp, stack_rate * stack_texp / qe,
        stack_bright, stack_dark, max_yd, frames, dsnu_short, *dark,
    )


def _dark_series(sensor: Sensor, texp: np.ndarray, limit_dn: float, progress=None):
    """Dark pairs at each of ``texp`` (their own frames, sequence :data:`SEQ_EMVA_DARK_SERIES`): the mean and
    temporal variance over the pixels below ``limit_dn`` in both frames of the longest exposure's pair."""
    def pair(i):
        shot = sensor.with_exposure(float(texp[i])).expose("flat:0", sequence=SEQ_EMVA_DARK_SERIES)
        return shot.frame(2 * i), shot.frame(2 * i + 1)

    last = pair(len(texp) - 1)
    keep = (last[0] < limit_dn) & (last[1] < limit_dn)
    mu, s2 = np.zeros(len(texp)), np.zeros(len(texp))
    for i in range(len(texp)):
        a, b = last if i == len(texp) - 1 else pair(i)
        a, b = a[keep], b[keep]
        mu[i], s2[i] = pair_stats(a, b)
        if progress:
            progress()
    return texp, mu, s2, int(keep.size - keep.sum())


def photon_transfer_gain(sensor: Sensor, series_e: np.ndarray | None = None) -> float:
    """The system gain K that EMVA 1288's photon-transfer fit gives on the model (DN/e-): the configured
    (small-signal) K on a linear sensor; under a nonlinearity ``f`` the through-the-origin slope of
    ``v = K^2 f'(x)^2 x`` against ``y = K f(x)`` over the series' photo-charges ``x`` below 70 % of saturation
    (the shot noise through the transfer, to first order; :func:`.emva_evaluation.small_signal_gain`).

    Parameters
    ----------
    sensor : Sensor
    series_e : array, e-, optional
        The series' photo-charge per pixel at each step (default: 101 equal steps to the full well).

    Returns
    -------
    float
        DN/e-.
    """
    k = sensor.transfer.gain_dn_per_e
    curve = sensor.spec.active_nonlinearity
    if curve is None:
        return k
    x = (np.asarray(series_e, np.float64) if series_e is not None
         else np.linspace(0.0, sensor.config.sensor.full_well_e, nonlinearity.SERIES))
    fx = curve.apply(x)
    x = x[(x > 0) & (fx <= 0.7 * float(curve.apply(sensor.saturation_e)))]
    if x.size == 0:
        return k
    y = k * curve.apply(x)
    v = k**2 * np.array([curve.slope(float(q)) for q in x]) ** 2 * x
    return float(np.sum(y * v) / np.sum(y * y))


def model_values(sensor: Sensor, stack_texp_s: float = 0.5, series_e: np.ndarray | None = None,
                 shortest_texp_s: float | None = None) -> dict:
    """The same quantities as the simulated sensor instance implies them (its configuration and maps).

    ``series_e``: the photo-charge per pixel at each step of the measured
    series, where the linearity error is sampled (default: 101 equal steps to the full well);
    ``shortest_texp_s``: the series' shortest exposure, where the DSNU of
    the pixel offsets is read (default: the stack's).

    DSNU: the EMVA estimator applied to the expected dark image at the
    stack's exposure time, with the full-well and ADC clips (white pixels
    that saturate count at the saturation level, as in the frames). PRNU:
    the photo-response map (PRNU gain, crosstalk, column gain) of every pixel.

    Parameters
    ----------
    sensor : Sensor
        The simulated sensor instance.
    stack_texp_s : float
        The stacks' exposure time, s.
    series_e : array, e-, optional
        The measured series' photo-charge per pixel at each step.
    shortest_texp_s : float, optional
        The series' shortest exposure time, s.

    Returns
    -------
    dict
        The quantities of :func:`cmosnoise.analysis.emva_evaluation.evaluate`, by the same keys, in the same units.
    """
    c = sensor.config
    t = sensor.transfer
    fp = sensor.fixed_pattern
    k = t.gain_dn_per_e
    tv = noise_budget.temporal_variances(sensor, 0.0)
    # the readout's variance (random telegraph traps included); a blinking pixel's is the dark current's
    read_var = sum(v for name, v in tv.items()
                   if name not in ("dark_shot", "quantization", "photon_shot", "rts_blinking"))
    sat_e = sensor.saturation_e
    s = sensor.with_exposure(1.0, 1.0)
    shot = s.expose("flat:1.0")
    signal = shot.photo_mean_e.astype(np.float64)
    if fp.column_gain is not None:
        signal = signal * fp.column_gain
    qe = float(signal.mean()) * (c.sensor.qe_mean() or 1.0)  # photo-electrons collected per photon
    dark_mean = mean_dark_rate(sensor)
    def expected_dark_at(texp_s):
        """The expected dark image (e-) at ``texp_s``, with the clips and the quantizer's pattern."""
        mo = noise_budget.clipped_moments(sensor.with_exposure(texp_s), 0.0)
        if not c.adc.enabled:
            return mo["mean"]
        # the quantizer: undithered where the temporal noise is well below a DN (adds its pattern)
        dn = adc.expected_output(mo["mean"] * k + t.black_level_dn, np.sqrt(mo["var"]) * k, t)
        return (dn - t.black_level_dn) / k

    sp = emva.spatial_variances(expected_dark_at(stack_texp_s)[None])
    short = expected_dark_at(shortest_texp_s if shortest_texp_s is not None else stack_texp_s)
    le = (0.0, 0.0)
    curve = sensor.spec.active_nonlinearity
    if curve is not None:
        # the transfer on the series' own photo-charges (the linearity error depends on where it is sampled)
        fw = c.sensor.full_well_e
        x = (np.asarray(series_e, np.float64) if series_e is not None
             else np.linspace(0.0, fw, nonlinearity.SERIES))
        x = x[x <= fw]
        y = curve.apply(x)
        le = nonlinearity.linearity_error(x, y, float(y[-1]))
    sigma_y_dark = math.sqrt(read_var * k**2 + t.quantization_var_dn2)
    u_p_min = (sigma_y_dark / k + 0.5) / qe
    return {
        "system_gain_K_dn_per_e": photon_transfer_gain(sensor, series_e),
        "small_signal_gain_K_dn_per_e": k * (curve.slope(0.0) if curve is not None else 1.0),
        "inverse_gain_e_per_dn": 1 / k,
        "quantum_efficiency": qe,
        "temporal_dark_noise_e": math.sqrt(read_var),
        "saturation_capacity_e": sat_e,
        "snr_max": math.sqrt(sat_e),
        "dynamic_range_db": 20 * math.log10(sat_e / qe / u_p_min),
        "dark_current_mean_e_per_s": dark_mean,
        "dark_current_var_e_per_s": dark_mean if c.dark_current.shot_noise else 0.0,
        "dsnu_e": math.sqrt(max(sp["total"], 0.0)),
        "dsnu_column_e": math.sqrt(max(sp["column"], 0.0)),
        "prnu_pct": 100 * float(signal.std(ddof=1) / signal.mean()),
        "dsnu_shortest_e": float(np.std(short, ddof=1)),
        "linearity_error_min_pct": le[0],
        "linearity_error_max_pct": le[1],  # ddof=1 as the EMVA estimator (matters on tiny sensors)
    }
