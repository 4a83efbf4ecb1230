"""Fitting the model to measured data: the dark-current map's body family and its white-pixel tail.

The paper chose each temperature's dark-current distribution by fitting
candidate families to the measured histogram and ranking them by
log-likelihood. Here every family of MODEL.md section 3 is fitted by maximum
likelihood to the pixels below the white-pixel threshold, the likelihood
truncated there (the tail is a separate population): each candidate gets
its mean, std, log-likelihood and AIC, and the lowest AIC is chosen. The
tail is the fraction of pixels above the threshold (ppm) and its largest
excess over the body.

This is the first part of ``cmosnoise fit`` (issue 14): the dark-current
stage from a rate map. A rate map from frames is the per-pixel slope of the
dark signal over exposure time (:func:`rate_map_from_stacks`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CmosnoiseError
from ..model.distributions import FAMILIES, POSITIVE_FAMILIES, body

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


def _truncated_loglik(family: str, mean: float, std: float, x: np.ndarray, threshold: float) -> float:
    try:
        d = body(family, mean, std)
    except ValueError:
        return -math.inf
    with np.errstate(all="ignore"):
        ll = float(np.sum(d.logpdf(x)))
        norm = float(d.logcdf(threshold)) if math.isfinite(threshold) else 0.0
    value = ll - x.size * norm
    return value if math.isfinite(value) else -math.inf


def fit_family(family: str, x: np.ndarray, threshold: float = math.inf) -> FamilyFit:
    """Maximum-likelihood mean and std of ``family`` for the values ``x`` (all below ``threshold``, the truncation)."""
    from scipy import optimize

    x = np.asarray(x, np.float64)
    m0, s0 = float(x.mean()), float(x.std()) or 1.0
    if family in POSITIVE_FAMILIES and m0 <= 0:
        return FamilyFit(family, math.nan, math.nan, -math.inf, math.inf, x.size)

    def neg(theta):
        mean, std = theta[0], math.exp(theta[1])
        if family in POSITIVE_FAMILIES and mean <= 0:
            return 1e300
        v = _truncated_loglik(family, mean, std, x, threshold)
        return -v if math.isfinite(v) else 1e300

    res = optimize.minimize(neg, [m0, math.log(s0)], method="Nelder-Mead",
                            options={"xatol": 1e-6 * max(abs(m0), 1.0), "fatol": 1e-3, "maxiter": 600})
    mean, std = float(res.x[0]), math.exp(float(res.x[1]))
    ll = -float(res.fun) if res.fun < 1e299 else -math.inf
    return FamilyFit(family, mean, std, ll, 2 * 2 - 2 * ll, x.size)


def select_family(rates: np.ndarray, threshold: float | None = None, seed: int = 0) -> list[FamilyFit]:
    """Every family of MODEL.md fitted to the body of a dark-rate map (e-/s), best (lowest AIC) first.

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
    fits = [fit_family(f, x, thr) for f in FAMILIES]
    return sorted(fits, key=lambda f: f.aic)


def tail(rates: np.ndarray, threshold: float, body_fit: FamilyFit) -> dict:
    """The white-pixel tail: ppm of pixels above ``threshold`` and the largest excess over the body's mean (e-/s)."""
    x = np.asarray(rates, np.float64).ravel()
    above = x > threshold
    return {"ppm_above": float(above.mean() * 1e6), "threshold_e_per_s": float(threshold),
            "max_e_per_s": float(max(x.max() - body_fit.mean, 0.0)) if above.any() else 0.0,
            "pixels_above": int(above.sum())}


def rate_map_from_stacks(means_dn: list[np.ndarray], exposures_s: list[float], gain_dn_per_e: float) -> np.ndarray:
    """Per-pixel dark current (e-/s): the least-squares slope of the mean dark signal over exposure time.

    ``means_dn`` are per-pixel means of dark stacks (DN) at ``exposures_s``
    (at least two distinct times); the black level and any fixed offset fall
    into the intercept.
    """
    t = np.asarray(exposures_s, np.float64)
    if len(means_dn) != t.size or len(set(np.round(t, 12))) < 2:
        raise CmosnoiseError("dark current: needs dark stacks at two or more distinct exposure times")
    shapes = {m.shape for m in means_dn}
    if len(shapes) != 1:
        raise CmosnoiseError(f"dark current: the dark stacks have different sizes {sorted(shapes)}")
    tc = t - t.mean()
    slope = sum(w * np.asarray(m, np.float64) for w, m in zip(tc / np.sum(tc * tc), means_dn))
    return slope / gain_dn_per_e
