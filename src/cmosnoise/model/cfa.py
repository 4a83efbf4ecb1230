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

