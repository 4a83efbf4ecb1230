"""Random telegraph pixels from a long dark stack: which pixels, their amplitudes and dwell times, with intervals.

A pixel whose level switches between two values over the frames (a trap
read without CDS, a blinking white pixel) is found in two steps:

1. **Candidates**: its temporal variance over the ``F`` frames exceeds the
   array's noise: ``(F - 1) v / sigma0^2`` above the chi-square(F - 1)
   quantile at the Z level (``sigma0^2``: the median of the per-pixel
   variances; random telegraph pixels are parts per million).
2. **Two levels**: a two-state Gaussian hidden Markov model
   (``hmmlearn.hmm.GaussianHMM``, one shared variance) fitted to its time
   series; it is a random telegraph pixel when its two levels are at least
   :data:`SEPARATION` within-state sigmas apart and it switches both ways. A
   pixel with a large but Gaussian noise (a flicker-tail pixel) fits two
   close levels and is left out.

Each pixel's amplitude is the distance of its levels (e-, through K); its
dwell times come from the HMM's per-frame transition probabilities of the
sampled two-state chain: ``p01 + p10 = 1 - exp(-s dt)``,
``pi1 = p01 / (p01 + p10)``, so ``tau_low = 1 / (pi1 s)`` and
``tau_high = 1 / (pi0 s)``. The population's ppm has the Clopper-Pearson
interval; the medians of the amplitudes and dwell times have percentile
bootstrap intervals over the pixels found (fixed seed).

Detection limits: a pixel whose levels are less than SEPARATION sigmas apart
is not found, nor one that does not switch both ways within the stack (a
dwell time much longer than the stack). A trap seen through CDS (three
levels, each frame nearly independent) is not a two-level pixel; its
change is counted among the candidates only.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

#: two levels count as a random telegraph pixel when at least this many within-state sigmas apart
SEPARATION = 3.0
#: standard normal quantile of the candidate test (one-sided): the suite's Z
Z = 5.0
#: bootstrap resamples of the medians' intervals
BOOTSTRAP = 2000


def candidates(frames: np.ndarray) -> tuple[np.ndarray, float]:
    """Pixels whose series is not white noise at the array's level: (flat indices, sigma0^2 DN^2).

    ``frames``: (F, rows, cols) dark frames, DN. A candidate's temporal
    variance exceeds the array's median variance ``sigma0^2`` at the Z level
    (``(F - 1) v / sigma0^2`` against chi-square(F - 1)), and its lag-1
    autocorrelation exceeds ``Z / sqrt(F)`` (white noise: Normal(0, 1 / F)).
    A level held over frames is both; a noisy but white pixel is not the second.
    """
    f = frames.shape[0]
    var = np.empty(frames.shape[1:])
    lag1 = np.empty(frames.shape[1:])
    for r in range(frames.shape[1]):  # a row at a time: float64 copies of one row of the stack
        x = frames[:, r].astype(np.float64)
        x = x - x.mean(axis=0)
        var[r] = (x * x).sum(axis=0) / (f - 1)
        lag1[r] = (x[1:] * x[:-1]).sum(axis=0) / np.maximum((x * x).sum(axis=0), 1e-300)
    sigma0 = float(np.median(var))
    limit = stats.chi2.isf(stats.norm.sf(Z), f - 1) / (f - 1)
    held = (var.ravel() > limit * max(sigma0, 1e-12)) & (lag1.ravel() > Z / math.sqrt(f))
    return np.flatnonzero(held), sigma0


def two_levels(series: np.ndarray, seed: int = 0):
    """A two-state Gaussian HMM of one pixel's series (DN): (low level, high level, within sigma, p01, p10) with
    state 1 the higher level."""
    from hmmlearn.hmm import GaussianHMM

    x = series.astype(np.float64).reshape(-1, 1)
    lo, hi = np.percentile(x, [10, 90])
    model = GaussianHMM(n_components=2, covariance_type="tied", n_iter=200, tol=1e-4, random_state=seed,
                        init_params="", params="stmc")
    model.startprob_ = np.array([0.5, 0.5])
    model.transmat_ = np.array([[0.9, 0.1], [0.1, 0.9]])
    model.means_ = np.array([[lo], [hi]])
    model.covars_ = np.array([[max(float(x.var()) / 4, 1e-6)]])
    model.fit(x)
    means = model.means_.ravel()
    order = np.argsort(means)
    t = model.transmat_[np.ix_(order, order)]
    sigma = math.sqrt(float(np.ravel(model.covars_)[0]))
    return float(means[order[0]]), float(means[order[1]]), sigma, float(t[0, 1]), float(t[1, 0])


def rates(p01: float, p10: float, dt: float) -> tuple[float, float]:
    """Mean dwell times (s) in the low and the high state from the per-frame transition probabilities of a two-state
    chain sampled every ``dt`` seconds."""
    total = p01 + p10
    if not 0 < total < 1:
        return math.nan, math.nan
    s = -math.log1p(-total) / dt
    pi1 = p01 / total
    return 1 / (pi1 * s), 1 / ((1 - pi1) * s)


def _median_interval(values: np.ndarray, rng: np.random.Generator) -> tuple[float, list[float]]:
    values = values[np.isfinite(values)]
    if values.size == 0:
        return math.nan, [math.nan, math.nan]
    boot = np.median(rng.choice(values, (BOOTSTRAP, values.size)), axis=1)
    return float(np.median(values)), [float(v) for v in np.percentile(boot, [2.5, 97.5])]


def fit(frames: np.ndarray, gain_dn_per_e: float, frame_period_s: float, seed: int = 0) -> dict:
    """The random telegraph pixels of a dark stack.

    Parameters
    ----------
    frames : ndarray, (F, rows, cols)
        Consecutive dark frames, DN (at least 50).
    gain_dn_per_e : float
        The system gain K, DN/e-: amplitudes are given in e-.
    frame_period_s : float
        Seconds between two frames' starts: dwell times are given in s.

    Returns
    -------
    dict
        ``pixels`` (flat indices found), ``amplitude_e``, ``tau_low_s``, ``tau_high_s``, ``levels_dn`` (the
        two levels, DN) (one per pixel), ``ppm``
        with ``ppm_ci95`` (Clopper-Pearson), ``median_amplitude_e``, ``median_tau_low_s``,
        ``median_tau_high_s`` each with a ``..._ci95`` (bootstrap over the pixels), ``candidates`` and
        ``noise_dn`` (the array's temporal sigma).
    """
    frames = np.asarray(frames)
    if frames.ndim != 3 or frames.shape[0] < 50:
        raise ValueError(f"a random telegraph fit needs a stack of at least 50 consecutive dark frames, got shape "
                         f"{frames.shape}")
    cand, sigma0 = candidates(frames)
    f = frames.shape[0]
    flat = frames.reshape(f, -1)
    found, amp, low, high, levels = [], [], [], [], []
    for p in cand:
        lo, hi, sigma, p01, p10 = two_levels(flat[:, p], seed)
        if hi - lo < SEPARATION * sigma or p01 <= 0 or p10 <= 0:
            continue
        t_low, t_high = rates(p01, p10, frame_period_s)
        found.append(int(p))
        levels.append((lo, hi))
        amp.append((hi - lo) / gain_dn_per_e)
        low.append(t_low)
        high.append(t_high)
    n = flat.shape[1]
    k = len(found)
    ci = stats.binomtest(k, n).proportion_ci(0.95, method="exact")
    rng = np.random.default_rng(seed)
    out = {"pixels": found, "amplitude_e": amp, "tau_low_s": low, "tau_high_s": high, "levels_dn": levels,
           "ppm": 1e6 * k / n, "ppm_ci95": [1e6 * ci.low, 1e6 * ci.high], "candidates": int(cand.size),
           "noise_dn": math.sqrt(sigma0), "frames": f}
    for name, values in (("amplitude_e", amp), ("tau_low_s", low), ("tau_high_s", high)):
        out[f"median_{name}"], out[f"median_{name}_ci95"] = _median_interval(np.asarray(values, float), rng)
    return out


def section(result: dict, cds: bool = False) -> dict | None:
    """A ``source_follower.rts`` section from :func:`fit` (None where no pixel was found).

    Amplitudes: lognormal, the median and the standard deviation of the logs
    of those found. Dwell times: log-uniform, its ends from the 10th and 90th
    percentiles of the logs (``q = a + p (b - a)`` for a uniform on
    ``[a, b]``), clipped to positive times. ``cds``: what the data's readout
    does (a held level is what a readout without CDS shows).
    """
    if not result["pixels"]:
        return None

    def log_uniform(values):
        logs = np.log(np.asarray(values, float))
        logs = logs[np.isfinite(logs)]
        q10, q90 = np.percentile(logs, [10, 90])
        width = (q90 - q10) / 0.8
        a = q10 - 0.1 * width
        return {"min_s": float(np.exp(a)), "max_s": float(np.exp(a + width))}

    logs = np.log(np.asarray(result["amplitude_e"], float))
    return {"enabled": True, "ppm": float(result["ppm"]), "traps_per_pixel": "one",
            "amplitude_e": {"distribution": "lognormal", "median": float(np.exp(np.median(logs))),
                            "sigma_log": float(logs.std(ddof=1)) if logs.size > 1 else 0.0},
            "tau_capture_s": log_uniform(result["tau_low_s"]), "tau_emission_s": log_uniform(result["tau_high_s"]),
            "cds": cds}
