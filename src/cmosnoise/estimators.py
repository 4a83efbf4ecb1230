"""Robust and interval estimators every layer uses: one place for each constant.

Base layer (no cmosnoise imports): defect correction (``isp``) and every
measurement and fit (``analysis``) read the same robust sigma and the same
95 % quantile.
"""

from __future__ import annotations

import numpy as np

#: the standard normal's 0.975 quantile: a two-sided 95 % interval is +- Z95 standard errors
Z95 = 1.959963984540054
#: the standard normal's 0.75 quantile: a normal law's median absolute deviation is this many sigma
NORMAL_MAD = 0.6744897501960817


def robust_centre(values: np.ndarray) -> tuple[float, float]:
    """(median, robust sigma) of the finite ``values``: sigma = median absolute deviation / NORMAL_MAD.

    The sigma of a normal law's sample, unmoved by a few outliers (white or
    dead pixels); scipy's ``median_abs_deviation(scale="normal")``, the same
    operations in the values' own precision (float32 stays float32).

    Parameters
    ----------
    values : ndarray, any shape
        NaN and infinite values are left out.
    """
    v = np.asarray(values)
    if not np.isfinite(v).all():
        v = v[np.isfinite(v)]
    med = np.median(v)
    return float(med), float(np.median(np.abs(v - med)) / NORMAL_MAD)


def robust_sigma(values: np.ndarray) -> float:
    """The robust sigma of :func:`robust_centre` alone."""
    return robust_centre(values)[1]


def snr(signal: float, noise: float) -> float:
    """A signal-to-noise ratio that stays defined without noise: ``signal / noise``, infinite for a positive signal
    without noise (every noise source switched off), 0 for none.

    Parameters
    ----------
    signal, noise : float
        The mean and the standard deviation, in one unit.

    Returns
    -------
    float
        ``inf`` where ``noise`` is 0 and ``signal`` above 0 (JSON writes it as null); 0 where ``signal`` is 0 or
        less.
    """
    signal, noise = float(signal), float(noise)
    if not signal > 0:
        return 0.0
    return signal / noise if noise > 0 else float("inf")
