"""Colour conversions of whole pictures, compiled: what a colour visual-noise metric does to every pixel.

:mod:`cmosnoise.analysis.visual_noise` filters a picture's opponent channels by FFTs and then needs, per pixel, a
3 x 3 matrix to XYZ (and negatives set to 0, ISO 15739's step), a chromatic adaptation, CIELUV or CIELAB
(CIE 15:2004), and only the means, variances and one covariance of the result. In NumPy that is some thirty passes
over the picture with a temporary each (2 s for 12 MP on 2 cores); here it is one pass that keeps each row's sums
(float64) and adds no array. The rows' sums are added in row order afterwards, so the figures do not depend on the
number of threads.

:func:`mix` is the picture's linear RGB times a 3 x 3 matrix, each output channel a plane (float32).
"""

from __future__ import annotations

import numpy as np

from .jit import ONE_LAUNCH, compiled, numba  # None where numba is not installed

#: the CIE 1976 spaces :func:`moments` computes
LUV, LAB = 0, 1
_E = (6.0 / 29.0) ** 3

if numba is not None:
    @numba.njit(cache=True, nogil=True, inline="always")
    def _f(t):  # pragma: no cover - compiled
        if t > _E:  # the cube root: single precision's (twice as fast as double's), one Newton step to double's
            y = np.float64(np.float32(t) ** np.float32(1.0 / 3.0))
            return y - (y * y * y - t) / (3.0 * y * y)
        return t * ((29.0 / 6.0) ** 2 / 3.0) + 4.0 / 29.0

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _moments(planes, first, clip, second, white, space, sums):  # pragma: no cover - compiled
        rows, cols = planes.shape[1], planes.shape[2]
        wx, wy, wz = white[0], white[1], white[2]
        dn = wx + 15.0 * wy + 3.0 * wz
        un, vn = 4.0 * wx / dn, 9.0 * wy / dn
        for i in numba.prange(rows):
            acc = np.zeros(9)
            for j in range(cols):
                p0, p1, p2 = np.float64(planes[0, i, j]), np.float64(planes[1, i, j]), np.float64(planes[2, i, j])
                a0 = first[0, 0] * p0 + first[0, 1] * p1 + first[0, 2] * p2
                a1 = first[1, 0] * p0 + first[1, 1] * p1 + first[1, 2] * p2
                a2 = first[2, 0] * p0 + first[2, 1] * p1 + first[2, 2] * p2
                if clip:
                    a0, a1, a2 = max(a0, 0.0), max(a1, 0.0), max(a2, 0.0)
                x = second[0, 0] * a0 + second[0, 1] * a1 + second[0, 2] * a2
                y = second[1, 0] * a0 + second[1, 1] * a1 + second[1, 2] * a2
                z = second[2, 0] * a0 + second[2, 1] * a1 + second[2, 2] * a2
                fy = _f(y / wy)
                lum = 116.0 * fy - 16.0
                if space == 0:  # CIELUV; a black pixel's u', v' the white's
                    d = x + 15.0 * y + 3.0 * z
                    if d > 0.0:
                        c1 = 13.0 * lum * (4.0 * x / d - un)
                        c2 = 13.0 * lum * (9.0 * y / d - vn)
                    else:
                        c1 = 0.0
                        c2 = 0.0
                else:
                    c1 = 500.0 * (_f(x / wx) - fy)
                    c2 = 200.0 * (fy - _f(z / wz))
                acc[0] += lum
                acc[1] += c1
                acc[2] += c2
                acc[3] += lum * lum
                acc[4] += c1 * c1
                acc[5] += c2 * c2
                acc[6] += lum * c1
                acc[7] += lum * c2
                acc[8] += c1 * c2
            for k in range(9):
                sums[i, k] = acc[k]

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _mix(rgb, m, out):  # pragma: no cover - compiled
        rows, cols = rgb.shape[0], rgb.shape[1]
        for i in numba.prange(rows):
            for j in range(cols):
                r, g, b = np.float64(rgb[i, j, 0]), np.float64(rgb[i, j, 1]), np.float64(rgb[i, j, 2])
                for c in range(3):
                    out[c, i, j] = m[c, 0] * r + m[c, 1] * g + m[c, 2] * b


def _f_numpy(t: np.ndarray) -> np.ndarray:
    return np.where(t > _E, np.cbrt(t), t * ((29.0 / 6.0) ** 2 / 3.0) + 4.0 / 29.0)


def _moments_numpy(planes, first, clip, second, white, space) -> np.ndarray:
    """:func:`moments`'s sums by NumPy, the whole picture at once (small pictures, or nothing compiled yet)."""
    p = planes.astype(np.float64).reshape(3, -1)
    a = first @ p
    if clip:
        a = np.maximum(a, 0.0)
    x, y, z = second @ a
    fy = _f_numpy(y / white[1])
    lum = 116.0 * fy - 16.0
    if space == LUV:
        d = x + 15.0 * y + 3.0 * z
        dn = white[0] + 15.0 * white[1] + 3.0 * white[2]
        ok = d > 0.0
        safe = np.where(ok, d, 1.0)
        c1 = np.where(ok, 13.0 * lum * (4.0 * x / safe - 4.0 * white[0] / dn), 0.0)
        c2 = np.where(ok, 13.0 * lum * (9.0 * y / safe - 9.0 * white[1] / dn), 0.0)
    else:
        c1 = 500.0 * (_f_numpy(x / white[0]) - fy)
        c2 = 200.0 * (fy - _f_numpy(z / white[2]))
    return np.array([lum.sum(), c1.sum(), c2.sum(), (lum * lum).sum(), (c1 * c1).sum(), (c2 * c2).sum(),
                     (lum * c1).sum(), (lum * c2).sum(), (c1 * c2).sum()])


def moments(planes: np.ndarray, first: np.ndarray, clip: bool, second: np.ndarray, white: np.ndarray,
            space: int) -> dict:
    """The means, variances and covariances of a picture's CIE 1976 coordinates.

    Each pixel's three planes' values ``p`` become ``a = first p`` (negatives 0 where ``clip``), XYZ
    ``second a``, then CIELUV or CIELAB against ``white`` (CIE 15:2004: ``f`` the cube root, linear below
    ``(6/29)^3``; a black pixel's u', v' the white's).

    Parameters
    ----------
    planes : (3, rows, cols) float32 or float64 array
    first, second : (3, 3) arrays
    clip : bool
    white : (3,) array
        XYZ of the white (its Y the picture's white, 1).
    space : {LUV, LAB}

    Returns
    -------
    dict
        ``mean`` (3,), ``var`` (3,) and ``cov`` (the (0, 1), (0, 2) and (1, 2) covariances), population moments.
    """
    first, second = np.ascontiguousarray(first, np.float64), np.ascontiguousarray(second, np.float64)
    white = np.ascontiguousarray(white, np.float64)
    n = planes.shape[1] * planes.shape[2]
    if numba is None or n < 1 << 14 or not compiled("the colour metrics' conversions", _moments, _mix):
        s = _moments_numpy(planes, first, clip, second, white, space)
    else:
        rows = np.empty((planes.shape[1], 9))
        with ONE_LAUNCH:
            _moments(np.ascontiguousarray(planes), first, bool(clip), second, white, int(space), rows)
        s = rows.sum(axis=0)
    mean = s[:3] / n
    var = np.maximum(s[3:6] / n - mean**2, 0.0)
    cov = s[6:9] / n - np.array([mean[0] * mean[1], mean[0] * mean[2], mean[1] * mean[2]])
    return {"mean": mean, "var": var, "cov": cov}


def mix(rgb: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """A picture's three channels through a 3 x 3 matrix, as planes: ``out[c] = sum_k matrix[c, k] rgb[..., k]``.

    Parameters
    ----------
    rgb : (rows, cols, 3) array
    matrix : (3, 3) array

    Returns
    -------
    (3, rows, cols) float32 array
    """
    m = np.ascontiguousarray(matrix, np.float64)
    out = np.empty((3, rgb.shape[0], rgb.shape[1]), np.float32)
    if numba is None or rgb.shape[0] * rgb.shape[1] < 1 << 14 or not compiled("the colour metrics' conversions",
                                                                              _moments, _mix):
        for c in range(3):
            out[c] = rgb[..., 0] * m[c, 0] + rgb[..., 1] * m[c, 1] + rgb[..., 2] * m[c, 2]
        return out
    with ONE_LAUNCH:
        _mix(np.ascontiguousarray(rgb), m, out)
    return out


__all__ = ["moments", "mix", "LUV", "LAB"]
