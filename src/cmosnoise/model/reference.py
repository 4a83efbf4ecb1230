"""The frame chain in NumPy, stage by stage: frame ``k`` of a :class:`~cmosnoise.engine.frame.plan.FramePlan` over a
region, the specification the compiled kernels are held to bit for bit.

A plan holds what every frame of an exposure shares (the mean charges, the per-pixel, per-row and per-column
maps, the ADC, the stream keys); a frame adds its index. :func:`electrons` runs stages 3b to 8 (shot noise with
the blinking pixels' charge, the charge's nonlinearity, pixel offsets, the source follower and its traps, row and
column noise) on the NumPy samplers; :func:`after_gain` makes stage 9a's black level and read noise in DN. The
frame kernel (``engine/frame/kernel.py``, ``_render_rows``) and the GPU's (``engine/frame/cuda_device.py``, ``pixels``) fuse
the same stages per pixel with the same draws: ``tests/test_engine.py`` and ``tests/test_cuda.py`` hold them to
this, and the golden digests hold all three (docs/model.md section 1).

:class:`~cmosnoise.model.sensor.Exposure` orchestrates: it builds the plan, picks the back-end, and turns the
parts this module reports into a frame's per-stage contributions.

Examples
--------
>>> import numpy as np
>>> from cmosnoise import Sensor
>>> from cmosnoise.model import reference
>>> shot = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7).expose("flat:0.5")
>>> e = reference.electrons(shot.plan(), 0, (0, 48, 0, 64))
>>> e.shape, e.dtype
((48, 64), dtype('float64'))
"""

from __future__ import annotations

import math

import numpy as np

from ..engine.frame.plan import KEY_ROWS, FramePlan
from ..engine.samplers import Stream
from ..engine.telegraph import per_pixel, plus_charge, positions
from .seeds import pixel_index
from .stages import column_noise, random_telegraph, read_noise, row_noise, shot_noise, source_follower


def stream(plan: FramePlan, name: str, k: int) -> Stream:
    """Frame ``k``'s random numbers of the temporal stream ``name`` (a row of :data:`~cmosnoise.engine.frame.plan.KEY_ROWS`).

    Parameters
    ----------
    plan : FramePlan
    name : str
        The stream's name, e.g. ``"shot_noise"``.
    k : int
        The frame.

    Returns
    -------
    Stream
        The draws :func:`cmosnoise.model.seeds.temporal_stream` gives for the plan's seed, stage, frame and series.
    """
    row = plan.keys[KEY_ROWS.index(name)]
    return Stream((int(row[0]), int(row[1])), int(k), int(plan.sequence))


def electrons(plan: FramePlan, k: int, region: tuple[int, int, int, int],
              parts: dict | None = None) -> np.ndarray:
    """Charge at the ADC input in frame ``k`` over ``region``, stage by stage (e-, float64).

    Parameters
    ----------
    plan : FramePlan
        The exposure's plan.
    k : int
        The frame, >= 0.
    region : (row0, row1, col0, col1)
        Inside the plan's window (the whole frame without one); the random numbers are drawn at the frame's own
        pixel addresses.
    parts : dict, optional
        Filled with what each stage made, by name: ``collected`` (after shot noise), ``converted`` (after the
        charge's nonlinearity), ``source_follower``, ``traps`` ((positions, values) of the trap pixels),
        ``blinking`` ((positions, this frame's extra mean)), ``row_noise``, ``before_columns``, and ``rows_on`` /
        ``columns_on``.

    Returns
    -------
    (rows, cols) float64 array, e-
    """
    r0, r1, c0, c1 = region
    cols_total = plan.shape[1]
    w0, v0 = plan.origin  # the region in the plan's arrays (a window's own)
    win = (slice(r0 - w0, r1 - w0), slice(c0 - v0, c1 - v0))
    index = pixel_index(region, cols_total)
    noisy = plan.noisy_e[win] if plan.noisy_e is not None else None
    exact = plan.exact_e[win] if plan.exact_e is not None else None
    if plan.blinkers is not None:  # stage 4b: this frame's mean at each blinking pixel
        pixels = plan.blinkers.within(region, cols_total)
        extra = random_telegraph.blink_charge(pixels, k, plan.sequence, plan.frame_period_s, plan.exposure_s,
                                              plan.blink_key)
        means = plus_charge(plan.blink_mean_e, pixels.index, extra, plan.origin, cols_total)
        at_blink = positions(pixels.index, region, cols_total)
        patched = (noisy if plan.blink_noisy else exact).copy()
        if parts is not None:
            parts["blinking"] = (at_blink, means - patched[at_blink])
        patched[at_blink] = means
        noisy, exact = (patched, exact) if plan.blink_noisy else (noisy, patched)
    n = shot_noise.collect(noisy, exact, plan.full_well_e, stream(plan, "shot_noise", k) if noisy is not None else None,
                           None if math.isinf(plan.normal_above_e) else plan.normal_above_e, index)
    collected = n
    if plan.nonlinearity is not None:
        n = plan.nonlinearity.apply(n)
    converted = n
    if plan.offset_e is not None:
        offsets = plan.offsets(k)
        n = n + offsets[win]
        if parts is not None and plan.pixel_flicker is not None:
            parts["pixel_flicker"] = (offsets - plan.offset_e)[win]
    if plan.sf_sigma_e is not None:
        sfn = source_follower.noise(plan.sf_sigma_e[win], stream(plan, "source_follower", k), index)
        n = n + sfn
        if parts is not None:
            parts["source_follower"] = sfn
    if plan.traps is not None:  # stage 6b
        inside = plan.traps.within(region, cols_total)
        pixels, traps = per_pixel(inside.index, random_telegraph.trap_output(
            inside, k, plan.sequence, plan.frame_period_s, plan.cds_interval_s, plan.trap_key))
        at = positions(pixels, region, cols_total)
        n[at] = n[at] + traps
        if parts is not None:
            parts["traps"] = (at, traps)
    rows_on, columns_on = plan.row_sigma_e is not None, plan.col_sigma_e is not None
    if rows_on:
        rown = (row_noise.temporal(np.arange(r0, r1), plan.row_sigma_e, stream(plan, "row_noise", k))
                + plan.row_offsets(k)[win[0], None])
        n = n + rown
        if parts is not None:
            parts["row_noise"] = rown
    before_columns = n
    if columns_on:
        # each column's temporal noise (sigma 0 where the stage has none: adding 0 changes no value), then the
        # column amplifier's gain and offset
        offset = plan.col_offsets(k)[None, win[1]] + column_noise.temporal(
            plan.col_sigma_e[None, :], np.arange(c0, c1), stream(plan, "column_noise", k), first=v0)
        n = column_noise.apply(n, plan.col_gain[None, win[1]], offset)
    if parts is not None:
        parts.update(collected=collected, converted=converted, before_columns=before_columns, rows_on=rows_on,
                     columns_on=columns_on)
    return n


def after_gain(plan: FramePlan, k: int, region: tuple[int, int, int, int]
               ) -> tuple[np.ndarray, np.ndarray | None]:
    """Frame ``k``'s black level per pixel and read noise after the gain over ``region`` (stage 9a), DN.

    Parameters
    ----------
    plan : FramePlan
        With its ADC (``plan.adc``).
    k : int
        The frame.
    region : (row0, row1, col0, col1)

    Returns
    -------
    (black, read)
        The black level with the cell offsets and the frame's error in it, (rows, cols) float64; the read noise,
        (rows, cols) float64, or None where it is off.
    """
    err = read_noise.frame_error(plan.frame_black_sigma_dn, stream(plan, "black_level", k))
    cell = read_noise.cell_black(plan.adc[1], plan.cell_offsets_dn, err)
    black = read_noise.black_map(cell, region)
    read = None
    if plan.read_noise is not None:
        distribution, scale_dn, shape = plan.read_noise
        read = read_noise.noise(distribution, scale_dn, shape, stream(plan, "source_follower", k),
                                pixel_index(region, plan.shape[1]))
    return black, read


__all__ = ["stream", "electrons", "after_gain"]
