"""Stage 4, dark current: a temperature-dependent non-uniformity with white pixels.

The dark-current non-uniformity (DCNU) is a body distribution plus a thin
uniform tail of very leaky "white" pixels (MODEL.md sections 3 and 4). A
sensor is characterized at one or more temperatures (the paper: logistic at
25 C, inverse Gaussian at 45 C, lognormal at 65 C). At an operating
temperature ``T``:

- between two points: ln(mean), ln(std), ln(tail max) and the tail fraction
  are interpolated linearly in ``T``; the body family is the nearer point's;
- outside them (or with one point): the body is scaled by
  ``2**((T - Tc) / doubling_c)`` and the tail by ``2**((T - Tc) / tail_doubling_c)``
  (very leaky pixels have a lower temperature coefficient).

Every pixel has fixed uniform variates (body quantile, tail membership, tail
magnitude) drawn once from the sensor's seed, so a pixel keeps its rank and a
white pixel stays white when the sensor warms up. Rates are e-/s per pixel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..distributions import body as body_dist
from ..heavy_tail import HeavyTail, variates


@dataclass(frozen=True)
class Point:
    """One characterization point, rates in e-/s per pixel."""

    temperature_c: float
    family: str
    mean: float
    std: float
    ppm_above: float = 0.0
    threshold: float | None = None
    tail_max: float = 0.0

    def model(self) -> HeavyTail:
        """The heavy-tailed DCNU at this point's own temperature (tail fraction solved from the ppm)."""
        b = body_dist(self.family, self.mean, self.std)
        if self.threshold is None or self.tail_max <= 0:
            return HeavyTail(b, 0.0, 0.0)
        return HeavyTail.from_ppm(b, self.ppm_above, self.threshold, self.tail_max)


@dataclass(frozen=True)
class DarkState:
    """The DCNU at one temperature."""

    temperature_c: float
    family: str
    mean: float  #: body mean, e-/s
    std: float  #: body std, e-/s
    tail_fraction: float
    tail_max: float  #: e-/s
    threshold: float | None  #: the nearest point's white-pixel threshold, e-/s

    @property
    def model(self) -> HeavyTail:
        return HeavyTail(body_dist(self.family, self.mean, self.std), self.tail_fraction, self.tail_max)

    def expected_ppm_above(self, threshold: float | None = None) -> float | None:
        thr = self.threshold if threshold is None else threshold
        return None if thr is None else self.model.ppm_above(thr)


def _log_lerp(a: float, b: float, w: float) -> float:
    if a <= 0 or b <= 0:  # a point without a tail: keep the other's magnitude
        return max(a, b)
    return math.exp((1 - w) * math.log(a) + w * math.log(b))


def at_temperature(points: list[Point], temperature_c: float, doubling_c: float = 7.0, tail_doubling_c: float = 10.0) -> DarkState:
    """The DCNU parameters at ``temperature_c`` from the characterization ``points``."""
    pts = sorted(points, key=lambda p: p.temperature_c)
    models = [p.model() for p in pts]
    t = temperature_c
    nearest = min(range(len(pts)), key=lambda i: (abs(pts[i].temperature_c - t), -pts[i].temperature_c))
    if t <= pts[0].temperature_c or t >= pts[-1].temperature_c:
        i = 0 if t <= pts[0].temperature_c else len(pts) - 1
        p, m = pts[i], models[i]
        sb = 2.0 ** ((t - p.temperature_c) / doubling_c)
        st = 2.0 ** ((t - p.temperature_c) / tail_doubling_c)
        return DarkState(t, p.family, p.mean * sb, p.std * sb, m.tail_fraction, m.tail_max * st, p.threshold)
    j = next(k for k in range(1, len(pts)) if pts[k].temperature_c >= t)
    a, b = pts[j - 1], pts[j]
    w = (t - a.temperature_c) / (b.temperature_c - a.temperature_c)
    ma, mb = models[j - 1], models[j]
    near = pts[nearest]
    return DarkState(
        t,
        near.family,
        _log_lerp(a.mean, b.mean, w),
        _log_lerp(a.std, b.std, w),
        (1 - w) * ma.tail_fraction + w * mb.tail_fraction,
        _log_lerp(ma.tail_max, mb.tail_max, w),
        near.threshold,
    )


def rate_map(state: DarkState, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """Fixed dark-current map at ``state``'s temperature, e-/s per pixel, float32 (>= 0)."""
    return state.model.values(*variates(shape, rng)).astype(np.float32)


def mean_charge(rate_e_per_s: np.ndarray, integration_time_s: float) -> np.ndarray:
    """Mean dark electrons collected in one integration time: ``rate * t_int`` (e-)."""
    return (rate_e_per_s * np.float32(integration_time_s)).astype(np.float32)
