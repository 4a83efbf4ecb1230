"""Colour filter array geometry.

A Bayer pattern is named by its top-left 2 x 2 tile read row by row
(``RGGB``, ``BGGR``, ``GRBG``, ``GBRG``); ``none`` is a monochrome sensor.
Channels are numbered R = 0, G = 1, B = 2.

Examples
--------
>>> from cmosnoise import cfa
>>> cfa.crop_pattern("RGGB", 1, 0)      # the pattern seen from row 1, column 0
'GBRG'
"""

import numpy as np

from ..errors import CmosnoiseError

BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
CHANNEL_INDEX = {"R": 0, "G": 1, "B": 2}

#: offsets (drow, dcol) of a pixel's nearest neighbours of the same colour.
#: R and B sit on a 2-pixel grid; G is a quincunx, so its nearest G
#: neighbours are the 4 diagonals and the 4 at distance 2 along rows/columns.
RB_NEIGHBOURS = tuple((dr, dc) for dr in (-2, 0, 2) for dc in (-2, 0, 2) if (dr, dc) != (0, 0))
G_NEIGHBOURS = ((-1, -1), (-1, 1), (1, -1), (1, 1), (-2, 0), (2, 0), (0, -2), (0, 2))
MONO_NEIGHBOURS = tuple((dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0))


def is_mono(pattern: str) -> bool:
    return pattern == "none"


def tile(pattern: str) -> np.ndarray:
    """The 2 x 2 tile of channel indices of a Bayer pattern.

    Parameters
    ----------
    pattern : str
        RGGB, BGGR, GRBG or GBRG.

    Returns
    -------
    (2, 2) int8 array
        0 for R, 1 for G, 2 for B.
    """
    if pattern not in BAYER_PATTERNS:
        raise ValueError(f"not a Bayer pattern: {pattern!r}; use one of {BAYER_PATTERNS}")
    return np.array([CHANNEL_INDEX[c] for c in pattern], dtype=np.int8).reshape(2, 2)


def crop_pattern(pattern: str, row: int, col: int) -> str:
    """The pattern of a crop whose corner is pixel (``row``, ``col``) of a sensor of ``pattern``.

    Parameters
    ----------
    pattern : str
        The sensor's pattern (RGGB, BGGR, GRBG or GBRG).
    row, col : int
        The crop's top-left pixel.

    Returns
    -------
    str
        The crop's pattern.
    """
    if is_mono(pattern):
        return pattern
    return "".join(pattern[2 * ((row + i) % 2) + (col + j) % 2] for i in (0, 1) for j in (0, 1))


def channel_map(pattern: str, shape: tuple[int, int]) -> np.ndarray:
    """Channel index of every pixel.

    Parameters
    ----------
    pattern : str
        RGGB, BGGR, GRBG, GBRG, or none (monochrome).
    shape : (rows, cols)

    Returns
    -------
    (rows, cols) int8 array
        0 for R, 1 for G, 2 for B; all 1 for monochrome.
    """
    rows, cols = shape
    if is_mono(pattern):
        return np.ones(shape, dtype=np.int8)
    reps = ((rows + 1) // 2, (cols + 1) // 2)
    return np.tile(tile(pattern), reps)[:rows, :cols]


def masks(pattern: str, shape: tuple[int, int]) -> np.ndarray:
    """Which pixels sit under R, G and B.

    Parameters
    ----------
    pattern : str
        RGGB, BGGR, GRBG, GBRG, or none (monochrome).
    shape : (rows, cols)

    Returns
    -------
    (3, rows, cols) bool array
    """
    cmap = channel_map(pattern, shape)
    return np.stack([cmap == c for c in range(3)])



#: the packed channels' order: R, the green on R's rows, the green on B's rows, B (as the raw denoising
#: literature packs RGGB: SID, ELD, PMN)
PACKED = ("R", "Gr", "Gb", "B")


def _positions(pattern: str) -> list[tuple[int, int]]:
    """The (row, col) in the 2 x 2 cell of each packed channel of :data:`PACKED`, for ``pattern``."""
    if pattern not in BAYER_PATTERNS:
        raise CmosnoiseError(f"pattern {pattern!r}: a Bayer phase is one of {', '.join(BAYER_PATTERNS)}")
    cells = [(i, j) for i in (0, 1) for j in (0, 1)]
    r = next(c for c in cells if pattern[2 * c[0] + c[1]] == "R")
    b = next(c for c in cells if pattern[2 * c[0] + c[1]] == "B")
    gr = (r[0], 1 - r[1])  # the green beside R on its row
    gb = (b[0], 1 - b[1])
    return [r, gr, gb, b]


def pack(mosaic: np.ndarray, pattern: str) -> np.ndarray:
    """A Bayer mosaic as four half-resolution channels in :data:`PACKED` order, for any phase.

    Parameters
    ----------
    mosaic : (..., H, W) array
        H and W even.
    pattern : str
        The mosaic's phase at (0, 0): RGGB, BGGR, GRBG or GBRG.

    Returns
    -------
    (..., 4, H/2, W/2) array
        R, Gr, Gb, B: the same values, reordered (:func:`unpack` gives the mosaic back exactly).

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise import cfa
    >>> x = np.arange(16).reshape(4, 4)
    >>> bool((cfa.unpack(cfa.pack(x, "GBRG"), "GBRG") == x).all())
    True
    """
    a = np.asarray(mosaic)
    if a.ndim < 2 or a.shape[-2] % 2 or a.shape[-1] % 2:
        raise CmosnoiseError(f"mosaic: shape {a.shape}; a Bayer mosaic has an even number of rows and columns")
    return np.stack([a[..., i::2, j::2] for i, j in _positions(pattern)], axis=-3)


def unpack(packed: np.ndarray, pattern: str) -> np.ndarray:
    """The mosaic of :func:`pack`'s channels, of phase ``pattern``.

    Parameters
    ----------
    packed : (..., 4, h, w) array
        R, Gr, Gb, B.
    pattern : str
        The phase the mosaic is to have at (0, 0).

    Returns
    -------
    (..., 2h, 2w) array
    """
    p = np.asarray(packed)
    if p.ndim < 3 or p.shape[-3] != 4:
        raise CmosnoiseError(f"packed: shape {p.shape}; packed raw has 4 channels (R, Gr, Gb, B) before its rows")
    out = np.empty(p.shape[:-3] + (2 * p.shape[-2], 2 * p.shape[-1]), p.dtype)
    for k, (i, j) in enumerate(_positions(pattern)):
        out[..., i::2, j::2] = p[..., k, :, :]
    return out


def bayer_flip(mosaic: np.ndarray, pattern: str, axis: str) -> np.ndarray:
    """A flip that keeps every pixel's colour and the phase: Liu et al.'s Bayer-preserving augmentation ("Learning
    raw image denoising with Bayer pattern unification and Bayer preserving augmentation", CVPRW 2019): the mosaic
    is flipped, then its first and last row (``axis="rows"``, an up-down flip) or column (``"columns"``, left-right)
    are cropped, which brings the flipped phase back to ``pattern``.

    Parameters
    ----------
    mosaic : (..., H, W) array
    pattern : str
        Its phase (RGGB, BGGR, GRBG, GBRG; ``none``: a plain flip, nothing cropped).
    axis : {"rows", "columns"}

    Returns
    -------
    (..., H - 2, W) or (..., H, W - 2) array
        Of phase ``pattern``; each pixel the colour it had.
    """
    a = np.asarray(mosaic)
    if axis not in ("rows", "columns"):
        raise CmosnoiseError(f"axis = {axis!r}: flip the rows (up-down) or the columns (left-right)")
    along = -2 if axis == "rows" else -1
    flipped = np.flip(a, axis=along)
    if is_mono(pattern):
        return flipped
    if pattern not in BAYER_PATTERNS:
        raise CmosnoiseError(f"pattern {pattern!r}: a Bayer phase is one of {', '.join(BAYER_PATTERNS)} (or none)")
    if a.shape[along] % 2 or a.shape[along] < 4:
        raise CmosnoiseError(f"mosaic: {a.shape[along]} {axis}; a Bayer-preserving flip needs an even number, at "
                             "least 4")
    inner = [slice(None)] * a.ndim
    inner[along] = slice(1, -1)
    return flipped[tuple(inner)]


def bayer_crop(mosaic: np.ndarray, pattern: str, row: int, col: int, height: int, width: int) -> tuple:
    """A crop of a mosaic and the phase it has (a crop at an odd corner changes it: recorded, not hidden).

    Parameters
    ----------
    mosaic : (..., H, W) array
    pattern : str
    row, col, height, width : int
        The crop's corner and size, inside the mosaic.

    Returns
    -------
    (array, str)
        The crop and its phase (:func:`crop_pattern`).
    """
    a = np.asarray(mosaic)
    if not (0 <= row and 0 <= col and height > 0 and width > 0 and row + height <= a.shape[-2]
            and col + width <= a.shape[-1]):
        raise CmosnoiseError(f"crop ({row}, {col}) of {height} x {width}: not inside the {a.shape[-2]} x "
                             f"{a.shape[-1]} mosaic")
    return a[..., row:row + height, col:col + width], crop_pattern(pattern, row, col)
