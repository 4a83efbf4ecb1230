"""Stage 5, shot noise and the full well.

The collected charge is ``N ~ Poisson(mu_photo + mu_dark)``: photon and dark
shot noise in one draw (a sum of independent Poisson variables is Poisson).
A part whose shot noise is switched off enters as its mean. The charge is
then clipped at the full-well capacity.
"""

from __future__ import annotations

import numpy as np


def collect(
    noisy_mean_e: np.ndarray | None,
    exact_mean_e: np.ndarray | None,
    full_well_e: float,
    rng: np.random.Generator | None,
    gaussian_above_e: float | None = None,
) -> np.ndarray:
    """Collected charge in one frame (e-), float32.

    Parameters
    ----------
    noisy_mean_e : (rows, cols) array or None
        Mean charge whose shot noise is simulated (e-).
    exact_mean_e : (rows, cols) array or None
        Mean charge that enters without shot noise (e-).
    full_well_e : float
        Full-well capacity (e-); the charge is clipped there.
    rng : numpy.random.Generator or None
        This frame's temporal stream for the stage (needed with ``noisy_mean_e``).
    gaussian_above_e : float or None
        Speed option: where the mean exceeds this, draw ``Normal(mu, sqrt(mu))``
        rounded to whole electrons instead of Poisson (the paper used 1000).
    """
    if noisy_mean_e is None:
        if exact_mean_e is None:
            raise ValueError("collect needs a noisy or an exact mean charge")
        n = np.array(exact_mean_e, dtype=np.float32)
        return np.minimum(n, np.float32(full_well_e), out=n)
    lam = np.asarray(noisy_mean_e, dtype=np.float64)
    if gaussian_above_e is None:
        n = rng.poisson(lam).astype(np.float32)
    else:
        big = lam > gaussian_above_e
        n = np.empty(lam.shape, dtype=np.float32)
        n[~big] = rng.poisson(lam[~big])
        lb = lam[big]
        n[big] = np.maximum(np.rint(lb + np.sqrt(lb) * rng.standard_normal(lb.shape)), 0)
    if exact_mean_e is not None:
        n += exact_mean_e
    return np.minimum(n, np.float32(full_well_e), out=n)
