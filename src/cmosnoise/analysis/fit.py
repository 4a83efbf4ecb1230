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


# ------------------------------------------------------------------ from an EMVA 1288 data set
def from_emva(m, temperature_c: float, threshold_e_per_s: float | None = None) -> dict:
    """Fit what an EMVA 1288 data set gives (a :class:`~cmosnoise.analysis.characterize.Measurement` loaded with
    ``keep_dark_means=True``): the ADC's gain, black level and full well, and the dark current at ``temperature_c``.

    Returns ``{"parameters": {name: {value, ci95, method}}, "dark_families": [...], "not_fitted": {...}}``.
    The dark map is the per-pixel slope over the exposure times where no dark
    pixel nears saturation; its body's std is corrected for the slope's
    temporal noise (estimated from the dark pairs' own temporal variance).
    """
    from . import characterize as ch

    res = ch.evaluate(m)
    if res["system_gain_K_dn_per_e"] is None:
        raise CmosnoiseError("fit: " + res["unavailable"]["system_gain_K_dn_per_e"])
    k = res["system_gain_K_dn_per_e"]
    z = 1.959964
    out: dict = {}
    # K: slope through the origin of the photon-transfer points below 70 % of saturation; its se from the residuals
    y, v = m.mu_y - m.mu_ydark, m.s2_y - m.s2_ydark
    i_sat = res["saturation_index"]
    lin = np.nonzero((y <= 0.7 * y[i_sat]) & (np.arange(len(y)) < i_sat))[0]
    se_k = math.sqrt(float(np.sum((v[lin] - k * y[lin]) ** 2)) / (len(lin) - 1) / float(np.sum(y[lin] ** 2)))
    out["system_gain_K_dn_per_e"] = {"value": k, "ci95": [k - z * se_k, k + z * se_k],
                                     "method": "EMVA 1288 photon transfer, least squares through the origin"}
    # black level: the dark mean's intercept at zero exposure
    ok = np.arange(res["dark_fit_points"]) if res["dark_fit_points"] >= 3 else np.arange(len(m.texp_s))
    t = m.texp_s[ok]
    coef, cov = np.polyfit(t, m.mu_ydark[ok], 1, cov=True)
    black, se_black = float(coef[1]), math.sqrt(float(cov[1, 1]))
    out["black_level_dn"] = {"value": black, "ci95": [black - z * se_black, black + z * se_black],
                             "method": "intercept of the dark mean over exposure time"}
    full = float(np.max(m.mu_y) - black) / k
    out["full_well_e"] = {"value": full, "ci95": None,
                          "method": "the brightest step's mean above black / K (most pixels saturated at 1.3 x saturation)"}
    means = m.frames.get("dark_means")
    families = []
    if means is None or len(ok) < 2:
        not_fitted = {"dark_current": "needs per-pixel dark means at two or more exposure times without saturation"}
    else:
        rates = rate_map_from_stacks([means[i] for i in ok], list(t), k)
        tc = t - t.mean()
        # the slope's temporal noise per pixel: a pair mean's variance is s2_ydark / 2 (DN^2), propagated
        noise_var = float(np.sum((tc / np.sum(tc * tc)) ** 2 * m.s2_ydark[ok] / 2)) / k**2
        thr = threshold_e_per_s
        if thr is None:  # a default from the body: 8 robust standard deviations above the median
            med = float(np.median(rates))
            thr = med + 8 * 1.4826 * float(np.median(np.abs(rates - med)))
        fits = select_family(rates, thr)
        best = fits[0]
        body_std = math.sqrt(max(best.std**2 - noise_var, 1e-12))
        n = best.n
        x = rates[rates < thr].astype(np.float64)
        kurt = float(np.mean((x - x.mean()) ** 4) / np.var(x) ** 2)
        se_mean, se_std = best.std / math.sqrt(n), best.std * math.sqrt((kurt - 1) / (4 * n))
        tl = tail(rates, thr, best)
        p = tl["ppm_above"] * 1e-6
        se_ppm = math.sqrt(p * (1 - p) / rates.size) * 1e6
        out["dark_current.family"] = {"value": best.family, "ci95": None,
                                      "method": "truncated maximum likelihood of MODEL.md's five families, lowest AIC"}
        out["dark_current.mean_e_per_s"] = {"value": best.mean, "ci95": [best.mean - z * se_mean, best.mean + z * se_mean],
                                            "method": "per-pixel slope over exposure time, body fit"}
        out["dark_current.std_e_per_s"] = {"value": body_std, "ci95": [max(body_std - z * se_std, 0.0), body_std + z * se_std],
                                           "method": f"body fit, less the slope's temporal noise ({math.sqrt(noise_var):.3g} e-/s rms)"}
        out["dark_current.tail.ppm_above"] = {"value": tl["ppm_above"], "ci95": [max(tl["ppm_above"] - z * se_ppm, 0.0),
                                                                                  tl["ppm_above"] + z * se_ppm],
                                              "method": f"pixels above {thr:.4g} e-/s"}
        out["dark_current.tail.max_e_per_s"] = {"value": max(tl["max_e_per_s"], 1.0), "ci95": None,
                                                "method": "largest rate above the body's mean"}
        families = [{"family": f.family, "mean": f.mean, "std": f.std, "loglik": f.loglik, "aic": f.aic} for f in fits]
        not_fitted = {}
        out["_threshold"] = thr
        out["_temperature"] = temperature_c
    not_fitted.update({
        "prnu, crosstalk": "needs flat-field stacks (an EMVA data set's bright stack is used only for K here; next)",
        "source_follower, row_noise, column_noise": "needs a long dark stack (per-pixel variances; next)",
        "dark_current doubling": "needs dark data at two or more temperatures",
    })
    return {"parameters": out, "dark_families": families, "not_fitted": not_fitted}


def fitted_config(base, result: dict, bits: int, shape: tuple[int, int]):
    """``base`` (a Config) with the fitted values: what ``cmosnoise simulate --config`` runs."""
    from ..config.loading import merge_updates
    from ..model.physics import check

    p = result["parameters"]
    k, black = p["system_gain_K_dn_per_e"]["value"], p["black_level_dn"]["value"]
    black = min(max(round(black, 3), 0.0), 2**bits - 2)
    updates = {
        "sensor": {"width": shape[1], "height": shape[0], "full_well_e": round(p["full_well_e"]["value"], 1)},
        "adc": {"enabled": True, "bits": bits, "black_level_dn": black, "full_scale_e": (2**bits - 1 - black) / k},
    }
    if "dark_current.family" in p:
        updates["sensor"]["temperature_c"] = p["_temperature"]
        point = {"temperature_c": p["_temperature"], "distribution": p["dark_current.family"]["value"],
                 "mean_e_per_s": p["dark_current.mean_e_per_s"]["value"], "std_e_per_s": p["dark_current.std_e_per_s"]["value"]}
        if p["dark_current.tail.ppm_above"]["value"] > 0:
            point["tail"] = {"ppm_above": p["dark_current.tail.ppm_above"]["value"], "threshold_e_per_s": p["_threshold"],
                             "max_e_per_s": p["dark_current.tail.max_e_per_s"]["value"]}
        updates["dark_current"] = {"enabled": True, "points": [point]}
    return check(merge_updates(base, updates))
