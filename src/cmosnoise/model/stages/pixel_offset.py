"""Stage 5c, pixel offset non-uniformity: DSNU at zero exposure ("dark shading"), docs/model.md stage 5c.

Each pixel has a fixed offset (e-), added to its charge after the full-well
clip and the nonlinearity, before the readout noise: a reset level or source
follower threshold that differs from pixel to pixel. It does not grow with
the exposure time and does not change with temperature, which is what
separates it from the dark-current map in a measurement (the dark image's
intercept against its slope).

The offsets are a ``Normal(0, sigma_e)`` body plus a thin uniform tail of
pixels with large offsets (docs/model.md section 4): a fraction ``f`` of the
pixels get an extra ``U(0, max_e)``, with ``f`` solved so that ``ppm_above``
ppm of pixels exceed ``threshold_e``:

    (1 - f) P(B > thr) + f P(B + U > thr) = ppm * 1e-6

The map is addressed per pixel (docs/model.md section 1): pixel ``i``'s offset
comes from the Philox block at counter (i, 0, 0, attempt) under the stage's
fixed key, so any tile of it is made alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

from ...engine import fixed_maps


@dataclass(frozen=True)
class OffsetModel:
    """The offsets' law over the array: ``Normal(0, sigma_e)`` body, a fraction ``tail_fraction`` of the
    pixels with an extra ``U(0, tail_max_e)``."""

    sigma_e: float
    tail_fraction: float = 0.0
    tail_max_e: float = 0.0

    def sf(self, x) -> np.ndarray:
        """P(offset > x), x in e-."""
        x = np.asarray(x, np.float64)
        body = _normal_sf(x, self.sigma_e)
        if self.tail_fraction == 0.0:
            return body
        return (1 - self.tail_fraction) * body + self.tail_fraction * _tail_sf(x, self.sigma_e, self.tail_max_e)

    def ppm_above(self, threshold_e: float) -> float:
        return float(self.sf(threshold_e)) * 1e6

    @property
    def std_e(self) -> float:
        """Standard deviation of the offsets over the array, e-."""
        f, m = self.tail_fraction, self.tail_max_e
        mean = f * m / 2
        second = self.sigma_e**2 + f * m * m / 3
        return math.sqrt(second - mean * mean)

    @property
    def mean_e(self) -> float:
        return self.tail_fraction * self.tail_max_e / 2


def _normal_sf(x, sigma):
    if sigma == 0.0:
        return np.where(x < 0, 1.0, 0.0)
    return special.ndtr(-x / sigma)


def _tail_sf(x, sigma, m):
    """P(B + U > x), B ~ Normal(0, sigma), U ~ U(0, m): the mean over u of P(B > x - u).

    With Q(t) = P(B > t), the integral of Q is t Q(t/sigma) - sigma phi(t/sigma) (its derivative is Q):
    P = (F(x) - F(x - m)) / m with F the antiderivative of Q at x - u, u from 0 to m.
    """
    if sigma == 0.0:
        return np.clip((m - np.maximum(x, 0.0)) / m, 0.0, 1.0) if m > 0 else np.where(x < 0, 1.0, 0.0)

    def antiderivative(t):
        z = t / sigma
        return t * special.ndtr(-z) - sigma * np.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)

    return (antiderivative(x) - antiderivative(x - m)) / m


def offset_model(sigma_e: float, ppm_above: float | None = None, threshold_e: float | None = None,
                 max_e: float = 0.0) -> OffsetModel:
    """The offsets' law, the tail fraction solved from ``ppm_above`` ppm above ``threshold_e``.

    Raises
    ------
    ValueError
        When no tail fraction reaches ``ppm_above``: the body alone exceeds it, or even every pixel in the
        tail falls short (the message names the reachable range).
    """
    if ppm_above is None or threshold_e is None:
        return OffsetModel(float(sigma_e))
    target = ppm_above * 1e-6
    body = float(_normal_sf(np.float64(threshold_e), sigma_e))
    tail = float(_tail_sf(np.float64(threshold_e), sigma_e, max_e))
    if not body <= target <= tail:
        raise ValueError(f"pixel_offset.tail.ppm_above = {ppm_above:g}: with sigma_e {sigma_e:g}, threshold_e "
                         f"{threshold_e:g} and max_e {max_e:g}, reachable is {body * 1e6:.3g} to {tail * 1e6:.3g} ppm")
    f = 0.0 if tail == body else (target - body) / (tail - body)
    return OffsetModel(float(sigma_e), f, float(max_e))


def offset_map(model: OffsetModel, key: tuple[int, int], region: tuple[int, int, int, int], cols: int,
               engine: str = "auto") -> np.ndarray:
    """The fixed offsets (e-) of the pixels of ``region = (row0, row1, col0, col1)`` of a sensor ``cols`` wide,
    float32, from the stage's fixed ``key``.

    Block 0 of a pixel's counter (frame and sequence 0) gives the body's
    normal (Box-Muller), block 1 its tail membership (first uniform below
    ``tail_fraction``) and where in the tail it sits (second uniform):
    :func:`cmosnoise.engine.fixed_maps.offset_map`, compiled, any rectangle alone.

    Parameters
    ----------
    model : OffsetModel
        The offsets' law (:func:`offset_model`).
    key : (int, int)
        The stage's fixed key (:func:`cmosnoise.model.seeds.fixed_key`).
    region : (row0, row1, col0, col1)
        The rectangle.
    cols : int
        The sensor's width (a pixel's address is ``r * cols + c``).
    engine : {"auto", "numpy", "compiled", "cuda"}
        Where the map is made (the same bits each way).

    Returns
    -------
    (row1 - row0, col1 - col0) float32 array, e-
    """
    return fixed_maps.offset_map(region, cols, key, model.sigma_e, model.tail_fraction, model.tail_max_e, engine)
