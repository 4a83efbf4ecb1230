"""EMVA 1288 measures computed from frames alone, as a lab would.

All functions take raw frames in DN and return DN (divide by the system
gain K, DN/e-, for electrons). Conventions follow EMVA 1288 release 4.0:

- temporal variance from two frames of the same scene: ``var(A - B) / 2``;
- spatial variance of the mean of L frames, corrected for the temporal
  variance left in it: ``s^2 = var(mean_L) - sigma_t^2 / L``;
- split of a spatial variance into column, row and pixel parts from the
  variances of column and row means (EMVA 1288 4.0, Sec. 8.3);
- PRNU = ``sqrt(s^2_bright - s^2_dark) / (mu_bright - mu_dark)``;
- quantization: 1/12 DN^2 is part of the temporal variance (``step^2 / 12`` where the output's codes are
  ``step`` DN apart: an ADC's codes scaled to a wider range).

Examples
--------
>>> import numpy as np
>>> from cmosnoise import emva
>>> rng = np.random.default_rng(0)
>>> stack = 100 + rng.normal(0, 2.0, (2, 64, 64))   # two frames of 2 DN temporal noise
>>> round(emva.temporal_variance(stack[0], stack[1]), 1)   # DN^2: half the variance of the difference
4.0
"""

from __future__ import annotations

import math

import numpy as np

from ..estimators import robust_centre


def temporal_variance(a: np.ndarray, b: np.ndarray) -> float:
    """Temporal variance (DN^2) from two frames of the same scene: ``var(a - b) / 2``.

    The difference is taken in float64 (exact for integer frames), in one
    temporary array, with the variance in place. (Not ``np.dot``: BLAS's
    threads keep spinning after the call and slow the next frame's kernel.)

    Parameters
    ----------
    a, b : (rows, cols) arrays, DN
        Two frames of the same scene.

    Returns
    -------
    float
        DN^2.
    """
    d = np.subtract(a, b, dtype=np.float64)
    d -= d.mean()
    np.square(d, out=d)
    return float(d.mean() / 2)


def temporal_variance_stack(stack: np.ndarray) -> float:
    """Temporal variance (DN^2): mean over pixels of the per-pixel variance over frames (ddof=1).

    Parameters
    ----------
    stack : (frames, rows, cols) array, DN
        Frames of the same scene, two or more.

    Returns
    -------
    float
        DN^2.
    """
    return float(np.mean(np.var(stack.astype(np.float64), axis=0, ddof=1)))


def spatial_variances(stack: np.ndarray) -> dict[str, float]:
    """Spatial variance of the frame average (DN^2), total and its column, row and pixel parts.

    The temporal noise that survives averaging L frames is removed from
    each part as measured in the stack itself: the pixels' temporal
    variance / L from the total, and the temporal variance of the column
    (row) means / L from the column (row) means' variance. EMVA 1288 takes
    the latter as the pixel noise / (L rows), which holds for white noise
    only: temporal column and row noise (a noise of the whole column in one
    frame) would otherwise count as fixed pattern.

    Parameters
    ----------
    stack : (frames, rows, cols) array, DN
        Frames of the same scene.

    Returns
    -------
    dict of str to float
        ``total``, ``column``, ``row`` and ``pixel`` variances (DN^2) and the frame average's ``mean`` (DN).
    """
    stack = stack.astype(np.float64)
    n_frames, rows, cols = stack.shape
    mean = stack.mean(axis=0)
    if n_frames > 1:
        residual = temporal_variance_stack(stack) / n_frames
        res_col = float(np.mean(np.var(stack.mean(axis=1), axis=0, ddof=1))) / n_frames
        res_row = float(np.mean(np.var(stack.mean(axis=2), axis=0, ddof=1))) / n_frames
    else:
        residual = res_col = res_row = 0.0
    total = float(np.var(mean, ddof=1)) - residual
    s_col = float(np.var(mean.mean(axis=0), ddof=1)) - res_col
    s_row = float(np.var(mean.mean(axis=1), ddof=1)) - res_row
    # E[total] = P + C + R, E[s_col] = C + P/rows, E[s_row] = R + P/cols  (P: pixel part), all fixed pattern
    pixel = (total - s_col - s_row) / (1 - 1 / rows - 1 / cols)
    return {
        "total": total,
        "column": s_col - pixel / rows,
        "row": s_row - pixel / cols,
        "pixel": pixel,
        "mean": float(mean.mean()),
    }


def dsnu(dark_stack: np.ndarray) -> dict[str, float]:
    """DSNU (DN rms): total, column, row and pixel parts, from a stack of dark frames.

    Parameters
    ----------
    dark_stack : (frames, rows, cols) array, DN
        Dark frames.

    Returns
    -------
    dict of str to float
        ``total``, ``column``, ``row`` and ``pixel``, DN rms.
    """
    v = spatial_variances(dark_stack)
    return {k: math.sqrt(max(v[k], 0.0)) for k in ("total", "column", "row", "pixel")}


def defect_pixels(bright_stack: np.ndarray, dark_stack: np.ndarray, saturation_dn: float) -> np.ndarray:
    """Pixels to leave out of the PRNU: outliers of the dark image and pixels near saturation, (rows, cols) bool.

    A pixel is a defect when its dark-stack mean lies more than 5 robust
    standard deviations (the median absolute deviation / 0.6745, at least
    the averaged temporal noise and 1 DN) from the median dark level - white
    and dark pixels, as EMVA 1288 sets them apart - or when its bright-stack
    mean is above 90 % of the way from the dark level to ``saturation_dn``
    (it clips, and its variance is no longer the gain's). Selecting by the
    dark signal is independent of the gain map, so the PRNU of the pixels
    left is an unbiased estimate of the whole map's.

    Parameters
    ----------
    bright_stack, dark_stack : (frames, rows, cols) arrays, DN
        Bright (about half saturation) and dark frames.
    saturation_dn : float
        The saturation level, DN.

    Returns
    -------
    (rows, cols) bool array
    """
    dark = dark_stack.astype(np.float64).mean(axis=0)
    bright = bright_stack.mean(axis=0, dtype=np.float64)
    med, robust = robust_centre(dark)
    floor = math.sqrt(temporal_variance_stack(dark_stack) / dark_stack.shape[0]) if dark_stack.shape[0] > 1 else 0.0
    sigma = max(robust, floor, 1.0)
    return (np.abs(dark - med) > 5.0 * sigma) | (bright > med + 0.9 * (saturation_dn - med))


def prnu(bright_stack: np.ndarray, dark_stack: np.ndarray, exclude: np.ndarray | None = None) -> float:
    """PRNU (fraction of the signal) from stacks of bright (~50 % saturation) and dark frames.

    ``exclude`` (rows, cols) bool leaves those pixels out (see
    :func:`defect_pixels`); the spatial variances are then totals over the
    pixels kept, each corrected for the temporal variance left in the mean.

    Parameters
    ----------
    bright_stack, dark_stack : (frames, rows, cols) arrays, DN
        Bright (about half saturation) and dark frames.
    exclude : (rows, cols) bool array, optional
        Pixels to leave out.

    Returns
    -------
    float
        PRNU as a fraction of the signal (NaN when fewer than two pixels are kept).
    """
    if exclude is None or not exclude.any():
        b = spatial_variances(bright_stack)
        d = spatial_variances(dark_stack)
        bt, dt, bm, dm = b["total"], d["total"], b["mean"], d["mean"]
    else:
        keep = ~exclude
        if keep.sum() < 2:  # every pixel a defect (e.g. a bright stack near saturation): no PRNU to give
            return math.nan

        def total(stack):
            s = stack.astype(np.float64)
            mean = s.mean(axis=0)[keep]
            residual = float(np.mean(np.var(s, axis=0, ddof=1)[keep])) / s.shape[0] if s.shape[0] > 1 else 0.0
            return float(np.var(mean, ddof=1)) - residual, float(mean.mean())

        (bt, bm), (dt, dm) = total(bright_stack), total(dark_stack)
    return math.sqrt(max(bt - dt, 0.0)) / (bm - dm)
