"""Noise budget: what each source contributes, predicted from a sensor instance.

Temporal noise adds in variance. For one pixel at mean signal ``mu`` (e-),
averaged over the array (the sensor's own fixed maps: flicker sigmas,
column sigmas, column gains, dark-current map)::

    var = (mu + d + thermal^2 + <flicker_i^2> + row^2) * <g_c^2> + <sigma_c^2> + 1 / (12 K^2)

with ``d`` the mean dark charge (its shot noise), ``g_c`` the column gains
and the last term quantization (1/12 DN^2, in e-). Fixed pattern noise is
listed apart: DSNU (dark-current map, row and column offsets) and PRNU.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..model.sensor import Sensor


def temporal_variances(sensor: Sensor, signal_e: float = 0.0) -> dict[str, float]:
    """Each temporal source's variance (e-^2) at mean photo-signal ``signal_e``."""
    c = sensor.config
    fp = sensor.fixed_pattern
    t = sensor.transfer
    g2 = float(np.mean(fp.column_gain.astype(np.float64) ** 2)) if fp.column_gain is not None else 1.0
    out: dict[str, float] = {}
    if c.shot_noise.enabled:
        out["photon_shot"] = signal_e * g2
    if fp.dark_rate is not None and c.dark_current.shot_noise:
        out["dark_shot"] = float(fp.dark_rate.mean()) * c.exposure.integration_time_s * g2
    if c.source_follower.enabled:
        out["thermal"] = c.source_follower.thermal_sigma_e**2 * g2
        if fp.flicker_sigma is not None:
            out["flicker"] = float(np.mean(fp.flicker_sigma.astype(np.float64) ** 2)) * g2
    if c.row_noise.enabled:
        out["row"] = c.row_noise.sigma_e**2 * g2
    if fp.column_sigma is not None:
        out["column"] = float(np.mean(fp.column_sigma.astype(np.float64) ** 2))
    if c.adc.enabled:  # the ideal readout (ADC off) is not quantized
        out["quantization"] = 1.0 / (12.0 * t.gain_dn_per_e**2)
    return out


def fixed_pattern_variances(sensor: Sensor, signal_e: float = 0.0) -> dict[str, float]:
    """Each fixed-pattern source's spatial variance (e-^2) at mean photo-signal ``signal_e``."""
    c = sensor.config
    fp = sensor.fixed_pattern
    out: dict[str, float] = {}
    if fp.dark_rate is not None:
        out["dcnu"] = float(np.var(fp.dark_rate.astype(np.float64))) * c.exposure.integration_time_s**2
    if fp.row_offset is not None:
        out["row_fixed"] = float(np.var(fp.row_offset.astype(np.float64)))
    if fp.vfpn is not None:
        out["vfpn"] = float(np.var(fp.vfpn.astype(np.float64)))
    if fp.prnu_gain is not None:
        out["prnu"] = float(np.var(fp.prnu_gain.astype(np.float64))) * signal_e**2
    if fp.column_gain is not None:
        out["column_gain"] = float(np.var(fp.column_gain.astype(np.float64))) * signal_e**2
    return out


def _rms(variances: dict[str, float]) -> dict[str, float]:
    return {k: math.sqrt(max(v, 0.0)) for k, v in variances.items()}


def budget(sensor: Sensor, signal_e: float = 0.0) -> dict:
    """Noise budget at ``signal_e``: rms per source (e-), totals in e- and DN, and the dominant source."""
    tv = temporal_variances(sensor, signal_e)
    fv = fixed_pattern_variances(sensor, signal_e)
    k = sensor.transfer.gain_dn_per_e
    total_t = sum(tv.values())
    total_f = sum(fv.values())
    return {
        "signal_e": signal_e,
        "temporal_rms_e": _rms(tv),
        "temporal_total_e": math.sqrt(total_t),
        "temporal_total_dn": math.sqrt(total_t) * k,
        "dominant_temporal": max(tv, key=tv.get) if tv else None,
        "fixed_pattern_rms_e": _rms(fv),
        "fixed_pattern_total_e": math.sqrt(total_f),
        "snr_temporal": signal_e / math.sqrt(total_t) if signal_e > 0 else 0.0,
        "snr": signal_e / math.sqrt(total_t + total_f) if signal_e > 0 else 0.0,
    }


def key_figures(sensor: Sensor, levels_e=(10.0, 100.0, 1000.0)) -> dict:
    """SNR (temporal and fixed pattern) at several signal levels, and the dynamic range."""
    sat = sensor.saturation_e
    levels = sorted({*levels_e, round(sat / 2, 3)})
    dark = budget(sensor, 0.0)["temporal_total_e"]
    at = {f"{lvl:g}": budget(sensor, lvl) for lvl in levels if lvl < sat}

    def db(v):
        return 20 * math.log10(v) if v > 0 else None

    return {
        "saturation_e": sat,
        "dark_temporal_noise_e": dark,
        "dynamic_range": sat / dark,
        "dynamic_range_db": 20 * math.log10(sat / dark),
        # temporal SNR (the EMVA 1288 convention), and with the fixed pattern added
        "snr_temporal_db_at_signal_e": {k: db(b["snr_temporal"]) for k, b in at.items()},
        "snr_total_db_at_signal_e": {k: db(b["snr"]) for k, b in at.items()},
    }
