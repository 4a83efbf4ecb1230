"""Scores of a denoiser or a defect corrector against a sample's ground truth.

- **PSNR and SSIM** (scikit-image's metrics) of the output against the
  target, both normalized as
  ``(DN - black) / (white - black)``; SSIM over the CFA's colour planes
  (each plane a channel), so no demosaicing enters the score. The target is
  the expected raw without its defects (:func:`defect_free`: each masked
  pixel at the median of its healthy same-colour neighbours' expected
  values), what a perfect denoiser and defect corrector together give; or
  the perfect image.
- **Defects left**, by kind: a defect pixel of the mask is *visible* where
  the noisy frame departs from its healthy same-colour neighbours' median
  in the expected raw by more than ``z`` robust sigmas of that departure
  over the healthy pixels, and *left* where the output still does, by the
  output's own sigma. The kinds: ``singles`` (a white pixel without a
  white neighbour, a dead, stuck, low- or high-gain pixel), ``couplets``
  and ``clusters``.
"""

from __future__ import annotations

import numpy as np

from .. import inputs
from ..errors import CmosnoiseError
from ..estimators import robust_sigma
from ..isp.defects import neighbours_at
from .ground_truth import MASK_BITS

#: defect kinds as the score groups them: name -> the mask bits that make a pixel one
KINDS = {
    "singles": MASK_BITS["white"] | MASK_BITS["dead"] | MASK_BITS["stuck"] | MASK_BITS["low_gain"]
    | MASK_BITS["high_gain"],
    "couplets": MASK_BITS["couplet"],
    "clusters": MASK_BITS["cluster"],
}
#: the departures a pixel is visible (left) above, in robust sigmas
Z_VISIBLE = 6.0
#: the image scores :func:`image_scores` gives, each (name, what it is, unit, which way is better): the one list
#: that ``evaluate``'s tables, summary and report iterate
SCORES = (
    ("psnr_db", "PSNR over the camera's white-minus-black range", "dB", "higher"),
    ("psnr_own_range_db", "PSNR over the target's own range", "dB", "higher"),
    ("ssim", "SSIM over the CFA's colour planes", "", "higher"),
)


def planes(a: np.ndarray) -> np.ndarray:
    """(H, W) -> (4, H/2, W/2): the four CFA positions as channels."""
    return np.stack([a[0::2, 0::2], a[0::2, 1::2], a[1::2, 0::2], a[1::2, 1::2]])


def image_scores(output: np.ndarray, target: np.ndarray, black: float, white: float) -> dict:
    """PSNR (dB) and SSIM of ``output`` against ``target`` (both (H, W), DN), normalized to [0, 1] of the range:
    the scores of :data:`SCORES`, by name.

    ``psnr_db`` is over the white-minus-black range (the camera's whole code range: comparable across samples
    of one camera, high for dark samples); ``psnr_own_range_db`` over the target's own range (its largest minus
    its smallest value, DN), as the low-light denoising literature normalises each image (NaN for a flat target).
    """
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    output, target = _frame(output, "output"), _frame(target, "target")
    if output.shape != target.shape:
        raise CmosnoiseError(f"output: shape {output.shape}, target {target.shape}; they must be the same frame")
    try:
        black, white = float(black), float(white)
    except (TypeError, ValueError):
        raise CmosnoiseError(f"black, white = {black!r}, {white!r}: expected two numbers (DN)") from None
    if not (np.isfinite(black) and np.isfinite(white) and white > black):
        raise CmosnoiseError(f"black, white = {black!r}, {white!r}: expected finite levels, white above black")
    scale = 1.0 / (white - black)
    out = (np.asarray(output, np.float64) - black) * scale
    ref = (np.asarray(target, np.float64) - black) * scale
    p_out, p_ref = planes(out), planes(ref)
    win = min(7, min(p_ref.shape[1:]) // 2 * 2 - 1)
    own = float(np.max(target) - np.min(target))
    mse = float(np.mean((np.asarray(output, np.float64) - np.asarray(target, np.float64)) ** 2))
    with np.errstate(divide="ignore"):
        own_db = float(10.0 * np.log10(own * own / mse)) if own > 0 else float("nan")
    values = (float(peak_signal_noise_ratio(ref, out, data_range=1.0)), own_db,
              float(structural_similarity(p_ref, p_out, data_range=1.0, channel_axis=0, win_size=win)))
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
    """Per kind of :data:`KINDS`: how many defects are visible in ``noisy`` and how many of those ``output``
    leaves, and each pixel's verdict."""
    import warnings

    healthy = mask == 0
    rows, cols = np.nonzero(healthy[::3, ::3])  # every third row and column's healthy pixels, for the sigmas
    rows, cols = rows * 3, cols * 3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN neighbourhoods: handled
        sig_noisy = robust_sigma(_departure(noisy, expected, healthy, pattern, rows, cols))
        sig_out = robust_sigma(_departure(output, expected, healthy, pattern, rows, cols))
        out = {}
        for kind, bits in KINDS.items():
            r, c = np.nonzero((mask & bits) > 0)
            if kind == "singles":  # a white pixel of a couplet is a couplet's
                solo = (mask[r, c] & MASK_BITS["couplet"]) == 0
                r, c = r[solo], c[solo]
            visible = np.abs(_departure(noisy, expected, healthy, pattern, r, c)) > z * max(sig_noisy, 0.5)
            left = visible & (np.abs(_departure(output, expected, healthy, pattern, r, c)) > z * max(sig_out, 0.5))
            out[kind] = {"visible": int(visible.sum()), "left": int(left.sum())}
    return out
