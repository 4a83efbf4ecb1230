"""Figures of merit of a simulated sensor and of its frames: one estimator for each.

``simulate``'s summary (:mod:`cmosnoise.app.run`), the sweep's records
(:mod:`cmosnoise.app.sweep`), the explorer's key figures
(:mod:`cmosnoise.app.workbench`) and the report all take their numbers from
here, so a figure means the same wherever it shows:

- :func:`temporal_noise`: from consecutive frames, ``var(A - B) / 2`` over
  the pixels (EMVA 1288), gathered by :class:`~.run_stats.RunStats`; in DN
  (quantization included) and in e- through K;
- :func:`key_figures`: SNR at signal levels and the dynamic range, from the
  noise budget (:mod:`.noise_budget`);
- :func:`dark_current`: the dark map's statistics and its white pixels
  (:func:`.white_pixels.report`, the one count: above the threshold of the
  nearest characterization point), and those seen in frame 0;
- :func:`telegraph`: the random telegraph pixels (traps, blinking pixels);
- :func:`pane`: what the explorer shows beside a picture.

The robust sigma and the 95 % quantile are :mod:`cmosnoise.estimators`'
(one place for every layer, ``isp`` included).

Examples
--------
>>> from cmosnoise import Sensor, figures_of_merit
>>> kf = figures_of_merit.key_figures(Sensor({"sensor": {"width": 64, "height": 48}}))
>>> kf["saturation_e"]
10000.0
"""

from __future__ import annotations

import math

import numpy as np

from ..engine import reduce
from ..engine import telegraph as telegraph_chain
from ..estimators import snr
from ..model.sensor import Exposure, Sensor
from ..model.units import e_per_s_to_aa
from . import noise_budget, white_pixels

__all__ = ["temporal_noise", "key_figures", "dark_map", "dark_current", "frame0_white_pixels", "telegraph", "pane"]


#: each figure's name and unit as the docs and the pages show them ({level}: the signal, e-, of a per-level figure)
FIGURE_NAMES = {
    "saturation_e": "saturation (e-)",
    "read_noise_e": "read noise, dark temporal without the dark shot noise (e- rms)",
    "dark_temporal_noise_e": "dark temporal noise (e- rms)",
    "dynamic_range": "dynamic range (ratio)",
    "dynamic_range_db": "dynamic range (dB)",
    "snr_temporal_db_at_signal_e": "SNR, temporal, at {level} e- (dB)",
    "snr_total_db_at_signal_e": "SNR with fixed pattern, at {level} e- (dB)",
    "mean_e_per_s": "dark current, map mean (e-/s)",
    "threshold_e_per_s": "white-pixel threshold (e-/s)",
    "threshold_aA": "white-pixel threshold (aA)",
    "threshold_source": "white-pixel threshold from",
    "threshold": "white-pixel threshold (e-/s)",
    "white_pixels": "white pixels (above the threshold)",
    "ppm": "white pixels (ppm)",
    "couplets": "couplets (white pixels side by side)",
    "couplets_expected_random": "couplets expected at random",
}


def temporal_noise(stats: dict, gain_dn_per_e: float) -> dict:
    """Temporal noise from a :meth:`RunStats.result` (``var(frame k - frame k-1) / 2`` over the pixels).

    Parameters
    ----------
    stats : dict
        :meth:`cmosnoise.analysis.run_stats.RunStats.result` of a run's frames.
    gain_dn_per_e : float
        K, DN per electron.

    Returns
    -------
    dict
        ``rms_dn`` (raw codes: quantization included), ``rms_e`` (``rms_dn`` through K), ``rms_e_before_adc``
        (the charge at the ADC input, without quantization) and ``method``; each None with fewer than two frames.
    """
    dn = stats.get("temporal_noise_dn")
    return {"rms_dn": dn, "rms_e": None if dn is None else dn / gain_dn_per_e,
            "rms_e_before_adc": stats.get("temporal_noise_e"), "method": stats.get("temporal_noise_method")}


def key_figures(sensor: Sensor, levels_e=(10.0, 100.0, 1000.0)) -> dict:
    """SNR (temporal, and with the fixed pattern) at signal levels and at half the saturation, and the dynamic
    range (saturation over the dark temporal noise).

    Parameters
    ----------
    sensor : Sensor
        The sensor instance.
    levels_e : sequence of float
        Signal levels, e-.

    Returns
    -------
    dict
        ``saturation_e``, ``read_noise_e`` (the dark temporal noise without the dark current's shot noise: what a data
        sheet calls the read noise) and ``dark_temporal_noise_e`` (e-), ``dynamic_range`` (ratio) and
        ``dynamic_range_db``;
        ``snr_temporal_db_at_signal_e`` and ``snr_total_db_at_signal_e``, dB by level keyed as text (``"100"``).
        :data:`FIGURE_NAMES` names them.
    """
    sat = sensor.saturation_e
    levels = sorted({*levels_e, round(sat / 2, 3)})
    parts = noise_budget.fixed_pattern_parts(sensor)  # once for every level
    dark = noise_budget.budget(sensor, 0.0, _parts=parts)["temporal_total_e"]
    at = {f"{lvl:g}": noise_budget.budget(sensor, lvl, _parts=parts) for lvl in levels if lvl < sat}

    def db(v):
        return 20 * math.log10(v) if 0 < v < math.inf else None

    dr = snr(sat, dark)  # infinite without dark noise (every noise source off): JSON's null, said as such
    # the read noise as a data sheet gives it: the dark temporal noise without the dark current's shot noise (EMVA
    # 1288's sigma_d at no exposure), what source_follower.read_noise_e sets
    read = noise_budget.temporal_variances(sensor, 0.0)
    return {
        "saturation_e": sat,
        "read_noise_e": math.sqrt(sum(v for k, v in read.items() if k not in ("dark_shot", "rts_blinking"))),
        "dark_temporal_noise_e": dark,
        "dynamic_range": dr,
        "dynamic_range_db": db(dr),
        # temporal SNR (the EMVA 1288 convention), and with the fixed pattern added
        "snr_temporal_db_at_signal_e": {k: db(b["snr_temporal"]) for k, b in at.items()},
        "snr_total_db_at_signal_e": {k: db(b["snr"]) for k, b in at.items()},
    }


def dark_map(sensor: Sensor) -> dict | None:
    """The dark-current map's mean and white pixels (None with dark current off).

    ``mean_e_per_s``, ``threshold_e_per_s`` (``dark_current.white_threshold_*``, else the nearest
    characterization point's, or None), ``threshold_source`` (which) and, with a threshold, :func:`white_pixels.report`'s
    ``ppm``, ``white_pixels``, ``couplets`` and ``couplets_expected_random``.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance.

    Returns
    -------
    dict or None
        The figures above (rates in e-/s); None with dark current off.
    """
    state, rate = sensor.dark_state, sensor.dark_rate
    if state is None:
        return None
    out = {"mean_e_per_s": noise_budget.map_moment(sensor, "dark_rate", "mean"), "threshold_e_per_s": state.threshold,
           "threshold_source": state.threshold_source}
    if state.threshold is not None:
        rep = white_pixels.report(rate, state.threshold, sensor.cfa)
        out.update({k: rep[k] for k in rep if isinstance(rep[k], (int, float))})
    return out


def dark_current(sensor: Sensor, shot: Exposure | None = None, electrons0: np.ndarray | None = None,
                 read_var_e2: float = 0.0) -> dict | None:
    """Dark-current figures of a run: the map's statistics, its white pixels and couplets, and (given frame 0's
    charge ``electrons0`` of ``shot`` and the dark read variance, e-^2) those seen in frame 0.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance.
    shot : Exposure, optional
        The run's exposure.
    electrons0 : (rows, cols) array, e-, optional
        Frame 0's charge at the ADC input.
    read_var_e2 : float
        The dark temporal variance of the readout, e-^2.

    Returns
    -------
    dict or None
        The body and tail, the map's mean and median (e-/s), the threshold (e-/s and aA) and where it comes from,
        the expected ppm, the map's white pixels and couplets (``map``) and frame 0's (``frame0``); None with the
        stage off.
    """
    state, rate = sensor.dark_state, sensor.dark_rate
    if state is None:
        return None
    t_int = sensor.config.exposure.integration_time_s
    mean = noise_budget.map_moment(sensor, "dark_rate", "mean")  # the map's statistics, once per sensor
    out = {
        "temperature_c": state.temperature_c,
        "body": {"family": state.family, "mean_e_per_s": state.mean, "std_e_per_s": state.std},
        "tail": {"fraction": state.tail_fraction, "max_e_per_s": state.tail_max},
        "map_mean_e_per_s": mean,
        "map_median_e_per_s": float(np.median(rate)),
        "mean_dark_e_per_frame": mean * t_int,
        "interpolation": (f"per-pixel exponential between the points at {state.temperature_c:g} C (weight {state.w:.3f})"
                          if state.between else "at a characterization point, or scaled from the nearest one"),
    }
    cooling = sensor.dark_cooling_fraction
    out["cooling_fraction"] = cooling
    if cooling > 0:
        out["warning"] = (f"{100 * cooling:.3g} % of pixels cool while the sensor warms between two of the "
                          "dark_current.points: a warmer point's quantiles lie below a colder one's")
    out.update(threshold_figures(state))
    if state.threshold is not None:
        out["map"] = white_pixels.report(rate, state.threshold, sensor.cfa)
        if shot is not None and electrons0 is not None:
            out["frame0"] = frame0_white_pixels(sensor, shot, electrons0, state.threshold, read_var_e2)
    return out


def threshold_figures(state) -> dict:
    """The white-pixel threshold of a dark state: e-/s, aA, where it comes from, and the ppm the law expects above
    it; empty without a threshold. The one place a summary states them (a whole run's, a tiled run's).

    Parameters
    ----------
    state : DarkState
        The dark current at the sensor's temperature.

    Returns
    -------
    dict
        ``threshold_e_per_s``, ``threshold_aA``, ``threshold_source``, ``ppm_expected``.

    Examples
    --------
    >>> from cmosnoise import Sensor, figures_of_merit
    >>> state = Sensor({"sensor": {"width": 64, "height": 48}}).dark_state
    >>> figures_of_merit.threshold_figures(state)["threshold_e_per_s"]
    100.0
    """
    thr = state.threshold
    if thr is None:
        return {}
    return {"threshold_e_per_s": thr, "threshold_aA": e_per_s_to_aa(thr), "threshold_source": state.threshold_source,
            "ppm_expected": state.expected_ppm_above()}


def frame0_white_pixels(sensor: Sensor, shot: Exposure, electrons0: np.ndarray, threshold_e_per_s: float,
                        read_var_e2: float) -> dict:
    """White pixels seen in frame 0, counted so that temporal noise is not taken for dark current.

    A pixel counts when its charge, less the expected photo-charge, exceeds
    the threshold's charge by 5 sigma of its temporal noise (photon shot
    noise plus the read noise): false alarms about 3e-7 per pixel. In a
    short exposure or a bright area a white pixel can hide in that noise,
    so the count is a lower bound of the map's; the summary says so.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance.
    shot : Exposure
        The run's exposure.
    electrons0 : (rows, cols) array, e-
        Frame 0's charge at the ADC input.
    threshold_e_per_s : float
        The white-pixel threshold, e-/s.
    read_var_e2 : float
        The dark temporal variance of the readout, e-^2.

    Returns
    -------
    dict
        :func:`white_pixels.report`'s figures and the ``method``.
    """
    t_int = sensor.config.exposure.integration_time_s
    # read_var_e2: the budget's dark variance (e-^2); one compiled pass, nothing the size of the frame in float64
    r, c, lit = reduce.excess_positions(electrons0, shot.photo_mean_e, read_var_e2, 5.0, t_int, threshold_e_per_s)
    rep = white_pixels.report_at(r, c, electrons0.shape, threshold_e_per_s, sensor.cfa)
    kind = "lit frame" if lit else "dark frame"
    rep["method"] = (f"{kind}: (charge - expected photo-charge - 5 sigma of photon shot and read noise) / integration "
                     "time, above the threshold; a lower bound of the map's count (white pixels can hide in the noise)")
    return rep


def pane(sensor: Sensor, shot: Exposure, levels_e=(10.0, 100.0, 1000.0)) -> dict:
    """What the explorer shows beside a picture and a sweep records of an instance.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance.
    shot : Exposure
        A scene on the sensor.
    levels_e : sequence of float
        The key figures' signal levels, e-.

    Returns
    -------
    dict
        ``key_figures`` (:func:`key_figures`), ``budget`` over the scene (per source, e- rms, and totals) and,
        with dark current on, ``dark`` (:func:`dark_map`).
    """
    b = noise_budget.budget(sensor, photo_e=shot.photo_mean_e)
    out = {"key_figures": key_figures(sensor, levels_e),
           "budget": {"temporal_e": b["temporal_rms_e"], "fixed_e": b["fixed_pattern_rms_e"],
                      "temporal_total_e": b["temporal_total_e"], "fixed_total_e": b["fixed_pattern_total_e"]}}
    dark = dark_map(sensor)
    if dark is not None:
        out["dark"] = dark
    return out


#: random telegraph pixels a summary names by position, the largest first (simulate writes every one to
#: rts_pixels.csv)
LARGEST_TELEGRAPHS = 10


def _largest(pop, cols: int, name: str) -> list[dict]:
    """The :data:`LARGEST_TELEGRAPHS` largest signals of ``pop``: their row, column, size and dwell times."""
    order = np.argsort(-pop.size, kind="stable")[:LARGEST_TELEGRAPHS]
    return [{"row": int(pop.index[i]) // cols, "col": int(pop.index[i]) % cols, name: float(pop.size[i]),
             "tau_low_s": float(pop.tau_low_s[i]), "tau_high_s": float(pop.tau_high_s[i])} for i in order]


def telegraph(sensor: Sensor, frame_period_s: float) -> dict | None:
    """The random telegraph pixels of ``sensor`` (None with both stages off).

    ``source_follower``: pixels with traps, traps, their ppm, the median
    amplitude (e-), and the fraction of traps that change between the CDS
    samples in a frame at least one time in a hundred (``2 pi0 pi1 (1 -
    e^-s tau) >= 0.01``: those a dark stack shows; with CDS off, those whose
    level is not all but always one state, ``min(pi0, pi1) >= 0.01``).
    ``blinking``: pixels, ppm, median step (e-/s) and median dwell times (s).
    Each also names its ``largest`` signals by row and column (at most
    :data:`LARGEST_TELEGRAPHS`, the largest first).

    Parameters
    ----------
    sensor : Sensor
        The sensor instance.
    frame_period_s : float
        The time from one frame to the next, s.

    Returns
    -------
    dict or None
        ``source_follower`` and ``blinking`` (where on), as above.
    """
    fp, c = sensor.fixed_pattern, sensor.config
    n = sensor.shape[0] * sensor.shape[1]
    out = {}
    if fp.traps is not None and c.source_follower.enabled:
        t = fp.traps
        rts = c.source_follower.rts
        pi1 = t.occupancy
        if rts.cds:  # P(X(tau) != X(0)) in the stationary chain
            p01, _, p10, _ = telegraph_chain.transition(t.up, t.down, rts.cds_interval_s)
            seen = (1 - pi1) * p01 + pi1 * p10
        else:
            seen = np.minimum(pi1, 1 - pi1)
        out["source_follower"] = {
            "pixels": int(t.pixels.size), "traps": int(t.index.size), "ppm": 1e6 * t.pixels.size / n,
            "median_amplitude_e": float(np.median(t.size)) if t.index.size else None,
            "visible_fraction": float(np.mean(seen >= 0.01)) if t.index.size else None,
            "cds": rts.cds,
            "largest": _largest(t, sensor.shape[1], "amplitude_e"),
        }
    if fp.blinkers is not None:
        b = fp.blinkers
        out["blinking"] = {
            "pixels": int(b.index.size), "ppm": 1e6 * b.index.size / n,
            "median_step_e_per_s": float(np.median(b.size)) if b.index.size else None,
            "median_tau_low_s": float(np.median(b.tau_low_s)) if b.index.size else None,
            "median_tau_high_s": float(np.median(b.tau_high_s)) if b.index.size else None,
            "largest": _largest(b, sensor.shape[1], "step_e_per_s"),
        }
    if not out:
        return None
    out["frame_period_s"] = frame_period_s
    return out
