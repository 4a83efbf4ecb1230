"""Colour error: CIEDE2000 per ColorChecker patch after a 3 x 3 colour matrix fitted by least squares.

A camera's RGB (each patch's mean in each colour channel, linear, black subtracted) is mapped to linear sRGB by
the matrix ``M`` that minimises ``sum |M cam - ref|^2`` over the 24 patches (the reference: the ColorChecker's
sRGB values decoded, or a given table), then each patch is compared with its reference in CIELAB (sRGB's D65
white, colour-science's conversions) by CIEDE2000 (``colour.delta_E(..., method="CIE 2000")``). About 1 is one
just-noticeable difference for colour patches.

Examples
--------
>>> import numpy as np
>>> from cmosnoise.analysis import colour_error
>>> ref = colour_error.reference_linear_srgb()
>>> cam = ref @ np.array([[0.8, 0.1, 0.0], [0.1, 0.9, 0.1], [0.0, 0.2, 0.7]]).T   # a camera: a linear mix of sRGB
>>> r = colour_error.colour_error(cam, ref)
>>> round(r["mean_de2000"], 6), r["matrix"].shape
(0.0, (3, 3))
"""

from __future__ import annotations

import numpy as np

from ..errors import CmosnoiseError
from ..model import charts
from ..model.encoding import srgb_to_linear

__all__ = ["reference_linear_srgb", "fit_matrix", "ciede2000", "colour_error", "mosaic_patch_means"]


def reference_linear_srgb() -> np.ndarray:
    """The ColorChecker's 24 patches in linear sRGB (its published sRGB values decoded), row by row.

    Returns
    -------
    (24, 3) float64 array
    """
    return srgb_to_linear(charts.COLORCHECKER_SRGB8 / 255.0)


def fit_matrix(camera: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The 3 x 3 matrix M minimising ``sum |M camera_i - reference_i|^2`` (least squares).

    Parameters
    ----------
    camera : (n, 3) array
        The patches' camera RGB, linear.
    reference : (n, 3) array
        Their linear sRGB.

    Returns
    -------
    (3, 3) float64 array
        ``reference ~ camera @ M.T``.
    """
    cam, ref = np.asarray(camera, float), np.asarray(reference, float)
    if cam.shape != ref.shape or cam.ndim != 2 or cam.shape[1] != 3 or cam.shape[0] < 3:
        raise CmosnoiseError(f"colour error: give (n, 3) camera and reference values, n >= 3; got {cam.shape} and "
                             f"{ref.shape}")
    if not (np.isfinite(cam).all() and np.isfinite(ref).all()):
        raise CmosnoiseError("colour error: the patch values must be finite")
    solution, *_ = np.linalg.lstsq(cam, ref, rcond=None)
    return solution.T


def ciede2000(linear_srgb: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """CIEDE2000 between linear sRGB values and their references, through CIELAB under D65.

    Parameters
    ----------
    linear_srgb, reference : (n, 3) arrays
        Linear sRGB (1: white).

    Returns
    -------
    (n,) float64 array
    """
    from .. import colour_lib

    colour = colour_lib.colour()

    def lab(x):
        return colour.XYZ_to_Lab(colour.RGB_to_XYZ(np.asarray(x, float), colour.RGB_COLOURSPACES["sRGB"],
                                                   apply_cctf_decoding=False))

    return np.asarray(colour.delta_E(lab(linear_srgb), lab(reference), method="CIE 2000"), float)


def colour_error(camera: np.ndarray, reference: np.ndarray | None = None) -> dict:
    """CIEDE2000 per patch after the least-squares colour matrix (see the module docstring).

    Parameters
    ----------
    camera : (24, 3) array
        The patches' camera RGB means, linear (:func:`mosaic_patch_means`), any scale: the matrix absorbs it.
    reference : (24, 3) array, optional
        Their linear sRGB; default: :func:`reference_linear_srgb`.

    Returns
    -------
    dict
        ``de2000`` (24,) per patch, ``mean_de2000``, ``max_de2000``, ``matrix`` (3, 3), ``corrected`` (24, 3):
        the camera's values through the matrix.
    """
    ref = reference_linear_srgb() if reference is None else np.asarray(reference, float)
    m = fit_matrix(camera, ref)
    corrected = np.asarray(camera, float) @ m.T
    de = ciede2000(np.clip(corrected, 0, None), ref)
    return {"de2000": de, "mean_de2000": float(de.mean()), "max_de2000": float(de.max()), "matrix": m,
            "corrected": corrected}


def mosaic_patch_means(raw: np.ndarray, pattern: str, patches, black: float = 0.0) -> np.ndarray:
    """Each patch's mean in each colour channel of a raw mosaic, black subtracted: a camera's RGB without
    demosaicing.

    Parameters
    ----------
    raw : (rows, cols) array
        A raw frame (DN or e-).
    pattern : str
        Its CFA pattern (RGGB, BGGR, GRBG, GBRG).
    patches : list of (row0, row1, col0, col1) or (slice, slice)
        The patches (:func:`cmosnoise.model.charts.truth`).
    black : float
        The black level to subtract.

    Returns
    -------
    (n, 3) float64 array
    """
    from ..model import cfa as cfa_mod

    a = np.asarray(raw, float) - black
    channels = cfa_mod.channel_map(pattern, a.shape)
    rows, cols = a.shape
    out = []
    for p in patches:
        r, c = (p if isinstance(p[0], slice) else (slice(p[0], p[1]), slice(p[2], p[3])))
        if not (0 <= (r.start or 0) < (r.stop or rows) <= rows and 0 <= (c.start or 0) < (c.stop or cols) <= cols):
            raise CmosnoiseError(f"colour error: a patch ({r.start}:{r.stop}, {c.start}:{c.stop}) is outside the "
                                 f"{rows} x {cols} image")
        block, ch = a[r, c], channels[r, c]
        out.append([block[ch == k].mean() for k in range(3)])
    return np.asarray(out)
