"""White pixels and couplets: the defects the paper's Fig. 9 is about.

A white pixel is one whose dark current (or dark signal) is above a
threshold. A **couplet** is two white pixels that are neighbours in the same
colour plane: for R and B the 8 nearest same-colour pixels (2 pixels away),
for G the 4 diagonal G pixels and the 4 G pixels 2 away along the row and
column, for a monochrome sensor the 8 adjacent pixels. A median filter over
same-colour neighbours cannot remove a couplet, because each pixel's
neighbour makes its high value look plausible.

Examples
--------
>>> import numpy as np
>>> from cmosnoise import white_pixels
>>> round(white_pixels.expected_couplets((480, 640), "RGGB", 4000e-6), 1)   # at random, 4000 ppm on VGA
19.6
"""

from __future__ import annotations

import numpy as np

from ..engine import reduce
from ..errors import CmosnoiseError
from ..model import cfa as cfa_mod


def _pair_offsets(pattern: str) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """(offsets for every pixel, offsets for green pixels only), each pair counted once."""
    if cfa_mod.is_mono(pattern):
        return [(0, 1), (1, 0), (1, 1), (1, -1)], []
    # (0, 2) and (2, 0) are same-colour for every channel;
    # R and B: also the diagonals (2, +-2); G: the diagonals (1, +-1) instead
    return [(0, 2), (2, 0)], [(1, 1), (1, -1)]


def _pair_starts(mask: np.ndarray, pattern: str) -> list[tuple[tuple[int, int], np.ndarray]]:
    """For each neighbour offset (each pair counted once), the pixels a pair may start from."""
    all_offsets, green_offsets = _pair_offsets(pattern)
    if cfa_mod.is_mono(pattern):
        return [(o, mask) for o in all_offsets]
    green = cfa_mod.channel_map(pattern, mask.shape) == 1
    return ([(o, mask) for o in all_offsets] + [(o, mask & green) for o in green_offsets]
            + [(o, mask & ~green) for o in [(2, 2), (2, -2)]])


def couplet_pairs(mask: np.ndarray, pattern: str) -> np.ndarray:
    """Coordinates of every couplet: array (n, 2, 2) of ((r1, c1), (r2, c2)), offset by offset, each offset's in
    row-major order of their first pixel.

    From the white pixels' coordinates (one pass over the map, then work in their number): which CFA positions
    may start a pair along each offset is :func:`_pair_starts` of one 2 x 2 cell (the CFA repeats every 2).

    Parameters
    ----------
    mask : (rows, cols) bool array
        The white pixels.
    pattern : str
        The CFA pattern (RGGB, BGGR, GRBG, GBRG, or none): couplets are neighbours in one colour plane.

    Returns
    -------
    (n, 2, 2) int array
        Each couplet's two pixels, ((r1, c1), (r2, c2)).
    """
    mask = np.asarray(mask, dtype=bool)
    r, c = np.nonzero(mask)
    return _pairs(r, c, mask.shape, pattern, lambda rr, cc: mask[rr, cc])


def pairs_at(r: np.ndarray, c: np.ndarray, shape: tuple[int, int], pattern: str) -> np.ndarray:
    """:func:`couplet_pairs` of the white pixels at rows ``r`` and columns ``c`` of a map of ``shape`` (a map too
    large to hold: its white pixels gathered tile by tile).

    Parameters
    ----------
    r, c : (n,) int arrays
        The white pixels' rows and columns, in row-major order.
    shape : (rows, cols)
        The map's size.
    pattern : str
        The CFA pattern (RGGB, BGGR, GRBG, GBRG, or none): couplets are neighbours in one colour plane.

    Returns
    -------
    (n, 2, 2) int array
        Each couplet's two pixels, ((r1, c1), (r2, c2)).

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise import white_pixels
    >>> white_pixels.pairs_at(np.array([1, 1]), np.array([1, 3]), (4, 6), "RGGB").tolist()
    [[[1, 1], [1, 3]]]
    """
    r, c = np.asarray(r, np.int64), np.asarray(c, np.int64)
    index = r * shape[1] + c
    return _pairs(r, c, shape, pattern, lambda rr, cc: np.isin(rr * shape[1] + cc, index))


def _pairs(r: np.ndarray, c: np.ndarray, shape: tuple[int, int], pattern: str, white) -> np.ndarray:
    """The couplets among the white pixels at (``r``, ``c``), row-major: ``white(rows, cols)`` says which of
    those pixels are white (a lookup in the map where it is held, a search among the coordinates where not)."""
    rows, cols = shape
    pairs = []
    for (dr, dc), start in _pair_starts(np.ones((2, 2), bool), pattern):
        ok = start[r % 2, c % 2] & (r + dr < rows) & (c + dc >= 0) & (c + dc < cols)
        rs, cs = r[ok], c[ok]
        hit = white(rs + dr, cs + dc)
        rs, cs = rs[hit], cs[hit]
        pairs.append(np.stack([np.stack([rs, cs], -1), np.stack([rs + dr, cs + dc], -1)], 1))
    return np.concatenate(pairs) if pairs else np.zeros((0, 2, 2), int)


#: a pixel is left by the processing (a residual defect) when it stands this far from the scene's expected
#: signal after dark calibration and defect correction, e-: the paper's Fig. 9 judgement, in ``simulate``'s
#: summary, the sweep's ``residual_defects`` and ``couplets_after_correction``, and the docs' figures alike
DEFECT_TOLERANCE_E = 150.0


def left_after_correction(corrected_dn: np.ndarray, expected_e: np.ndarray, gain_dn_per_e: float, pattern: str,
                          tolerance_e: float = DEFECT_TOLERANCE_E) -> dict:
    """What a processing chain leaves: the pixels of a corrected CFA image more than ``tolerance_e`` off the
    scene's expected signal, and the couplets among them.

    Parameters
    ----------
    corrected_dn : ndarray, (rows, cols)
        The CFA image after dark calibration and defect correction, DN above black
        (:meth:`cmosnoise.Processor.cfa_image`).
    expected_e : ndarray, (rows, cols)
        The expected photo signal, e- (:attr:`Shot.photo_mean_e`).
    gain_dn_per_e : float
        K, DN/e-.
    pattern : str
        The CFA pattern.
    tolerance_e : float
        How far off a pixel is left, e-.

    Returns
    -------
    dict
        ``pixels`` (int), ``couplets`` (int: pairs of same-colour neighbours among them), ``tolerance_e``.
    """
    k = float(gain_dn_per_e)
    bad = np.abs(np.asarray(corrected_dn, np.float64) - np.asarray(expected_e, np.float64) * k) > tolerance_e * k
    return {"pixels": int(bad.sum()), "couplets": count_couplets(bad, pattern), "tolerance_e": float(tolerance_e)}


def count_couplets(mask: np.ndarray, pattern: str) -> int:
    """Number of couplets (pairs of same-colour neighbouring white pixels).

    Parameters
    ----------
    mask : (rows, cols) bool array
        The white pixels.
    pattern : str
        The CFA pattern (RGGB, BGGR, GRBG, GBRG, or none): couplets are neighbours in one colour plane.

    Returns
    -------
    int
    """
    return int(len(couplet_pairs(mask, pattern)))  # one count of couplets: from the white pixels' coordinates


def neighbour_pairs(shape: tuple[int, int], pattern: str) -> int:
    """How many same-colour neighbour pairs an array of this shape has (every place a couplet could be).

    Parameters
    ----------
    shape : (rows, cols)
    pattern : str
        The CFA pattern (RGGB, BGGR, GRBG, GBRG, or none): couplets are neighbours in one colour plane.

    Returns
    -------
    int
    """
    rows, cols = shape
    n = 0
    for (dr, dc), start in _pair_starts(np.ones((min(rows, 4), min(cols, 4)), bool), pattern):
        # pairs start in rows [0, rows - dr) and columns [max(0, -dc), cols - max(0, dc));
        # the CFA repeats every 2 pixels, so count the starting pixels of one 2 x 2 cell and scale
        r_n, c_lo, c_hi = rows - dr, max(0, -dc), cols - max(0, dc)
        if r_n <= 0 or c_hi <= c_lo:
            continue
        for pr in range(min(2, start.shape[0])):
            for pc in range(min(2, start.shape[1])):
                if start[pr, pc]:
                    n += _count_in(0, r_n, pr) * _count_in(c_lo, c_hi, pc)
    return n


def _count_in(lo: int, hi: int, parity: int) -> int:
    """How many whole numbers in [lo, hi) have this parity (0 or 1)."""
    first = lo + ((parity - lo) % 2)
    return max(0, (hi - first + 1) // 2)


def expected_couplets(shape: tuple[int, int], pattern: str, white_fraction: float) -> float:
    """Couplets expected if white pixels were placed at random with this density.

    Each of the array's same-colour neighbour pairs (:func:`neighbour_pairs`,
    a closed form) is a couplet with probability ``white_fraction**2``.

    Parameters
    ----------
    shape : (rows, cols)
    pattern : str
        The CFA pattern (RGGB, BGGR, GRBG, GBRG, or none): couplets are neighbours in one colour plane.
    white_fraction : float
        The fraction of white pixels, 0 to 1.

    Returns
    -------
    float
        The expected number of couplets.
    """
    return neighbour_pairs(shape, pattern) * white_fraction**2


def report(values: np.ndarray, threshold: float, pattern: str) -> dict:
    """White pixels above ``threshold`` in a map or frame and the couplets they form.

    Parameters
    ----------
    values : (rows, cols) array
        A dark-current map (e-/s) or a frame's signal (DN).
    threshold : float
        In the unit of ``values``: a pixel above it is white.
    pattern : str
        The CFA pattern (RGGB, BGGR, GRBG, GBRG, or none): couplets are neighbours in one colour plane.

    Returns
    -------
    dict
        ``threshold``, ``white_pixels``, ``ppm``, ``couplets`` and ``couplets_expected_random`` (at random with the
        same density, :func:`expected_couplets`).

    Examples
    --------
    Two white pixels two columns apart are neighbours in the same colour plane of an RGGB mosaic, a couplet:

    >>> import numpy as np
    >>> from cmosnoise import white_pixels
    >>> rate = np.zeros((4, 6))
    >>> rate[1, 1] = rate[1, 3] = 500.0
    >>> r = white_pixels.report(rate, threshold=100.0, pattern="RGGB")
    >>> r["white_pixels"], r["couplets"]
    (2, 1)
    """
    values = np.asarray(values)
    if values.ndim != 2:
        raise CmosnoiseError(f"white_pixels.report: values of shape {values.shape}; give one (rows, cols) map or frame "
                             "(for a stack of dark frames, dark_rate_from_raw averages them)")
    return report_at(*reduce.positions_above(values, threshold), values.shape, threshold, pattern)


def report_at(r: np.ndarray, c: np.ndarray, shape: tuple[int, int], threshold: float, pattern: str) -> dict:
    """:func:`report` of a map or frame whose white pixels are at rows ``r`` and columns ``c``: for one too large to
    hold, its white pixels gathered band by band or tile by tile.

    Parameters
    ----------
    r, c : (n,) int arrays
        The white pixels' rows and columns, in row-major order.
    shape : (rows, cols)
        The map's size.
    threshold : float
        The threshold they are above (recorded).
    pattern : str
        The CFA pattern (RGGB, BGGR, GRBG, GBRG, or none): couplets are neighbours in one colour plane.

    Returns
    -------
    dict
        As :func:`report`.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise import white_pixels
    >>> white_pixels.report_at(np.array([1, 1]), np.array([1, 3]), (4, 6), 100.0, "RGGB")["couplets"]
    1
    """
    n = int(np.size(r))
    frac = n / (shape[0] * shape[1])
    return {
        "threshold": float(threshold),
        "white_pixels": n,
        "ppm": frac * 1e6,
        "couplets": int(len(pairs_at(r, c, shape, pattern))),
        "couplets_expected_random": expected_couplets(tuple(shape), pattern, frac),
    }


def dark_rate_from_raw(raw: np.ndarray, black_level_dn: float, gain_dn_per_e: float, integration_time_s: float) -> np.ndarray:
    """Dark-current estimate from a dark raw frame: ``(DN - black) / K / t_int`` (e-/s), (rows, cols).

    ``raw`` is one frame (rows, cols) or a stack (frames, rows, cols), as
    ``tifffile.imread`` returns ``raw.tiff``; a stack is averaged over its
    frames first, which lowers the temporal noise in the estimate.

    Parameters
    ----------
    raw : (rows, cols) or (frames, rows, cols) array, DN
        Dark raw codes.
    black_level_dn : float
        The black level, DN.
    gain_dn_per_e : float
        K, DN per electron.
    integration_time_s : float
        The frames' integration time, s.

    Returns
    -------
    (rows, cols) float64 array, e-/s
    """
    raw = np.asarray(raw, dtype=np.float64)
    if raw.ndim == 3:
        raw = raw.mean(axis=0)
    if raw.ndim != 2:
        raise CmosnoiseError(f"dark_rate_from_raw: raw of shape {raw.shape}; give (rows, cols) or (frames, rows, cols)")
    return (raw - black_level_dn) / gain_dn_per_e / integration_time_s
