"""Body distributions set by their mean and standard deviation (docs/model.md section 3).

Each is a frozen distribution with the interface of :mod:`scipy.stats`
(``pdf``, ``cdf``, ``sf``, ``ppf``, ``rvs``, ``fit``, ...):

====================  ====================================================
``logistic``          ``loc = mean``, ``scale = std * sqrt(3) / pi``
``inverse_gaussian``  Wald: shape ``lambda = mean**3 / std**2``
                      (scipy ``invgauss(mu=mean/lambda, scale=lambda)``)
``lognormal``         ``sigma_ln**2 = ln(1 + std**2/mean**2)``,
                      ``mu_ln = ln(mean) - sigma_ln**2 / 2``
``normal``            ``loc = mean``, ``scale = std``
``gamma``             ``a = mean**2 / std**2``, ``scale = std**2 / mean``
====================  ====================================================

plus :func:`gumbel` (``gumbel_r``), the source-follower and column
amplifiers' noise sigma over the array (docs/model.md stages 6 and 8).

Why not :mod:`scipy.stats` itself: importing it takes about 0.6 s, and a
default ``cmosnoise simulate`` took 1.67 s with it imported against 1.34 s
without (``docs/performance.md``, "Machinery measured against the library's
own way"); making a sensor needs only quantiles, survival functions and
moments. :class:`Frozen` computes those
with :mod:`scipy.special` in exactly the operations scipy.stats uses (the
same bits; a test holds them), and hands every other method to the
equivalent frozen scipy.stats distribution, made on first use.

Examples
--------
>>> from cmosnoise import distributions
>>> d = distributions.body("lognormal", 500.0, 200.0)
>>> round(float(d.mean()), 6), round(float(d.std()), 6)
(500.0, 200.0)
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy import special

FAMILIES = ("logistic", "inverse_gaussian", "lognormal", "normal", "gamma")
#: families defined only for positive values: their mean must be > 0
POSITIVE_FAMILIES = ("inverse_gaussian", "lognormal", "gamma")

_EULER = 0.577215664901532860606512090082402431042


def _invgauss_ppf(q: np.ndarray, mu: float, max_steps: int = 100) -> np.ndarray:
    """Quantile of scipy's standard inverse Gaussian ``invgauss(mu)`` at ``q`` in (0, 1).

    Safeguarded Newton steps in ``t = log x`` on the log of the lower tail
    (``q <= 0.5``) or of the upper tail (``q > 0.5``), so neither tail loses
    digits to ``1 - q``; each step is kept inside the bracket the earlier
    steps found, else the bracket is halved. The tails are scipy's own
    formulas through :func:`scipy.special.log_ndtr`::

        F(x) = Phi((x/mu - 1)/sqrt(x)) + exp(2/mu) Phi(-(x/mu + 1)/sqrt(x))

    It converges (to 4e-16 in ``t``) in 6 to 11 steps for most ``q``; at the
    last bits the evaluated tail is flat and a step may cycle, where
    ``max_steps`` ends it. Its error is that of evaluating the tail in
    float64: within 1e-12 of scipy.stats' quantile over mu from 1e-2 to 20,
    closer than scipy's at small mu (1e-3: scipy's Boost quantile is 3e-6 off).

    Parameters
    ----------
    q : ndarray of float64, probabilities strictly inside (0, 1)
    mu : float, scipy's shape (mean over shape lambda of the Wald law)

    Returns
    -------
    ndarray of float64, the shape of ``q``
    """
    q = np.asarray(q, dtype=np.float64)
    lower = q <= 0.5
    target = np.where(lower, np.log(q), np.log1p(-q))
    sign = np.where(lower, 1.0, -1.0)
    inv_mu = 1.0 / mu

    def log_tail_and_slope(t):
        x, root = np.exp(t), np.exp(-0.5 * t)
        a = special.log_ndtr(sign * root * (x * inv_mu - 1))  # log Phi(+-(x/mu - 1)/sqrt(x))
        b = 2 * inv_mu + special.log_ndtr(-root * (x * inv_mu + 1))
        log_tail = np.where(lower, np.logaddexp(a, b), a + np.log1p(-np.exp(b - a)))
        log_pdf = -0.5 * math.log(2 * math.pi) - 1.5 * t - (x - mu) ** 2 / (2 * x * mu * mu)
        return log_tail, sign * np.exp(t + log_pdf - log_tail)  # d log(tail) / dt

    s2 = math.log1p(mu)  # start: the lognormal with the same mean and variance
    t = math.log(mu) - s2 / 2 + math.sqrt(s2) * special.ndtri(q)
    lo, hi = np.full(q.shape, -np.inf), np.full(q.shape, np.inf)
    active = np.ones(q.shape, dtype=bool)
    with np.errstate(all="ignore"):
        for _ in range(max_steps):
            g, slope = log_tail_and_slope(t)
            g = g - target
            below = sign * g < 0  # the root lies above t
            lo, hi = np.where(below, t, lo), np.where(below, hi, t)
            step = t + np.clip(-g / slope, -2.0, 2.0)
            halved = np.where(np.isfinite(lo) & np.isfinite(hi), 0.5 * (lo + hi),
                              np.where(np.isfinite(lo), lo + 2.0, hi - 2.0))
            step = np.where((step > lo) & (step < hi), step, halved)
            done = np.abs(step - t) <= 4e-16 * np.maximum(1.0, np.abs(t))
            t = np.where(active, step, t)
            active &= ~done
            if not active.any():
                break
    return np.exp(t)


class Frozen:
    """A frozen distribution: scipy.stats' ``name(*shapes, loc=loc, scale=scale)``.

    ``ppf``, ``sf``, ``mean`` and ``std`` are computed here for the
    standardized forms below (scipy's own formulas, so the same values);
    any other attribute is the scipy.stats frozen distribution's.

    Parameters
    ----------
    name : scipy.stats name: ``logistic``, ``norm``, ``lognorm``, ``gamma``, ``gumbel_r``, ``invgauss``
    shapes : tuple of float, the shape parameters (``s`` of lognorm, ``a`` of gamma, ``mu`` of invgauss)
    loc, scale : float
    """

    NAMES = ("logistic", "norm", "lognorm", "gamma", "gumbel_r", "invgauss")

    def __init__(self, name: str, shapes: tuple = (), loc: float = 0.0, scale: float = 1.0):
        if name not in self.NAMES:
            raise ValueError(f"unknown distribution {name!r}; use one of {self.NAMES}")
        # numpy floats, as scipy.stats has them (``x ** 3.0`` of a Python float can differ in the last bit)
        self.name, self.shapes = name, tuple(np.float64(a) for a in shapes)
        self.loc, self.scale = np.float64(loc), np.float64(scale)

    def __repr__(self) -> str:
        args = ", ".join([f"{a!r}" for a in self.shapes] + [f"loc={self.loc!r}", f"scale={self.scale!r}"])
        return f"Frozen({self.name!r}: {args})"

    @functools.cached_property
    def scipy(self):
        """The equivalent frozen :mod:`scipy.stats` distribution (imports scipy.stats)."""
        from scipy import stats

        return getattr(stats, self.name)(*self.shapes, loc=self.loc, scale=self.scale)

    def __getattr__(self, attr):
        if attr.startswith("_") or attr in ("name", "shapes", "loc", "scale"):
            raise AttributeError(attr)
        return getattr(self.scipy, attr)

    # the standardized quantile, survival function, mean and variance, as scipy.stats computes them
    def _ppf(self, q):
        n = self.name
        if n == "logistic":
            return special.logit(q)
        if n == "norm":
            return special.ndtri(q)
        if n == "lognorm":
            return np.exp(self.shapes[0] * special.ndtri(q))
        if n == "gamma":
            return special.gammaincinv(self.shapes[0], q)
        if n == "gumbel_r":
            return -np.log(-np.log(q))
        return _invgauss_ppf(q, self.shapes[0])

    def _sf(self, x):
        n = self.name
        if n == "logistic":
            return special.expit(-x)
        if n == "norm":
            return special.ndtr(-x)
        if n == "lognorm":
            return special.ndtr(-(np.log(x) / self.shapes[0]))
        if n == "gamma":
            return special.gammaincc(self.shapes[0], x)
        if n == "gumbel_r":
            return -special.expm1(-np.exp(-x))
        mu = self.shapes[0]  # invgauss
        fac = 1 / np.sqrt(x)
        a = special.log_ndtr(-(fac * (x / mu - 1)))
        b = 2 / mu + special.log_ndtr(-fac * (x / mu + 1))
        return np.exp(a + np.log1p(-np.exp(b - a)))

    def _lower(self) -> float:
        """The standardized support's lower end."""
        return 0.0 if self.name in ("lognorm", "gamma", "invgauss") else -np.inf

    def _moments(self):
        n, s = self.name, self.shapes
        if n == "logistic":
            return 0.0, np.pi * np.pi / 3.0
        if n == "norm":
            return 0.0, 1.0
        if n == "lognorm":
            p = np.exp(s[0] * s[0])
            return np.sqrt(p), p * (p - 1)
        if n == "gamma":
            return s[0], s[0]
        if n == "gumbel_r":
            return _EULER, np.pi * np.pi / 6.0
        # invgauss; on a 1-element array, as scipy.stats: numpy's array power can differ from its scalar one
        return s[0], float((np.array([s[0]]) ** 3.0)[0])

    def ppf(self, q):
        """Quantile at ``q`` (scalar or array, in [0, 1]; nan outside)."""
        q = np.asarray(q, dtype=np.float64)
        inside = (q > 0) & (q < 1)
        with np.errstate(all="ignore"):
            x = self._ppf(np.where(inside, q, 0.5)) * self.scale + self.loc
        x = np.where(inside, x, np.where(q == 0, self._lower() * self.scale + self.loc,
                                         np.where(q == 1, np.inf, np.nan)))
        return x[()] if x.ndim == 0 else x

    def sf(self, x):
        """P(X > x), scalar or array."""
        z = np.asarray((np.asarray(x, dtype=np.float64) - self.loc) / self.scale, dtype=np.float64)
        inside = z > self._lower()
        with np.errstate(all="ignore"):
            p = np.where(inside, self._sf(np.where(inside, z, 1.0)), 1.0)
        p = np.where(np.isnan(z), np.nan, p)
        return p[()] if p.ndim == 0 else p

    def mean(self) -> float:
        m = self._moments()
        return np.float64(m[0] * self.scale + self.loc)

    def std(self) -> float:
        m = self._moments()
        return np.float64(np.sqrt(m[1] * self.scale * self.scale))


@functools.lru_cache(maxsize=256)
def body(family: str, mean: float, std: float) -> Frozen:
    """Frozen distribution of ``family`` with the given mean and std.

    The same arguments give the same (read-only) object, so its quantile
    table (:func:`ppf_table`) is made once per process.
    """
    if std <= 0:
        raise ValueError(f"std must be > 0, got {std}")
    if family in POSITIVE_FAMILIES and mean <= 0:
        raise ValueError(f"{family} needs a mean > 0, got {mean}")
    if family == "logistic":
        return Frozen("logistic", loc=mean, scale=std * math.sqrt(3) / math.pi)
    if family == "inverse_gaussian":
        lam = mean**3 / std**2
        return Frozen("invgauss", (mean / lam,), scale=lam)
    if family == "lognormal":
        s2 = math.log1p(std**2 / mean**2)
        return Frozen("lognorm", (math.sqrt(s2),), scale=math.exp(math.log(mean) - s2 / 2))
    if family == "normal":
        return Frozen("norm", loc=mean, scale=std)
    if family == "gamma":
        return Frozen("gamma", (mean**2 / std**2,), scale=std**2 / mean)
    raise ValueError(f"unknown family {family!r}; use one of {FAMILIES}")


def gumbel(loc: float, scale: float) -> Frozen:
    """The Fisher-Tippett-Gumbel distribution of the maximum, scipy's ``gumbel_r(loc, scale)``.

    Parameters
    ----------
    loc, scale : float
        Location and scale, in the unit of the values (e- rms for the noise sigmas).

    Returns
    -------
    Frozen
        With the interface of a frozen :mod:`scipy.stats` distribution.
    """
    return Frozen("gumbel_r", loc=loc, scale=scale)


_LOGIT_GRID = np.linspace(-30.0, 30.0, 8193)
#: that grid as the fixed maps read it (cmosnoise.engine.fixed_maps.ppf_cell): (first node, step, last node's index)
LOGIT_GRID = (float(_LOGIT_GRID[0]), float(_LOGIT_GRID[1] - _LOGIT_GRID[0]), len(_LOGIT_GRID) - 1)


def ppf_table(dist) -> np.ndarray:
    """``dist.ppf`` on 8193 quantiles evenly spaced in ``logit(q)`` (from 1e-13 to 1 - 1e-13), float64, made once
    per distribution (it is frozen: its table never changes).

    The fixed maps interpolate it linearly in logit space
    (:func:`cmosnoise.engine.fixed_maps.ppf_cell`): relative error below 1e-6 for these families, where some
    scipy ppfs (the inverse Gaussian's) take seconds per million values.

    Parameters
    ----------
    dist : Frozen or frozen scipy.stats distribution
        The distribution (:func:`body`, :func:`gumbel`).

    Returns
    -------
    (8193,) float64 array
        The quantiles, in the distribution's unit.
    """
    xg = getattr(dist, "_cmosnoise_ppf_table", None)
    if xg is None:
        xg = np.asarray(dist.ppf(special.expit(_LOGIT_GRID)), np.float64)
        xg.flags.writeable = False
        dist._cmosnoise_ppf_table = xg
    return xg
