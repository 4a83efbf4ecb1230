"""Stage 8, column noise (e-): column amplifiers and sample-and-hold (paper Section VII-D).

- Temporal: each column has a fixed sigma drawn once from
  ``gumbel_r(loc, scale)`` clipped at 0 (a few columns much noisier than the
  rest); in each frame the column gets ``Normal(0, sigma_c)``, or, with
  ``temporal.spectrum = one_over_f``, ``sigma_c`` times its amplifier's own
  1/f process sampled at the frame's time (:class:`Flicker`).
- Vertical fixed pattern noise (VFPN): one ``Normal(0, vfpn_sigma_e)``
  offset per column, fixed.
- Optional column gain mismatch ``Normal(1, gain_sigma_pct / 100)``, fixed,
  scaling the signal that passes through the column amplifier.
- Two-phase column amplifiers (``alternating``): the even and the odd
  columns are read by two banks, each with its own offset, fixed
  (``Normal(0, fixed_sigma_e)`` per bank, once) and per frame
  (``Normal(0, temporal_sigma_e)`` per bank, every frame): the even/odd
  column pattern a dark frame shows (:func:`alternating_offsets`,
  :class:`Alternating`).

Examples
--------
>>> from cmosnoise import seeds
>>> from cmosnoise.model.stages import column_noise
>>> vfpn = column_noise.vfpn_offsets(0, 640, 6.0, seeds.fixed_key(0, "column_noise"))   # 6 e- of column offsets
>>> vfpn.shape, 5.0 < float(vfpn.std()) < 7.0
((1, 640), True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...engine import fixed_maps, gauss_markov
from ...engine.samplers import Stream
from ..distributions import gumbel
from ..one_over_f import Spectrum

# Each fixed column map covers columns ``col0`` to ``col1`` (the whole map: 0 to cols); column ``c``'s value comes
# from its own counter under the map's fixed key (cmosnoise.engine.fixed_maps.lines), so any span is made alone.


def temporal_sigma_map(col0: int, col1: int, gumbel_loc_e: float, gumbel_scale_e: float,
                       key: tuple[int, int]) -> np.ndarray:
    """Fixed per-column temporal sigma: the column amplifiers' noise differs from column to column (Gumbel).

    Parameters
    ----------
    col0, col1 : int
        The columns to make, ``col0 <= c < col1``.
    gumbel_loc_e, gumbel_scale_e : float
        Location and scale of the Gumbel distribution of the sigmas, e-.
    key : (int, int)
        The map's fixed key (:func:`cmosnoise.model.seeds.fixed_key`).

    Returns
    -------
    (1, col1 - col0) float32 array, e-, >= 0
        Each column's temporal sigma.
    """
    s = gumbel(gumbel_loc_e, gumbel_scale_e).ppf(fixed_maps.lines(col0, col1, key, "uniform"))
    return np.maximum(s, 0.0).astype(np.float32)[None, :]


def vfpn_offsets(col0: int, col1: int, vfpn_sigma_e: float, key: tuple[int, int]) -> np.ndarray:
    """Fixed per-column offsets (VFPN).

    Parameters
    ----------
    col0, col1 : int
        The columns to make, ``col0 <= c < col1``.
    vfpn_sigma_e : float
        Standard deviation of the offsets, e-.
    key : (int, int)
        The map's fixed key (:func:`cmosnoise.model.seeds.fixed_key`).

    Returns
    -------
    (1, col1 - col0) float32 array, e-
        Each column's offset, Normal(0, ``vfpn_sigma_e``).
    """
    return (vfpn_sigma_e * fixed_maps.lines(col0, col1, key)).astype(np.float32)[None, :]


def gain_map(col0: int, col1: int, gain_sigma_pct: float, key: tuple[int, int]) -> np.ndarray:
    """Fixed per-column gain of the column amplifiers.

    Parameters
    ----------
    col0, col1 : int
        The columns to make, ``col0 <= c < col1``.
    gain_sigma_pct : float
        Standard deviation of the gains, percent of 1.
    key : (int, int)
        The map's fixed key (:func:`cmosnoise.model.seeds.fixed_key`).

    Returns
    -------
    (1, col1 - col0) float32 array, dimensionless, >= 0
        Each column's gain, 1 + Normal(0, ``gain_sigma_pct`` / 100), clipped at 0.
    """
    g = 1.0 + gain_sigma_pct / 100.0 * fixed_maps.lines(col0, col1, key)
    return np.maximum(g, 0.0).astype(np.float32)[None, :]


def temporal(sigma: np.ndarray, columns: np.ndarray, stream: Stream, first: int = 0) -> np.ndarray:
    """One frame's column noise of the column numbers ``columns``: ``Normal(0, sigma_c)`` per column.

    Parameters
    ----------
    sigma : (1, cols) array, e-
        The per-column sigma map (:func:`temporal_sigma_map`): the whole sensor's, or a window's from column
        ``first``.
    columns : (n,) int array
        Column numbers (drawn at their own numbers: a crop gets the whole sensor's values).
    stream : Stream
        The frame's stream of the stage (:func:`cmosnoise.model.seeds.temporal_stream`).
    first : int
        The column number of ``sigma``'s first entry.

    Returns
    -------
    (1, n) float64 array, e-
    """
    columns = np.asarray(columns)
    return (np.asarray(sigma, np.float64)[0, columns - first] * stream.normal(columns))[None, :]


def apply(signal_e: np.ndarray, gain: np.ndarray | None, offset_e: np.ndarray | None) -> np.ndarray:
    """The column amplifier: ``signal * gain + offset`` per column.

    Parameters
    ----------
    signal_e : (rows, cols) array, e-
    gain : (1, cols) array, dimensionless, or None
        The column gains (:func:`gain_map`); None: 1.
    offset_e : (1, cols) or (rows, cols) array, e-, or None
        Column offsets (fixed and this frame's temporal ones); None: 0.

    Returns
    -------
    (rows, cols) array, e-
    """
    out = signal_e * gain if gain is not None else signal_e
    if offset_e is not None:
        out = out + offset_e
    return out


@dataclass(frozen=True)
class Flicker:
    """Each column amplifier's 1/f noise over frames (``column_noise.temporal.spectrum = one_over_f``).

    Parameters
    ----------
    sigma_e : (count,) float64
        Each column's sigma, e- (its temporal sigma map's values).
    spectrum : Spectrum
        The unit-variance process's Lorentzians.
    frame_period_s : float
        The time between two frames, s: frame ``k`` is grid point ``k``.
    key : (int, int)
        The stream's key words (``column_noise_flicker``); column ``c`` is lane ``c``.
    first, count : int
        The columns a call makes, ``first <= c < first + count`` (a window's).
    """

    sigma_e: np.ndarray
    spectrum: Spectrum
    frame_period_s: float
    key: tuple[int, int]
    first: int
    count: int

    def __call__(self, frame: int, sequence: int) -> np.ndarray:
        """Frame ``frame``'s noise of the columns, (count,) float64 e-.

        Parameters
        ----------
        frame : int
            The frame's number.
        sequence : int
            The frame series.

        Returns
        -------
        (count,) float64, e-
            Each column's sigma times its process at ``frame frame_period_s``.
        """
        x = gauss_markov.sample(self.spectrum.rates_per_s, self.spectrum.weights, self.frame_period_s, int(frame),
                                int(frame) + 1, self.key, int(sequence),
                                lanes=np.arange(self.first, self.first + self.count))
        return self.sigma_e * x[:, 0]


def alternating_offsets(col0: int, col1: int, sigma_e: float, key: tuple[int, int]) -> np.ndarray:
    """The two banks' fixed offsets on columns ``col0`` to ``col1``: the even columns get bank 0's, the odd bank 1's.

    Parameters
    ----------
    col0, col1 : int
        The columns, ``col0 <= c < col1``.
    sigma_e : float
        Each bank's offset's standard deviation, e-.
    key : (int, int)
        The map's fixed key (``column_noise``, part 3): bank ``b``'s value is line ``b`` of it.

    Returns
    -------
    (1, col1 - col0) float32 array, e-
        Each column's bank offset.
    """
    banks = sigma_e * fixed_maps.lines(0, 2, key)
    return banks[np.arange(col0, col1) % 2].astype(np.float32)[None, :]


@dataclass(frozen=True)
class Alternating:
    """The two banks' offsets per frame (``column_noise.alternating.temporal_sigma_e``): a call gives a frame's.

    Parameters
    ----------
    sigma_e : float
        Each bank's offset's standard deviation per frame, e-.
    key : (int, int)
        The stream's key words (``column_noise_alternating``): bank ``b``'s normal is index ``b`` of the frame.
    first, count : int
        The columns a call makes, ``first <= c < first + count``.
    """

    sigma_e: float
    key: tuple[int, int]
    first: int
    count: int

    def __call__(self, frame: int, sequence: int) -> np.ndarray:
        """Frame ``frame``'s bank offset of each column, (count,) float64 e-.

        Parameters
        ----------
        frame : int
            The frame's number.
        sequence : int
            The frame series.

        Returns
        -------
        (count,) float64, e-
            Bank ``c mod 2``'s offset in the frame.
        """
        banks = self.sigma_e * Stream(self.key, int(frame), int(sequence)).normal(np.arange(2))
        return banks[np.arange(self.first, self.first + self.count) % 2]


@dataclass(frozen=True)
class Summed:
    """Several per-frame column offsets (each a call of ``(frame, sequence)`` giving (count,) e-) added in order.

    Parameters
    ----------
    parts : tuple of callables
        The parts, each like :class:`Flicker` or :class:`Alternating`.
    """

    parts: tuple

    def __call__(self, frame: int, sequence: int) -> np.ndarray:
        """The parts' sum in frame ``frame``, (count,) float64 e-.

        Parameters
        ----------
        frame : int
            The frame's number.
        sequence : int
            The frame series.

        Returns
        -------
        (count,) float64, e-
            The sum, the first part first.
        """
        total = self.parts[0](frame, sequence)
        for part in self.parts[1:]:
            total = total + part(frame, sequence)
        return total
