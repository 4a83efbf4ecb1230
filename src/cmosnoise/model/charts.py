"""Test charts with their truth: the scenes image-quality measurements are made on, and where their parts lie.

Each chart draws any rectangle of itself alone (``region``), bit for bit that crop of the whole, and
:func:`truth` says where its patches or its edge are at a sensor's size, so a measurement finds them without a
person. Values are linear light, 0 to 1; with light in lux (``light.enabled``) they are reflectances.

========================  ===================================================
``colorchecker``          the 24 patches of the ColorChecker Classic on a dark surround; with light in lux, each
                          patch's reflectance spectrum (Ohta's) under the illuminant and the pixels' QE
``edge:ANGLE:LOW:HIGH``   a slanted edge (ISO 12233 e-SFR; ``edge`` and ``edge:ANGLE`` take the defaults): dark
                          on the left, light on the right, tilted
                          ANGLE degrees (5) clockwise from vertical through the centre; LOW and HIGH the two
                          levels (0.1 and 0.4: the 4:1 contrast ISO 12233:2017 asks for), each pixel the exact share
                          of its square on either side
``greys[:N]``             N uniform grey patches (20) in a row, from 1 down to 10**-3 in equal steps of optical
                          density (an OECF / ISO 15739 chart), on a surround of 0.18
========================  ===================================================

Examples
--------
>>> from cmosnoise.model import charts
>>> t = charts.truth("greys:4", (40, 80))
>>> [round(v, 3) for v in t["levels"]], t["patches"][0]
([1.0, 0.1, 0.01, 0.001], (10, 30, 4, 16))
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import CmosnoiseError
from .encoding import span, srgb_to_linear

#: ColorChecker Classic patches, sRGB 8-bit (X-Rite, post-2014 values), row by row from "dark skin" to "black".
COLORCHECKER_SRGB8 = np.array(
    [
        [115, 82, 68], [194, 150, 130], [98, 122, 157], [87, 108, 67], [133, 128, 177], [103, 189, 170],
        [214, 126, 44], [80, 91, 166], [193, 90, 99], [94, 60, 108], [157, 188, 64], [224, 163, 46],
        [56, 61, 150], [70, 148, 73], [175, 54, 60], [231, 199, 31], [187, 86, 149], [8, 133, 161],
        [243, 243, 242], [200, 200, 200], [160, 160, 160], [122, 122, 121], [85, 85, 85], [52, 52, 52],
    ],
    dtype=np.float64,
)
#: the ColorChecker's surround, sRGB 8-bit
SURROUND_SRGB8 = 30.0
#: the slanted edge's defaults: degrees from vertical, the dark and the light level (4:1)
EDGE_ANGLE_DEG, EDGE_LOW, EDGE_HIGH = 5.0, 0.1, 0.4
#: the grey patches' defaults: how many, the optical density of the darkest, the surround
GREYS_N, GREYS_DENSITY, GREYS_SURROUND = 20, 3.0, 0.18

__all__ = ["colorchecker", "colorchecker_patches", "edge", "edge_parameters", "greys", "greys_levels",
           "greys_patches", "truth", "zoneplate", "zoneplate_frequency", "siemens", "COLORCHECKER_SRGB8"]


# ------------------------------------------------------------------ ColorChecker
def colorchecker(shape: tuple[int, int], region=None, patch_values: np.ndarray | None = None,
                 surround: float | None = None) -> np.ndarray:
    """The 24-patch ColorChecker on a dark grey surround (linear light).

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, pixels.
    region : (row0, row1, col0, col1), optional
        The rectangle of the picture to draw (a tile), the same values as that crop of the whole.
    patch_values : (24, 3) array, optional
        Each patch's three values; default: the sRGB values decoded to linear light.
    surround : float, optional
        The surround's value; default: sRGB 30 decoded (0.0123).

    Returns
    -------
    (rows, cols, 3) float64 array
        Linear light, 0 to 1 (1: the peak rate).
    """
    rows, cols = shape
    g0, g1, h0, h1 = span(shape, region)
    lin = srgb_to_linear(COLORCHECKER_SRGB8 / 255.0) if patch_values is None else np.asarray(patch_values, float)
    back = srgb_to_linear(np.array(SURROUND_SRGB8 / 255.0)) if surround is None else float(surround)
    img = np.full((g1 - g0, h1 - h0, 3), back)
    ph, pw = rows / 4, cols / 6
    border = 0.12
    for i in range(4):
        for j in range(6):
            r0, r1 = int(round((i + border) * ph)), int(round((i + 1 - border) * ph))
            c0, c1 = int(round((j + border) * pw)), int(round((j + 1 - border) * pw))
            img[max(r0 - g0, 0):max(r1 - g0, 0), max(c0 - h0, 0):max(c1 - h0, 0)] = lin[i * 6 + j]
    return img


def colorchecker_patches(shape: tuple[int, int]) -> list[tuple[slice, slice]]:
    """Central regions (half of each patch) of the 24 patches, for measuring them.

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, pixels.

    Returns
    -------
    list of (slice, slice)
        The 24 patches' central regions, row by row.
    """
    rows, cols = shape
    ph, pw = rows / 4, cols / 6
    return [(slice(int((i + 0.3) * ph), int((i + 0.7) * ph)), slice(int((j + 0.3) * pw), int((j + 0.7) * pw)))
            for i in range(4) for j in range(6)]


# ------------------------------------------------------------------ slanted edge
def _ramp_integral(u: np.ndarray) -> np.ndarray:
    """The integral from -inf to ``u`` of clip(x, 0, 1): 0, u^2 / 2, u - 1/2."""
    return np.where(u <= 0, 0.0, np.where(u >= 1, u - 0.5, 0.5 * u * u))


def edge(shape: tuple[int, int], angle_deg: float = EDGE_ANGLE_DEG, low: float = EDGE_LOW, high: float = EDGE_HIGH,
         region=None) -> np.ndarray:
    """A slanted edge through the picture's centre, each pixel the exact area share of its square on either side.

    The edge is the line ``x = xc + (y - yc) tan(angle)`` (x to the right, y down, pixel (r, c) the square
    ``[c, c + 1] x [r, r + 1]``, the centre ``(xc, yc) = (cols / 2, rows / 2)``); ``high`` lies to its right.

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, pixels.
    angle_deg : float
        The tilt from vertical, degrees, -45 to 45 except 0 (ISO 12233: about 5).
    low, high : float
        The levels left and right of the edge, 0 to 1.
    region : (row0, row1, col0, col1), optional
        The rectangle to draw, the same values as that crop of the whole.

    Returns
    -------
    (rows, cols, 3) float64 array
    """
    rows, cols = shape
    r0, r1, c0, c1 = span(shape, region)
    t = math.tan(math.radians(angle_deg))
    xc, yc = cols / 2.0, rows / 2.0
    r = np.arange(r0, r1, dtype=np.float64)[:, None]
    c = np.arange(c0, c1, dtype=np.float64)[None, :]
    # share of the pixel right of the line: the mean over y in [r, r + 1] of clip(c + 1 - x_edge(y), 0, 1)
    a = c + 1.0 - xc + t * yc
    right = (_ramp_integral(a - t * r) - _ramp_integral(a - t * (r + 1.0))) / t
    v = low + (high - low) * right
    return np.repeat(v[..., None], 3, axis=2)


def edge_parameters(text: str) -> tuple[float, float, float]:
    """``edge[:ANGLE[:LOW:HIGH]]`` read, or a one-line error.

    Parameters
    ----------
    text : str
        The scene's name.

    Returns
    -------
    (angle_deg, low, high) : floats
    """
    parts = text.split(":")[1:]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = None
    if values is None or len(values) not in (0, 1, 3):
        raise CmosnoiseError(f"scene {text!r}: give edge, edge:ANGLE or edge:ANGLE:LOW:HIGH (degrees, levels 0 to 1)")
    angle = values[0] if values else EDGE_ANGLE_DEG
    low, high = (values[1], values[2]) if len(values) == 3 else (EDGE_LOW, EDGE_HIGH)
    if not (0 < abs(angle) <= 45):
        raise CmosnoiseError(f"scene {text!r}: ANGLE = {angle:g} degrees; give 0 < |ANGLE| <= 45 (ISO 12233: about 5)")
    if not (0 <= low <= 1 and 0 <= high <= 1 and low != high):
        raise CmosnoiseError(f"scene {text!r}: LOW and HIGH must be two different levels from 0 to 1")
    return angle, low, high


# ------------------------------------------------------------------ zone plate and Siemens star
#: the zone plate's default local frequency at the middle of the picture's shorter edge, cycles per pixel
ZONEPLATE_EDGE_CY_PER_PX = 0.5
#: the Siemens star's default number of black and white sectors
SIEMENS_SPOKES = 36


def _fresnel_parts(lo: np.ndarray, hi: np.ndarray, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """The integrals of ``cos(alpha x^2)`` and ``sin(alpha x^2)`` over ``[lo, hi]``: Fresnel's integrals,
    ``sqrt(pi / (2 alpha)) (C(hi s) - C(lo s))`` with ``s = sqrt(2 alpha / pi)`` (scipy's ``fresnel``)."""
    from scipy.special import fresnel

    scale = math.sqrt(2.0 * alpha / math.pi)
    s_hi, c_hi = fresnel(hi * scale)
    s_lo, c_lo = fresnel(lo * scale)
    return (c_hi - c_lo) / scale, (s_hi - s_lo) / scale


def zoneplate(shape: tuple[int, int], region=None, edge_cy_per_px: float = ZONEPLATE_EDGE_CY_PER_PX,
              cells: int = 1) -> np.ndarray:
    """A circular zone plate ``(1 + cos(alpha r^2)) / 2``, each cell its exact area average.

    The local frequency ``alpha r / pi`` reaches ``edge_cy_per_px`` cycles per pixel at the middle of the shorter
    edge; beyond Nyquist (0.5) a sensor shows it at ``1 - f``. The average over a cell is separable:
    ``cos(a (x^2 + y^2)) = cos(a x^2) cos(a y^2) - sin(a x^2) sin(a y^2)``, each factor's integral a difference of
    Fresnel integrals.

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, cells (``cells`` to a pixel along each axis).
    region : (row0, row1, col0, col1), optional
        The rectangle to draw, the same values as that crop of the whole.
    edge_cy_per_px : float
        The local frequency at the shorter edge's middle, cycles per pixel.
    cells : int
        Cells per pixel along each axis (the optical image's fine grid).

    Returns
    -------
    (rows, cols, 3) float64 array
        0 to 1.
    """
    rows, cols = shape
    r0, r1, c0, c1 = span(shape, region)
    r_edge = min(rows, cols) / 2.0 / cells  # pixels
    alpha = math.pi * edge_cy_per_px / r_edge  # rad per pixel^2
    y = (np.arange(r0, r1 + 1) - rows / 2.0) / cells  # the cells' edges, pixels from the centre
    x = (np.arange(c0, c1 + 1) - cols / 2.0) / cells
    cy, sy = _fresnel_parts(y[:-1], y[1:], alpha)
    cx, sx = _fresnel_parts(x[:-1], x[1:], alpha)
    mean = (np.outer(cy, cx) - np.outer(sy, sx)) * (cells * cells)
    v = 0.5 + 0.5 * mean
    return np.repeat(np.clip(v, 0.0, 1.0)[..., None], 3, axis=2)


def zoneplate_frequency(text: str) -> float:
    """``zoneplate[:F]`` read: F, the local frequency at the shorter edge's middle (cycles per pixel, 0.5 by
    default, more than 0 and at most 4), or a one-line error.

    Parameters
    ----------
    text : str
        The scene's name.

    Returns
    -------
    float
    """
    part = text.partition(":")[2].strip()
    if not part:
        return ZONEPLATE_EDGE_CY_PER_PX
    try:
        f = float(part)
    except ValueError:
        f = float("nan")
    if not (0 < f <= 4):
        raise CmosnoiseError(f"scene {text!r}: give zoneplate or zoneplate:F, F the frequency at the middle of the "
                             "shorter edge in cycles per pixel, more than 0 and at most 4 (0.5: Nyquist)")
    return f


def _halfplane_share(x0: np.ndarray, y0: np.ndarray, size: float, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The share of each square ``[x0, x0 + size] x [y0, y0 + size]`` where ``a x + b y > 0`` (a line through the
    origin), exactly: the mean over the square's y of the covered share of its width, a clipped ramp's integral
    (:func:`_ramp_integral`), as the slanted edge's."""
    x0, y0, a, b = np.broadcast_arrays(*(np.asarray(v, float) for v in (x0, y0, a, b)))
    out = np.empty(x0.shape)
    flat = np.abs(a) < 1e-12 * np.abs(b)
    ylo, yhi = y0[flat], y0[flat] + size  # a = 0: b y > 0
    above = (np.clip(yhi, 0, None) - np.clip(ylo, 0, None)) / size
    out[flat] = np.where(b[flat] > 0, above, 1.0 - above)
    m = ~flat
    t = -b[m] / a[m]  # the line is x = t y
    right = a[m] > 0  # a > 0: the side x > t y; else x < t y
    # the covered share of the width at y, before clipping to [0, 1]: linear in y, u0 at y0 and u1 at y0 + size
    u0 = np.where(right, x0[m] + size - t * y0[m], t * y0[m] - x0[m]) / size
    u1 = u0 + np.where(right, -t, t)
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = (_ramp_integral(u1) - _ramp_integral(u0)) / (u1 - u0)
    out[m] = np.where(np.abs(u1 - u0) < 1e-12, np.clip(u0, 0.0, 1.0), mean)
    return out


def siemens(shape: tuple[int, int], spokes: int = SIEMENS_SPOKES, region=None) -> np.ndarray:
    """A Siemens star: ``spokes`` sectors around the centre, white (0.95) and black (0.05) in turn, each cell its
    area share of white.

    A cell that one sector boundary crosses is split exactly (the share of a square on one side of a line through
    the centre); the few cells near the centre that two or more boundaries cross are integrated at 64 x 64
    points.

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, cells.
    spokes : int
        The number of sectors (even).
    region : (row0, row1, col0, col1), optional
        The rectangle to draw, the same values as that crop of the whole.

    Returns
    -------
    (rows, cols, 3) float64 array
        The star fills the picture whatever its cells' size (an optical image's fine grid too).
    """
    rows, cols = shape
    r0, r1, c0, c1 = span(shape, region)
    y0 = (np.arange(r0, r1) - rows / 2.0)[:, None] * np.ones((1, c1 - c0))
    x0 = np.ones((r1 - r0, 1)) * (np.arange(c0, c1) - cols / 2.0)[None, :]
    step = 2.0 * math.pi / spokes  # white where the angle mod 2 step lies in (0, step): sin(spokes theta / 2) > 0
    centre = np.arctan2(y0 + 0.5, x0 + 0.5)
    span_lo = np.full(centre.shape, np.inf)
    span_hi = np.full(centre.shape, -np.inf)
    for dy in (0.0, 1.0):
        for dx in (0.0, 1.0):
            d = np.angle(np.exp(1j * (np.arctan2(y0 + dy, x0 + dx) - centre)))  # from the centre's, (-pi, pi]
            span_lo, span_hi = np.minimum(span_lo, d), np.maximum(span_hi, d)
    first = np.ceil((centre + span_lo) / step)
    last = np.floor((centre + span_hi) / step)
    count = last - first + 1
    inside = (x0 <= 0) & (x0 + 1 >= 0) & (y0 <= 0) & (y0 + 1 >= 0)  # the cell holds the centre
    white = np.where(np.mod(centre, 2 * step) < step, 1.0, 0.0)  # no boundary crosses it
    one = (count == 1) & ~inside
    j = first[one]
    theta = j * step
    # the side past the boundary (angles above theta, cross product > 0) is white where j is even
    share_above = _halfplane_share(x0[one], y0[one], 1.0, -np.sin(theta), np.cos(theta))
    white[one] = np.where(np.mod(j, 2) == 0, share_above, 1.0 - share_above)
    many = ((count > 1) | inside)
    if many.any():
        n = 64
        sub = (np.arange(n) + 0.5) / n
        for (i, c) in zip(*np.nonzero(many)):
            yy = y0[i, c] + sub[:, None]
            xx = x0[i, c] + sub[None, :]
            white[i, c] = float((np.mod(np.arctan2(yy, xx), 2 * step) < step).mean())
    v = 0.05 + 0.9 * white
    return np.repeat(v[..., None], 3, axis=2)


# ------------------------------------------------------------------ grey patches
def greys_levels(n: int = GREYS_N) -> np.ndarray:
    """The grey patches' levels, left to right: 1 down to ``10**-GREYS_DENSITY`` in equal steps of density.

    Parameters
    ----------
    n : int
        How many patches.

    Returns
    -------
    (n,) float64 array
    """
    return 10.0 ** (-GREYS_DENSITY * np.arange(n) / max(n - 1, 1))


def greys_patches(shape: tuple[int, int], n: int = GREYS_N) -> list[tuple[int, int, int, int]]:
    """Where the ``n`` grey patches lie: the middle half of the picture's height, each patch 60 % of its column.

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, pixels.
    n : int
        How many patches.

    Returns
    -------
    list of (row0, row1, col0, col1)
        Left to right.
    """
    rows, cols = shape
    out = []
    for i in range(n):
        w = cols / n
        out.append((int(rows * 0.25), int(rows * 0.75), int(round((i + 0.2) * w)), int(round((i + 0.8) * w))))
    return out


def greys(shape: tuple[int, int], n: int = GREYS_N, region=None) -> np.ndarray:
    """``n`` grey patches in a row on a surround of 0.18 (see :func:`greys_levels` and :func:`greys_patches`).

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, pixels.
    n : int
        How many patches, 2 to 64.
    region : (row0, row1, col0, col1), optional
        The rectangle to draw, the same values as that crop of the whole.

    Returns
    -------
    (rows, cols, 3) float64 array
    """
    g0, g1, h0, h1 = span(shape, region)
    img = np.full((g1 - g0, h1 - h0, 3), GREYS_SURROUND)
    for level, (r0, r1, c0, c1) in zip(greys_levels(n), greys_patches(shape, n)):
        img[max(r0 - g0, 0):max(r1 - g0, 0), max(c0 - h0, 0):max(c1 - h0, 0)] = level
    return img


def greys_count(text: str) -> int:
    """``greys[:N]`` read, or a one-line error.

    Parameters
    ----------
    text : str
        The scene's name.

    Returns
    -------
    int
        N, 2 to 64.
    """
    part = text.partition(":")[2] or str(GREYS_N)
    if not part.isdigit() or not 2 <= int(part) <= 64:
        raise CmosnoiseError(f"scene {text!r}: N must be a whole number of patches from 2 to 64")
    return int(part)


# ------------------------------------------------------------------ truth
def truth(source: str, shape: tuple[int, int]) -> dict:
    """Where a chart's parts lie at a sensor's size, and what they are.

    Parameters
    ----------
    source : str
        ``colorchecker``, ``edge[...]``, ``greys[:N]`` or ``flat:LEVEL``.
    shape : (rows, cols)
        The sensor's size.

    Returns
    -------
    dict
        ``chart`` (its name); for patches, ``patches``: (row0, row1, col0, col1) each (the ColorChecker's central
        halves), and ``levels`` (greys) or ``names`` (ColorChecker); for the edge, ``angle_deg``, ``low``,
        ``high``, ``centre`` (x, y) and ``region``, the edge's middle 60 % of the rows and the columns within a
        quarter of the picture's width of it; for a flat field, ``patches`` (its middle half) and ``levels``.
    """
    low = source.strip().lower()
    rows, cols = shape
    if low == "colorchecker":
        boxes = [(r.start, r.stop, c.start, c.stop) for r, c in colorchecker_patches(shape)]
        names = ["dark skin", "light skin", "blue sky", "foliage", "blue flower", "bluish green", "orange",
                 "purplish blue", "moderate red", "purple", "yellow green", "orange yellow", "blue", "green", "red",
                 "yellow", "magenta", "cyan", "white 9.5", "neutral 8", "neutral 6.5", "neutral 5", "neutral 3.5",
                 "black 2"]
        return {"chart": "colorchecker", "patches": boxes, "names": names}
    if low.startswith("edge"):
        angle, lo, hi = edge_parameters(low)
        half = max(int(cols / 4), 4)
        return {"chart": "edge", "angle_deg": angle, "low": lo, "high": hi, "centre": (cols / 2.0, rows / 2.0),
                "region": (int(rows * 0.2), int(rows * 0.8), max(cols // 2 - half, 0), min(cols // 2 + half, cols))}
    if low.startswith("greys"):
        n = greys_count(low)
        return {"chart": "greys", "patches": greys_patches(shape, n), "levels": greys_levels(n).tolist()}
    if low.startswith("flat:"):
        return {"chart": "flat", "patches": [(rows // 4, rows - rows // 4, cols // 4, cols - cols // 4)],
                "levels": [float(low.partition(":")[2])]}
    raise CmosnoiseError(f"scene {source!r} is not a chart with a truth; give colorchecker, edge, greys or flat:LEVEL")
