"""Shared helpers: every statistical tolerance comes from the estimator's sampling error."""

import atexit
import contextlib
import io
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

# One numba compile cache for the test sessions of this checkout, kept between them (tests/../.cache/numba-tests,
# ignored by git), so that a developer's second run of the fast tier loads the compiled loops instead of building
# them again; CMOSNOISE_TEST_FRESH_CACHE=1 gives a session an empty one of its own instead, removed at its end (what
# a clean clone's first run has anyway). Set before anything imports numba. The suite runs in two pytest-xdist
# workers (pyproject's addopts), which start after this file has run in the controlling process and so inherit the
# cache through the environment (CMOSNOISE_TEST_CACHE marks it as the session's, not a developer's own
# NUMBA_CACHE_DIR, which is kept). numba writes each entry whole, so the workers share it. The test of a first run
# (slow, moved to the front below) compiles into the session's cache where that is still empty, as a user's first
# run does; else into an empty cache of its own.
SESSION_CACHE = None
if os.environ.get("CMOSNOISE_TEST_CACHE") and os.environ.get("NUMBA_CACHE_DIR") == os.environ["CMOSNOISE_TEST_CACHE"]:
    SESSION_CACHE = os.environ["CMOSNOISE_TEST_CACHE"]  # an xdist worker: the controller's
elif not os.environ.get("NUMBA_CACHE_DIR"):
    if os.environ.get("CMOSNOISE_TEST_FRESH_CACHE"):
        SESSION_CACHE = tempfile.mkdtemp(prefix="cmosnoise-numba-cache-")
        # removed when the process that made it exits: pytest's (or xdist's controlling) process, or a script
        # that imports a test module (benchmarks/fit_coverage.py)
        atexit.register(shutil.rmtree, SESSION_CACHE, True)
    else:
        SESSION_CACHE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), ".cache",
                                     "numba-tests")
        os.makedirs(SESSION_CACHE, exist_ok=True)
    os.environ["NUMBA_CACHE_DIR"] = os.environ["CMOSNOISE_TEST_CACHE"] = SESSION_CACHE
FIRST_RUN_TEST = "test_the_first_run_says_once_that_it_compiles_and_later_runs_do_not"
# The tests' command lines compile in their own process, as the library does (the console script's default is a
# background compile while the NumPy specification runs: engine/jit.py, compiled), so that no test leaves a
# compiling process behind; the tests of the background compile set it themselves and stop what they start.
os.environ["CMOSNOISE_COMPILE"] = "foreground"
# numba's CUDA simulator stands in for a GPU (set before numba is imported, here and in every child): the GPU
# kernel's tests (test_cuda.py) and `--device cuda` then run on any machine. CMOSNOISE_TEST_GPU=1 runs them on the
# machine's real GPU instead.
if not os.environ.get("CMOSNOISE_TEST_GPU"):
    os.environ.setdefault("NUMBA_ENABLE_CUDASIM", "1")
# The explorer's token (app/explore.py): one random token for the session's explorers (their processes inherit it),
# and every urllib request of a test carries it unless the test builds an opener of its own to show that a request
# without it is refused.
import secrets as _secrets  # noqa: E402
import urllib.request as _urlreq  # noqa: E402

EXPLORE_TOKEN = os.environ.setdefault("CMOSNOISE_EXPLORE_TOKEN", "test-" + _secrets.token_urlsafe(24))


class _ExplorerToken(_urlreq.BaseHandler):
    def http_request(self, req):
        if not req.has_header("X-cmosnoise-token"):
            req.add_unredirected_header("X-cmosnoise-token", EXPLORE_TOKEN)
        return req


_urlreq.install_opener(_urlreq.build_opener(_ExplorerToken))
# numba's target as the package sets it (engine/jit.py: the host's full vector width), before a test module
# imports numba itself: this process and its children then key the compile cache alike
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import cmosnoise.engine.jit  # noqa: E402, F401
from cmosnoise import load_config  # noqa: E402
from cmosnoise.model.spec import resolve  # noqa: E402

#: the longest file (its fit round trip is some three minutes): started at once, on the other worker
LONGEST_FILE = "test_fit_stages.py"


def pytest_collection_modifyitems(items):
    """The first-run test before every other (it needs the session's compile cache still empty), then the
    longest file. xdist hands files to its two workers in this order (pyproject's ``--no-loadscope-reorder``):
    the first-run test's file to one, the longest file to the other."""
    items.sort(key=lambda item: (item.name != FIRST_RUN_TEST, item.path.name != LONGEST_FILE))  # stable
    for item in items:  # a GPU test is slow too: `-m "not slow"` leaves the CUDA simulator's tests out
        if item.get_closest_marker("gpu") and not item.get_closest_marker("slow"):
            item.add_marker(pytest.mark.slow)


#: a test of the fast tier (not marked slow) whose call takes longer than this on the machine it runs on is named
#: at the session's end: the fast tier is the inner loop (docs/development.md, "Suite times"), so mark it slow or
#: make it cheaper. Said, not failed: a timing is not a test's verdict on a shared machine.
FAST_TIER_LIMIT_S = 5.0
_LONG_FAST_TESTS: list[tuple[float, str]] = []


#: where the session's timeline goes, if anywhere: each test's phase as "worker start stop phase nodeid" (epoch
#: seconds), for finding what a clean clone's suite waits on (docs/development.md, "Suite times")
TIMELINE = os.environ.get("CMOSNOISE_TEST_TIMELINE")


def pytest_runtest_logreport(report):
    """Note a call of a test outside the slow tier that took over :data:`FAST_TIER_LIMIT_S` (xdist's workers
    report to the controlling process, which runs this); with ``CMOSNOISE_TEST_TIMELINE`` set, write each phase's
    start and stop to that file."""
    if report.when == "call" and report.duration > FAST_TIER_LIMIT_S and "slow" not in report.keywords:
        _LONG_FAST_TESTS.append((report.duration, report.nodeid))
    if TIMELINE and hasattr(report, "start") and not os.environ.get("PYTEST_XDIST_WORKER"):  # the controller's
        worker = getattr(getattr(getattr(report, "node", None), "gateway", None), "id", "main")
        with open(TIMELINE, "a") as fh:
            fh.write(f"{worker} {report.start:.2f} {report.stop:.2f} {report.when} {report.nodeid}\n")


def pytest_terminal_summary(terminalreporter):
    """Name the fast tier's tests that took over :data:`FAST_TIER_LIMIT_S`."""
    if _LONG_FAST_TESTS:
        terminalreporter.section(f"tests of the fast tier over {FAST_TIER_LIMIT_S:g} s")
        for seconds, nodeid in sorted(_LONG_FAST_TESTS, reverse=True):
            terminalreporter.write_line(f"{seconds:6.1f} s  {nodeid}: mark it slow or make it cheaper")


#: what another x86-64 CPU would change, changed in a child process on this one: NumPy's SIMD loops off (its float64
#: exp, log, power and sin give other last bits without its AVX2 loops, measured), OpenBLAS's Prescott kernels (other
#: sums in a dot or a LAPACK solve), and glibc's libm without its FMA and AVX2 variants (exp, sin, log and erfc,
#: which compiled loops call through math.*, give other last bits, measured on glibc 2.36)
ANOTHER_CPU = {"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR", "OPENBLAS_CORETYPE": "Prescott",
               "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F"}
#: where ANOTHER_CPU's names mean something (x86-64 dispatch targets and BLAS kernels; glibc's tunables elsewhere
#: are ignored)
X86_64 = platform.machine() in ("x86_64", "AMD64")


#: number of standard errors a statistic may stray before a test fails.
#: 5 sigma: a correct implementation fails about once in 1.7 million runs.
Z = 5.0


def quiet_config(**sections):
    """A resolved configuration (physics checked, PRNU solved) with every stage off except those given (dict per
    section)."""
    base = {
        "prnu": {"enabled": False},
        "crosstalk": {"enabled": False},
        "shot_noise": {"enabled": False},
        "dark_current": {"enabled": False},
        "source_follower": {"enabled": False},
        "row_noise": {"enabled": False},
        "column_noise": {"enabled": False},
    }
    for k, v in sections.items():
        base[k] = {**base.get(k, {}), **v}
    return resolve(load_config(extra=base)).config


def assert_close(measured, expected, se, what=""):
    """|measured - expected| <= Z standard errors."""
    assert abs(measured - expected) <= Z * se, (
        f"{what}: measured {measured:.6g}, expected {expected:.6g}, "
        f"differs by {abs(measured - expected) / se:.1f} standard errors (allowed {Z})"
    )


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def smoothed_std_se(std: float, n: int, kernel) -> float:
    """Standard error of a sample standard deviation over ``n`` pixels of white noise smoothed by ``kernel``.

    For a stationary Gaussian field Var(s^2) = (2 sigma^4 / n) sum_d rho(d)^2, with rho the kernel's
    normalised autocorrelation; so se(s) = s sqrt(sum_d rho(d)^2 / (2 n)).
    """
    from scipy.signal import correlate2d

    k = np.asarray(kernel, dtype=np.float64)
    auto = correlate2d(k, k)
    rho = auto / auto.max()
    return std * np.sqrt(np.sum(rho**2) / (2 * n))


def temporal_variance_se(sensor, dof: float, signal_e=0.0) -> float:
    """Standard error (DN^2) of a pooled temporal variance with ``dof`` degrees of freedom per pixel.

    Estimators: the mean over pixels of per-pixel sample variances over L
    frames (dof = L - 1), or of var(A - B)/2 over P independent frame pairs
    (dof = P). A normal term of variance v contributes 2 v^2 / dof per
    independent sample: pixels (each with its own v: dark shot, flicker,
    photon shot, read noise after the gain, with its fourth cumulant where it
    is not normal), rows (one sample per row) and columns (one per column).
    """
    c = sensor.config
    fp = sensor.fixed_pattern
    k2 = sensor.transfer.gain_dn_per_e ** 2
    rows, cols = sensor.shape
    v_pix = np.zeros(sensor.shape) + signal_e
    if fp.dark_rate is not None and c.dark_current.shot_noise:
        v_pix = v_pix + fp.dark_rate.astype(np.float64) * c.exposure.integration_time_s
    if c.source_follower.enabled:
        v_pix = v_pix + c.source_follower.thermal_sigma_e**2
        if fp.flicker_sigma is not None:
            v_pix = v_pix + fp.flicker_sigma.astype(np.float64) ** 2
    v_pix = v_pix * k2 + 1 / 12
    k4 = 0.0  # the read noise's fourth cumulant (DN^4): a pair's var(D^2 / 2) is 2 v^2 + k4 / 2, not 2 v^2
    if c.read_noise.enabled and c.adc.enabled:
        rn = c.read_noise
        if rn.distribution == "normal":
            v_pix = v_pix + rn.scale_dn**2
        else:
            from scipy import stats

            var, kurt = (float(x) for x in stats.tukeylambda(rn.shape).stats(moments="vk"))
            v_pix = v_pix + var * rn.scale_dn**2
            k4 = kurt * (var * rn.scale_dn**2) ** 2
    se2 = (np.mean(2 * v_pix**2) + k4 / 2) / v_pix.size
    if c.row_noise.enabled:
        se2 += 2 * (sensor.spec.row_sigma_e**2 * k2) ** 2 / rows
    if fp.column_sigma is not None:
        se2 += np.mean(2 * (fp.column_sigma.astype(np.float64) ** 2 * k2) ** 2) / cols
    return float(np.sqrt(se2 / dof))


def std_se_with_noise(true_var: float, noise_var: float, n: int) -> float:
    """Standard error of ``sqrt(var(x) - noise_var)`` for n values x = o + e (o fixed pattern, e noise).

    var(x) - noise_var has se sqrt((2 (true_var + noise_var)^2) / (n - 1));
    the square root divides it by 2 sqrt(true_var).
    """
    return float(np.sqrt(2 / (n - 1)) * (true_var + noise_var) / (2 * np.sqrt(true_var)))


def on_threads(n: int, fn):
    """``fn()`` with numba's parallel loops on ``n`` threads (the thread count restored after)."""
    import numba

    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(n)
        return fn()
    finally:
        numba.set_num_threads(threads)


# ------------------------------------------------------------------ the command line
@dataclass
class CliResult:
    returncode: int
    stdout: str
    stderr: str


@contextlib.contextmanager
def _cwd(path):
    old = os.getcwd()
    if path is not None:
        os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


def cli(*args, cwd=None) -> CliResult:
    """Run ``cmosnoise ARGS`` in this process (no interpreter start-up), as the console script would."""
    from cmosnoise.app.cli import run

    out, err = io.StringIO(), io.StringIO()
    with _cwd(cwd), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = run([str(a) for a in args])
    return CliResult(code, out.getvalue(), err.getvalue())


def cli_subprocess(*args, cwd=None, timeout=300) -> subprocess.CompletedProcess:
    """Run ``python -m cmosnoise ARGS`` as a separate process: for exit codes, signals, the real entry point."""
    return subprocess.run([sys.executable, "-m", "cmosnoise", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=timeout)


# ------------------------------------------------------------------ the browser (pytest-playwright)
@pytest.fixture(scope="session")
def browser_type_launch_args(browser_type_launch_args):
    """The system Chromium (Debian's `chromium`; .ci/run installs it): Playwright's own download is not used."""
    import shutil

    path = shutil.which("chromium") or shutil.which("chromium-browser")
    assert path, "the browser tests need the system Chromium: apt-get install chromium (.ci/run does)"
    return {**browser_type_launch_args, "executable_path": path, "args": ["--no-sandbox"]}


# ------------------------------------------------------------------ processes the tests start (stopped by their id)
#: Dask's command beside this interpreter (its venv's bin, on the PATH or not)
DASK = str(Path(sys.executable).with_name("dask"))


def free_port() -> int:
    """A free TCP port on the loopback address."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_port(port: int, proc=None, timeout_s: float = 60) -> None:
    """Until something listens on 127.0.0.1:``port`` (fails early if ``proc`` exits)."""
    import socket
    import time

    deadline = time.monotonic() + timeout_s
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            assert proc is None or proc.poll() is None, f"the process exited ({proc.returncode}) before listening"
            assert time.monotonic() < deadline, f"nothing listens on port {port} after {timeout_s} s"
            time.sleep(0.2)


def stop_process(proc, timeout_s: float = 30) -> None:
    """SIGTERM by its id, then SIGKILL if it does not end in time."""
    import signal

    if proc is None or proc.poll() is not None:
        return
    os.kill(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()


def takes_o_direct(folder) -> bool:
    """Whether files in ``folder`` open with O_DIRECT (the system has it, the file system takes it)."""
    if not hasattr(os, "O_DIRECT"):
        return False
    probe = folder / "probe"
    probe.touch()
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_DIRECT))
        return True
    except OSError:
        return False


def refuse_direct_writes(monkeypatch) -> list:
    """Make ``os.pwrite`` refuse (``EINVAL``) every write to a descriptor opened with O_DIRECT, as a file system
    that opens files so but takes no direct write; returns the list the refused writes' offsets go to."""
    import errno
    import fcntl

    refused, pwrite = [], os.pwrite

    def refuse(fd, data, offset):
        if fcntl.fcntl(fd, fcntl.F_GETFL) & getattr(os, "O_DIRECT", 0):
            refused.append(offset)
            raise OSError(errno.EINVAL, "Invalid argument")
        return pwrite(fd, data, offset)

    monkeypatch.setattr(os, "pwrite", refuse)
    return refused
