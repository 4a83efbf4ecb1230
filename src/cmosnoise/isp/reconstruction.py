"""Colour reconstruction: demosaicing, crosstalk compensation, white balance, sRGB.

- Demosaicing with ``colour-demosaicing``: bilinear, Malvar et al. 2004, or
  Menon et al. 2007 (DDFAPD).
- Crosstalk colour mixing (MODEL.md section 5): the kernel and the CFA induce
  a 3 x 3 matrix M between the true and the measured R, G, B channel means
  (:func:`cmosnoise.crosstalk.channel_mixing_matrix`); its inverse is applied
  per pixel after demosaicing.
- White balance: per-channel gains, from the sensor's known responsivities,
  given, or grey world (the image's mean is grey).
- sRGB encoding and 8-bit output.
"""

from __future__ import annotations

import numpy as np

from ..model.scene import linear_to_srgb

DEMOSAIC_METHODS = ("bilinear", "malvar2004", "menon2007")


def demosaic(cfa_img: np.ndarray, pattern: str, method: str = "bilinear") -> np.ndarray:
    """CFA image (rows, cols) to RGB (rows, cols, 3), float32."""
    import colour_demosaicing as cd

    funcs = {
        "bilinear": cd.demosaicing_CFA_Bayer_bilinear,
        "malvar2004": cd.demosaicing_CFA_Bayer_Malvar2004,
        "menon2007": cd.demosaicing_CFA_Bayer_Menon2007,
    }
    if method not in funcs:
        raise ValueError(f"unknown demosaicing method {method!r}; use one of {DEMOSAIC_METHODS}")
    return np.asarray(funcs[method](cfa_img.astype(np.float64), pattern), dtype=np.float32)


def apply_matrix(rgb: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """Per-pixel ``matrix @ rgb``."""
    return np.einsum("ij,...j->...i", matrix.astype(np.float32), rgb, optimize=True)


def grey_world_gains(rgb: np.ndarray) -> np.ndarray:
    """Gains that make the image's mean grey (normalised to green)."""
    means = rgb.reshape(-1, 3).mean(axis=0)
    means = np.where(means > 0, means, 1.0)
    return (means[1] / means).astype(np.float32)


_LUT_SIZE = 65536
#: sRGB 8-bit code of linear values k / 65535
_SRGB8_LUT = np.round(linear_to_srgb(np.arange(_LUT_SIZE) / (_LUT_SIZE - 1)) * 255).astype(np.uint8)


def encode_srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear light (white = 1) to 8-bit sRGB, clipped to [0, 1].

    Through a 16-bit lookup table: the input step (1/65535) moves the output
    by at most 0.05 of a code, near black where the sRGB slope is steepest.
    """
    idx = np.clip(linear * np.float32(_LUT_SIZE - 1) + np.float32(0.5), 0, _LUT_SIZE - 1).astype(np.intp)
    return _SRGB8_LUT[idx]
