"""Stage 6, source-follower noise (input-referred, e-): thermal plus flicker/RTS.

Thermal noise is ``Normal(0, thermal_sigma_e)`` in every pixel and frame.

Flicker/RTS (paper Section VII-B): each pixel has a fixed temporal sigma,
drawn once from a Fisher-Tippett-Gumbel body (``gumbel_r(loc, scale)``,
clipped at 0) plus a thin uniform tail of very noisy pixels (docs/model.md
section 4, the same heavy-tail map as the dark current). In each frame the
pixel gets ``Normal(0, sigma_i)``. That is the paper's simplification:
the per-pixel noise is Gaussian in time, only its size varies over the array.

Examples
--------
>>> from cmosnoise import Sensor
>>> fp = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7).fixed_pattern
>>> fp.flicker_sigma.shape, bool((fp.flicker_sigma > 0).all())    # each pixel's flicker sigma, e- rms
((48, 64), True)
"""

from __future__ import annotations

import functools

import numpy as np

from ...engine.samplers import Stream
from ..distributions import gumbel
from ..heavy_tail import HeavyTail


@functools.lru_cache(maxsize=64)
def flicker_model(gumbel_loc_e: float, gumbel_scale_e: float, ppm_above: float | None = None,
                  threshold_e: float | None = None, max_e: float = 0.0) -> HeavyTail:
    """Distribution of the per-pixel flicker sigma over the array (e-).

    Made once per process for each set of parameters (the tail solve integrates numerically; the result is
    a frozen, read-only model).
    """
    b = gumbel(gumbel_loc_e, gumbel_scale_e)
    if ppm_above is None or threshold_e is None or max_e <= 0:
        return HeavyTail(b, 0.0, 0.0)
    return HeavyTail.from_ppm(b, ppm_above, threshold_e, max_e)


def flicker_sigma_map(model: HeavyTail, region: tuple[int, int, int, int], cols: int,
                      key: tuple[int, int], engine: str = "auto") -> np.ndarray:
    """Fixed per-pixel flicker sigma over a rectangle, from the stage's fixed ``key`` (:meth:`HeavyTail.map`).

    Parameters
    ----------
    model : HeavyTail
        The sigmas' law over the array (:func:`flicker_model`), e-.
    region : (row0, row1, col0, col1)
        The rectangle to make.
    cols : int
        The sensor's width (a pixel's address is ``r * cols + c``).
    key : (int, int)
        The stage's fixed key (:func:`cmosnoise.model.seeds.fixed_key`).
    engine : {"auto", "numpy", "compiled", "cuda"}
        Where the map is made (:func:`cmosnoise.engine.fixed_maps.heavy_tail_map`; the same bits each way).

    Returns
    -------
    (row1 - row0, col1 - col0) float32 array, e- rms
    """
    return model.map(region, cols, key, engine)


def total_sigma(thermal_sigma_e: float, flicker_sigma: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """Each pixel's fixed source-follower sigma, ``sqrt(thermal**2 + flicker_i**2)`` (e-), float32 (rows, cols).

    Thermal and flicker noise are both zero-mean normal in each frame, so
    they are drawn as one normal with this sigma. Computed once per sensor.

    Parameters
    ----------
    thermal_sigma_e : float
        The thermal (white) noise, the same in every pixel, e- rms.
    flicker_sigma : (rows, cols) array, e- rms, or None
        Each pixel's flicker sigma (:func:`flicker_sigma_map`); None: thermal noise alone.
    shape : (rows, cols)
        The map's shape where ``flicker_sigma`` is None.

    Returns
    -------
    (rows, cols) float32 array, e- rms
    """
    if flicker_sigma is None:
        return np.full(shape, thermal_sigma_e, np.float32)
    out = flicker_sigma * flicker_sigma  # then in place: one map's memory, not three (200 MB each at 50 MP)
    out += np.float32(thermal_sigma_e) ** 2
    return np.sqrt(out, out=out)


def noise(sigma_e: np.ndarray, stream: Stream, index: np.ndarray) -> np.ndarray:
    """One frame of source-follower noise (e-), float64: ``sigma_i * Normal(0, 1)`` per pixel.

    Parameters
    ----------
    sigma_e : array, e- rms
        Each pixel's sigma (:func:`total_sigma`).
    stream : Stream
        The frame's stream of the stage (:func:`cmosnoise.model.seeds.temporal_stream`).
    index : int array, the shape of ``sigma_e``
        The pixels' indices ``r * cols + c``.

    Returns
    -------
    float64 array, e-, the shape of ``sigma_e``
    """
    return np.asarray(sigma_e, np.float64) * stream.normal(index)
