"""Run statistics gathered frame by frame, with bounded memory.

Temporal noise is measured the EMVA 1288 way, from differences of
consecutive frames: for frames A and B of the same scene,
``var(A - B) / 2`` over the pixels is the temporal variance, free of the
fixed pattern. Only the previous frame is kept.
"""

from __future__ import annotations

import numpy as np

from .emva import temporal_variance


class RunStats:
    """Accumulates mean signal and temporal noise (e- and DN) over frames."""

    def __init__(self, max_code: int):
        self.max_code = max_code
        self.n = 0
        self._sum_mean_e = 0.0
        self._sum_mean_dn = 0.0
        self._sum_sat = 0
        self._pairs = 0
        self._sum_tvar_e = 0.0
        self._sum_tvar_dn = 0.0
        self._prev: tuple[np.ndarray, np.ndarray] | None = None

    def update(self, raw: np.ndarray, electrons: np.ndarray) -> None:
        raw64 = raw.astype(np.float64)
        e64 = electrons.astype(np.float64)
        self.n += 1
        self._sum_mean_e += e64.mean()
        self._sum_mean_dn += raw64.mean()
        self._sum_sat += int(np.count_nonzero(raw >= self.max_code))
        if self._prev is not None:
            self._sum_tvar_dn += temporal_variance(raw64, self._prev[0])
            self._sum_tvar_e += temporal_variance(e64, self._prev[1])
            self._pairs += 1
        self._prev = (raw64, e64)

    def result(self) -> dict:
        if self.n == 0:
            return {}
        out = {
            "frames": self.n,
            "mean_e": self._sum_mean_e / self.n,
            "mean_dn": self._sum_mean_dn / self.n,
            "saturated_fraction": self._sum_sat / (self.n * self._prev[0].size),
        }
        if self._pairs:
            out["temporal_noise_e"] = float(np.sqrt(self._sum_tvar_e / self._pairs))
            out["temporal_noise_dn"] = float(np.sqrt(self._sum_tvar_dn / self._pairs))
            out["temporal_noise_method"] = f"var(frame k - frame k-1)/2 over pixels, mean of {self._pairs} pairs"
        else:
            out["temporal_noise_e"] = None
            out["temporal_noise_dn"] = None
            out["temporal_noise_method"] = "needs at least 2 frames"
        return out
