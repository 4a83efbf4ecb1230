"""Fitting the readout stages to a long dark stack: source follower, row noise, column noise and VFPN.

All in e- (the stack's DN divided by the system gain K).

**Source follower** (docs/model.md stage 6). Each pixel's temporal variance over
a stack of N frames, its own row and column means removed frame by frame,
is a scaled chi-square with N - 1 degrees of freedom::

    s2_i ~ v_i * chi2(N - 1) / (N - 1),   v_i = a_i + thermal^2 + sigma_i^2

where ``a_i`` is what is known per pixel (dark shot noise ``rate_i * t``,
the quantizer's 1/(12 K^2)) and ``sigma_i`` is the pixel's flicker sigma,
``max(gumbel_r(loc, scale), 0)`` plus, for a fraction f of the pixels,
``Uniform(0, tail_max)`` (docs/model.md section 4). The parameters (thermal,
loc, scale, f, tail_max) maximise the marginal likelihood of the observed
s2_i, the flicker sigma integrated out on a grid of v; the histogram of the
noisy s2_i itself is never fitted. Confidence intervals: from the outer
product of the pixels' scores (the information estimated from first
derivatives; :func:`_fit` says why not the sandwich).

**Column noise** (stage 8). Each column's mean over rows, less the
frame's mean, varies over frames with ``sigma_c^2 + v_pixel / rows``; the
same machinery fits sigma_c's ``gumbel_r`` (no floor, no tail).
**Row noise** (stage 7): the rows' means likewise give ``sigma_row^2``.
**VFPN and fixed row offsets**: the covariance of each column's (row's)
mean over two halves of the stack's mean image, white pixels masked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CmosnoiseError
from ..estimators import Z95, robust_centre

GRID = 600  #: at most this many bins of the variance grid


# ------------------------------------------------------------------ the flicker sigma's distribution
def sigma_cdf(s: np.ndarray, loc: float, scale: float, f: float = 0.0, tail_max: float = 0.0) -> np.ndarray:
    """CDF of ``S = max(gumbel_r(loc, scale), 0) + Bernoulli(f) * Uniform(0, tail_max)`` at ``s`` (e- rms).

    The tail part is closed form: with ``F_B`` the clipped Gumbel CDF,
    ``P(B + U <= s) = (J(s) - J(s - M)) / M``, ``J(x) = integral_0^x F_B``,
    and ``integral exp(-exp(-z)) dz`` is an exponential integral.
    """
    from scipy.special import exp1

    s = np.asarray(s, np.float64)

    def fb(x):
        with np.errstate(over="ignore"):  # exp(-exp(large)) is 0, as it should be
            return np.where(x >= 0, np.exp(-np.exp(-(x - loc) / scale)), 0.0)

    out = fb(s)
    if f > 0 and tail_max > 0:
        t0 = math.exp(min(loc / scale, 700.0))  # exp(-z(0)); past 700 its exponential integral is 0 anyway

        def J(x):
            xp = np.maximum(x, 0.0)
            z = -(xp - loc) / scale  # log t
            with np.errstate(over="ignore", under="ignore"):
                t = np.exp(z)
            # far above the body t underflows to 0, where E1(t) = -gamma - ln t + O(t): taken from z itself
            e1 = np.where(z < -700, -np.euler_gamma - z, exp1(np.where(z < -700, 1.0, t)))
            e0 = exp1(t0) if t0 < 700 else 0.0
            return np.where(x > 0, scale * (e1 - e0), 0.0)

        out = (1 - f) * out + f * (J(s) - J(s - tail_max)) / tail_max
    return np.clip(out, 0.0, 1.0)


def _gumbel_cdf_at_0(loc: float, scale: float) -> float:
    """P(gumbel_r(loc, scale) <= 0): the share of sigmas that ``max(., 0)`` puts at exactly 0."""
    z = loc / scale
    return math.exp(-math.exp(z)) if z < 700 else 0.0


def ppm_above(threshold: float, loc: float, scale: float, f: float, tail_max: float) -> float:
    """Parts per million of flicker sigmas above ``threshold`` (docs/model.md section 4's ppm)."""
    return float(1e6 * (1 - sigma_cdf(np.array([threshold]), loc, scale, f, tail_max)[0]))


# ------------------------------------------------------------------ the marginal likelihood on a grid of v
@dataclass
class VarianceFit:
    """Maximum-likelihood fit of per-unit sample variances (e-^2)."""

    names: list[str]
    value: np.ndarray
    cov: np.ndarray
    loglik: float
    n_units: int
    n_used: int
    theta: np.ndarray | None = None  #: the optimizer's parameters (internal scale)
    extra: dict | None = None  #: parameters whose value or interval is not the scores' (name -> value, ci95)

    def interval(self, name: str) -> tuple[float | None, list[float] | None]:
        """Value and 95 % interval of ``name``."""
        if self.extra and name in self.extra:
            return self.extra[name]["value"], self.extra[name]["ci95"]
        v, se = float(self.value[self.names.index(name)]), self.se(name)
        if not math.isfinite(se):
            return v, None
        if name.endswith("scale_e") and v > 0 and Z95 * se <= 3 * v:
            # a scale's estimate is skewed (its spread grows with it): the interval is symmetric in log(scale),
            # the parameter the fit searches. On 1000 fits of 256 Gumbel column sigmas it held the scale 95.0 %
            # of the time, against 93.8 % for the symmetric one. (A scale the data do not pin down, its
            # interval wider than 20 times itself in log, keeps the symmetric interval below.)
            return v, [v * math.exp(-Z95 * se / v), v * math.exp(Z95 * se / v)]
        return v, [max(v - Z95 * se, 0.0) if v >= 0 and not name.endswith("loc_e") else v - Z95 * se, v + Z95 * se]

    def se(self, name: str) -> float:
        i = self.names.index(name)
        c = self.cov[i, i]
        return math.sqrt(max(c, 0.0)) if math.isfinite(c) else math.nan


class _Grid:
    """Per-unit likelihood of s2 on a grid of the unknown part c of the variance (precomputed once)."""

    def __init__(self, s2: np.ndarray, a: np.ndarray, dof: int, weights: np.ndarray, c_max: float, c_min: float,
                 kappa4: np.ndarray | None = None, fraction: float = 0.12):
        # bins an eighth of the chi-square's relative width apart. The likelihood of each bin is taken at its
        # middle, an error of order step^2 that does not average out: at a quarter of the width it biased the
        # thermal floor up and the Gumbel location down by half a standard error (on exact chi-square
        # variances, 40 fits of 49 152 pixels); at an eighth by a quarter, and finer gains little.
        # (``fraction`` 0.25: the coarse grid the first, rough searches use to find the basin.)
        step = fraction * math.sqrt(2.0 / dof)
        inner = np.geomspace(c_min, c_max, int(min(max(math.ceil(math.log(c_max / c_min) / step), 60), GRID)))
        self.edges = np.concatenate([[0.0], inner])
        mids = np.concatenate([[inner[0] / 2], np.sqrt(inner[:-1] * inner[1:]), [inner[-1] * 1.5]])
        self.s2, self.a, self.dof, self.kappa4 = s2, a, dof, kappa4
        ll = self._loglik(mids[None, :])
        self.ll_max = ll.max(axis=1)
        L = np.exp(ll - self.ll_max[:, None])
        L[L < 1e-9] = 0.0  # each unit's likelihood is a narrow band of the grid: keep it sparse
        from scipy import sparse

        self.L = sparse.csr_matrix(L)
        self.weights = weights  #: how many pixels each unit stands for

    def _loglik(self, c: np.ndarray) -> np.ndarray:
        """Each unit's log-likelihood of its s2 when the unknown part of its variance is ``c`` (broadcast to
        (units, k)), up to a constant per unit."""
        s2, a, dof, kappa4 = self.s2[:, None], self.a[:, None], self.dof, self.kappa4
        v = a + c
        if kappa4 is None:
            nu = float(dof)
            return -0.5 * nu * np.log(v) - 0.5 * nu * s2 / v
        # noise that is not Gaussian (the quantizer's uniform error, Poisson dark charge) changes the spread
        # of a sample variance: var(s2) = 2 v^2 / (N - 1) + kappa4 / N (+ the known part's own variance).
        # A scaled chi-square with the degrees of freedom that give that spread keeps the likelihood right
        # to second order.
        frames = dof + 1
        nu = 2 * v * v / np.maximum(2 * v * v / dof + kappa4[:, None] / frames, 1e-3 * v * v / dof)
        x = nu * s2 / v
        from scipy.special import gammaln

        return (np.log(nu / v) + (0.5 * nu - 1) * np.log(np.maximum(x, 1e-300)) - 0.5 * x
                - 0.5 * nu * math.log(2) - gammaln(0.5 * nu))

    def at(self, c: float) -> np.ndarray:
        """Each unit's likelihood (on the grid's scale) when the unknown part is exactly ``c``."""
        return np.exp(self._loglik(np.array([[c]], np.float64))[:, 0] - self.ll_max)

    def bin_mass(self, cdf_c, top: float = 1.0) -> np.ndarray:
        F = cdf_c(self.edges)
        return np.diff(np.concatenate([F, [top]]))

    def per_unit(self, cdf_c, atom: tuple[float, float] | None = None) -> np.ndarray:
        """Each unit's log marginal likelihood under the distribution of the unknown part c.

        ``cdf_c`` is the CDF of c's continuous part; ``atom = (c0, mass)`` a
        point mass at c0 (sigmas clipped at 0 put one at the thermal floor, or
        at 0 for the columns). The atom is taken at c0 exactly: binned, it
        would jump from bin to bin as the floor moves, a step in the
        likelihood; left out of the bins' masses, as the column fit once had
        it, the likelihood is not normalised. Below 1e-12 (a Gumbel body
        well above 0) it is left out, which changes nothing measurable.
        """
        if atom is None or atom[1] < 1e-12:
            return np.log(np.maximum(self.L @ self.bin_mass(cdf_c, 1.0 if atom is None else 1.0 - atom[1]), 1e-300))
        c0, mass = atom
        return np.log(np.maximum(self.L @ self.bin_mass(cdf_c, 1.0 - mass) + mass * self.at(c0), 1e-300))


def _fit(grid: _Grid, unpack, theta0: list[np.ndarray], names: list[str], natural, coarse: _Grid | None = None
         ) -> VarianceFit:
    """Nelder-Mead on the weighted log-likelihood, from several starts; covariance of ``natural(theta)`` from the scores.

    The rough searches from the starts run on ``coarse`` (a grid half as fine, half the cost) where given; the
    best of them is polished, and the interval taken, on ``grid``.
    """
    from scipy import optimize

    def total_on(g):
        def total(theta):
            model = unpack(theta)
            if model is None:
                return 1e300
            return -float(np.sum(g.weights * g.per_unit(*model)))
        return total

    total = total_on(grid)
    rough = total_on(coarse) if coarse is not None and len(theta0) > 1 else total
    best = None
    # a rough search from each start, then the best one polished. 150 steps only pick the basin: with 300,
    # 180 round-trip fits (benchmarks/fit_coverage.py) gave the same coverage and the same mean z to 0.01
    for t0 in theta0:
        res = optimize.minimize(rough, t0, method="Nelder-Mead",
                                options={"xatol": 1e-3, "fatol": 1e-1, "maxfev": 150 if len(theta0) > 1 else 4000})
        if best is None or res.fun < best.fun:
            best = res
    if len(theta0) > 1:
        best = optimize.minimize(total, best.x, method="Nelder-Mead",
                                 options={"xatol": 1e-5, "fatol": 1e-4, "maxiter": 4000, "maxfev": 4000})
    theta = best.x
    k = theta.size
    h = 1e-4 * np.maximum(1.0, np.abs(theta))
    # per-unit scores by central differences; the covariance is the inverse of their outer product (the
    # information's estimate from first derivatives, BHHH). Not the sandwich H^-1 B H^-1: the floor and the
    # flicker body's location and scale are nearly collinear (the data pin down their sum far better than
    # each), so H^-1 comes from a nearly singular Hessian, and second differences see the likelihood's
    # roughness at the scale of its grid. In one fit in twelve of a hot sensor the sandwich gave the floor a
    # standard error of 0.0014 e- where the estimates' spread over seeds is 0.03 e-; the scores' outer
    # product gives 0.03 in every fit, for Gaussian and Poisson data alike
    # (``python benchmarks/bias_source_follower.py --known --poisson``).
    scores = np.empty((grid.weights.size, k))
    for j in range(k):
        e = np.zeros(k); e[j] = h[j]  # noqa: E702
        up, dn = unpack(theta + e), unpack(theta - e)
        scores[:, j] = (grid.per_unit(*up) - grid.per_unit(*dn)) / (2 * h[j])
    B = (scores * grid.weights[:, None]).T @ scores  # sum over pixels of score score^T (a unit's pixels share one)
    try:  # where the likelihood is flat in some direction, no interval can be given
        np.linalg.cholesky(B)
        cov_theta = np.linalg.inv(B)
    except np.linalg.LinAlgError:
        cov_theta = np.full((k, k), np.nan)
    # the natural parameters and their covariance by the delta method
    value = np.asarray(natural(theta), np.float64)
    J = np.empty((value.size, k))
    for j in range(k):
        e = np.zeros(k); e[j] = h[j]  # noqa: E702
        J[:, j] = (np.asarray(natural(theta + e)) - np.asarray(natural(theta - e))) / (2 * h[j])
    return VarianceFit(names, value, J @ cov_theta @ J.T, -float(best.fun), int(round(grid.weights.sum())), grid.weights.size,
                       theta=theta)


def _aggregate(s2: np.ndarray, a: np.ndarray, scale: float, k4: np.ndarray | None, dof: int):
    """Pixels with (nearly) the same variance and known part as one unit: its mean values and its pixel count.

    Pixels whose variances, and whose known parts (plus a tenth of ``scale``),
    agree to a tenth of the chi-square's relative width ``sqrt(2 / dof)``
    give the same likelihood to well within that width: the error of using
    the unit's means is of the order of (1/10)^2 / 12 of it, and it averages
    out. So every pixel counts, and the likelihood costs what a few thousand
    units cost, even where a large dark shot noise makes every pixel's known
    part different.
    """
    step = 0.1 * math.sqrt(2.0 / dof)
    k_s2 = np.log(np.maximum(s2, 1e-30)) / step
    k_a = np.log(np.maximum(a, 0.0) + 0.1 * scale) / step
    keys = np.stack([np.round(k_s2), np.round(k_a)], axis=1)
    _, inv, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    k4u = None if k4 is None else np.bincount(inv, k4) / counts
    return np.bincount(inv, s2) / counts, np.bincount(inv, a) / counts, counts.astype(np.float64), k4u


def _clipped(theta: np.ndarray) -> np.ndarray:
    """The parameter vector inside what exp can take (log scale, logit f, log max within +-14, +-30, +-14)."""
    t = np.array(theta, np.float64)
    lim = [math.inf, math.inf, 14.0, 30.0, 14.0][: t.size]
    return np.clip(t, -np.array(lim), np.array(lim))


def fit_source_follower(s2: np.ndarray, known: np.ndarray, frames: int, threshold_e: float | None, seed: int = 0,
                        with_tail: bool = True, kappa4: np.ndarray | None = None,
                        known_var: np.ndarray | None = None) -> dict:
    """Thermal floor and flicker sigma distribution from per-pixel variances (e-^2), see the module docstring.

    ``s2``: per-pixel temporal variances (e-^2, ddof 1) over ``frames`` frames;
    ``known``: the known part of each pixel's variance (e-^2), same shape;
    ``kappa4``: the known fourth cumulant of each pixel's noise (e-^4; the
    quantizer's ``-1.2 q^2``, the dark charge's Poisson mean), or None for Gaussian noise;
    ``known_var``: the variance of ``known``'s own estimate (e-^4; a dark shot
    noise from a measured rate map is itself uncertain), or None.
    ``threshold_e``: the flicker-tail threshold for the reported ppm.
    Returns ``{name: (value, se)}`` for thermal_sigma_e, gumbel_loc_e,
    gumbel_scale_e and (with the tail) tail_ppm_above, tail_max_e, plus
    ``loglik`` and the pixel counts.
    """
    s2 = np.asarray(s2, np.float64).ravel()
    a = np.broadcast_to(np.asarray(known, np.float64).ravel(), s2.shape) if np.size(known) in (1, s2.size) else None
    if a is None:
        raise CmosnoiseError(f"source follower: {np.size(known)} known variances for {s2.size} pixels")
    if frames < 4:
        raise CmosnoiseError(f"source follower: a dark stack of {frames} frames; per-pixel variances need at least 4 (50 to 100 recommended)")
    c = s2 - a
    med = float(np.median(s2))
    k4 = None if kappa4 is None else np.broadcast_to(np.asarray(kappa4, np.float64).ravel(), s2.shape)
    if known_var is not None:
        extra = frames * np.broadcast_to(np.asarray(known_var, np.float64).ravel(), s2.shape)
        k4 = extra if k4 is None else k4 + extra
    su, au, counts, k4u = _aggregate(s2, a, med, k4, frames - 1)
    limits = dict(c_max=max(float(c.max()) * 3, med * 4), c_min=1e-3 * med, kappa4=k4u)
    grid = _Grid(su, au, frames - 1, counts, **limits)
    coarse = _Grid(su, au, frames - 1, counts, fraction=0.25, **limits)
    # starts: the floor from the low quantiles, the body from what is left
    c_pos = np.maximum(c, 0)
    starts = []
    for frac in (0.9, 0.5, 0.1):
        th2 = frac * float(np.quantile(c_pos, 0.02))
        sig = np.sqrt(np.maximum(c_pos - th2, 0))
        body = sig[sig <= np.quantile(sig, 0.995)]
        scale = max(float(body.std()) * math.sqrt(6) / math.pi, 1e-3)
        loc = float(np.median(body)) - 0.3665 * scale
        t = [math.sqrt(th2), loc, math.log(scale)]
        if with_tail:
            t += [math.log(1e-4 / (1 - 1e-4)), math.log(max(4 * float(np.sqrt(c_pos.max())), 1e-3))]
        starts.append(np.array(t))

    def unpack(theta):
        theta = _clipped(theta)
        th, loc, scale = abs(theta[0]), theta[1], math.exp(theta[2])
        f, M = (1 / (1 + math.exp(-theta[3])), math.exp(theta[4])) if with_tail else (0.0, 0.0)

        atom = (1 - f) * _gumbel_cdf_at_0(loc, scale)  # the sigmas clipped at 0: c exactly thermal^2

        def cdf_c(x):  # c's continuous part
            d = x - th * th
            return np.where(d >= 0, sigma_cdf(np.sqrt(np.maximum(d, 0)), loc, scale, f, M) - atom, 0.0)
        return cdf_c, (th * th, atom)

    thr = threshold_e if threshold_e is not None else math.inf

    def natural(theta):
        theta = _clipped(theta)
        th, loc, scale = abs(theta[0]), theta[1], math.exp(theta[2])
        out = [th, loc, scale]
        if with_tail:
            f, M = 1 / (1 + math.exp(-theta[3])), math.exp(theta[4])
            out += [ppm_above(thr, loc, scale, f, M) if math.isfinite(thr) else f * 1e6, M]
        return out

    names = ["thermal_sigma_e", "gumbel_loc_e", "gumbel_scale_e"] + (["tail_ppm_above", "tail_max_e"] if with_tail else [])
    r = _fit(grid, unpack, starts, names, natural, coarse)
    if with_tail and s2.size / (1 + math.exp(-float(_clipped(r.theta)[3]))) < 0.5:
        # not one tail pixel: no tail can be fitted; the body alone, the tail's ppm bounded from above
        body = fit_source_follower(s2, known, frames, threshold_e, seed, with_tail=False, kappa4=kappa4,
                                   known_var=known_var)
        b = body["fit"]
        loc, scale = float(b.value[1]), float(b.value[2])
        own = ppm_above(thr, loc, scale, 0.0, 0.0) if math.isfinite(thr) else 0.0
        b.extra = {"tail_ppm_above": {"value": own, "ci95": [0.0, own + 3e6 / s2.size], "tail_pixels": 0},
                   "tail_max_e": {"value": None, "ci95": None, "tail_pixels": 0}}
        body["no_tail"] = True
        return body  # its tail_fraction is 0
    if with_tail:
        # the tail's maximum is the end point of a uniform: its estimate sits near the largest of the n tail
        # pixels' values, below the truth by about max / (n + 1); the interval is the order statistic's
        # (the truth is below max * 0.025^(-1 / n) with 97.5 % probability) widened by the blur of the variances
        i, j = names.index("tail_max_e"), names.index("tail_ppm_above")
        n_tail = max(r.value[j] * 1e-6 * s2.size, 1.0)
        # a few tail pixels: the count's own (Poisson, Garwood) interval where it is wider than the scores'
        from scipy import stats

        ppm, ci = r.interval("tail_ppm_above")
        lo, hi = ci if ci is not None else (math.inf, -math.inf)
        g_lo = stats.chi2.ppf(0.025, 2 * n_tail) / 2 / s2.size * 1e6
        g_hi = stats.chi2.ppf(0.975, 2 * n_tail + 2) / 2 / s2.size * 1e6
        m_hat, se = float(r.value[i]), r.se("tail_max_e")
        r.extra = {"tail_max_e": {"value": m_hat * (n_tail + 1) / n_tail,
                                  "ci95": [m_hat - Z95 * se, m_hat * 0.025 ** (-1 / n_tail) + Z95 * se],
                                  "tail_pixels": n_tail},
                   "tail_ppm_above": {"value": ppm, "ci95": [min(lo, g_lo), max(hi, g_hi)], "tail_pixels": n_tail}}
    t = _clipped(r.theta)
    tail_f, tail_m = (1 / (1 + math.exp(-t[3])), math.exp(t[4])) if with_tail else (0.0, 0.0)
    return {"fit": r, "pixels": int(s2.size), "pixels_used": r.n_used, "tail_fraction": tail_f, "tail_max": tail_m}


def fit_column_sigma(s2: np.ndarray, known: float, frames: int) -> VarianceFit:
    """The per-column temporal sigma's ``gumbel_r`` (clipped at 0) from each column's variance (e-^2) over frames."""
    s2 = np.asarray(s2, np.float64).ravel()
    a = np.full(s2.size, float(known))
    c = np.maximum(s2 - a, 0)
    med = float(np.median(s2))
    grid = _Grid(s2, a, frames - 1, np.ones(s2.size), c_max=max(float(c.max()) * 3, med * 4), c_min=1e-3 * med)
    sig = np.sqrt(c)
    scale = max(float(sig.std()) * math.sqrt(6) / math.pi, 1e-3)
    starts = [np.array([float(np.median(sig)) - 0.3665 * scale, math.log(scale)])]

    def unpack(theta):
        loc, scale = theta[0], math.exp(min(max(theta[1], -14.0), 14.0))
        atom = _gumbel_cdf_at_0(loc, scale)  # columns whose sigma is clipped at 0
        return (lambda x: sigma_cdf(np.sqrt(x), loc, scale) - atom), (0.0, atom)

    return _fit(grid, unpack, starts, ["gumbel_loc_e", "gumbel_scale_e"], lambda t: [t[0], math.exp(t[1])])


# ------------------------------------------------------------------ row and column statistics of a stack
def centred_series(means: np.ndarray) -> np.ndarray:
    """A (frames, units) series of row or column means less each unit's temporal mean and each frame's mean."""
    x = np.asarray(means, np.float64)
    x = x - x.mean(axis=0, keepdims=True)
    return x - x.mean(axis=1, keepdims=True)


def sigma_from_variance(var: float, se: float) -> dict:
    """A sigma from a variance estimate and its standard error: value and 95 % interval (clipped at 0)."""
    lo, hi = var - Z95 * se, var + Z95 * se
    return {"value": math.sqrt(max(var, 0.0)), "ci95": [math.sqrt(max(lo, 0.0)), math.sqrt(max(hi, 0.0))]}


def robust_mask(image: np.ndarray, k: float = 5.0) -> np.ndarray:
    """Pixels within ``k`` robust standard deviations of the median (white and dead pixels out)."""
    med, sigma = robust_centre(image)
    return np.abs(image - med) <= k * (sigma or 1e-12)


def split_half_covariance(image: np.ndarray, mask: np.ndarray, axis: str) -> tuple[float, float]:
    """Variance of what is common to a column (``axis="col"``) or row, by the covariance of two halves' means.

    Each column's mean over the top half of the rows and over the bottom
    half: a column offset or gain is in both, a pixel's own deviation (even
    when crosstalk makes neighbours alike) in only one, so their covariance
    over the columns is the column part's variance alone; even and odd
    columns are centred apart (a CFA cell's black level alternates them).
    Returns the covariance and its standard error.
    """
    img = image if axis == "col" else image.T
    m = mask if axis == "col" else mask.T
    h = img.shape[0] // 2

    def means(a, k):
        return np.where(k, a, 0).sum(axis=0) / np.maximum(k.sum(axis=0), 1)

    x, y = means(img[:h], m[:h]), means(img[h:], m[h:])
    n = x.size
    # each centred on its even and on its odd columns (rows) apart: a black level per CFA cell position makes
    # them alternate, which is not a column's (row's) own offset; two means fitted, so n - 2 degrees of freedom
    for a in (x, y):
        a[0::2] -= a[0::2].mean()
        a[1::2] -= a[1::2].mean()
    c = float(np.sum(x * y)) / (n - 2)
    se = math.sqrt((float(np.sum(x * x)) / (n - 2) * float(np.sum(y * y)) / (n - 2) + c * c) / (n - 2))
    return c, se


def residual_variance(image: np.ndarray, mask: np.ndarray) -> float:
    """Variance of a (rows, cols) image's pixels about their row and column means (masked pixels left out),
    corrected for the fitted means' degrees of freedom."""
    m = mask.astype(np.float64)
    x = np.where(mask, image, 0.0)
    col = x.sum(axis=0) / np.maximum(m.sum(axis=0), 1)
    row = x.sum(axis=1) / np.maximum(m.sum(axis=1), 1)
    g = float(x.sum() / m.sum())
    resid = (image - row[:, None] - col[None, :] + g)[mask]
    rows, cols = image.shape
    return float(np.var(resid)) * rows * cols / ((rows - 1) * (cols - 1))


def tukey_lambda_kurtosis(lam: float) -> float:
    """Excess kurtosis of the Tukey-lambda law (scale-free); decreasing in ``lam`` over (-0.25, 0.9)."""
    from scipy import stats

    return float(stats.tukeylambda(lam).stats(moments="k"))


def read_noise_shape(pixel_var: np.ndarray, pixel_m4: np.ndarray, n: int, common_var: float,
                     known_k4: np.ndarray | float = 0.0, shrink: float = 1.0) -> dict | None:
    """The shape of the noise common to every pixel (the read noise) from the pixels' fourth moments.

    Each pixel's frames (row and column means taken out) have variance
    ``V_i`` and fourth cumulant ``k4`` (the common noise's, plus ``known_k4``:
    the dark charge's Poisson ``mean`` and the quantizer's ``-1/120`` DN^4).
    Over ``n`` frames the fourth central moment ``m4`` (ddof 0) and the
    squared variance ``s4`` (ddof 1) have expectations linear in ``V_i**2``
    and ``k4``::

        E m4 = a (3 V^2 + k4) + b V^2,  a = (n-1)(n^2-3n+3)/n^3,  b = 3(2n-3)(n-1)/n^3
        E s4 = V^2 + (3 V^2 + k4)/n - V^2 (n-3)/(n(n-1))

    so each pixel gives an unbiased ``k4`` estimate. Where the frames had
    their row and column means taken out, a pixel keeps ``shrink = (1 - 1/cols)
    (1 - 1/rows)`` of its own value: of its variance ``shrink``, of its fourth
    cumulant ``shrink**4`` (the other pixels' shares are of order 1/cols^3),
    so the estimate is divided by ``shrink**4``. Their mean over the
    pixels (standard error from their spread) divided by the common noise's
    variance squared is its excess kurtosis; the Tukey-lambda shape with that
    kurtosis is the fitted ``lam`` (ELD models the read noise so).

    Returns ``{"kurtosis": (value, ci95), "lam": (value, ci95), "k4": ...}``
    or None when the common variance is too small to judge.
    """
    from scipy.optimize import brentq

    if common_var <= 0 or n < 8:
        return None
    s4 = np.asarray(pixel_var, np.float64) ** 2
    m4 = np.asarray(pixel_m4, np.float64)
    a = (n - 1) * (n * n - 3 * n + 3) / n**3
    b = 3 * (2 * n - 3) * (n - 1) / n**3
    # solve per pixel: m4 = (3a + b) V2 + a k4 ; s4 = (1 + 3/n - (n-3)/(n(n-1))) V2 + k4 / n
    c = 1 + 3 / n - (n - 3) / (n * (n - 1))
    det = (3 * a + b) / n - a * c
    k4_i = ((3 * a + b) * s4 - c * m4) / det / shrink**4 - known_k4
    k4 = float(np.mean(k4_i))
    se = float(np.std(k4_i, ddof=1)) / math.sqrt(k4_i.size)
    kurt = k4 / common_var**2
    kse = se / common_var**2
    lo_k, hi_k = kurt - Z95 * kse, kurt + Z95 * kse
    top, bottom = tukey_lambda_kurtosis(-0.24), tukey_lambda_kurtosis(0.9)

    def shape(kv):
        kv = min(max(kv, bottom + 1e-9), top - 1e-9)
        return float(brentq(lambda lam: tukey_lambda_kurtosis(lam) - kv, -0.24, 0.9, xtol=1e-10))

    return {"kurtosis": (kurt, [lo_k, hi_k]), "lam": (shape(kurt), [shape(hi_k), shape(lo_k)]), "k4": (k4, se)}


def own_share(rows: int, cols: int) -> float:
    """What a pixel keeps of its own value when each frame has its row and column means taken out:
    ``(1 - 1/cols)(1 - 1/rows)``, the diagonal of that projection; so of its variance too (the variance of the
    residual is this times the pixel's)."""
    return (1 - 1 / cols) * (1 - 1 / rows)


def pixel_noise_shape(pixel_var: np.ndarray, pixel_m4: np.ndarray, n: int, known_var: np.ndarray | float,
                      known_k4: np.ndarray | float, shrink: float = 1.0) -> dict | None:
    """Whether the pixels' temporal noise (DN, their frames less the row and column means) is Tukey-lambda read
    noise they share, and its shape and scale.

    The pixels' mean variance less what is known not to be the read noise
    (``known_var``: the dark charge's shot noise, the quantizer's) is the
    shared noise's (``common``: a median
    would be low, a sample variance being skewed; white and noisy pixels out
    beyond 10 robust sigmas) is the shared noise's; :func:`read_noise_shape`
    gives its kurtosis and shape. ``spread`` is how far the pixels' own
    variances spread beyond what ``n`` frames of a noise of that kurtosis
    leave, ``var(s^2) = V^2 (kurt / n + 2 / (n - 1))``, relative to ``common``:
    a flicker-like spread says the noise is not one shared law.

    Returns ``read_noise_shape``'s dict plus ``common_dn2`` (value, standard
    error), ``spread`` and ``scale_dn`` (value, 95 % interval: from the
    shape's interval and the common variance's), or None.
    """
    from ..model.stages.read_noise import tukey_lambda_variance

    v_i = pixel_var / shrink - known_var  # the frames' row and column means took (1 - shrink) of each variance
    med, rob = robust_centre(v_i)
    kept = v_i[v_i <= med + 10 * rob]
    common = float(np.mean(kept))
    common_se = float(np.std(kept, ddof=1)) / math.sqrt(kept.size)
    shp = read_noise_shape(pixel_var, pixel_m4, n, common, known_k4, shrink)
    if shp is None:
        return None
    (kurt, _), (lam, (lam_lo, lam_hi)) = shp["kurtosis"], shp["lam"]
    sampling = common**2 * (max(kurt, 0.0) / n + 2 / (n - 1))
    spread = math.sqrt(max(float(np.var(v_i)) - sampling, 0.0)) / max(common, 1e-12)
    # the scale gives the common variance: s = sqrt(common / var(lam)); var(lam) falls as lam rises, so the
    # interval's ends are the shape's ends with the common variance's own ends
    scale = math.sqrt(common / tukey_lambda_variance(lam))
    lo = math.sqrt(max(common - Z95 * common_se, 0.0) / tukey_lambda_variance(lam_lo))
    hi = math.sqrt((common + Z95 * common_se) / tukey_lambda_variance(lam_hi))
    return {**shp, "common_dn2": (common, common_se), "spread": spread, "scale_dn": (scale, [lo, hi])}


def frame_error_variance(row_means: np.ndarray, col_means: np.ndarray, pixel_var: float,
                         row_ratio: float | None = None) -> tuple[float, float]:
    """The variance of the black level's error per frame (DN^2) and its standard error, from a dark stack's row
    means (frames, rows), column means (frames, cols) and mean pixel temporal variance.

    A frame's mean is its error plus the means of its rows' and columns'
    temporal noise and of its pixels': ``var(fm) = e^2 + rho^2/rows + gamma^2/cols
    + p/(rows cols)``. The rows' means about the frame's spread by
    ``(rho^2 + p/cols)(1 - 1/rows)``, the columns' by ``(gamma^2 + p/rows)(1 - 1/cols)``,
    which leaves ``e^2 = var(fm) - vr/(rows - 1) - vc/(cols - 1) + p/(rows cols)``;
    its standard error is that of a variance over the frames, ``var(fm) sqrt(2/(n - 1))``. A row noise with
    a 1/f spectrum in readout order puts more into the frame means than ``vr / (rows - 1)``: ``row_ratio``
    replaces ``1 / (rows - 1)`` (:func:`.noise_spectrum.frame_mean_ratio_rows`).
    """
    n, rows = row_means.shape
    cols = col_means.shape[1]
    fm = row_means.mean(axis=1)
    vr = float(np.mean((row_means - fm[:, None]).var(axis=0, ddof=1)))
    vc = float(np.mean((col_means - fm[:, None]).var(axis=0, ddof=1)))
    v_fm = float(np.var(fm, ddof=1))
    ratio = 1.0 / (rows - 1) if row_ratio is None else float(row_ratio)
    pixels_in_rows = pixel_var / cols * (1 - 1 / rows)  # white: its share of the frame means is 1 / (rows - 1)
    rows_part = (vr - pixels_in_rows) * ratio + pixels_in_rows / (rows - 1)
    return v_fm - rows_part - vc / (cols - 1) + pixel_var / (rows * cols), v_fm * math.sqrt(2 / (n - 1))
