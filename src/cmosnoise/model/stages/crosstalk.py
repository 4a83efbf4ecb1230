"""Stage 3, diffusion crosstalk: photo-charge spreads to the neighbouring pixels.

The kernel ``k`` (3 x 3, fractions) gives where a photo-electron generated in
a pixel is collected: ``k[1, 1]`` is the fraction that stays (78.4 % in the
paper's Fig. 4), ``k[1 + dr, 1 + dc]`` the fraction collected by the pixel at
offset (dr, dc). ``sum(k) <= 1``; the rest is lost to the substrate.

The kernel acts on the photo-electron **mean**, before the shot-noise draw:
each electron lands in exactly one pixel, so collected counts stay independent
Poisson variables with mean ``k * mu`` (Poisson thinning) and the shot noise
is not smoothed (docs/model.md stage 3; the paper's MATLAB blurred the noisy image,
which lowers the shot-noise variance by ``sum(k**2)``).

A kernel per CFA colour models longer diffusion of red (deeper) photo-charge;
the colour is that of the pixel where the charge was generated. Edges reflect.

Examples
--------
>>> import numpy as np
>>> from cmosnoise import crosstalk
>>> kernel = [[0.9, 4.5, 0.9], [4.5, 78.4, 4.5], [0.9, 4.5, 0.9]]      # percent: the 0.18 um pixel's kernel
>>> lit = np.zeros((5, 5)); lit[2, 2] = 1000.0
>>> out = crosstalk.spread(lit, crosstalk.kernel_fractions(kernel))
>>> round(float(out[2, 2]), 1), round(float(out.sum()), 1)           # 78.4 % stays; the charge is kept
(784.0, 1000.0)
"""

from __future__ import annotations

import numpy as np

from ...engine import stencil
from .. import cfa as cfa_mod


def kernel_fractions(kernel_pct) -> np.ndarray | dict[str, np.ndarray]:
    """Kernel(s) from percent to fractions.

    Parameters
    ----------
    kernel_pct : (3, 3) array_like, or dict of them
        Percent of a pixel's charge that each neighbour receives (the centre keeps its own), or one such kernel
        per colour, ``{"R": k, "G": k, "B": k}``.

    Returns
    -------
    (3, 3) float64 array, or dict of them
        The same kernel(s) as fractions (divided by 100).
    """
    if isinstance(kernel_pct, dict):
        return {c: np.asarray(k, dtype=np.float64) / 100.0 for c, k in kernel_pct.items()}
    return np.asarray(kernel_pct, dtype=np.float64) / 100.0


def spread(mean_e: np.ndarray, kernel) -> np.ndarray:
    """Spread charge with one kernel: pixel q sends ``mean_e[q] * k[d]`` to pixel q + d (e-).

    Edges reflect (docs/model.md stage 3): charge that would diffuse off the
    array is sent back into the edge pixel it left, so the array keeps all
    the charge the kernel keeps, whatever the kernel's symmetry. (A
    convolution with ``mode="reflect"`` mirrors the sources instead, which
    loses charge at one edge and creates it at the other for a lopsided
    kernel.)

    Parameters
    ----------
    mean_e : (rows, cols) array, e-
        Charge per pixel before diffusion.
    kernel : (3, 3) array_like, fractions
        Fraction of a pixel's charge sent to each neighbour (:func:`kernel_fractions`).

    Returns
    -------
    (rows, cols) array, e-, of ``mean_e``'s dtype
        Charge per pixel after diffusion.
    """
    out = stencil.framed_convolve(mean_e, kernel)  # into a one-pixel frame around the array (ndimage's bits)
    out[1, :] += out[0, :]
    out[-2, :] += out[-1, :]
    out[:, 1] += out[:, 0]
    out[:, -2] += out[:, -1]
    return out[1:-1, 1:-1]


def apply(mean_e: np.ndarray, kernel, pattern: str = "none") -> np.ndarray:
    """Mean photo-electrons (e-) after diffusion crosstalk.

    Parameters
    ----------
    mean_e : (rows, cols) array, e-
        Charge per pixel before diffusion.
    kernel : (3, 3) array of fractions, or ``{"R": k, "G": k, "B": k}``
        One kernel for every pixel, or one per colour of the CFA.
    pattern : str
        The CFA pattern (RGGB, BGGR, GRBG, GBRG), used only with per-colour kernels.

    Returns
    -------
    (rows, cols) array, e-
        Charge per pixel after diffusion.
    """
    if not isinstance(kernel, dict):
        return spread(mean_e, kernel)
    out = np.zeros_like(mean_e)
    for name, mask in zip("RGB", cfa_mod.masks(pattern, mean_e.shape)):
        out += spread(np.where(mask, mean_e, 0).astype(mean_e.dtype), kernel[name])
    return out


def lean_kernels(kernel, kernel_at_angle) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's change from normal incidence to the reference angle, for light leaning each way.

    Parameters
    ----------
    kernel, kernel_at_angle : (3, 3) arrays of fractions
        At normal incidence, and at the reference angle for a pixel right of the optical centre.

    Returns
    -------
    (right, left, down, up) : four (3, 3) arrays
        ``kernel_at_angle - kernel`` for charge leaning toward +column, mirrored for -column, transposed for
        +row (down), and mirrored again for -row. Each sums to 0.
    """
    d = np.asarray(kernel_at_angle, np.float64) - np.asarray(kernel, np.float64)
    return d, d[:, ::-1], d.T, d.T[::-1, :]


def lean(mean_e: np.ndarray, leans: tuple, toward_col: np.ndarray, toward_row: np.ndarray, row0: int = 0) -> np.ndarray:
    """The charge that leaning crosstalk moves: what :func:`spread` adds for a kernel that depends on the pixel.

    Pixel q spreads with ``kernel + a(q) D_col + b(q) D_row``, where ``a`` and ``b`` are the signed shares of
    the reference angle's change along the columns and the rows (``(angle / reference) * cos(phi)`` and
    ``* sin(phi)``, phi the pixel's direction from the optical centre) and ``D`` the kernels of
    :func:`lean_kernels` for the sign's direction. Spread is linear in the charge and the kernel, so this is
    a scatter of each pixel's charge with its own kernel change, in one compiled pass
    (:func:`cmosnoise.engine.stencil.leaning_spread`; charge off the array goes back into the edge pixel it left, as
    :func:`spread` sends it); each ``D`` sums to 0, so the array's total charge is unchanged (to rounding).

    Parameters
    ----------
    mean_e : (rows, cols) array, e-
        Charge per pixel before diffusion.
    leans : tuple of four (3, 3) arrays
        :func:`lean_kernels`.
    toward_col, toward_row : (rows, cols) arrays
        ``a`` and ``b`` per pixel, each from -1 to 1.
    row0 : int
        The sensor's row number of the first row (the compiled pass adds each pixel's terms in an order fixed by
        the sensor's rows, so that a tile's values are the whole's).

    Returns
    -------
    (rows, cols) float64 array, e-
        To add to :func:`apply`'s result.
    """
    return stencil.leaning_spread(mean_e, toward_col, toward_row, leans, row0)


def channel_mixing_matrix(kernel, pattern: str) -> np.ndarray:
    """3 x 3 matrix M with ``measured_channel_means = M @ true_channel_means``.

    Found by passing flat single-colour fields through :func:`apply`: column j
    is what a flat field of unit signal in channel j alone produces in the
    R, G and B pixels. Its inverse undoes crosstalk's colour mixing.

    Parameters
    ----------
    kernel : (3, 3) array of fractions, or ``{"R": k, "G": k, "B": k}``
        The crosstalk kernel(s), as :func:`apply` takes them.
    pattern : str
        The CFA pattern (RGGB, BGGR, GRBG, GBRG).

    Returns
    -------
    (3, 3) float64 array, dimensionless
        ``M[i, j]``: the mean of channel i's pixels for unit signal in channel j.
    """
    shape = (16, 16)
    masks = cfa_mod.masks(pattern, shape)
    inner = (slice(4, -4), slice(4, -4))
    m = np.zeros((3, 3))
    for j in range(3):
        field = masks[j].astype(np.float64)
        out = apply(field, kernel, pattern)
        for i in range(3):
            m[i, j] = out[inner][masks[i][inner]].mean()
    return m
