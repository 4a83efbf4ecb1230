"""A small kernel's direct convolution of a picture's channels, made at each pixel's own channel only: the lens's
point spread function in front of a colour filter array.

A Bayer pixel sees one channel, so of the three blurred channels only that one is needed there: a third of the
work of blurring the picture (a quarter for red and blue, a half for green). :func:`mosaic` computes, for each
pixel ``(i, j)`` of a region, with ``c = cells[i % 2, j % 2]``::

    out[i, j] = gain[c] * max(sum over (u, v) of kernels[c, u, v] * x_c[i + m - u, j + m - v], 0)

``x_c`` the channel's picture, its edge pixels repeated beyond the sensor, ``m`` the kernel's radius. The
products and sums follow one fixed order, whatever the region: the flipped kernel's columns ``v`` in turn, down
each its rows ``u`` four at a time, the four products added in single precision as ``(p0 + p1) + (p2 + p3)`` and
that sum added to the pixel's double-precision total, started at 0.0 (a last one to three rows one at a time).
So a tile's pixels are the whole frame's, bit for bit, and the compiled loop and the NumPy specification
(:func:`mosaic_numpy`, which runs while a background compile builds the loop) give the same bits. The rounding:
every term is non-negative (a PSF and a picture are) and carries at most five float32 roundings (the picture's
value, the weight, their product, the group's two additions), the total in float64: each value within ``5u`` of
the exact convolution, relative to itself, ``u = 6e-8``.

The planes come in the layout the loop reads along its vectors (:func:`layout_indices`): channels first,
transposed (a column of the picture is a row in memory), and the rows of the region's window (the region and a
margin of ``m`` on each side) in two halves, the window's even rows then its odd rows, so that the pixels of one
CFA row phase and one kernel row are consecutive in memory. On the development machine (2 AVX-512 cores) the
blur of a 12 MP picture through the CFA, its planes drawn included, took 0.13 s with an 11 x 11 kernel, 0.19 s
with 19 x 19, 0.26 s with 25 x 25 and 0.37 s with 31 x 31; by FFT blocks 0.29 to 0.34 s. Beyond
:data:`MAX_SIDE` pixels across, :mod:`cmosnoise.model.optics` takes the FFT.
"""

from __future__ import annotations

import numpy as np

from .jit import ONE_LAUNCH, compiled, numba  # None where numba is not installed

#: the widest kernel convolved directly, pixels across: the direct work grows as the kernel's area, an FFT's does
#: not, and they cross between 25 and 31 (the module's timings)
MAX_SIDE = 25
#: output columns each parallel task makes (its totals stay in the core's cache; each pixel row is then written
#: as one stretch of this many values)
_COLUMNS = 16

if numba is not None:
    @numba.njit(parallel=True, cache=True, nogil=True)
    def _mosaic(planes, half, kf, cells, gain, out):  # pragma: no cover - compiled
        rows, cols = out.shape
        k = kf.shape[1]
        n0 = (rows + 1) // 2  # the region's even rows
        for blk in numba.prange((cols + _COLUMNS - 1) // _COLUMNS):
            j0 = blk * _COLUMNS
            j1 = min(j0 + _COLUMNS, cols)
            acc = np.empty((_COLUMNS, 2, n0))
            for jj in range(j1 - j0):
                j = j0 + jj
                for a in range(2):  # the row phase: rows i = 2 t + a
                    n = (rows - a + 1) // 2
                    c = cells[a, j & 1]
                    dst = acc[jj, a]
                    for t in range(n):
                        dst[t] = 0.0
                    for v in range(k):
                        line = planes[c, j + v]  # the window's column j + v, its rows in halves
                        u = 0
                        while u + 4 <= k:
                            w0, w1, w2, w3 = kf[c, u, v], kf[c, u + 1, v], kf[c, u + 2, v], kf[c, u + 3, v]
                            # window row 2 t + a + u: its half's row t + (a + u) // 2
                            o0 = ((a + u) & 1) * half + ((a + u) >> 1)
                            o1 = ((a + u + 1) & 1) * half + ((a + u + 1) >> 1)
                            o2 = ((a + u + 2) & 1) * half + ((a + u + 2) >> 1)
                            o3 = ((a + u + 3) & 1) * half + ((a + u + 3) >> 1)
                            s0, s1, s2, s3 = line[o0:o0 + n], line[o1:o1 + n], line[o2:o2 + n], line[o3:o3 + n]
                            for t in range(n):
                                dst[t] += np.float64((w0 * s0[t] + w1 * s1[t]) + (w2 * s2[t] + w3 * s3[t]))
                            u += 4
                        while u < k:
                            w = kf[c, u, v]
                            o = ((a + u) & 1) * half + ((a + u) >> 1)
                            s = line[o:o + n]
                            for t in range(n):
                                dst[t] += np.float64(w * s[t])
                            u += 1
            for i in range(rows):
                a, t = i & 1, i >> 1
                for jj in range(j1 - j0):
                    j = j0 + jj
                    x = acc[jj, a, t]
                    if not x > 0.0:  # at least 0, NaN as 0
                        x = 0.0
                    out[i, j] = gain[cells[a, j & 1]] * x


def layout_indices(start: int, stop: int, size: int, radius: int, halves: bool) -> np.ndarray:
    """The picture's rows (or columns) a region's window reads, in the order :func:`mosaic` takes them.

    Parameters
    ----------
    start, stop : int
        The region's rows ``start:stop`` (sensor coordinates).
    size : int
        The sensor's rows; a window's rows beyond it are its edge rows, repeated.
    radius : int
        m, the kernel's radius: the window is ``start - m:stop + m``.
    halves : bool
        True for the rows (the window's even rows, then its odd ones), False for the columns (in order).

    Returns
    -------
    (stop - start + 2 m,) int64 array

    Examples
    --------
    >>> from cmosnoise.engine.convolve import layout_indices
    >>> layout_indices(0, 4, 4, 1, True)
    array([0, 1, 3, 0, 2, 3])
    """
    idx = np.clip(np.arange(start - radius, stop + radius), 0, size - 1)
    return np.concatenate([idx[0::2], idx[1::2]]) if halves else idx


def _flipped(kernels: np.ndarray) -> np.ndarray:
    """The kernels flipped along both axes (a convolution is the correlation with them), in single precision."""
    return np.ascontiguousarray(np.asarray(kernels)[:, ::-1, ::-1], np.float32)


def mosaic_numpy(planes: np.ndarray, kernels: np.ndarray, cells: np.ndarray, gain: np.ndarray,
                 out: np.ndarray) -> np.ndarray:
    """:func:`mosaic`'s specification in NumPy: the same products and sums in the same order, the same bits."""
    rows, cols = out.shape
    kf = _flipped(kernels)
    k = kf.shape[1]
    half = (rows + k) // 2  # the window's even rows (rows + 2 m of them)
    for a in range(2):
        n = (rows - a + 1) // 2
        for b in range(2):
            c = int(cells[a, b])
            ncols = (cols - b + 1) // 2
            if n == 0 or ncols == 0:
                continue
            total = np.zeros((ncols, n))
            for v in range(k):
                lines = planes[c, b + v:b + v + 2 * ncols:2]  # the window's columns j + v of these pixels
                u = 0
                while u + 4 <= k:
                    s = [lines[:, o:o + n] for o in (((a + q) & 1) * half + ((a + q) >> 1) for q in range(u, u + 4))]
                    w = kf[c, u:u + 4, v]
                    total += ((w[0] * s[0] + w[1] * s[1]) + (w[2] * s[2] + w[3] * s[3])).astype(np.float64)
                    u += 4
                while u < k:
                    o = ((a + u) & 1) * half + ((a + u) >> 1)
                    total += (kf[c, u, v] * lines[:, o:o + n]).astype(np.float64)
                    u += 1
            total[~(total > 0.0)] = 0.0
            out[a::2, b::2] = gain[c] * total.T
    return out


def mosaic(planes: np.ndarray, kernels: np.ndarray, cells: np.ndarray, gain: np.ndarray,
           out: np.ndarray) -> np.ndarray:
    """Each pixel's own channel of the picture convolved with that channel's kernel, times its gain.

    Parameters
    ----------
    planes : (C, cols + 2 m, rows + 2 m) float32 array, C-contiguous
        The picture over the region's window, channels first and transposed, each column's values in
        :func:`layout_indices` order (the window's even rows, then its odd rows); ``m`` the kernels' radius.
    kernels : (C, k, k) array
        One kernel per channel, ``k = 2 m + 1`` odd, each applied as a convolution.
    cells : (2, 2) int array
        The channel of each pixel of the region's 2 x 2 cell (its first pixel's phase); all one channel for a
        plain blur of that channel.
    gain : (C,) float64 array
        Each channel's factor.
    out : (rows, cols) float64 array
        Where the region's values go.

    Returns
    -------
    (rows, cols) float64 array
        ``out``: at least 0 (a NaN taken as 0).
    """
    kf = _flipped(kernels)
    cells = np.ascontiguousarray(cells, np.int64)
    gain = np.ascontiguousarray(gain, np.float64)
    rows = out.shape[0]
    if planes.shape[2] != rows + kf.shape[1] - 1 or planes.shape[1] != out.shape[1] + kf.shape[1] - 1:
        raise ValueError(f"planes {planes.shape} do not hold a window of {out.shape} with a margin of "
                         f"{kf.shape[1] // 2}")
    if numba is None or out.size < 1 << 12 or not compiled("the lens's blur", _mosaic):
        return mosaic_numpy(planes, kernels, cells, gain, out)
    with ONE_LAUNCH:
        _mosaic(np.ascontiguousarray(planes, np.float32), (rows + kf.shape[1]) // 2, kf, cells, gain, out)
    return out


__all__ = ["mosaic", "mosaic_numpy", "layout_indices", "MAX_SIDE"]
