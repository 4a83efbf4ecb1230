"""Stage 8, column noise (e-): column amplifiers and sample-and-hold (paper Section VII-D).

- Temporal: each column has a fixed sigma drawn once from
  ``gumbel_r(loc, scale)`` clipped at 0 (a few columns much noisier than the
  rest); in each frame the column gets ``Normal(0, sigma_c)``.
- Vertical fixed pattern noise (VFPN): one ``Normal(0, vfpn_sigma_e)``
  offset per column, fixed.
- Optional column gain mismatch ``Normal(1, gain_sigma_pct / 100)``, fixed,
  scaling the signal that passes through the column amplifier.
"""

from __future__ import annotations

import numpy as np

from ...engine.samplers import Stream
from ..distributions import gumbel


def temporal_sigma_map(cols: int, gumbel_loc_e: float, gumbel_scale_e: float, rng: np.random.Generator) -> np.ndarray:
    """Fixed per-column temporal sigma (e-), shape (1, cols), float32, >= 0."""
    s = gumbel(gumbel_loc_e, gumbel_scale_e).ppf(rng.random(cols))
    return np.maximum(s, 0.0).astype(np.float32)[None, :]


def vfpn_offsets(cols: int, vfpn_sigma_e: float, rng: np.random.Generator) -> np.ndarray:
    """Fixed per-column offsets (e-), shape (1, cols), float32."""
    return (vfpn_sigma_e * rng.standard_normal(cols)).astype(np.float32)[None, :]


def gain_map(cols: int, gain_sigma_pct: float, rng: np.random.Generator) -> np.ndarray:
    """Fixed per-column gain, dimensionless, shape (1, cols), float32, clipped at 0."""
    return np.maximum(1.0 + gain_sigma_pct / 100.0 * rng.standard_normal(cols), 0.0).astype(np.float32)[None, :]


def temporal(sigma: np.ndarray, columns: np.ndarray, stream: Stream) -> np.ndarray:
    """One frame's column noise (e-) of the column numbers ``columns``, shape (1, len), float64.

    ``sigma`` is the per-column sigma map (1, cols); ``Normal(0, sigma_c)`` per column.
    """
    columns = np.asarray(columns)
    return (np.asarray(sigma, np.float64)[0, columns] * stream.normal(columns))[None, :]


def apply(signal_e: np.ndarray, gain: np.ndarray | None, offset_e: np.ndarray | None) -> np.ndarray:
    """The column amplifier: ``signal * gain + offset`` per column (e-)."""
    out = signal_e * gain if gain is not None else signal_e
    if offset_e is not None:
        out = out + offset_e
    return out
