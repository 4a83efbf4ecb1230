"""Noise budget: what each source contributes, predicted from a sensor instance.

Temporal noise adds in variance. For one pixel at mean signal ``mu`` (e-),
averaged over the array (the sensor's own fixed maps: flicker sigmas,
column sigmas, column gains, dark-current map)::

    var = ((mu + d) f'^2 + thermal^2 + <flicker_i^2> + row^2) * <g_c^2> + <sigma_c^2>
          + (read_dn^2 + black_frame_dn^2 + step^2/12) / K^2

with ``d`` the mean dark charge (its shot noise), ``f'`` the
nonlinearity's slope at ``mu + d`` (1 without one), ``g_c`` the column
gains, the read noise after the gain and the frame's black-level error in DN,
and quantization (``step^2 / 12`` DN^2, ``step`` the output DN per ADC code: 1 unless
``adc.output_bits`` scales the codes), referred to e-. The random telegraph pixels
(stages 6b and 4b, where on) add their stationary variances, averaged over
the array (:func:`telegraph_moments`): a trap's ``2 A^2 pi0 pi1 (1 -
e^-s tau)`` through CDS (``A^2 pi0 pi1`` without), a blinking pixel's rate
step times the variance of its time high over the exposure, with its
shot noise. Fixed pattern noise is
listed apart: DSNU (dark-current map, pixel offsets, row and column offsets,
the black level's cell offsets) and PRNU, the
PRNU as the photo-charge shows it, after crosstalk has averaged neighbouring
gains (:attr:`Sensor.flat_response`).

**Clipping.** Near saturation a pixel's charge is clipped at the full well
and its code at the ADC's top: clipped pixels have less temporal noise.
:func:`clipping` follows each pixel through both clips (its mean from the
scene or a flat field through the PRNU and crosstalk maps, plus its dark
charge; shot noise as a normal, then the read noise, then the ADC's top),
with the moments of a clipped normal, and gives the temporal and spatial
variance and the fraction of clipped pixels that frames will show. The
totals in :func:`budget` include it; the per-source lines are the unclipped
contributions.

Examples
--------
>>> from cmosnoise import Sensor, noise_budget
>>> b = noise_budget.budget(Sensor({"sensor": {"width": 64, "height": 48}}, seed=7))   # in the dark
>>> b["dominant_temporal"], noise_budget.SOURCE_NAMES[b["dominant_temporal"]]
('thermal', 'source follower, thermal (white)')
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..engine.reduce import statistics
from ..estimators import snr

if TYPE_CHECKING:
    from ..model.sensor import Sensor


#: each source's name as the docs and the pages show it (the budget's keys are short JSON names)
SOURCE_NAMES = {
    "photon_shot": "photon shot noise",
    "dark_shot": "dark-current shot noise",
    "thermal": "source follower, thermal (white)",
    "flicker": "source follower, flicker (1/f)",
    "row": "row noise",
    "column": "column noise",
    "column_alternating": "even/odd column banks",
    "rts_traps": "random telegraph traps",
    "rts_blinking": "blinking (dark-current RTS) pixels",
    "quantization": "quantization",
    "read_after_gain": "read noise after the gain",
    "black_level_frame": "black level, frame to frame",
    "dcnu": "DCNU (dark-current non-uniformity)",
    "row_fixed": "row offsets",
    "vfpn": "column offsets (VFPN)",
    "pixel_offset": "pixel offsets (DSNU at zero exposure)",
    "rts_level": "random telegraph held levels",
    "black_level_cells": "black level per CFA channel",
    "prnu": "PRNU",
    "column_gain": "column gains",
}


def transfer_slope(sensor: Sensor, charge_e: float) -> float:
    """The nonlinearity's slope (output e- per collected e-) at ``charge_e``; 1 without one (stage 5b).

    Charge-referred noise (shot noise) and signal differences (PRNU) pass
    through the transfer scaled by it, to first order.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).
    charge_e : float
        The mean collected charge, e-.

    Returns
    -------
    float
        d(output e-) / d(collected e-), dimensionless.
    """
    curve = sensor.spec.nonlinearity_on("charge")  # on the mean charge, the shot noise follows the mean it is drawn with
    return 1.0 if curve is None else curve.slope(charge_e)


def map_moment(sensor: Sensor, name: str, which: str) -> float:
    """A fixed map's mean, variance, mean square or extreme (``which``: one of
    :data:`cmosnoise.engine.reduce.STATISTICS`), computed once per sensor with the others
    (:func:`cmosnoise.engine.reduce.statistics`, one compiled pass) and kept by
    :meth:`~cmosnoise.model.sensor.Sensor.map_statistic`.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance.
    name : str
        A field of its fixed pattern (``dark_rate``, ``flicker_sigma``, ...) or ``flat_response``
        (:meth:`~cmosnoise.model.sensor.Sensor.flat_statistics`, made in bands without the map).
    which : {"mean", "var", "mean_square", "min", "max"}
        The statistic.

    Returns
    -------
    float

    Examples
    --------
    >>> from cmosnoise import Sensor, noise_budget
    >>> sensor = Sensor({"sensor": {"width": 64, "height": 48}}, seed=1)
    >>> noise_budget.map_moment(sensor, "dark_rate", "mean") > 0
    True
    """
    def compute():
        if name == "flat_response":
            found = sensor.flat_statistics()
        else:
            found = statistics(getattr(sensor.fixed_pattern, name))
        for other, value in found.items():  # they come together: keep them all
            sensor.map_statistic(f"{other}:{name}", lambda v=value: v)
        return found[which]

    return sensor.map_statistic(f"{which}:{name}", compute)


def temporal_variances(sensor: Sensor, signal_e: float = 0.0) -> dict[str, float]:
    """Each temporal source's variance at mean photo-signal ``signal_e``.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).
    signal_e : float
        The mean photo-signal, e-.

    Returns
    -------
    dict of str to float
        Variance per source (:data:`SOURCE_NAMES`), e-^2, referred to the charge.
    """
    c = sensor.config
    fp = sensor.fixed_pattern
    t = sensor.transfer
    g2 = (map_moment(sensor, "column_gain", "mean_square")
          if fp.column_gain is not None else 1.0)
    dark_e = (map_moment(sensor, "dark_rate", "mean") * c.exposure.integration_time_s
              if fp.dark_rate is not None else 0.0)
    slope2 = transfer_slope(sensor, signal_e + dark_e) ** 2
    out: dict[str, float] = {}
    if c.shot_noise.enabled:
        out["photon_shot"] = signal_e * g2 * slope2
    if fp.dark_rate is not None and c.dark_current.shot_noise:
        out["dark_shot"] = dark_e * g2 * slope2
    if c.source_follower.enabled:
        out["thermal"] = c.source_follower.thermal_sigma_e**2 * g2
        if fp.flicker_sigma is not None:
            out["flicker"] = map_moment(sensor, "flicker_sigma", "mean_square") * g2
    if c.row_noise.enabled:
        out["row"] = sensor.spec.row_sigma_e**2 * g2
    n = sensor.shape[0] * sensor.shape[1]
    rts = telegraph_moments(sensor)
    if "traps" in rts:  # before the column gain, as the source follower's
        out["rts_traps"] = float(rts["traps"][2].sum()) / n * g2
    if "blinking" in rts:  # a dark charge: through the transfer, with its shot noise where the dark current has it
        _, mean, var = rts["blinking"]
        shot = float(mean.sum()) if c.dark_current.shot_noise else 0.0
        out["rts_blinking"] = (float(var.sum()) + shot) / n * g2 * slope2
    if fp.column_sigma is not None:
        out["column"] = map_moment(sensor, "column_sigma", "mean_square")
    alt = c.column_noise.alternating
    if c.column_noise.enabled and alt.enabled and alt.temporal_sigma_e > 0:
        out["column_alternating"] = alt.temporal_sigma_e**2
    if c.adc.enabled:  # the ideal readout (ADC off) is not quantized
        out.update(after_gain_variances(sensor))
        out["quantization"] = t.quantization_var_dn2 / t.gain_dn_per_e**2
    return out


def after_gain_variances(sensor: Sensor) -> dict[str, float]:
    """The temporal variances the ADC adds before rounding (stage 9a): the read noise after the gain and the black
    level's error per frame.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).

    Returns
    -------
    dict of str to float
        ``read_after_gain`` and ``black_level_frame``, where on: DN^2 referred to e-^2 (empty with the ADC off).
    """
    c, k = sensor.config, sensor.transfer.gain_dn_per_e
    out: dict[str, float] = {}
    if not c.adc.enabled:
        return out
    if c.read_noise.enabled:
        from ..model.stages.read_noise import variance_dn2

        rn = c.read_noise
        out["read_after_gain"] = variance_dn2(rn.distribution, rn.scale_dn, rn.shape) / k**2
    if c.black_level.frame_sigma_dn > 0:
        out["black_level_frame"] = c.black_level.frame_sigma_dn**2 / k**2
    return out


def fixed_pattern_parts(sensor: Sensor) -> tuple[dict[str, float], dict[str, float]]:
    """The fixed-pattern variances that do not depend on the signal, and those that grow with it.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).

    Returns
    -------
    (dict of str to float, dict of str to float)
        The constant variances, e-^2 (DCNU, offsets, VFPN, ...), and those per signal^2 (PRNU, column gains),
        e-^2 / e-^2.
    """
    c = sensor.config
    fp = sensor.fixed_pattern
    const: dict[str, float] = {}
    per_s2: dict[str, float] = {}

    def var(name):  # a fixed map's variance, once per sensor
        return map_moment(sensor, name, "var")

    if fp.dark_rate is not None:
        const["dcnu"] = var("dark_rate") * c.exposure.integration_time_s**2
    if fp.row_offset is not None:
        const["row_fixed"] = var("row_offset")
    if fp.vfpn is not None:
        const["vfpn"] = var("vfpn")
    if fp.pixel_offset is not None:
        const["pixel_offset"] = var("pixel_offset")
    rts = telegraph_moments(sensor)
    n = sensor.shape[0] * sensor.shape[1]
    if "traps" in rts and not c.source_follower.rts.cds:  # the held level's mean: a pixel offset of its own
        const["rts_level"] = _sparse_variance(rts["traps"][1], n)
    if "blinking" in rts:
        const["rts_blinking"] = _sparse_variance(rts["blinking"][1], n)
    offsets = np.asarray(c.black_level.channel_offsets_dn, np.float64)
    if c.adc.enabled and offsets.any():  # the four cell positions, equally many pixels each (the frame error: temporal)
        const["black_level_cells"] = float(np.var(offsets)) / sensor.transfer.gain_dn_per_e**2
    if fp.prnu_gain is not None or c.crosstalk.enabled:
        per_s2["prnu"] = map_moment(sensor, "flat_response", "var")  # after crosstalk
    if fp.column_gain is not None:
        per_s2["column_gain"] = var("column_gain")
    return const, per_s2


def fixed_pattern_variances(sensor: Sensor, signal_e: float = 0.0, _parts=None) -> dict[str, float]:
    """Each fixed-pattern source's spatial variance (e-^2) at mean photo-signal ``signal_e``.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).
    signal_e : float
        The mean photo-signal, e-.
    _parts : tuple, optional
        :func:`fixed_pattern_parts` of this sensor, when several levels are asked for.

    Returns
    -------
    dict of str to float
        Spatial variance per source (:data:`SOURCE_NAMES`), e-^2.
    """
    const, per_s2 = _parts or fixed_pattern_parts(sensor)
    seen = signal_e * transfer_slope(sensor, signal_e)  # a gain difference passes the transfer by its slope
    return {**const, **{k: v * seen**2 for k, v in per_s2.items()}}


def _clipped_normal(m: np.ndarray, v: np.ndarray, top: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean, variance and P(X > top) of ``min(X, top)`` for X ~ Normal(m, v), elementwise."""
    from scipy.special import ndtr

    if math.isinf(top):
        return m, v, np.zeros(np.shape(m))
    s = np.sqrt(np.maximum(v, 1e-300))
    a = (top - m) / s
    cdf = ndtr(a)
    pdf = np.exp(-0.5 * a * a) / math.sqrt(2 * math.pi)
    mean = m * cdf - s * pdf + top * (1 - cdf)
    second = (m * m + v) * cdf - s * (m + top) * pdf + top * top * (1 - cdf)
    return mean, np.maximum(second - mean * mean, 0.0), 1 - cdf


def clipped_moments(sensor: Sensor, signal_e: float = 0.0, photo_e: np.ndarray | None = None,
                    exposure=None, codes: bool = False) -> dict:
    """Per-pixel expected value and temporal variance at the ADC input (e-), with the full-well and ADC clips.

    ``photo_e`` is the mean photo-charge per pixel (a scene); without it, a
    flat field of mean ``signal_e`` through the sensor's PRNU and crosstalk.
    Returns ``mean`` and ``var`` (rows, cols) float64 e-, and ``p_full_well``
    and ``p_top`` (the probability that the pixel clips at the full well or
    at the ADC's top code), or ``None`` for these two when no pixel comes
    within 10 sigma of a clip (then ``mean`` and ``var`` are the unclipped
    moments). As the frame kernel does it: the charge (a normal
    approximation of the Poisson count) is clipped at the full well; the
    source follower's and the row's noise and offset are added; the column
    gain multiplies, the column's offset (VFPN) and noise are added; the ADC
    clips at its top (the read noise after the gain, the frame's black-level
    error and the cell offsets with it). The nonlinearity is not followed
    here: its slope scales the unclipped lines (:func:`transfer_slope`).
    Below the clips the moments are exact; where pixels
    clip, the normal charge and the two clips taken as clipped normals leave
    an error of up to about 3 % of the temporal noise (+ 0.3 e- of the top
    code's quantization), 2 points of the top-code fraction and 4 % of the
    fixed pattern (tests/test_readout.py measures it).

    Given an ``exposure`` (a :class:`~cmosnoise.model.sensor.Exposure` of
    ``sensor``), its mean charges are taken instead, with the defects of
    stage 15 (gain, dead and hot pixels, offset lines) and the random
    telegraph pixels at their stationary means (a blinking pixel's step times
    its time high, a trap's amplitude times its occupancy where CDS is off).

    ``codes``: near the ADC's top, ``mean`` is the quantizer's expectation
    ``E[min(round(black + K X), top code)]`` referred back to e- (exact for
    each of the two normal components), and ``quantized`` marks those pixels
    (the others' means are the charge's, for :func:`~cmosnoise.model.stages.adc.expected_code`).

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).
    signal_e : float
        A flat field's mean photo-signal, e- (where ``photo_e`` is not given).
    photo_e : (rows, cols) array, e-, optional
        A scene's mean photo-charge per pixel.
    exposure : Exposure, optional
        A scene on ``sensor``: its mean charges, defects and telegraph pixels.
    codes : bool
        Near the ADC's top, the quantizer's expectation instead of the charge's mean.

    Returns
    -------
    dict
        ``mean`` and ``var``, (rows, cols) float64, e- and e-^2; ``p_full_well`` and ``p_top``, (rows, cols)
        probabilities or None; ``quantized``, a (rows, cols) bool array or None.
    """
    terms = readout_terms(sensor, signal_e, photo_e, exposure)
    shape = sensor.shape
    mean_n, shot, read, col_read = terms["mean_n"], terms["shot"], terms["read"], terms["col_read"]
    row_off, col_off, gain = terms["row_off"], terms["col_off"], terms["gain"]
    mean = np.broadcast_to((mean_n + row_off) * gain + col_off, shape).copy()
    var = np.broadcast_to((shot + read) * (gain * gain) + col_read, shape).copy()
    # only pixels within 10 sigma of a clip need the clipped moments (a few, unless the scene is near saturation)
    near = (mean_n + 10 * np.sqrt(shot) + 1 >= terms["fw"]) | (mean + 10 * np.sqrt(var) + 1 >= terms["top"])
    if not near.any():
        return {"mean": mean, "var": var, "p_full_well": None, "p_top": None, "quantized": None}
    idx = np.nonzero(near)
    part = near_moments(sensor, terms, idx, codes)
    mean[idx] = part["mean"]
    var[idx] = part["var"]
    p_full = np.zeros(shape)
    p_full[idx] = part["p_full_well"]
    p_top = np.zeros(shape)
    p_top[idx] = part["p_top"]
    quantized = None
    if part["quantized"] is not None:
        quantized = np.zeros(shape, bool)
        quantized[idx] = part["quantized"]
    return {"mean": mean, "var": var, "p_full_well": p_full, "p_top": p_top, "quantized": quantized}


def readout_terms(sensor: Sensor, signal_e: float = 0.0, photo_e: np.ndarray | None = None, exposure=None) -> dict:
    """The terms :func:`clipped_moments` combines, each as it comes (a scalar, per row (rows, 1), per column
    (1, cols) or per pixel; never expanded): the mean charge ``mean_n`` and its shot variance ``shot``, the
    read variance before the column gain ``read`` and after it ``col_read`` (e-^2), the offsets before the
    column gain ``row_off`` and after it ``col_off`` (e-), the column ``gain``; the full well ``fw`` and the
    top code's charge ``top`` (e-).

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).
    signal_e : float
        A flat field's mean photo-signal, e- (where ``photo_e`` is not given).
    photo_e : (rows, cols) array, e-, optional
        A scene's mean photo-charge per pixel.
    exposure : Exposure, optional
        A scene on ``sensor`` (its mean charges, defects and telegraph pixels).

    Returns
    -------
    dict
        The terms by the names above: scalars or arrays of shape (rows, 1), (1, cols) or (rows, cols).
    """
    c = sensor.config
    fp = sensor.fixed_pattern
    t = sensor.transfer
    shape = sensor.shape
    rts = {name: (_pixel_map(p, m, shape), _pixel_map(p, v, shape))  # (mean, variance) maps
           for name, (p, m, v) in telegraph_moments(sensor).items()}
    if exposure is not None:
        photo = exposure.collected_photo_e.astype(np.float64)
        dark = exposure.collected_dark_e.astype(np.float64) if exposure.collected_dark_e is not None else 0.0
    elif photo_e is None:
        photo = signal_e * sensor.flat_response
    else:
        photo = np.asarray(photo_e, np.float64)
    if exposure is None:
        dark = (fp.dark_rate.astype(np.float64) * c.exposure.integration_time_s if fp.dark_rate is not None else 0.0)
    blink_var = 0.0
    if "blinking" in rts:  # its mean with the dark charge; the variance of its time high with the charge's
        dark = dark + rts["blinking"][0]
        blink_var = rts["blinking"][1]
    mean_n = np.broadcast_to(photo + dark, shape)
    shot = (photo if c.shot_noise.enabled else 0.0) + (dark if c.dark_current.shot_noise else 0.0) + blink_var
    # the top code's charge (values within half a code of it round to it)
    top = (t.max_code - 0.5 * t.step - t.black_level_dn) / t.gain_dn_per_e if c.adc.enabled else math.inf
    read = sensor.spec.row_sigma_e**2 if c.row_noise.enabled else 0.0  # before the column gain, e-^2
    if c.source_follower.enabled:
        read = read + sensor.source_follower_sigma.astype(np.float64) ** 2
    if "traps" in rts:
        read = read + rts["traps"][1]
    col_read = fp.column_sigma.astype(np.float64) ** 2 if fp.column_sigma is not None else 0.0  # after it
    alt = c.column_noise.alternating
    if c.column_noise.enabled and alt.enabled:  # the even and odd banks' offsets per frame: the amplifiers'
        col_read = col_read + alt.temporal_sigma_e**2
    row_off = fp.row_offset.astype(np.float64) if fp.row_offset is not None else 0.0
    col_off = fp.vfpn.astype(np.float64) if fp.vfpn is not None else 0.0
    if exposure is not None:  # the fixed row and column offsets with the offset lines
        _, _, lines_r, _, lines_c = exposure.readout_lines()
        row_off, col_off = lines_r[:, None], lines_c[None, :]
    if "traps" in rts and not c.source_follower.rts.cds:  # the held level's stationary mean
        row_off = row_off + rts["traps"][0]
    if fp.pixel_offset is not None:  # with the row offsets: before the column gain
        row_off = row_off + fp.pixel_offset.astype(np.float64)
    if c.adc.enabled:  # after the gain, in DN: referred to e-
        col_read = col_read + sum(after_gain_variances(sensor).values())
        cells = np.asarray(c.black_level.channel_offsets_dn, np.float64).reshape(2, 2)
        if cells.any():
            from ..model.stages.read_noise import black_map

            col_off = col_off + black_map(cells, (0, shape[0], 0, shape[1])) / t.gain_dn_per_e
    gain = fp.column_gain.astype(np.float64) if fp.column_gain is not None else 1.0
    return {"mean_n": mean_n, "shot": shot, "read": read, "col_read": col_read, "row_off": row_off,
            "col_off": col_off, "gain": gain, "fw": float(c.sensor.full_well_e), "top": top}


def near_moments(sensor: Sensor, terms: dict, idx: tuple, codes: bool = False) -> dict:
    """:func:`clipped_moments` at the pixels ``idx`` near a clip.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).
    terms : dict
        :func:`readout_terms` of the sensor.
    idx : (rows_index, cols_index)
        Two index arrays of the pixels.
    codes : bool
        Near the ADC's top, the quantizer's expectation instead of the charge's mean.

    Returns
    -------
    dict
        ``mean`` (e-), ``var`` (e-^2), ``p_full_well``, ``p_top`` and ``quantized`` (or None), each an array over
        ``idx``.
    """
    c = sensor.config
    t = sensor.transfer.adc_codes()  # the quantizer's own codes (the means in e- are the same)
    shape = sensor.shape
    fw, top = terms["fw"], terms["top"]

    def at(a):
        return np.broadcast_to(np.asarray(a, np.float64), shape)[idx]

    mn, sh, rd, cr, ro, co, g = (at(terms[k]) for k in ("mean_n", "shot", "read", "col_read", "row_off", "col_off",
                                                        "gain"))
    # the charge: N ~ Normal(mn, sh), clipped at the full well with probability p_fw
    p_fw = 1.0 - _cdf((fw - mn) / np.sqrt(np.maximum(sh, 1e-300)))
    m_below, v_below = _truncated_below(mn, sh, fw)  # N given N < FW
    # the readout adds noise, offsets and the column gain, then the ADC clips at its top: a mixture of the two cases
    m_c, v_c, q_c = _clipped_normal((fw + ro) * g + co, rd * g * g + cr, top)  # clipped at the full well
    m_u, v_u, q_u = _clipped_normal((m_below + ro) * g + co, (v_below + rd) * g * g + cr, top)
    m = p_fw * m_c + (1 - p_fw) * m_u
    quantized = None
    if codes and c.adc.enabled:
        e_c, at_c = _top_code((fw + ro) * g + co, rd * g * g + cr, t)
        e_u, at_u = _top_code((m_below + ro) * g + co, (v_below + rd) * g * g + cr, t)
        quantized = at_c | at_u  # either component within reach of the top code: the code expectation for both
        e_c = np.where(at_c, e_c, (t.black_level_dn + t.gain_dn_per_e * ((fw + ro) * g + co)))
        e_u = np.where(at_u, e_u, (t.black_level_dn + t.gain_dn_per_e * ((m_below + ro) * g + co)))
        m = np.where(quantized, ((p_fw * e_c + (1 - p_fw) * e_u) - t.black_level_dn) / t.gain_dn_per_e, m)
    second = p_fw * (v_c + m_c**2) + (1 - p_fw) * (v_u + m_u**2)
    return {"mean": m, "var": np.maximum(second - m**2, 0.0), "p_full_well": p_fw, "p_top": p_fw * q_c + (1 - p_fw) * q_u,
            "quantized": quantized}


def clipping(sensor: Sensor, signal_e: float = 0.0, photo_e: np.ndarray | None = None) -> dict:
    """Temporal and spatial variance (e-^2) with the full-well and ADC clips, and the fraction of pixels clipped.

    Averages of :func:`clipped_moments` over the pixels; where nothing comes
    near a clip, the fractions are 0 and the variances NaN (the unclipped
    budget holds).

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).
    signal_e : float
        A flat field's mean photo-signal, e- (where ``photo_e`` is not given).
    photo_e : (rows, cols) array, e-, optional
        A scene's mean photo-charge per pixel.

    Returns
    -------
    dict
        ``temporal_var_e2`` and ``spatial_var_e2`` (e-^2), ``full_well_fraction``, ``top_code_fraction`` and
        ``clipped_fraction`` (0 to 1).
    """
    nothing = {"full_well_fraction": 0.0, "top_code_fraction": 0.0, "clipped_fraction": 0.0,
               "temporal_var_e2": math.nan, "spatial_var_e2": math.nan}
    if not _may_clip(sensor, signal_e, photo_e):
        return nothing
    mo = clipped_moments(sensor, signal_e, photo_e)
    if mo["p_full_well"] is None:
        return nothing
    p_fw, at_top = mo["p_full_well"], mo["p_top"]
    return {"full_well_fraction": float(np.mean(p_fw)), "top_code_fraction": float(np.mean(at_top)),
            "clipped_fraction": float(np.mean(np.maximum(p_fw, at_top))),
            "temporal_var_e2": float(np.mean(mo["var"])), "spatial_var_e2": float(np.var(mo["mean"]))}


def _may_clip(sensor: Sensor, signal_e: float, photo_e: np.ndarray | None) -> bool:
    """Whether any pixel can come within 10 sigma of a clip, from bounds on each term (a few maxima, no maps).

    False means :func:`clipped_moments` would find no pixel near a clip (its test,
    with every term at its largest); True only that it has to look.
    """
    c = sensor.config
    fp = sensor.fixed_pattern
    t = sensor.transfer

    def top_of(name) -> float:  # a fixed map's largest value, once per sensor
        return map_moment(sensor, name, "max") if getattr(fp, name) is not None else 0.0

    photo = float(np.max(photo_e)) if photo_e is not None else signal_e * map_moment(sensor, "flat_response", "max")
    photo = max(photo, 0.0)
    dark = max(top_of("dark_rate") * c.exposure.integration_time_s, 0.0)
    shot = (photo if c.shot_noise.enabled else 0.0) + (dark if c.dark_current.shot_noise else 0.0)
    if photo + dark + 10 * math.sqrt(shot) + 1 >= c.sensor.full_well_e:
        return True
    if not c.adc.enabled:
        return False
    top = (t.max_code - 0.5 * t.step - t.black_level_dn) / t.gain_dn_per_e
    # the largest source-follower sigma, sqrt(thermal^2 + flicker^2), is the largest flicker sigma's
    sf = c.source_follower.thermal_sigma_e**2 + top_of("flicker_sigma") ** 2
    read = (sensor.spec.row_sigma_e**2 if c.row_noise.enabled else 0.0) + (sf if c.source_follower.enabled else 0.0)
    g_hi = top_of("column_gain") if fp.column_gain is not None else 1.0
    g_lo = map_moment(sensor, "column_gain", "min") if fp.column_gain is not None else 1.0
    x = photo + dark + top_of("row_offset")
    mean = max(x * g_hi, x * g_lo) + top_of("vfpn")
    col_read = top_of("column_sigma") ** 2
    var = (shot + read) * max(g_hi * g_hi, g_lo * g_lo) + col_read
    return mean + 10 * math.sqrt(var) + 1 >= top


def _top_code(m: np.ndarray, v: np.ndarray, t) -> tuple[np.ndarray, np.ndarray]:
    """``E[min(round(Y), top)]`` for Y ~ Normal(black + K m, K^2 v) where the top code is within 10 sigma (and 2
    codes), DN; and where that is.

    Below 2 DN of noise the sum ``top - sum_{j >= 1} P(round(Y) <= top - j)`` (exact for a normal Y, at most
    44 terms there); from 2 DN the rounding dithers (its bias is below exp(-2 pi^2 sigma^2) = 1e-34 of a code)
    and the clipped normal's mean at ``top + 1/2``, less half a code times the chance of reaching it, is the
    same number in closed form.
    """
    mu = t.black_level_dn + t.gain_dn_per_e * m
    sd = t.gain_dn_per_e * np.sqrt(np.maximum(v, 0.0))
    top = float(t.max_code)
    near = top - mu < 10 * sd + 2
    out = np.zeros(mu.shape)
    fine = near & (sd < 2.0)
    if fine.any():
        mu_n, sd_n = mu[fine], sd[fine]
        noiseless = sd_n == 0
        acc = np.zeros(mu_n.shape)
        span = int(np.ceil(np.max(np.where(noiseless, 0.0, top - mu_n + 10 * sd_n)))) + 2
        safe = np.where(noiseless, 1.0, sd_n)
        for j in range(1, max(span, 1) + 1):
            acc += _cdf((top - j + 0.5 - mu_n) / safe)
        out[fine] = np.where(noiseless, np.minimum(np.rint(mu_n), top), top - acc)
    wide = near & ~fine
    if wide.any():
        mean, _, above = _clipped_normal(mu[wide], sd[wide] ** 2, top + 0.5)
        out[wide] = mean - 0.5 * above
    return out, near


def telegraph_moments(sensor: Sensor) -> dict:
    """The random telegraph pixels' stationary moments at the sensor's exposure, per pixel (several traps summed).

    ``traps`` (stage 6b, where on) and ``blinking`` (4b), each (pixels uint64, mean e-, variance e-^2) as
    :func:`~cmosnoise.model.stages.random_telegraph.trap_moments` and ``blink_moments`` give them. Empty with
    both stages off.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).

    Returns
    -------
    dict
        ``{"traps" | "blinking": (pixels, mean_e, variance_e2)}``: the pixels' indices ``r * cols + c`` (uint64),
        their stationary mean (e-) and variance (e-^2).
    """
    from ..engine.telegraph import per_pixel
    from ..model.stages import random_telegraph as rt

    fp, c = sensor.fixed_pattern, sensor.config
    out = {}
    if fp.traps is not None and c.source_follower.enabled:
        cds = c.source_follower.rts.cds_interval_s if c.source_follower.rts.cds else None
        out["traps"] = (fp.traps, rt.trap_moments(fp.traps, cds))
    if fp.blinkers is not None:
        out["blinking"] = (fp.blinkers, rt.blink_moments(fp.blinkers, c.exposure.integration_time_s))
    for name, (signals, (mean, var)) in out.items():
        pixels, m = per_pixel(signals.index, mean)
        out[name] = (pixels, m, per_pixel(signals.index, var)[1])
    return out


def _pixel_map(pixels: np.ndarray, values: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A (rows, cols) float64 map that is ``values`` at the flat indices ``pixels`` and 0 elsewhere."""
    out = np.zeros(shape[0] * shape[1])
    out[pixels.astype(np.int64)] = values
    return out.reshape(shape)


def _sparse_variance(values: np.ndarray, n: int) -> float:
    """The variance over ``n`` pixels of a map that is ``values`` at a few of them and 0 elsewhere."""
    mean = float(values.sum()) / n
    return max(float((values * values).sum()) / n - mean * mean, 0.0)


def _cdf(a):
    from scipy.special import ndtr

    return ndtr(a)


def _truncated_below(m: np.ndarray, v: np.ndarray, c: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of X ~ Normal(m, v) given X < c (where that is almost sure: X itself)."""
    s = np.sqrt(np.maximum(v, 1e-300))
    a = (c - m) / s
    cdf = np.maximum(_cdf(a), 1e-300)
    ratio = np.exp(-0.5 * a * a) / math.sqrt(2 * math.pi) / cdf
    mean = m - s * ratio
    var = v * np.clip(1 - a * ratio - ratio**2, 0.0, 1.0)
    return mean, var


def _rms(variances: dict[str, float]) -> dict[str, float]:
    return {k: math.sqrt(max(v, 0.0)) for k, v in variances.items()}


def by_size(dark: dict, scene: dict, key: str = "temporal_rms_e") -> list[str]:
    """The sources of two budgets, largest at the scene's mean first (then in the dark): the order the report's
    table and its bar chart share.

    Parameters
    ----------
    dark, scene : dict
        :func:`budget` in the dark and at the scene's mean.
    key : str
        ``temporal_rms_e`` or ``fixed_pattern_rms_e``.

    Returns
    -------
    list of str
        Source names.
    """
    names = set(dark[key]) | set(scene[key])
    return sorted(names, key=lambda n: (-scene[key].get(n, 0.0), -dark[key].get(n, 0.0), n))


def budget(sensor: Sensor, signal_e: float = 0.0, photo_e: np.ndarray | None = None, _parts=None) -> dict:
    """Noise budget at ``signal_e`` (or over a scene's ``photo_e`` map, e-): rms per source (e-), totals in e- and DN.

    The totals include clipping at the full well and the ADC's top where more
    than 1e-6 of the pixels clip (``clipped_fraction``); the per-source lines
    are the unclipped contributions.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance (its configuration and fixed pattern).
    signal_e : float
        The mean photo-signal, e- (ignored where ``photo_e`` is given).
    photo_e : (rows, cols) array, e-, optional
        A scene's mean photo-charge per pixel: the budget over the scene, pixel by pixel.
    _parts : tuple, optional
        :func:`fixed_pattern_parts` of this sensor, when several levels are asked for.

    Returns
    -------
    dict
        ``signal_e``; ``temporal_rms_e`` and ``fixed_pattern_rms_e`` (per source, e- rms); ``temporal_total_e``,
        ``temporal_total_dn`` and ``fixed_pattern_total_e``; ``dominant_temporal``; ``clipped_fraction``;
        ``snr_temporal`` and ``snr`` (with the fixed pattern), ratios.

    Examples
    --------
    >>> from cmosnoise import Sensor, noise_budget
    >>> b = noise_budget.budget(Sensor({"sensor": {"width": 64, "height": 48}}, seed=7), 1000.0)
    >>> b["dominant_temporal"], round(b["temporal_rms_e"]["photon_shot"], 1)
    ('photon_shot', 31.6)
    """
    if photo_e is not None:
        signal_e = float(np.mean(photo_e))
    tv = temporal_variances(sensor, signal_e)
    fv = fixed_pattern_variances(sensor, signal_e, _parts)
    k = sensor.transfer.gain_dn_per_e
    total_t = sum(tv.values())
    total_f = sum(fv.values())
    clip = clipping(sensor, signal_e, photo_e)
    if clip["clipped_fraction"] > 1e-6:
        q = tv.get("quantization", 0.0)
        total_t = clip["temporal_var_e2"] + q
        total_f = clip["spatial_var_e2"] if photo_e is None else total_f
    return {
        "signal_e": signal_e,
        "clipped_fraction": clip["clipped_fraction"],
        "temporal_rms_e": _rms(tv),
        "temporal_total_e": math.sqrt(total_t),
        "temporal_total_dn": math.sqrt(total_t) * k,
        "dominant_temporal": max(tv, key=tv.get) if tv else None,
        "fixed_pattern_rms_e": _rms(fv),
        "fixed_pattern_total_e": math.sqrt(total_f),
        "snr_temporal": snr(signal_e, math.sqrt(total_t)),
        "snr": snr(signal_e, math.sqrt(total_t + total_f)),
    }
