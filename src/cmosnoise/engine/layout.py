"""Array layouts changed by compiled loops: what NumPy does slowly at tens of megapixels.

A channel-interleaved image (rows, cols, C) made from planes held transposed (cols, rows), as a separable
resampling gives them (:func:`cmosnoise.model.scene.resample`): NumPy's strided copy walks one of the two
arrays against its memory order and took 3 to 5 s at 50 MP; blocks of 64 x 64 that both fit in cache, in
parallel over row blocks, take a tenth of it. Only values move, so the result is the same bits.

The mosaic a colour filter array samples from such an image (:func:`cfa_pick`, what ``scene.to_cfa`` calls):
each pixel's own channel times its gain in one parallel pass, the same product as NumPy's.
"""

from __future__ import annotations

import numpy as np

from .jit import ONE_LAUNCH, compiled, numba  # None where numba is not installed

_BLOCK = 64

if numba is not None:
    @numba.njit(parallel=True, cache=True, nogil=True)
    def _interleave(plane, out, c):  # pragma: no cover - compiled
        cols, rows = plane.shape
        for bi in numba.prange((rows + _BLOCK - 1) // _BLOCK):
            i0 = bi * _BLOCK
            i1 = min(rows, i0 + _BLOCK)
            for j0 in range(0, cols, _BLOCK):
                j1 = min(cols, j0 + _BLOCK)
                for i in range(i0, i1):
                    for j in range(j0, j1):
                        out[i, j, c] = plane[j, i]


if numba is not None:
    @numba.njit(parallel=True, cache=True, nogil=True)
    def _pick(planes, cell, gain, out):  # pragma: no cover - compiled
        rows, cols = out.shape
        for i in numba.prange(rows):
            for j in range(cols):
                c = cell[i & 1, j & 1]
                out[i, j] = np.float64(planes[c, i, j]) * gain[c]


def _pick_numpy(planes, cell, gain, out):
    """:func:`_pick` by NumPy's strided copies, one per position of the 2 x 2 cell (small images, or nothing
    compiled yet): the same products."""
    for (i, j), ch in np.ndenumerate(cell):
        np.multiply(planes[ch, i::2, j::2], gain[ch], out=out[i::2, j::2])
    return out


def cfa_pick(rgb: np.ndarray, cell: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """Each pixel's own channel of a channel-interleaved image, times that channel's gain: the mosaic a colour
    filter array samples, in one parallel pass (NumPy's four strided copies of the 2 x 2 cell's positions write
    every other value, a fifth of the speed at tens of megapixels).

    Parameters
    ----------
    rgb : (rows, cols, C) array
        The image (any strides: a broadcast flat field too).
    cell : (2, 2) int array
        The channel of each position of the 2 x 2 cell (row and column parity).
    gain : (C,) float64 array
        Each channel's factor.

    Returns
    -------
    (rows, cols) float64 array
        ``rgb[i, j, cell[i % 2, j % 2]] * gain[cell[i % 2, j % 2]]``, the same bits as NumPy's product.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine.layout import cfa_pick
    >>> rgb = np.arange(12.0).reshape(2, 2, 3)
    >>> cfa_pick(rgb, np.array([[0, 1], [1, 2]]), np.array([1.0, 10.0, 100.0]))
    array([[   0.,   40.],
           [  70., 1100.]])
    """
    rows, cols = rgb.shape[:2]
    cell = np.ascontiguousarray(cell, dtype=np.int64)
    gain = np.ascontiguousarray(gain, dtype=np.float64)
    out = np.empty((rows, cols), np.result_type(rgb.dtype, np.float64))
    planes = np.moveaxis(rgb, -1, 0)  # a view: channel first, as _pick reads it
    if (numba is None or rows * cols < 1 << 16 or out.dtype != np.float64
            or not compiled("the image layout loops", _interleave, _pick)):
        return _pick_numpy(planes, cell, gain, out)
    with ONE_LAUNCH:
        _pick(planes, cell, gain, out)
    return out


def interleave_transposed(planes: list[np.ndarray]) -> np.ndarray:
    """The image whose channel ``c`` is ``planes[c].T``: (rows, cols, C) float64 from C planes (cols, rows).

    Parameters
    ----------
    planes : list of (cols, rows) float64 arrays
        Each channel, transposed.

    Returns
    -------
    (rows, cols, C) float64 array
        ``np.stack([p.T for p in planes], axis=-1)``, the same values.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine.layout import interleave_transposed
    >>> planes = [np.arange(6.0).reshape(3, 2), 10 + np.arange(6.0).reshape(3, 2)]
    >>> out = interleave_transposed(planes)
    >>> out.shape, bool((out == np.stack([p.T for p in planes], axis=-1)).all())
    ((2, 3, 2), True)
    """
    cols, rows = planes[0].shape
    out = np.empty((rows, cols, len(planes)))
    for c, plane in enumerate(planes):
        plane = np.ascontiguousarray(plane, np.float64)
        if numba is None or plane.size < 1 << 16 or not compiled("the image layout loops", _interleave, _pick):
            out[..., c] = plane.T  # small (NumPy's copy is quick, nothing compiled is loaded), or not compiled yet
            continue
        with ONE_LAUNCH:
            _interleave(plane, out, c)
    return out
