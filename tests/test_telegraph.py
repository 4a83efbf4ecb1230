"""Random telegraph noise in time (stages 6b and 4b): the two-state chain's laws, random access, the kernel's bits.

Every statistic is compared with its closed form within Z standard errors
of its estimator (conftest.Z), the standard error derived in place. The
chains are many independent traps (one per pixel index) with equal rates,
so a statistic at fixed frames is a mean of independent values.
"""

import math

import numpy as np
import pytest
from conftest import Z, assert_close, cli, on_threads, quiet_config
from scipy import stats

from cmosnoise import Sensor
from cmosnoise.engine import telegraph
from cmosnoise.engine.frame import kernel
from cmosnoise.engine.telegraph import Telegraphs
from cmosnoise.errors import CmosnoiseError
from cmosnoise.model.stages import random_telegraph

KEY = (0x1234, 0x5678)


def chains(n, tau_low, tau_high, size=1.0, first=0):
    """``n`` independent signals with the same dwell times, at pixels first .. first + n - 1, slot 0."""
    index = np.arange(first, first + n, dtype=np.uint64)
    full = np.full(n, 1.0)
    return Telegraphs(index, np.zeros(n, np.uint64), full * size, full * tau_low, full * tau_high)


def levels(pop, frames, dt, cds=None, sequence=0):
    """What each signal adds in each frame, (frames, n): the compiled trap output (the level with ``cds=None``)."""
    out = np.empty((len(frames), pop.index.size))
    k0, k1 = (np.uint64(w) for w in KEY)
    for i, f in enumerate(frames):
        kernel._trap_values(int(f), np.uint64(sequence), pop.up, pop.down, pop.size, pop.index, pop.slot, dt,
                            float(cds or 0.0), cds is not None, k0, k1, out[i])
    return out


def closed(tau_low, tau_high):
    s = 1 / tau_low + 1 / tau_high
    return s, tau_high / (tau_low + tau_high)


# ------------------------------------------------------------------ the chain
def test_the_state_of_a_frame_is_that_of_its_neighbours_descent():
    """frame_states(k) gives (X_k, X_k+1); frame_states(k + 1) must start from the same X_k+1, at any k: the
    dyadic bridge draws each node once, whichever frame asks."""
    pop = chains(4000, 0.7, 1.9)
    k0, k1 = (np.uint64(w) for w in KEY)
    for k in (0, 1, 2, 3, 7, 8, 1023, 999_999, 2**31 - 1, 2**31, 2**32 - 2):
        _, nxt = telegraph.frame_states(k, pop.up, pop.down, 1.0, pop.index, pop.slot, 0, k0, k1)
        here, _ = telegraph.frame_states(k + 1, pop.up, pop.down, 1.0, pop.index, pop.slot, 0, k0, k1)
        assert np.array_equal(nxt, here), k


def test_occupancy_and_lag_k_autocorrelation_of_the_level_match_the_two_state_chain():
    """P(X = 1) = tau_high / (tau_low + tau_high); Cov(X_0, X_k) = pi0 pi1 exp(-s k dt).

    Over n independent chains at fixed frames, the mean of X has se sqrt(pi0 pi1 / n); the mean of the
    product of centred values has se = its sample std / sqrt(n) (CLT).
    """
    tau_low, tau_high, dt, n = 2.0, 3.0, 1.0, 100_000
    s, pi1 = closed(tau_low, tau_high)
    frames = [123_456, 123_457, 123_459, 123_462]
    x = levels(chains(n, tau_low, tau_high), frames, dt)
    assert_close(x[0].mean(), pi1, math.sqrt(pi1 * (1 - pi1) / n), "occupancy")
    c = x - pi1
    for i, f in enumerate(frames[1:], 1):
        lag = f - frames[0]
        prod = c[0] * c[i]
        assert_close(prod.mean(), pi1 * (1 - pi1) * math.exp(-s * lag * dt), prod.std() / math.sqrt(n),
                     f"covariance at lag {lag}")


def test_dwell_times_in_frames_follow_the_geometric_law_of_the_frame_rate():
    """Runs of state 1 in the frame-sampled chain are geometric: P(L = l) = p^(l-1) (1 - p), with
    p = pi1 + pi0 exp(-s dt). Runs cut by the record's ends are left out; a chi-square test at the Z level."""
    tau_low, tau_high, dt = 0.05, 0.12, 0.033
    s, pi1 = closed(tau_low, tau_high)
    stay = pi1 + (1 - pi1) * math.exp(-s * dt)
    x = levels(chains(300, tau_low, tau_high), range(5000, 6500), dt)
    runs = []
    for seq in x.T:  # the runs of 1s, less the first and last (cut by the record's ends, whatever state they are)
        edges = np.flatnonzero(np.diff(np.r_[0, seq, 0]))
        lengths = edges[1::2] - edges[0::2]
        runs.extend(lengths[1:-1].tolist())
    runs = np.asarray(runs)
    top = 12
    observed = np.array([np.sum(runs == length) for length in range(1, top)] + [np.sum(runs >= top)])
    pmf = [stay ** (length - 1) * (1 - stay) for length in range(1, top)]
    expected = runs.size * np.array(pmf + [1 - sum(pmf)])
    chi2 = float(np.sum((observed - expected) ** 2 / expected))
    p = stats.chi2.sf(chi2, observed.size - 1)
    assert p > 2 * stats.norm.sf(Z), f"chi2 {chi2:.1f} over {observed.size - 1} dof, p = {p:.2g}"


def test_cds_output_of_a_trap_comparable_to_its_interval_has_the_closed_form_levels_and_autocorrelation():
    """Y = A (X(t + tau) - X(t)): P(Y = A) = P(Y = -A) = pi0 pi1 (1 - exp(-s tau)) and
    Cov(Y_0, Y_k) = -A^2 pi0 pi1 exp(-s k dt) (exp(s tau) + exp(-s tau) - 2), both from C(t) = pi0 pi1 exp(-s|t|)."""
    tau_low, tau_high, dt, tau, a, n = 1.0, 2.0, 1.0, 0.5, 3.0, 100_000
    s, pi1 = closed(tau_low, tau_high)
    pi0 = 1 - pi1
    y = levels(chains(n, tau_low, tau_high, size=a), [4000, 4001, 4002], dt, cds=tau)
    assert set(np.unique(y)) <= {-a, 0.0, a}
    side = pi0 * pi1 * (1 - math.exp(-s * tau))
    for value in (a, -a):
        assert_close(np.mean(y[0] == value), side, math.sqrt(side * (1 - side) / n), f"P(Y = {value})")
    for lag in (1, 2):
        prod = y[0] * y[lag]
        expected = -a * a * pi0 * pi1 * math.exp(-s * lag * dt) * (math.exp(s * tau) + math.exp(-s * tau) - 2)
        assert_close(prod.mean(), expected, prod.std() / math.sqrt(n), f"CDS covariance at lag {lag}")


def test_a_fast_trap_is_three_level_and_a_slow_one_is_zero_after_cds_but_held_without():
    """Far faster than the CDS interval: the two samples are independent, P(+-A) = pi0 pi1, P(0) = pi0^2 + pi1^2
    (chi-square). Far slower: nonzero in a fraction 2 pi0 pi1 (1 - exp(-s tau)) of frames (binomial), and
    without CDS the level is held from frame to frame (lag-1 agreement exp(-s dt) close to 1)."""
    dt, tau, a, n = 1 / 30, 1e-5, 5.0, 50_000
    tl, th = fast_taus = (1e-8 * 0.7 / 0.3, 1e-8)  # switching every 10 ns against a 10 us interval; pi1 = 0.3
    fast = levels(chains(n, *fast_taus, size=a), [77], dt, cds=tau)[0]
    pi1 = th / (tl + th)
    probs = np.array([pi1 * (1 - pi1), pi1**2 + (1 - pi1) ** 2, pi1 * (1 - pi1)])
    observed = np.array([np.sum(fast == -a), np.sum(fast == 0), np.sum(fast == a)])
    chi2 = float(np.sum((observed - n * probs) ** 2 / (n * probs)))
    assert stats.chi2.sf(chi2, 2) > 2 * stats.norm.sf(Z), (observed, n * probs)

    slow_taus = (20.0, 30.0)
    s, pi1 = closed(*slow_taus)
    slow = levels(chains(n, *slow_taus, size=a, first=n), [77], dt, cds=tau)[0]
    frac = 2 * pi1 * (1 - pi1) * (1 - math.exp(-s * tau))
    hits = int(np.sum(slow != 0))
    # n frac is 0.02: the binomial's own quantiles at the two-sided Z level, not its normal approximation
    alpha = stats.norm.sf(Z)
    assert stats.binom.ppf(alpha, n, frac) <= hits <= stats.binom.isf(alpha, n, frac), (hits, n * frac)
    held = levels(chains(n, *slow_taus, size=a, first=n), [77, 78], dt)
    assert set(np.unique(held)) <= {0.0, a}
    same = np.mean(held[0] == held[1])
    p_same = 1 - 2 * pi1 * (1 - pi1) * (1 - math.exp(-s * dt))
    assert_close(same, p_same, math.sqrt(p_same * (1 - p_same) / n), "no CDS: level held over a frame")


def test_a_blinking_pixels_exposure_integral_has_the_closed_form_mean_variance_and_autocorrelation():
    """O = time high in [t_k, t_k + T]: E O = pi1 T; Var O = 2 pi0 pi1 (T / s - (1 - e^-sT) / s^2);
    Cov(O_0, O_k) = pi0 pi1 e^(-s k dt) (e^(sT) - 1)(1 - e^(-sT)) / s^2 (from C(t) = pi0 pi1 e^(-s|t|)).
    Means over n independent pixels, se from the sample (CLT). The uniformization draws exactly."""
    tau_low, tau_high, dt, exposure, n = 0.4, 0.6, 1.0, 0.8, 40_000
    s, pi1 = closed(tau_low, tau_high)
    pi0 = 1 - pi1
    pop = chains(n, tau_low, tau_high)
    k0, k1 = (np.uint64(w) for w in KEY)
    occ = np.empty((2, n))
    for i, f in enumerate((500, 501)):
        kernel._blink_values(f, np.uint64(0), pop.up, pop.down, pop.size, pop.index, pop.slot, dt, exposure, k0, k1,
                             occ[i])
    assert np.all((occ >= 0) & (occ <= exposure * (1 + 1e-15)))  # a sum of intervals, to rounding
    assert_close(occ[0].mean(), pi1 * exposure, occ[0].std() / math.sqrt(n), "mean time high")
    var = 2 * pi0 * pi1 * (exposure / s - (1 - math.exp(-s * exposure)) / s**2)
    dev = (occ[0] - pi1 * exposure) ** 2
    assert_close(dev.mean(), var, dev.std() / math.sqrt(n), "variance of the time high")
    prod = (occ[0] - pi1 * exposure) * (occ[1] - pi1 * exposure)
    cov = pi0 * pi1 * math.exp(-s * dt) * (math.exp(s * exposure) - 1) * (1 - math.exp(-s * exposure)) / s**2
    assert_close(prod.mean(), cov, prod.std() / math.sqrt(n), "lag-1 covariance of the time high")


def test_the_numpy_specification_and_the_compiled_signals_agree_bit_for_bit():
    rng = np.random.default_rng(3)
    n = 300
    pop = Telegraphs(np.sort(rng.choice(10**6, n, replace=False)).astype(np.uint64), np.zeros(n, np.uint64),
                     rng.uniform(1, 9, n), 10 ** rng.uniform(-6, 1, n), 10 ** rng.uniform(-6, 1, n))
    for frame in (0, 5, 2**20 + 3):
        for cds in (None, 2e-3):
            ours = random_telegraph.trap_output(pop, frame, 2, 0.01, cds, KEY)
            assert np.array_equal(ours, levels(pop, [frame], 0.01, cds, sequence=2)[0])
        k0, k1 = (np.uint64(w) for w in KEY)
        blink = Telegraphs(pop.index, pop.slot, pop.size, pop.tau_low_s * 1e5, pop.tau_high_s * 1e5)
        compiled = np.empty(n)
        kernel._blink_values(frame, np.uint64(2), blink.up, blink.down, blink.size, blink.index, blink.slot, 0.5, 0.4,
                             k0, k1, compiled)
        assert np.array_equal(random_telegraph.blink_charge(blink, frame, 2, 0.5, 0.4, KEY), compiled)


# ------------------------------------------------------------------ the populations (fixed pattern)
def test_trap_population_has_its_ppm_amplitude_law_and_log_uniform_dwell_times():
    """Affected pixels ~ Binomial(N, ppm 1e-6) (Z sigma); amplitudes lognormal and dwell times log-uniform
    (KS at the two-sided Z level); Poisson trap counts follow the zero-truncated Poisson law (chi-square)."""
    shape = (600, 800)
    law = quiet_config(source_follower={"enabled": True, "rts": {"enabled": True, "ppm": 20000,
                                                                 "traps_per_pixel": "poisson"}}).source_follower.rts
    traps = random_telegraph.draw_traps(law, KEY, shape)
    n, p = shape[0] * shape[1], law.ppm * 1e-6
    pixels, counts = np.unique(traps.index, return_counts=True)
    assert abs(pixels.size - n * p) <= Z * math.sqrt(n * p * (1 - p))
    alpha = 2 * stats.norm.sf(Z)
    amp = law.amplitude_e
    assert stats.kstest(traps.size, stats.lognorm(s=amp.sigma_log, scale=amp.median).cdf).pvalue > alpha
    for taus, values in ((law.tau_capture_s, traps.tau_low_s), (law.tau_emission_s, traps.tau_high_s)):
        assert stats.kstest(np.log(values), stats.uniform(math.log(taus.min_s), math.log(taus.max_s / taus.min_s)).cdf
                            ).pvalue > alpha
    lam = -math.log1p(-p)
    pmf = np.array([stats.poisson.pmf(k, lam) for k in (1, 2)]) / (1 - math.exp(-lam))
    observed = np.array([np.sum(counts == 1), np.sum(counts >= 2)])
    expected = pixels.size * np.array([pmf[0], 1 - pmf[0]])
    chi2 = float(np.sum((observed - expected) ** 2 / expected))
    assert stats.chi2.sf(chi2, 1) > alpha, (observed, expected)


def test_a_tile_of_the_population_is_the_same_tile_of_the_whole():
    law = quiet_config(source_follower={"enabled": True, "rts": {"enabled": True, "ppm": 5000}}).source_follower.rts
    whole = random_telegraph.draw_traps(law, KEY, (300, 400))
    sub = whole.within((100, 200, 50, 300), 400)
    again = random_telegraph.draw_traps(law, KEY, (300, 400)).within((100, 200, 50, 300), 400)
    assert sub.index.size > 0 and all(np.array_equal(getattr(sub, f), getattr(again, f)) for f in
                                      ("index", "slot", "size", "tau_low_s", "tau_high_s"))


# ------------------------------------------------------------------ frames
def rts_sensor(**extra):
    base = {"sensor": {"width": 96, "height": 64, "frame_rate_hz": 30},
            "source_follower": {"rts": {"enabled": True, "ppm": 30000, "traps_per_pixel": "poisson",
                                        "tau_capture_s": {"min_s": 1e-6, "max_s": 1e-3},
                                        "tau_emission_s": {"min_s": 1e-6, "max_s": 1e-3}}},
            "dark_current": {"rts": {"enabled": True, "ppm": 30000, "tau_low_s": {"min_s": 0.05, "max_s": 5},
                                     "tau_high_s": {"min_s": 0.05, "max_s": 5}}}}
    for k, v in extra.items():
        base[k] = {**base.get(k, {}), **v}
    return Sensor(base, seed=11)


def test_frames_with_rts_equal_the_numpy_specification_crops_and_far_frames_included():
    shot = rts_sensor().expose("flat:0.3")
    for k in (0, 1, 1_000_000):
        whole = shot.frame(k, detail=True)
        assert np.array_equal(whole.raw, shot.frame(k)), k
        assert np.abs(whole.contributions["source_follower_rts"]).max() > 0
        assert np.abs(whole.contributions["dark_current_rts"]).max() > 0
        part = (5, 40, 17, 90)
        assert np.array_equal(shot.frame(k, region=part), whole.raw[5:40, 17:90])
    parts = [v.astype(np.float64) for name, v in whole.contributions.items()
             if name not in ("quantization", "black_level", "read_noise")]
    # each part is float32, rounded by at most half an ulp of its magnitude; the electrons too
    bound = sum(np.spacing(np.abs(v).astype(np.float32)).astype(np.float64) / 2 for v in parts)
    bound = bound + np.spacing(np.abs(whole.electrons).astype(np.float32)) / 2
    assert np.all(np.abs(sum(parts) - whole.electrons) <= bound)


def test_frame_a_million_alone_equals_it_in_a_sequence_and_does_not_depend_on_threads():
    sensor = rts_sensor()
    shot = sensor.expose("flat:0.2")
    run = sensor.capture("flat:0.2", frames=3, first_frame=999_999)
    alone = shot.frame(1_000_000)  # its speed is benchmarks/bench_telegraph.py's, not a timed test's
    assert np.array_equal(alone, run[1])
    assert np.array_equal(on_threads(1, lambda: shot.frame(1_000_000)), alone)


def test_with_rts_off_frames_are_unchanged_and_a_ppm_change_moves_only_the_affected_pixels():
    plain = Sensor({"sensor": {"width": 96, "height": 64}}, seed=11).expose("flat:0.3").frame(4)
    off = rts_sensor(source_follower={"rts": {"enabled": False}},
                     dark_current={"rts": {"enabled": False}}).expose("flat:0.3").frame(4)
    assert np.array_equal(plain, off)
    few = rts_sensor(source_follower={"rts": {"ppm": 1000}}, dark_current={"rts": {"ppm": 1000}})
    many = rts_sensor()
    moved = few.expose("flat:0.3").frame(4) != many.expose("flat:0.3").frame(4)
    cols = 96
    touched = np.zeros((64, 96), bool)
    for pop in (many.fixed_pattern.traps, many.fixed_pattern.blinkers):
        i = pop.index.astype(np.int64)
        touched[i // cols, i % cols] = True
    assert moved.any() and not (moved & ~touched).any()


@pytest.mark.parametrize("setting, words", [
    ("source_follower.rts.tau_capture_s.min_s=0", "tau_capture_s.min_s"),
    ("source_follower.rts.amplitude_e.sigma_log=null", "lognormal"),
    ("source_follower.rts.cds_interval_s=0.5", "cds_interval_s"),
    ("sensor.frame_rate_hz=1000", "frame_rate_hz"),
])
def test_bad_rts_settings_get_one_line_and_exit_2(tmp_path, setting, words):
    r = cli("simulate", "--set", "source_follower.rts.enabled=true", "--set", "dark_current.rts.enabled=true",
            "--set", setting, "--out", tmp_path / "out")
    assert r.returncode == 2, r.stderr
    lines = [line for line in r.stderr.strip().splitlines() if line.strip()]
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


def test_another_exposure_of_the_same_sensor_meets_the_same_timing_check():
    """Sensor.with_exposure skips what nothing implies, but not the frame timing an exposure meets."""
    sensor = rts_sensor()  # 30 frames/s
    assert sensor.with_exposure(integration_time_s=0.02).config.exposure.integration_time_s == 0.02
    with pytest.raises(CmosnoiseError, match="frame_rate_hz"):
        sensor.with_exposure(integration_time_s=0.1)


# ------------------------------------------------------------------ the noise budget
def budget_sensor(cds: bool) -> Sensor:
    """Only the random telegraph pixels move between frames' contributions: traps with dwell times near the CDS
    interval (10 us), blinking pixels of 0.05 to 2 s over a 20 ms exposure, the dark current without shot noise
    (a blinking pixel's contribution is then its step times its time high)."""
    cfg = quiet_config(
        sensor={"width": 96, "height": 64, "frame_rate_hz": 30},
        exposure={"integration_time_s": 0.02},
        source_follower={"enabled": True, "rts": {"enabled": True, "ppm": 60000, "traps_per_pixel": "poisson", "cds": cds,
                                                  "tau_capture_s": {"min_s": 2e-6, "max_s": 1e-4},
                                                  "tau_emission_s": {"min_s": 2e-6, "max_s": 1e-4}}},
        dark_current={"enabled": True, "shot_noise": False,
                      "rts": {"enabled": True, "ppm": 60000, "tau_low_s": {"min_s": 0.05, "max_s": 2},
                              "tau_high_s": {"min_s": 0.05, "max_s": 2}}})
    return Sensor(cfg, seed=5)


@pytest.mark.parametrize("cds", [True, False])
def test_the_noise_budget_holds_the_variance_and_mean_the_random_telegraph_pixels_show(cds):
    """The budget's ``rts_traps`` and ``rts_blinking`` lines are the array means of each pixel's stationary
    variance (trap_moments, blink_moments); frames 1000 apart (33 s: every chain forgets, e^(-33 s / 2 s) < 1e-7)
    are independent, so each pixel's mean square deviation from its stationary mean over F frames, summed over
    pixels, estimates the summed variance with the standard error sqrt(sum_i Var((x_i - mu_i)^2) / F) (the
    variances estimated from the sample); the summed frame means estimate the summed stationary means likewise."""
    from cmosnoise.analysis import noise_budget

    sensor = budget_sensor(cds)
    n = sensor.shape[0] * sensor.shape[1]
    shot = sensor.expose("flat:0")
    frames = [shot.frame(1000 * k, detail=True).contributions for k in range(60)]
    tv = noise_budget.temporal_variances(sensor, 0.0)
    fv = noise_budget.fixed_pattern_variances(sensor, 0.0)
    moments = noise_budget.telegraph_moments(sensor)
    for part, line in (("source_follower_rts", "traps"), ("dark_current_rts", "blinking")):
        pixels, m, v = moments[line]
        mean, var = np.zeros(n), np.zeros(n)  # as maps: every pixel's stationary mean and variance
        mean[pixels.astype(np.int64)], var[pixels.astype(np.int64)] = m, v
        mean, var = mean.reshape(sensor.shape), var.reshape(sensor.shape)
        x = np.stack([c[part].astype(np.float64) for c in frames])  # (F, rows, cols)
        f = x.shape[0]
        dev = (x - mean) ** 2
        assert_close(dev.mean(axis=0).sum(), var.sum(), math.sqrt(dev.var(axis=0, ddof=1).sum() / f),
                     f"{line}: summed temporal variance")
        assert_close(x.mean(axis=0).sum(), mean.sum(), math.sqrt(x.var(axis=0, ddof=1).sum() / f),
                     f"{line}: summed stationary mean")
        name = "rts_" + line
        assert tv[name] == pytest.approx(var.sum() / n, rel=1e-12)  # no column gain, no nonlinearity here
        fixed = "rts_level" if line == "traps" else "rts_blinking"
        if line == "traps" and cds:
            assert fixed not in fv and not mean.any()  # CDS takes the level away
        else:
            assert fv[fixed] == pytest.approx(np.var(mean), rel=1e-9)
