"""Scores of a denoiser or a defect corrector against a sample's ground truth.

- **PSNR and SSIM as the low-light raw denoising literature reports them** (scikit-image's metrics): on
  *packed raw* (the four CFA positions as channels at half resolution), black subtracted, normalised to the
  white level, **amplified by the sample's exposure ratio and clipped to [0, 1]**, output and target alike:
  ``clip((DN - black) / (white - black) * ratio, 0, 1)``; SSIM over the four packed channels, data range 1.
  That is what PMN's evaluation does (``trainer_SID.py``: the short exposure times its ratio, ``clamp(0, 1)``,
  then PSNR and SSIM of the packed raw; ELD's and SID's evaluations amplify and clip alike), without its
  rounding to 8 bits. And on **sRGB through one fixed pipeline** (:func:`to_srgb`): the same amplified, clipped
  mosaic demosaiced bilinearly, white-balanced by the target's grey-world gains (both images the same gains),
  clipped, encoded by the sRGB curve (IEC 61966-2-1); no colour matrix (the camera's own RGB). And, for a
  camera's whole code range without a ratio, ``psnr_code_range_db``. The target is the expected raw without
  its defects (:func:`defect_free`: each masked pixel at the median of its healthy same-colour neighbours'
  expected values), what a perfect denoiser and defect corrector together give; or the perfect image. A
  score that would be infinite (an output equal to the target) is NaN, and tables leave it out, counted.
- **Defects left**, by kind: a defect pixel of the mask is *visible* where
  the noisy frame departs from its healthy same-colour neighbours' median
  in the expected raw by more than ``z`` robust sigmas of that departure
  over the healthy pixels, and *left* where the output still does, by the
  output's own sigma. The kinds (:data:`KINDS`): ``whites`` (a white pixel
  without a white neighbour), ``couplets``, ``clusters``, ``dead``, ``stuck``
  and ``gain`` (a low- or high-gain pixel). Each pixel counts once: a pixel
  of a couplet is the couplet's, and a pixel that is two single defects is
  the one that sets its value (dead, then stuck, then gain, then white). A
  corrector that maps its defects from dark frames cannot see a dead or a
  gain pixel there (each reads as its neighbours do in the dark): those kinds
  are reported apart so that its whites are not judged by them.
"""

from __future__ import annotations

import numpy as np

from .. import inputs
from ..errors import CmosnoiseError
from ..estimators import robust_sigma
from ..isp.defects import neighbours_at
from .ground_truth import MASK_BITS

#: defect kinds as the score groups them: name -> the mask bits that make a pixel one. The single defects
#: (:data:`SINGLES`) partition their pixels: a pixel of a couplet is the couplet's, and one that is two of them is
#: the first of :data:`SINGLES` it is
KINDS = {
    "whites": MASK_BITS["white"],
    "couplets": MASK_BITS["couplet"],
    "clusters": MASK_BITS["cluster"],
    "dead": MASK_BITS["dead"],
    "stuck": MASK_BITS["stuck"],
    "gain": MASK_BITS["low_gain"] | MASK_BITS["high_gain"],
}
#: the single defects, in the order that decides a pixel that is two of them: the defect that sets its value first
SINGLES = ("dead", "stuck", "gain", "whites")
#: the departures a pixel is visible (left) above, in robust sigmas
Z_VISIBLE = 6.0
#: the image scores :func:`image_scores` gives, each (name, what it is, unit, which way is better): the one list
#: that ``evaluate``'s tables, summary and report iterate
SCORES = (
    ("psnr_raw_db", "PSNR on packed raw in [0, 1] at the sample's exposure ratio (the literature's)", "dB", "higher"),
    ("ssim_raw", "SSIM on packed raw in [0, 1] at the sample's exposure ratio (the literature's)", "", "higher"),
    ("psnr_srgb_db", "PSNR on sRGB through the fixed pipeline, at the exposure ratio", "dB", "higher"),
    ("ssim_srgb", "SSIM on sRGB through the fixed pipeline, at the exposure ratio", "", "higher"),
    ("psnr_code_range_db", "PSNR over the camera's whole code range (white minus black), no ratio", "dB", "higher"),
)


def planes(a: np.ndarray) -> np.ndarray:
    """(H, W) -> (4, H/2, W/2): the four CFA positions as channels."""
    return np.stack([a[0::2, 0::2], a[0::2, 1::2], a[1::2, 0::2], a[1::2, 1::2]])


def normalised(a: np.ndarray, black: float, white: float, ratio: float = 1.0) -> np.ndarray:
    """``clip((a - black) / (white - black) * ratio, 0, 1)``: a raw frame as the literature scores it (float64).

    Parameters
    ----------
    a : (H, W) array, DN
    black, white : float
        The black and white levels, DN.
    ratio : float
        The exposure ratio the frame is amplified by (1: none).

    Returns
    -------
    (H, W) float64 array in [0, 1]
    """
    return np.clip((np.asarray(a, np.float64) - black) * (ratio / (white - black)), 0.0, 1.0)


def to_srgb(mosaic: np.ndarray, pattern: str, gains: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The fixed pipeline the sRGB scores use: a normalised mosaic in [0, 1] demosaiced bilinearly
    (colour-demosaicing), times white-balance gains (default: the grey-world gains of this image, green 1),
    clipped to [0, 1] and encoded by the sRGB curve; a monochrome mosaic is its own grey.

    Parameters
    ----------
    mosaic : (H, W) array in [0, 1]
    pattern : str
        The CFA (RGGB, ..., or none).
    gains : (3,) array, optional
        White-balance gains to apply (another image's, so output and target share them).

    Returns
    -------
    (H, W, 3) float64 array, and the gains used
    """
    from ..colour_lib import colour_demosaicing
    from ..model import cfa as cfa_mod

    if cfa_mod.is_mono(pattern):
        rgb = np.repeat(np.asarray(mosaic, np.float64)[..., None], 3, axis=2)
    else:
        rgb = np.asarray(colour_demosaicing().demosaicing_CFA_Bayer_bilinear(mosaic, pattern), np.float64)
    if gains is None:
        means = rgb.reshape(-1, 3).mean(axis=0)
        gains = np.where(means > 0, means[1] / np.where(means > 0, means, 1.0), 1.0)
    lin = np.clip(rgb * gains, 0.0, 1.0)
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.power(lin, 1 / 2.4) - 0.055), gains


def image_scores(output: np.ndarray, target: np.ndarray, black: float, white: float, ratio: float = 1.0,
                 pattern: str = "RGGB") -> dict:
    """The scores of :data:`SCORES` of ``output`` against ``target`` (both (H, W), DN), by name (see the module
    docstring): NaN where a score would be infinite (an output equal to the target).

    Parameters
    ----------
    output, target : (H, W) arrays, DN
    black, white : float
        The black and white levels, DN.
    ratio : float
        The sample's exposure ratio (both images amplified by it, as the literature scores a short exposure).
    pattern : str
        The CFA, for the sRGB pipeline's demosaicing.

    Returns
    -------
    dict
    """
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    output, target = _frame(output, "output"), _frame(target, "target")
    if output.shape != target.shape:
        raise CmosnoiseError(f"output: shape {output.shape}, target {target.shape}; they must be the same frame")
    try:
        black, white, ratio = float(black), float(white), float(ratio)
    except (TypeError, ValueError):
        raise CmosnoiseError(f"black, white, ratio = {black!r}, {white!r}, {ratio!r}: expected numbers") from None
    if not (np.isfinite(black) and np.isfinite(white) and white > black):
        raise CmosnoiseError(f"black, white = {black!r}, {white!r}: expected finite levels, white above black")
    if not (np.isfinite(ratio) and ratio >= 1):
        raise CmosnoiseError(f"ratio = {ratio!r}: an exposure ratio is a finite number >= 1")

    def psnr(ref, out) -> float:
        return float(peak_signal_noise_ratio(ref, out, data_range=1.0)) if np.any(ref != out) else float("nan")

    out, ref = normalised(output, black, white, ratio), normalised(target, black, white, ratio)
    p_out, p_ref = planes(out), planes(ref)
    win = min(7, min(p_ref.shape[1:]) // 2 * 2 - 1)
    ref_rgb, gains = to_srgb(ref, pattern)
    out_rgb, _ = to_srgb(out, pattern, gains)
    win_rgb = min(7, min(ref_rgb.shape[:2]) // 2 * 2 - 1)
    code_out, code_ref = normalised(output, black, white), normalised(target, black, white)
    values = (psnr(p_ref, p_out),
              float(structural_similarity(p_ref, p_out, data_range=1.0, channel_axis=0, win_size=win)),
              psnr(ref_rgb, out_rgb),
              float(structural_similarity(ref_rgb, out_rgb, data_range=1.0, channel_axis=2, win_size=win_rgb)),
              psnr(code_ref, code_out))
    return {name: v for (name, *_), v in zip(SCORES, values)}


def _frame(a, name: str) -> np.ndarray:
    """``a`` as a float64 frame, checked as the API's frames are (:func:`cmosnoise.inputs.check_frame`)."""
    return inputs.check_frame(a, name).astype(np.float64)


def defect_free(expected: np.ndarray, mask: np.ndarray, pattern: str) -> np.ndarray:
    """``expected`` (H, W) with each pixel of ``mask`` (nonzero) at the median of its healthy same-colour
    neighbours' values (float64; a pixel with no healthy neighbour keeps its own)."""
    import warnings

    out = np.asarray(expected, np.float64).copy()
    r, c = np.nonzero(mask)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        out[r, c] -= _departure(expected, expected, mask == 0, pattern, r, c)
    return out


def _departure(img: np.ndarray, expected: np.ndarray, healthy: np.ndarray, pattern: str, r, c) -> np.ndarray:
    """``img`` at (r, c) minus the median of the healthy same-colour neighbours' expected values."""
    vals = neighbours_at(expected, pattern, r, c).astype(np.float64)
    vals[~neighbours_at(healthy, pattern, r, c)] = np.nan
    ref = np.nanmedian(np.where(np.isfinite(vals).any(axis=0), vals, expected[r, c][None]), axis=0)
    return img[r, c].astype(np.float64) - ref


def defects_left(noisy: np.ndarray, output: np.ndarray, expected: np.ndarray, mask: np.ndarray,
                 pattern: str, z: float = Z_VISIBLE) -> dict:
    """Per kind of :data:`KINDS`: how many defect pixels are visible in ``noisy`` and how many of those ``output``
    leaves (``{kind: {"visible": n, "left": m}}``; a couplet is two pixels)."""
    import warnings

    healthy = mask == 0
    rows, cols = np.nonzero(healthy[::3, ::3])  # every third row and column's healthy pixels, for the sigmas
    rows, cols = rows * 3, cols * 3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN neighbourhoods: handled
        sig_noisy = robust_sigma(_departure(noisy, expected, healthy, pattern, rows, cols))
        sig_out = robust_sigma(_departure(output, expected, healthy, pattern, rows, cols))
        pixels, out = {}, {}
        claimed = MASK_BITS["couplet"]  # a white pixel of a couplet is a couplet's
        for kind in SINGLES:  # each single defect's pixels, less those an earlier kind claimed
            bits = KINDS[kind]
            pixels[kind] = np.nonzero(((mask & bits) > 0) & ((mask & claimed) == 0))
            claimed |= bits
        for kind, bits in KINDS.items():
            r, c = pixels[kind] if kind in SINGLES else np.nonzero((mask & bits) > 0)
            visible = np.abs(_departure(noisy, expected, healthy, pattern, r, c)) > z * max(sig_noisy, 0.5)
            left = visible & (np.abs(_departure(output, expected, healthy, pattern, r, c)) > z * max(sig_out, 0.5))
            out[kind] = {"visible": int(visible.sum()), "left": int(left.sum())}
    return out
