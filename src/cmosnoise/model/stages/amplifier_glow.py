"""Stage 4c, amplifier glow (e-/s): a dark signal that grows with exposure, brightest at a corner or an edge.

The readout's amplifiers and drivers emit light (hot-carrier luminescence)
that the pixels near them collect as charge: in a long dark frame a glow
rises from the corner or edge where they sit. It is a dark-current rate
added to the pixel's own, ``rate exp(-d / length)``, ``d`` the pixel
centre's distance (in pixels) from the source: a corner's point or an
edge's line. It integrates over the exposure and has the dark current's shot
noise; it does not follow the temperature (the amplifiers' light does not
double with it). No published figure of the cameras in the presets gives its
rate, so they leave it off.

Examples
--------
>>> from cmosnoise.model.stages import amplifier_glow
>>> g = amplifier_glow.glow_map((0, 4, 0, 6), (4, 6), 100.0, "top_right", 2.0)
>>> round(float(g[0, 5]), 2), bool(g[0, 5] > g[3, 0])
(70.22, True)
"""

from __future__ import annotations

import numpy as np

from ...engine import fdmath

#: where the glow may rise: the four corners and the four edges
SOURCES = ("top_left", "top_right", "bottom_left", "bottom_right", "top", "bottom", "left", "right")


def distance(region: tuple[int, int, int, int], shape: tuple[int, int], source: str) -> np.ndarray:
    """Each pixel centre's distance from the glow's source, pixels.

    Parameters
    ----------
    region : (row0, row1, col0, col1)
        The rectangle to make.
    shape : (rows, cols)
        The sensor's size (the far corners and edges lie at its borders).
    source : str
        One of :data:`SOURCES`: a corner (the sensor's outer corner point) or an edge (its outer line).

    Returns
    -------
    (row1 - row0, col1 - col0) float64 array, pixels
    """
    if source not in SOURCES:
        raise ValueError(f"dark_current.glow.source = {source!r}: expected one of {', '.join(SOURCES)}")
    r0, r1, c0, c1 = region
    rows, cols = shape
    r = np.arange(r0, r1, dtype=np.float64)[:, None] + 0.5  # pixel centres; the sensor spans 0 .. rows
    c = np.arange(c0, c1, dtype=np.float64)[None, :] + 0.5
    dr = r if "top" in source else rows - r
    dc = c if "left" in source else cols - c
    if source in ("top", "bottom"):
        return np.broadcast_to(dr, (r1 - r0, c1 - c0)).copy()
    if source in ("left", "right"):
        return np.broadcast_to(dc, (r1 - r0, c1 - c0)).copy()
    return np.sqrt(dr * dr + dc * dc)


def glow_map(region: tuple[int, int, int, int], shape: tuple[int, int], rate_e_per_s: float, source: str,
             length_px: float) -> np.ndarray:
    """The glow's dark-current rate over ``region``, e-/s per pixel, float32.

    Parameters
    ----------
    region : (row0, row1, col0, col1)
        The rectangle to make.
    shape : (rows, cols)
        The sensor's size.
    rate_e_per_s : float
        The rate at the source (distance 0), e-/s per pixel.
    source : str
        One of :data:`SOURCES`.
    length_px : float
        The distance over which the glow falls by a factor e, pixels.

    Returns
    -------
    (row1 - row0, col1 - col0) float32 array, e-/s
        ``rate exp(-d / length)``, with fdmath's exp (the same bits on every machine).
    """
    d = distance(region, shape, source)
    x = np.maximum(-d / length_px, -700.0)  # fdmath's exp's range; exp(-700) of any rate is 0 in float32
    return (rate_e_per_s * fdmath.exp(x)).astype(np.float32)
