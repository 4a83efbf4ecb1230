"""Stage 7, row noise (e-): one value per row, added to the whole row.

Temporal: ``Normal(0, sigma_e)`` per row per frame (paper Section VII-C;
noise entering through the reset, transfer-gate or read lines). The fixed
row component, which the paper neglects, is optional: ``Normal(0,
fixed_sigma_e)`` per row, drawn once.

Examples
--------
>>> from cmosnoise import seeds
>>> from cmosnoise.model.stages import row_noise
>>> offsets = row_noise.fixed_offsets(0, 480, 1.0, seeds.fixed_key(0, "row_noise"))   # fixed row offsets, e-
>>> offsets.shape, 0.85 < float(offsets.std()) < 1.15
((480, 1), True)
"""

from __future__ import annotations

import numpy as np

from ...engine import fixed_maps
from ...engine.samplers import Stream


def fixed_offsets(row0: int, row1: int, fixed_sigma_e: float, key: tuple[int, int]) -> np.ndarray:
    """Fixed offsets of rows ``row0`` to ``row1``; row ``r``'s from its own counter under the map's fixed ``key``
    (:func:`cmosnoise.engine.fixed_maps.lines`).

    Parameters
    ----------
    row0, row1 : int
        The rows to make, ``row0 <= r < row1``.
    fixed_sigma_e : float
        Standard deviation of the offsets, e-.
    key : (int, int)
        The map's fixed key (:func:`cmosnoise.model.seeds.fixed_key`).

    Returns
    -------
    (row1 - row0, 1) float32 array, e-
        Each row's offset, Normal(0, ``fixed_sigma_e``).
    """
    return (fixed_sigma_e * fixed_maps.lines(row0, row1, key)).astype(np.float32)[:, None]


def temporal(rows: np.ndarray, sigma_e: float, stream: Stream) -> np.ndarray:
    """One frame's row noise of the row numbers ``rows``.

    Parameters
    ----------
    rows : (n,) int array
        Row numbers (a row's noise is drawn at its own number: a crop gets the whole sensor's values).
    sigma_e : float
        Standard deviation, e-.
    stream : Stream
        The frame's stream of the stage (:func:`cmosnoise.model.seeds.temporal_stream`).

    Returns
    -------
    (n, 1) float64 array, e-
        One Normal(0, ``sigma_e``) value per row.
    """
    return (sigma_e * stream.normal(np.asarray(rows)))[:, None]
