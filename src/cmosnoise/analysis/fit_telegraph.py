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

**Three levels (a trap seen through CDS).** A frame shows ``A (X(tau) -
X(0))``: ``-A``, 0 or ``+A``, each frame nearly independent of the last, so
the pixel has an excess variance but no lag-1 correlation. Those pixels get
a symmetric three-component normal mixture (levels ``mu - A``, ``mu``,
``mu + A``, weights ``q / 2``, ``1 - q``, ``q / 2``, one sigma), fitted by
expectation-maximization; one counts when ``A`` is at least SEPARATION
sigmas, the mixture beats one normal by the likelihood-ratio test at the Z
level (chi-square, 2 degrees of freedom) and each side level holds at least
:data:`MIN_SIDE_FRAMES` frames' worth. ``q = P(X(tau) != X(0)) = 2 pi0 pi1
(1 - e^(-s tau))`` is what the frames tell of the dwell times (not each one:
a trap much slower than the CDS interval is invisible, one much faster is
three-level at ``q = 2 pi0 pi1``).

Detection limits: a pixel whose levels are less than SEPARATION sigmas apart
is not found, nor one that does not switch both ways within the stack (a
dwell time much longer than the stack).
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
#: a three-level pixel's side levels must each hold at least this many frames' worth (q F / 2): fewer are a
#: heavy-tailed read noise's outliers as readily as a level (Tukey-lambda -0.1 noise over 64 frames gave 6 false
#: pixels of 49 152 at 2 frames' worth, each at 2 to 2.6)
MIN_SIDE_FRAMES = 5.0


def candidates(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Pixels whose series is not white noise at the array's level: (held, white, sigma0^2 DN^2), flat indices.

    ``frames``: (F, rows, cols) dark frames, DN. A candidate's temporal
    variance exceeds the array's median variance ``sigma0^2`` at the Z level
    (``(F - 1) v / sigma0^2`` against chi-square(F - 1)). ``held``: those whose
    lag-1 autocorrelation also exceeds ``Z / sqrt(F)`` (white noise: Normal(0,
    1 / F)): a level held over frames. ``white``: the others (a trap seen
    through CDS, or a noisy but Gaussian pixel).
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
    excess = var.ravel() > limit * max(sigma0, 1e-12)
    held = lag1.ravel() > Z / math.sqrt(f)
    return np.flatnonzero(excess & held), np.flatnonzero(excess & ~held), sigma0


def three_levels(series: np.ndarray, iterations: int = 300, tol: float = 1e-7):
    """Symmetric three-level normal mixtures of pixels' series, by expectation-maximization, all pixels at once.

    ``series``: (F, P) DN. Returns (centre, A, sigma, q, log-likelihood gain over one normal), each (P,); each
    pixel iterates until its log-likelihood rises by no more than ``tol`` of itself (or ``iterations`` pass),
    and then leaves the pixels still iterating (so that one slow pixel does not keep the others at work)."""
    x_all = np.asarray(series, np.float64)
    f = x_all.shape[0]
    mu = np.median(x_all, axis=0)
    sigma = np.maximum(1.4826 * np.median(np.abs(x_all - mu), axis=0), 1e-6)
    hi, lo = np.percentile(x_all, [97.5, 2.5], axis=0)
    a = np.maximum(np.maximum(hi - mu, mu - lo), 3 * sigma)
    q = np.full(mu.shape, 0.2)
    loglik = np.full(mu.shape, -np.inf)
    j = np.array([-1.0, 0.0, 1.0])
    sx_all = x_all.sum(axis=0)
    act = np.arange(mu.size)  # the pixels still iterating
    last = np.full(act.size, -np.inf)
    for _ in range(iterations):
        if act.size == 0:
            break
        x, sx = (x_all, sx_all) if act.size == mu.size else (x_all[:, act], sx_all[act])
        m, am, sg, qa = mu[act], a[act], sigma[act], q[act]
        w = np.stack([qa / 2, 1 - qa, qa / 2], axis=-1)  # (P, 3)
        z = (x[:, :, None] - m[:, None] - j * am[:, None]) / sg[:, None]  # (F, P, 3)
        logp = np.log(np.maximum(w, 1e-300)) - 0.5 * z * z - np.log(sg * math.sqrt(2 * math.pi))[:, None]
        top = logp.max(axis=2, keepdims=True)
        mix = top[..., 0] + np.log(np.exp(logp - top).sum(axis=2))  # (F, P)
        ll = mix.sum(axis=0)
        r = np.exp(logp - mix[..., None])  # responsibilities
        side = r[..., 0] + r[..., 2]
        sign = r[..., 2] - r[..., 0]
        q[act] = np.clip(side.mean(axis=0), 1e-9, 1 - 1e-9)
        # centre and amplitude by weighted least squares: sum r (x - mu - j a)^2 least
        s_sign, s_side, s_sx = sign.sum(axis=0), side.sum(axis=0), (sign * x).sum(axis=0)
        det = np.maximum(f * s_side - s_sign**2, 1e-12)
        m = (s_side * sx - s_sign * s_sx) / det
        am = np.abs((f * s_sx - s_sign * sx) / det)
        res = x[:, :, None] - m[:, None] - j * am[:, None]
        mu[act], a[act] = m, am
        sigma[act] = np.maximum(np.sqrt((r * res * res).sum(axis=(0, 2)) / f), 1e-6)
        loglik[act] = ll
        going = ~(ll - last < tol * np.abs(ll))
        act, last = act[going], ll[going]
    one = -0.5 * f * (np.log(2 * math.pi * np.maximum(x_all.var(axis=0), 1e-300)) + 1)
    return mu, a, sigma, q, loglik - one


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
        ``noise_dn`` (the array's temporal sigma); ``three_level``: the pixels a trap shows through CDS, with
        ``pixels``, ``amplitude_e``, ``switching`` (q, the fraction of frames at a side level), ``levels_dn``,
        ``ppm``, ``ppm_ci95``, ``median_amplitude_e`` and ``median_switching`` with their ``..._ci95``.
    """
    frames = np.asarray(frames)
    if frames.ndim != 3 or frames.shape[0] < 50:
        raise ValueError(f"a random telegraph fit needs a stack of at least 50 consecutive dark frames, got shape "
                         f"{frames.shape}")
    cand, white, sigma0 = candidates(frames)
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
    rng = np.random.default_rng(seed)
    out = {"pixels": found, "amplitude_e": amp, "tau_low_s": low, "tau_high_s": high, "levels_dn": levels,
           **_ppm(len(found), n), "candidates": int(cand.size), "noise_dn": math.sqrt(sigma0), "frames": f}
    for name, values in (("amplitude_e", amp), ("tau_low_s", low), ("tau_high_s", high)):
        out[f"median_{name}"], out[f"median_{name}_ci95"] = _median_interval(np.asarray(values, float), rng)
    # three-level pixels (a trap through CDS): white in time, a side level either way
    lr_limit = stats.chi2.isf(stats.norm.sf(Z), 2)
    tri, tri_amp, tri_q, tri_levels = [], [], [], []
    for start in range(0, white.size, 256):  # a block of pixels at a time (bounds the mixture's memory)
        block = white[start:start + 256]
        mus, amps, sigmas, qs, gains = three_levels(flat[:, block])
        for p, mu, a, sigma, q, gain in zip(block, mus, amps, sigmas, qs, gains):
            if a < SEPARATION * sigma or 2 * gain < lr_limit or q * f / 2 < MIN_SIDE_FRAMES:
                continue
            tri.append(int(p))
            tri_amp.append(float(a) / gain_dn_per_e)
            tri_q.append(float(q))
            tri_levels.append((float(mu - a), float(mu), float(mu + a)))
    three = {"pixels": tri, "amplitude_e": tri_amp, "switching": tri_q, "levels_dn": tri_levels,
             **_ppm(len(tri), n), "candidates": int(white.size)}
    for name, values in (("amplitude_e", tri_amp), ("switching", tri_q)):
        three[f"median_{name}"], three[f"median_{name}_ci95"] = _median_interval(np.asarray(values, float), rng)
    out["three_level"] = three
    return out


def _ppm(k: int, n: int) -> dict:
    ci = stats.binomtest(k, n).proportion_ci(0.95, method="exact")
    return {"ppm": 1e6 * k / n, "ppm_ci95": [1e6 * ci.low, 1e6 * ci.high]}


def through_cds(result: dict) -> bool:
    """Whether :func:`fit` found more three-level pixels (traps through CDS) than held ones: the population a
    ``source_follower.rts`` section (one readout) describes."""
    return len(result["three_level"]["pixels"]) > len(result["pixels"])


def section(result: dict, cds: bool | None = None, cds_interval_s: float = 1e-5) -> dict | None:
    """A ``source_follower.rts`` section from :func:`fit` (None where no pixel was found).

    ``cds``: False for the held levels (what a readout without CDS shows, and
    a blinking pixel), True for the three-level pixels (traps through CDS,
    ``cds_interval_s`` apart: the data's readout, which the frames do not tell),
    None for the population with more pixels (:func:`through_cds`). Amplitudes: lognormal, the
    median and the standard deviation of the logs of those found. Dwell times:
    log-uniform, its ends from the 10th and 90th percentiles of the logs
    (``q = a + p (b - a)`` for a uniform on ``[a, b]``), clipped to positive
    times. A three-level pixel's two dwell times are not told apart: each is
    the time ``t`` that gives its switching fraction with equal dwell times,
    ``q = (1 - e^(-2 tau / t)) / 2``, and both laws are the same.
    """
    if cds is None:
        cds = through_cds(result)
    found = result["three_level"] if cds else result
    if not found["pixels"]:
        return None

    def log_uniform(values):
        logs = np.log(np.asarray(values, float))
        logs = logs[np.isfinite(logs)]
        q10, q90 = np.percentile(logs, [10, 90])
        width = (q90 - q10) / 0.8
        a = q10 - 0.1 * width
        return {"min_s": float(np.exp(a)), "max_s": float(np.exp(a + width))}

    logs = np.log(np.asarray(found["amplitude_e"], float))
    out = {"enabled": True, "ppm": float(found["ppm"]), "traps_per_pixel": "one",
           "amplitude_e": {"distribution": "lognormal", "median": float(np.exp(np.median(logs))),
                           "sigma_log": float(logs.std(ddof=1)) if logs.size > 1 else 0.0}, "cds": bool(cds)}
    if cds:
        q = np.minimum(np.asarray(found["switching"], float), 0.49)
        equal = log_uniform(-2 * cds_interval_s / np.log1p(-2 * q))
        return {**out, "tau_capture_s": equal, "tau_emission_s": dict(equal), "cds_interval_s": cds_interval_s}
    return {**out, "tau_capture_s": log_uniform(result["tau_low_s"]), "tau_emission_s": log_uniform(result["tau_high_s"])}
