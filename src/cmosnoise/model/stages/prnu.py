"""Stage 2, photo-response non-uniformity (PRNU): a fixed per-pixel gain.

Each pixel's responsivity is ``g ~ Normal(1, sigma_pct / 100)``, clipped at 0,
drawn once per sensor instance and applied to the mean photo-electrons. As in
the paper (Section V-B) the PRNU is independent of the signal level.
"""

import numpy as np


def gain_map(shape: tuple[int, int], sigma_pct: float, rng: np.random.Generator) -> np.ndarray:
    """Fixed PRNU gain map, dimensionless, mean 1, std ``sigma_pct`` % (before clipping at 0).

    Parameters
    ----------
    shape : (rows, cols)
    sigma_pct : float
        PRNU as a percentage of the signal, >= 0.
    rng : numpy.random.Generator
        The sensor's fixed-pattern stream for this stage.
    """
    if sigma_pct < 0:
        raise ValueError(f"sigma_pct must be >= 0, got {sigma_pct}")
    g = 1.0 + (sigma_pct / 100.0) * rng.standard_normal(shape, dtype=np.float32)
    return np.maximum(g, 0.0, out=g)


def apply(mean_e: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """Mean photo-electrons (e-) after the gain map."""
    return mean_e * gain
