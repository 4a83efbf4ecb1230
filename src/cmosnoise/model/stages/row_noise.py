"""Stage 7, row noise (e-): one value per row, added to the whole row.

Temporal: ``Normal(0, sigma_e)`` per row per frame (paper Section VII-C;
noise entering through the reset, transfer-gate or read lines), or, with
``spectrum = one_over_f``, a 1/f process of the same rms sampled at each
row's readout time (:class:`Flicker`): row ``r`` of frame ``k`` is read at
``(k rows + r) row_time``, the rows of a frame after those of the frame
before (a rolling readout without blanking), so the banding drifts slowly
and correlates from frame to frame. The fixed
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

from dataclasses import dataclass

import numpy as np

from ...engine import fixed_maps, gauss_markov
from ...engine.samplers import Stream
from ..one_over_f import Spectrum


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


@dataclass(frozen=True)
class Flicker:
    """The 1/f row offsets of ``row_noise.spectrum = one_over_f``: a call gives a frame's, e-.

    Parameters
    ----------
    sigma_e : float
        The offsets' rms, e- (the stage's sigma).
    spectrum : Spectrum
        The unit-variance process's Lorentzians (:func:`cmosnoise.model.one_over_f.lorentzians`).
    rows : int
        The sensor's rows: row ``r`` of frame ``k`` is grid point ``k rows + r``.
    row_time_s : float
        The time between two rows' readouts, s (the frame period over the rows).
    key : (int, int)
        The stream's key words (:func:`cmosnoise.model.seeds.stream_key` of ``row_noise_flicker``).
    first, count : int
        The rows a call makes: ``first <= r < first + count`` (a window's).
    """

    sigma_e: float
    spectrum: Spectrum
    rows: int
    row_time_s: float
    key: tuple[int, int]
    first: int
    count: int

    def __call__(self, frame: int, sequence: int) -> np.ndarray:
        """Frame ``frame``'s offsets of rows ``first`` to ``first + count``, (count,) float64 e-.

        Parameters
        ----------
        frame : int
            The frame's number.
        sequence : int
            The frame series (each has its own process).

        Returns
        -------
        (count,) float64, e-
            ``sigma_e x((frame rows + r) row_time)``.
        """
        n0 = int(frame) * self.rows + self.first
        x = gauss_markov.sample(self.spectrum.rates_per_s, self.spectrum.weights, self.row_time_s, n0,
                                n0 + self.count, self.key, int(sequence))
        return self.sigma_e * x
