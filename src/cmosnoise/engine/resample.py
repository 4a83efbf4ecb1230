"""A separable resampling's second axis, sampled through a colour filter array in the same pass, or made for every
channel straight into the transposed, single-precision planes a lens's blur reads.

A picture resampled to a sensor (:func:`cmosnoise.model.scene.resample`) is two sparse products per channel:
the rows' weights, then the columns'. Through a CFA each pixel keeps one channel of three, so making the three
channels at the sensor's size and then picking one (``to_cfa``) makes three times the values it keeps: at 50 MP,
4.6 s of a 6 s exposure. Here the columns' product is made only for the channel each pixel keeps, straight into
the mosaic, in parallel over rows.

The sums are the same terms in the same order as scipy's ``csr_matvecs`` makes them (start at 0, add each stored
weight times its value, in the stored order) and the channel's responsivity multiplies the sum afterwards, as
``to_cfa`` does: the same bits (``fastmath`` is off, so nothing is fused or reordered), which the tests check
against the three-channel path. :func:`transposed` makes every channel, each column of the result a row in
memory (the same sums, rounded once to the result's dtype): a 12 MP picture's three float32 planes in about a
third of the time of scipy's products and a cast.
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

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _transposed(planes_t, data, indices, indptr, out):  # pragma: no cover - compiled
        channels, cols, rows = out.shape
        for j in numba.prange(cols):
            acc = np.empty(rows)
            for c in range(channels):
                for t in range(rows):
                    acc[t] = 0.0
                for k in range(indptr[j], indptr[j + 1]):
                    w = data[k]
                    src = planes_t[c, indices[k]]
                    for t in range(rows):
                        acc[t] += w * src[t]
                for t in range(rows):
                    out[c, j, t] = acc[t]


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


def transposed(planes: np.ndarray, columns: sp.csr_matrix, dtype=np.float32) -> np.ndarray:
    """Every channel of ``planes`` through ``columns``, transposed: ``out[c] = columns @ planes[c].T``, rounded to
    ``dtype``.

    Parameters
    ----------
    planes : (C, rows, n) float64 array
        Each channel after the rows' weights.
    columns : (cols, n) scipy CSR matrix, float64
        The columns' weights.
    dtype : dtype
        Of the result.

    Returns
    -------
    (C, cols, rows) array
        Bit for bit scipy's ``columns @ planes[c].T`` (its sums in the stored order, started at 0), each rounded
        once to ``dtype``.
    """
    columns = sp.csr_matrix(columns)
    channels, rows = planes.shape[0], planes.shape[1]
    out = np.empty((channels, columns.shape[0], rows), dtype)
    if numba is None or out[0].size < 1 << 16 or not compiled("the scene's resampling", _transposed):
        for c in range(channels):
            out[c] = columns @ planes[c].T
        return out
    planes_t = np.ascontiguousarray(np.asarray(planes, np.float64).transpose(0, 2, 1))
    with ONE_LAUNCH:
        _transposed(planes_t, np.ascontiguousarray(columns.data, np.float64), columns.indices.astype(np.int64),
                    columns.indptr.astype(np.int64), out)
    return out
