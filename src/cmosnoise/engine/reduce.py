"""A map's mean, variance, mean square and extremes in one compiled pass, without a float64 copy of it; its sum;
and the positions above a threshold.

NumPy's ``np.var(a.astype(np.float64))`` makes a copy of the map, then its deviations, then their squares: at
50 MP some 1.2 GB of temporaries and half a second a map. :func:`statistics` reads each row of the map once from
memory, in float64, in parallel over rows: its sum, extremes and sum of squares, then (from cache) the squared
deviations from the row's own mean; the rows are joined in order by Chan, Golub and LeVeque's pairwise update, so
the result is the same on any number of threads. It agrees with NumPy's to float64 rounding (NumPy sums pairwise,
this row by row), not bit for bit: these are summary figures, not frames.

A map's median is ``np.median``'s: a radix selection here took a fifth of its time at 50 MP (0.06 against 0.58 s),
but a 50 MP ``cmosnoise simulate`` of 2 frames took the same time and peak memory either way (the dark map's
figures are made on a thread of their own beside the frames), so it was removed (docs/performance.md).
"""

from __future__ import annotations

import numpy as np

from .jit import ONE_LAUNCH, compiled, numba  # None where numba is not installed

#: how the compile message names this module's loops
WHAT = "the summary's reductions"

#: independent partial sums per row in :func:`statistics`' compiled pass
_LANES = 8

if numba is not None:
    @numba.njit(parallel=True, cache=True, nogil=True)
    def _rows(a):  # pragma: no cover - compiled
        """Each row's sum, sum of squared deviations from its own mean, sum of squares, min and max: one pass
        over memory (a row's second reading comes from cache). Each sum runs in 8 lanes (column mod 8) added at
        the row's end: independent chains the compiler can overlap or vectorize, in a fixed order."""
        rows, cols = a.shape
        part = np.zeros((rows, 5))
        for r in numba.prange(rows):
            s = np.zeros(_LANES)
            q = np.zeros(_LANES)
            lo = np.full(_LANES, np.inf)
            hi = np.full(_LANES, -np.inf)
            body = cols - cols % _LANES
            for c0 in range(0, body, _LANES):
                for k in range(_LANES):
                    x = np.float64(a[r, c0 + k])
                    s[k] += x
                    q[k] += x * x
                    lo[k] = min(lo[k], x)
                    hi[k] = max(hi[k], x)
            for c in range(body, cols):
                x = np.float64(a[r, c])
                s[0] += x
                q[0] += x * x
                lo[0] = min(lo[0], x)
                hi[0] = max(hi[0], x)
            total = s.sum()
            mean = total / cols
            d2 = np.zeros(_LANES)
            for c0 in range(0, body, _LANES):
                for k in range(_LANES):
                    d = np.float64(a[r, c0 + k]) - mean
                    d2[k] += d * d
            for c in range(body, cols):
                d = np.float64(a[r, c]) - mean
                d2[0] += d * d
            part[r, 0] = total
            part[r, 1] = d2.sum()
            part[r, 2] = q.sum()
            part[r, 3] = lo.min()
            part[r, 4] = hi.max()
        return part

    @numba.njit(cache=True, nogil=True)
    def _join(part, cols):  # pragma: no cover - compiled
        """The rows' figures joined in order (Chan et al.'s pairwise update): (sum, squared deviations from the
        mean, sum of squares, min, max) of the whole."""
        out = np.zeros(5)
        out[3] = np.inf
        out[4] = -np.inf
        n = 0.0
        for r in range(part.shape[0]):
            if n > 0:
                delta = part[r, 0] / cols - out[0] / n
                out[1] += part[r, 1] + delta * delta * n * cols / (n + cols)
            else:
                out[1] = part[r, 1]
            n += cols
            out[0] += part[r, 0]
            out[2] += part[r, 2]
            out[3] = min(out[3], part[r, 3])
            out[4] = max(out[4], part[r, 4])
        return out


#: a band of a map made and reduced in pieces holds at least this many values (a parallel pass's worth)
BAND_VALUES = 1 << 20

#: the figures :func:`statistics` gives
STATISTICS = ("mean", "var", "mean_square", "min", "max")


def statistics(a: np.ndarray) -> dict[str, float]:
    """The mean, variance, mean square, smallest and largest value of ``a``, in float64, from one pass over memory.

    Parameters
    ----------
    a : array
        A map (any shape; float32 or float64; not empty).

    Returns
    -------
    dict of str to float
        :data:`STATISTICS`: the population variance (``ddof=0``), the extremes exactly (as ``np.min``, ``np.max``).

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine.reduce import statistics
    >>> statistics(np.array([[1.0, 2.0], [3.0, 4.0]], np.float32))
    {'mean': 2.5, 'var': 1.25, 'mean_square': 7.5, 'min': 1.0, 'max': 4.0}
    """
    a = np.asarray(a)
    if a.ndim != 2:
        a = a.reshape(1, -1) if a.ndim < 2 else a.reshape(-1, a.shape[-1])
    n = a.size
    if numba is None or n < 1 << 16 or not compiled(WHAT, _rows, _join):  # small (nothing compiled to load), or
        x = a.astype(np.float64)  # not compiled yet: NumPy's own
        values = (x.mean(), x.var(), np.mean(x * x), x.min(), x.max())
    else:
        a = np.ascontiguousarray(a)
        with ONE_LAUNCH:
            s = _join(_rows(a), a.shape[1])
        values = (s[0] / n, s[1] / n, s[2] / n, s[3], s[4])
    return dict(zip(STATISTICS, map(float, values)))


if numba is not None:
    @numba.njit(parallel=True, cache=True, nogil=True)
    def _row_sums(a):  # pragma: no cover - compiled
        """Each row's sum in float64, in 8 lanes (column mod 8) added at the row's end; ``a`` of any strides."""
        rows, cols = a.shape
        out = np.zeros(rows)
        for r in numba.prange(rows):
            s = np.zeros(_LANES)
            for c in range(cols):
                s[c % _LANES] += np.float64(a[r, c])
            out[r] = s.sum()
        return out


def total(a: np.ndarray) -> float:
    """The sum of a 2-D array's values in float64, in parallel over rows (of any strides: a view of a map is not
    copied), then the rows' sums added: the same on any number of threads.

    NumPy's ``a.sum(dtype=np.float64)`` on a float32 view runs on one thread, through a buffered cast: a tile's
    sums of a 400 MP run in tiles took some 2 s of its thread time. The two agree to float64 rounding (NumPy adds
    pairwise, this row by row), not bit for bit: these are summary figures.

    Parameters
    ----------
    a : (rows, cols) array
        Float or integer values.

    Returns
    -------
    float

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine.reduce import total
    >>> total(np.arange(12, dtype=np.float32).reshape(3, 4)[:, 1:3])
    33.0
    """
    a = np.asarray(a)
    if numba is None or a.size < 1 << 16 or a.ndim != 2 or not compiled(WHAT, _row_sums):  # small, or not compiled
        return float(a.sum(dtype=np.float64))  # yet: NumPy's own
    with ONE_LAUNCH:
        return float(_row_sums(a).sum())


def combine(parts: list[tuple[int, dict[str, float]]]) -> dict[str, float]:
    """The :func:`statistics` of several arrays together, from each one's count and statistics (the variances
    joined by Chan, Golub and LeVeque's pairwise formula, exact up to float64 rounding).

    Parameters
    ----------
    parts : list of (int, dict)
        Each array's number of values and its :func:`statistics`.

    Returns
    -------
    dict of str to float
        :data:`STATISTICS` of all the values.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine.reduce import combine, statistics
    >>> a, b = np.array([1.0, 2.0]), np.array([3.0, 4.0, 8.0])
    >>> both, whole = combine([(2, statistics(a)), (3, statistics(b))]), statistics(np.r_[a, b])
    >>> all(np.isclose(both[k], whole[k], rtol=1e-15) for k in whole)
    True
    """
    n, out = 0, None
    for m, st in parts:
        if out is None:
            n, out = m, dict(st)
            continue
        total = n + m
        delta = st["mean"] - out["mean"]
        m2 = out["var"] * n + st["var"] * m + delta * delta * n * m / total
        out = {"mean": out["mean"] + delta * m / total, "var": m2 / total,
               "mean_square": (out["mean_square"] * n + st["mean_square"] * m) / total,
               "min": min(out["min"], st["min"]), "max": max(out["max"], st["max"])}
        n = total
    return out


if numba is not None:
    @numba.njit(parallel=True, cache=True, nogil=True)
    def _count_above(values, threshold):  # pragma: no cover - compiled
        rows, cols = values.shape
        counts = np.zeros(rows, np.int64)
        for r in numba.prange(rows):
            k = 0
            for c in range(cols):
                if values[r, c] > threshold:
                    k += 1
            counts[r] = k
        return counts

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _fill_above(values, threshold, start, out_r, out_c):  # pragma: no cover - compiled
        rows, cols = values.shape
        for r in numba.prange(rows):
            k = start[r]
            for c in range(cols):
                if values[r, c] > threshold:
                    out_r[k] = r
                    out_c[k] = c
                    k += 1

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _excess(charge, photo, read_var, k_sigma, t_int, threshold, keep):  # pragma: no cover - compiled
        rows, cols = charge.shape
        lit = np.zeros(rows, np.bool_)
        for r in numba.prange(rows):
            for c in range(cols):
                p = np.float64(photo[r, c])
                if p > 0:
                    lit[r] = True
                excess = np.float64(charge[r, c]) - p - k_sigma * np.sqrt(p + read_var)
                keep[r, c] = excess / t_int > threshold
        return lit.any()


def positions_above(values: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """The rows and columns of the values above ``threshold``, in row-major order: ``np.nonzero(values > threshold)``
    without the mask, in parallel over rows.

    Parameters
    ----------
    values : (rows, cols) array
        A map or a frame.
    threshold : float
        In the values' unit; compared as ``values > threshold`` (NumPy's comparison of the two types).

    Returns
    -------
    (n,) int64 array, (n,) int64 array
        Rows and columns.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine.reduce import positions_above
    >>> positions_above(np.array([[0.0, 5.0], [7.0, 1.0]]), 2.0)
    (array([0, 1]), array([1, 0]))
    """
    values = np.asarray(values)
    if numba is None or values.size < 1 << 16 or values.ndim != 2 or not compiled(WHAT, _count_above, _fill_above):
        r, c = np.nonzero(values > threshold)
        return r.astype(np.int64), c.astype(np.int64)
    values = np.ascontiguousarray(values)
    # NumPy compares a float array with a Python float in the array's type (NEP 50), an integer array in float64
    threshold = values.dtype.type(threshold) if values.dtype.kind == "f" else float(threshold)
    with ONE_LAUNCH:
        counts = _count_above(values, threshold)
        start = np.zeros(counts.size, np.int64)
        np.cumsum(counts[:-1], out=start[1:])
        n = int(start[-1] + counts[-1])
        out_r, out_c = np.empty(n, np.int64), np.empty(n, np.int64)
        _fill_above(values, threshold, start, out_r, out_c)
    return out_r, out_c


def excess_positions(charge: np.ndarray, photo: np.ndarray, read_var: float, k_sigma: float, t_int: float,
                     threshold: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """Where a frame's charge exceeds its expected photo-charge by more than ``k_sigma`` of its temporal noise and
    then ``threshold`` per second: the pixels with
    ``(charge - photo - k_sigma * sqrt(photo + read_var)) / t_int > threshold``, in float64, as NumPy evaluates that
    expression (frame 0's white pixels, :func:`cmosnoise.analysis.figures_of_merit.frame0_white_pixels`).

    Parameters
    ----------
    charge : (rows, cols) array, e-
        A frame's charge.
    photo : (rows, cols) array, e-
        Each pixel's expected photo-charge.
    read_var : float
        The readout's temporal variance, e-^2.
    k_sigma : float
        How many sigma.
    t_int : float
        The integration time, s.
    threshold : float
        e-/s.

    Returns
    -------
    (n,) int64 array, (n,) int64 array, bool
        The pixels' rows and columns in row-major order, and whether any pixel expects photo-charge.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine.reduce import excess_positions
    >>> charge = np.array([[5.0, 100.0], [0.0, 2.0]]); photo = np.zeros((2, 2))
    >>> excess_positions(charge, photo, 1.0, 5.0, 0.1, 100.0)
    (array([0]), array([1]), False)
    """
    if numba is None or charge.size < 1 << 16 or not compiled(WHAT, _excess):
        photo = np.asarray(photo).astype(np.float64)
        excess = charge - photo - k_sigma * np.sqrt(photo + read_var)
        r, c = np.nonzero(excess / t_int > threshold)
        return r.astype(np.int64), c.astype(np.int64), bool(photo.size and photo.max() > 0)
    keep = np.empty(charge.shape, np.bool_)
    with ONE_LAUNCH:
        lit = bool(_excess(np.ascontiguousarray(charge), np.ascontiguousarray(photo), float(read_var),
                           float(k_sigma), float(t_int), float(threshold), keep))
    r, c = positions_above(keep.view(np.uint8), 0)
    return r, c, lit
