"""The lens's per-pixel factors across the field, compiled: relative illumination and the chief-ray angle's QE loss
multiplied into a signal in one pass, and the leaning crosstalk's shares.

:mod:`cmosnoise.model.optics` is the specification (:func:`~cmosnoise.model.optics.relative_illumination`,
:func:`~cmosnoise.model.optics.angle_qe`, :func:`~cmosnoise.model.optics.lean_weights`): NumPy over whole
arrays, each a few passes of a 12 MP map (about 0.6 s of a 12 MP exposure on 2 cores). These loops compute the
same expressions pixel by pixel, in the same order of operations and with :func:`interp` written as NumPy's
``np.interp`` computes it, so they give the same bits without the intermediate maps; the tests hold them to the
specification bit for bit. Each pixel needs only its distance from the optical centre: ``h^2 = y^2 + x^2`` (mm),
``y`` and ``x`` the row's and the column's offsets.
"""

from __future__ import annotations

import numpy as np

from . import stencil
from .jit import ONE_LAUNCH, compiled, keyed_on, numba  # None where numba is not installed

if numba is not None:
    from .stencil import scatter

#: relative illumination kinds: none, cos^4 of the field angle, a table of image height
RI_NONE, RI_COS4, RI_TABLE = 0, 1, 2

if numba is not None:
    @numba.njit(cache=True, nogil=True, inline="always")
    def interp(x, xp, fp, slopes):  # pragma: no cover - compiled
        """``np.interp(x, xp, fp)`` for one value, as NumPy computes it (``numpy/_core/src/multiarray/
        compiled_base.c``, ``arr_interp``): the end values beyond the table, the last value at its last point,
        ``fp[j]`` at a point, ``slope * (x - xp[j]) + fp[j]`` between, and the other end's form where that is
        NaN. ``slopes``: :func:`slopes` of the table, as NumPy computes them once for a long ``x``."""
        n = xp.size
        if x > xp[n - 1]:
            return fp[n - 1]
        if x < xp[0]:
            return fp[0]
        if x == xp[n - 1]:
            return fp[n - 1]
        if x != x:
            return x
        lo, hi = 0, n - 1  # xp[lo] <= x < xp[hi]
        while hi - lo > 1:
            mid = (lo + hi) >> 1
            if xp[mid] <= x:
                lo = mid
            else:
                hi = mid
        if xp[lo] == x:  # NumPy avoids a non-finite interpolation there
            return fp[lo]
        slope = slopes[lo]
        out = slope * (x - xp[lo]) + fp[lo]
        if out != out:
            out = slope * (x - xp[lo + 1]) + fp[lo + 1]
            if out != out and fp[lo] == fp[lo + 1]:
                out = fp[lo]
        return out

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _shade(signal, y, x, ri_kind, f2, ri_h, ri_v, ri_s, qe_on, cra_h, cra_a, cra_s, keep, qe_a, qe_v, qe_s,
               cells):
        # pragma: no cover - compiled
        rows, cols = signal.shape
        for i in numba.prange(rows):
            yy = y[i] * y[i]
            for j in range(cols):
                h2 = yy + x[j] * x[j]
                h = np.sqrt(h2) if (ri_kind == RI_TABLE or qe_on) else 0.0  # the image height, where a table reads it
                s = signal[i, j]
                if ri_kind == RI_COS4:  # 1 / (1 + h^2 / f^2)^2, as optics.relative_illumination
                    t = h2 / f2
                    t += 1.0
                    t = t * t
                    s = s * (1.0 / t)
                elif ri_kind == RI_TABLE:
                    s = s * interp(h, ri_h, ri_v, ri_s)
                if qe_on:  # as optics.incidence, then optics.angle_qe by the pixel's channel
                    angle = interp(h, cra_h, cra_a, cra_s)
                    angle *= keep
                    c = cells[i & 1, j & 1]
                    s = s * interp(abs(angle), qe_a, qe_v[c], qe_s[c])
                signal[i, j] = s

    @numba.njit(cache=True, nogil=True, inline="always")
    def _shares(yy, y, x, cra_h, cra_a, cra_s, keep, reference):  # pragma: no cover - compiled
        """One pixel's lean shares along the columns and the rows, as optics.lean_weights: ``yy = y * y``."""
        h = np.sqrt(yy + x * x)
        angle = interp(h, cra_h, cra_a, cra_s)
        angle *= keep
        inv = 1.0 / h if h > 0 else 0.0
        share = min(max(angle / reference, -1.0), 1.0)
        return share * (x * inv), share * (y * inv)

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _lean(y, x, cra_h, cra_a, cra_s, keep, reference, a, b):  # pragma: no cover - compiled
        rows, cols = a.shape
        for i in numba.prange(rows):
            yy = y[i] * y[i]
            for j in range(cols):
                a[i, j], b[i, j] = _shares(yy, y[i], x[j], cra_h, cra_a, cra_s, keep, reference)

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _leaning(q, y, x, cra_h, cra_a, cra_s, keep, reference, right, left, down, up, row0, out):
        # pragma: no cover - compiled
        # stencil._leaning with each pixel's shares made where it is scattered (no maps): a third of the rows at a
        # time by the sensor's row number, each pixel's terms in the same order, the same bits
        rows, cols = q.shape
        for phase in range(3):
            first = (phase - row0) % 3
            for t in numba.prange(max(rows - first + 2, 0) // 3):
                i = first + 3 * t
                yy = y[i] * y[i]
                for j in range(cols):
                    a, b = _shares(yy, y[i], x[j], cra_h, cra_a, cra_s, keep, reference)
                    qv = np.float64(q[i, j])
                    scatter(out, i, j, qv * a, qv * b, right, left, down, up)

    keyed_on(_leaning, stencil)  # it inlines stencil.scatter


def slopes(xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """A table's slopes between its points, ``(fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])``, as ``np.interp`` makes
    them (along the last axis of ``fp``)."""
    return np.ascontiguousarray(np.diff(fp, axis=-1) / np.diff(xp))


def _line(v) -> np.ndarray:
    """A 1-D float64 C-contiguous array (one compiled variant for every table)."""
    return np.ascontiguousarray(v, np.float64)


def ready() -> bool:
    """Whether the compiled loops run now (:func:`cmosnoise.engine.jit.compiled`); False: the NumPy specification."""
    return numba is not None and compiled("the lens's field maps", _shade, _lean, _leaning)


def shade(signal: np.ndarray, y_mm: np.ndarray, x_mm: np.ndarray, ri_kind: int, image_distance_mm: float,
          ri_table: tuple[np.ndarray, np.ndarray] | None, angle: tuple[np.ndarray, np.ndarray, float] | None,
          qe_table: np.ndarray | None, cells: np.ndarray) -> np.ndarray:
    """Multiply ``signal`` in place by each pixel's relative illumination, then by its QE at its angle.

    Parameters
    ----------
    signal : (rows, cols) float64 array, C-contiguous
        Relative signal; changed in place.
    y_mm : (rows,) float64 array
        Each row's offset from the optical centre, mm.
    x_mm : (cols,) float64 array
        Each column's offset, mm.
    ri_kind : {RI_NONE, RI_COS4, RI_TABLE}
    image_distance_mm : float
        The lens's image distance ``f (1 + m)``, for cos^4 (``tan theta = h / i``).
    ri_table : (heights_mm, relative_illumination) or None
        For RI_TABLE.
    angle : (heights_mm, chief_ray_angle_deg, 1 - microlens_compensation) or None
        None: no QE loss.
    qe_table : (n, 1 + channels) array or None
        Angle (deg), then the relative QE of each channel column.
    cells : (2, 2) int array
        The column of ``qe_table`` (from 0, after the angle) of each cell of the region's 2 x 2 pattern.

    Returns
    -------
    (rows, cols) float64 array
        ``signal``.
    """
    axis, zero = np.array([0.0, 1.0]), np.zeros(2)  # a table that is not read
    ri_h, ri_v = ri_table if ri_table is not None else (axis, zero)
    cra_h, cra_a, keep = angle if angle is not None else (axis, zero, 1.0)
    qe_a = _line(qe_table[:, 0]) if qe_table is not None else axis
    qe_v = np.ascontiguousarray(np.asarray(qe_table, np.float64)[:, 1:].T) if qe_table is not None else np.zeros((1, 2))
    ri_h, ri_v, cra_h, cra_a = _line(ri_h), _line(ri_v), _line(cra_h), _line(cra_a)
    with ONE_LAUNCH:
        _shade(signal, _line(y_mm), _line(x_mm), ri_kind, float(image_distance_mm) ** 2, ri_h, ri_v, slopes(ri_h, ri_v),
               angle is not None, cra_h, cra_a, slopes(cra_h, cra_a), float(keep), qe_a, qe_v, slopes(qe_a, qe_v),
               np.asarray(cells, np.int64))
    return signal


def lean_shares(y_mm: np.ndarray, x_mm: np.ndarray, heights_mm: np.ndarray, angles_deg: np.ndarray, keep: float,
                reference_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """The leaning crosstalk's signed shares along the columns and the rows per pixel.

    Parameters
    ----------
    y_mm, x_mm : (rows,) and (cols,) float64 arrays
        The rows' and columns' offsets from the optical centre, mm.
    heights_mm, angles_deg : (n,) float64 arrays
        The chief-ray angle's table.
    keep : float
        ``1 - microlens_compensation``.
    reference_deg : float
        The angle of the leaning kernel.

    Returns
    -------
    (toward_col, toward_row), each (rows, cols) float64
    """
    a = np.empty((y_mm.size, x_mm.size))
    b = np.empty_like(a)
    heights_mm, angles_deg = _line(heights_mm), _line(angles_deg)
    with ONE_LAUNCH:
        _lean(_line(y_mm), _line(x_mm), heights_mm, angles_deg, slopes(heights_mm, angles_deg), float(keep),
              float(reference_deg), a, b)
    return a, b


def leaning_spread(q: np.ndarray, y_mm: np.ndarray, x_mm: np.ndarray, heights_mm: np.ndarray,
                   angles_deg: np.ndarray, keep: float, reference_deg: float, leans: tuple,
                   row0: int = 0) -> np.ndarray:
    """:func:`.stencil.leaning_spread` of ``q`` with the shares of :func:`lean_shares`, each pixel's made where it
    is scattered: the same bits, without the two maps (only where :func:`ready`).

    Parameters
    ----------
    q : (rows, cols) float32 or float64 array
        Charge, e-.
    y_mm, x_mm, heights_mm, angles_deg, keep, reference_deg
        As :func:`lean_shares`; ``y_mm`` and ``x_mm`` give ``q``'s rows and columns.
    leans : tuple of four (3, 3) arrays
        As :func:`.stencil.leaning_spread`.
    row0 : int
        The sensor's row number of ``q``'s first row.

    Returns
    -------
    (rows, cols) float64 array
    """
    q = np.ascontiguousarray(q, np.float32 if q.dtype == np.float32 else np.float64)
    ks = [np.ascontiguousarray(k, np.float64) for k in leans]
    out = np.zeros(q.shape)
    heights_mm, angles_deg = _line(heights_mm), _line(angles_deg)
    with ONE_LAUNCH:
        _leaning(q, _line(y_mm), _line(x_mm), heights_mm, angles_deg, slopes(heights_mm, angles_deg), float(keep),
                 float(reference_deg), ks[0], ks[1], ks[2], ks[3], int(row0), out)
    return out


__all__ = ["ready", "shade", "lean_shares", "leaning_spread", "RI_NONE", "RI_COS4", "RI_TABLE"]
