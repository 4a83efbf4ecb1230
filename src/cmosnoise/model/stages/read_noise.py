"""Stage 9a, read noise after the analogue gain and the black level's errors, in DN (docs/model.md stage 9a).

Measured cameras calibrate part of their read noise after the gain, in DN
(ELD, Wei et al. 2020): its law is often heavier-tailed than a normal, and
a Tukey-lambda law with shape ``lam`` and scale ``s`` fits it. Each pixel in
each frame gets ``s * z`` or ``s * Q(Phi(z))``, ``Q`` the standard
Tukey-lambda quantile (tabulated against ``z`` and interpolated:
:func:`cmosnoise.engine.samplers.tukey_lambda_from`), where ``z`` is the
second normal of the pixel's source-follower block (Box-Muller's sine branch;
the source follower, stage 6, takes the cosine): independent of every other
draw, and no Philox block of its own.

The black level has two errors beside ``adc.black_level_dn``: a fixed offset
per position of the 2 x 2 CFA cell (the "colour bias" of ELD's cameras), and
a per-frame error ``Normal(0, frame_sigma_dn)`` shared by every pixel of the
frame. Both are added to the black level before the rounding.
"""

from __future__ import annotations

import math

import numpy as np

from ...engine.samplers import Stream, normal_pair_from, tukey_lambda_from, tukey_lambda_table


def noise(kind: str, scale_dn: float, shape: float, stream: Stream, index: np.ndarray) -> np.ndarray:
    """One frame of read noise (DN), float64, at pixel indices ``index`` (``r * cols + c``).

    ``stream`` is the frame's source-follower stream: the noise is made from
    the sine normal of each pixel's block, whose cosine normal is the source
    follower's (:func:`cmosnoise.engine.samplers.normal_pair_from`).
    """
    _, z = normal_pair_from(*stream.uniforms(index))
    if kind == "normal":
        return scale_dn * z
    return scale_dn * tukey_lambda_from(z, tukey_lambda_table(float(shape)))


def tukey_lambda_variance(lam: float) -> float:
    """Variance of the standard Tukey-lambda law (scale 1); infinite for ``lam <= -0.5``."""
    if lam <= -0.5:
        return math.inf
    if lam == 0.0:
        return math.pi**2 / 3
    return 2.0 / lam**2 * (1.0 / (1.0 + 2.0 * lam) - math.exp(2 * math.lgamma(lam + 1) - math.lgamma(2 * lam + 2)))


def variance_dn2(kind: str, scale_dn: float, shape: float) -> float:
    """The read noise's variance, DN^2."""
    return scale_dn**2 * (1.0 if kind == "normal" else tukey_lambda_variance(shape))


def frame_error(sigma_dn: float, stream: Stream) -> float:
    """The black-level error of one frame (DN): one normal of the frame's stream, at index 0."""
    return float(sigma_dn * stream.normal(np.zeros(1, np.uint64))[0]) if sigma_dn > 0 else 0.0


def cell_black(black_level_dn: float, offsets_dn, frame_error_dn: float) -> np.ndarray:
    """The black level of each position of the 2 x 2 CFA cell in one frame, (2, 2) float64 DN:
    ``black + offset + frame error``, in that order (the kernel's)."""
    return (black_level_dn + np.asarray(offsets_dn, np.float64).reshape(2, 2)) + frame_error_dn


def black_map(cell: np.ndarray, region: tuple[int, int, int, int]) -> np.ndarray:
    """``cell`` laid over ``region = (row0, row1, col0, col1)`` by each pixel's position in the cell."""
    r0, r1, c0, c1 = region
    rows, cols = r1 - r0, c1 - c0
    origin = cell[np.ix_((np.arange(2) + r0) % 2, (np.arange(2) + c0) % 2)]  # the cell as the region's corner has it
    return np.tile(origin, ((rows + 1) // 2, (cols + 1) // 2))[:rows, :cols]  # copies, not a gather per pixel
