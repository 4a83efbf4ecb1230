"""The noise's power spectrum from a dark stack: over frames per pixel and per column, and along the readout order.

What a lab reads off a dark stack to tell white noise from 1/f noise in time
(docs/model.md stages 6 to 8): Welch's averaged periodogram (scipy.signal's
``welch``, Hann segments with half overlap) of

- each pixel's series over the frames, averaged over the pixels, less each
  frame's row and column means (what a row or a column amplifier adds to
  every pixel of it: a 1/f row noise is not a pixel's 1/f noise);
- each column's mean over its rows, over the frames, averaged over the columns
  (the column amplifiers), less each frame's mean over the columns (what all
  columns share in a frame: its rows' mean offset, a black-level error);
- the rows' means in readout order, the rows of frame ``k`` after those of
  frame ``k - 1`` (the row noise a rolling readout drifts with), less each
  frame's mean over its rows (what every row of a frame shares: its columns'
  mean noise), so the band starts at two cycles per frame.

Every series has its own mean over the stack taken away first (a fixed
pattern is not noise in time). The slope of ``log P`` against ``log f`` is
fitted over a band clear of the lowest bins (a segment's mean is taken away)
and of Nyquist, with its standard error: the regression's residual spread
over the spread of ``log f``, times ``sqrt(2)`` because a Hann window's
neighbouring bins are correlated. A spectrum is ``white`` when its slope
lies within 0.15 of 0, ``one_over_f`` when it lies within 0.5 of -1 and its
95 % interval below -0.15, and ``unresolved`` otherwise (a mix of the two,
or a stack too short to tell); a series too short for three Welch segments over the band is
refused with what it would need.

Examples
--------
>>> import numpy as np
>>> from cmosnoise.analysis import noise_spectrum
>>> stack = np.random.default_rng(0).normal(100.0, 2.0, (128, 16, 16))   # 128 frames of white noise
>>> noise_spectrum.over_frames(stack).verdict
'white'
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import signal

from ..errors import CmosnoiseError

#: fewest frames for a spectrum over frames: Welch segments of 32 frames, three of them with half overlap and more
MIN_FRAMES = 64
#: the longest Welch segment over frames (the issue's 2/256 to 1/4 cycles per frame at 512 frames)
MAX_SEGMENT_FRAMES = 256
#: fewest rows in readout order (a segment of 64 rows, eight of them)
MIN_READOUT_ROWS = 512
#: the longest Welch segment in readout order, rows
MAX_SEGMENT_ROWS = 4096
#: how many pixels' series are averaged at most (spread over the frame; their spectra's mean is precise enough)
MAX_PIXELS = 4096
#: a slope within this of 0 is white; one within 0.5 of -1 is 1/f
WHITE_SLOPE, FLICKER_SLOPE = 0.15, 0.5


@dataclass(frozen=True)
class SpectrumEstimate:
    """A Welch spectrum of a dark stack's series and its fitted slope.

    Parameters
    ----------
    series : str
        ``pixels over frames``, ``columns over frames`` or ``rows in readout order``.
    unit : str
        The frequency axis's unit: ``cycles per frame`` or ``cycles per row``.
    f : (n,) float64 array
        Frequencies, in ``unit``.
    psd : (n,) float64 array
        The one-sided spectral density, (the stack's unit)^2 per ``unit``.
    band : (float, float)
        The frequencies the slope is fitted over.
    slope : float
        The fitted slope of ``log psd`` against ``log f`` (0 white, -1 for 1/f).
    slope_se : float
        Its standard error.
    segments : int
        Welch segments averaged (per series).
    verdict : str
        ``white``, ``one_over_f`` or ``unresolved``.
    """

    series: str
    unit: str
    f: np.ndarray
    psd: np.ndarray
    band: tuple[float, float]
    slope: float
    slope_se: float
    segments: int
    verdict: str

    @property
    def interval(self) -> tuple[float, float]:
        """The slope's 95 % interval, ``slope +- 1.96 se``."""
        return self.slope - 1.96 * self.slope_se, self.slope + 1.96 * self.slope_se

    def summary(self) -> dict:
        """What ``characterization.json`` keeps: the slope, its interval, the band and the verdict (no arrays)."""
        d = asdict(self)
        d.pop("f")
        d.pop("psd")
        return {**d, "band": list(self.band), "interval": list(self.interval)}


def verdict(slope: float, se: float) -> str:
    """``white``, ``one_over_f`` or ``unresolved`` from a slope and its standard error (see the module)."""
    hi = slope + 1.96 * se
    if abs(slope) <= WHITE_SLOPE:
        return "white"
    if abs(slope + 1) <= FLICKER_SLOPE and hi < -WHITE_SLOPE:
        return "one_over_f"
    return "unresolved"


def _fit(series: str, unit: str, f: np.ndarray, p: np.ndarray, band: tuple[float, float],
         segments: int) -> SpectrumEstimate:
    inside = (f >= band[0]) & (f <= band[1]) & (p > 0)
    if np.count_nonzero(inside) < 4:
        raise CmosnoiseError(f"the {series} spectrum has {np.count_nonzero(inside)} bins in its band "
                             f"{band[0]:.4g} to {band[1]:.4g} {unit}: a longer stack is needed")
    x, y = np.log(f[inside]), np.log(p[inside])
    (slope, _), res, *_ = np.polyfit(x, y, 1, full=True)
    spread = math.sqrt(float(res[0]) / (x.size - 2)) if res.size and x.size > 2 else 0.0
    se = math.sqrt(2.0) * spread / math.sqrt(float(np.sum((x - x.mean()) ** 2)))
    return SpectrumEstimate(series, unit, f, p, band, float(slope), float(se), segments, verdict(float(slope), se))


def _stack(stack) -> np.ndarray:
    a = np.asarray(stack)
    if a.ndim != 3 or min(a.shape) < 1:
        raise CmosnoiseError(f"a dark stack: expected (frames, rows, cols), got shape {a.shape}")
    return a


def _segment(n: int, most: int) -> int:
    """The Welch segment: the largest power of two at most ``n / 2`` and ``most``."""
    return min(most, 2 ** int(math.floor(math.log2(max(n // 2, 1)))))


def _over_frames(x: np.ndarray, what: str) -> SpectrumEstimate:
    """Welch over axis 0 of ``x`` (frames, series), each series less its mean, averaged over the series."""
    frames = x.shape[0]
    if frames < MIN_FRAMES:
        raise CmosnoiseError(f"a spectrum over frames needs at least {MIN_FRAMES} dark frames (Welch segments of "
                             f"32 frames); the stack has {frames}")
    x = x - x.mean(axis=0)
    nperseg = _segment(frames, MAX_SEGMENT_FRAMES)
    f, p = signal.welch(x, fs=1.0, nperseg=nperseg, axis=0)
    segments = 1 + (frames - nperseg) // (nperseg // 2)
    return _fit(what, "cycles per frame", f, p.mean(axis=1), (2.0 / nperseg, 0.25), segments)


def over_frames(stack, columns: bool = False, col_means=None) -> SpectrumEstimate:
    """Each pixel's (or, with ``columns``, each column's mean's) spectrum over the frames, averaged.

    A pixel's series is taken less its frame's row mean and column mean (plus the frame's mean): the pixel's own
    noise, without the rows' and column amplifiers' (which :func:`readout_order` and :func:`columns_over_frames`
    measure).

    Parameters
    ----------
    stack : (frames, rows, cols) array
        Dark frames, in any unit (DN or e-), in time order: whole, or some of their rows (then give
        ``col_means``).
    columns : bool
        Each column's mean over its rows instead of each pixel.
    col_means : (frames, cols) array, optional
        Each whole frame's column means, where ``stack`` holds only some of its rows (the frame's mean is then
        theirs).

    Returns
    -------
    SpectrumEstimate
        In cycles per frame, the slope fitted from two bins above the lowest to a quarter cycle per frame.

    Raises
    ------
    CmosnoiseError
        Fewer than :data:`MIN_FRAMES` frames.
    """
    a = _stack(stack)
    if columns:
        return columns_over_frames(a.astype(np.float64).mean(axis=1))
    if a.shape[0] < MIN_FRAMES:  # refused before any pixel is read
        _over_frames(np.zeros((a.shape[0], 1)), "pixels over frames")
    # whole rows (their row means exact), every k-th, about MAX_PIXELS pixels in all (at least one row)
    every = max(1, a.shape[1] * a.shape[2] // MAX_PIXELS // max(a.shape[2], 1))
    x = a[:, ::every, :].astype(np.float64)
    cm = a.mean(axis=1, dtype=np.float64) if col_means is None else np.asarray(col_means, np.float64)
    if cm.shape != (a.shape[0], a.shape[2]):
        raise CmosnoiseError(f"col_means: expected (frames, cols) = ({a.shape[0]}, {a.shape[2]}), got {cm.shape}")
    y = x - x.mean(axis=2, keepdims=True) - cm[:, None, :] + cm.mean(axis=1)[:, None, None]
    flat = y.reshape(y.shape[0], -1)
    return _over_frames(flat[:, :: max(1, flat.shape[1] // MAX_PIXELS)], "pixels over frames")


def columns_over_frames(col_means) -> SpectrumEstimate:
    """The column amplifiers' spectrum over frames from each frame's column means.

    Parameters
    ----------
    col_means : (frames, cols) array
        Each frame's mean of each column over its rows.

    Returns
    -------
    SpectrumEstimate
        In cycles per frame; each frame's mean over the columns is taken away first.
    """
    x = np.asarray(col_means, np.float64)
    return _over_frames(x - x.mean(axis=1, keepdims=True), "columns over frames")


def readout_order(stack) -> SpectrumEstimate:
    """The rows' means in readout order (frame after frame), their spectrum.

    Parameters
    ----------
    stack : (frames, rows, cols) array
        Dark frames in time order, each read row by row from the top.

    Returns
    -------
    SpectrumEstimate
        In cycles per row, the slope fitted from four bins above the lowest (and two cycles per frame) to an
        eighth of a cycle per row.

    Raises
    ------
    CmosnoiseError
        Fewer than :data:`MIN_READOUT_ROWS` rows in all.
    """
    return rows_in_readout_order(_stack(stack).astype(np.float64).mean(axis=2))


def rows_in_readout_order(row_means) -> SpectrumEstimate:
    """The row noise's spectrum in readout order from each frame's row means.

    Parameters
    ----------
    row_means : (frames, rows) array
        Each frame's mean of each row over its columns, the frames in time order.

    Returns
    -------
    SpectrumEstimate
        As :func:`readout_order`.
    """
    means = np.asarray(row_means, np.float64)
    frames, rows = means.shape
    if frames * rows < MIN_READOUT_ROWS or frames < 2:
        raise CmosnoiseError(f"a spectrum in readout order needs at least {MIN_READOUT_ROWS} rows in two or more "
                             f"frames; the stack has {frames} frames of {rows} rows")
    means = means - means.mean(axis=0)
    x = (means - means.mean(axis=1, keepdims=True)).ravel()  # what the frame's rows share is not a row's
    nperseg = _segment(x.size // 4, MAX_SEGMENT_ROWS)
    f, p = signal.welch(x, fs=1.0, nperseg=nperseg)
    segments = 1 + (x.size - nperseg) // (nperseg // 2)
    return _fit("rows in readout order", "cycles per row", f, p, (max(4.0 / nperseg, 2.0 / rows), 0.125), segments)


def of_stack(stack, frame_rate_hz: float | None = None) -> dict:
    """The three spectra of a dark stack as ``characterization.json`` keeps them, each a summary or the reason
    it is not given; a 1/f spectrum over frames with its corners (:func:`with_corners`).

    Parameters
    ----------
    stack : (frames, rows, cols) array
        Dark frames in time order, back to back at ``frame_rate_hz``.
    frame_rate_hz : float or None
        Frames a second (None: not known, and no corner is fitted).

    Returns
    -------
    dict
        ``{"pixels_over_frames", "columns_over_frames", "rows_in_readout_order"}``: each
        :func:`with_corners`' summary, or ``{"not_given": why}``.
    """
    out = {}
    for key, make in (("pixels_over_frames", lambda: over_frames(stack)),
                      ("columns_over_frames", lambda: over_frames(stack, columns=True)),
                      ("rows_in_readout_order", lambda: readout_order(stack))):
        try:
            out[key] = with_corners(make(), frame_rate_hz)
        except CmosnoiseError as exc:
            out[key] = {"not_given": str(exc)}
    return out


def with_corners(estimate: SpectrumEstimate, frame_rate_hz: float | None) -> dict:
    """``estimate``'s summary, and for a 1/f spectrum over frames its range in Hz (:func:`fit_corners`) with
    the frame rate it used, or why it has none (the rate not known).

    Parameters
    ----------
    estimate : SpectrumEstimate
        Any of the three spectra.
    frame_rate_hz : float or None
        The stack's frames a second.

    Returns
    -------
    dict
        :meth:`SpectrumEstimate.summary`, with ``frame_rate_hz`` and ``corners`` for a 1/f spectrum over
        frames.
    """
    out = estimate.summary()
    if estimate.unit == "cycles per frame" and estimate.verdict == "one_over_f":
        if frame_rate_hz is None:
            out["corners"] = {"not_given": "the stack's frame rate is not known, so its 1/f range is not "
                                           "given in Hz"}
        else:
            out["frame_rate_hz"] = float(frame_rate_hz)
            out["corners"] = fit_corners(estimate, float(frame_rate_hz))
    return out


def _centring_weights(n: int) -> np.ndarray:
    """``a_n(d)`` for lags ``d = 0 .. n - 1``: the sum over pairs ``d`` apart of a centring projector's entries,
    ``n - 1`` at 0 and ``-(n - d) / n`` elsewhere."""
    d = np.arange(n, dtype=np.float64)
    a = -(n - d) / n
    a[0] = n - 1
    return a


def seen_share_rows(spectrum, frames: int, rows: int, row_time_s: float) -> float:
    """What a dark stack's double-centred row means see of a 1/f row noise's variance, against white noise's.

    The fit takes the row noise's variance from each frame's row means less each row's mean over the frames and
    each frame's mean over its rows: for white noise their sum of squares is ``sigma^2 (K - 1)(H - 1)``; for a
    process of autocorrelation ``rho`` sampled at ``n = k H + r`` it is ``sigma^2 tr(P C)``,
    ``sum_dk sum_dr a_K(dk) a_H(dr) rho((dk H + dr) t_row)``. For a Lorentzian the frames' and the rows' lags
    separate (``|dk H + dr| = |dk| H + sign(dk) dr`` when ``dk != 0``), so the sum costs ``O(K + H)`` a component.

    Parameters
    ----------
    spectrum : cmosnoise.model.one_over_f.Spectrum
        The unit-variance process's Lorentzians.
    frames, rows : int
        The stack's frames ``K`` and the rows ``H`` each is read in.
    row_time_s : float
        Seconds between two rows' readouts.

    Returns
    -------
    float
        ``tr(P C) / ((K - 1)(H - 1))``: 1 for white noise, less for 1/f (its slow part moves the whole stack).
    """
    a_k, a_h = _centring_weights(frames), _centring_weights(rows)
    lag_h = np.arange(rows, dtype=np.float64)
    lag_k = np.arange(1, frames, dtype=np.float64)
    total = 0.0
    for rate, w in zip(spectrum.rates_per_s, spectrum.weights):
        x = rate * row_time_s
        same = a_h[0] + 2.0 * np.sum(a_h[1:] * np.exp(-x * lag_h[1:]))  # dk = 0
        # dk >= 1: exp(-x (dk H + dr)) = exp(-x H (dk - 1)) exp(-x (H + dr)), H + dr from 1 to 2H - 1
        cross = a_h[0] * math.exp(-x * rows) + np.sum(a_h[1:] * (np.exp(-x * (rows + lag_h[1:]))
                                                                  + np.exp(-x * (rows - lag_h[1:]))))
        total += w * (a_k[0] * same + 2.0 * cross * np.sum(a_k[1:] * np.exp(-x * rows * (lag_k - 1))))
    return float(total / ((frames - 1) * (rows - 1)))


def seen_share_frames(spectrum, frames: int, frame_period_s: float) -> float:
    """What a stack's variance over ``frames`` frames (ddof 1) sees of a 1/f process's variance.

    Parameters
    ----------
    spectrum : cmosnoise.model.one_over_f.Spectrum
        The unit-variance process's Lorentzians.
    frames : int
        The stack's frames ``K``.
    frame_period_s : float
        Seconds between two frames.

    Returns
    -------
    float
        ``sum_dk a_K(dk) rho(dk T) / (K - 1)``: 1 for white noise.
    """
    a_k = _centring_weights(frames)
    lag = np.arange(1, frames, dtype=np.float64) * frame_period_s
    rho = np.sum(spectrum.weights * np.exp(-np.outer(lag, spectrum.rates_per_s)), axis=1)
    return float((a_k[0] + 2.0 * np.sum(a_k[1:] * rho)) / (frames - 1))


def variance_dof_frames(spectrum, frames: int, frame_period_s: float, part: float, white: float) -> float:
    """The degrees of freedom of a series' variance over ``frames`` frames (ddof 1), rescaled to its mean, where
    the series is a 1/f process of variance ``part`` plus white noise of variance ``white``.

    For white noise alone it is ``K - 1``; a 1/f part moves slowly, so its variance estimate spreads more:
    ``dof = tr(P C)^2 / tr(P C P C)`` (the Gaussian quadratic form's), ``C = part R + white I``.

    Parameters
    ----------
    spectrum : cmosnoise.model.one_over_f.Spectrum
        The 1/f part's Lorentzians.
    frames : int
        The frames ``K``.
    frame_period_s : float
        Seconds between frames.
    part, white : float
        The variances of the 1/f part and of the white part.

    Returns
    -------
    float
        The chi-square degrees of freedom that spread like the estimate (exact up to 2048 frames; past that the
        first 2048 frames', scaled by ``(K - 1) / 2047``).
    """
    n = min(frames, 2048)
    lag = np.arange(n, dtype=np.float64) * frame_period_s
    rho = np.sum(spectrum.weights * np.exp(-np.outer(lag, spectrum.rates_per_s)), axis=1)
    i = np.arange(n)
    c = part * rho[np.abs(i[:, None] - i[None, :])] + white * np.eye(n)
    pc = c - c.mean(axis=0, keepdims=True)  # P C with P = I - 11'/n
    first = float(np.trace(pc))
    second = float(np.sum(pc * pc.T))
    return first * first / second * (frames - 1) / (n - 1)


def _row_lag_sums(x: float, frames: int, rows: int, weights_rows: np.ndarray) -> tuple[float, np.ndarray]:
    """For one Lorentzian (``x = rate t_row``): ``sum_dr w(dr) rho(|dr|)`` at frame lag 0 and, for frame lags
    ``dk = 1 .. K - 1``, ``sum_dr w(dr) rho(dk H + dr)``, where ``w`` (lags 0 .. H - 1) is symmetric in ``dr``."""
    lag_h = np.arange(rows, dtype=np.float64)
    same = weights_rows[0] + 2.0 * np.sum(weights_rows[1:] * np.exp(-x * lag_h[1:]))
    base = weights_rows[0] * math.exp(-x * rows) + np.sum(weights_rows[1:] * (np.exp(-x * (rows + lag_h[1:]))
                                                                           + np.exp(-x * (rows - lag_h[1:]))))
    return same, base * np.exp(-x * rows * np.arange(frames - 1, dtype=np.float64))


def frame_mean_ratio_rows(spectrum, frames: int, rows: int, row_time_s: float) -> float:
    """What a 1/f row noise puts into the spread of a stack's frame means, over what it puts into the rows'
    spread about their frame's mean (both as variances over the frames, ddof 1): ``1 / (H - 1)`` for white noise.

    With ``y_k`` a frame's mean of its rows' offsets, ``Cov_y(dk) = H^-2 sum_dr (H - |dr|) rho(dk H + dr)``, the
    frame means' expected variance is ``sum_dk a_K(dk) Cov_y(dk) / (K - 1)`` and the rows' about their frame's
    ``sum_dk a_K(dk) (rho(dk H) - Cov_y(dk)) / (K - 1)``.

    Parameters
    ----------
    spectrum : cmosnoise.model.one_over_f.Spectrum
        The row noise's Lorentzians.
    frames, rows : int
        The stack's frames and rows.
    row_time_s : float
        Seconds between two rows' readouts.

    Returns
    -------
    float
        The ratio of the two expected variances.
    """
    a_k = _centring_weights(frames)
    tri = (rows - np.arange(rows, dtype=np.float64)) / rows**2
    same_row = np.zeros(rows)
    same_row[0] = 1.0
    fm = rw = 0.0
    for rate, w in zip(spectrum.rates_per_s, spectrum.weights):
        x = rate * row_time_s
        cy0, cy = _row_lag_sums(x, frames, rows, tri)
        r0, r = _row_lag_sums(x, frames, rows, same_row)  # rho(dk H): the same row a frame apart
        fm += w * (a_k[0] * cy0 + 2.0 * np.sum(a_k[1:] * cy))
        rw += w * (a_k[0] * (r0 - cy0) + 2.0 * np.sum(a_k[1:] * (r - cy)))
    return float(fm / rw)


def stack_mean_share_frames(spectrum, frames: int, frame_period_s: float) -> float:
    """The variance of a 1/f process's mean over ``frames`` frames, over white noise's ``1 / K``.

    Parameters
    ----------
    spectrum : cmosnoise.model.one_over_f.Spectrum
        The unit-variance process's Lorentzians.
    frames : int
        The frames ``K``.
    frame_period_s : float
        Seconds between frames.

    Returns
    -------
    float
        ``(1 / K) sum_dk (K - |dk|) rho(dk T)``: 1 for white noise, up to ``K`` for a process slower than the stack.
    """
    lag = np.arange(1, frames, dtype=np.float64)
    rho = np.sum(spectrum.weights * np.exp(-np.outer(lag * frame_period_s, spectrum.rates_per_s)), axis=1)
    return float((frames + 2.0 * np.sum((frames - lag) * rho)) / frames)


def stack_mean_share_rows(spectrum, frames: int, rows: int, row_time_s: float) -> float:
    """The rows' spread about their mean in a stack's mean image that a 1/f row noise leaves, over white noise's.

    Row ``r``'s mean over the frames is ``z_r``; ``Cov(z_r, z_r') = K^-2 sum_dk (K - |dk|) rho(dk H + r' - r)``,
    and the rows' centred sum of squares is ``sum_dr a_H(dr) Cov_z(dr)`` (``(H - 1) / K`` for white noise).

    Parameters
    ----------
    spectrum : cmosnoise.model.one_over_f.Spectrum
        The row noise's Lorentzians.
    frames, rows : int
        The stack's frames and rows.
    row_time_s : float
        Seconds between two rows' readouts.

    Returns
    -------
    float
        The ratio: 1 for white noise.
    """
    a_h = _centring_weights(rows)
    tri_k = frames - np.arange(1, frames, dtype=np.float64)
    total = 0.0
    for rate, w in zip(spectrum.rates_per_s, spectrum.weights):
        same, cross = _row_lag_sums(rate * row_time_s, frames, rows, a_h)
        total += w * (frames * same + 2.0 * np.sum(tri_k * cross)) / frames**2
    return float(total / ((rows - 1) / frames))


#: the grid the corner fit searches, decades per step
CORNER_STEP_DECADES = 0.05
#: how far below the lowest bin and above Nyquist the grid reaches, decades: a corner out there is only bounded
CORNER_REACH_DECADES = 2.0


def _ar1_sum(f_cpf: np.ndarray, spectrum, frame_rate_hz: float) -> np.ndarray:
    """The one-sided spectrum, per cycle per frame, of a unit-variance sum of Lorentzians sampled once a frame:
    each component an AR(1) sequence of ``rho = exp(-2 pi f_c / rate)``, exactly (aliasing included)."""
    rho = np.exp(-spectrum.rates_per_s / frame_rate_hz)[None, :]
    c = np.cos(2.0 * math.pi * f_cpf)[:, None]
    return np.sum(spectrum.weights * 2.0 * (1.0 - rho**2) / (1.0 - 2.0 * rho * c + rho**2), axis=1)


def _welch_expected(f_cpf: np.ndarray, df: float, spectrum, frame_rate_hz: float) -> np.ndarray:
    """What a Welch estimate with Hann segments reads at ``f_cpf`` (bins ``df`` apart): the spectrum seen through
    the window. The Hann window's DFT is ``-1/4, 1/2, -1/4`` on a bin and its two neighbours (Harris, "On the use
    of windows for harmonic analysis with the discrete Fourier transform", Proc. IEEE 66(1), 1978, the Hanning
    window's spectral coefficients); squared and normalised, a bin reads its neighbours' power 1/6 each and its
    own 2/3 (a 1/f spectrum reads 11 % high two bins above zero, where the segments' means are taken away)."""
    return (_ar1_sum(f_cpf - df, spectrum, frame_rate_hz) + 4.0 * _ar1_sum(f_cpf, spectrum, frame_rate_hz)
            + _ar1_sum(f_cpf + df, spectrum, frame_rate_hz)) / 6.0


def fit_corners(estimate: SpectrumEstimate, frame_rate_hz: float) -> dict:
    """The 1/f range (lowest and highest corner, Hz) that a spectrum over frames shows, with 95 % intervals.

    The model is the simulator's own (:func:`cmosnoise.model.one_over_f.lorentzians`: Lorentzians at equal
    steps of ``log f`` between the corners, each of equal variance), sampled once a frame (each component an
    AR(1) sequence, aliasing exact) and seen through the Hann window (a bin reads its neighbours a sixth each),
    times a level, plus a white floor (the pixel's other noises). Each pair of
    corners on a grid of :data:`CORNER_STEP_DECADES` takes its level and floor by linear least squares on the
    bins' relative residuals (``(model - P) / P``, from two bins above the lowest to below Nyquist); the
    interval of a corner is the grid's range whose residual sum exceeds the best by at most ``2 x 3.84``
    residual variances (the profile likelihood's 95 % of one parameter; two for the Hann window's correlated
    neighbouring bins), one grid step wider each side (the grid's resolution). A corner whose interval reaches the
    grid's end lies beyond what the stack resolves
    (below its lowest bin, or above Nyquist): it is given as a bound only, ``resolved`` false.

    Parameters
    ----------
    estimate : SpectrumEstimate
        A spectrum over frames (:func:`over_frames`, :func:`columns_over_frames`).
    frame_rate_hz : float
        Frames per second of the stack.

    Returns
    -------
    dict
        ``low_hz`` and ``high_hz``, each ``{"value", "interval": [lo, hi], "resolved"}``; ``floor_share`` (the
        white floor's part of the spectrum at the band's upper end); ``resolved_band_hz`` (the lowest bin to
        Nyquist, Hz).
    """
    from ..model import one_over_f

    if estimate.unit != "cycles per frame":
        raise CmosnoiseError(f"fit_corners: a spectrum over frames, not {estimate.series!r}")
    keep = (estimate.f >= estimate.band[0]) & (estimate.f < 0.5) & (estimate.psd > 0)
    f, p = estimate.f[keep], estimate.psd[keep]
    df = float(estimate.f[1] - estimate.f[0])
    if f.size < 8:
        raise CmosnoiseError(f"the {estimate.series} spectrum has {f.size} bins: too few to fit its corners")
    lo_hz, nyq_hz = float(f[0]) * frame_rate_hz, 0.5 * frame_rate_hz
    grid = np.arange(math.log10(lo_hz) - CORNER_REACH_DECADES, math.log10(nyq_hz) + CORNER_REACH_DECADES + 1e-9,
                     CORNER_STEP_DECADES)
    sse = np.full((grid.size, grid.size), np.inf)
    fits = {}
    for i, la in enumerate(grid):
        for j in range(i + 1, grid.size):
            shape = _welch_expected(f, df, one_over_f.lorentzians(10.0**la, 10.0**grid[j]), frame_rate_hz)
            design = np.stack([shape / p, 1.0 / p], axis=1)  # (A shape + W) / p - 1: linear in A, W
            coef, *_ = np.linalg.lstsq(design, np.ones_like(p), rcond=None)
            if coef[0] <= 0 or coef[1] < 0:  # a level must be positive and a floor not negative
                a = max(float(np.sum(shape / p) / np.sum((shape / p) ** 2)), 0.0)
                coef = np.array([a, 0.0])
            r = design @ coef - 1.0
            sse[i, j] = float(r @ r)
            fits[i, j] = coef
    best = np.unravel_index(int(np.argmin(sse)), sse.shape)
    s2 = sse[best] / max(f.size - 4, 1)
    inside = sse <= sse[best] + 2.0 * 3.84 * s2
    rows, cols = np.nonzero(inside)

    def corner(axis_idx, value_idx) -> dict:
        lo_i, hi_i = int(axis_idx.min()), int(axis_idx.max())
        edge = lo_i == 0 or hi_i == grid.size - 1
        # one grid step more each side: a corner between two grid points is as near the one as the other
        lo, hi = grid[lo_i] - CORNER_STEP_DECADES, grid[hi_i] + CORNER_STEP_DECADES
        return {"value": float(10.0 ** grid[value_idx]), "interval": [float(10.0**lo), float(10.0**hi)],
                "resolved": not edge}

    a, w = fits[best]
    top = _ar1_sum(np.array([estimate.band[1]]), one_over_f.lorentzians(10.0 ** grid[best[0]],
                                                                          10.0 ** grid[best[1]]), frame_rate_hz)[0]
    return {"low_hz": corner(rows, best[0]), "high_hz": corner(cols, best[1]),
            "floor_share": float(w / (a * top + w)) if a * top + w > 0 else 1.0,
            "resolved_band_hz": [lo_hz, nyq_hz]}
