"""ISO 12233 e-SFR: the spatial frequency response (MTF) of a camera from a slanted edge.

The steps of ISO 12233's edge method as Burns' sfrmat describes them, with the derivative correction done for the
filter actually used (Asplund's note: the correction of ISO 12233:2014/2017 Annex D does not match its filter):

1. each row's derivative across the edge ([-1, 1]) and its centroid: where the edge crosses that row;
2. a straight line fitted to the centroids by least squares: the edge's position and angle;
3. every pixel's signed distance from the line, perpendicular to it, binned at 1/4 pixel: the oversampled edge
   spread function (ESF; the slant spreads the pixels' phases over the bins);
4. the ESF's derivative ([-1, 1] at the bins' spacing): the line spread function (LSF), centred on its centroid
   and windowed by a Hamming window as wide as the LSF's support;
5. the magnitude of its DFT, normalised at zero frequency, divided by the [-1, 1] filter's own response
   ``|sinc(f d)|`` (d the bin spacing) and by the binning's (each bin the mean of the ESF across its width: a
   second ``sinc(f d)``): the SFR at frequencies ``k / (n d)`` cycles per pixel.

From the SFR: MTF50 (the frequency where it falls to 0.5, linearly interpolated), the MTF at Nyquist (0.5
cycles/pixel) and the share of the SFR's area from 0 to the sampling frequency that lies above Nyquist.

**Its standard error** (``se``), from the pixels' own spread: each ESF bin's mean has the variance ``v_i`` of its
pixels' values over their number (the pixels independent: noise, fixed pattern and defects all count). The
windowed LSF's DFT ``X(w) = sum_j a_j (e_(j+1) - e_j) exp(-i w m_j)`` (``a`` the window, ``m`` the centring's
shifted index) is a linear sum of the bins, of variance ``sum_i v_i |u_(i-1) - u_i|^2``; the shift adds one
sample a step (``m_(i-1) - m_i = -1`` modulo n), so that is ``A + B - 2 C cos w`` with ``A = sum v_i a_(i-1)^2``,
``B = sum v_i a_i^2``, ``C = sum v_i a_(i-1) a_i``. The noise's share along the signal's phase is half of it, so
``se = sqrt((A + B - 2 C cos w) / 2) / |X(0)|``, through the same ``sinc^2`` correction; ``mtf50_se`` is its value
at MTF50 over the SFR's slope there.

Distances are measured perpendicular to the edge, so the frequencies are cycles per pixel across it (ISO 12233
bins along the rows and scales the frequency by the cosine of the angle: the same thing).

Examples
--------
>>> import numpy as np
>>> from cmosnoise.analysis import sfr
>>> from cmosnoise.model import charts
>>> img = charts.edge((100, 100), 5.0, 0.1, 0.4)[..., 0]     # an ideal edge sampled by square pixels
>>> r = sfr.esfr(img)
>>> round(r.angle_deg, 2), round(float(np.interp(0.25, r.frequency, r.sfr)), 3)   # sinc(0.25) = 0.900
(5.0, 0.899)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CmosnoiseError

#: ESF bins per pixel (ISO 12233: 4)
OVERSAMPLING = 4
#: the least edge contrast measured, (high - low) / (high + low) (ISETCam warns below 20 %)
MIN_CONTRAST = 0.2
#: the slant an edge must have to spread its phases over the bins, and at most, degrees from vertical
MIN_ANGLE_DEG, MAX_ANGLE_DEG = 1.0, 45.0

__all__ = ["SfrResult", "esfr", "raw_channel", "mtf50", "OVERSAMPLING"]


@dataclass(frozen=True)
class SfrResult:
    """An e-SFR measurement.

    Parameters
    ----------
    frequency : (n,) float64 array
        Cycles per pixel, from 0 to :data:`OVERSAMPLING` / 2.
    sfr : (n,) float64 array
        The spatial frequency response, 1 at zero frequency.
    angle_deg : float
        The edge's slant from vertical, degrees (positive: its bottom to the right).
    contrast : float
        ``(high - low) / (high + low)`` of the two sides.
    mtf50 : float
        Cycles per pixel where the SFR first falls to 0.5.
    mtf_nyquist : float
        The SFR at 0.5 cycles per pixel.
    above_nyquist : float
        The share of the SFR's area from 0 to 1 cycle per pixel that lies above 0.5: aliasing's room.
    se : (n,) float64 array, optional
        The SFR's standard error at each frequency from the pixels' spread (the module docstring); None where not
        estimated.
    """

    frequency: np.ndarray
    sfr: np.ndarray
    angle_deg: float
    contrast: float
    mtf50: float
    mtf_nyquist: float
    above_nyquist: float
    se: np.ndarray | None = None

    def se_at(self, frequency: float) -> float:
        """The SFR's standard error at ``frequency`` (cycles per pixel), interpolated; nan where not estimated."""
        if self.se is None or not np.isfinite(frequency):
            return float("nan")
        return float(np.interp(frequency, self.frequency, self.se))

    @property
    def mtf50_se(self) -> float:
        """MTF50's standard error, cycles per pixel: the SFR's at MTF50 over the SFR's slope there."""
        if self.se is None or not np.isfinite(self.mtf50):
            return float("nan")
        slope = np.gradient(self.sfr, self.frequency)
        return self.se_at(self.mtf50) / max(abs(float(np.interp(self.mtf50, self.frequency, slope))), 1e-12)

    def as_dict(self) -> dict:
        """The figures (not the curve) as plain numbers."""
        return {"mtf50_cy_per_px": self.mtf50, "mtf50_se": self.mtf50_se, "mtf_nyquist": self.mtf_nyquist,
                "mtf_nyquist_se": self.se_at(0.5), "above_nyquist": self.above_nyquist,
                "angle_deg": self.angle_deg, "contrast": self.contrast}


def _centroids(img: np.ndarray, near: np.ndarray | None = None, half: float = 0.0) -> np.ndarray:
    """Each row's edge position: the centroid of the row's derivative (the edge rising to the right), in pixel
    coordinates (pixel c spans [c, c + 1]); with ``near``, only within ``half`` pixels of it on each row, under a
    Hamming window centred there (noise far from the edge then adds nothing)."""
    d = np.diff(img, axis=1)  # between columns c and c + 1: at x = c + 1
    x = np.arange(d.shape[1]) + 1.0
    if near is None:
        w = np.hamming(d.shape[1])[None, :]
    else:
        u = (x[None, :] - near[:, None]) / half
        w = np.where(np.abs(u) < 1, 0.54 + 0.46 * np.cos(np.pi * u), 0.0)
    d = d * w
    total = d.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (d * x[None, :]).sum(axis=1) / total


def mtf50(frequency: np.ndarray, sfr: np.ndarray) -> float:
    """Where an SFR first falls to 0.5, linearly interpolated (cycles per pixel); nan if it never does.

    Parameters
    ----------
    frequency : (n,) array
        Cycles per pixel, increasing.
    sfr : (n,) array
        The SFR.

    Returns
    -------
    float
    """
    below = np.nonzero(sfr < 0.5)[0]
    if below.size == 0 or below[0] == 0:
        return float("nan")
    i = below[0]
    f0, f1, s0, s1 = frequency[i - 1], frequency[i], sfr[i - 1], sfr[i]
    return float(f0 + (s0 - 0.5) * (f1 - f0) / (s0 - s1))


def esfr(image: np.ndarray, region: tuple[int, int, int, int] | None = None) -> SfrResult:
    """The e-SFR of a slanted edge (see the module docstring).

    Parameters
    ----------
    image : (rows, cols) array
        A single-channel image (a monochrome raw less its black level, one CFA channel, a luminance): linear in
        light, the edge within 45 degrees of vertical.
    region : (row0, row1, col0, col1), optional
        The part of ``image`` holding the edge and both sides (:func:`cmosnoise.model.charts.truth` gives it for
        the built-in edge); default: all of it.

    Returns
    -------
    SfrResult

    Raises
    ------
    CmosnoiseError
        A region outside the image, fewer than 8 rows or 16 columns, an edge of less than :data:`MIN_CONTRAST`, or
        one too close to vertical (under 1 degree) or not found.
    """
    a = np.asarray(image)
    if a.ndim != 2 or a.dtype.kind not in "uif":
        raise CmosnoiseError(f"sfr: give one 2-D image of real numbers; got {a.shape} {a.dtype}")
    a = a.astype(np.float64)
    if region is not None:
        r0, r1, c0, c1 = (int(v) for v in region)
        if not (0 <= r0 < r1 <= a.shape[0] and 0 <= c0 < c1 <= a.shape[1]):
            raise CmosnoiseError(f"sfr: region {list(region)} is not inside the {a.shape[0]} x {a.shape[1]} image")
        a = a[r0:r1, c0:c1]
    rows, cols = a.shape
    if rows < 8 or cols < 16:
        raise CmosnoiseError(f"sfr: the edge's region is {rows} x {cols} pixels; give at least 8 rows and 16 columns")
    if not np.isfinite(a).all():
        raise CmosnoiseError("sfr: the image has NaN or infinite values")
    k = max(cols // 8, 2)
    left, right = float(np.median(a[:, :k])), float(np.median(a[:, -k:]))
    lo, hi = min(left, right), max(left, right)
    contrast = (hi - lo) / (hi + lo) if hi + lo > 0 else 0.0
    if contrast < MIN_CONTRAST:
        raise CmosnoiseError(f"sfr: the edge's contrast (high - low) / (high + low) is {contrast:.3f}; give an "
                             f"edge of at least {MIN_CONTRAST:g} (ISO 12233: 4:1 is 0.6)")
    if right < left:  # the ESF rises from left to right
        a = -a
    # 1.-2. the edge: each row's centroid, a line through them; again within a window about that line (sfrmat's
    # second pass: the first one's noise far from the edge pulls every centroid toward the row's middle)
    y = np.arange(rows) + 0.5
    slope = intercept = None
    for near_half in (None, max(8.0, cols / 8)):
        near = None if slope is None else intercept + slope * y
        cen = _centroids(a, near, near_half or 0.0)
        ok = np.isfinite(cen)
        if ok.sum() < rows // 2:
            raise CmosnoiseError("sfr: no edge found across most rows of the region")
        slope, intercept = np.polyfit(y[ok], cen[ok], 1)
    angle = float(np.degrees(np.arctan(slope)))
    if abs(angle) < MIN_ANGLE_DEG or abs(angle) > MAX_ANGLE_DEG:
        raise CmosnoiseError(f"sfr: the edge is {angle:.2f} degrees from vertical; give a slanted edge of "
                             f"{MIN_ANGLE_DEG:g} to {MAX_ANGLE_DEG:g} degrees (ISO 12233: about 5)")
    # 3. each pixel centre's perpendicular distance from the line, binned at 1 / OVERSAMPLING pixel
    xs = np.arange(cols) + 0.5
    dist = (xs[None, :] - (intercept + slope * y[:, None])) * np.cos(np.arctan(slope))
    step = 1.0 / OVERSAMPLING
    # keep the distances every row reaches, so every bin has pixels from many rows
    reach = min(-dist[:, 0].max(), dist[:, -1].min())
    keep = np.abs(dist) < reach
    if keep.sum() < 4 * OVERSAMPLING:  # a line the noise drew: no distance from it that every row reaches
        raise CmosnoiseError("sfr: no straight edge found across the region (the line fitted to the rows' edges "
                             "leaves it)")
    idx = np.floor(dist[keep] / step).astype(np.int64)
    first = idx.min()
    counts = np.bincount(idx - first)
    sums = np.bincount(idx - first, weights=a[keep])
    if (counts == 0).any():  # an empty bin (a tiny angle over few rows): the neighbours' mean
        empty = counts == 0
        filled = np.nonzero(~empty)[0]
        sums[empty] = np.interp(np.nonzero(empty)[0], filled, sums[filled] / counts[filled])
        counts[empty] = 1
    esf = sums / counts
    centres = (np.arange(esf.size) + first + 0.5) * step
    bin_var = _bin_variance(idx - first, a[keep] - np.interp(dist[keep], centres, esf), counts)
    # 4. the LSF, centred and windowed
    lsf = np.diff(esf)
    n = lsf.size
    centre = float((lsf * np.arange(n)).sum() / lsf.sum())
    shift = int(round(centre - (n - 1) / 2))
    window = np.roll(np.hamming(n), shift)  # the window each unshifted LSF sample gets
    lsf = np.roll(lsf, -shift)
    lsf = lsf * np.hamming(n)
    # 5. |DFT|, normalised, corrected for the [-1, 1] derivative at the bins' spacing
    spectrum = np.abs(np.fft.rfft(lsf))
    freq = np.fft.rfftfreq(n, d=step)
    sfr = spectrum / spectrum[0]
    # the [-1, 1] derivative and the binning (each bin the mean of the ESF over its width): two boxes of the bins'
    # width, sinc(f d) each
    correction = np.maximum(np.sinc(freq * step) ** 2, 0.1)
    sfr = sfr / correction
    # the standard error (the module docstring): bin i enters LSF samples i - 1 (+) and i (-)
    before = np.concatenate([[0.0], window])  # a_(i-1), bins 0..n
    after = np.concatenate([window, [0.0]])  # a_i
    big_a, big_b, big_c = (float(np.sum(bin_var * before ** 2)), float(np.sum(bin_var * after ** 2)),
                           float(np.sum(bin_var * before * after)))
    noise = np.maximum(big_a + big_b - 2.0 * big_c * np.cos(2.0 * np.pi * freq * step), 0.0)
    se = np.sqrt(noise / 2.0) / spectrum[0] / correction
    nyq = float(np.interp(0.5, freq, sfr))
    inside = freq <= 1.0
    from scipy.integrate import trapezoid

    total = float(trapezoid(sfr[inside], freq[inside]))
    above = float(trapezoid(sfr[inside & (freq >= 0.5)], freq[inside & (freq >= 0.5)]))
    return SfrResult(freq, sfr, angle, contrast, mtf50(freq, sfr), nyq, above / total if total > 0 else float("nan"),
                     se)


def _bin_variance(bins: np.ndarray, residual: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Each ESF bin's mean's variance: its pixels' variance about the ESF (``residual``: each pixel less the ESF
    interpolated at its own distance, so the edge's slope within a bin is not counted as noise) over their number;
    a bin of one pixel (or none) takes the median of the others' pixel variances."""
    sq = np.bincount(bins, weights=residual ** 2, minlength=counts.size)
    raw = np.bincount(bins, minlength=counts.size)
    with np.errstate(invalid="ignore", divide="ignore"):
        pixel_var = np.where(raw > 1, sq / np.maximum(raw - 1, 1), np.nan)
    fill = np.nanmedian(pixel_var) if np.isfinite(pixel_var).any() else 0.0
    pixel_var = np.where(np.isfinite(pixel_var), pixel_var, fill)
    return pixel_var / counts


def raw_channel(raw: np.ndarray, pattern: str, region: tuple[int, int, int, int] | None = None) -> SfrResult:
    """The e-SFR of a raw mosaic before demosaicing: a monochrome sensor's every pixel, a Bayer sensor's green
    pixels.

    The green pixels of a Bayer mosaic lie on two grids of every other row and column (G1 and G2); each is an image
    of the edge at twice the pitch, its pixels the sensor's own (so its MTF holds the pixel's aperture, ``sinc(f)``
    in the sensor's cycles per pixel). The e-SFR of each (``esfr``, frequencies halved to the sensor's cycles per
    pixel) is averaged, the second interpolated at the first's frequencies: the MTF the raw channel has, without
    the demosaicing's interpolation.

    Parameters
    ----------
    raw : (rows, cols) array
        The mosaic, black subtracted (a frames' mean, or one frame).
    pattern : str
        Its CFA: RGGB, BGGR, GRBG, GBRG or none.
    region : (row0, row1, col0, col1), optional
        The edge's part of the mosaic (sensor pixels).

    Returns
    -------
    SfrResult
        Frequencies in the sensor's cycles per pixel (from 0 to 1); MTF50 and the MTF at 0.5 cycles per pixel of the
        sensor.
    """
    from ..model import cfa as cfa_mod

    a = np.asarray(raw, np.float64)
    if cfa_mod.is_mono(pattern):
        return esfr(a, region)
    r0, r1, c0, c1 = (0, a.shape[0], 0, a.shape[1]) if region is None else (int(v) for v in region)
    tile = cfa_mod.tile(pattern)
    results = []
    for i in range(2):
        for j in range(2):
            if tile[i, j] != 1:  # the green pixels' two grids
                continue
            sub = a[i::2, j::2]
            sub_region = ((r0 - i + 1) // 2, (r1 - i) // 2, (c0 - j + 1) // 2, (c1 - j) // 2)
            results.append(esfr(sub, sub_region))
    f = results[0].frequency / 2.0
    curve = np.mean([np.interp(f, r.frequency / 2.0, r.sfr) for r in results], axis=0)
    # the two grids' pixels are different pixels: their errors independent, the mean's the root mean square over 2
    se = np.sqrt(np.sum([np.interp(f, r.frequency / 2.0, r.se) ** 2 for r in results], axis=0)) / len(results)
    keep = f <= 1.0
    f, curve, se = f[keep], curve[keep], se[keep]
    from scipy.integrate import trapezoid

    total = float(trapezoid(curve, f))
    above = float(trapezoid(curve[f >= 0.5], f[f >= 0.5]))
    return SfrResult(f, curve, float(np.mean([r.angle_deg for r in results])),
                     float(np.mean([r.contrast for r in results])), mtf50(f, curve),
                     float(np.interp(0.5, f, curve)), above / total if total > 0 else float("nan"), se)
