"""A map's mean, variance and mean square in two compiled passes, without a float64 copy of it.

NumPy's ``np.var(a.astype(np.float64))`` makes a copy of the map, then its deviations, then their squares: at
50 MP some 1.2 GB of temporaries and half a second a map. :func:`moments` reads the map twice (the mean, then the
squared deviations from it), in float64, in parallel over rows; each row's partial sum is kept and the rows are
added in order, so the result is the same on any number of threads. It agrees with NumPy's to float64 rounding
(NumPy sums pairwise, this row by row), not bit for bit: these are summary figures, not frames.
"""

from __future__ import annotations

import numpy as np

from .jit import ONE_LAUNCH, numba  # None where numba is not installed

if numba is not None:
    @numba.njit(parallel=True, cache=True, nogil=True)
    def _sums(a, mean):  # pragma: no cover - compiled
        rows, cols = a.shape
        part = np.zeros((rows, 3))
        for r in numba.prange(rows):
            s = 0.0
            d2 = 0.0
            q = 0.0
            for c in range(cols):
                x = np.float64(a[r, c])
                s += x
                d = x - mean
                d2 += d * d
                q += x * x
            part[r, 0] = s
            part[r, 1] = d2
            part[r, 2] = q
        out = np.zeros(3)
        for r in range(rows):
            for i in range(3):
                out[i] += part[r, i]
        return out


def moments(a: np.ndarray) -> tuple[float, float, float]:
    """(mean, variance, mean square) of every value of ``a``, in float64.

    Parameters
    ----------
    a : array
        A map (any shape; float32 or float64).

    Returns
    -------
    (float, float, float)
        The mean, the population variance (``ddof=0``, as ``np.var``) and the mean of the squares.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine.reduce import moments
    >>> moments(np.array([[1.0, 2.0], [3.0, 4.0]], np.float32))
    (2.5, 1.25, 7.5)
    """
    a = np.asarray(a)
    if a.ndim != 2:
        a = a.reshape(1, -1) if a.ndim < 2 else a.reshape(-1, a.shape[-1])
    n = a.size
    if numba is None or n < 1 << 16:  # small: NumPy's own, nothing compiled to load
        x = a.astype(np.float64)
        return float(x.mean()), float(x.var()), float(np.mean(x * x))
    a = np.ascontiguousarray(a)
    with ONE_LAUNCH:
        s = _sums(a, 0.0)
        mean = s[0] / n
        d = _sums(a, mean)
    return float(mean), float(d[1] / n), float(s[2] / n)
