"""A 2-D kernel as a short sum of separable terms, the same bits on any machine.

A point spread function sampled on a grid is a small matrix ``K``. Its singular value decomposition writes it as
``sum_r s_r u_r v_r^T``; a radially symmetric PSF needs few terms (the polychromatic Airy core of
:mod:`cmosnoise.model.optics`: four to six for a largest error of 1e-4 of its peak), and each term is a pass
along the rows and one along the columns: a convolution by a kernel of side ``n`` then costs ``2 R n`` products a
sample instead of ``n^2``, and folds into the separable weights that resample a picture (:mod:`cmosnoise.model.
focal_plane`).

LAPACK's SVD sums through BLAS kernels that differ between CPUs in their last bits, and the kernel's bits are the
frames' bits. So the decomposition here is the one-sided Jacobi method (Hestenes 1958; Demmel and Veselic 1992)
written with element-wise NumPy operations, each one correctly rounded, and ``math.fsum`` (correctly rounded too)
for every sum: each step is a fixed sequence of IEEE operations, so any machine gives the same terms.

The rotations are also compiled (``_rotations``, numba): the same operations in the same order, each sum by
CPython's own ``fsum`` algorithm (Shewchuk's exact partials, then its half-even correction), so the compiled loop
gives the specification's bits, and a large core (a 113-sample Gaussian, f/16 on a fine grid) is split in
milliseconds instead of minutes of Python.

Examples
--------
>>> import numpy as np
>>> from cmosnoise.engine.separable import terms
>>> k = np.outer([1.0, 2.0, 1.0], [1.0, 2.0, 1.0]) / 16
>>> rows, cols = terms(k, 1e-12)
>>> len(rows), bool(np.allclose(np.outer(rows[0], cols[0]), k))
(1, True)
"""

from __future__ import annotations

import math

import numpy as np

from .jit import ONE_LAUNCH, compiled, numba  # None where numba is not installed

#: rotations stop once every pair of columns is orthogonal to this share of their norms
_ORTHOGONAL = 1e-15
#: the most sweeps over the pairs (a few suffice: the method converges quadratically)
_SWEEPS = 60

__all__ = ["svd", "terms"]


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    return math.fsum((a * b).tolist())


def svd(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The singular value decomposition of a small matrix, by one-sided Jacobi rotations in a fixed order.

    Parameters
    ----------
    matrix : (m, n) array
        Real and finite; ``m >= n`` is not required.

    Returns
    -------
    u : (m, p) float64 array
        Left singular vectors (columns), ``p = min(m, n)``.
    s : (p,) float64 array
        Singular values, largest first.
    vt : (p, n) float64 array
        Right singular vectors (rows).
    """
    a = np.array(matrix, dtype=np.float64)
    transposed = a.shape[0] < a.shape[1]
    if transposed:
        a = a.T.copy()
    m, n = a.shape
    if numba is not None and compiled("the PSF's separable split", _rotations):
        c_arr, v_arr = np.ascontiguousarray(a.T), np.eye(n)
        with ONE_LAUNCH:
            _rotations(c_arr, v_arr, _SWEEPS, _ORTHOGONAL)
        cols, v = list(c_arr), list(v_arr)
    else:
        cols, v = _rotations_numpy(a)
    sigma = np.array([math.sqrt(_dot(col, col)) for col in cols])
    order = sorted(range(n), key=lambda j: (-sigma[j], j))
    p = min(m, n)
    u = np.zeros((m, p))
    s_out = np.zeros(p)
    vt = np.zeros((p, n))
    for i, j in enumerate(order[:p]):
        s_out[i] = sigma[j]
        if sigma[j] > 0:
            u[:, i] = cols[j] / sigma[j]
        vt[i] = v[j]
    if transposed:
        return vt.T.copy(), s_out, u.T.copy()
    return u, s_out, vt


def _rotations_numpy(a: np.ndarray) -> tuple[list, list]:
    """The one-sided Jacobi rotations of ``a``'s columns (m, n): (the rotated columns, the rotations' rows), each
    a list of n arrays. The specification of ``_rotations``."""
    n = a.shape[1]
    cols = [a[:, j].copy() for j in range(n)]
    v = [np.eye(n)[j].copy() for j in range(n)]
    for _ in range(_SWEEPS):
        rotated = False
        for p in range(n - 1):
            for q in range(p + 1, n):
                alpha, beta, gamma = _dot(cols[p], cols[p]), _dot(cols[q], cols[q]), _dot(cols[p], cols[q])
                if gamma == 0.0 or abs(gamma) <= _ORTHOGONAL * math.sqrt(alpha * beta):
                    continue
                rotated = True
                zeta = (beta - alpha) / (2.0 * gamma)
                t = math.copysign(1.0, zeta) / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
                c = 1.0 / math.sqrt(1.0 + t * t)
                s = c * t
                cp, cq = cols[p], cols[q]
                cols[p], cols[q] = c * cp - s * cq, s * cp + c * cq
                vp, vq = v[p], v[q]
                v[p], v[q] = c * vp - s * vq, s * vp + c * vq
        if not rotated:
            break
    return cols, v


_rotations = _fsum_products = None
if numba is not None:
    @numba.njit(cache=True, nogil=True)
    def _fsum_products(a, b, partials):
        """``math.fsum(a * b)``: the correctly rounded sum of the rounded products, by CPython's algorithm
        (finite values; ``partials`` a scratch array of at least ``a.size + 1``)."""
        n = 0
        for k in range(a.size):
            x = a[k] * b[k]
            i = 0
            for j in range(n):
                y = partials[j]
                if abs(x) < abs(y):
                    x, y = y, x
                hi = x + y
                yr = hi - x
                lo = y - yr
                if lo != 0.0:
                    partials[i] = lo
                    i += 1
                x = hi
            n = i
            if x != 0.0:
                partials[n] = x
                n += 1
        hi = 0.0
        if n > 0:
            n -= 1
            hi = partials[n]
            lo = 0.0
            while n > 0:
                x = hi
                n -= 1
                y = partials[n]
                hi = x + y
                yr = hi - x
                lo = y - yr
                if lo != 0.0:
                    break
            if n > 0 and ((lo < 0.0 and partials[n - 1] < 0.0) or (lo > 0.0 and partials[n - 1] > 0.0)):
                y = lo * 2.0
                x = hi + y
                yr = x - hi
                if y == yr:
                    hi = x
        return hi

    @numba.njit(cache=True, nogil=True)
    def _rotations(cols, v, sweeps, orthogonal):
        """``_rotations_numpy`` in place: ``cols`` (n, m), a row for each column of the matrix; ``v`` (n, n) the
        identity at the start."""
        n, m = cols.shape
        partials = np.empty(m + 1)
        for _ in range(sweeps):
            rotated = False
            for p in range(n - 1):
                for q in range(p + 1, n):
                    alpha = _fsum_products(cols[p], cols[p], partials)
                    beta = _fsum_products(cols[q], cols[q], partials)
                    gamma = _fsum_products(cols[p], cols[q], partials)
                    if gamma == 0.0 or abs(gamma) <= orthogonal * math.sqrt(alpha * beta):
                        continue
                    rotated = True
                    zeta = (beta - alpha) / (2.0 * gamma)
                    t = math.copysign(1.0, zeta) / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
                    c = 1.0 / math.sqrt(1.0 + t * t)
                    s = c * t
                    for i in range(m):
                        cp, cq = cols[p, i], cols[q, i]
                        cols[p, i] = c * cp - s * cq
                        cols[q, i] = s * cp + c * cq
                    for i in range(n):
                        vp, vq = v[p, i], v[q, i]
                        v[p, i] = c * vp - s * vq
                        v[q, i] = s * vp + c * vq
            if not rotated:
                break


def terms(kernel: np.ndarray, tolerance: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The fewest separable terms whose sum is within ``tolerance`` of ``kernel``'s peak everywhere, with its sum.

    Parameters
    ----------
    kernel : (m, n) array
        A kernel (a PSF on a grid), real and finite.
    tolerance : float
        The largest error allowed at any sample, relative to the kernel's largest absolute value.

    Returns
    -------
    rows, cols : lists of (m,) and (n,) float64 arrays
        ``kernel ~ sum_r outer(rows[r], cols[r])``; the first term is scaled so that the sum's total is the
        kernel's own (``math.fsum`` of both), so a flat field keeps its level. A zero kernel gives one zero term.
    """
    k = np.asarray(kernel, dtype=np.float64)
    peak = float(np.abs(k).max())
    if peak == 0.0:
        return [np.zeros(k.shape[0])], [np.zeros(k.shape[1])]
    u, s, vt = svd(k)
    rows, cols = [], []
    approx = np.zeros_like(k)
    for r in range(s.size):
        if s[r] == 0.0:
            break
        # the singular value split evenly between the two factors
        root = math.sqrt(s[r])
        rows.append(u[:, r] * root)
        cols.append(vt[r] * root)
        approx = approx + np.outer(rows[-1], cols[-1])
        if float(np.abs(approx - k).max()) <= tolerance * peak:
            break
    total = math.fsum(k.ravel().tolist())
    have = math.fsum(approx.ravel().tolist())
    first = math.fsum(rows[0].tolist()) * math.fsum(cols[0].tolist())
    if first != 0.0 and have != total:
        rows[0] = rows[0] * (1.0 + (total - have) / first)
    return rows, cols
