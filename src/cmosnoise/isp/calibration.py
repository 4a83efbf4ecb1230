"""Black level and dark calibration (docs/model.md section 5).

Dark calibration subtracts a **master dark**: the mean of n dark frames taken
by the same sensor instance at the same temperature and exposure. It removes
the fixed dark pattern (DCNU, VFPN, fixed row offsets), not the dark shot
noise of the frame at hand, and it cannot restore a white pixel that has
saturated (the scene's charge is gone).

Examples
--------
>>> import numpy as np
>>> from cmosnoise import calibration
>>> dark = np.full((3, 4, 6), 70.0)            # three dark frames, DN
>>> calibration.master_dark(dark).shape
(4, 6)
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np


def subtract_black(raw: np.ndarray, black_level_dn: float) -> np.ndarray:
    """Raw codes to signal above black.

    Parameters
    ----------
    raw : array, DN
        Raw codes.
    black_level_dn : float
        The black level, DN.

    Returns
    -------
    float32 array, DN, ``raw``'s shape
        May be negative (noise around black).
    """
    return raw.astype(np.float32) - np.float32(black_level_dn)


def master_dark(frames: Iterable[np.ndarray]) -> np.ndarray:
    """Mean of dark frames, accumulated one frame at a time.

    Parameters
    ----------
    frames : iterable of (rows, cols) arrays, DN
        Dark frames (raw codes, black level included).

    Returns
    -------
    (rows, cols) float32 array, DN
        The master dark, black level included.
    """
    total = None
    n = 0
    for f in frames:
        total = f.astype(np.float64) if total is None else total + f
        n += 1
    if n == 0:
        raise ValueError("a master dark needs at least one dark frame")
    return (total / n).astype(np.float32)


def subtract_dark(signal_dn: np.ndarray, master_dark_dn: np.ndarray, black_level_dn: float) -> np.ndarray:
    """Signal above black minus the master dark's signal above black.

    Parameters
    ----------
    signal_dn : (rows, cols) array, DN
        A frame's signal above black (:func:`subtract_black`).
    master_dark_dn : (rows, cols) array, DN
        The master dark, black level included (:func:`master_dark`).
    black_level_dn : float
        The black level, DN.

    Returns
    -------
    (rows, cols) array, DN
    """
    return signal_dn - (master_dark_dn - np.float32(black_level_dn))
