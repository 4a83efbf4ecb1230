"""Stage 2, photo-response non-uniformity (PRNU): a fixed per-pixel gain.

Each pixel's responsivity is ``g ~ Normal(1, sigma_pct / 100)``, clipped at 0,
drawn once per sensor instance and applied to the mean photo-electrons. As in
the paper (Section V-B) the PRNU is independent of the signal level. The map
is addressed per pixel (:mod:`cmosnoise.engine.fixed_maps`): any rectangle of
it is made alone.

Examples
--------
>>> from cmosnoise import Sensor
>>> gain = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7).fixed_pattern.prnu_gain
>>> 0.97 < float(gain.mean()) < 1.03   # a gain of 1 on average, spread by prnu.sigma_pct
True
"""

import numpy as np

from ...engine import fixed_maps


def gain_map(region: tuple[int, int, int, int], cols: int, sigma_pct: float, key: tuple[int, int],
             engine: str = "auto") -> np.ndarray:
    """Fixed PRNU gain over ``region``, dimensionless, mean 1, std ``sigma_pct`` % (before clipping at 0).

    Parameters
    ----------
    region : (row0, row1, col0, col1)
        The rectangle to make (the whole map: ``(0, rows, 0, cols)``).
    cols : int
        The sensor's width (a pixel's address is ``r * cols + c``).
    sigma_pct : float
        PRNU as a percentage of the signal, >= 0.
    key : (int, int)
        The stage's fixed key (:func:`cmosnoise.model.seeds.fixed_key`).
    engine : {"auto", "numpy", "compiled", "cuda"}
        Where the map is made (:func:`cmosnoise.engine.fixed_maps.normal_map`; the same bits each way).

    Returns
    -------
    (row1 - row0, col1 - col0) float32
    """
    if sigma_pct < 0:
        raise ValueError(f"sigma_pct must be >= 0, got {sigma_pct}")
    return fixed_maps.normal_map(region, cols, key, 1.0, sigma_pct / 100.0, 0.0, engine=engine)


def apply(mean_e: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """Mean photo-electrons after the gain map.

    Parameters
    ----------
    mean_e : (rows, cols) array, e-
        Mean photo-electrons per pixel.
    gain : (rows, cols) array, dimensionless
        The PRNU gain map (:func:`gain_map`) of the same rectangle.

    Returns
    -------
    (rows, cols) array, e-
        ``mean_e * gain``.
    """
    return mean_e * gain
