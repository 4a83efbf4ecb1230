"""Visual noise and banding visibility: noise weighted by the eye's contrast sensitivity at stated viewing conditions.

**Viewing conditions** (:class:`Viewing`) set the pixels per degree of visual angle: a print (the picture, its
``rows`` pixels, ``picture_height_cm`` high, seen from ``viewing_distance_cm``: it spans
``360 / pi * atan(h / 2 d)`` degrees), or a display at 100 % (one pixel of ``pixel_pitch_mm`` seen from
``viewing_distance_cm``). Every result says which.

**Visual luminance noise** (:func:`visual_luminance_noise`): the patch's relative luminance Y (1: white) as CIE L*
(``116 Y^(1/3) - 16``, linear below ``(6/29)^3``) less its mean, its 2-D DFT weighted by the luminance contrast
sensitivity ``CSF(v) = a v^c exp(-b v) / K``, a = 75, b = 0.2, c = 0.8, K = 34.05 (ISETCam's ``cpiqCSF.m``, the
CPIQ luminance CSF; Baxter et al., SPIE 8293, 2012) scaled to 1 at its 4 cycles/degree peak, the zero frequency
0; the inverse DFT's standard deviation.

**Visual noise of a colour picture**, three named variants (:data:`VARIANTS`, :func:`visual_noise`), each of linear
sRGB (rows, cols, 3):

- ``iso15739_2013``: ISO 15739:2013's visual noise as two public re-implementations write it (a phone-camera tuning
  script; Pedersen's ``ColorContrastFiltering.m``) and Imatest's and Image Engineering's descriptions: XYZ (D65)
  to illuminant E by Bradford, the opponent space ``A = Y, C1 = X - Y, C2 = 0.4 (Y - Z)``, each channel's DFT
  weighted by its CSF (A: the luminance CSF above at its 2013 scale, K = 34.05, a peak of 3; C1, C2: Johnson and
  Fairchild's sums of two exponentials ``a1 exp(-b1 f^c1) + a2 exp(-b2 f^c2)``, C2 less its constant floor a1,
  each 1 at f = 0) with the DC term 0 (the filters act on the patch less its mean, which is restored), back to XYZ,
  **negative XYZ set to 0** (the reference implementation's two steps, as Image Engineering's techNote 669 says),
  to D65 by Bradford, CIELUV; ``VN = sigma(L*) + 0.852 sigma(u*) + 0.323 sigma(v*)``. The standard's own text was
  not read: this is the variant its re-implementations give;
- ``scielab``: S-CIELAB (Zhang and Wandell 1996) with ISETCam's constants: XYZ (D65) to its opponent space by the
  10-degree matrix of ``colorTransformMatrix.m``, each channel filtered by its default sum of Gaussians
  (``scGaussianParameters.m``: half widths at half maximum in degrees and weights; each Gaussian of unit sum, the
  weighted sum renormalised to 1, applied in the frequency domain, so any pixels per degree sample it exactly),
  back to XYZ, CIELAB (D65); ``sqrt(var L* + var a* + var b*)``, and ISETCam's vSNR, its inverse (infinite for a
  noise-free patch);
- ``cpiq``: the CPIQ (IEEE 1858) form of Keelan et al. (SPIE 7867, 2011): the opponent filtering of
  ``iso15739_2013`` with the luminance CSF normalised to 1 at its peak (K = 102.16, CPIQ's), CIELAB (D65), and the
  weighted sum ``100 var(L*) + 5 var(a*) + 12 cov(L*, a*)`` (their "relative weights of 100, 5 and 12"; the
  covariance is "normally negative"). The wrapper that maps it to just-noticeable differences of quality loss is
  not in any public text read, so none is applied.

**Banding** (row or column noise, VFPN) is a 1-D pattern: the line means of L* filtered by the luminance CSF along
their axis. Lines are a small modulation of a grey, so their L* is their luminance times L*'s slope at the patch's
mean (:func:`lightness_slope`): linear, so a noisy pixel's L* does not bend them (a patch's negative pixels, a dark
frame's, are kept). Isotropic noise of any spectrum also has line means, of variance ``1 / rows`` of its own: white noise
alone would read as banding (0.9 JND at 1 lux on the default sensor). So the lines are estimated from two
independent groups of the patch's rows (eight, for column banding: each group's column means): their filtered
profiles share the lines, not the noise, so the mean product over every pair of different groups is an unbiased
estimate of the lines' filtered variance (0 in expectation without lines; a negative estimate reads 0), with
``2 K / (K - 1)`` times the squared profile noise's variance over the profile's independent points (two halves
alone would have 4). Its visibility is its square root
over the visual luminance noise of **3 % white luminance noise on a mid grey** at the same viewing conditions, the
noise "observers can just barely detect" in a uniform image (ISETCam's MPE30, after Wandell's *Foundations of
Vision*): 1 is the threshold, one just-noticeable difference.

Examples
--------
>>> import numpy as np
>>> from cmosnoise.analysis import visual_noise
>>> flat = np.full((64, 64), 0.18)
>>> visual_noise.visual_luminance_noise(flat)["sigma_l"]
0.0
>>> round(visual_noise.visual_noise(np.full((64, 64, 3), 0.18), "iso15739_2013")["value"], 12)
0.0
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..engine import colorimetry
from ..errors import CmosnoiseError

#: the CPIQ luminance CSF's constants (ISETCam cpiqCSF.m): a v^c exp(-b v) / K, v in cycles per degree
CSF_A, CSF_B, CSF_C, CSF_K = 75.0, 0.2, 0.8, 34.05
#: the default viewing conditions of a print: a picture 20 cm high seen from 50 cm
PICTURE_HEIGHT_CM, VIEWING_DISTANCE_CM = 20.0, 50.0
#: the default viewing conditions of a display at 100 %: a 100 ppi monitor (0.254 mm pixels) seen from 60 cm, a
#: desktop's distance (our statement: no standard's text was read for it)
DISPLAY_PIXEL_PITCH_MM, DISPLAY_DISTANCE_CM = 0.254, 60.0
#: the just-detectable noise of a uniform picture: 3 % of a mid grey's luminance (ISETCam's MPE30)
THRESHOLD_NOISE, THRESHOLD_GREY = 0.03, 0.18
#: the groups of consecutive lines :func:`banding` cross-estimates the lines from (all their pairs)
BANDING_GROUPS = 8
#: the visual-noise variants :func:`visual_noise` takes
VARIANTS = ("iso15739_2013", "scielab", "cpiq")
#: ISO 15739's chrominance CSFs, (a1, b1, c1, a2, b2, c2) of a1 exp(-b1 f^c1) + a2 exp(-b2 f^c2): Johnson and
#: Fairchild's, as Pedersen's ColorContrastFiltering.m gives them (its exp(b f^c) with negative b written here
#: as exp(-b f^c))
CSF_C1 = (109.1413, 0.00038, 3.42436, 93.59711, 0.00367, 2.16771)
CSF_C2 = (7.0328, 0.0, 4.2582, 40.6910, 0.1039, 1.6487)
#: ISO 15739's opponent space from XYZ under illuminant E, and its inverse
XYZ_TO_ACC = np.array([[0.0, 1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 0.4, -0.4]])
ACC_TO_XYZ = np.array([[1.0, 1.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, -2.5]])
#: ISO 15739's weights of sigma(L*), sigma(u*), sigma(v*)
ISO_WEIGHTS = (1.0, 0.852, 0.323)
#: CPIQ's (Keelan et al.) relative weights of var(L*), var(a*) and cov(L*, a*)
CPIQ_WEIGHTS = (100.0, 5.0, 12.0)
#: S-CIELAB's opponent space from XYZ, ISETCam's 10 degree matrix (colorTransformMatrix.m; its red-green row ends
#: in +0.0624, where many re-implementations copy a 3-decimal matrix with a sign changed)
XYZ_TO_OPP_10DEG = np.array([[288.5613, 659.7617, -130.5654], [-464.8864, 326.2702, 62.4200],
                             [79.8787, -554.7976, 481.4746]]) / 1000.0
#: S-CIELAB's default filters (scGaussianParameters.m): per channel, (half width at half maximum in degrees, weight)
SCIELAB_FILTERS = (((0.05, 1.00327), (0.225, 0.114416), (7.0, -0.117686)),
                   ((0.0685, 0.616725), (0.826, 0.383275)),
                   ((0.0920, 0.567885), (0.6451, 0.432115)))

__all__ = ["Viewing", "print_viewing", "display_viewing", "csf", "csf_chroma", "lightness", "visual_luminance_noise",
           "visual_noise", "scielab_filter", "banding", "threshold_sigma_l", "VARIANTS"]


# ------------------------------------------------------------------ viewing conditions
@dataclass(frozen=True)
class Viewing:
    """Viewing conditions: how many pixels of the picture fall in one degree of visual angle.

    Parameters
    ----------
    pixels_per_degree : float
    kind : {"print", "display"}
    described : dict
        The conditions as given (picture height and distance, or pixel pitch and distance).
    """

    pixels_per_degree: float
    kind: str
    described: dict

    def as_dict(self) -> dict:
        """The conditions and their pixels per degree, for a result."""
        return {"viewing": self.kind, "pixels_per_degree": self.pixels_per_degree, **self.described}


def _positive(**values) -> None:
    bad = {k: v for k, v in values.items() if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0)}
    if bad:
        shown = ", ".join(f"{k} = {v!r}" for k, v in bad.items())
        raise CmosnoiseError(f"viewing conditions: {shown}; each must be a finite number above 0")


def print_viewing(rows: int, picture_height_cm: float = PICTURE_HEIGHT_CM,
                  viewing_distance_cm: float = VIEWING_DISTANCE_CM) -> Viewing:
    """A print (or a picture fitted to a screen) of ``rows`` pixels, ``picture_height_cm`` high, seen from
    ``viewing_distance_cm``.

    Parameters
    ----------
    rows : int
        The whole picture's height in pixels.
    picture_height_cm, viewing_distance_cm : float

    Returns
    -------
    Viewing
    """
    _positive(rows=rows, picture_height_cm=picture_height_cm, viewing_distance_cm=viewing_distance_cm)
    degrees = math.degrees(2 * math.atan(picture_height_cm / (2 * viewing_distance_cm)))
    return Viewing(rows / degrees, "print", {"picture_rows": int(rows), "picture_height_cm": picture_height_cm,
                                            "viewing_distance_cm": viewing_distance_cm})


def display_viewing(pixel_pitch_mm: float = DISPLAY_PIXEL_PITCH_MM,
                    viewing_distance_cm: float = DISPLAY_DISTANCE_CM) -> Viewing:
    """A display showing the picture at 100 % (a picture's pixel per screen pixel), its pixels ``pixel_pitch_mm``
    apart, seen from ``viewing_distance_cm``.

    Parameters
    ----------
    pixel_pitch_mm, viewing_distance_cm : float

    Returns
    -------
    Viewing
    """
    _positive(display_pixel_pitch_mm=pixel_pitch_mm, display_distance_cm=viewing_distance_cm)
    degrees = math.degrees(2 * math.atan(pixel_pitch_mm / 10.0 / (2 * viewing_distance_cm)))
    return Viewing(1.0 / degrees, "display", {"display_pixel_pitch_mm": pixel_pitch_mm,
                                             "viewing_distance_cm": viewing_distance_cm})


def _viewing(rows, picture_height_cm, viewing_distance_cm, viewing: Viewing | None, default_rows: int) -> Viewing:
    if viewing is not None:
        return viewing
    return print_viewing(default_rows if rows is None else int(rows), picture_height_cm, viewing_distance_cm)


# ------------------------------------------------------------------ sensitivities and lightness
def csf(v: np.ndarray) -> np.ndarray:
    """The luminance contrast sensitivity, 1 at its peak (4 cycles/degree).

    Parameters
    ----------
    v : array
        Spatial frequency, cycles per degree, >= 0.

    Returns
    -------
    array
        ``a v^c exp(-b v) / K`` over its peak value (its peak value is 3.0 at K = 34.05, ISO 15739:2013's scale).
    """
    v = np.asarray(v, float)
    peak = CSF_C / CSF_B
    return (v / peak) ** CSF_C * np.exp(-CSF_B * (v - peak))


def csf_chroma(v: np.ndarray, channel: str) -> np.ndarray:
    """ISO 15739's chrominance contrast sensitivity, 1 at zero frequency.

    Parameters
    ----------
    v : array
        Spatial frequency, cycles per degree, >= 0.
    channel : {"C1", "C2"}
        Red-green or yellow-blue.

    Returns
    -------
    array
        ``(a1 exp(-b1 v^c1) + a2 exp(-b2 v^c2) - floor) / (a1 + a2 - floor)``, floor ``a1`` for C2 (its first term
        is constant) and 0 for C1.
    """
    a1, b1, c1, a2, b2, c2 = {"C1": CSF_C1, "C2": CSF_C2}[channel]
    v = np.asarray(v, float)
    floor = a1 if channel == "C2" else 0.0
    return (a1 * np.exp(-b1 * v**c1) + a2 * np.exp(-b2 * v**c2) - floor) / (a1 + a2 - floor)


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


def lightness_slope(y: float) -> float:
    """dL*/dY at relative luminance ``y``: ``116 / 3 y^(-2/3)``, ``(29/3)^3`` below ``(6/29)^3``.

    Parameters
    ----------
    y : float
        Relative luminance (1: white), > 0.

    Returns
    -------
    float
        L* per unit of relative luminance.
    """
    return float(116.0 / 3.0 * y ** (-2.0 / 3.0) if y > (6 / 29) ** 3 else (29 / 3) ** 3)


def _check(y, what: str, negative: bool = False) -> np.ndarray:
    a = np.asarray(y)
    if a.ndim != 2 or a.dtype.kind not in "uif" or min(a.shape) < 4:
        raise CmosnoiseError(f"{what}: give one 2-D patch of relative luminance, at least 4 x 4; got {a.shape}")
    a = a.astype(np.float64)
    if not np.isfinite(a).all() or (not negative and (a < 0).any()):
        raise CmosnoiseError(f"{what}: the luminance must be finite{'' if negative else ' and >= 0'}")
    return a


def _radial(shape: tuple[int, int], ppd: float) -> np.ndarray:
    """Each DFT coefficient's spatial frequency, cycles per degree (``fft2``'s order)."""
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.fftfreq(shape[1])[None, :]
    return np.hypot(fy, fx) * ppd


# ------------------------------------------------------------------ luminance noise
def visual_luminance_noise(y: np.ndarray, rows: int | None = None, picture_height_cm: float = PICTURE_HEIGHT_CM,
                           viewing_distance_cm: float = VIEWING_DISTANCE_CM, viewing: Viewing | None = None) -> dict:
    """The visual luminance noise of a uniform patch (see the module docstring).

    Parameters
    ----------
    y : (h, w) array
        The patch's relative luminance (1: the picture's white).
    rows : int, optional
        The whole picture's height in pixels (the patch's own by default), for a print's viewing conditions.
    picture_height_cm, viewing_distance_cm : float
        A print's viewing conditions.
    viewing : Viewing, optional
        Other viewing conditions (a display's), in place of the print's.

    Returns
    -------
    dict
        ``sigma_l`` (the CSF-weighted standard deviation of L*), ``sigma_l_unweighted``, ``mean_l`` and the
        viewing conditions (``pixels_per_degree`` among them).
    """
    a = _check(y, "visual noise")
    view = _viewing(rows, picture_height_cm, viewing_distance_cm, viewing, a.shape[0])
    lum = lightness(a)
    dev = lum - lum.mean()
    fy = np.fft.fftfreq(a.shape[0])[:, None]
    fx = np.fft.rfftfreq(a.shape[1])[None, :]
    weight = csf(np.hypot(fy, fx) * view.pixels_per_degree)
    weight[0, 0] = 0.0
    filtered = np.fft.irfft2(np.fft.rfft2(dev) * weight, s=a.shape)
    return {"sigma_l": float(filtered.std()), "sigma_l_unweighted": float(dev.std()), "mean_l": float(lum.mean()),
            **view.as_dict()}


def threshold_sigma_l(rows: int | None = None, shape: tuple[int, int] = (256, 256),
                      picture_height_cm: float = PICTURE_HEIGHT_CM, viewing_distance_cm: float = VIEWING_DISTANCE_CM,
                      viewing: Viewing | None = None) -> float:
    """The visual luminance noise of the just-detectable noise (:data:`THRESHOLD_NOISE` white noise on
    :data:`THRESHOLD_GREY`) at these viewing conditions: the unit of :func:`banding`'s visibility.

    Computed analytically: white noise of L* sigma ``s`` (the luminance noise through L*'s slope at the grey) has
    the weighted variance ``s^2`` times the mean of ``CSF^2`` over the frequencies up to Nyquist.

    Parameters
    ----------
    rows : int, optional
        The picture's height in pixels (a print's viewing conditions; the patch's rows by default).
    shape : (h, w)
        The frequency grid the mean is taken on (a patch's size).
    picture_height_cm, viewing_distance_cm : float
        A print's viewing conditions.
    viewing : Viewing, optional
        Other viewing conditions.

    Returns
    -------
    float
        sigma of L*.
    """
    view = _viewing(rows, picture_height_cm, viewing_distance_cm, viewing, shape[0])
    slope = 116 / 3 * THRESHOLD_GREY ** (-2 / 3)  # dL*/dY
    s = slope * THRESHOLD_NOISE * THRESHOLD_GREY
    w = csf(_radial(shape, view.pixels_per_degree))
    w[0, 0] = 0.0
    return float(s * math.sqrt(np.mean(w**2)))


# ------------------------------------------------------------------ colour visual noise
def _colour():
    from .. import colour_lib

    return colour_lib.colour()


def _check_rgb(rgb) -> np.ndarray:
    a = np.asarray(rgb)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype.kind not in "uif" or min(a.shape[:2]) < 4:
        raise CmosnoiseError(f"visual noise: give one (rows, cols, 3) patch of linear sRGB, at least 4 x 4; got "
                             f"{a.shape}")
    a = a.astype(np.float32, copy=False)  # single precision: the figures to 1e-6 of themselves, half the memory and time
    if not np.isfinite(a).all():
        raise CmosnoiseError("visual noise: the patch's values must be finite")
    return a


def _srgb_to_xyz() -> np.ndarray:
    """sRGB's matrix from linear RGB to CIE XYZ under D65 (IEC 61966-2-1, colour-science's table)."""
    return np.asarray(_colour().RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ, float)


def _white() -> np.ndarray:
    """The sRGB matrix's own white (its rows' sums: D65 to the matrix's 4 digits), so a neutral patch stays
    exactly neutral."""
    return _srgb_to_xyz().sum(axis=1)


def _bradford(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    return np.asarray(_colour().adaptation.matrix_chromatic_adaptation_VonKries(source, target,
                                                                                transform="Bradford"), float)


@functools.lru_cache(maxsize=16)
def _weights(shape: tuple[int, int], ppd: float, kind: str) -> np.ndarray:
    """A filter's frequency response on ``rfft2``'s grid of ``shape`` at ``ppd`` pixels per degree, float32, made
    once: ``A`` (the luminance CSF at its 2013 scale, peak 3), ``A1`` (peak 1), ``C1``, ``C2``, ``S0``..``S2``
    (S-CIELAB's)."""
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    f = np.hypot(fy, fx) * ppd
    if kind in ("A", "A1"):
        w = csf(f) * (3.0 if kind == "A" else 1.0)
    elif kind in ("C1", "C2"):
        w = csf_chroma(f, kind)
    else:
        w = scielab_filter(f, int(kind[1]))
    # a Gaussian's tail underflows to subnormal floats, which make every FFT after them several times slower: a
    # weight under 1e-12 of the peak adds nothing a variance can see, and is 0
    w = np.where(np.abs(w) < 1e-12 * np.abs(w).max(), 0.0, w).astype(np.float32)
    w.setflags(write=False)
    return w


def _filtered(channel: np.ndarray, weight: np.ndarray, keep_mean: bool = True) -> np.ndarray:
    """``channel`` (float32) less its mean through the frequency weights (``rfft2``'s order), its mean restored:
    the DC term is not weighted (``keep_mean``), or it is the weight's."""
    import scipy.fft as sfft

    mean = np.float32(channel.mean(dtype=np.float64)) if keep_mean else np.float32(0.0)
    channel -= mean
    spectrum = sfft.rfft2(channel, workers=-1)
    spectrum *= weight
    out = sfft.irfft2(spectrum, s=channel.shape, workers=-1, overwrite_x=True)  # the spectrum is ours: no copy
    out += mean
    return out


def _opponent_filtered(rgb: np.ndarray, ppd: float, luminance_scale: float) -> np.ndarray:
    """ISO 15739's opponent channels A, C1, C2 (under illuminant E) of linear sRGB, each filtered by its CSF:
    (3, rows, cols) float32."""
    white = _white()
    to_acc = XYZ_TO_ACC @ _bradford(white, np.ones(3)) @ _srgb_to_xyz()  # linear sRGB to A, C1, C2 at once
    kinds = ("A" if luminance_scale == 3.0 else "A1", "C1", "C2")
    acc = colorimetry.mix(rgb, to_acc)
    for c, k in enumerate(kinds):
        acc[c] = _filtered(acc[c], _weights(rgb.shape[:2], ppd, k))
    return acc


def visual_noise(rgb: np.ndarray, variant: str = "iso15739_2013", viewing: Viewing | None = None) -> dict:
    """The visual noise of a uniform colour patch, by one of :data:`VARIANTS` (see the module docstring).

    Parameters
    ----------
    rgb : (rows, cols, 3) array
        Linear sRGB (1: the picture's white), the patch's frames or one.
    variant : {"iso15739_2013", "scielab", "cpiq"}
    viewing : Viewing, optional
        Default: a print of the patch's own rows at the default height and distance.

    Returns
    -------
    dict
        ``variant``, ``value`` (the variant's figure: ISO's VN in L* units, S-CIELAB's sqrt of the summed
        variances, CPIQ's weighted sum in L*^2), its parts (``sigma_l``, ``sigma_u``, ``sigma_v``; ``sigma_l``,
        ``sigma_a``, ``sigma_b`` and ``vsnr``, infinite without noise; ``var_l``, ``var_a``, ``cov_la``), the
        viewing conditions and ``source``.
    """
    if variant not in VARIANTS:
        raise CmosnoiseError(f"visual noise variant = {variant!r} is not known; give one of {', '.join(VARIANTS)}")
    a = _check_rgb(rgb)
    view = viewing if viewing is not None else print_viewing(a.shape[0])
    white = _white()
    out = {"variant": variant, **view.as_dict()}
    flat = bool((a == a[0, 0]).all())  # no noise at all: every figure exactly 0 (the transforms' rounding aside)
    to_d65 = _bradford(np.ones(3), white)
    if variant == "iso15739_2013":  # to XYZ under E, negatives to 0, to D65, CIELUV
        m = colorimetry.moments(_opponent_filtered(a, view.pixels_per_degree, 3.0), ACC_TO_XYZ, True, to_d65, white,
                                colorimetry.LUV)
        s = np.zeros(3) if flat else np.sqrt(m["var"])
        value = float(ISO_WEIGHTS[0] * s[0] + ISO_WEIGHTS[1] * s[1] + ISO_WEIGHTS[2] * s[2])
        out.update(value=value, sigma_l=float(s[0]), sigma_u=float(s[1]), sigma_v=float(s[2]),
                   source="ISO 15739:2013 as its public re-implementations write it (the standard's text not read)")
    elif variant == "cpiq":
        m = colorimetry.moments(_opponent_filtered(a, view.pixels_per_degree, 1.0), ACC_TO_XYZ, True, to_d65, white,
                                colorimetry.LAB)
        var_l, var_a, cov = (0.0, 0.0, 0.0) if flat else (float(m["var"][0]), float(m["var"][1]),
                                                          float(m["cov"][0]))
        w = CPIQ_WEIGHTS
        out.update(value=w[0] * var_l + w[1] * var_a + w[2] * cov, var_l=var_l, var_a=var_a, cov_la=cov,
                   source="Keelan et al., SPIE 7867 (2011): CPIQ's weighted sum, no JND mapping")
    else:
        opp = colorimetry.mix(a, XYZ_TO_OPP_10DEG @ _srgb_to_xyz())
        for c in range(3):
            opp[c] = _filtered(opp[c], _weights(a.shape[:2], view.pixels_per_degree, f"S{c}"), keep_mean=False)
        m = colorimetry.moments(opp, np.linalg.inv(XYZ_TO_OPP_10DEG), False, np.eye(3), white, colorimetry.LAB)
        var = np.zeros(3) if flat else m["var"]
        total = float(var.sum())
        out.update(value=math.sqrt(total), sigma_l=float(math.sqrt(var[0])), sigma_a=float(math.sqrt(var[1])),
                   sigma_b=float(math.sqrt(var[2])), vsnr=(1.0 / math.sqrt(total)) if total > 0 else math.inf,
                   source="S-CIELAB, ISETCam's 10 degree opponent matrix and default filters")
    return out


def scielab_filter(f_cpd: np.ndarray, channel: int) -> np.ndarray:
    """S-CIELAB's spatial filter of an opponent channel as a frequency response: ``sum_i w_i G_i(f) / sum_i w_i``,
    ``G_i`` the transform of a Gaussian of unit sum whose half width at half maximum is ``h_i`` degrees
    (``sigma = h / sqrt(2 ln 2)``): 1 at zero frequency, a filter that sums to 1.

    Parameters
    ----------
    f_cpd : array
        Spatial frequency, cycles per degree.
    channel : int
        0: luminance, 1: red-green, 2: blue-yellow (:data:`SCIELAB_FILTERS`).

    Returns
    -------
    array
    """
    pairs = SCIELAB_FILTERS[channel]
    f = np.asarray(f_cpd, float)
    h = np.zeros_like(f)
    for hwhm, weight in pairs:
        sigma = hwhm / math.sqrt(2 * math.log(2))
        h += weight * np.exp(-2 * math.pi**2 * sigma**2 * f**2)
    return h / sum(w for _, w in pairs)


# ------------------------------------------------------------------ banding
def banding(y: np.ndarray, axis: str = "columns", rows: int | None = None,
            picture_height_cm: float = PICTURE_HEIGHT_CM, viewing_distance_cm: float = VIEWING_DISTANCE_CM,
            viewing: Viewing | None = None) -> dict:
    """How visible a patch's row or column lines are (see the module docstring).

    Parameters
    ----------
    y : (h, w) array
        A uniform patch's relative luminance (1: the picture's white).
    axis : {"columns", "rows"}
        Column banding (each column's mean, along the row) or row banding.
    rows : int, optional
        The whole picture's height in pixels (the patch's by default), for a print's viewing conditions.
    picture_height_cm, viewing_distance_cm : float
        A print's viewing conditions.
    viewing : Viewing, optional
        Other viewing conditions (a display's).

    Returns
    -------
    dict
        ``sigma_l`` (the lines' CSF-weighted standard deviation of L*, the isotropic noise's share removed),
        ``sigma_l_with_noise`` (the line means' own, noise and all), ``visibility`` (``sigma_l`` over the
        just-detectable noise: 1 is the threshold), ``visible``, ``threshold_sigma_l``, ``estimate_se`` (the
        lines' variance estimate's standard error without lines, L*^2) and the viewing conditions.
    """
    a = _check(y, "banding", negative=True)
    if axis not in ("columns", "rows"):
        raise CmosnoiseError(f"banding: axis = {axis!r}; give columns or rows")
    view = _viewing(rows, picture_height_cm, viewing_distance_cm, viewing, a.shape[0])
    grey = float(a.mean())
    if not grey > 0:
        raise CmosnoiseError(f"banding: the patch's mean luminance is {grey:.3g}; give a patch brighter than black")
    # the lines are a small modulation of the grey: their L* is the luminance's times L*'s slope at the grey's
    # mean (linear, so the noise's part of each group stays independent and its square adds no lines; L* of each
    # noisy pixel would bend the lines by the noise's level)
    lum = (a - grey) * lightness_slope(grey)
    lines = lum if axis == "columns" else lum.T  # each column a line: the profile runs along the second axis
    groups = min(BANDING_GROUPS, lines.shape[0] // 2)
    if groups < 2:
        raise CmosnoiseError(f"banding: the patch has {lines.shape[0]} lines across; give at least 4")
    size = lines.shape[0] // groups
    weight = csf(np.fft.rfftfreq(lines.shape[1]) * view.pixels_per_degree)
    weight[0] = 0.0

    def profile(part):
        p = part.mean(axis=0)
        return np.fft.irfft(np.fft.rfft(p - p.mean()) * weight, n=p.size)

    whole = profile(lines)
    # each group of consecutive rows' filtered profile: the lines in every one, the noise independent between them;
    # the mean product over the pairs of different groups is an unbiased estimate of the lines' filtered variance
    f = np.stack([profile(lines[g * size:(g + 1) * size]) for g in range(groups)])
    total = f.sum(axis=0)
    estimate = float((np.mean(total * total) - np.mean((f * f).sum(axis=0))) / (groups * (groups - 1)))
    # its spread without lines: Var = 2 K / (K - 1) s^4 rho2 / n, s^2 a whole profile's noise variance (a group's
    # over K), rho2 the filtered noise's summed squared correlation (the filter's, by Parseval)
    auto = np.fft.irfft(weight**2, n=lines.shape[1])
    rho2 = float((auto**2).sum() / auto[0] ** 2) if auto[0] > 0 else 0.0
    s2 = float(np.mean(f.var(axis=1))) / groups
    se = float(np.sqrt(2 * groups / (groups - 1) * s2**2 * rho2 / lines.shape[1]))
    sigma = math.sqrt(max(estimate, 0.0))
    unit = threshold_sigma_l(shape=a.shape, viewing=view)
    return {"sigma_l": sigma, "sigma_l_with_noise": float(whole.std()), "visibility": sigma / unit,
            "visible": bool(sigma >= unit), "threshold_sigma_l": unit, "estimate_se": se, **view.as_dict()}
