"""A first run on the command line does not wait for the compilers (#63): the NumPy specification makes its
frames, the same bits, while `cmosnoise compile` builds the loops in the background; once it has, a process
loads them (mid-run too), and a run after it compiles nothing."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import tifffile

from cmosnoise.app.cli import run as cli_run
from cmosnoise.engine import jit

SMALL = ["--set", "sensor.width=64", "--set", "sensor.height=48", "--no-progress"]


def _env(tmp_path, **extra) -> dict:
    """A command line's environment as a user's: the console script's default mode (background), an empty
    compile cache and a temporary folder of the test's own (the build's lock and log are kept there)."""
    env = {k: v for k, v in os.environ.items() if k != jit.COMPILE_ENV}
    (tmp_path / "tmp").mkdir(exist_ok=True)
    return {**env, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "TMPDIR": str(tmp_path / "tmp"), **extra}


#: the console script beside this interpreter (what ``pip install`` wrote), as a user types it
CONSOLE_SCRIPT = Path(sys.executable).with_name("cmosnoise")


def _simulate(env, out, *args, console_script=False) -> subprocess.CompletedProcess:
    """``python -m cmosnoise simulate`` (or, with ``console_script``, the ``cmosnoise`` command) in ``env``."""
    entry = [str(CONSOLE_SCRIPT)] if console_script else [sys.executable, "-m", "cmosnoise"]
    return subprocess.run([*entry, "simulate", *SMALL, *args, "--out", str(out)], env=env, capture_output=True,
                          text=True, timeout=600)


def _pid_of(stderr: str) -> int:
    return int(stderr.split("(pid ")[1].split(")")[0])


def _stop_group(pid: int) -> None:
    """End the background compile (the leader of a session of its own) and everything it started, by its id."""
    try:
        os.killpg(pid, signal.SIGKILL)
    except ProcessLookupError:
        return
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:  # a child of a child: init reaps it once the process that started it has exited
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        if Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z":
            return
        time.sleep(0.05)
    raise AssertionError(f"the background compile {pid} did not end")


@pytest.mark.skipif(jit.numba is None or jit.fcntl is None, reason="needs numba and POSIX file locks")
@pytest.mark.slow
def test_a_first_run_takes_the_numpy_specification_while_the_loops_compile_in_the_background(tmp_path):
    """With nothing compiled for this machine, the `cmosnoise simulate` command says that it takes the NumPy
    specification and which process compiles; it writes the same raw frames as a run that compiles in its own
    process; the background process is `cmosnoise compile --background`, holding the build's lock with its pid in
    it; a second run meanwhile, started as `python -m cmosnoise`, starts no second compile: it joins the first's."""
    env = _env(tmp_path)
    assert CONSOLE_SCRIPT.exists(), f"the console script {CONSOLE_SCRIPT} (pip install -e . writes it)"
    first = _simulate(env, tmp_path / "a", "--frames", "2", console_script=True)
    pid = _pid_of(first.stderr) if "(pid " in first.stderr else None
    try:
        assert first.returncode == 0, first.stderr
        assert "takes the NumPy specification" in first.stderr and pid is not None, first.stderr
        assert "compiling the frame kernel" not in first.stderr, first.stderr
        cmdline = Path(f"/proc/{pid}/cmdline").read_text().split("\0")
        assert cmdline[-4:-1] == ["cmosnoise", "compile", "--background"], cmdline
        assert os.getpgid(pid) == pid  # a session of its own: it outlives the run, and one signal ends it
        (log,) = (tmp_path / "tmp").glob("cmosnoise-compile-*.log")  # in the run's temporary folder
        lock = log.with_suffix(".lock")
        deadline = time.monotonic() + 60
        while (not lock.exists() or lock.read_text().strip() != str(pid)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert lock.read_text().strip() == str(pid)
        second = _simulate(env, tmp_path / "b")
        assert second.returncode == 0, second.stderr
        # it starts no build of its own, and says how far the running one is: its pid, its time, its step
        assert f"another process builds them (pid {pid}, " in second.stderr and " of 3: " in second.stderr, \
            second.stderr
        # the same bits as a run whose loops compile (or load) in its own process, this one's
        assert cli_run(["simulate", *SMALL, "--frames", "2", "--out", str(tmp_path / "c")]) == 0
        assert np.array_equal(tifffile.imread(tmp_path / "a" / "raw.tiff"), tifffile.imread(tmp_path / "c" / "raw.tiff"))
    finally:
        if pid is not None:
            _stop_group(pid)


def _session_cache_without_the_frame_kernel(cache: Path) -> None:
    """``cache`` made a copy of the test session's compile cache (whatever it holds by now) without the frame
    kernel's entries: the build then compiles the frame kernel (and anything the session has not compiled yet) and
    loads the rest, instead of compiling every loop again (some 3 minutes of the suite on 2 busy cores)."""
    import shutil

    session = os.environ.get("NUMBA_CACHE_DIR")
    if session and Path(session).is_dir():
        shutil.copytree(session, cache, ignore=lambda _, names: [n for n in names if n.startswith("kernel._render-")])


@pytest.mark.slow
@pytest.mark.skipif(jit.numba is None or jit.fcntl is None, reason="needs numba and POSIX file locks")
def test_a_process_takes_the_loops_once_the_background_compile_has_built_them(tmp_path):
    """The background compile runs to its end (`cmosnoise compile --background`, every warm-up): a process that
    found the frame kernel missing then finds it in the cache and loads it, without compiling (numba counts no
    cache miss), mid-run, as a long first run does; a later command line run says nothing of compiling and its
    frame comes from the kernel. The cache starts as the session's without the frame kernel: the build's other
    warm-ups load what the session compiled (the first run's test builds from an empty cache)."""
    import json

    env = _env(tmp_path)
    _session_cache_without_the_frame_kernel(tmp_path / "cache")
    probe = ("from cmosnoise.engine import jit\nfrom cmosnoise.engine.frame import kernel\n"
             "from cmosnoise import Sensor, load_config\n"
             "first = jit.compiled('the frame kernel', kernel._render, say=False)\n"
             "proc = jit.build_process()\n"
             "print(proc.pid, flush=True)\n"
             "proc.wait(timeout=1200)\n"
             "now = jit.compiled('the frame kernel', kernel._render, say=False)\n"
             "Sensor(load_config(extra={'sensor': {'width': 64, 'height': 48}})).expose().frame(0)\n"
             "print(first, proc.returncode, now, len(kernel._render.signatures),\n"
             "      sum(kernel._render.stats.cache_misses.values()))\n")
    r = subprocess.run([sys.executable, "-c", probe], env={**env, jit.COMPILE_ENV: "background"}, capture_output=True,
                       text=True, timeout=1500)
    pid = int(r.stdout.split()[0]) if r.stdout.split() else None
    try:
        assert r.returncode == 0, r.stderr
        assert r.stdout.split()[1:] == ["False", "0", "True", "1", "0"], r.stdout + r.stderr
    finally:
        if pid is not None:
            _stop_group(pid)
    after = _simulate(env, tmp_path / "a")
    assert after.returncode == 0, after.stderr
    assert "compil" not in after.stderr and "NumPy" not in after.stderr, after.stderr
    stages = json.loads((tmp_path / "a" / "summary.json").read_text())["timings_s"]["stages"]
    assert "frame_kernel" in stages and "frame_numpy" not in stages, stages


def test_an_unknown_compile_mode_is_refused_in_one_line(monkeypatch):
    """CMOSNOISE_COMPILE takes foreground or background; anything else is named with what is allowed."""
    from cmosnoise.errors import CmosnoiseError

    monkeypatch.setenv(jit.COMPILE_ENV, "later")
    with pytest.raises(CmosnoiseError, match="CMOSNOISE_COMPILE='later': allowed are foreground, background"):
        jit.compile_mode()


@pytest.mark.skipif(jit.fcntl is None, reason="needs POSIX file locks")
def test_one_lock_whatever_starts_the_command_and_a_held_lock_starts_no_build(tmp_path, monkeypatch):
    # `cmosnoise` and `python -m cmosnoise` may name one interpreter by two paths: the lock is numba's cache's
    # key alone (#79). A process holding it (a foreground `cmosnoise compile`) is seen, and no build is started
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    lock, _ = jit.build_files()
    python = sys.executable
    monkeypatch.setattr(sys, "executable", "/some/other/path/python3")
    assert jit.build_files()[0] == lock
    holder = subprocess.Popen([python, "-c",
                               "import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT); "
                               "fcntl.flock(fd, fcntl.LOCK_EX); print('held', flush=True); time.sleep(60)", str(lock)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        monkeypatch.setattr(jit, "_BUILD", {})
        assert jit.building() and jit.start_build() is None and "process" not in jit._BUILD
    finally:
        holder.kill()
        holder.wait()
    assert not jit.building()


def _private_build_files(tmp_path, monkeypatch):
    """The build's lock, log and failure file in a folder of the test's own."""
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    monkeypatch.setattr(jit, "_ANNOUNCED", set())
    return jit.build_files()


def test_a_run_that_finds_a_build_running_says_how_far_it_is(tmp_path, monkeypatch, caplog):
    lock, log = _private_build_files(tmp_path, monkeypatch)
    lock.write_text("4242\n")
    os.utime(lock, (time.time() - 35, time.time() - 35))
    log.write_text("step 1 of 3: the default sensor: compiling what its run uses (or loading it ...) ...\n"
                   "the default sensor: 20.1 s\nstep 2 of 3: every stage on: compiling what its run uses ...\n")
    state = jit.build_state()
    assert state.startswith("pid 4242, 3") and state.endswith("s so far, at step 2 of 3: every stage on"), state
    with caplog.at_level("INFO", logger="cmosnoise.engine.jit"):
        jit._say_building(None)
    line = caplog.records[-1].getMessage()
    assert "another process builds them (pid 4242" in line and "step 2 of 3: every stage on" in line and str(log) in line


def test_a_failed_build_is_said_by_the_next_run_with_its_log_and_a_good_one_clears_it(tmp_path, monkeypatch,
                                                                                       caplog):
    from cmosnoise.app import compiling
    from cmosnoise.errors import CmosnoiseError

    lock, log = _private_build_files(tmp_path, monkeypatch)
    monkeypatch.setattr(compiling, "WARM_UPS", (("a broken run", {"sensor": {"width": -1}}),))
    said = []
    with pytest.raises(CmosnoiseError):
        compiling.build(say=said.append)
    assert said and said[0].startswith("step 1 of 1: a broken run")
    reason = jit.last_failure()
    assert reason is not None and reason.startswith("CmosnoiseError") and "sensor.width" in reason
    started = type("Started", (), {"pid": 777})()  # what start_build returns: the next run's build
    with caplog.at_level("INFO", logger="cmosnoise.engine.jit"):
        jit._say_building(started)
    line = caplog.records[-1].getMessage()
    assert line.startswith("the last background compile failed (CmosnoiseError") and str(log) in line
    assert "pid 777" in line
    monkeypatch.setattr(compiling, "WARM_UPS", ())  # a build that ends well removes the failure
    assert compiling.build(say=said.append) == {}
    assert jit.last_failure() is None and not jit.failure_file().exists()


@pytest.mark.skipif(jit.fcntl is None, reason="needs POSIX file locks")
def test_an_install_during_a_build_makes_it_start_over_on_the_new_sources_once_said(tmp_path, monkeypatch):
    """The package installed again while a build runs (its sources' stamp changes after the first step): the
    build says so in one line and replaces itself by a new build of the same kind (``os.execve``, the same pid
    and log) that holds the same lock, inherited; no temporary folder is left; after MAX_RESTARTS it goes on."""
    from cmosnoise.analysis import ground_truth
    from cmosnoise.app import compiling
    from cmosnoise.app import run as run_mod

    lock, _ = _private_build_files(tmp_path, monkeypatch)
    monkeypatch.setattr(compiling, "WARM_UPS", (("one", {}), ("two", {}), ("three", {})))
    monkeypatch.setattr(run_mod, "simulate", lambda config, out: None)
    monkeypatch.setattr(ground_truth, "expected_raw", lambda exposure: None)
    stamps = iter(["before", "before", "after"])  # the build's own, the check before step 1, the one before step 2
    monkeypatch.setattr(jit, "sources_stamp", lambda: next(stamps, "after"))
    monkeypatch.delenv(compiling.RESTARTS_ENV, raising=False)
    seen = {}

    class Replaced(Exception):
        pass

    def execve(path, args, env):
        fd = int(env[jit.LOCK_FD_ENV])
        seen.update(args=args, restarts=env[compiling.RESTARTS_ENV], mode=env[jit.COMPILE_ENV],
                    inheritable=os.get_inheritable(fd), pid=lock.read_text().strip())
        other = os.open(lock, os.O_RDWR)  # the lock is held through the exec: nobody else takes it meanwhile
        try:
            with pytest.raises(OSError):
                jit.fcntl.flock(other, jit.fcntl.LOCK_EX | jit.fcntl.LOCK_NB)
        finally:
            os.close(other)
        raise Replaced

    monkeypatch.setattr(os, "execve", execve)
    said = []
    with pytest.raises(Replaced):
        compiling.build(background=False, say=said.append)
    restarts = [line for line in said if "installed again" in line]
    assert len(restarts) == 1 and "starting over on the new sources (restart 1 of at most 3)" in restarts[0], said
    assert [line for line in said if line.startswith("step ")] == [said[0]]  # step 1 ran, step 2 did not
    assert seen["args"][1:] == ["-m", "cmosnoise", "compile"]  # a foreground build starts over as one
    assert seen["restarts"] == "1" and seen["mode"] == "foreground" and seen["inheritable"]
    assert seen["pid"] == str(os.getpid())
    assert not list(tmp_path.glob("cmosnoise-compile-*/"))  # the build's temporary folder went before the exec
    # a build that has started over MAX_RESTARTS times goes on to its end
    monkeypatch.setenv(compiling.RESTARTS_ENV, str(compiling.MAX_RESTARTS))
    monkeypatch.setattr(jit, "sources_stamp", lambda: str(time.perf_counter_ns()))
    assert set(compiling.build(say=said.append)) == {"one", "two", "three"}
