"""Array layouts changed by compiled, cache-blocked loops: what NumPy does slowly at tens of megapixels.

A channel-interleaved image (rows, cols, C) made from planes held transposed (cols, rows), as a separable
resampling gives them (:func:`cmosnoise.model.scene.resample`): NumPy's strided copy walks one of the two
arrays against its memory order and took 3 to 5 s at 50 MP; blocks of 64 x 64 that both fit in cache, in
parallel over row blocks, take a tenth of it. Only values move, so the result is the same bits.
"""

from __future__ import annotations

import numpy as np

from .jit import ONE_LAUNCH, announce, numba  # None where numba is not installed

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
        if numba is None or plane.size < 1 << 16:  # small: NumPy's copy is quick, and nothing compiled is loaded
            out[..., c] = plane.T
            continue
        announce("the image interleave", _interleave)
        with ONE_LAUNCH:
            _interleave(plane, out, c)
    return out
