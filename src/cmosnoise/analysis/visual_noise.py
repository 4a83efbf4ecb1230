"""Visual luminance noise and banding visibility: noise weighted by the eye's luminance contrast sensitivity, in L*.

The luminance channel of the ISO 15739 (Annex B) and IEEE CPIQ visual-noise framework, at stated viewing
conditions:

1. the patch's relative luminance Y (1: the picture's white) becomes CIE L* (``116 Y^(1/3) - 16``, the linear
   segment below ``(6/29)^3``), less its mean;
2. its 2-D DFT, frequencies turned into cycles per degree of visual angle: a picture ``picture_height_cm`` high
   (all its ``rows``) seen from ``viewing_distance_cm`` spans ``360 / pi * atan(h / 2 d)`` degrees;
3. times the luminance contrast sensitivity ``CSF(v) = a v^c exp(-b v) / K`` with a = 75, b = 0.2, c = 0.8,
   K = 34.05 (ISETCam's ``cpiqCSF.m``, after the CPIQ luminance CSF; Baxter et al., SPIE 8293, 2012), scaled
   to 1 at its peak (4 cycles/degree), the zero frequency set to 0;
4. the inverse DFT's standard deviation: the **visual luminance noise**, sigma of L* as the eye weighs it.

The chrominance channels of ISO 15739 (opponent colour, their two CSFs, CIELUV and the weighted sum) are not
here: their constants could not be checked against the standard. What this module gives is named for what it is.

**Banding** (row or column noise, VFPN) is a 1-D pattern: the row (or column) means of L*, each line's mean over
the patch, are filtered by the same CSF along their axis and their standard deviation taken the same way. Its
visibility is that sigma over the visual luminance noise of **3 % white luminance noise on a mid grey** at the
same viewing conditions, the noise "observers can just barely detect" in a uniform image (ISETCam's MPE30, after
Wandell's *Foundations of Vision*): 1 is the threshold, one just-noticeable difference.

Examples
--------
>>> import numpy as np
>>> from cmosnoise.analysis import visual_noise
>>> flat = np.full((64, 64), 0.18)
>>> visual_noise.visual_luminance_noise(flat)["sigma_l"]
0.0
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import CmosnoiseError

#: the CPIQ luminance CSF's constants (ISETCam cpiqCSF.m): a v^c exp(-b v) / K, v in cycles per degree
CSF_A, CSF_B, CSF_C, CSF_K = 75.0, 0.2, 0.8, 34.05
#: the default viewing conditions: a picture 20 cm high seen from 50 cm (a print or a laptop screen)
PICTURE_HEIGHT_CM, VIEWING_DISTANCE_CM = 20.0, 50.0
#: the just-detectable noise of a uniform picture: 3 % of a mid grey's luminance (ISETCam's MPE30)
THRESHOLD_NOISE, THRESHOLD_GREY = 0.03, 0.18

__all__ = ["csf", "lightness", "visual_luminance_noise", "banding", "threshold_sigma_l"]


def csf(v: np.ndarray) -> np.ndarray:
    """The luminance contrast sensitivity, 1 at its peak (4 cycles/degree).

    Parameters
    ----------
    v : array
        Spatial frequency, cycles per degree, >= 0.

    Returns
    -------
    array
        ``a v^c exp(-b v) / K`` over its peak value.
    """
    v = np.asarray(v, float)
    peak = CSF_C / CSF_B
    return (v / peak) ** CSF_C * np.exp(-CSF_B * (v - peak))


def lightness(y: np.ndarray) -> np.ndarray:
    """CIE L* of relative luminance ``y`` (1: white).

    Parameters
    ----------
    y : array
        Relative luminance, >= 0.

    Returns
    -------
    array
        L*, 0 to 100.
    """
    y = np.asarray(y, float)
    e = (6 / 29) ** 3
    return np.where(y > e, 116 * np.cbrt(y) - 16, y * (29 / 3) ** 3)


def _degrees(rows: int, picture_height_cm: float, viewing_distance_cm: float) -> float:
    if not (picture_height_cm > 0 and viewing_distance_cm > 0 and math.isfinite(picture_height_cm)
            and math.isfinite(viewing_distance_cm)):
        raise CmosnoiseError(f"viewing conditions: picture_height_cm = {picture_height_cm:g} and viewing_distance_cm "
                             f"= {viewing_distance_cm:g}; both must be finite and > 0")
    return math.degrees(2 * math.atan(picture_height_cm / (2 * viewing_distance_cm)))


def _check(y, what: str) -> np.ndarray:
    a = np.asarray(y)
    if a.ndim != 2 or a.dtype.kind not in "uif" or min(a.shape) < 4:
        raise CmosnoiseError(f"{what}: give one 2-D patch of relative luminance, at least 4 x 4; got {a.shape}")
    a = a.astype(np.float64)
    if not np.isfinite(a).all() or (a < 0).any():
        raise CmosnoiseError(f"{what}: the luminance must be finite and >= 0")
    return a


def visual_luminance_noise(y: np.ndarray, rows: int | None = None, picture_height_cm: float = PICTURE_HEIGHT_CM,
                           viewing_distance_cm: float = VIEWING_DISTANCE_CM) -> dict:
    """The visual luminance noise of a uniform patch (see the module docstring).

    Parameters
    ----------
    y : (h, w) array
        The patch's relative luminance (1: the picture's white).
    rows : int, optional
        The whole picture's height in pixels (the patch's own by default): with ``picture_height_cm`` it sets the
        pixels per degree.
    picture_height_cm, viewing_distance_cm : float
        The viewing conditions.

    Returns
    -------
    dict
        ``sigma_l`` (the CSF-weighted standard deviation of L*), ``sigma_l_unweighted``, ``mean_l``,
        ``pixels_per_degree``, ``picture_height_cm``, ``viewing_distance_cm``.
    """
    a = _check(y, "visual noise")
    rows = a.shape[0] if rows is None else int(rows)
    ppd = rows / _degrees(rows, picture_height_cm, viewing_distance_cm)
    lum = lightness(a)
    dev = lum - lum.mean()
    fy = np.fft.fftfreq(a.shape[0])[:, None]
    fx = np.fft.rfftfreq(a.shape[1])[None, :]
    weight = csf(np.hypot(fy, fx) * ppd)
    weight[0, 0] = 0.0
    filtered = np.fft.irfft2(np.fft.rfft2(dev) * weight, s=a.shape)
    return {"sigma_l": float(filtered.std()), "sigma_l_unweighted": float(dev.std()), "mean_l": float(lum.mean()),
            "pixels_per_degree": ppd, "picture_height_cm": picture_height_cm,
            "viewing_distance_cm": viewing_distance_cm}


def threshold_sigma_l(rows: int, shape: tuple[int, int] = (256, 256), picture_height_cm: float = PICTURE_HEIGHT_CM,
                      viewing_distance_cm: float = VIEWING_DISTANCE_CM) -> float:
    """The visual luminance noise of the just-detectable noise (:data:`THRESHOLD_NOISE` white noise on
    :data:`THRESHOLD_GREY`) at these viewing conditions: the unit of :func:`banding`'s visibility.

    Computed analytically: white noise of L* sigma ``s`` (the luminance noise through L*'s slope at the grey) has
    the weighted variance ``s^2`` times the mean of ``CSF^2`` over the frequencies up to Nyquist.

    Parameters
    ----------
    rows : int
        The picture's height in pixels.
    shape : (h, w)
        The frequency grid the mean is taken on (a patch's size).
    picture_height_cm, viewing_distance_cm : float
        The viewing conditions.

    Returns
    -------
    float
        sigma of L*.
    """
    ppd = rows / _degrees(rows, picture_height_cm, viewing_distance_cm)
    slope = 116 / 3 * THRESHOLD_GREY ** (-2 / 3)  # dL*/dY
    s = slope * THRESHOLD_NOISE * THRESHOLD_GREY
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.fftfreq(shape[1])[None, :]
    w = csf(np.hypot(fy, fx) * ppd)
    w[0, 0] = 0.0
    return float(s * math.sqrt(np.mean(w**2)))


def banding(y: np.ndarray, axis: str = "columns", rows: int | None = None,
            picture_height_cm: float = PICTURE_HEIGHT_CM, viewing_distance_cm: float = VIEWING_DISTANCE_CM) -> dict:
    """How visible a patch's row or column banding is (see the module docstring).

    Parameters
    ----------
    y : (h, w) array
        A uniform patch's relative luminance (1: the picture's white).
    axis : {"columns", "rows"}
        Column banding (each column's mean, along the row) or row banding.
    rows : int, optional
        The whole picture's height in pixels (the patch's by default).
    picture_height_cm, viewing_distance_cm : float
        The viewing conditions.

    Returns
    -------
    dict
        ``sigma_l`` (the CSF-weighted standard deviation of the line means' L*), ``visibility`` (over the
        just-detectable noise: 1 is the threshold), ``visible`` (visibility >= 1), ``threshold_sigma_l``, and the
        viewing conditions.
    """
    a = _check(y, "banding")
    if axis not in ("columns", "rows"):
        raise CmosnoiseError(f"banding: axis = {axis!r}; give columns or rows")
    rows = a.shape[0] if rows is None else int(rows)
    ppd = rows / _degrees(rows, picture_height_cm, viewing_distance_cm)
    lum = lightness(a)
    profile = lum.mean(axis=0 if axis == "columns" else 1)
    dev = profile - profile.mean()
    f = np.fft.rfftfreq(dev.size)
    weight = csf(f * ppd)
    weight[0] = 0.0
    filtered = np.fft.irfft(np.fft.rfft(dev) * weight, n=dev.size)
    sigma = float(filtered.std())
    unit = threshold_sigma_l(rows, a.shape, picture_height_cm, viewing_distance_cm)
    return {"sigma_l": sigma, "visibility": sigma / unit, "visible": bool(sigma >= unit), "threshold_sigma_l": unit,
            "pixels_per_degree": ppd, "picture_height_cm": picture_height_cm,
            "viewing_distance_cm": viewing_distance_cm}
