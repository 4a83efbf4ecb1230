"""A run's summary (``summary.json``) and the metadata its raw.tiff records, built in one place for a whole run
(:mod:`.run`), a tiled run (:mod:`.tiled`) and the further instances that ``compare`` makes.

The figures come from :mod:`cmosnoise.analysis` (each figure's one estimator); this module arranges them: the
head every summary starts with, the signal, the sensor's own figures, the noise budget at the scene, the
warnings a run prints.
"""

from __future__ import annotations

import time

import numpy as np

from .._version import __version__
from ..analysis import figures_of_merit as fom
from ..analysis import noise_budget
from ..analysis.run_stats import RunStats
from ..engine.frame.kernel import generator_info
from ..io.raw_tiff import raw_metadata
from ..model.sensor import Sensor


def run_warnings(measured: dict, predicted: dict) -> list[str]:
    """What a user should know before trusting the figures: pixels that clip."""
    out = []
    sat = measured.get("saturated_fraction") or 0.0
    if max(sat, predicted.get("clipped_fraction", 0.0)) > 1e-3:
        out.append(f"{100 * sat:.3g} % of pixels sit at the top code in the frames ({100 * predicted['clipped_fraction']:.3g} % "
                   "predicted to clip at the full well or the ADC's top): their noise is lower than unclipped pixels' "
                   "(the predicted totals include it)")
    return out


def run_metadata(sensor: Sensor, **extra) -> dict:
    """What a run's raw.tiff records (:func:`~cmosnoise.io.raw_tiff.raw_metadata`): the CFA, black level, bits and
    gain, the first frame, the seed, the version, scene white, the responsivities, crosstalk, the generator, the
    units, and ``extra``.

    Parameters
    ----------
    sensor : Sensor
        The run's sensor (a whole one, or a tiled run's corner window).
    **extra
        Further entries (a tiled run's ``tile``).

    Returns
    -------
    dict
    """
    config, t, info = sensor.config, sensor.transfer, sensor.raw_info()
    return raw_metadata(
        sensor.cfa, t.black_level_dn, t.output_bits, t.gain_dn_per_e,
        adc_bits=t.bits, first_frame=config.run.first_frame, seed=config.seed, cmosnoise_version=__version__,
        scene_white_dn=info.white_dn, channel_responsivity=list(info.responsivity),
        crosstalk_kernel_pct=info.crosstalk_kernel_pct, generator=generator_info(sensor.device),
        units="DN" if config.adc.enabled else "e- (ideal readout: ADC off)", **extra,
    )


def summary_head(sensor: Sensor, n: int) -> dict:
    """What every run's summary.json starts with: the version, the generator, the seed, the scene, the frames,
    the sensor's size and CFA, its stages and its ADC (a whole run's sensor, or a tiled run's corner window: the
    same configuration).

    Parameters
    ----------
    sensor : Sensor
        The run's sensor.
    n : int
        The run's frames.

    Returns
    -------
    dict
    """
    c = sensor.config
    t = sensor.transfer
    return {
        "cmosnoise_version": __version__,
        "generator": generator_info(sensor.device),
        "seed": c.seed,
        "scene": c.scene.source,
        "frames": n,
        "first_frame": c.run.first_frame,
        "sensor": {"rows": sensor.shape[0], "cols": sensor.shape[1], "cfa": sensor.cfa},
        "stages": sensor.stages_on(),
        "adc": {
            "gain_dn_per_e": t.gain_dn_per_e,
            "gain_e_per_dn": 1 / t.gain_dn_per_e,
            "black_level_dn": t.black_level_dn,
            "bits": t.bits,
            "output_bits": t.output_bits,
            "step_dn": t.step,
        },
        **({"light": light_figures(sensor)} if sensor.spec.light is not None else {}),
    }


def light_figures(sensor: Sensor) -> dict:
    """With light in lux: the light, the lens, and what a white (reflectance 1) gives on the optical axis.

    Parameters
    ----------
    sensor : Sensor
        A sensor with ``light.enabled``.

    Returns
    -------
    dict
        ``illuminance_lux`` (or ``luminance_cd_m2``), ``illuminant``, ``f_number``, ``camera_equation``,
        ``focal_plane_lux`` and ``focal_plane_lux_s`` of a white, its photo-electrons per second and per exposure
        in each channel (R, G, B).
    """
    c, li = sensor.config, sensor.spec.light
    white = sensor.spec.focal_plane.white_e_per_s
    t = c.exposure.integration_time_s
    given = ({"illuminance_lux": c.light.illuminance_lux} if c.light.illuminance_lux is not None
             else {"luminance_cd_m2": c.light.luminance_cd_m2})
    return {**given, "illuminant": c.light.illuminant, "f_number": c.optics.f_number,
            "camera_equation": c.optics.camera_equation, "focal_plane_lux": li.focal_plane_lux,
            "focal_plane_lux_s": li.focal_plane_lux * t, "white_e_per_s": [float(v) for v in white],
            "white_e": [float(v * t) for v in white]}


def signal_figures(perfect_mean_e: float, expected_mean_e: float, measured: dict) -> dict:
    """A summary's ``signal``: the perfect image's and the expected charge's means (e-, float64 sums) beside the
    frames' measured ones (:meth:`RunStats.result`).

    Parameters
    ----------
    perfect_mean_e, expected_mean_e : float
        The means over the sensor, e-.
    measured : dict
        The run's statistics.

    Returns
    -------
    dict
    """
    return {"perfect_mean_e": perfect_mean_e, "expected_mean_e": expected_mean_e,
            "mean_e": measured.get("mean_e"), "mean_dn": measured.get("mean_dn"),
            "saturated_fraction": measured.get("saturated_fraction")}


def sensor_figures(sensor: Sensor) -> dict:
    """The summary's figures of the sensor alone, from its fixed maps (not the scene, not the frames): the dark
    noise budget, the key figures and the dark-current map's figures. A run makes them on a thread of their own
    while the scene and the frames are made (:func:`simulate`), so the summary after the frames has only the
    scene's and frame 0's figures left to make.

    Parameters
    ----------
    sensor : Sensor
        The sensor instance.

    Returns
    -------
    dict
        ``at_dark`` (:func:`noise_budget.budget` at no signal), ``key_figures`` (:func:`fom.key_figures`),
        ``dark_current`` (:func:`fom.dark_current` of the map, without frame 0's figures; None with the stage
        off) and ``seconds`` (what they took).
    """
    t0 = time.perf_counter()
    out = {"at_dark": noise_budget.budget(sensor, 0.0), "key_figures": fom.key_figures(sensor),
           "dark_current": fom.dark_current(sensor)}
    out["seconds"] = time.perf_counter() - t0
    return out


def build_summary(sensor: Sensor, shot, stats: RunStats, wall_s: float, n: int, electrons0: np.ndarray,
                  prepared: dict | None = None) -> dict:
    t = sensor.transfer
    measured = stats.result()
    timings = {k: round(v, 6) for k, v in sensor.timings.items()}
    prepared = prepared or sensor_figures(sensor)
    at_dark = prepared["at_dark"]
    predicted = noise_budget.budget(sensor, photo_e=shot.photo_mean_e)  # this scene, pixel by pixel: clipping included
    dark = prepared["dark_current"]
    state = sensor.dark_state
    if dark is not None and state.threshold is not None:  # the white pixels seen in frame 0, after the map's
        dark = {**dark, "frame0": fom.frame0_white_pixels(sensor, shot, electrons0, state.threshold,
                                                          at_dark["temporal_total_e"] ** 2)}
    return {
        **summary_head(sensor, n),
        "signal": signal_figures(float(shot.perfect_e.mean(dtype=np.float64)),
                                 shot.expected_sum() / shot.photo_mean_e.size, measured),
        "temporal_noise": {
            **fom.temporal_noise(measured, t.gain_dn_per_e),
            "predicted_rms_e": predicted["temporal_total_e"],
            "predicted_rms_dn": predicted["temporal_total_dn"],
        },
        "noise_budget": {
            "dark": at_dark,
            "scene_mean": predicted,
        },
        "key_figures": prepared["key_figures"],
        "dark_current": dark,
        "random_telegraph": fom.telegraph(sensor, shot.frame_period_s),
        "warnings": run_warnings(measured, predicted) + ([dark["warning"]] if dark and "warning" in dark else []),
        "timings_s": {
            "total": round(wall_s, 6),  # simulate() adds the summary's own time ("summary")
            "per_frame": round(wall_s / max(n, 1), 6),  # set-up and frames, per frame
            "stages": timings,
            # the sensor's own figures, made on a thread of their own beside the scene and the frames
            "summary_aside": round(prepared["seconds"], 6),
        },
    }
