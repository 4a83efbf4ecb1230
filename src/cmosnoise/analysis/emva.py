"""EMVA 1288 measures computed from frames alone, as a lab would.

All functions take raw frames in DN and return DN (divide by the system
gain K, DN/e-, for electrons). Conventions follow EMVA 1288 release 4.0:

- temporal variance from two frames of the same scene: ``var(A - B) / 2``;
- spatial variance of the mean of L frames, corrected for the temporal
  variance left in it: ``s^2 = var(mean_L) - sigma_t^2 / L``;
- split of a spatial variance into column, row and pixel parts from the
  variances of column and row means (EMVA 1288 4.0, Sec. 8.3);
- PRNU = ``sqrt(s^2_bright - s^2_dark) / (mu_bright - mu_dark)``;
- quantization: 1/12 DN^2 is part of the temporal variance.
"""

from __future__ import annotations

import math

import numpy as np


def temporal_variance(a: np.ndarray, b: np.ndarray) -> float:
    """Temporal variance (DN^2) from two frames of the same scene: ``var(a - b) / 2``.

    The difference is taken in float64 (exact for integer frames), in one
    temporary array, with the variance in place. (Not ``np.dot``: BLAS's
    threads keep spinning after the call and slow the next frame's kernel.)
    """
    d = np.subtract(a, b, dtype=np.float64)
    d -= d.mean()
    np.square(d, out=d)
    return float(d.mean() / 2)


def temporal_variance_stack(stack: np.ndarray) -> float:
    """Temporal variance (DN^2): mean over pixels of the per-pixel variance over frames (ddof=1)."""
    return float(np.mean(np.var(stack.astype(np.float64), axis=0, ddof=1)))


def spatial_variances(stack: np.ndarray) -> dict[str, float]:
    """Spatial variance of the frame average (DN^2), total and its column, row and pixel parts.

    The part of the temporal noise that survives averaging L frames is
    removed (``sigma_t^2 / L``, from the pixel part, where it lives).
    """
    stack = stack.astype(np.float64)
    n_frames, rows, cols = stack.shape
    mean = stack.mean(axis=0)
    residual = temporal_variance_stack(stack) / n_frames if n_frames > 1 else 0.0
    total = float(np.var(mean, ddof=1))
    col_means = mean.mean(axis=0)
    row_means = mean.mean(axis=1)
    s_col = float(np.var(col_means, ddof=1))
    s_row = float(np.var(row_means, ddof=1))
    # E[total] = P + C + R, E[s_col] = C + P/rows, E[s_row] = R + P/cols  (P: pixel part)
    pixel = (total - s_col - s_row) / (1 - 1 / rows - 1 / cols)
    column = s_col - pixel / rows
    row = s_row - pixel / cols
    return {
        "total": total - residual,
        "column": column - residual / rows,
        "row": row - residual / cols,
        "pixel": pixel - residual,
        "mean": float(mean.mean()),
    }


def dsnu(dark_stack: np.ndarray) -> dict[str, float]:
    """DSNU (DN rms): total, column, row and pixel parts, from a stack of dark frames."""
    v = spatial_variances(dark_stack)
    return {k: math.sqrt(max(v[k], 0.0)) for k in ("total", "column", "row", "pixel")}


def prnu(bright_stack: np.ndarray, dark_stack: np.ndarray) -> float:
    """PRNU (fraction of the signal) from stacks of bright (~50 % saturation) and dark frames."""
    b = spatial_variances(bright_stack)
    d = spatial_variances(dark_stack)
    return math.sqrt(max(b["total"] - d["total"], 0.0)) / (b["mean"] - d["mean"])
