"""Colour reconstruction: demosaicing, crosstalk compensation, white balance, sRGB.

- Demosaicing: Malvar et al. 2004 and Menon et al. 2007 (DDFAPD) with
  ``colour-demosaicing``; bilinear by the same two 3 x 3 convolutions as
  ``colour-demosaicing``'s (a test checks they agree), written here because
  importing ``colour-demosaicing`` takes about a second (it imports
  ``colour`` and matplotlib), longer than a whole quick-look preview.
- Crosstalk colour mixing (docs/model.md section 5): the kernel and the CFA induce
  a 3 x 3 matrix M between the true and the measured R, G, B channel means
  (:func:`cmosnoise.crosstalk.channel_mixing_matrix`); its inverse is applied
  per pixel after demosaicing.
- White balance: per-channel gains, from the sensor's known responsivities,
  given, or grey world (the image's mean is grey).
- sRGB encoding and 8-bit output.

Examples
--------
>>> import numpy as np
>>> from cmosnoise import reconstruction
>>> reconstruction.demosaic(np.ones((4, 6)), "RGGB").shape   # a CFA image to RGB
(4, 6, 3)
"""

from __future__ import annotations

import numpy as np

from ..model import cfa as cfa_mod
from ..model.scene import linear_to_srgb

DEMOSAIC_METHODS = ("bilinear", "malvar2004", "menon2007")


#: the CFA is extended by this many pixels on each side before demosaicing (even: the pattern's phase is kept)
EDGE_PAD = 4


def demosaic(cfa_img: np.ndarray, pattern: str, method: str = "bilinear") -> np.ndarray:
    """CFA image (rows, cols) to RGB (rows, cols, 3), float32.

    The mosaic is first extended by mirroring (``numpy.pad(mode="reflect")``
    by an even number of pixels keeps every pixel's colour), so border pixels
    are interpolated from real neighbours of their own colour: without it
    the methods' own edge handling leaves a one-pixel colour fringe.

    Parameters
    ----------
    cfa_img : (rows, cols) array
        A CFA image (signal, any unit).
    pattern : str
        RGGB, BGGR, GRBG or GBRG.
    method : str
        One of :data:`DEMOSAIC_METHODS`: bilinear, malvar2004 or menon2007 (the last two by ``colour-demosaicing``).

    Returns
    -------
    (rows, cols, 3) float32 array
    """
    if method not in DEMOSAIC_METHODS:
        raise ValueError(f"unknown demosaicing method {method!r}; use one of {DEMOSAIC_METHODS}")
    img = np.asarray(cfa_img)
    p = EDGE_PAD if min(img.shape) > EDGE_PAD else 0
    padded = np.pad(img, p, mode="reflect") if p else img
    if method == "bilinear":
        rgb = bilinear(padded, pattern)
    else:
        from .. import colour_lib

        cd = colour_lib.colour_demosaicing()
        func = {"malvar2004": cd.demosaicing_CFA_Bayer_Malvar2004, "menon2007": cd.demosaicing_CFA_Bayer_Menon2007}[method]
        rgb = np.asarray(func(padded.astype(np.float64), pattern), dtype=np.float32)
    return np.ascontiguousarray(rgb[p:p + img.shape[0], p:p + img.shape[1]]) if p else rgb


_H_G = np.array([[0, 1, 0], [1, 4, 1], [0, 1, 0]]) / 4
_H_RB = np.array([[1, 2, 1], [2, 4, 2], [1, 2, 1]]) / 4


def bilinear(cfa_img: np.ndarray, pattern: str) -> np.ndarray:
    """Bilinear demosaicing, (rows, cols) -> (rows, cols, 3) float32: each channel's samples, convolved.

    The kernels and edge mode (``reflect``) of ``colour-demosaicing``'s
    ``demosaicing_CFA_Bayer_bilinear``.

    Parameters
    ----------
    cfa_img : (rows, cols) array
        A CFA image (signal, any unit).
    pattern : str
        RGGB, BGGR, GRBG or GBRG.

    Returns
    -------
    (rows, cols, 3) float32 array
    """
    from scipy.ndimage import convolve

    img = np.asarray(cfa_img, dtype=np.float64)
    cmap = cfa_mod.channel_map(pattern, img.shape)
    out = np.empty((*img.shape, 3), np.float32)
    for ch, kern in ((0, _H_RB), (1, _H_G), (2, _H_RB)):
        out[..., ch] = convolve(np.where(cmap == ch, img, 0.0), kern)
    return out


def superpixel(cfa_img: np.ndarray, pattern: str) -> np.ndarray:
    """Half-resolution demosaicing: each 2 x 2 CFA cell becomes one RGB pixel (R, the mean of the two G, B).

    (rows, cols) -> (rows // 2, cols // 2, 3) float32; a trailing odd row or
    column is dropped. For previews at half size or less: exact colours,
    no interpolation, four times fewer pixels to process.

    Parameters
    ----------
    cfa_img : (rows, cols) array
        A CFA image (signal, any unit).
    pattern : str
        RGGB, BGGR, GRBG or GBRG.

    Returns
    -------
    (rows // 2, cols // 2, 3) float32 array
    """
    img = np.asarray(cfa_img, dtype=np.float32)
    rows, cols = img.shape[0] // 2 * 2, img.shape[1] // 2 * 2
    cell = cfa_mod.tile(pattern)
    out = np.zeros((rows // 2, cols // 2, 3), np.float32)
    for dr in (0, 1):
        for dc in (0, 1):
            ch = int(cell[dr, dc])
            part = img[dr:rows:2, dc:cols:2]
            out[..., ch] += part * np.float32(0.5 if ch == 1 else 1.0)
    return out


def apply_matrix(rgb: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """Per-pixel ``matrix @ rgb``: (..., 3) float32 -> (..., 3) float32.

    Element-wise, not through BLAS: a BLAS call leaves its threads spinning
    for a while afterwards, and on a small machine they take the cores the
    next frame's kernel needs (it ran at half speed after each picture).

    Parameters
    ----------
    rgb : (..., 3) float32 array
        Linear RGB.
    matrix : (3, 3) array
        Applied to each pixel's RGB vector.

    Returns
    -------
    (..., 3) float32 array
    """
    m = np.asarray(matrix, np.float32)
    rgb = np.asarray(rgb, np.float32)
    out = np.empty(rgb.shape[:-1] + (3,), np.float32)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    for i in range(3):
        out[..., i] = m[i, 0] * r + m[i, 1] * g + m[i, 2] * b
    return out


def grey_world_gains(rgb: np.ndarray) -> np.ndarray:
    """Gains that make the image's mean grey (normalised to green).

    Parameters
    ----------
    rgb : (..., 3) array
        Linear RGB.

    Returns
    -------
    (3,) float32 array
        The R, G and B gains: green's mean over each channel's (G's gain is 1).
    """
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

    Parameters
    ----------
    linear : array
        Linear light, white = 1.

    Returns
    -------
    uint8 array, ``linear``'s shape
        sRGB codes.
    """
    idx = np.clip(np.nan_to_num(linear * np.float32(_LUT_SIZE - 1) + np.float32(0.5), nan=0.0), 0,
                  _LUT_SIZE - 1).astype(np.intp)  # NaN (an overflow of huge codes) to 0, as the compiled pass
    return _SRGB8_LUT[idx]


# ------------------------------------------------------------------ pictures in one pass
from ..engine.jit import ONE_LAUNCH, announce, compiled, numba  # noqa: E402 - numba is None where it is not installed; the section's own import

#: whether :func:`superpixel_srgb8` and :func:`bilinear_srgb8` can run here (without numba, Processor takes the
#: steps one by one)
COMPILED = numba is not None
#: how the compile message names the one-pass picture loops
_PICTURE_LOOPS = "the pictures' demosaicing to sRGB"


def one_pass_ready() -> bool:
    """Whether :func:`superpixel_srgb8` and :func:`bilinear_srgb8` run now: numba installed and the loops in memory
    or numba's cache, or compiled here (:func:`cmosnoise.engine.jit.compiled`; False while a background compile
    builds them, and Processor takes the steps one by one, the same bits).

    Returns
    -------
    bool
    """
    return COMPILED and compiled(_PICTURE_LOOPS, _bilinear_srgb8, _superpixel_srgb8)

if numba is not None:
    @numba.njit(inline="always", fastmath=False, error_model="numpy")
    def _encode_pixel(px, out, r, c, matrix, has_matrix, gains, lut):  # pragma: no cover - compiled
        # one linear RGB pixel (float32) through the compensation matrix, the gains and the sRGB table, in
        # apply_matrix's and encode_srgb8's order of operations
        half = np.float32(0.5)
        top = np.float32(lut.size - 1)
        r_, g_, b_ = px[0], px[1], px[2]
        for i in range(3):
            y = matrix[i, 0] * r_ + matrix[i, 1] * g_ + matrix[i, 2] * b_ if has_matrix else px[i]
            y = y * gains[i] * top + half
            if not y >= np.float32(0.0):  # NaN too (an overflow of huge codes): never an index outside the table
                y = np.float32(0.0)
            elif y > top:
                y = top
            out[r, c, i] = lut[np.intp(y)]

    @numba.njit(parallel=True, cache=True, nogil=True, fastmath=False, error_model="numpy")
    def _superpixel_srgb8(img, cell, offset, white, matrix, has_matrix, gains, lut):  # pragma: no cover - compiled
        # float32 throughout, in the reference's order of operations: the same bits
        rows, cols = img.shape[0] // 2, img.shape[1] // 2
        out = np.empty((rows, cols, 3), np.uint8)
        half = np.float32(0.5)
        for r in numba.prange(rows):
            px = np.zeros(3, np.float32)
            for c in range(cols):
                px[0] = np.float32(0.0)
                px[1] = np.float32(0.0)
                px[2] = np.float32(0.0)
                for dr in range(2):
                    for dc in range(2):
                        ch = cell[dr, dc]
                        v = (np.float32(img[2 * r + dr, 2 * c + dc]) - offset) / white
                        px[ch] += v * half if ch == 1 else v
                _encode_pixel(px, out, r, c, matrix, has_matrix, gains, lut)
        return out


if numba is not None:
    @numba.njit(inline="always")
    def _reflect(i, n):  # pragma: no cover - compiled
        # numpy.pad(mode="reflect") of an index one step outside 0 .. n - 1
        return 1 if i < 0 else (n - 2 if i >= n else i)

    @numba.njit(parallel=True, cache=True, nogil=True, fastmath=False, error_model="numpy")
    def _bilinear_srgb8(img, cell, offset, white, matrix, has_matrix, gains, lut):  # pragma: no cover - compiled
        # the reference's operations in its order: float32 scaling, each channel's 3 x 3 convolution summed in
        # float64 over the kernel's non-zero taps in row-major order from 0.0 (scipy.ndimage's loop), rounded
        # to float32, then the float32 matrix, gains and table
        rows, cols = img.shape
        out = np.empty((rows, cols, 3), np.uint8)
        w_g = np.array([[0.0, 0.25, 0.0], [0.25, 1.0, 0.25], [0.0, 0.25, 0.0]])
        w_rb = np.array([[0.25, 0.5, 0.25], [0.5, 1.0, 0.5], [0.25, 0.5, 0.25]])
        for r in numba.prange(rows):
            px = np.zeros(3, np.float32)
            for c in range(cols):
                for ch in range(3):
                    acc = 0.0
                    for dr in range(3):
                        rr = _reflect(r + dr - 1, rows)
                        for dc in range(3):
                            w = w_g[dr, dc] if ch == 1 else w_rb[dr, dc]
                            if w != 0.0:
                                cc = _reflect(c + dc - 1, cols)
                                if cell[rr % 2, cc % 2] == ch:
                                    x = (np.float32(img[rr, cc]) - offset) / white
                                    acc += np.float64(x) * w
                    px[ch] = np.float32(acc)
                _encode_pixel(px, out, r, c, matrix, has_matrix, gains, lut)
        return out


def bilinear_srgb8(cfa_img: np.ndarray, pattern: str, offset: float, white: float,
                   matrix: np.ndarray | None, gains: np.ndarray) -> np.ndarray:
    """A CFA image to an 8-bit full-size sRGB picture in one compiled pass, (rows, cols) -> (rows, cols, 3).

    ``(cfa_img - offset) / white``, :func:`demosaic` (bilinear, the mosaic
    mirrored at its edges), ``matrix`` (or None), the white-balance
    ``gains`` and :func:`encode_srgb8`, with the bits of those steps taken
    one by one (a test holds them equal), several times faster: it is every
    run's ``preview.png``. Bayer patterns larger than 4 x 4; needs numba
    (:data:`COMPILED`).

    Parameters
    ----------
    cfa_img : (rows, cols) array
        A CFA image (signal, any unit) DN.
    pattern : str
        RGGB, BGGR, GRBG or GBRG.
    offset : float
        Subtracted first: the black level, DN (0 for an image already above black).
    white : float
        The signal of scene white above black, DN.
    matrix : (3, 3) array or None
        Crosstalk compensation.
    gains : (3,) array
        The white-balance gains of R, G and B.

    Returns
    -------
    (rows, cols, 3) uint8 array
        sRGB.
    """
    if numba is None:  # pragma: no cover
        raise RuntimeError("numba is not installed: take the steps one by one (Processor does so by itself)")
    img = np.asarray(cfa_img)
    if min(img.shape) <= EDGE_PAD:
        raise ValueError(f"a {img.shape[0]} x {img.shape[1]} mosaic is too small for the one-pass picture")
    if img.dtype not in (np.uint16, np.float32):
        img = img.astype(np.float32)
    m = np.eye(3, dtype=np.float32) if matrix is None else np.asarray(matrix, np.float32)
    announce(_PICTURE_LOOPS, _bilinear_srgb8, _superpixel_srgb8)
    with ONE_LAUNCH:
        return _bilinear_srgb8(img, cfa_mod.tile(pattern), np.float32(offset), np.float32(white), m,
                               matrix is not None, np.asarray(gains, np.float32), _SRGB8_LUT)


def superpixel_srgb8(cfa_img: np.ndarray, pattern: str, offset: float, white: float,
                     matrix: np.ndarray | None, gains: np.ndarray) -> np.ndarray:
    """A CFA image to an 8-bit half-size sRGB picture in one compiled pass, (rows, cols) -> (rows // 2, cols // 2, 3).

    ``(cfa_img - offset) / white`` (offset: the black level in DN, or 0 for
    an image already above black; white: the DN of scene white above
    black), :func:`superpixel`, ``matrix`` (crosstalk compensation, or
    None), the white-balance ``gains`` and :func:`encode_srgb8`: the bits of
    those steps taken one by one (a test holds them equal), about ten times
    faster at 1920 x 1080 (it is the explore page's picture after every
    slider move). Needs numba (:data:`COMPILED`).

    Parameters
    ----------
    cfa_img : (rows, cols) array
        A CFA image (signal, any unit) DN.
    pattern : str
        RGGB, BGGR, GRBG or GBRG.
    offset : float
        Subtracted first: the black level, DN (0 for an image already above black).
    white : float
        The signal of scene white above black, DN.
    matrix : (3, 3) array or None
        Crosstalk compensation.
    gains : (3,) array
        The white-balance gains of R, G and B.

    Returns
    -------
    (rows // 2, cols // 2, 3) uint8 array
        sRGB.
    """
    if numba is None:  # pragma: no cover
        raise RuntimeError("numba is not installed: take the steps one by one (Processor does so by itself)")
    img = np.asarray(cfa_img)
    if img.dtype not in (np.uint16, np.float32):
        img = img.astype(np.float32)
    m = np.eye(3, dtype=np.float32) if matrix is None else np.asarray(matrix, np.float32)
    announce(_PICTURE_LOOPS, _bilinear_srgb8, _superpixel_srgb8)
    with ONE_LAUNCH:
        return _superpixel_srgb8(img, cfa_mod.tile(pattern), np.float32(offset), np.float32(white), m,
                                 matrix is not None, np.asarray(gains, np.float32), _SRGB8_LUT)
