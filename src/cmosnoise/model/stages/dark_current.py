"""Stage 4, dark current: a temperature-dependent non-uniformity with white pixels.

The dark-current non-uniformity (DCNU) is a body distribution plus a thin
uniform tail of very leaky "white" pixels (docs/model.md sections 3 and 4). A
sensor is characterized at one or more temperatures (the paper: logistic at
25 C, inverse Gaussian at 45 C, lognormal at 65 C). At an operating
temperature ``T``:

- between two points T_lo < T < T_hi: **each pixel follows its own
  exponential law** between its rates at the two points,
  ``ln r = (1 - w) ln r_lo + w ln r_hi`` with ``w = (T - T_lo) / (T_hi - T_lo)``
  (rates floored at 1e-6 of the point's body mean first), so every pixel's
  rate, and every quantile of the map, is continuous in ``T``, and the
  map's shape morphs from one family to the next;
- outside them (or with one point): the body part is scaled by
  ``2**((T - Tc) / doubling_c)`` and the tail part by
  ``2**((T - Tc) / tail_doubling_c)`` (very leaky pixels have a lower
  temperature coefficient).

Every pixel has fixed uniform variates (body quantile, tail membership, tail
magnitude) from its own counter under the stage's fixed key, so a pixel keeps
its rank and a white pixel stays white when the sensor warms up, and any
rectangle of the map is made alone. Rates are e-/s per pixel.

Examples
--------
>>> from cmosnoise import Sensor
>>> s = Sensor({"sensor": {"width": 64, "height": 48, "temperature_c": 65}}, seed=7)
>>> s.dark_state.temperature_c, s.dark_rate.shape
(65.0, (48, 64))
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ...engine import fixed_maps
from ..distributions import LOGIT_GRID
from ..distributions import body as body_dist
from ..heavy_tail import HeavyTail


@dataclass(frozen=True)
class Point:
    """One characterization point, rates in e-/s per pixel.

    Parameters
    ----------
    temperature_c : float
        The point's temperature, C.
    family : str
        The body's distribution: logistic, inverse_gaussian, lognormal, normal or gamma.
    mean, std : float
        The body's mean and standard deviation, e-/s.
    ppm_above : float
        Parts per million of pixels above ``threshold`` (the white-pixel tail's target).
    threshold : float or None
        The white-pixel threshold, e-/s (None: no tail).
    tail_max : float
        The tail's largest rate, e-/s (0: no tail).
    """

    temperature_c: float
    family: str
    mean: float
    std: float
    ppm_above: float = 0.0
    threshold: float | None = None
    tail_max: float = 0.0

    def model(self) -> HeavyTail:
        """The heavy-tailed DCNU at this point's own temperature (tail fraction solved from the ppm)."""
        return _point_model(self)


@functools.lru_cache(maxsize=256)
def _point_model(p: Point) -> HeavyTail:
    """Point.model, solved once per process for each point (the solve integrates numerically)."""
    b = body_dist(p.family, p.mean, p.std)
    if p.threshold is None or p.tail_max <= 0:
        return HeavyTail(b, 0.0, 0.0)
    return HeavyTail.from_ppm(b, p.ppm_above, p.threshold, p.tail_max)


#: rates are floored at this fraction of the point's body mean before the log
RATE_FLOOR = 1e-6


@dataclass(frozen=True)
class DarkState:
    """The DCNU at one temperature.

    At a point or outside the points, the map is one heavy-tailed model
    (``lo``) with its body scaled by ``body_scale`` and its tail by
    ``tail_scale``. Between two points it is the per-pixel exponential
    interpolation between ``lo`` and ``hi`` with weight ``w``; ``family``
    then names both, and ``mean``, ``std``, ``tail_fraction`` and
    ``tail_max`` are the log-interpolated parameters, a description (the
    map's own statistics are in the run summary).

    Parameters
    ----------
    temperature_c : float
        The sensor's temperature, C.
    family : str
        The body's family (two names between two points of different families).
    mean, std : float
        The body's mean and standard deviation, e-/s.
    tail_fraction : float
        The fraction of pixels in the white-pixel tail.
    tail_max : float
        The tail's largest rate, e-/s.
    threshold : float or None
        The white-pixel threshold every count uses, e-/s.
    lo, hi : HeavyTail or None
        The model at (or below) the temperature, and above it between two points.
    w : float
        The warmer point's weight between two points.
    body_scale, tail_scale : float
        The doubling laws' factors outside the points.
    threshold_source : str
        Where ``threshold`` comes from.
    """

    temperature_c: float
    family: str
    mean: float  #: body mean, e-/s
    std: float  #: body std, e-/s
    tail_fraction: float
    tail_max: float  #: e-/s
    threshold: float | None  #: the white-pixel threshold every count uses, e-/s (see ``threshold_source``)
    lo: HeavyTail | None = None
    hi: HeavyTail | None = None
    w: float = 0.0
    body_scale: float = 1.0
    tail_scale: float = 1.0
    #: where ``threshold`` comes from: a fixed key, or the characterization point it was taken from
    threshold_source: str = ""

    @property
    def between(self) -> bool:
        return self.hi is not None

    @property
    def model(self) -> HeavyTail:
        """The heavy-tailed model at this temperature (at or outside the points only)."""
        if self.between:
            raise ValueError("between two characterization points the DCNU is a per-pixel interpolation, not one model")
        return HeavyTail(body_dist(self.family, self.mean, self.std), self.tail_fraction, self.tail_max)

    def inversion(self) -> dict:
        """How the map is made from a pixel's variates at this temperature, as
        :func:`cmosnoise.engine.fixed_maps.heavy_tail_values` takes it: the point and its scales, or the two
        points (each rate floored at ``RATE_FLOOR`` times its point's body mean) and the weight of the warmer."""
        if self.between:
            return {"points": [(*m.point[:3], RATE_FLOOR * float(m.body.mean())) for m in (self.lo, self.hi)],
                    "w": self.w}
        return {"points": [self.lo.point], "body_scale": self.body_scale, "tail_scale": self.tail_scale}

    def values(self, u_body: np.ndarray, u_member: np.ndarray, u_tail: np.ndarray) -> np.ndarray:
        """Rates (e-/s, float64) of pixels with these fixed open uniform variates: the map's inversion, by NumPy
        (for studies over variates: the expected ppm, the cooling fraction; the map itself is :func:`rate_map`)."""
        return fixed_maps.heavy_tail_values(u_body, u_member, u_tail, LOGIT_GRID, **self.inversion())

    def expected_ppm_above(self, threshold: float | None = None) -> float | None:
        """Expected ppm of pixels above ``threshold`` (default: the state's own), e-/s.

        At or outside the points, the model's survival function; between
        them, the probability over the fixed variates, by quadrature: a
        pixel's rate rises with its body quantile and tail magnitude, so
        for each tail-membership case the exceedance is the area of a
        monotone region of the unit square (grid of 2048 x 2048 midpoints,
        error below 1e-3 of the value).
        """
        thr = self.threshold if threshold is None else threshold
        if thr is None:
            return None
        if not self.between:
            return self.model.ppm_above(thr)
        n = 2048
        u = (np.arange(n) + 0.5) / n
        fl, fh = self.lo.tail_fraction, self.hi.tail_fraction
        # (weight, u_member): in both tails, in the larger tail only, in neither
        cases = [(min(fl, fh), 0.0), (abs(fl - fh), 0.5 * (fl + fh)), (1.0 - max(fl, fh), 1.0)]
        total = 0.0
        for weight, member in cases:
            if weight <= 0:
                continue
            if member == 1.0:  # no tail: one dimension suffices
                total += weight * float(np.mean(self.values(u, np.ones(n), np.zeros(n)) > thr))
                continue
            ub, ut = np.meshgrid(u, u, indexing="ij")
            total += weight * float(np.mean(self.values(ub, np.full(ub.shape, member), ut) > thr))
        return total * 1e6


def _log_lerp(a: float, b: float, w: float) -> float:
    if a <= 0 or b <= 0:  # a point without a tail: keep the other's magnitude
        return max(a, b)
    return math.exp((1 - w) * math.log(a) + w * math.log(b))


def at_temperature(points: list[Point], temperature_c: float, doubling_c: float = 7.0, tail_doubling_c: float = 10.0,
                   white_threshold: tuple[float, str] | None = None) -> DarkState:
    """The DCNU parameters at ``temperature_c`` from the characterization ``points``.

    ``white_threshold``: (e-/s, where it comes from), the threshold every white-pixel count uses at any
    temperature; without it, the nearest characterization point's tail threshold (which moves with the
    temperature: 100 e-/s at 25 C and 1560 e-/s at 65 C by default, so counts at two temperatures then differ in
    their threshold as well as in the dark current). The map is the same either way.

    Parameters
    ----------
    points : list of Point
        The characterization points (one or more temperatures).
    temperature_c : float
        The sensor's temperature, C.
    doubling_c, tail_doubling_c : float
        The body and the tail double every this many degrees C (outside the points).
    white_threshold : (float, str), optional
        A fixed white-pixel threshold, e-/s, and the key that gave it.

    Returns
    -------
    DarkState
    """
    pts = sorted(points, key=lambda p: p.temperature_c)
    models = [p.model() for p in pts]
    t = temperature_c
    nearest = min(range(len(pts)), key=lambda i: (abs(pts[i].temperature_c - t), -pts[i].temperature_c))
    near = pts[nearest]
    if white_threshold is not None:
        count = {"threshold": white_threshold[0], "threshold_source": f"fixed by {white_threshold[1]}"}
    elif near.threshold is not None:
        # outside the points the tail is its nearest point's, doubled every tail_doubling_c: its threshold moves
        # with it, so a camera characterized at one temperature counts the same tail as white at any other
        # (the body's pixels, which double faster, would otherwise cross a fixed threshold by the thousand)
        outside = t < pts[0].temperature_c or t > pts[-1].temperature_c
        moved = 2.0 ** ((t - near.temperature_c) / tail_doubling_c) if outside else 1.0
        count = {"threshold": near.threshold * moved,
                 "threshold_source": f"the nearest characterization point's ({near.temperature_c:g} C) tail threshold"
                                     + (f", doubled every {tail_doubling_c:g} C to {t:g} C" if outside else "")}
    else:
        count = {"threshold": None, "threshold_source": "none: no characterization point has a tail threshold"}
    at_point = [k for k, p in enumerate(pts) if p.temperature_c == t]
    if at_point or t <= pts[0].temperature_c or t >= pts[-1].temperature_c:
        i = at_point[0] if at_point else (0 if t <= pts[0].temperature_c else len(pts) - 1)
        p, m = pts[i], models[i]
        sb = 2.0 ** ((t - p.temperature_c) / doubling_c)
        st = 2.0 ** ((t - p.temperature_c) / tail_doubling_c)
        return DarkState(t, p.family, p.mean * sb, p.std * sb, m.tail_fraction, m.tail_max * st, lo=m, body_scale=sb,
                         tail_scale=st, **count)
    j = next(k for k in range(1, len(pts)) if pts[k].temperature_c >= t)
    a, b = pts[j - 1], pts[j]
    w = (t - a.temperature_c) / (b.temperature_c - a.temperature_c)
    ma, mb = models[j - 1], models[j]
    family = a.family if a.family == b.family else f"{a.family} to {b.family}"
    return DarkState(
        t,
        family,
        _log_lerp(a.mean, b.mean, w),
        _log_lerp(a.std, b.std, w),
        (1 - w) * ma.tail_fraction + w * mb.tail_fraction,
        _log_lerp(ma.tail_max, mb.tail_max, w),
        lo=ma, hi=mb, w=w, **count,
    )


def rate_map(state: DarkState, region: tuple[int, int, int, int], cols: int, key: tuple[int, int],
             engine: str = "auto") -> np.ndarray:
    """Fixed dark-current map at ``state``'s temperature over ``region = (row0, row1, col0, col1)`` of a sensor
    ``cols`` wide, e-/s per pixel, float32 (>= 0), from the stage's fixed ``key``.

    Addressed per pixel (:func:`cmosnoise.engine.fixed_maps.heavy_tail_map`): each pixel's variates, and so
    its rank and its tail membership, are the same at every temperature; between two points its rate is
    log-linear between its own rates there (floored at ``RATE_FLOOR`` times each point's body mean).

    Parameters
    ----------
    state : DarkState
        The DCNU at the sensor's temperature (:func:`at_temperature`).
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
    (row1 - row0, col1 - col0) float32 array, e-/s, >= 0
    """
    return fixed_maps.heavy_tail_map(region, cols, key, LOGIT_GRID, **state.inversion(), engine=engine)


def cooling_fraction(points: list[Point], draw_variates) -> float:
    """Fraction of pixels whose rate drops from one characterization point to the next warmer one.

    ``draw_variates()`` returns the pixels' fixed uniforms, shape (3, ...), or an iterable of such arrays
    (row bands, so that a large sensor is never held as variates at once); it is called only when some pixel
    can cool, since with ordered points
    (every quantile of each warmer point above the colder one's, tails no
    smaller) the answer is 0 without looking at pixels. A user's points can
    break that, and the run summary says so.

    Parameters
    ----------
    points : list of Point
        The characterization points.
    draw_variates : callable
        Returns the pixels' fixed uniforms, (3, ...) arrays (one, or an iterable of row bands).

    Returns
    -------
    float
        The fraction of pixels, 0 to 1.
    """
    pts = sorted(points, key=lambda p: p.temperature_c)
    if len(pts) < 2:
        return 0.0
    models = [p.model() for p in pts]
    if all(_dominates(b, a) for a, b in zip(models[:-1], models[1:])):
        return 0.0
    bands = draw_variates()
    cooling = total = 0
    for u in [bands] if isinstance(bands, np.ndarray) else bands:
        rates = [m.values(*u) for m in models]
        cools = np.zeros(u.shape[1:], bool)
        for lo, hi in zip(rates[:-1], rates[1:]):
            cools |= hi < lo
        cooling += int(cools.sum())
        total += cools.size
    return cooling / max(total, 1)


def _dominates(hot: HeavyTail, cold: HeavyTail) -> bool:
    """Whether every pixel's rate under ``hot`` is at least its rate under ``cold``, whatever its variates.

    True when the bodies are ordered (every quantile of ``hot`` at least
    ``cold``'s, which is: ``hot``'s survival function at least ``cold``'s
    everywhere) and the tail is no smaller in fraction or magnitude (tail
    sets are nested in ``u_member``). The survival functions are compared on
    8193 points spanning both bodies between their quantiles 1e-13 and
    1 - 1e-13 (the maps' range), linearly and, for positive bodies, also
    geometrically spaced, with a tolerance of 1e-13 in probability: a few
    milliseconds, where tabulating the quantiles of an inverse Gaussian takes
    a tenth of a second.
    """
    ends = [d.ppf(np.array([1e-13, 1 - 1e-13])) for d in (hot.body, cold.body)]
    lo, hi = min(e[0] for e in ends), max(e[1] for e in ends)
    x = np.linspace(lo, hi, 8193)
    if lo > 0:
        x = np.concatenate([x, np.geomspace(lo, hi, 8193)])
    body_ok = np.all(hot.body.sf(x) >= cold.body.sf(x) - 1e-13)
    tail_ok = hot.tail_fraction >= cold.tail_fraction and hot.tail_max >= cold.tail_max or cold.tail_fraction == 0
    return bool(body_ok and tail_ok)


def mean_charge(rate_e_per_s: np.ndarray, integration_time_s: float) -> np.ndarray:
    """Mean dark electrons collected in one integration time: ``rate * t_int``.

    Parameters
    ----------
    rate_e_per_s : array, e-/s
        The dark-current map (:func:`rate_map`).
    integration_time_s : float
        The integration time, s.

    Returns
    -------
    float32 array, e-, the map's shape
    """
    return (rate_e_per_s * np.float32(integration_time_s)).astype(np.float32, copy=False)  # float32 already: no copy
