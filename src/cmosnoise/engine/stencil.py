"""A small kernel's convolution over an array and a frame around it, compiled: what crosstalk spreads; and the
scatter of a kernel that leans pixel by pixel (:func:`leaning_spread`, the chief-ray angle's crosstalk).

:func:`framed_convolve` gives, for an array ``x`` (rows, cols) and a 3 x 3 kernel, the (rows + 2, cols + 2)
array that ``scipy.ndimage.convolve(np.pad(x, 1), k, mode="constant")`` gives, bit for bit: each value is a sum
started at 0.0 over the kernel's points in the order ndimage takes them (the flipped kernel in C order, points
whose weight is within ``DBL_EPSILON`` of 0 left out, as ndimage leaves them out of its footprint), each term the
float64 value times the float64 weight, and the result rounded to ``x``'s dtype once. Points outside ``x`` add
nothing (ndimage adds ``0.0 * w`` there, which leaves every sum as it is). One parallel pass, without the padded
copy: at 50 MP about a sixth of ndimage's time with the pad (arrays under 65 536 values go to ndimage itself,
quicker than a parallel launch). The tests hold it to ndimage on random arrays,
kernels (lopsided, with zeros and near-zeros) and both float dtypes.
"""

from __future__ import annotations

import numpy as np

from .jit import ONE_LAUNCH, announce, compiled, numba  # None where numba is not installed

if numba is not None:
    @numba.njit(parallel=True, cache=True, nogil=True)
    def _framed(x, dr, dc, w, out):  # pragma: no cover - compiled
        rows, cols = x.shape
        for i in numba.prange(rows + 2):
            # the row's sums in float64, a point at a time over the whole row (a loop the compiler vectorizes):
            # each pixel still adds its points in the kernel's order, starting at 0.0, so the same sums
            acc = np.zeros(cols + 2)
            for q in range(w.size):
                y = i + dr[q] - 2
                if y < 0 or y >= rows:
                    continue
                shift = dc[q] - 2
                wq = w[q]
                j0 = max(0, -shift)
                src = x[y, j0 + shift:min(cols + 2, cols - shift) + shift]
                dst = acc[j0:j0 + src.size]
                for t in range(src.size):  # indices from 0: no negative-index test in the loop, so it vectorizes
                    dst[t] += np.float64(src[t]) * wq
            for j in range(cols + 2):
                out[i, j] = acc[j]


if numba is not None:
    @numba.njit(cache=True, nogil=True, inline="always")
    def scatter(out, y, x, wa, wb, right, left, down, up):  # pragma: no cover - compiled
        """Pixel (y, x) sends ``|wa| D_a + |wb| D_b`` to its 3 x 3 neighbours (off the array: into the edge pixel
        it left), D_a the column kernel of ``wa``'s sign, D_b the row kernel of ``wb``'s: one pixel of
        :func:`leaning_spread`, shared by the loops that take the shares from maps and from the lens's field
        (:mod:`.lens`)."""
        rows, cols = out.shape
        if wa == 0.0 and wb == 0.0:
            return
        kx = right if wa >= 0.0 else left
        ky = down if wb >= 0.0 else up
        wa, wb = abs(wa), abs(wb)
        for dy in range(3):
            ty = min(max(y + dy - 1, 0), rows - 1)  # off the array: back into the edge pixel it left
            for dx in range(3):
                tx = min(max(x + dx - 1, 0), cols - 1)
                out[ty, tx] += wa * kx[dy, dx] + wb * ky[dy, dx]

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _leaning(q, a, b, right, left, down, up, row0, out):  # pragma: no cover - compiled
        rows, cols = q.shape
        # a source row writes the rows next to it only: rows three apart never write the same values, so each
        # third of the rows (by the sensor's own row number, row0 + y, so that a tile adds each value's terms in
        # the whole's order) is scattered in parallel, one third after another
        for phase in range(3):
            first = (phase - row0) % 3
            for t in numba.prange(max(rows - first + 2, 0) // 3):
                y = first + 3 * t
                for x in range(cols):
                    scatter(out, y, x, q[y, x] * a[y, x], q[y, x] * b[y, x], right, left, down, up)


def leaning_spread(q: np.ndarray, a: np.ndarray, b: np.ndarray, leans: tuple, row0: int = 0) -> np.ndarray:
    """Charge scattered by a kernel that leans per pixel: pixel p sends ``q[p] (|a[p]| D_a + |b[p]| D_b)[d]`` to
    p + d, D_a the column kernel of ``a``'s sign and D_b the row kernel of ``b``'s (off the array: into the edge
    pixel it left). One compiled pass over the cores, each value's terms added in an order fixed by the rows'
    numbers on the sensor (a tile's values are the whole's, bit for bit, away from its edges).

    Parameters
    ----------
    q : (rows, cols) array
        Charge, e-.
    a, b : (rows, cols) arrays
        The signed shares along the columns and the rows.
    leans : tuple of four (3, 3) arrays
        The kernels' changes toward +column, -column, +row, -row (:func:`cmosnoise.model.stages.crosstalk.lean_kernels`).
    row0 : int
        The sensor's row number of ``q``'s first row.

    Returns
    -------
    (rows, cols) float64 array
    """
    q, a, b = (np.ascontiguousarray(v, np.float64) for v in np.broadcast_arrays(q, a, b))
    ks = [np.ascontiguousarray(k, np.float64) for k in leans]
    out = np.zeros(q.shape)
    if numba is None:  # the same scatter in NumPy, slowly
        rows, cols = q.shape
        for w, (pos, neg) in ((a, (ks[0], ks[1])), (b, (ks[2], ks[3]))):
            for k, part in ((pos, np.clip(w, 0, None)), (neg, np.clip(-w, 0, None))):
                src = q * part
                for dy in range(3):
                    ty = np.clip(np.arange(rows) + dy - 1, 0, rows - 1)
                    for dx in range(3):
                        tx = np.clip(np.arange(cols) + dx - 1, 0, cols - 1)
                        np.add.at(out, (ty[:, None], tx[None, :]), src * k[dy, dx])
        return out
    announce("the leaning crosstalk", _leaning)
    with ONE_LAUNCH:
        _leaning(q, a, b, ks[0], ks[1], ks[2], ks[3], int(row0), out)
    return out


def framed_convolve(x: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """The convolution of ``x`` with a 3 x 3 ``kernel`` over ``x`` and a one-pixel frame of zeros around it.

    Parameters
    ----------
    x : (rows, cols) float32 or float64 array
        The values.
    kernel : (3, 3) array_like
        The weights, in ``x``'s dtype (as ndimage takes them).

    Returns
    -------
    (rows + 2, cols + 2) array of ``x``'s dtype
        ``scipy.ndimage.convolve(np.pad(x, 1), kernel, mode="constant")``, the same bits.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine.stencil import framed_convolve
    >>> x = np.zeros((3, 3)); x[1, 1] = 1.0
    >>> framed_convolve(x, [[0, 0, 0], [0.1, 0.8, 0.1], [0, 0, 0]])[2]
    array([0. , 0. , 0.1, 0.8, 0.1])
    """
    x = np.ascontiguousarray(x)
    k = np.asarray(kernel, dtype=x.dtype).astype(np.float64)
    if numba is None or x.size < 1 << 16 or not compiled("the crosstalk stencil", _framed):
        # small (a PRNU solve's 16 x 16 fields: ndimage is quicker than a launch), or not compiled yet
        from scipy import ndimage

        return ndimage.convolve(np.pad(x, 1), k.astype(x.dtype), mode="constant")
    flipped = k[::-1, ::-1]  # a convolution is the correlation with the flipped kernel
    dr, dc = np.nonzero(np.abs(flipped) > np.finfo(np.float64).eps)
    out = np.empty((x.shape[0] + 2, x.shape[1] + 2), x.dtype)
    with ONE_LAUNCH:
        _framed(x, dr.astype(np.int64), dc.astype(np.int64), np.ascontiguousarray(flipped[dr, dc]), out)
    return out
