"""A quick viewable picture of a raw frame: bilinear demosaic and sRGB gamma.

Scene white (a scene value of 1 at the peak rate, or the ADC's full scale if
lower) is display white, so the preview shows the scene at its exposure.
"""

from __future__ import annotations

import numpy as np

from . import cfa as cfa_mod
from .scene import linear_to_srgb


def demosaic_bilinear(plane: np.ndarray, pattern: str) -> np.ndarray:
    """Bilinear demosaic of a CFA plane (rows, cols) to RGB (rows, cols, 3)."""
    from colour_demosaicing import demosaicing_CFA_Bayer_bilinear

    return np.asarray(demosaicing_CFA_Bayer_bilinear(plane, pattern))


def to_8bit_srgb(linear: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] to 8-bit sRGB."""
    return np.round(linear_to_srgb(linear) * 255).astype(np.uint8)


def preview(raw: np.ndarray, pattern: str, black_level_dn: float, white_dn: float) -> np.ndarray:
    """8-bit sRGB picture of one raw frame; ``white_dn`` is the code shown as white.

    Returns (rows, cols, 3) uint8 for a colour sensor, (rows, cols) for mono.
    """
    lin = (raw.astype(np.float64) - black_level_dn) / max(white_dn - black_level_dn, 1e-9)
    if not cfa_mod.is_mono(pattern):
        lin = demosaic_bilinear(lin, pattern)
    return to_8bit_srgb(lin)
