"""Fitting the light-dependent stages to flat fields: photon transfer (K, full well), PRNU and column gain.

**Photon transfer** (EMVA 1288's method). For every flat stack, the mean
signal above its dark reference ``mu = mean(flat) - mean(dark)`` and the
temporal variance ``v = var(flat) - var(dark)`` (DN, DN^2). Shot noise makes
``v = K mu`` until the pixels clip; saturation is the point of largest
variance, and K the slope through the origin of the points below 70 % of
it, each weighted by the inverse of its sampling variance.

**PRNU and column gain.** A flat stack's mean image less its dark
stack's (same exposure) is the signal; each colour channel is divided by
its mean. A two-way analysis splits it into column means (the column gain
mismatch, after the pixel part's and the temporal noise's share is taken
off: the covariance of two halves of each column) and a pixel residual
(PRNU, after the temporal noise's share).
Defect pixels (5 robust sigma) are left out.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import CmosnoiseError
from ..estimators import Z95
from ..model import cfa as cfa_mod
from .fit_readout import centred_series, residual_variance, robust_mask, split_half_covariance


def photon_transfer(mu, v, frames=None, dark_var=None, dark_frames=None) -> dict:
    """K (DN/e-) from the photon-transfer points ``mu`` (DN above dark) and ``v`` (DN^2, less the dark's).

    Parameters
    ----------
    mu, v : sequences of float, one per flat stack
        Mean signal above the dark (DN) and temporal variance less the dark's (DN^2): EMVA 1288's
        ``mu_y - mu_y.dark`` and ``sigma_y^2 - sigma_y.dark^2``.
    frames : sequence of int, optional
        Frames in each flat stack (default 2, EMVA's pairs).
    dark_var, dark_frames : sequences, optional
        Each point's dark temporal variance (DN^2, default 0) and the frames of its dark stack (default 2).

    The slope through the origin of the points below 70 % of saturation (the point of largest
    variance), weighted by the inverse of each point's sampling variance: a mean of per-pixel variances
    over ``n`` frames has a variance proportional to ``sigma^4 / (n - 1)``, so a 2-frame level has 240
    times the sampling variance of a 16-frame level a quarter as bright. (An unweighted slope, which
    EMVA 1288 draws, is more than twice as noisy on such a set.) The weights' scale is left to the data:
    the interval is Student t on the weighted residuals, exact when the weights are right up to a
    factor, and honest when the pixels share noise the weights do not know of.

    Returns K, its 95 % interval, its relative standard error, the saturation index (into the points
    sorted by ``mu``), the number of points fitted and the sorted points.
    """
    mu, v = np.asarray(mu, np.float64), np.asarray(v, np.float64)
    m = mu.size
    n = np.full(m, 2.0) if frames is None else np.asarray(frames, np.float64)
    vd = np.zeros(m) if dark_var is None else np.asarray(dark_var, np.float64)
    nd = np.full(m, 2.0) if dark_frames is None else np.asarray(dark_frames, np.float64)
    order = np.argsort(mu)
    mu, v, n, vd, nd = mu[order], v[order], n[order], vd[order], nd[order]
    i_sat = int(np.argmax(v))
    lin = np.nonzero((mu <= 0.7 * mu[i_sat]) & (np.arange(mu.size) < i_sat) & (mu > 0))[0]
    if lin.size < 3:
        raise CmosnoiseError(f"system gain K: {lin.size} flat level(s) below 70 % of saturation; the photon transfer "
                             "needs at least 3 (EMVA 1288 recommends 50 levels from dark to beyond saturation)")
    x, y = mu[lin], v[lin]
    k = float(np.sum(x * y) / np.sum(x * x))  # the unweighted slope: where the weights start
    for _ in range(3):  # weights from the fitted line, never from the noisy variances themselves
        w = 1.0 / ((k * x + vd[lin]) ** 2 / np.maximum(n[lin] - 1, 1) + vd[lin] ** 2 / np.maximum(nd[lin] - 1, 1))
        k = float(np.sum(w * x * y) / np.sum(w * x * x))
    dof = lin.size - 1
    se = math.sqrt(float(np.sum(w * (y - k * x) ** 2)) / dof / float(np.sum(w * x * x)))
    from scipy import stats

    q = float(stats.t.ppf(0.975, dof))  # the residuals' scale is itself estimated from few levels
    return {"K": k, "ci95": [k - q * se, k + q * se], "rel_se": q * se / Z95 / k, "saturation_index": i_sat, "fit_points": int(lin.size),
            "mu": mu, "v": v, "linear": lin}


def quantum_efficiency(mu_dn, photons, k: float, saturation_index: int, k_rel_se: float = 0.0) -> dict:
    """QE: the slope through the origin of photo-electrons (``mu_dn / k``) over photons per pixel, below 70 % of
    saturation (EMVA 1288's responsivity divided by K). Its interval combines the slope's (Student t, from the
    residuals) with K's relative standard error ``k_rel_se``: QE is only as sure as K."""
    from scipy import stats

    mu = np.asarray(mu_dn, np.float64) / k
    ph = np.asarray(photons, np.float64)
    order = np.argsort(mu)
    mu, ph = mu[order], ph[order]
    lin = np.nonzero((mu <= 0.7 * mu[saturation_index]) & (np.arange(mu.size) < saturation_index) & (mu > 0))[0]
    if lin.size < 3:
        raise CmosnoiseError(f"quantum efficiency: {lin.size} flat level(s) below 70 % of saturation; it needs at least 3")
    q = float(np.sum(ph[lin] * mu[lin]) / np.sum(ph[lin] ** 2))
    se = math.sqrt(float(np.sum((mu[lin] - q * ph[lin]) ** 2)) / (lin.size - 1) / float(np.sum(ph[lin] ** 2)))
    t = float(stats.t.ppf(0.975, lin.size - 1))
    half = q * math.hypot(t * se / q, Z95 * k_rel_se)
    return {"value": q, "ci95": [q - half, q + half], "points": int(lin.size)}


def nonlinearity(mu_dn, v_dn2, photons, k: float, saturation_index: int, mean_var_dn2, alpha: float = 1e-3) -> dict:
    """The photo-response nonlinearity (docs/model.md stage 5b) from the photon-transfer means.

    The mean signal in e- (``mu_dn / k``) below saturation is fitted as a
    quartic through the origin in the photons, ``y = p1 x + p2 x**2 + p3 x**3
    + p4 x**4`` (weighted least squares, each mean's sampling variance
    ``mean_var_dn2``, DN^2),
    and against a line through the origin: an F test says whether the bend is
    there (p < ``alpha``; the fit passes its share of a family-wise rate). ``p1`` is then the quantum efficiency (the small-signal
    slope), and the transfer, as a function of the collected charge
    ``c = p1 x``, is ``f(c) = c + p2 c**2 / p1**2 + p3 c**3 / p1**3 + p4 c**4 / p1**4``.

    Where it acts: on each frame's charge (after the shot noise) the
    variance follows ``K**2 f'(c)**2 c``; on the mean charge (before it)
    ``K**2 f(c)``, as the photon transfer of a linear sensor. The one with
    the smaller chi-square over the same points is taken.

    Returns
    -------
    dict: ``bent`` (bool), ``p_value``, ``coefficients`` (p1..p4, in photons), ``qe`` and
    its standard error, ``acts_on``, and ``transfer(c)`` (e- in, e- out).
    """
    from scipy import stats

    mu = np.asarray(mu_dn, np.float64) / k
    v = np.asarray(v_dn2, np.float64) / k**2
    ph = np.asarray(photons, np.float64)
    order = np.argsort(mu)
    mu, v, ph = mu[order], v[order], ph[order]
    use = np.nonzero((np.arange(mu.size) < saturation_index) & (mu > 0) & (mu <= 0.95 * mu[saturation_index]))[0]
    if use.size < 6:
        return {"bent": False, "p_value": 1.0, "why": f"{use.size} levels below saturation; a bend needs 6"}
    x, y = ph[use], mu[use]
    w = k**2 / np.asarray(mean_var_dn2, np.float64)[order][use]
    scale = float(x.max())
    X4 = np.stack([(x / scale) ** j for j in (1, 2, 3, 4)], axis=1)
    sw = np.sqrt(w)
    coef4, *_ = np.linalg.lstsq(X4 * sw[:, None], y * sw, rcond=None)
    rss4 = float(np.sum(w * (y - X4 @ coef4) ** 2))
    coef1 = float(np.sum(w * X4[:, 0] * y) / np.sum(w * X4[:, 0] ** 2))
    rss1 = float(np.sum(w * (y - X4[:, 0] * coef1) ** 2))
    dof = use.size - 4
    F = ((rss1 - rss4) / 3) / max(rss4 / dof, 1e-300)
    p_value = float(stats.f.sf(F, 3, dof))
    p = coef4 / scale ** np.arange(1, 5)  # in photons
    cov = np.linalg.pinv((X4 * w[:, None]).T @ X4) * max(rss4 / dof, 1.0)
    qe, qe_se = float(p[0]), float(math.sqrt(cov[0, 0])) / scale

    def transfer(c):
        c = np.asarray(c, np.float64)
        return c + p[1] * c**2 / p[0] ** 2 + p[2] * c**3 / p[0] ** 3 + p[3] * c**4 / p[0] ** 4

    def slope(c):
        return 1 + 2 * p[1] * c / p[0] ** 2 + 3 * p[2] * c**2 / p[0] ** 3 + 4 * p[3] * c**3 / p[0] ** 4

    c = qe * x
    # a variance estimate's sampling variance goes as its square: each level weighted by 1 / v^2 (the common
    # factor of frames and pixels cancels in the comparison)
    w_v = 1.0 / np.maximum(v[use], 1e-12) ** 2
    chi_charge = float(np.sum(w_v * (v[use] - slope(c) ** 2 * c) ** 2))
    chi_mean = float(np.sum(w_v * (v[use] - transfer(c)) ** 2))
    return {"bent": p_value < alpha, "p_value": p_value, "coefficients": [float(a) for a in p], "qe": qe,
            "qe_se": qe_se, "acts_on": "charge" if chi_charge < chi_mean else "mean", "transfer": transfer,
            "slope": slope, "levels": int(use.size)}


def channel_normalised(signal: np.ndarray, pattern: str, mask: np.ndarray) -> np.ndarray:
    """``signal`` divided, colour channel by colour channel, by the channel's mean over the kept pixels."""
    out = np.empty_like(signal, dtype=np.float64)
    for m in cfa_mod.masks(pattern, signal.shape):
        sel = m.astype(bool)
        out[sel] = signal[sel] / float(np.mean(signal[sel & mask]))
    return out


def prnu_and_column_gain(flat, dark, pattern: str, saturation_dn: float) -> dict:
    """PRNU (%) and column gain mismatch (%) from a flat stack and a dark stack at its exposure (:class:`StackStats`).

    Returns ``{"prnu_pct": {value, ci95}, "column_gain_pct": {value, ci95}, "excluded_pixels", "signal_dn"}``.
    """
    if flat.shape != dark.shape:
        raise CmosnoiseError("PRNU: the flat and dark stacks differ in size")
    signal = flat.mean - dark.mean
    rows, cols = signal.shape
    keep = robust_mask(dark.mean) & (flat.mean < 0.95 * saturation_dn)
    for m in cfa_mod.masks(pattern, signal.shape):  # defects of the signal, per channel
        sel = m.astype(bool)
        keep[sel] &= robust_mask(signal[sel])
    mean_s = float(np.mean(signal[keep]))
    if mean_s <= 0:
        raise CmosnoiseError("PRNU: the flat stack is not brighter than its dark stack")
    rel = channel_normalised(signal, pattern, keep)
    corr = 1 - 2 / cols - 2 / rows
    # per-pixel temporal variance of the two means, relative to the signal
    v_f = float(np.mean(flat.pixel_var)) / corr / flat.n / mean_s**2
    v_d = float(np.mean(dark.pixel_var)) / corr / dark.n / mean_s**2
    resid = residual_variance(rel, keep)
    x = (rel - np.mean(rel[keep]))[keep]
    kurt = float(np.mean(x**4) / np.var(x) ** 2)
    prnu2 = resid - v_f - v_d
    se = resid * math.sqrt((kurt - 1) / x.size)
    prnu = {"value": 100 * math.sqrt(max(prnu2, 0.0)),
            "ci95": [100 * math.sqrt(max(prnu2 - Z95 * se, 0.0)), 100 * math.sqrt(max(prnu2 + Z95 * se, 0.0))]}
    # column gain: what two halves of each column share (split_half_covariance), less the column means'
    # temporal noise (common to both halves too); the pixels' share of that noise is not common
    cov, se_g = split_half_covariance(rel, keep, "col")
    s2c_f = float(np.mean(centred_series(flat.col_means).var(axis=0, ddof=1))) / flat.n / mean_s**2
    s2c_d = float(np.mean(centred_series(dark.col_means).var(axis=0, ddof=1))) / dark.n / mean_s**2
    g2 = cov - (s2c_f - v_f / rows) - (s2c_d - v_d / rows)
    gain = {"value": 100 * math.sqrt(max(g2, 0.0)),
            "ci95": [100 * math.sqrt(max(g2 - Z95 * se_g, 0.0)), 100 * math.sqrt(max(g2 + Z95 * se_g, 0.0))]}
    return {"prnu_pct": prnu, "column_gain_pct": gain, "excluded_pixels": int((~keep).sum()), "signal_dn": mean_s,
            "relative_residual": x}


def crosstalk_from_spots(spot, dark, pattern: str, kernel_sum: float, saturation_dn: float) -> dict:
    """The crosstalk kernel from a stack of frames lit on single, well separated pixels (:class:`StackStats`).

    Each spot is a local maximum of (spot - dark), less the difference's
    common level (the median of the unlit pixels), that stands clear of its
    5 x 5 surroundings; the 3 x 3 charge around it, divided by its sum, is
    the fraction of the lit pixel's charge in itself and each neighbour. A
    spot measures how charge is shared, not how much is lost to the
    substrate, so the kernel is scaled to ``kernel_sum`` (the base's). With a
    CFA, one kernel per colour of the lit pixel. Returns ``{colour or "all":
    {"kernel_pct", "ci95_pct", "spots"}}``; the interval of each entry is
    the spots' spread (Student t).
    """
    from scipy import ndimage, stats

    sig = spot.mean - dark.mean
    rows, cols = sig.shape
    noise = math.sqrt(max(float(np.median(spot.pixel_var)) / spot.n + float(np.median(dark.pixel_var)) / dark.n, 1e-12))
    # the black level's error per frame does not average out of two stacks' means: a level common to the whole
    # difference, taken off as the median of the unlit pixels (within 5 noise sigmas of the difference's median:
    # the lit pixels' neighbours, a sixth of the frame, would pull a plain median up)
    centre = float(np.median(sig))
    sig = sig - float(np.median(sig[np.abs(sig - centre) < 5 * noise]))
    peak = (sig == ndimage.maximum_filter(sig, size=5)) & (sig > 50 * noise) & (spot.mean < 0.9 * saturation_dn)
    peak[:2, :] = peak[-2:, :] = False
    peak[:, :2] = peak[:, -2:] = False
    r, c = np.nonzero(peak)
    # the 5 x 5 ring outside the 3 x 3 must be dark: a spot, not an edge or a flat
    ring_ok = []
    for i, j in zip(r, c):
        win = sig[i - 2:i + 3, j - 2:j + 3].copy()
        win[1:4, 1:4] = 0
        ring_ok.append(float(np.abs(win).max()) < 0.02 * sig[i, j] + 5 * noise)
    r, c = r[np.array(ring_ok, bool)], c[np.array(ring_ok, bool)]
    if r.size < 3:
        raise CmosnoiseError(f"crosstalk: {r.size} isolated spot(s) found in the spot stack; the fit needs at least 3 "
                             "single lit pixels, each at least 3 pixels from the next and from the edge")
    k3 = np.stack([sig[i - 1:i + 2, j - 1:j + 2] / sig[i - 1:i + 2, j - 1:j + 2].sum() for i, j in zip(r, c)])
    colour = cfa_mod.channel_map(pattern, sig.shape)[r, c] if not cfa_mod.is_mono(pattern) else np.zeros(r.size, int)
    out = {}
    groups = {"all": np.ones(r.size, bool)} if cfa_mod.is_mono(pattern) else {
        name: colour == ch for ch, name in enumerate("RGB") if np.any(colour == ch)}
    if not cfa_mod.is_mono(pattern):
        groups["all"] = np.ones(r.size, bool)
    for name, sel in groups.items():
        k = k3[sel] * kernel_sum * 100
        n = int(sel.sum())
        mean = k.mean(axis=0)
        half = (float(stats.t.ppf(0.975, n - 1)) * k.std(axis=0, ddof=1) / math.sqrt(n)) if n > 1 else np.full((3, 3), np.inf)
        out[name] = {"kernel_pct": mean.tolist(), "ci95_pct": (np.stack([mean - half, mean + half], -1)).tolist(),
                     "spots": n}
    return out
