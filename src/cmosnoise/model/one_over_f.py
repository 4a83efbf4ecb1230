"""1/f noise in time as McWhorter's superposition of Lorentzians, and what it implies.

A process whose power spectrum falls as ``1/f`` between two corner
frequencies is a sum of first-order Gauss-Markov (Lorentzian) processes
whose corners are spread log-uniformly over that range, with equal
variances (McWhorter 1957; the superposition of traps with log-uniformly
spread time constants). With ``n`` components per unit of ``ln f`` each of
variance ``v``, the one-sided spectrum between the corners is
``n v / f``: a Lorentzian of corner ``f_c`` (autocorrelation
``exp(-2 pi f_c |tau|)``) has the one-sided spectrum
``S(f) = (2 / (pi f_c)) / (1 + (f / f_c)^2)`` per unit variance, and
``int_0^inf (2 / (pi f_c)) / (1 + (f / f_c)^2) d ln f_c = 1 / f``.

:func:`lorentzians` makes the components, :func:`psd` and
:func:`autocorrelation` say what a process made of them is, and
:func:`cds_variance` the variance of the difference of two samples
``dt`` apart (a correlated double sampling's output): ``2 (1 - rho(dt))``,
which equals ``int S(f) |2 sin(pi f dt)|^2 df``. The processes themselves
are sampled by :mod:`cmosnoise.engine.gauss_markov`.

Examples
--------
>>> from cmosnoise.model import one_over_f
>>> s = one_over_f.lorentzians(1.0, 1000.0)
>>> s.corners_hz.size, round(float(s.weights.sum()), 12)
(6, 1.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Lorentzians per decade of corner frequency: the sum's f S(f) ripples by under 1 % between the corners (0.6 % measured)
PER_DECADE = 2
#: the names of the spectra a stage's ``spectrum`` key takes
SPECTRA = ("white", "one_over_f")


@dataclass(frozen=True)
class Spectrum:
    """A unit-variance process as a sum of Lorentzians.

    Attributes
    ----------
    corners_hz : (J,) float64
        Each component's corner frequency, Hz.
    weights : (J,) float64
        Each component's variance (they sum to 1).
    """

    corners_hz: np.ndarray
    weights: np.ndarray

    @property
    def rates_per_s(self) -> np.ndarray:
        """Each component's decay rate ``2 pi f_c``, 1/s."""
        return 2.0 * math.pi * self.corners_hz


def lorentzians(low_hz: float, high_hz: float, per_decade: int = PER_DECADE) -> Spectrum:
    """The components of a unit-variance 1/f process between two corner frequencies.

    Parameters
    ----------
    low_hz, high_hz : float
        The lowest and highest corner, Hz, ``0 < low_hz < high_hz``.
    per_decade : int
        Components per decade (at least one component in all).

    Returns
    -------
    Spectrum
        ``J = ceil(per_decade log10(high / low))`` corners at the midpoints of equal steps of ``log f``, each
        of variance ``1 / J``.
    """
    if not (0 < low_hz < high_hz and math.isfinite(high_hz)):
        raise ValueError(f"corner frequencies {low_hz}..{high_hz} Hz: need 0 < low < high, finite")
    n = max(1, math.ceil(per_decade * math.log10(high_hz / low_hz) - 1e-9))
    steps = (np.arange(n) + 0.5) / n
    return Spectrum(low_hz * (high_hz / low_hz) ** steps, np.full(n, 1.0 / n))


def psd(spectrum: Spectrum, f_hz) -> np.ndarray:
    """The one-sided power spectral density of the process, per Hz (its integral over ``f > 0`` is 1).

    Parameters
    ----------
    spectrum : Spectrum
        The components.
    f_hz : array_like
        Frequencies, Hz.

    Returns
    -------
    ndarray, 1/Hz
        ``sum_j w_j (2 / (pi f_j)) / (1 + (f / f_j)^2)``.
    """
    f = np.asarray(f_hz, np.float64)[..., None]
    fc, w = spectrum.corners_hz, spectrum.weights
    return np.sum(w * (2.0 / (math.pi * fc)) / (1.0 + (f / fc) ** 2), axis=-1)


def autocorrelation(spectrum: Spectrum, lag_s) -> np.ndarray:
    """The process's autocorrelation at ``lag_s``: ``sum_j w_j exp(-2 pi f_j |lag|)``.

    Parameters
    ----------
    spectrum : Spectrum
        The components.
    lag_s : array_like
        Lags, s.

    Returns
    -------
    ndarray
        The correlation of two samples ``lag_s`` apart.
    """
    lag = np.abs(np.asarray(lag_s, np.float64))[..., None]
    return np.sum(spectrum.weights * np.exp(-spectrum.rates_per_s * lag), axis=-1)


def cds_variance(spectrum: Spectrum, dt_s) -> np.ndarray:
    """The variance of ``x(t + dt) - x(t)`` of the unit-variance process: ``2 (1 - rho(dt))``.

    It is the integral of the spectrum through the correlated double sampling's transfer,
    ``int_0^inf S(f) |2 sin(pi f dt)|^2 df`` (for each Lorentzian the integral is
    ``2 (1 - exp(-2 pi f_c dt))``).

    Parameters
    ----------
    spectrum : Spectrum
        The components.
    dt_s : array_like
        The interval between the two samples, s.

    Returns
    -------
    ndarray
        The difference's variance, per unit variance of the process.
    """
    return 2.0 * (1.0 - autocorrelation(spectrum, dt_s))


def row_corners(frame_rate_hz: float, rows: int) -> tuple[float, float]:
    """The row noise's default 1/f range, Hz: a thousandth of the frame rate to the lesser of half the row rate
    (``rows x frame rate``) and a thousand times the frame rate."""
    return frame_rate_hz / 1000.0, min(0.5 * frame_rate_hz * rows, 1000.0 * frame_rate_hz)


def column_corners(frame_rate_hz: float) -> tuple[float, float]:
    """The column amplifiers' default 1/f range, Hz: a thousandth of the frame rate to half of it."""
    return frame_rate_hz / 1000.0, 0.5 * frame_rate_hz


def pixel_corners(frame_rate_hz: float) -> tuple[float, float]:
    """A pixel's default 1/f flicker range, Hz: a thousandth of the frame rate to a thousand times it."""
    return frame_rate_hz / 1000.0, 1000.0 * frame_rate_hz


def corners(key: str, given, default: tuple[float, float], frame_rate_hz: float) -> tuple[float, float]:
    """A stage's 1/f range, Hz: ``given`` (a ``corner_hz`` pair) checked against the frame rate, or ``default``.

    Parameters
    ----------
    key : str
        The configuration key, for the message.
    given : (float, float) or None
        The configured corners (the schema has checked ``0 < low < high``).
    default : (float, float)
        The corners when ``given`` is None.
    frame_rate_hz : float
        Frames per second: the highest corner may be at most a thousand times it.

    Returns
    -------
    (float, float)
        The lowest and highest corner, Hz.

    Raises
    ------
    ValueError
        Naming the key, the value and what is allowed.
    """
    if given is None:
        return default
    low, high = (float(v) for v in given)
    if high > 1000.0 * frame_rate_hz:
        raise ValueError(f"{key} = [{low:g}, {high:g}]: the highest corner must be at most a thousand times the "
                         f"frame rate, {1000.0 * frame_rate_hz:g} Hz (the corners lie in (0, frame rate x 1000])")
    return low, high
