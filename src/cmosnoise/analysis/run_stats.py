"""Run statistics gathered frame by frame, with bounded memory.

Temporal noise is measured the EMVA 1288 way, from differences of
consecutive frames: for frames A and B of the same scene,
``var(A - B) / 2`` over the pixels is the temporal variance, free of the
fixed pattern. Only the previous frame is kept.

Each frame's sums come from one pass over it (compiled by numba, parallel
over rows, per-row float64 sums added in row order, so the result does not
depend on the thread count); :func:`frame_sums_numpy` is the same with
NumPy, the fallback without numba and the reference in tests.
"""

from __future__ import annotations

import numpy as np

from ..engine.jit import ONE_LAUNCH, compiled, numba  # None where numba is not installed

#: the sums one frame contributes: e- total, DN total, saturated count, and,
#: against the previous frame, sum and sum of squares of the differences (DN, e-)
_FIELDS = ("sum_e", "sum_dn", "saturated", "d_dn", "d2_dn", "d_e", "d2_e")


def frame_sums_numpy(raw, electrons, prev_raw, prev_e, max_code: float) -> np.ndarray:
    """The sums of :data:`_FIELDS` for one frame, with NumPy (``prev_*`` may be None)."""
    out = np.zeros(len(_FIELDS))
    out[0] = electrons.sum(dtype=np.float64)
    out[1] = raw.sum(dtype=np.float64)
    out[2] = np.count_nonzero(raw >= max_code)
    if prev_raw is not None:
        for i, (a, b) in ((3, (raw, prev_raw)), (5, (electrons, prev_e))):
            d = np.subtract(a, b, dtype=np.float64)
            out[i] = d.sum()
            np.square(d, out=d)
            out[i + 1] = d.sum()
    return out


if numba is not None:
    # A row's sums run in the CPU's vector lanes: each function below may reassociate its additions (``reassoc``;
    # nothing else of fast math: no fused multiply-add, no approximations), so LLVM vectorizes them, some five
    # times faster than one chain of additions per sum (2.4 against 0.5 ns a pixel on one thread, measured with
    # a previous frame). A row's sums then depend on the vector width these loops were compiled for (how many
    # lanes), not on the thread count: the rows are added in order.
    _LANES_MATH = {"reassoc", "nsz"}

    @numba.njit(cache=True, nogil=True, fastmath=_LANES_MATH, error_model="numpy")
    def _row_sums(x, y, max_code, acc):  # pragma: no cover - compiled
        """One row's e- total, DN total and saturated count into ``acc[:3]``."""
        s_e = 0.0
        s_dn = 0.0
        sat = 0.0
        for c in range(x.size):
            v = np.float64(x[c])
            s_e += np.float64(y[c])
            s_dn += v
            sat += 1.0 if v >= max_code else 0.0
        acc[0] = s_e
        acc[1] = s_dn
        acc[2] = sat

    @numba.njit(cache=True, nogil=True, fastmath=_LANES_MATH, error_model="numpy")
    def _row_differences(x, y, px, py, acc):  # pragma: no cover - compiled
        """One row's sums of the differences from the previous frame and of their squares (DN, e-) into
        ``acc[3:]``."""
        d1 = 0.0
        d2 = 0.0
        e1 = 0.0
        e2 = 0.0
        for c in range(x.size):
            d = np.float64(x[c]) - np.float64(px[c])
            d1 += d
            d2 += d * d
            f = np.float64(y[c]) - np.float64(py[c])
            e1 += f
            e2 += f * f
        acc[3] = d1
        acc[4] = d2
        acc[5] = e1
        acc[6] = e2

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _frame_sums(raw, electrons, prev_raw, prev_e, max_code, has_prev):  # pragma: no cover - compiled
        rows = raw.shape[0]
        acc = np.zeros((rows, 7))
        for r in numba.prange(rows):
            _row_sums(raw[r], electrons[r], max_code, acc[r])
            if has_prev:
                _row_differences(raw[r], electrons[r], prev_raw[r], prev_e[r], acc[r])
        out = np.zeros(7)
        for r in range(rows):  # in row order: the same bits on any number of threads
            for i in range(7):
                out[i] += acc[r, i]
        return out


def frame_sums(raw, electrons, prev_raw, prev_e, max_code: float) -> np.ndarray:
    """The sums of :data:`_FIELDS` for one (rows, cols) frame; compiled where numba is installed."""
    if numba is None or raw.ndim != 2 or not compiled("the run statistics", _frame_sums, _row_sums, _row_differences):
        return frame_sums_numpy(raw, electrons, prev_raw, prev_e, max_code)
    has_prev = prev_raw is not None
    with ONE_LAUNCH:
        return _frame_sums(raw, electrons, prev_raw if has_prev else raw, prev_e if has_prev else electrons,
                           float(max_code), has_prev)


class RunStats:
    """Accumulates mean signal and temporal noise (e- and DN) over frames."""

    def __init__(self, max_code: int):
        self.max_code = max_code
        self.n = 0
        self._size = 0
        self._sums = np.zeros(len(_FIELDS))
        self._pair_sums: list[np.ndarray] = []  # per pair of frames: the sums of d_dn, d2_dn, d_e, d2_e
        self._prev: tuple[np.ndarray, np.ndarray] | None = None

    def update(self, raw: np.ndarray, electrons: np.ndarray) -> None:
        """Add one frame: ``raw`` (DN, or e- with the ADC off) and ``electrons`` (e-), kept until the next one."""
        prev = self._prev if self._prev is not None else (None, None)
        s = frame_sums(raw, electrons, prev[0], prev[1], self.max_code)
        self.n += 1
        self._size = raw.size
        self._sums[:3] += s[:3]
        if self._prev is not None:
            self._pair_sums.append(s[3:7].copy())
        self._prev = (raw, electrons)

    def absorb(self, other: RunStats) -> None:
        """Add the sums of ``other``: the same frames of another part of the frame (a tile), so that the result
        is that of the whole frame's pixels; ``other`` keeps its own."""
        if self.n == 0:
            self.n, self._pair_sums = other.n, [p.copy() for p in other._pair_sums]
        elif other.n != self.n:
            raise ValueError(f"RunStats.absorb: {other.n} frames against {self.n}; parts must hold the same frames")
        else:
            for mine, theirs in zip(self._pair_sums, other._pair_sums):
                mine += theirs
        self._size += other._size
        self._sums += other._sums

    def result(self) -> dict:
        if self.n == 0:
            return {}
        px = self.n * self._size
        out = {
            "frames": self.n,
            "mean_e": float(self._sums[0] / px),
            "mean_dn": float(self._sums[1] / px),
            "saturated_fraction": float(self._sums[2] / px),
        }
        pairs = len(self._pair_sums)
        if pairs:
            n = self._size
            tvar = np.zeros(2)  # sum over pairs of var(A - B) / 2: DN, e-
            for s in self._pair_sums:
                tvar += [(s[1] - s[0] ** 2 / n) / n / 2, (s[3] - s[2] ** 2 / n) / n / 2]
            out["temporal_noise_dn"] = float(np.sqrt(tvar[0] / pairs))
            out["temporal_noise_e"] = float(np.sqrt(tvar[1] / pairs))
            out["temporal_noise_method"] = f"var(frame k - frame k-1)/2 over pixels, mean of {pairs} pairs"
        else:
            out["temporal_noise_e"] = None
            out["temporal_noise_dn"] = None
            out["temporal_noise_method"] = "needs at least 2 frames"
        return out
