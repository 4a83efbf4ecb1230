"""sRGB's encoding, and the rectangle a region names: what the scenes and the charts share.

Examples
--------
>>> from cmosnoise.model import encoding
>>> round(float(encoding.srgb_to_linear(0.5)), 4), encoding.span((4, 6), None)
(0.214, (0, 4, 0, 6))
"""

from __future__ import annotations

import numpy as np

__all__ = ["srgb_to_linear", "linear_to_srgb", "span"]


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """Decode sRGB-encoded values in [0, 1] to linear light (IEC 61966-2-1).

    Parameters
    ----------
    v : array
        sRGB-encoded values, 0 to 1.

    Returns
    -------
    array
        Linear light, 0 to 1, ``v``'s shape.
    """
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(v: np.ndarray) -> np.ndarray:
    """Encode linear light in [0, 1] as sRGB in [0, 1].

    Parameters
    ----------
    v : array
        Linear light, 0 to 1.

    Returns
    -------
    array
        sRGB-encoded values, 0 to 1, ``v``'s shape.
    """
    v = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.0031308, v * 12.92, 1.055 * v ** (1 / 2.4) - 0.055)


def span(shape: tuple[int, int], region) -> tuple[int, int, int, int]:
    """``region`` (row0, row1, col0, col1) of a picture of ``shape``, or the whole of it.

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size.
    region : (row0, row1, col0, col1) or None
        A rectangle of it.

    Returns
    -------
    (row0, row1, col0, col1) of ints
    """
    return (0, shape[0], 0, shape[1]) if region is None else tuple(int(v) for v in region)
