"""Stage 5, shot noise and the full well.

The collected charge is ``N ~ Poisson(mu_photo + mu_dark)``: photon and dark
shot noise in one draw (a sum of independent Poisson variables is Poisson).
A part whose shot noise is switched off enters as its mean. The charge is
then clipped at the full-well capacity. The draws are counter-based
(:mod:`cmosnoise.engine.samplers`): a pixel's count depends on its own mean
and nothing else, so a scene changed at one pixel changes no other pixel.

Examples
--------
>>> from cmosnoise import Sensor
>>> shot = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7).expose("flat:0.5")
>>> d = shot.frame(0, detail=True)
>>> d.contributions["shot_noise"].shape                       # what photon and dark shot noise added, e-
(48, 64)
"""

from __future__ import annotations

import numpy as np

from ...engine.samplers import Stream


def collect(
    noisy_mean_e: np.ndarray | None,
    exact_mean_e: np.ndarray | None,
    full_well_e: float,
    stream: Stream | None,
    gaussian_above_e: float | None = None,
    index: np.ndarray | None = None,
) -> np.ndarray:
    """Collected charge in one frame (e-), float64, any shape.

    Parameters
    ----------
    noisy_mean_e : array or None
        Mean charge whose shot noise is simulated (e-).
    exact_mean_e : array or None
        Mean charge that enters without shot noise (e-).
    full_well_e : float
        Full-well capacity (e-); the charge is clipped there.
    stream : cmosnoise.engine.samplers.Stream or None
        This frame's shot-noise stream (needed with ``noisy_mean_e``).
    gaussian_above_e : float or None
        Speed option: where the mean exceeds this, draw ``Normal(mu, sqrt(mu))``
        rounded to whole electrons instead of Poisson (the paper used 1000).
    index : array of int, optional
        The pixels' indices ``r * cols + c``, the shape of the means (default: 0, 1, 2, ... in C order, the pixels
        of a whole frame): a pixel's noise is drawn at its own index.

    Returns
    -------
    array, e-, float64, the means' shape
        Whole electrons where shot noise is drawn (Poisson), the exact mean elsewhere, clipped at the full well.
    """
    if noisy_mean_e is None:
        if exact_mean_e is None:
            raise ValueError("collect needs a noisy or an exact mean charge")
        n = np.asarray(exact_mean_e, dtype=np.float64)
        return np.minimum(n, full_well_e)
    lam = np.asarray(noisy_mean_e, dtype=np.float64)
    if index is None:
        index = np.arange(lam.size, dtype=np.uint64).reshape(lam.shape)
    if gaussian_above_e is None:
        n = stream.poisson(lam, index)
    else:
        n = stream.poisson_or_normal(lam, index, gaussian_above_e)
    if exact_mean_e is not None:
        n = n + np.asarray(exact_mean_e, dtype=np.float64)
    return np.minimum(n, full_well_e)
