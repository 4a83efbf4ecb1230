"""Fitting the dark-current stage (docs/model.md section 3): the rate map's body family, its white-pixel tail, doubling.

The paper chose each temperature's dark-current distribution by fitting
candidate families to the measured histogram and ranking them by
log-likelihood. Here every family of docs/model.md section 3 is fitted by maximum
likelihood to the pixels below the white-pixel threshold, the likelihood
truncated there (the tail is a separate population): each candidate gets
its mean, std, log-likelihood and AIC, and the lowest AIC is chosen. The
tail is the fraction of pixels above the threshold (ppm) and its largest
excess over the body.

A rate map from frames is the per-pixel slope of the dark signal over
exposure time (:func:`rate_map_from_stacks`); with maps at two or more
temperatures, :func:`doubling` and :func:`tail_doubling` give how fast the
body and the white-pixel tail grow with temperature.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CmosnoiseError
from ..estimators import Z95, robust_centre
from ..model.distributions import FAMILIES, POSITIVE_FAMILIES, body
from .fit_readout import own_share

#: pixels used for the family fits (a fixed random subset: the ranking is clear long before all 300 000)
FIT_PIXELS = 50_000


@dataclass(frozen=True)
class FamilyFit:
    """One candidate family's maximum-likelihood fit to the body (e-/s)."""

    family: str
    mean: float
    std: float
    loglik: float
    aic: float
    n: int


class TruncatedLikelihood:
    """Log-likelihood of each family for values ``x`` all below ``threshold``, the density truncated there.

    ``loglik(family, mean, std)`` equals ``sum(body(family, mean, std).logpdf(x))
    - x.size * body(...).logcdf(threshold)`` (:mod:`scipy.stats`, the reference
    the tests hold it to), computed from the data's sufficient statistics: the
    normal, lognormal, gamma and inverse Gaussian cost a few operations per
    call whatever the pixel count; only the logistic, which has none, passes
    over the values. A fit calls it some seventy times per family.
    """

    def __init__(self, x: np.ndarray, threshold: float = math.inf):
        x = np.asarray(x, np.float64).ravel()
        self.x, self.n, self.threshold = x, x.size, float(threshold)
        self.mean_x = float(x.mean())
        self.ss_x = float(np.sum((x - self.mean_x) ** 2))  # centred: no cancellation against n mean^2
        self.positive = bool(np.all(x > 0))
        if self.positive:
            lx = np.log(x)
            self.sum_log = float(lx.sum())
            self.mean_log = self.sum_log / self.n
            self.ss_log = float(np.sum((lx - self.mean_log) ** 2))
            self.sum_inv = float(np.sum(1.0 / x))

    def loglik(self, family: str, mean: float, std: float) -> float:
        from scipy import special

        n, thr, half_log_2pi = self.n, self.threshold, 0.5 * math.log(2 * math.pi)
        if not (std > 0 and math.isfinite(mean) and math.isfinite(std)):
            return -math.inf
        if family in POSITIVE_FAMILIES and (mean <= 0 or not self.positive):
            return -math.inf
        finite = math.isfinite(thr)
        with np.errstate(all="ignore"):
            if family == "normal":
                ll = -n * (half_log_2pi + math.log(std)) - (self.ss_x + n * (self.mean_x - mean) ** 2) / (2 * std * std)
                norm = float(special.log_ndtr((thr - mean) / std)) if finite else 0.0
            elif family == "logistic":
                b = std * math.sqrt(3) / math.pi
                z = np.abs(self.x - mean) / b
                ll = -float(np.sum(z + 2 * np.log1p(np.exp(-z)))) - n * math.log(b)
                norm = -float(np.logaddexp(0.0, -(thr - mean) / b)) if finite else 0.0
            elif family == "lognormal":
                s2 = math.log1p(std**2 / mean**2)
                mu, sig = math.log(mean) - s2 / 2, math.sqrt(s2)
                ll = (-self.sum_log - n * (half_log_2pi + math.log(sig))
                      - (self.ss_log + n * (self.mean_log - mu) ** 2) / (2 * s2))
                norm = float(special.log_ndtr((math.log(thr) - mu) / sig)) if finite and thr > 0 else 0.0
            elif family == "gamma":
                a, theta = mean**2 / std**2, std**2 / mean
                ll = (a - 1) * self.sum_log - n * self.mean_x / theta - n * (float(special.gammaln(a)) + a * math.log(theta))
                norm = math.log(float(special.gammainc(a, thr / theta))) if finite else 0.0
            elif family == "inverse_gaussian":
                lam = mean**3 / std**2
                ll = (0.5 * n * math.log(lam) - n * half_log_2pi - 1.5 * self.sum_log
                      - lam / (2 * mean * mean) * (n * self.mean_x - 2 * n * mean + mean * mean * self.sum_inv))
                if finite:
                    r = math.sqrt(lam / thr)
                    norm = float(np.logaddexp(special.log_ndtr(r * (thr / mean - 1)),
                                              2 * lam / mean + special.log_ndtr(-r * (thr / mean + 1))))
                else:
                    norm = 0.0
            else:
                raise ValueError(f"unknown family {family!r}; use one of {FAMILIES}")
        value = ll - n * norm
        return value if math.isfinite(value) else -math.inf


def fit_family(family: str, x: np.ndarray | TruncatedLikelihood, threshold: float = math.inf) -> FamilyFit:
    """Maximum-likelihood mean and std of ``family`` for the values ``x`` (all below ``threshold``, the truncation).

    ``x`` may be a :class:`TruncatedLikelihood` already made (its threshold is then used).
    """
    from scipy import optimize

    like = x if isinstance(x, TruncatedLikelihood) else TruncatedLikelihood(x, threshold)
    m0, s0 = like.mean_x, math.sqrt(like.ss_x / like.n) or 1.0
    if family in POSITIVE_FAMILIES and m0 <= 0:
        return FamilyFit(family, math.nan, math.nan, -math.inf, math.inf, like.n)

    def neg(theta):
        mean, std = theta[0], math.exp(theta[1])
        if family in POSITIVE_FAMILIES and mean <= 0:
            return 1e300
        v = like.loglik(family, mean, std)
        return -v if math.isfinite(v) else 1e300

    res = optimize.minimize(neg, [m0, math.log(s0)], method="Nelder-Mead",
                            options={"xatol": 1e-6 * max(abs(m0), 1.0), "fatol": 1e-3, "maxiter": 600})
    mean, std = float(res.x[0]), math.exp(float(res.x[1]))
    ll = -float(res.fun) if res.fun < 1e299 else -math.inf
    return FamilyFit(family, mean, std, ll, 2 * 2 - 2 * ll, like.n)


def select_family(rates: np.ndarray, threshold: float | None = None, seed: int = 0) -> list[FamilyFit]:
    """Every family of docs/model.md fitted to the body of a dark-rate map (e-/s), best (lowest AIC) first.

    Pixels at or above ``threshold`` (the white-pixel tail) are left out and
    the likelihood is truncated there; without a threshold every pixel is
    the body. At most FIT_PIXELS pixels, a fixed random subset, are used.
    """
    x = np.asarray(rates, np.float64).ravel()
    x = x[np.isfinite(x)]
    thr = math.inf if threshold is None else float(threshold)
    x = x[x < thr]
    if x.size < 100:
        raise CmosnoiseError(f"dark-current family: {x.size} pixels below the threshold; a fit needs at least 100")
    if x.size > FIT_PIXELS:
        x = np.random.default_rng(seed).choice(x, FIT_PIXELS, replace=False)
    like = TruncatedLikelihood(x, thr)
    fits = [fit_family(f, like) for f in FAMILIES]
    return sorted(fits, key=lambda f: f.aic)


def tail(rates: np.ndarray, threshold: float, body_fit: FamilyFit) -> dict:
    """The white-pixel tail: ppm of pixels above ``threshold`` and the largest excess over the body's mean (e-/s)."""
    x = np.asarray(rates, np.float64).ravel()
    above = x > threshold
    return {"ppm_above": float(above.mean() * 1e6), "threshold_e_per_s": float(threshold),
            "max_e_per_s": float(max(x.max() - body_fit.mean, 0.0)) if above.any() else 0.0,
            "pixels_above": int(above.sum())}


def rate_map_from_stacks(means_dn: list[np.ndarray], exposures_s: list[float], gain_dn_per_e: float,
                         limit_dn: float | None = None) -> np.ndarray:
    """Per-pixel dark current (e-/s): the least-squares slope of the mean dark signal over exposure time.

    ``means_dn`` are per-pixel means of dark stacks (DN) at ``exposures_s``
    (at least two distinct times); the black level and any fixed offset fall
    into the intercept. With ``limit_dn``, each pixel's slope uses only the
    exposure times where its mean is below that (a white pixel that clips at
    the long exposures is measured on the short ones); a pixel below it at
    fewer than two times gets the slope from its shortest time and the
    intercept of the others (at least: it is that bright).
    """
    t = np.asarray(exposures_s, np.float64)
    if len(means_dn) != t.size or len(set(np.round(t, 12))) < 2:
        raise CmosnoiseError("dark current: needs dark stacks at two or more distinct exposure times")
    shapes = {m.shape for m in means_dn}
    if len(shapes) != 1:
        raise CmosnoiseError(f"dark current: the dark stacks have different sizes {sorted(shapes)}")
    if limit_dn is None:
        tc = t - t.mean()
        slope = sum(w * np.asarray(m, np.float64) for w, m in zip(tc / np.sum(tc * tc), means_dn))
        return slope / gain_dn_per_e
    # per-pixel weighted least squares, weight 1 where the pixel is below the limit
    s0 = s1 = s2 = sy = sty = 0.0
    for ti, m in zip(t, means_dn):
        y = np.asarray(m, np.float64)
        w = (y < limit_dn).astype(np.float64)
        s0 = s0 + w; s1 = s1 + w * ti; s2 = s2 + w * ti * ti; sy = sy + w * y; sty = sty + w * ti * y  # noqa: E702
    det = s0 * s2 - s1 * s1
    ok = det > 1e-12 * np.max(t) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        slope = np.where(ok, (s0 * sty - s1 * sy) / np.where(ok, det, 1.0), 0.0)
    if not ok.all():  # clipped at all but one time: from the shortest, over the intercept of the rest
        good = ok.astype(np.float64)
        intercept = float(np.sum(np.where(ok, (sy - slope * s1) / np.where(ok, s0, 1.0), 0.0)) / max(good.sum(), 1.0))
        i0 = int(np.argmin(t))
        slope = np.where(ok, slope, (np.asarray(means_dn[i0], np.float64) - intercept) / max(t[i0], 1e-12))
    return slope / gain_dn_per_e


def pixel_offsets(means_dn: list[np.ndarray], exposures_s: list[float], pixel_vars_dn2: list[np.ndarray],
                  frames: list[int], gain_dn_per_e: float, limit_dn: float, exclude: np.ndarray | None = None,
                  tail_alpha: float = 1e-3) -> dict:
    """The pixel offsets (docs/model.md stage 5c) from each pixel's dark intercept over exposure time.

    Each pixel's dark mean is a line in exposure time: its intercept is the
    black level plus the pixel's offset, its slope the pixel's dark current.
    The intercepts' spread over the array, with the row and column means
    taken out (the fixed row offsets and VFPN are fitted apart) and the
    intercepts' own temporal noise removed, is the offsets' variance. With
    two or more exposure times in each half of the stacks, it is the
    covariance of the intercepts of the two halves (their noises are
    independent: no model of the noise needed); else

        var(offset) = var_robust(residual) / (1 - 1/rows - 1/cols) - <var(intercept)>

    with ``var(intercept) = sum_j c_j**2 var_j / n_j`` (``c_j`` the intercept's
    least-squares weights, ``var_j`` a pixel's temporal variance at exposure
    ``j`` over its ``n_j`` frames). The body's sigma is taken robustly
    (median absolute deviation: a tail of large offsets does not inflate it);
    pixels more than 5 body sigmas (with the noise) above it are the tail,
    counted with an exact binomial interval against what the body puts there,
    and reported where their count's Poisson p-value under the body is below
    ``tail_alpha``. ``p_value`` is the body's: that its variance is 0
    (one-sided, from its standard error).
    Pixels that reach ``limit_dn`` in any stack are left out (a white pixel
    bends its own line), and the pixels ``exclude`` (flat indices: random
    telegraph pixels, whose level in a stack is where their traps happened to be).

    Each 2 x 2 cell position's mean intercept (less the four's mean) is the
    black level's offset of that CFA position (``cells_dn``, with standard
    errors ``cells_se_dn``); it is taken out before the spread is measured.

    Returns
    -------
    dict with ``sigma_e`` (value, ci95), ``p_value``, ``tail`` (ppm_above, threshold_e,
    max_e, ci95, pixels) or None, ``tail_p_value``, ``residual_e`` (rows, cols), ``pixels``,
    ``cells_dn`` and ``cells_se_dn`` (2, 2).
    """
    from scipy import stats

    t = np.asarray(exposures_s, np.float64)
    stack = np.stack([np.asarray(m, np.float64) for m in means_dn])
    usable = np.all(stack < limit_dn, axis=0)
    rows, cols = stack.shape[1:]
    if exclude is not None and exclude.size:
        usable.ravel()[exclude] = False
    shrink = own_share(rows, cols)  # what taking out the rows' and columns' means leaves of a pixel's variance

    def intercepts(idx):
        """Each pixel's intercept from the stacks ``idx`` (least squares over their times), DN; NaN where unusable."""
        ti = t[idx]
        tc = ti - ti.mean()
        w = 1.0 / ti.size - ti.mean() * tc / np.sum(tc * tc)
        return np.where(usable, np.tensordot(w, stack[idx], axes=1), np.nan), w

    def residual(r):
        """The intercepts less their 2 x 2 cell position's mean (the black level per CFA cell), then less their
        rows' and columns' means (fixed row offsets and VFPN), e-."""
        r = r.copy()
        for dr in (0, 1):
            for dc in (0, 1):
                r[dr::2, dc::2] -= np.nanmean(r[dr::2, dc::2])
        r = r - np.nanmean(r, axis=1, keepdims=True) - np.nanmean(r, axis=0, keepdims=True) + np.nanmean(r)
        return r / gain_dn_per_e

    every = np.arange(t.size)
    raw, c = intercepts(every)
    # the black level of each 2 x 2 cell position against their mean, DN: each position's mean intercept, its
    # standard error from the intercepts' spread in that position
    cells = np.array([[np.nanmean(raw[dr::2, dc::2]) for dc in (0, 1)] for dr in (0, 1)])
    def position_se(sub):
        """Standard error of a position's mean: its pixels' spread over their number, and what its rows and its
        columns share (fixed row offsets, VFPN: a column's pixels move together), over their numbers."""
        n_pix = np.sum(np.isfinite(sub))
        by_col, by_row = np.nanmean(sub, axis=0), np.nanmean(sub, axis=1)
        return math.sqrt(np.nanvar(sub, ddof=1) / n_pix + np.nanvar(by_col, ddof=1) / by_col.size
                         + np.nanvar(by_row, ddof=1) / by_row.size)

    cells_se = np.array([[position_se(raw[dr::2, dc::2]) for dc in (0, 1)] for dr in (0, 1)])
    cells = cells - cells.mean()
    resid_e = residual(raw)
    values = resid_e[usable]
    n = values.size
    # the pixels' variances are of frames less their row and column means: ``shrink`` of a pixel's own
    noise = float(sum(ci * ci * float(np.mean(v)) / nj for ci, v, nj in zip(c, pixel_vars_dn2, frames)))
    noise /= shrink * gain_dn_per_e**2
    _, robust = robust_centre(values)
    total_var = robust**2 / shrink
    order = np.argsort(t, kind="stable")
    halves = order[0::2], order[1::2]
    if min(len(set(np.round(t[h], 12))) for h in halves) >= 2:
        # two intercepts from disjoint stacks: their noises are independent, so the covariance over the pixels is
        # the offsets' variance whatever the noise's law (a robust spread assumes it normal); the body's pixels
        # only (within 6 robust sigmas: a tail is counted apart)
        a = residual(intercepts(halves[0])[0])
        b = residual(intercepts(halves[1])[0])
        body = usable & (np.abs(resid_e) <= 6 * robust)
        xa, xb = a[body] - a[body].mean(), b[body] - b[body].mean()
        var = float(np.mean(xa * xb)) / shrink
        se = math.sqrt(float(np.mean(xa * xa)) * float(np.mean(xb * xb)) + var**2) / math.sqrt(xa.size) / shrink
        how = "covariance of two intercepts from disjoint halves of the stacks"
    else:
        var = total_var - noise
        # the MAD's sampling variance is 1.36 times the standard deviation's: se(var) = 2 var sqrt(1.36 / (2 n))
        se = 2 * total_var * math.sqrt(1.36 / (2 * n))
        how = "robust variance of the intercepts less their temporal noise"
    sigma = math.sqrt(max(var, 0.0))
    threshold = 5.0 * math.sqrt(total_var)
    above = int(np.sum(values > threshold))
    expected = n * float(stats.norm.sf(threshold / math.sqrt(total_var)))
    tail = None
    tail_p = float(stats.poisson.sf(above - 1, expected)) if above >= 1 else 1.0
    if above >= 3 and tail_p < tail_alpha:
        ci = stats.binomtest(above, n).proportion_ci(0.95, method="exact")
        tail = {"ppm_above": above / n * 1e6, "threshold_e": threshold, "max_e": float(values.max()),
                "ci95": [ci.low * 1e6, ci.high * 1e6], "pixels": above}
    return {"sigma_e": {"value": sigma, "ci95": [math.sqrt(max(var - Z95 * se, 0.0)), math.sqrt(max(var + Z95 * se, 0.0))]},
            "p_value": float(stats.norm.sf(var / se)) if se > 0 else (0.0 if var > 0 else 1.0), "tail_p_value": tail_p,
            "noise_e": math.sqrt(noise), "tail": tail, "residual_e": resid_e, "pixels": n, "method": how,
            "cells_dn": cells, "cells_se_dn": cells_se}


def clipped_pixels(means_dn: list[np.ndarray], limit_dn: float) -> np.ndarray:
    """Pixels below ``limit_dn`` at fewer than two of the stacks: their rate is a lower bound (bool map)."""
    return sum((np.asarray(m) < limit_dn).astype(np.int32) for m in means_dn) < 2


def fit_point(rates: np.ndarray, slope_noise_var: float, threshold: float | None, common_var: float = 0.0) -> dict:
    """One temperature's dark current from its rate map (e-/s): the body's family, mean and std, the tail.

    ``slope_noise_var`` is the variance (e-/s)^2 the per-pixel slope's temporal
    noise adds to the map; the body's std is corrected for it. ``common_var``
    is the variance (e-/s)^2 of the noise every pixel's slope shares (the
    frames' row and column noise averaged over the map): it adds to the mean's
    uncertainty and to no pixel's spread.

    ``threshold`` is where the tail's ppm is counted (the user's, or the
    base configuration's); without one, 8 robust standard deviations above
    the median. The body is fitted below its own cut: the threshold where it
    lies between 5 and 8 robust standard deviations above the median, else
    8. A threshold far above the body (a white-pixel threshold set for a
    warmer sensor) would let the tail pixels that fall below it into the
    body, and one inside the body would leave the body's fit to a
    correction for the half it cuts off.
    Returns ``{"parameters": {name: {value, ci95, method}}, "families": [...], "threshold": thr,
    "body_cut": cut}``.
    """
    med, robust = robust_centre(rates)
    cut = med + 8 * robust
    if threshold is None:
        threshold = cut
    elif med + 5 * robust <= threshold <= cut:
        cut = float(threshold)
    fits = select_family(rates, cut)
    best = fits[0]
    # mean and std by moments of the pixels below the cut: the slope's noise blurs the map's shape (a
    # family's maximum-likelihood std of a blurred map is not the body's), but it only adds to the variance
    x = rates[rates < cut].astype(np.float64).ravel()
    n = x.size
    mean, var = float(x.mean()), float(x.var(ddof=1))
    # what the cut takes off the body's upper end, by the chosen family: added back to the moments
    try:
        d = body(best.family, best.mean, best.std)
        p_in = float(d.cdf(cut))
        if 0.5 < p_in < 1.0:
            m_in = float(d.expect(lambda v: v, ub=cut, conditional=True))
            v_in = float(d.expect(lambda v: (v - m_in) ** 2, ub=cut, conditional=True))
            mean += float(d.mean()) - m_in
            var *= float(d.var()) / v_in if v_in > 0 else 1.0
    except (ValueError, ZeroDivisionError):
        pass
    floor = 1e-3 * abs(mean)  # the least std the configuration can take (1e-6 of the mean), with room
    body_std = math.sqrt(max(var - slope_noise_var, floor**2))
    kurt = float(np.mean((x - mean) ** 4) / np.var(x) ** 2)
    se_mean = math.sqrt(var / n + common_var)
    se_var = var * math.sqrt((kurt - 1) / n)
    lo_var, hi_var = var - slope_noise_var - Z95 * se_var, var - slope_noise_var + Z95 * se_var
    blurred = math.sqrt(slope_noise_var) > 0.1 * body_std
    tl = tail(rates, threshold, best)
    from scipy import stats

    ci = stats.binomtest(tl["pixels_above"], rates.size).proportion_ci(0.95, method="exact")
    z = Z95
    params = {
        "family": {"value": best.family, "ci95": None,
                   "method": "truncated maximum likelihood of docs/model.md's five families, lowest AIC"
                             + (f"; the slope noise is {math.sqrt(slope_noise_var) / max(body_std, 1e-12):.0%} of the body's "
                                "std and blurs the shape: longer exposures or more frames make the choice surer"
                                if blurred else "")},
        "mean_e_per_s": {"value": mean, "ci95": [mean - z * se_mean, mean + z * se_mean],
                         "method": f"per-pixel slope over exposure time: mean of the {n} pixels below {cut:.4g} e-/s "
                                   "(the body's cut)"},
        "std_e_per_s": {"value": body_std, "ci95": [math.sqrt(max(lo_var, 0.0)), math.sqrt(max(hi_var, floor**2))],
                        "method": f"their standard deviation, less the slope's temporal noise "
                                  f"({math.sqrt(slope_noise_var):.3g} e-/s rms)"
                                  + (": not resolved above that noise (the value is a floor)" if body_std <= floor * 1.0001 else "")},
        "tail.ppm_above": {"value": tl["ppm_above"], "ci95": [ci.low * 1e6, ci.high * 1e6],
                           "method": f"pixels above {threshold:.4g} e-/s (exact binomial interval)"},
        "tail.max_e_per_s": {"value": max(tl["max_e_per_s"], 1.0), "ci95": None,
                             "method": "largest rate above the body's mean"},
    }
    families = [{"family": f.family, "mean": f.mean, "std": f.std, "loglik": f.loglik, "aic": f.aic,
                 "delta_aic": f.aic - best.aic} for f in fits]
    return {"parameters": params, "families": families, "threshold": float(threshold), "body_cut": float(cut)}


def doubling(temperatures: list[float], means: list[float], ses: list[float]) -> dict:
    """Doubling temperature (C) of a mean dark current measured at two or more temperatures.

    Weighted least squares of log2(mean) over temperature; the doubling is
    the slope's inverse, its interval from the means' standard errors.
    """
    t = np.asarray(temperatures, np.float64)
    y = np.log2(np.asarray(means, np.float64))
    sy = np.asarray(ses, np.float64) / (np.asarray(means, np.float64) * math.log(2))
    w = 1 / np.maximum(sy, 1e-12) ** 2
    tm = np.sum(w * t) / np.sum(w)
    slope = float(np.sum(w * (t - tm) * y) / np.sum(w * (t - tm) ** 2))
    se = math.sqrt(1 / float(np.sum(w * (t - tm) ** 2)))
    if len(t) > 2:  # residual scatter beyond the standard errors widens the interval
        ym = np.sum(w * y) / np.sum(w)
        chi2 = float(np.sum(w * (y - ym - slope * (t - tm)) ** 2)) / (len(t) - 2)
        se *= math.sqrt(max(chi2, 1.0))
    lo, hi = slope - Z95 * se, slope + Z95 * se
    return {"value": 1 / slope if slope > 0 else math.inf,
            "ci95": [1 / hi if hi > 0 else math.inf, 1 / lo if lo > 0 else math.inf], "slope_per_c": slope}


def tail_doubling(rate_maps: dict[float, np.ndarray], body_std_hot: float, seed: int = 0,
                  exclude: np.ndarray | None = None) -> dict | None:
    """Doubling temperature of the white-pixel tail: the same tail pixels' excess over the body at each temperature.

    The pixels are those whose rate at the hottest temperature exceeds the
    map's median by more than 20 body standard deviations (their excess is
    then nearly all tail); each one's excess over the map's median at every
    temperature, the median excess's log2 regressed on temperature.
    Interval: a bootstrap over the pixels (200 resamples). ``exclude``: pixels
    whose rate is only a lower bound (clipped at all but one exposure time).
    """
    temps = sorted(rate_maps)
    hot = temps[-1]
    med = {t: float(np.median(rate_maps[t])) for t in temps}
    sel = (rate_maps[hot] - med[hot]) > 20 * body_std_hot
    if exclude is not None:
        sel &= ~exclude
    if sel.sum() < 10:
        return None
    ex = np.stack([rate_maps[t][sel] - med[t] for t in temps])  # (temperatures, pixels)
    t = np.asarray(temps)

    def slope(cols):
        y = np.log2(np.maximum(np.median(ex[:, cols], axis=1), 1e-9))
        return float(np.polyfit(t, y, 1)[0])

    s = slope(np.arange(ex.shape[1]))
    rng = np.random.default_rng(seed)
    boots = np.array([slope(rng.integers(0, ex.shape[1], ex.shape[1])) for _ in range(200)])
    lo, hi = np.quantile(boots, [0.025, 0.975])
    return {"value": 1 / s if s > 0 else math.inf, "ci95": [1 / hi if hi > 0 else math.inf, 1 / lo if lo > 0 else math.inf],
            "pixels": int(sel.sum())}
