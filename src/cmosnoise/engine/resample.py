"""A separable resampling's second axis, sampled through a colour filter array in the same pass; and the optical
image's separable terms, rows' pass and columns' pass, at each pixel's own channel.

A picture resampled to a sensor (:func:`cmosnoise.model.scene.resample`) is two sparse products per channel:
the rows' weights, then the columns'. Through a CFA each pixel keeps one channel of three, so making the three
channels at the sensor's size and then picking one (``to_cfa``) makes three times the values it keeps: at 50 MP,
4.6 s of a 6 s exposure. Here the columns' product is made only for the channel each pixel keeps, straight into
the mosaic, in parallel over rows.

The sums are the same terms in the same order as scipy's ``csr_matvecs`` makes them (start at 0, add each stored
weight times its value, in the stored order) and the channel's responsivity multiplies the sum afterwards, as
``to_cfa`` does: the same bits (``fastmath`` is off, so nothing is fused or reordered), which the tests check
against the three-channel path. :func:`rows_transposed` and :func:`mosaic_transposed` make the optical image's
terms (:mod:`cmosnoise.model.focal_plane`): each channel's own weights, the rows' pass written transposed so that
the columns' pass sums every row of a column at once (each sum still in the stored order: scipy's bits).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .jit import ONE_LAUNCH, compiled, numba  # None where numba is not installed

if numba is not None:
    @numba.njit(parallel=True, cache=True, nogil=True)
    def _mosaic(planes, data, indices, indptr, cell, gain, out):  # pragma: no cover - compiled
        rows, cols = out.shape
        for i in numba.prange(rows):
            for j in range(cols):
                c = cell[i & 1, j & 1]
                acc = 0.0
                for k in range(indptr[j], indptr[j + 1]):
                    acc += data[k] * planes[c, i, indices[k]]
                out[i, j] = acc * gain[c]



#: output rows (:func:`rows_transposed`) and output columns (:func:`mosaic_transposed`) each parallel task makes
_ROWS, _BLOCK = 32, 16

if numba is not None:
    @numba.njit(parallel=True, cache=True, nogil=True)
    def _rows_transposed(x, indptr, indices, data, half, out_t):  # pragma: no cover - compiled
        # a block of _ROWS consecutive rows of one parity at a time: each row's sums along the source's rows
        # (contiguous, in the stored order), then the block written transposed
        n = indptr.size - 1
        width = x.shape[1]
        even = (half + _ROWS - 1) // _ROWS
        blocks = even + (n - half + _ROWS - 1) // _ROWS
        for blk in numba.prange(blocks):
            if blk < even:
                a, p0 = 0, blk * _ROWS
                p1 = min(p0 + _ROWS, half)
            else:
                a, p0 = 1, (blk - even) * _ROWS
                p1 = min(p0 + _ROWS, n - half)
            acc = np.zeros((_ROWS, width))
            for p in range(p0, p1):
                i = 2 * p + a
                dst = acc[p - p0]
                for k in range(indptr[i], indptr[i + 1]):
                    w = data[k]
                    row = x[indices[k]]
                    for b in range(width):
                        dst[b] += w * row[b]
            base = a * half
            for b in range(width):
                for p in range(p0, p1):
                    out_t[b, base + p] = acc[p - p0, b]

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _mosaic_transposed(planes_t, half, data, indices, indptr, cell, gain, out):  # pragma: no cover - compiled
        rows, cols = out.shape
        n0 = (rows + 1) // 2
        for blk in numba.prange((cols + _BLOCK - 1) // _BLOCK):
            j0 = blk * _BLOCK
            j1 = min(j0 + _BLOCK, cols)
            acc = np.empty((_BLOCK, 2, n0))
            for jj in range(j1 - j0):
                j = j0 + jj
                for a in range(2):  # the row phase: rows i = 2 t + a, consecutive in the planes
                    n = (rows - a + 1) // 2
                    c = cell[a, j & 1]
                    dst = acc[jj, a]
                    for t in range(n):
                        dst[t] = 0.0
                    base = a * half
                    for k in range(indptr[c, j], indptr[c, j + 1]):
                        w = data[k]
                        src = planes_t[c, indices[k]]
                        for t in range(n):
                            dst[t] += w * src[base + t]
            for i in range(rows):
                a, t = i & 1, i >> 1
                for jj in range(j1 - j0):
                    j = j0 + jj
                    x = acc[jj, a, t]
                    if not x > 0.0:  # at least 0, NaN as 0
                        x = 0.0
                    out[i, j] = gain[cell[a, j & 1]] * x


def parity_order(n: int) -> np.ndarray:
    """The order :func:`rows_transposed` and :func:`mosaic_transposed` keep ``n`` rows in: even rows, then odd ones.

    Parameters
    ----------
    n : int

    Returns
    -------
    (n,) int64 array
    """
    idx = np.arange(n)
    return np.concatenate([idx[0::2], idx[1::2]])


def rows_transposed(x: np.ndarray, rows: sp.csr_matrix, out_t: np.ndarray) -> np.ndarray:
    """A rows' pass ``rows @ x`` written transposed, its rows in :func:`parity_order`: ``out_t[b, p] =
    (rows @ x)[parity_order(n)[p], b]``, each sum in the stored order from 0 (scipy's ``csr_matvecs``): the same
    bits.

    Parameters
    ----------
    x : (m, width) float64 array
        The source (a picture's channel, or a band of the optical image's fine cells).
    rows : (n, m) scipy CSR matrix
        The rows' weights.
    out_t : (width, n) float64 array
        Where the result goes (a view into a stack of such planes).

    Returns
    -------
    (width, n) float64 array
        ``out_t``.
    """
    n = rows.shape[0]
    if numba is None or n * x.shape[1] < 1 << 14 or not compiled("the optical image's rows", _rows_transposed):
        out_t[:] = (rows @ x)[parity_order(n)].T
        return out_t
    with ONE_LAUNCH:
        _rows_transposed(np.ascontiguousarray(x, np.float64), rows.indptr, rows.indices,
                         np.asarray(rows.data, np.float64), (n + 1) // 2, out_t)
    return out_t


def mosaic_transposed(planes_t: np.ndarray, columns: list, cell: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """:func:`mosaic` with weights of each channel's own, on planes laid out transposed (:func:`rows_transposed`):
    pixel (i, j) of channel ``c = cell[i % 2, j % 2]`` is ``gain[c] * max(sum_k columns[c][j, k] *
    planes[c, i, k], 0)``, each sum in the stored order from 0.

    What the optical image's separable terms need (:mod:`cmosnoise.model.focal_plane`): each channel's PSF differs,
    so each has its columns' weights, and a term's weights may be negative, so a sum is taken as at least 0. The
    compiled loop makes a block of output columns at a time, each column's sums for every row at once (the rows'
    values consecutive in the planes): the same sums as scipy's products, element by element.

    Parameters
    ----------
    planes_t : (C, n, rows) float64 array
        Each channel after its rows' weights, transposed, the rows in :func:`parity_order`.
    columns : list of C scipy CSR matrices, each (cols, n), float64
        Each channel's columns' weights.
    cell : (2, 2) int array
        The channel of each position of the 2 x 2 CFA cell.
    gain : (C,) float64 array
        Each channel's factor after the sum.

    Returns
    -------
    (rows, cols) float64 array
        Bit for bit ``max((columns[c] @ planes[c].T).T, 0) * gain[c]`` at each pixel's channel.
    """
    cell = np.ascontiguousarray(cell, dtype=np.int64)
    gain = np.ascontiguousarray(gain, dtype=np.float64)
    rows, cols = planes_t.shape[2], columns[0].shape[0]
    out = np.empty((rows, cols))
    if numba is None or rows * cols < 1 << 14 or not compiled("the optical image's terms", _mosaic_transposed):
        back = np.argsort(parity_order(rows))
        for c in np.unique(cell):
            whole = (columns[c] @ planes_t[c]).T[back]
            whole[~(whole > 0.0)] = 0.0
            for (i, j), cc in np.ndenumerate(cell):
                if cc == c:
                    out[i::2, j::2] = whole[i::2, j::2] * gain[c]
        return out
    starts = np.cumsum([0] + [m.nnz for m in columns])
    data = np.concatenate([np.asarray(m.data, np.float64) for m in columns])
    indices = np.concatenate([m.indices for m in columns]).astype(np.int32, copy=False)
    indptr = np.stack([m.indptr.astype(np.int64) + starts[c] for c, m in enumerate(columns)])
    with ONE_LAUNCH:
        _mosaic_transposed(np.ascontiguousarray(planes_t, np.float64), (rows + 1) // 2, data, indices, indptr, cell,
                           gain, out)
    return out


def mosaic(planes: np.ndarray, columns: sp.csr_matrix, cell: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """The CFA mosaic of ``columns`` applied to each channel's rows: pixel (i, j) of channel ``c = cell[i % 2, j % 2]``
    is ``gain[c] * sum_k columns[j, k] * planes[c, i, k]``, summed in the stored order.

    Parameters
    ----------
    planes : (C, rows, n) float64 array
        Each channel after the rows' weights: rows of the result, ``n`` source columns.
    columns : (cols, n) scipy CSR matrix, float64
        The columns' weights.
    cell : (2, 2) int array
        The channel of each position of the 2 x 2 CFA cell (array-relative: row and column parity).
    gain : (C,) float64 array
        Each channel's factor after the sum (its relative responsivity).

    Returns
    -------
    (rows, cols) float64 array
        Bit for bit what ``(columns @ planes[c].T).T`` gives at each pixel's channel, times its gain.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> from cmosnoise.engine.resample import mosaic
    >>> planes = np.arange(24.0).reshape(3, 2, 4)
    >>> columns = sp.csr_matrix(np.array([[0.5, 0.5, 0, 0], [0, 0, 0.5, 0.5], [0, 0, 0, 1.0]]))
    >>> cell = np.array([[0, 1], [1, 2]])
    >>> mosaic(planes, columns, cell, np.ones(3))
    array([[ 0.5, 10.5,  3. ],
           [12.5, 22.5, 15. ]])
    """
    planes = np.ascontiguousarray(planes, dtype=np.float64)
    columns = sp.csr_matrix(columns)
    cell = np.ascontiguousarray(cell, dtype=np.int64)
    gain = np.ascontiguousarray(gain, dtype=np.float64)
    rows, cols = planes.shape[1], columns.shape[0]
    if numba is None or rows * cols < 1 << 16 or not compiled("the scene's resampling through the CFA", _mosaic):
        # small, or nothing compiled (yet): scipy's products and a pick
        out = np.empty((rows, cols))
        for (i, j), c in np.ndenumerate(cell):
            out[i::2, j::2] = (columns @ planes[c].T).T[i::2, j::2] * gain[c]
        return out
    out = np.empty((rows, cols))
    with ONE_LAUNCH:
        _mosaic(planes, np.ascontiguousarray(columns.data, np.float64), columns.indices.astype(np.int64),
                columns.indptr.astype(np.int64), cell, gain, out)
    return out
