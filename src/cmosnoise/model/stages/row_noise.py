"""Stage 7, row noise (e-): one value per row, added to the whole row.

Temporal: ``Normal(0, sigma_e)`` per row per frame (paper Section VII-C;
noise entering through the reset, transfer-gate or read lines). The fixed
row component, which the paper neglects, is optional: ``Normal(0,
fixed_sigma_e)`` per row, drawn once.
"""

from __future__ import annotations

import numpy as np

from ...engine.samplers import Stream


def fixed_offsets(rows: int, fixed_sigma_e: float, rng: np.random.Generator) -> np.ndarray:
    """Fixed per-row offsets (e-), shape (rows, 1), float32."""
    return (fixed_sigma_e * rng.standard_normal((rows, 1))).astype(np.float32)


def temporal(rows: np.ndarray, sigma_e: float, stream: Stream) -> np.ndarray:
    """One frame's row noise (e-) of the row numbers ``rows``, shape (len(rows), 1), float64."""
    return (sigma_e * stream.normal(np.asarray(rows)))[:, None]
