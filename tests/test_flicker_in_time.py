"""1/f noise in time (#76): the Gauss-Markov bridges that sample it, the McWhorter sum that makes it 1/f, and the
row noise in readout order and the column amplifiers over frames that use it. Statistics are tested as
statistics: each tolerance says which estimator's spread it is five standard errors of."""

import math

import numpy as np
import pytest
from conftest import cli
from scipy import integrate, signal

from cmosnoise import Sensor, load_config
from cmosnoise.engine import gauss_markov as gm
from cmosnoise.model import one_over_f

QUIET = {"prnu": {"enabled": False}, "crosstalk": {"enabled": False}, "shot_noise": {"enabled": False},
         "dark_current": {"enabled": False}, "source_follower": {"enabled": False}, "row_noise": {"enabled": False},
         "column_noise": {"enabled": False}, "read_noise": {"enabled": False}, "pixel_offset": {"enabled": False},
         "nonlinearity": {"enabled": False}, "defects": {"enabled": False},
         "adc": {"enabled": True, "bits": 16, "gain_dn_per_e": 4.0, "black_level_dn": 1000},
         "exposure": {"integration_time_s": 0.02}}
FPS = 30.0
ROW = {"row_noise": {"enabled": True, "sigma_e": 2.0, "spectrum": "one_over_f"}}
COLUMN = {"column_noise": {"enabled": True, "vfpn_sigma_e": 0.0,
                           "temporal": {"enabled": True, "gumbel_loc_e": 2.0, "gumbel_scale_e": 0.3,
                                        "spectrum": "one_over_f"}}}


def _config(extra: dict, rows: int = 48, cols: int = 64):
    out = {k: dict(v) for k, v in QUIET.items()}
    for k, v in extra.items():
        out[k] = {**out.get(k, {}), **v}
    out["sensor"] = {"width": cols, "height": rows, "frame_rate_hz": FPS, **out.get("sensor", {})}
    return load_config(extra=out)


def _slope(f, p, band):
    """The log-log slope of a Welch spectrum over ``band`` and its standard error. Each Welch bin of M averaged
    segments has ln P spread about ``1/sqrt(M)``; the slope's standard error is the regression's (residual spread
    over the spread of ln f), times sqrt(2) because a Hann window's neighbouring bins are correlated."""
    x, y = np.log(f[band]), np.log(p[band])
    (slope, icpt), res, *_ = np.polyfit(x, y, 1, full=True)
    s = math.sqrt(float(res[0]) / (x.size - 2))
    return float(slope), math.sqrt(2.0) * s / math.sqrt(float(np.sum((x - x.mean()) ** 2)))


# ------------------------------------------------------------------ the bridges
def test_a_block_of_the_process_is_the_same_bits_wherever_it_is_made():
    rates, weights = 2 * np.pi * np.array([0.3, 7.0, 150.0]), np.array([0.5, 0.3, 0.2])
    whole = gm.sample(rates, weights, 1e-3, 0, 5000, (11, 12), 3)
    for a, b in ((0, 1), (1, 2), (4095, 4097), (1234, 5000), (2000, 2100)):
        np.testing.assert_array_equal(gm.sample(rates, weights, 1e-3, a, b, (11, 12), 3), whole[a:b])
    far = gm.sample(rates, weights, 1e-3, 2**40, 2**40 + 300, (11, 12), 3)
    np.testing.assert_array_equal(gm.sample(rates, weights, 1e-3, 2**40 + 100, 2**40 + 120, (11, 12), 3),
                                  far[100:120])
    lanes = gm.sample(rates, weights, 1e-3, 10, 20, (11, 12), 3, lanes=np.arange(5, 40))
    np.testing.assert_array_equal(gm.sample(rates, weights, 1e-3, 12, 13, (11, 12), 3, lanes=[7, 30])[:, 0],
                                  lanes[[2, 25], 2])
    assert not np.array_equal(lanes[0], lanes[1])  # each lane its own process
    assert not np.array_equal(gm.sample(rates, weights, 1e-3, 0, 50, (11, 12), 4), whole[:50])  # each sequence


def test_one_component_has_unit_variance_and_an_exponential_correlation():
    lam, dt, n = 2.0, 0.01, 2**20
    x = gm.sample(np.array([lam]), np.array([1.0]), dt, 0, n, (3, 4), 0)
    a = math.exp(-lam * dt)
    # the sample variance of an AR(1) series: Var(s^2) ~ 2 sum_k rho_k^2 / n = 2 (1 + a^2) / ((1 - a^2) n)
    se_var = math.sqrt(2 * (1 + a * a) / ((1 - a * a) * n))
    assert abs(x.var() - 1.0) < 5 * se_var
    # Bartlett's variance of an AR(1)'s lag-k autocorrelation estimate:
    # (1/n) [(1 + a^2)(1 - a^2k) / (1 - a^2) - 2 k a^2k]
    for k in (1, 10, 50):
        rho = float(np.mean(x[:-k] * x[k:]) / np.mean(x * x))
        se = math.sqrt(((1 + a * a) * (1 - a ** (2 * k)) / (1 - a * a) - 2 * k * a ** (2 * k)) / n)
        assert abs(rho - a**k) < 5 * se, (k, rho, a**k, se)
    # the top level's nodes and the bridges' midpoints have the law's variance alike (no seam at a top node)
    top = 2 ** gm.top_level(lam, dt)
    for offset in (0, 1, top // 2):
        sel = x[offset::top]
        assert abs(sel.var() - 1.0) < 5 * math.sqrt(2.0 / sel.size), offset


def test_the_bridge_coefficients_are_the_exact_conditional_law():
    rate, dt = 5.0, 0.01
    weight, sigma = gm.bridge_constants(rate, dt, 6)
    for level in range(6):
        a = math.exp(-rate * dt * 2**level)
        assert weight[level] == pytest.approx(a / (1 + a * a), rel=1e-13)
        assert sigma[level] == pytest.approx(math.sqrt((1 - a * a) / (1 + a * a)), rel=1e-12)
    for x in (1e-9, 1e-4, 0.05, 0.0999, 0.1, 3.0):
        assert gm.one_minus_a2(x) == pytest.approx(-math.expm1(-2 * x), rel=1e-14)


# ------------------------------------------------------------------ the 1/f law
def test_lorentzians_make_a_one_over_f_spectrum_whose_cds_variance_is_its_integral():
    s = one_over_f.lorentzians(1e-2, 1e4)
    assert s.weights.sum() == pytest.approx(1.0, rel=1e-12)
    f = np.logspace(0, 2, 401)  # two decades inside the corners
    flat = f * one_over_f.psd(s, f)
    assert flat.max() / flat.min() - 1 < 0.01  # f S(f) constant within its stated ripple
    def integral(g, lo, hi):  # over log-spaced pieces: the Lorentzians' corners span six decades
        edges = np.concatenate([[lo], np.geomspace(max(lo, 1e-6), hi, 200)[1:]])
        return sum(integrate.quad(g, a, b, limit=100)[0] for a, b in zip(edges[:-1], edges[1:]))

    def S(v):
        return float(one_over_f.psd(s, v))

    # past 1e12 Hz the spectrum holds (2 / pi) sum_j w_j f_j / 1e12 < 1e-8 of the variance
    assert integral(S, 0.0, 1e12) == pytest.approx(1.0, rel=1e-6)
    for dt in (1e-4, 1e-3, 1e-2):  # three decades of CDS interval: the closed form against the integral
        top = 4.0 / dt  # below: |2 sin(pi f dt)|^2 as it is; above: 2 - 2 cos(2 pi f dt), the cosine by QAWF
        below = integral(lambda v, dt=dt: S(v) * (2 * math.sin(math.pi * v * dt)) ** 2, 0.0, top)
        above = 2 * integral(S, top, 1e12) - 2 * integrate.quad(S, top, np.inf, weight="cos", wvar=2 * math.pi * dt)[0]
        total = below + above
        assert float(one_over_f.cds_variance(s, dt)) == pytest.approx(total, rel=1e-4), dt


# ------------------------------------------------------------------ the row noise in readout order
def test_row_flicker_is_the_same_bits_in_every_copy_of_the_chain():
    cfg = _config({**ROW, **COLUMN})
    shot = Sensor(cfg, seed=21).expose("flat:0.0")
    for k in (0, 1, 1000, 10**6):  # the kernel against the NumPy reference; a frame alone
        np.testing.assert_array_equal(shot.frame(k), shot.frame(k, detail=True).raw, err_msg=f"frame {k}")
    run = list(shot.frames(4))
    for k in range(4):
        np.testing.assert_array_equal(run[k], shot.frame(k))
    region = (6, 30, 10, 50)
    crop = shot.frame(7, region=region)
    np.testing.assert_array_equal(crop, shot.frame(7)[6:30, 10:50])
    tile = Sensor(cfg, seed=21, window=region).expose("flat:0.0")
    np.testing.assert_array_equal(tile.frame(7), crop)
    detail = shot.frame(3, detail=True)
    offsets = shot.plan().row_offsets(3)
    np.testing.assert_allclose(detail.contributions["row_noise"][:, 0], offsets, rtol=1e-6)
    # white stays what it was: no flicker in its plan
    white = Sensor(_config({"row_noise": {"enabled": True, "sigma_e": 2.0}}), seed=21).expose("flat:0.0").plan()
    assert white.row_flicker is None and white.col_flicker is None and white.row_sigma_e == 2.0


def _row_series(spectrum: str, frames: int, rows: int = 64, cols: int = 32, corner=None):
    extra = {"row_noise": {**ROW["row_noise"], "spectrum": spectrum, "corner_hz": corner}}
    sensor = Sensor(_config(extra, rows, cols), seed=5)
    stack = np.stack(list(sensor.expose("flat:0.0").frames(frames))).astype(np.float64)
    return sensor, (stack.mean(axis=2) - 1000.0) / sensor.transfer.gain_dn_per_e  # (frames, rows) e-


@pytest.mark.parametrize("spectrum, want, tol", [("one_over_f", -1.0, 0.2), ("white", 0.0, 0.15)])
def test_row_offsets_in_readout_order_have_the_spectrums_slope(spectrum, want, tol):
    sensor, rows = _row_series(spectrum, 256)
    x = rows.ravel()  # readout order: the rows of frame k after those of frame k - 1
    assert x.var() == pytest.approx(4.0, rel=0.25)  # the rms stays sigma_e (a loose check; the slope is the test)
    fs = FPS * rows.shape[1]
    f, p = signal.welch(x, fs=fs, nperseg=2048)
    band = (f >= 4 * fs / 2048) & (f <= fs / 8)  # inside the corners (0.03 Hz to 960 Hz), clear of DC and Nyquist
    slope, se = _slope(f, p, band)
    assert 5 * se < tol  # the test can tell the slope to its tolerance
    assert abs(slope - want) < tol, (slope, se)
    if spectrum == "one_over_f":  # the level too: the Welch estimate's median bin against the law's spectrum
        ratio = np.median(p[band] / (4.0 * one_over_f.psd(sensor.spec.row_flicker, f[band])))
        assert 0.8 < ratio < 1.25, ratio


def test_the_row_offsets_frame_to_frame_correlation_is_what_the_spectrum_implies():
    sensor, rows = _row_series("one_over_f", 513, rows=32, cols=16, corner=[3.0, 400.0])
    rho = float(one_over_f.autocorrelation(sensor.spec.row_flicker, 1.0 / FPS))
    products = (rows[:-1] * rows[1:]).mean(axis=1) / 4.0  # each frame pair's estimate
    # batch means: 16 batches of 32 pairs are independent to within exp(-2 pi 3 Hz 32 / 30 Hz) = 2e-9
    batches = products[: 16 * 32].reshape(16, 32).mean(axis=1)
    se = batches.std(ddof=1) / math.sqrt(batches.size)
    assert abs(batches.mean() - rho) < 5 * se, (batches.mean(), rho, se)
    assert 0.05 < rho < 0.5  # a correlation the test can see


# ------------------------------------------------------------------ the column amplifiers over frames
@pytest.mark.parametrize("spectrum, want, tol", [("one_over_f", -1.0, 0.2), ("white", 0.0, 0.15)])
def test_column_noise_over_frames_has_the_spectrums_slope(spectrum, want, tol):
    extra = {"column_noise": {**COLUMN["column_noise"],
                              "temporal": {**COLUMN["column_noise"]["temporal"], "spectrum": spectrum}}}
    sensor = Sensor(_config(extra, rows=8, cols=64), seed=9)
    stack = np.stack(list(sensor.expose("flat:0.0").frames(512))).astype(np.float64)
    cols = (stack.mean(axis=1) - 1000.0) / sensor.transfer.gain_dn_per_e  # (frames, cols) e-
    cols = cols / cols.std(axis=0)  # each column to unit rms: the average spectrum weighs them alike
    f, p = signal.welch(cols, fs=1.0, nperseg=256, axis=0)
    p = p.mean(axis=1)
    band = (f >= 2 / 256) & (f <= 0.25)  # 2/256 to 1/4 cycles per frame
    slope, se = _slope(f, p, band)
    assert 5 * se < tol
    assert abs(slope - want) < tol, (slope, se)


@pytest.mark.gpu
def test_the_gpu_gives_the_cpus_bits_with_offsets_that_change_from_frame_to_frame():
    """1/f row, column and pixel noise (no CDS) and the column banks' temporal offsets on the GPU (numba's CUDA
    simulator without one): whole frames far apart, crops at several corners, and a batch that mixes such a
    plan with one whose offsets are fixed, each item the CPU kernel's frame bit for bit (#76)."""
    from cmosnoise.engine.frame import cuda_kernel

    timed = {**ROW, "column_noise": {**COLUMN["column_noise"], "alternating": {"enabled": True, "temporal_sigma_e": 0.7}},
             **_pixel("one_over_f", cds=False), "shot_noise": {"enabled": True}}
    rows, cols = 12, 16  # the simulator's time is its pixels'
    cpu = Sensor(_config(timed, rows, cols), seed=4).expose("photo")
    still = Sensor(_config({"shot_noise": {"enabled": True}}, rows, cols), seed=5).expose("photo")
    gpu = Sensor(_config(timed, rows, cols), seed=4, device="cuda").expose("photo")
    made = cpu.plan()
    assert made.row_flicker is not None and made.pixel_flicker is not None
    assert type(made.col_flicker).__name__ == "Summed"  # the amplifiers' 1/f noise and the banks' offsets
    frames = [0, 3, 1_000_000]
    raw, _ = gpu.frames_on_device(frames)
    for b, k in enumerate(frames):
        np.testing.assert_array_equal(raw.copy_to_host()[b], cpu.frame(k), err_msg=f"frame {k}")
    plan = cuda_kernel.DevicePlan([cpu.plan(), still.plan()], [cpu.stuck_pixels(), still.stuck_pixels()])
    which, frames, corners = [0, 1, 0], [7, 7, 2], [(0, 0), (5, 6), (6, 8)]
    raw, electrons = plan.render(frames, corners, (6, 8), electrons=True, plans=which)
    raw, electrons = raw.copy_to_host(), electrons.copy_to_host()
    for b, (q, k, (r, c)) in enumerate(zip(which, frames, corners)):
        expected, expected_e = (cpu, still)[q]._render(k)
        np.testing.assert_array_equal(raw[b], expected[r:r + 6, c:c + 8], err_msg=f"item {b}")
        np.testing.assert_array_equal(electrons[b], expected_e[r:r + 6, c:c + 8], err_msg=f"item {b}")


# ------------------------------------------------------------------ a pixel's flicker in time
def _pixel(spectrum="one_over_f", cds=True, tau=1e-5, corner=None) -> dict:
    return {"source_follower": {"enabled": True, "thermal_sigma_e": 0.0,
                                "flicker": {"enabled": True, "gumbel_loc_e": 3.0, "gumbel_scale_e": 0.3, "tail": None,
                                            "spectrum": spectrum, "corner_hz": corner},
                                "rts": {"cds": cds, "cds_interval_s": tau}}}


def test_through_cds_a_pixels_one_over_f_flicker_grows_with_the_interval_as_its_integral():
    frames = 64
    base = Sensor(_config(_pixel(), 32, 32), seed=2)
    sigma2 = base.fixed_pattern.flicker_sigma.astype(np.float64) ** 2  # at the reference interval, 1e-5 s
    spectrum = base.spec.pixel_flicker
    for tau in (1e-6, 1e-5, 1e-4, 1e-3):  # three decades of CDS interval
        sensor = Sensor(_config(_pixel(tau=tau), 32, 32), seed=2)
        stack = (np.stack(list(sensor.expose("flat:0.0").frames(frames))).astype(np.float64) - 1000.0) / 4.0
        ratio = stack.var(axis=0, ddof=1) / sigma2  # each pixel's, against its sigma at the reference interval
        # the law: D(tau) / D(tau_ref), D the CDS transfer's integral of the 1/f spectrum (tested above against
        # quad); each pixel's ratio spreads as a chi-square over 63 degrees of freedom: the mean's standard error
        # from their spread over the 1024 pixels
        want = float(one_over_f.cds_variance(spectrum, tau) / one_over_f.cds_variance(spectrum, 1e-5))
        se = ratio.std(ddof=1) / math.sqrt(ratio.size)
        assert abs(ratio.mean() - want) < 5 * se, (tau, ratio.mean(), want, se)
    assert want > 4 and float(one_over_f.cds_variance(spectrum, 1e-6) / one_over_f.cds_variance(spectrum, 1e-5)) < 0.2
    white = Sensor(_config(_pixel("white"), 32, 32), seed=2).expose("flat:0.0")
    np.testing.assert_array_equal(white.frame(5), base.expose("flat:0.0").frame(5))  # at tau_ref: white's bits


@pytest.mark.parametrize("spectrum, want, tol", [("one_over_f", -1.0, 0.2), ("white", 0.0, 0.15)])
def test_without_cds_a_pixels_flicker_over_frames_has_the_spectrums_slope(spectrum, want, tol):
    from cmosnoise.analysis import noise_spectrum as ns

    # the corners inside what 30 frames/s resolve (0.03 to 15 Hz): above it the level aliases into white
    sensor = Sensor(_config(_pixel(spectrum, cds=False, corner=[0.03, 15.0]), 16, 16), seed=2)
    stack = np.stack(list(sensor.expose("flat:0.0").frames(512))).astype(np.float64)
    e = ns.over_frames(stack)  # 2/256 to 1/4 cycles per frame, averaged over the pixels
    assert 5 * e.slope_se < tol
    assert abs(e.slope - want) < tol, (e.slope, e.slope_se)
    # the level's variance is the map's: sigma_i^2 (a 1/f process seen over 512 frames, less its slow part)
    seen = ((stack - 1000.0) / 4.0).var(axis=0, ddof=1) / sensor.fixed_pattern.flicker_sigma.astype(np.float64) ** 2
    share = ns.seen_share_frames(sensor.spec.pixel_flicker, 512, 1 / FPS) if spectrum == "one_over_f" else 1.0
    assert seen.mean() == pytest.approx(share, rel=0.15)


def test_a_pixels_flicker_level_is_the_same_bits_in_every_copy_of_the_chain():
    cfg = _config(_pixel(cds=False), 24, 32)
    shot = Sensor(cfg, seed=21).expose("flat:0.0")
    for k in (0, 1, 1000, 10**6):
        np.testing.assert_array_equal(shot.frame(k), shot.frame(k, detail=True).raw, err_msg=f"frame {k}")
    run = list(shot.frames(3))
    for k in range(3):
        np.testing.assert_array_equal(run[k], shot.frame(k))
    region = (4, 20, 6, 30)
    tile = Sensor(cfg, seed=21, window=region).expose("flat:0.0")
    np.testing.assert_array_equal(tile.frame(8), shot.frame(8)[4:20, 6:30])
    np.testing.assert_array_equal(shot.frame(8, region=region), shot.frame(8)[4:20, 6:30])
    d = shot.frame(2, detail=True)
    np.testing.assert_allclose(d.contributions["source_follower"], d.electrons, atol=1e-4)  # the only stage on


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("args, needles", [
    (["--set", "row_noise.spectrum=pink"], ["row_noise.spectrum", "pink", "one_over_f"]),
    (["--set", "row_noise.spectrum=one_over_f", "--set", "row_noise.corner_hz=[10, 1]"],
     ["row_noise.corner_hz", "0 < low < high"]),
    (["--set", "row_noise.spectrum=one_over_f", "--set", "row_noise.corner_hz=[0, 1]"],
     ["row_noise.corner_hz", "0 < low < high"]),
    (["--set", "row_noise.spectrum=one_over_f", "--set", "row_noise.corner_hz=[5, 5]"],
     ["row_noise.corner_hz", "0 < low < high"]),
    (["--set", "sensor.frame_rate_hz=30", "--set", "column_noise.temporal.corner_hz=[1, 40000]"],
     ["column_noise.temporal.corner_hz", "30000 Hz"]),
    (["--set", "sensor.frame_rate_hz=30", "--set", "source_follower.flicker.corner_hz=[1, 1e6]"],
     ["source_follower.flicker.corner_hz", "30000 Hz"]),
    (["--set", "source_follower.flicker.spectrum=brown"], ["source_follower.flicker.spectrum", "one_over_f"]),
])
def test_a_bad_spectrum_or_corner_range_is_one_line(tmp_path, args, needles):
    r = cli("simulate", "--set", "sensor.width=64", "--set", "sensor.height=48", *args, "--out", tmp_path / "o")
    lines = [x for x in r.stderr.strip().splitlines() if " compil" not in x]
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    for n in needles:
        assert n in lines[0], lines[0]
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------ measured: characterize and fit
def _stack(extra: dict, frames: int, rows: int = 48, cols: int = 64, seed: int = 3) -> np.ndarray:
    ex = {k: dict(v) for k, v in extra.items()}
    ex["source_follower"] = {"enabled": True, "thermal_sigma_e": 3.0, "flicker": {"enabled": False}}
    return np.stack(list(Sensor(_config(ex, rows, cols), seed=seed).expose("flat:0.0").frames(frames)))


def test_the_spectra_of_a_dark_stack_tell_white_from_one_over_f_and_rows_from_columns():
    from cmosnoise.analysis import noise_spectrum as ns

    white = ns.of_stack(np.random.default_rng(0).normal(100.0, 2.0, (128, 48, 64)))
    assert {k: v["verdict"] for k, v in white.items()} == dict.fromkeys(white, "white")
    rows = ns.of_stack(_stack(ROW, 256))
    assert rows["rows_in_readout_order"]["verdict"] == "one_over_f"
    assert rows["columns_over_frames"]["verdict"] == "white"  # what the frame's columns share is taken away
    lo, hi = rows["rows_in_readout_order"]["interval"]
    assert lo < -1 < hi or abs(rows["rows_in_readout_order"]["slope"] + 1) < 0.2
    columns = ns.of_stack(_stack(COLUMN, 256))
    assert columns["columns_over_frames"]["verdict"] == "one_over_f"
    assert columns["rows_in_readout_order"]["verdict"] == "white"  # what the frame's rows share is taken away
    assert abs(columns["columns_over_frames"]["slope"] + 1) < 0.2


@pytest.mark.parametrize("corner, resolved", [([0.3, 3.0], (True, True)), ([0.03, 15.0], (False, True))])
def test_the_corner_fit_recovers_the_one_over_f_range_within_its_intervals(corner, resolved):
    """A pixel's 1/f flicker without CDS, 512 frames at 30 frames/s: the fitted corners' 95 % intervals hold the
    configured ones; a corner below the stack's lowest bin (0.23 Hz) is a bound only, not resolved."""
    from cmosnoise.analysis import noise_spectrum as ns

    sensor = Sensor(_config(_pixel("one_over_f", cds=False, corner=corner), 16, 16), seed=2)
    stack = np.stack(list(sensor.expose("flat:0.0").frames(512))).astype(np.float64)
    got = ns.fit_corners(ns.over_frames(stack), FPS)
    for (name, true), res in zip((("low_hz", corner[0]), ("high_hz", corner[1])), resolved):
        lo, hi = got[name]["interval"]
        assert lo <= true <= hi and got[name]["resolved"] == res, (name, got[name])
        if res:  # a requirement, not an estimate: a resolved corner is known to a factor of 1.5 either side
            assert hi / lo < 2.25, got[name]  # (measured 1.58 and 1.26; the grid's own widening alone is 1.26)
    from cmosnoise.errors import CmosnoiseError

    rows = ns.rows_in_readout_order(np.random.default_rng(1).normal(0.0, 1.0, (64, 64)))
    with pytest.raises(CmosnoiseError, match="a spectrum over frames, not 'rows in readout order'"):
        ns.fit_corners(rows, FPS)


@pytest.mark.slow
def test_characterize_gives_the_one_over_f_range_of_a_simulated_stack_in_hz(tmp_path):
    """characterize's dark stack of a simulated sensor comes at the sensor's frame rate: its 1/f pixel spectrum
    has its corners fitted as fit's is (the same function), the intervals holding the configured 0.3 and
    3 Hz, and said in the note; a descriptor's stack, whose rate is not known, says why it has none."""
    from cmosnoise.analysis import noise_spectrum as ns
    from cmosnoise.app import characterizing
    from cmosnoise.model.spec import resolve

    extra = {**_pixel("one_over_f", cds=False, corner=[0.3, 3.0]), "shot_noise": {"enabled": True}}
    res = characterizing.run(resolve(_config(extra, 16, 16)), tmp_path / "ch", steps=8, stack_frames=512)
    pixels = res["spectra"]["pixels_over_frames"]
    assert pixels["verdict"] == "one_over_f" and pixels["frame_rate_hz"] == FPS, pixels
    for name, true in (("low_hz", 0.3), ("high_hz", 3.0)):
        got = pixels["corners"][name]
        assert got["resolved"] and got["interval"][0] <= true <= got["interval"][1], (name, got)
    assert "1/f from" in " ".join(res["notes"]) and " Hz" in " ".join(res["notes"]), res["notes"]
    stack = np.stack(list(Sensor(_config(extra, 16, 16), seed=2).expose("flat:0.0").frames(256)))
    unknown = ns.of_stack(stack)["pixels_over_frames"]
    assert unknown["verdict"] == "one_over_f" and "frame rate is not known" in unknown["corners"]["not_given"]


def test_a_stack_too_short_for_a_spectrum_says_what_it_needs():
    from cmosnoise.analysis import noise_spectrum as ns
    from cmosnoise.errors import CmosnoiseError

    short = np.zeros((16, 8, 8))
    with pytest.raises(CmosnoiseError, match="at least 64 dark frames.*has 16"):
        ns.over_frames(short)
    with pytest.raises(CmosnoiseError, match="at least 512 rows"):
        ns.readout_order(short)
    assert set(ns.of_stack(short)["pixels_over_frames"]) == {"not_given"}


def test_what_a_stack_sees_of_a_one_over_f_process_is_the_exact_quadratic_forms():
    """Each closed form against the matrix it sums: a small stack's covariance built whole."""
    from cmosnoise.analysis import noise_spectrum as ns

    K, H, t = 7, 5, 0.01
    s = one_over_f.lorentzians(0.5, 50.0)
    n = np.arange(K * H)
    C = one_over_f.autocorrelation(s, (n[:, None] - n[None, :]) * t)
    PK, PH = np.eye(K) - 1 / K, np.eye(H) - 1 / H
    assert ns.seen_share_rows(s, K, H, t) == pytest.approx(np.trace(np.kron(PK, PH) @ C) / ((K - 1) * (H - 1)),
                                                           rel=1e-12)
    M = np.kron(np.eye(K), np.ones((1, H)) / H)  # each frame's mean
    D = np.eye(K * H) - np.kron(np.eye(K), np.ones((H, H)) / H)  # each row less its frame's mean
    CD = D @ C @ D.T
    rows_spread = np.mean([np.trace(PK @ CD[r::H, r::H]) / (K - 1) for r in range(H)])
    assert ns.frame_mean_ratio_rows(s, K, H, t) == pytest.approx(np.trace(PK @ M @ C @ M.T) / (K - 1) / rows_spread,
                                                                 rel=1e-12)
    Z = np.kron(np.ones((1, K)) / K, np.eye(H))  # each row's mean over the frames
    assert ns.stack_mean_share_rows(s, K, H, t) == pytest.approx(np.trace(PH @ Z @ C @ Z.T) / ((H - 1) / K),
                                                                 rel=1e-12)
    T = 0.1
    Cf = one_over_f.autocorrelation(s, (np.arange(K)[:, None] - np.arange(K)[None, :]) * T)
    assert ns.seen_share_frames(s, K, T) == pytest.approx(np.trace(PK @ Cf) / (K - 1), rel=1e-12)
    assert ns.stack_mean_share_frames(s, K, T) == pytest.approx(Cf.sum() / K, rel=1e-12)
    C2 = 2.0 * Cf + 0.5 * np.eye(K)
    PC = PK @ C2
    assert ns.variance_dof_frames(s, K, T, 2.0, 0.5) == pytest.approx(np.trace(PC) ** 2 / np.trace(PC @ PC),
                                                                      rel=1e-12)
    white = one_over_f.lorentzians(1e6, 1e7)  # corners far above the sampling: white
    assert ns.seen_share_rows(white, K, H, t) == pytest.approx(1.0)
    assert ns.frame_mean_ratio_rows(white, K, H, t) == pytest.approx(1 / (H - 1))


@pytest.mark.slow
def test_an_emva1288_data_set_is_white_in_readout_order_and_too_short_over_frames(tmp_path):
    import json
    import subprocess
    import sys
    from pathlib import Path

    data = tmp_path / "data"
    proc = subprocess.run([sys.executable, str(Path(__file__).parent / "emva_dataset.py"), str(data), "0.4", "10000",
                           "0", "0", "0"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    r = cli("characterize", "--frames-from", data / "EMVA1288descriptor.txt", "--out", tmp_path / "ch")
    assert r.returncode == 0, r.stderr
    spectra = json.loads((tmp_path / "ch" / "characterization.json").read_text())["spectra"]
    assert spectra["rows_in_readout_order"]["verdict"] == "white", spectra
    assert "64" in spectra["pixels_over_frames"]["not_given"]
    assert "noise in time" in r.stdout and "white" in r.stdout
    assert (tmp_path / "ch" / "noise_spectra.png").exists()


@pytest.mark.slow
def test_fit_sets_the_pixel_flickers_spectrum_from_the_dark_stack(tmp_path):
    """A sensor whose pixels flicker as 1/f without CDS (their level correlated from frame to frame): fit reads
    each pixel's series over the long dark stack, less its rows' and columns' means, finds it 1/f and writes source_follower.flicker.spectrum = one_over_f; the rows and columns stay white."""
    import json

    import yaml

    # 64 x 48 pixels and the fewest levels measure takes: without CDS each pixel's 1/f process is bridged in NumPy
    # (about 10 us a pixel and frame), and 96 x 64 with 12 levels took 75 s of CI's suite
    args = ["--set", "sensor.width=64", "--set", "sensor.height=48", "--set", "sensor.frame_rate_hz=30",
            "--set", "source_follower.flicker.spectrum=one_over_f", "--set", "source_follower.rts.cds=false",
            "--set", "source_follower.flicker.corner_hz=[0.03, 15.0]", "--set", "source_follower.flicker.tail=null",
            "--set", "source_follower.flicker.gumbel_loc_e=3.0"]
    assert cli("measure", *args, "--long-frames", "256", "--levels", "8", "--out", tmp_path / "m").returncode == 0
    r = cli("fit", "--frames-from", tmp_path / "m" / "manifest.yaml", "--out", tmp_path / "f")
    assert r.returncode == 0, r.stderr
    spectra = json.loads((tmp_path / "f" / "fit.json").read_text())["spectra"]
    pixels = spectra["pixels_over_frames"]
    # (measured: -0.69; the sensor's white noises, dark shot noise and the ADC's, flatten it from -1)
    assert pixels["verdict"] == "one_over_f" and pixels["slope"] < -0.5, pixels
    assert spectra["rows_in_readout_order"]["verdict"] == "white"
    # the 1/f range (0.03 to 15 Hz, Nyquist at 30 frames/s; the stack's lowest bin 0.47 Hz): each interval holds
    # the truth, under the pixels' white floor of dark shot noise and the ADC's
    high, low = pixels["corners"]["high_hz"], pixels["corners"]["low_hz"]
    assert high["resolved"] and high["interval"][0] <= 15.0 <= high["interval"][1], high
    assert low["interval"][0] <= 0.03 <= low["interval"][1], low
    cfg = yaml.safe_load((tmp_path / "f" / "config.yaml").read_text())
    assert cfg["source_follower"]["flicker"]["spectrum"] == "one_over_f"
    # the flicker sigmas as the pixels have them, not as 256 frames see them (0.861 of the variance at 0.03 to
    # 15 Hz): the configured 3 e- and 0.3 e- inside the intervals (measured: 3.43, 2.53 to 4.32; 0.312, 0.245 to
    # 0.397; the thermal and flicker split is weakly identified on one stack)
    P = json.loads((tmp_path / "f" / "fit.json").read_text())["parameters"]
    for name, true in (("gumbel_loc_e", 3.0), ("gumbel_scale_e", 0.3)):
        got = P[f"source_follower.flicker.{name}"]
        assert got["ci95"][0] <= true <= got["ci95"][1] and "1/f flicker's variance" in got["method"], got
    written = cfg["source_follower"]["flicker"]["corner_hz"]
    assert low["interval"][0] <= written[0] <= low["interval"][1] and written[1] == pytest.approx(high["value"])
    assert cfg["row_noise"]["spectrum"] == "white"


@pytest.mark.parametrize("spectrum", ["one_over_f", pytest.param("white", marks=pytest.mark.slow)])
@pytest.mark.slow
def test_fit_finds_the_spectrum_of_the_row_and_column_noise_and_their_sigmas(tmp_path, spectrum):
    import json

    import yaml

    args = ["--set", "sensor.width=128", "--set", "sensor.height=96", "--set", "row_noise.sigma_e=3",
            "--set", "column_noise.temporal.gumbel_loc_e=2", "--set", "sensor.frame_rate_hz=30",
            "--set", f"row_noise.spectrum={spectrum}", "--set", f"column_noise.temporal.spectrum={spectrum}"]
    assert cli("measure", *args, "--long-frames", "256", "--levels", "12", "--out", tmp_path / "m").returncode == 0
    r = cli("fit", "--frames-from", tmp_path / "m" / "manifest.yaml", "--out", tmp_path / "f")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "f" / "fit.json").read_text())
    # the pixels' own noise (less their rows' and columns') is white: a 1/f row noise is not read as pixel flicker
    assert {k: v["verdict"] for k, v in doc["spectra"].items()} == {"pixels_over_frames": "white",
                                                                   "rows_in_readout_order": spectrum,
                                                                   "columns_over_frames": spectrum}
    assert "corners" not in doc["spectra"]["pixels_over_frames"]  # no 1/f, no corners fitted
    cfg = yaml.safe_load((tmp_path / "f" / "config.yaml").read_text())
    assert cfg["row_noise"]["spectrum"] == spectrum and cfg["column_noise"]["temporal"]["spectrum"] == spectrum
    assert cfg["source_follower"]["flicker"]["spectrum"] == "white"
    assert cfg["source_follower"]["flicker"].get("corner_hz") is None
    truth = {row["parameter"]: row for row in doc["truth"]["rows"]}
    # the sigmas a 1/f stack sees only in part, given back whole: each 95 % interval holds the truth
    for name in ("row_noise.sigma_e", "column_noise.temporal.gumbel_loc_e", "column_noise.temporal.gumbel_scale_e",
                 "column_noise.vfpn_sigma_e", "black_level.frame_sigma_dn"):
        assert truth[name]["inside"], truth[name]
