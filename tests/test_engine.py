"""The noise engine (docs/model.md section 1): Philox, the samplers, and frames that never change a bit."""

import dataclasses
import json
import math
import os

import numpy as np
import pytest
from conftest import assert_close, on_threads
from scipy import stats

from cmosnoise import Sensor, load_config
from cmosnoise.engine import fdmath
from cmosnoise.engine.frame import kernel
from cmosnoise.engine.frame.plan import FramePlan
from cmosnoise.engine.philox import philox4x32
from cmosnoise.engine.samplers import Stream, normal_pair_from, poisson_inversion

U = np.uint64


# ------------------------------------------------------------------ Philox
@pytest.mark.parametrize("ctr,key,expected", [  # Random123 kat_vectors, philox4x32 10
    ((0, 0, 0, 0), (0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
    ((0xFFFFFFFF,) * 4, (0xFFFFFFFF,) * 2, (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)),
    ((0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344), (0xA4093822, 0x299F31D0),
     (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1)),
])
def test_philox_known_answer_vectors(ctr, key, expected):
    words = philox4x32(*(np.array([c], U) for c in ctr), *(np.array([k], U) for k in key))
    assert tuple(int(w[0]) for w in words) == expected


def test_uniforms_are_open_and_uniform():
    u1, u2 = Stream((1, 2), 0).uniforms(np.arange(200_000, dtype=U))
    u = np.concatenate([u1, u2])
    assert u.min() > 0 and u.max() < 1
    assert stats.kstest(u, "uniform").pvalue > 1e-6


# ------------------------------------------------------------------ own math
def test_own_log_exp_cos_loggam_match_the_correctly_rounded_functions():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(2.0**-53, 1, 50_000), rng.uniform(1, 1e7, 50_000)])
    ref = np.array([math.log(v) for v in x])
    assert np.max(np.abs(fdmath.log(x) - ref) / np.spacing(np.abs(ref))) <= 1.0  # within 1 ulp
    x = rng.uniform(-12, 0, 50_000)
    ref = np.array([math.exp(v) for v in x])
    assert np.max(np.abs(fdmath.exp(x) - ref) / np.spacing(ref)) <= 1.0
    u = rng.uniform(0, 1, 50_000)
    assert np.max(np.abs(fdmath.cos_turn(u) - np.cos(2 * np.pi * u))) < 2e-15
    c, s = fdmath.sincos_turn(u)
    assert np.array_equal(c, fdmath.cos_turn(u))  # one reduction for both: the cosine's bits are cos_turn's
    assert np.max(np.abs(s - np.sin(2 * np.pi * u))) < 2e-15
    k = np.arange(1.0, 400.0)
    np.testing.assert_allclose(fdmath.loggam(k), [math.lgamma(v) for v in k], rtol=1e-13, atol=1e-13)


# ------------------------------------------------------------------ Poisson
def test_inversion_below_10_equals_scipy_ppf_on_the_same_uniforms():
    idx = np.arange(100_000, dtype=U)
    for lam in (0.5, 5.0, 9.9):
        u, _ = Stream((7, 8), 3).uniforms(idx)
        k = poisson_inversion(np.full(u.shape, lam), u)
        np.testing.assert_array_equal(k, stats.poisson.ppf(u, lam))


def _numpy_ptrs(lam, uniforms):
    """A plain port of numpy's random_poisson_ptrs (distributions.c), its loggam included."""
    def loggam(x):
        a = [8.333333333333333e-02, -2.777777777777778e-03, 7.936507936507937e-04, -5.952380952380952e-04,
             8.417508417508418e-04, -1.917526917526918e-03, 6.410256410256410e-03, -2.955065359477124e-02,
             1.796443723688307e-01, -1.39243221690590e+00]
        if x in (1.0, 2.0):
            return 0.0
        n = int(7 - x) if x < 7.0 else 0
        x0 = x + n
        x2 = (1.0 / x0) * (1.0 / x0)
        gl0 = a[9]
        for k in range(8, -1, -1):
            gl0 = gl0 * x2 + a[k]
        gl = gl0 / x0 + 0.5 * 1.8378770664093453 + (x0 - 0.5) * math.log(x0) - x0
        for _ in range(n):
            gl -= math.log(x0 - 1.0)
            x0 -= 1.0
        return gl

    slam, loglam = math.sqrt(lam), math.log(lam)
    b = 0.931 + 2.53 * slam
    a = -0.059 + 0.02483 * b
    invalpha = 1.1239 + 1.1328 / (b - 3.4)
    vr = 0.9277 - 3.6224 / (b - 2)
    for u1, u2 in uniforms:
        U_, V = u1 - 0.5, u2
        us = 0.5 - abs(U_)
        k = math.floor((2 * a / us + b) * U_ + lam + 0.43)
        if us >= 0.07 and vr >= V:
            return k
        if k < 0 or (us < 0.013 and us < V):
            continue
        if math.log(V) + math.log(invalpha) - math.log(a / (us * us) + b) <= -lam + k * loglam - loggam(k + 1):
            return k


@pytest.mark.parametrize("lam", [10.0, 50.0, 1000.0, 5000.0])
def test_ptrs_equals_a_port_of_numpys_algorithm_on_the_same_uniforms(lam):
    s = Stream((21, 22), 5)
    idx = np.arange(3000, dtype=U)
    ours = s.poisson(np.full(idx.shape, lam), idx)
    tries = [s.uniforms(idx, t) for t in range(12)]
    theirs = [_numpy_ptrs(lam, ((tries[t][0][i], tries[t][1][i]) for t in range(12))) for i in range(idx.size)]
    np.testing.assert_array_equal(ours, theirs)


@pytest.mark.parametrize("lam", [0.5, 5.0, 9.9, 10.0, 50.0, 1000.0, 5000.0])
def test_poisson_moments_and_chi_square(lam):
    n = 200_000
    k = Stream((31, 32), 1).poisson(np.full(n, lam), np.arange(n, dtype=U))
    assert_close(k.mean(), lam, math.sqrt(lam / n), f"mean at {lam}")
    assert_close(k.var(ddof=1), lam, math.sqrt((lam + 2 * lam**2) / n), f"variance at {lam}")
    lo, hi = stats.poisson.ppf([1e-4, 1 - 1e-4], lam)
    edges = np.arange(lo, hi + 2) - 0.5
    observed = np.histogram(k, np.concatenate([[-np.inf], edges[1:-1], [np.inf]]))[0]
    expected = n * np.diff(np.concatenate([[0.0], stats.poisson.cdf(edges[1:-1] - 0.5, lam), [1.0]]))
    keep = expected >= 5
    chi2 = np.sum((observed[keep] - expected[keep]) ** 2 / expected[keep])
    assert stats.chi2.sf(chi2, keep.sum() - 1) > 1e-6  # about 5 sigma


def test_normals_are_standard_normal():
    z = Stream((41, 42), 0).normal(np.arange(200_000, dtype=U))
    assert_close(z.mean(), 0.0, 1 / math.sqrt(z.size), "mean")
    assert_close(z.var(ddof=1), 1.0, math.sqrt(2 / z.size), "variance")
    assert stats.kstest(z, "norm").pvalue > 1e-6


def test_box_mullers_two_normals_are_independent_standard_normals():
    """The sine normal of a block (read noise after the gain takes it; the source follower the cosine one):
    standard normal (mean, variance, KS), uncorrelated with the cosine normal and with uncorrelated squares
    (both share the block's radius: a dependence there shows in the squares). Over n pairs the sample
    correlation has standard error 1/sqrt(n); z1^2 z2^2 has mean 1 and variance E z^4 E z^4 - 1 = 8."""
    n = 200_000
    z1, z2 = normal_pair_from(*Stream((41, 42), 0).uniforms(np.arange(n, dtype=U)))
    assert np.array_equal(z1, Stream((41, 42), 0).normal(np.arange(n, dtype=U)))  # the cosine one, bit for bit
    assert_close(z2.mean(), 0.0, 1 / math.sqrt(n), "mean")
    assert_close(z2.var(ddof=1), 1.0, math.sqrt(2 / n), "variance")
    assert stats.kstest(z2, "norm").pvalue > 1e-6
    assert_close(np.corrcoef(z1, z2)[0, 1], 0.0, 1 / math.sqrt(n), "correlation")
    assert_close(np.mean(z1**2 * z2**2), 1.0, math.sqrt(8 / n), "E z1^2 z2^2")


# ------------------------------------------------------------------ frames never change a bit
def _full_chain(**extra):
    over = ["sensor.width=61", "sensor.height=37", "column_noise.gain_sigma_pct=1", "row_noise.fixed_sigma_e=0.5"]
    return Sensor(load_config(overrides=over, extra=extra or None), seed=11)


needs_numba = pytest.mark.skipif(not kernel.AVAILABLE, reason="numba not installed")


@needs_numba
@pytest.mark.parametrize("extra", [
    {}, {"shot_noise": {"gaussian_above_e": 100.0}}, {"adc": {"enabled": False}},
    # an ADC whose codes are scaled to a wider range: one black level (the kernel's short path), and with the DN
    # terms (cell offsets, the frame's error, read noise after the gain) that the quantizer divides by its step
    {"adc": {"bits": 10, "output_bits": 16, "black_level_dn": 1000}},
    {"adc": {"bits": 14, "output_bits": 16, "black_level_dn": 512},
     "black_level": {"channel_offsets_dn": [3.0, -2.0, 1.0, 6.0], "frame_sigma_dn": 2.5},
     "read_noise": {"enabled": True, "distribution": "tukey_lambda", "scale_dn": 5.0, "shape": -0.05}}],
    ids=["default", "normal-approx", "adc-off", "10-bit-in-16", "14-bit-in-16-dn-terms"])
def test_kernel_equals_the_numpy_implementation_on_any_threads_and_tiling(extra):
    shot = _full_chain(**extra).expose("photo")
    reference = shot.frame(3, detail=True)  # the NumPy implementation, stage by stage
    one = on_threads(1, lambda: shot.frame(3))
    full = shot.frame(3)
    np.testing.assert_array_equal(full, reference.raw)
    np.testing.assert_array_equal(one, full)
    rows, cols = full.shape
    for tile in [(7, 5), (16, 16), (37, 61)]:
        tiled = np.block([[shot.frame(3, region=(r, min(r + tile[0], rows), c, min(c + tile[1], cols)))
                           for c in range(0, cols, tile[1])] for r in range(0, rows, tile[0])])
        np.testing.assert_array_equal(tiled, full)
    # a crop through the NumPy path equals the kernel's crop
    crop = shot.frame(3, detail=True, region=(4, 20, 9, 50))
    np.testing.assert_array_equal(crop.raw, full[4:20, 9:50])


@needs_numba
@pytest.mark.parametrize("low, high, table_for", [(10.0, 14.0, None), (4500.0, 6000.0, 0.0)])
def test_kernel_ptrs_takes_loggam_from_a_table_and_redoes_the_counts_past_it(low, high, table_for):
    """The kernel's PTRS log test reads loggam(k + 1) from the plan's table (samplers.loggam_table).
    Means just above 10: counts below 7, where loggam recurses, come from the table too. Means past the
    table (forced here: a table for means up to 0 holds 4096 counts): each try whose log test meets such a
    count is left undecided and redone exactly. Either way the frame equals the NumPy implementation bit for
    bit."""
    from cmosnoise.engine import samplers

    lam = np.random.default_rng(5).uniform(low, high, (40, 50)).astype(np.float32)
    keys = np.array([[21, 22], [0, 0], [0, 0], [0, 0]], np.uint64)
    plan = FramePlan(shape=lam.shape, keys=keys, sequence=0, full_well_e=1e9, noisy_e=lam)
    if table_for is not None:
        plan.__dict__["loggam_table"] = samplers.loggam_table(table_for)  # what the cached property holds
    table = plan.loggam_table
    last = float(table.size - 1)
    stream, idx, lam64 = Stream((21, 22), 3), np.arange(lam.size, dtype=U), lam.ravel().astype(np.float64)
    u1, u2 = stream.uniforms(idx)
    loglam, a, b, invalpha, vr = samplers.ptrs_constants(lam64)
    k, us, V = samplers.ptrs_candidate(lam64, a, b, u1, u2)
    log_test = ~(((us >= 0.07) & (vr >= V)) | (k < 0) | ((us < 0.013) & (us < V)))
    past = log_test & (np.maximum(k, 0.0) + 1.0 > last)
    if table_for is None:
        assert np.count_nonzero(log_test & (k < 6)) >= 50 and not past.any()  # first tries alone
    else:
        assert np.count_nonzero(past) >= 200  # about a fifth of the first tries
    left = np.array([kernel._ptrs_test(*c, kernel._ptrs_loggam(kc, table), last) == kernel._REDO
                     for *c, kc in zip(lam64, loglam, a, b, fdmath.log(invalpha), vr, u1, u2, k)])
    np.testing.assert_array_equal(left, past)  # the branch-free pass leaves exactly those
    raw, _ = kernel.render(plan, 3)
    np.testing.assert_array_equal(raw.ravel(), stream.poisson(lam64, idx).astype(np.float32))


def test_loggam_table_holds_loggam_and_every_count_the_log_test_meets():
    """table[n] is loggam(n), the same bits; it reaches past the highest count a log test can meet with
    us >= 0.013 (k <= mean + 0.43 + (0.5 - 0.013)(2a/0.013 + b), numpy's constants), and it is shared."""
    from cmosnoise.engine import samplers

    for mean_max in (0.0, 9.9, 10.0, 350.0, 4096.0, 1e5, 3e6, np.inf):
        table = samplers.loggam_table(mean_max)
        assert table.size % 4096 == 0 and table.size <= samplers.TABLE_MAX and not table.flags.writeable
        if mean_max < 2e6:
            m = np.array(max(mean_max, 10.0))
            _, a, b, _, _ = samplers.ptrs_constants(m)
            assert m + 0.43 + (0.5 - 0.013) * (2 * a / 0.013 + b) + 1 < table.size - 1
        else:
            assert table.size == samplers.TABLE_MAX
    n = np.arange(1.0, samplers.loggam_table(20_000.0).size)
    np.testing.assert_array_equal(samplers.loggam_table(20_000.0)[1:].view(U), fdmath.loggam(n).view(U))
    assert samplers.loggam_table(300.0) is samplers.loggam_table(310.0)


def test_frame_k_alone_equals_frame_k_of_a_run():
    shot = _full_chain().expose("ramp")
    run = [shot.frame(k) for k in range(5)]
    np.testing.assert_array_equal(shot.frame(3), run[3])
    assert not np.array_equal(run[2], run[3])


def test_a_scene_changed_at_one_pixel_changes_no_other_pixel():
    sensor = Sensor(load_config(overrides=["sensor.width=64", "sensor.height=48", "crosstalk.enabled=false"]), seed=2)
    scene = np.full((48, 64), 0.002)  # 200 e- at the default exposure
    a = sensor.expose(scene).frame(0)
    scene[0, 0] = 0.0
    b = sensor.expose(scene).frame(0)
    changed = a != b
    assert changed[0, 0] and changed.sum() == 1


def test_a_row_noise_change_changes_only_the_row_term():
    over = ["sensor.width=64", "sensor.height=48"]
    a = Sensor(load_config(overrides=over), seed=4).expose("photo").frame(1, detail=True)
    b = Sensor(load_config(overrides=over + ["row_noise.sigma_e=3"]), seed=4).expose("photo").frame(1, detail=True)
    for stage, part in a.contributions.items():
        if stage not in ("row_noise", "quantization"):
            np.testing.assert_array_equal(part, b.contributions[stage], err_msg=stage)
    ratio = b.contributions["row_noise"][:, 0] / a.contributions["row_noise"][:, 0]
    np.testing.assert_allclose(ratio, 3 / 0.4, rtol=1e-6)  # the same normals, rescaled


def test_adc_off_reads_electrons_unclipped_and_unbiased():
    cfg = load_config(overrides=["sensor.width=200", "sensor.height=150", "adc.enabled=false", "prnu.enabled=false",
                                 "dark_current.enabled=false", "row_noise.enabled=false", "column_noise.enabled=false",
                                 "source_follower.flicker.enabled=false", "source_follower.thermal_sigma_e=2"])
    raw = Sensor(cfg, seed=0).expose("flat:0").frame(0)
    assert raw.dtype == np.float32 and raw.min() < 0
    assert_close(float(raw.mean()), 0.0, 2 / math.sqrt(raw.size), "mean")
    assert_close(float(raw.std(ddof=1)), 2.0, 2 / math.sqrt(2 * (raw.size - 1)), "std")


@pytest.mark.parametrize("bad", [1.7, -1, "x"])
def test_a_frame_number_must_be_a_whole_number(bad):
    from cmosnoise import CmosnoiseError

    with pytest.raises(CmosnoiseError, match="frame"):
        _full_chain().expose("flat:0.1").frame(bad)


def test_a_region_outside_the_frame_is_refused():
    from cmosnoise import CmosnoiseError

    with pytest.raises(CmosnoiseError, match="region"):
        _full_chain().expose("flat:0.1").frame(0, region=(0, 100, 0, 10))


@pytest.mark.slow
def test_the_first_run_says_once_that_it_compiles_and_later_runs_do_not(tmp_path):
    """With an empty compile cache `simulate` says it is compiling the frame kernel, once, and how long that
    took; a second run loads the cache and says nothing of it. The cache is the session's when conftest.py
    made one and it is still empty (conftest runs this test first; the other xdist worker may have compiled
    into it already), so the rest of the suite loads what this compiled; else one of its own."""
    import os
    import subprocess
    import sys

    from conftest import SESSION_CACHE

    shared = SESSION_CACHE is not None and os.environ["NUMBA_CACHE_DIR"] == SESSION_CACHE and not [
        f for _, _, files in os.walk(SESSION_CACHE) for f in files]  # (importing makes empty folders)
    if shared:
        env = dict(os.environ)
    else:
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    cmd = [sys.executable, "-m", "cmosnoise", "simulate", "--frames", "1", "--no-progress",
           "--set", "sensor.width=64", "--set", "sensor.height=48"]
    first = subprocess.run(cmd + ["--out", str(tmp_path / "a")], env=env, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    assert first.stderr.count("compiling the frame kernel") == 1, first.stderr
    assert first.stderr.count("compiled the frame kernel in") == 1, first.stderr
    # its one frame waited for the compile: no time per frame is claimed, and the compile is in the timings
    timings = json.loads((tmp_path / "a" / "summary.json").read_text())["timings_s"]
    assert timings["frame_s"] is None and timings["stages"]["kernel_compile"] > 2.0, timings
    said = "included: run again (with --overwrite, or another --out) for the time per frame"
    assert said in first.stdout, first.stdout
    second = subprocess.run(cmd + ["--out", str(tmp_path / "b")], env=env, capture_output=True, text=True, timeout=600)
    assert second.returncode == 0, second.stderr
    assert "compil" not in second.stderr, second.stderr
    timings = json.loads((tmp_path / "b" / "summary.json").read_text())["timings_s"]
    assert timings["frame_s"] > 0 and "kernel_compile" not in timings["stages"] and "ms/frame after" in second.stdout
    # the cache is found by a run's preload (in a process of its own, and in this one, which renders with the
    # same numba target: conftest imported engine.jit first), and it loads what render then uses
    probe = ("from cmosnoise.engine.frame import kernel\n"
             "from cmosnoise import Sensor, load_config\n"
             "print(kernel.preload(), len(kernel._render.signatures))\n"
             "Sensor(load_config(extra={'sensor': {'width': 64, 'height': 48}})).expose().frame(0)\n"
             "print(len(kernel._render.signatures), sum(kernel._render.stats.cache_misses.values()))\n")
    third = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=600)
    assert third.returncode == 0, third.stderr
    assert third.stdout.split() == ["True", "1", "1", "0"], third.stdout + third.stderr
    empty = subprocess.run([sys.executable, "-c", "from cmosnoise.engine.frame import kernel\n"
                            "print(kernel.preload(), len(kernel._render.signatures))\n"],
                           env={**env, "NUMBA_CACHE_DIR": str(tmp_path / "empty")}, capture_output=True, text=True,
                           timeout=600)
    assert empty.stdout.split() == ["False", "0"], empty.stdout + empty.stderr  # nothing cached: never compiles
    # this process and its children key numba's cache alike (conftest imported engine.jit first), so what one
    # compiles the other loads; where this test's child compiled into the session's cache, this process loads it
    key = "from cmosnoise.engine.frame import kernel\nprint(repr(kernel._render.targetctx.codegen().magic_tuple()))\n"
    child = subprocess.run([sys.executable, "-c", key], env=env, capture_output=True, text=True, timeout=600)
    assert child.stdout.strip() == repr(kernel._render.targetctx.codegen().magic_tuple()), child.stdout + child.stderr
    if shared:
        assert kernel.preload(), "this process keys numba's cache unlike its children: the suite would compile twice"


@pytest.mark.slow
def test_numba_imported_first_still_gets_the_full_vector_width_or_says_it_did_not():
    """`import numba` before cmosnoise: the vector width is still chosen (numba's CPU target reads its features
    when it first compiles); where numba had compiled already, vectors() says the 256-bit tuning it got."""
    import os
    import subprocess
    import sys

    from cmosnoise.engine.jit import host_features

    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CPU_FEATURES", "NUMBA_CPU_NAME")}
    avx512 = "+avx512f" in (host_features() or "").split(",")
    first = ("import numba\nimport cmosnoise.engine.jit as j\n"
             "print(j.vectors() + '|' + str(numba.config.CPU_FEATURES))\n")
    out = subprocess.run([sys.executable, "-c", first], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    vectors, features = out.stdout.strip().split("|")
    if avx512:
        assert vectors == "AVX-512" and features.endswith("-prefer-256-bit"), out.stdout
    late = ("import numba\nnumba.njit(lambda x: x + 1)(1)\nimport cmosnoise.engine.jit as j\nprint(j.vectors())\n")
    out = subprocess.run([sys.executable, "-c", late], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == ("AVX-512 (256-bit preferred)" if avx512 else vectors), out.stdout


def _first_of_two_processes(code: str, tmp_path, absent: tuple[str, ...]) -> str:
    """The stderr of ``code`` run in a process whose compile cache lacks the loops named by ``absent`` (the
    starts of their entries' file names, ``module.function``), after checking that a second process, which loads
    what the first compiled, says nothing of compiling. The cache is the session's (whatever it holds by now)
    without those loops: the first process compiles them as on an empty cache, and loads the rest (the fixed
    maps and the like, which an empty cache made it compile too: a minute of the suite on 2 busy cores)."""
    import shutil
    import subprocess
    import sys

    session = os.environ.get("NUMBA_CACHE_DIR")
    if session and os.path.isdir(session):
        shutil.copytree(session, tmp_path / "cache", ignore=lambda _, names: [n for n in names if n.startswith(absent)])
    prelude = "import logging, numpy as np\nlogging.basicConfig(level=logging.INFO, format='%(message)s')\n"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    said = [subprocess.run([sys.executable, "-c", prelude + code], env=env, capture_output=True, text=True,
                           timeout=600) for _ in range(2)]
    assert all(r.returncode == 0 for r in said), said[0].stderr + said[1].stderr
    assert "compil" not in said[1].stderr, said[1].stderr
    return said[0].stderr


@pytest.mark.slow
def test_the_run_statistics_truth_and_picture_loops_say_once_that_they_compile(tmp_path):
    """#33: a compile of any variant says so once. With a compile cache without them the run statistics, the ground
    truth's expected raw, the pictures' one-pass demosaicing and the random telegraph loops each say once that
    they compile (the statistics' two variants, with and without a frame before, once together; the traps' and
    the blinking pixels' loops once together); a second process, which loads them from the cache, says
    nothing."""
    said = _first_of_two_processes(
        "from cmosnoise.analysis.run_stats import RunStats\n"
        "from cmosnoise.analysis import ground_truth\n"
        "from cmosnoise.isp import reconstruction\n"
        "from cmosnoise import Sensor\n"
        "raw = np.full((40, 60), 100, np.uint16)\n"
        "st = RunStats(4095)\n"
        "st.update(raw, raw.astype(np.float32)); st.update(raw, raw.astype(np.float32))\n"
        "ground_truth.expected_raw(Sensor({'sensor': {'width': 60, 'height': 40}}).expose('flat:0.5'))\n"
        "reconstruction.bilinear_srgb8(raw, 'RGGB', 64.0, 1000.0, None, np.ones(3, np.float32))\n"
        "reconstruction.superpixel_srgb8(raw, 'RGGB', 64.0, 1000.0, None, np.ones(3, np.float32))\n"
        "from cmosnoise.engine.frame import kernel\n"
        "rts = {'sensor': {'width': 60, 'height': 40}, 'dark_current': {'rts': {'enabled': True, 'ppm': 50000}},\n"
        "       'source_follower': {'rts': {'enabled': True, 'ppm': 50000}}}\n"
        "plan = Sensor(rts).expose('flat:0.5').plan()\n"
        "kernel.trap_values(plan, 0, (0, 40, 0, 60)); kernel.blink_means(plan, 0, (0, 40, 0, 60))\n", tmp_path,
        absent=("run_stats.", "ground_truth.", "reconstruction.", "kernel._trap_values", "kernel._blink_values"))
    for what in ("the run statistics", "the ground truth's expected raw", "the pictures' demosaicing to sRGB",
                 "the random telegraph loops"):
        assert said.count(f"compiling {what} for this machine") == 1, said


@pytest.mark.slow
def test_the_summarys_compiled_loops_say_once_that_they_compile(tmp_path):
    """#33: a compile of any variant says so once. With a compile cache without them the summary's reductions (one
    module's loops, several of them compiled in turn) are announced once; a second process, which loads them
    from the cache, says nothing."""
    said = _first_of_two_processes(
        "from cmosnoise.engine import reduce\n"
        "a = np.random.default_rng(0).random((300, 300)).astype(np.float32)\n"
        "reduce.statistics(a); reduce.total(a); reduce.positions_above(a, 0.5); reduce.statistics(a)\n", tmp_path,
        absent=("reduce.",))
    assert said.count("compiling the summary's reductions for this machine") == 1, said


def test_the_kernels_read_switches_and_key_rows_by_name_from_one_table():
    """#58: the switches, the key rows and the GPU table's columns are derived from one table of the temporal
    stages (frame/plan.STAGES); the CPU and the GPU loops read them by indices derived by name, never by a typed
    number; switches() fills each by its stage's own test, and a plan's key rows are the streams of those names."""
    import re
    from pathlib import Path

    from cmosnoise.engine.frame import cuda_table
    from cmosnoise.engine.frame import plan as frame
    from cmosnoise.model.seeds import STAGE_IDS, stream_key

    src = Path(kernel.__file__).parent
    for name in ("kernel.py", "cuda_device.py"):
        text = (src / name).read_text()
        literal = re.findall(r"\b(?:flags|keys)\[(?:p, )?\d", text)
        assert not literal, f"{name} reads a switch or a key row by a typed index: {literal}"
    names = [n for n, _ in frame.SWITCHES]
    assert names == [s.name for stage in frame.STAGES for s in stage.switches] and len(set(names)) == len(names)
    assert [frame.S_NOISY, frame.S_ROW, frame.S_BLINK_EXACT] == [names.index(n) for n in ("noisy", "row",
                                                                                       "blink_exact")]
    assert frame.KEY_ROWS == tuple(s.key for s in frame.STAGES if s.key)
    assert frame.NUMBERS == tuple(n for s in frame.STAGES for n in s.numbers)
    # every stage is a stage of the random-number scheme, and every plan field but the address is one stage's
    assert {s.name for s in frame.STAGES} - set(STAGE_IDS) == {"nonlinearity", "adc"}
    owned = [f for s in frame.STAGES for f in s.fields]
    fields = [f.name for f in dataclasses.fields(frame.FramePlan)]
    assert sorted(owned + list(frame.ADDRESS_FIELDS)) == sorted(fields), "a plan field no stage (or two) reads"
    cfg = load_config(extra={"sensor": {"width": 32, "height": 16}, "row_noise": {"enabled": True, "sigma_e": 1.0},
                             "column_noise": {"enabled": False}, "source_follower": {"enabled": False}})
    plan = Sensor(cfg, seed=5).expose("flat:0.5").plan()
    flags = frame.switches(plan, electrons=False, traps=False, blinkers=False)
    on = {n for n, v in zip(names, flags) if v}
    assert on == {"noisy", "row", "adc", "blink_exact"} - ({"blink_exact"} if plan.blink_noisy else set()), on
    asked = frame.switches(plan, electrons=True, traps=True, blinkers=True)
    assert {n for n, v in zip(names, asked) if v} - on == {"electrons", "traps", "blinkers"}
    for row, stage in enumerate(frame.KEY_ROWS):
        assert tuple(int(w) for w in plan.keys[row]) == stream_key(5, stage), stage
    assert plan.keys.shape[0] == len(frame.KEY_ROWS) and frame.KEY_ROW == frame.KEY_ROWS.index("row_noise")
    # the GPU's per-plan table: its columns by name too, each row filled by name and refused short of one
    assert [cuda_table.NORMAL_ABOVE, cuda_table.STEP, cuda_table.EXPOSURE, cuda_table.CDS] == [
        frame.NUMBERS.index("normal_above"), frame.NUMBERS.index("step"),
        frame.NUMBERS.index("exposure"), frame.INTS.index("cds")]
    ints = {"cds": 1, "nl_size": 2, "read_kind": 0}
    assert cuda_table.row(frame.INTS, ints) == [ints[n] for n in frame.INTS]
    with pytest.raises(RuntimeError, match="its columns are"):
        cuda_table.row(frame.INTS, {"read_kind": 0, "nl_size": 2})


def test_numbas_cache_of_the_kernel_is_keyed_on_the_stages_table():
    """The kernel takes the table's indices as constants: its on-disk cache entry carries plan.py's stamp beside
    its own file's, so an edit of the table alone recompiles it instead of loading stale indices."""
    import os

    from cmosnoise.engine.frame import plan as frame

    stamp = kernel._render._cache._cache_file._source_stamp
    st = os.stat(frame.__file__)
    assert stamp[1] == ((st.st_mtime, st.st_size),), stamp
