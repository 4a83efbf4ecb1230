"""A body distribution plus a thin uniform tail (docs/model.md section 4).

``value = body + tail`` where ``tail ~ Uniform(0, tail_max)`` for a fraction
``f`` of the pixels and 0 for the rest. Used for the dark-current
non-uniformity (white pixels) and the per-pixel flicker-noise sigma.

Users do not give ``f``; they give what a data sheet gives, the parts per
million of pixels above a threshold. :meth:`HeavyTail.from_ppm` solves::

    (1 - f) P(body > thr) + f P(body + U > thr) = ppm * 1e-6

counting the body's own exceedance, and rejects a ppm outside what any
``f`` in [0, 1] reaches. The interface follows ``scipy.stats``: ``sf``,
``cdf``, ``rvs``, plus :meth:`values` for maps drawn from fixed uniform
variates (so that a pixel keeps its rank when parameters change).

Examples
--------
>>> from cmosnoise import distributions
>>> from cmosnoise.model.heavy_tail import HeavyTail
>>> m = HeavyTail.from_ppm(distributions.body("lognormal", 500.0, 200.0), 4000, 1560.4, 80000.0)
>>> round(m.ppm_above(1560.4), 6)
4000.0
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..engine import fixed_maps
from .distributions import LOGIT_GRID, ppf_table

# Gauss-Legendre nodes and weights on [0, 1] for the integrals of the body's sf (numpy's, not scipy.integrate:
# making a sensor must not import scipy.integrate, a third of a second)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(12)
_GL_X, _GL_W = (_GL_X + 1.0) / 2.0, _GL_W / 2.0
#: quantiles where the body's sf changes character: the integration pieces' ends
_BREAK_Q = (1e-15, 1e-9, 1e-5, 1e-3, 0.02, 0.1, 0.3, 0.5, 0.7, 0.9, 0.98, 1 - 1e-3, 1 - 1e-5, 1 - 1e-9, 1 - 1e-15)


def integral_of_sf(body, a: float, b: float) -> float:
    """``integral_a^b body.sf(y) dy`` for a smooth body, ``a <= b`` (within 1e-9 relative: tested).

    Composite 12-point Gauss-Legendre: the interval is cut at the body's
    quantiles 1e-15 ... 1 - 1e-15 (where its sf bends) and each piece into
    16 equal parts. Beyond those quantiles the sf is within 1e-15 of 1 or 0,
    and smooth. Tested against ``scipy.integrate.quad``.

    Parameters
    ----------
    body : frozen distribution
        The body (:func:`cmosnoise.model.distributions.body`).
    a, b : float
        The interval, in the body's unit, ``a <= b``.

    Returns
    -------
    float
        The integral, in the body's unit.
    """
    if not b > a:
        return 0.0
    cuts = np.asarray(body.ppf(np.asarray(_BREAK_Q)), dtype=np.float64)
    edges = np.unique(np.concatenate(([a, b], cuts[(cuts > a) & (cuts < b)])))
    fine = (edges[:-1, None] + (edges[1:] - edges[:-1])[:, None] * np.linspace(0.0, 1.0, 17)[None, :])
    lo, hi = fine[:, :-1].ravel(), fine[:, 1:].ravel()
    y = lo[:, None] + (hi - lo)[:, None] * _GL_X[None, :]
    return float(np.sum((hi - lo) * (body.sf(y) @ _GL_W)))


class UnreachablePpm(ValueError):
    """The requested ppm cannot be produced by any tail fraction in [0, 1].

    Parameters
    ----------
    ppm : float
        The ppm asked for.
    low_ppm, high_ppm : float
        The reachable range: the body alone, and the body with every pixel in the tail.
    threshold, tail_max : float
        The threshold and the tail's largest value, in the model's unit.
    """

    def __init__(self, ppm: float, low_ppm: float, high_ppm: float, threshold: float, tail_max: float):
        self.ppm, self.low_ppm, self.high_ppm = ppm, low_ppm, high_ppm
        super().__init__(
            f"{ppm:g} ppm above {threshold:g} cannot be reached with this body and a tail up to {tail_max:g}: "
            f"reachable is {low_ppm:.4g} to {high_ppm:.6g} ppm (the body alone gives {low_ppm:.4g})"
        )


def _sf_body_plus_uniform(body, x: float, tail_max: float) -> float:
    """P(max(body, 0) + U > x), U ~ Uniform(0, tail_max)."""
    if tail_max <= 0:
        return float(body.sf(x)) if x >= 0 else 1.0
    if x < 0:
        return 1.0
    # P(B + U > x) = (1/M) * integral_0^M sf_B(x - t) dt, with sf_B(y) = 1 for y < 0 (clipping)
    lo = max(x - tail_max, 0.0)
    part = integral_of_sf(body, lo, x)
    below = max(tail_max - x, 0.0)  # t > x: x - t < 0, the clipped body always exceeds
    return (part + below) / tail_max


@dataclass(frozen=True)
class HeavyTail:
    """``max(body, 0) + Bernoulli(f) * Uniform(0, tail_max)``.

    Parameters
    ----------
    body : frozen scipy.stats distribution
    tail_fraction : float in [0, 1]
    tail_max : float >= 0 (same units as the body)
    """

    body: Any  #: a frozen scipy.stats distribution (its sf, ppf, pdf)
    tail_fraction: float
    tail_max: float

    @classmethod
    def from_ppm(cls, body, ppm_above: float, threshold: float, tail_max: float) -> HeavyTail:
        """Solve the tail fraction that puts ``ppm_above`` ppm above ``threshold``."""
        p = ppm_above * 1e-6
        s0 = float(body.sf(threshold)) if threshold >= 0 else 1.0
        s1 = _sf_body_plus_uniform(body, threshold, tail_max)
        if s1 - s0 <= 1e-15:
            if abs(p - s0) <= 1e-12:
                return cls(body, 0.0, tail_max)
            raise UnreachablePpm(ppm_above, s0 * 1e6, s0 * 1e6, threshold, tail_max)
        f = (p - s0) / (s1 - s0)
        if f < -1e-12 or f > 1 + 1e-12:
            raise UnreachablePpm(ppm_above, s0 * 1e6, s1 * 1e6, threshold, tail_max)
        return cls(body, float(min(max(f, 0.0), 1.0)), tail_max)

    # ------------------------------------------------------------ scipy-like
    def sf(self, x):
        """P(value > x), for scalars or arrays."""
        x = np.asarray(x, dtype=np.float64)
        body_sf = np.where(x >= 0, self.body.sf(np.maximum(x, 0)), 1.0)
        if self.tail_fraction == 0 or self.tail_max <= 0:
            return body_sf
        if x.size <= 16:
            tail_sf = np.vectorize(lambda v: _sf_body_plus_uniform(self.body, v, self.tail_max))(x)
        else:
            tail_sf = self._tail_sf_tabulated(x)
        return (1 - self.tail_fraction) * body_sf + self.tail_fraction * tail_sf

    def _tail_sf_tabulated(self, x: np.ndarray) -> np.ndarray:
        """P(max(body, 0) + U > x) for many x: the integral of the body's sf, tabulated once.

        With I(y) = integral_0^y sf_B(t) dt (sf_B = 1 below 0, the clip),
        P = (I(x) - I(x - M) + max(M - x, 0)) / M.
        """
        m = self.tail_max
        top = float(max(np.max(x), 0.0)) + 1e-9
        grid = np.linspace(0.0, top, 40001)
        sf = self.body.sf(grid)
        cum = np.concatenate(([0.0], np.cumsum(np.diff(grid) * (sf[1:] + sf[:-1]) / 2.0)))  # the trapezoid rule

        def integral(y):
            return np.interp(np.clip(y, 0.0, top), grid, cum)

        xc = np.maximum(x, 0.0)
        p = (integral(xc) - integral(xc - m) + np.maximum(m - xc, 0.0)) / m
        return np.where(x < 0, 1.0, np.clip(p, 0.0, 1.0))

    def cdf(self, x):
        return 1.0 - self.sf(x)

    def ppm_above(self, threshold: float) -> float:
        """Expected parts per million above ``threshold``."""
        return float(self.sf(threshold)) * 1e6

    @property
    def point(self) -> tuple:
        """This law as the fixed maps take it: (the body's quantile table, tail fraction, tail max, floor 0)."""
        return ppf_table(self.body), self.tail_fraction, self.tail_max, 0.0

    def values(self, u_body: np.ndarray, u_member: np.ndarray, u_tail: np.ndarray) -> np.ndarray:
        """Values from fixed open uniform variates (one triple per pixel), float64.

        ``u_body`` is the pixel's body quantile, ``u_member < tail_fraction``
        puts it in the tail, ``u_tail`` is where in the tail. The same
        variates under other parameters give the same ranks in the body and
        nested tail sets (a larger fraction adds pixels, never removes them).
        The inversion is the map's (:func:`cmosnoise.engine.fixed_maps.heavy_tail_values`).
        """
        return fixed_maps.heavy_tail_values(u_body, u_member, u_tail, LOGIT_GRID, [self.point])

    def map(self, region: tuple[int, int, int, int], cols: int, key: tuple[int, int],
            engine: str = "auto") -> np.ndarray:
        """The map of this law over ``region = (row0, row1, col0, col1)`` of a sensor ``cols`` wide, float32,
        addressed per pixel under the fixed ``key``: :meth:`values` of the pixels' own variates
        (:func:`cmosnoise.engine.fixed_maps.heavy_tail_map`, made where ``engine`` says)."""
        return fixed_maps.heavy_tail_map(region, cols, key, LOGIT_GRID, [self.point], engine=engine)

    def rvs(self, size, random_state: np.random.Generator) -> np.ndarray:
        """Independent draws (each pixel its own variates)."""
        return self.values(*variates(tuple(np.atleast_1d(size)), random_state))


def variates(shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """The fixed uniforms of a heavy-tailed map: array ``(3, *shape)`` of (body quantile, tail membership, tail magnitude).

    Open uniforms, ``(m + 0.5) 2**-52`` as the counter-based maps' (never 0 or 1, where the quantile's logit
    has no value); passed to :meth:`HeavyTail.values`, the same variates under other parameters keep every
    pixel's rank. (A sensor's own variates: :func:`cmosnoise.engine.fixed_maps.variates`.)

    Parameters
    ----------
    shape : tuple of int
        The map's shape.
    rng : numpy.random.Generator
        Where the uniforms come from.

    Returns
    -------
    ``(3, *shape)`` float64 array, in (0, 1)
    """
    return (rng.integers(0, 2**52, (3, *shape)) + 0.5) * 2.0**-52
