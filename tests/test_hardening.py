"""Hardening: an output folder whole or absent, clean interrupts, no leftovers (issue 12).

Every process a test starts is stopped by its id before the test ends.
"""

import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest
import tifffile
import yaml
from conftest import cli, cli_subprocess

SMALL = ["--set", "sensor.width=64", "--set", "sensor.height=48", "--scene", "flat:0.5"]


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".cmosnoise-"))


def _stop(proc):
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)


# ------------------------------------------------------------------ the rule for an existing --out
def test_an_existing_folder_is_refused_without_overwrite_and_replaced_whole_with_it(tmp_path):
    out = tmp_path / "run"
    assert cli("simulate", *SMALL, "--seed", "1", "--process", "--report", "--out", out).returncode == 0
    assert {"processed.png", "report.html"} <= {p.name for p in out.iterdir()}
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    r = cli("simulate", *SMALL, "--seed", "2", "--out", out)
    assert r.returncode == 2 and "already exists and is not empty" in r.stderr and "--overwrite" in r.stderr
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before  # untouched
    r = cli("simulate", *SMALL, "--seed", "2", "--overwrite", "--out", out)
    assert r.returncode == 0, r.stderr
    # replaced as a whole: the first run's processed.png and report.html are gone, not merged
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "preview.png", "raw.tiff", "summary.json"]
    assert yaml.safe_load((out / "config.yaml").read_text())["seed"] == 2
    assert _leftovers(tmp_path) == []


def test_an_empty_existing_folder_is_used(tmp_path):
    (tmp_path / "empty").mkdir()
    assert cli("simulate", *SMALL, "--out", tmp_path / "empty").returncode == 0
    assert (tmp_path / "empty" / "raw.tiff").exists()


@pytest.mark.parametrize("out", ["", ".", "./", ".."])
def test_the_current_folder_is_never_written_into(tmp_path, out):
    (tmp_path / "work").mkdir()
    r = cli("simulate", *SMALL, "--out", out, cwd=tmp_path / "work")
    assert r.returncode == 2 and "folder" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert list((tmp_path / "work").iterdir()) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["work"]


def test_a_run_that_fails_half_way_leaves_the_old_folder_whole(tmp_path):
    out = tmp_path / "run"
    assert cli("simulate", *SMALL, "--seed", "1", "--out", out).returncode == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    # the DNG needs the ADC: refused after the folder rule passed, before anything is replaced
    r = cli("simulate", *SMALL, "--seed", "2", "--overwrite", "--format", "dng", "--set", "adc.enabled=false", "--out", out)
    assert r.returncode == 2
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert _leftovers(tmp_path) == []


# ------------------------------------------------------------------ no temporary folder left by a failed run
def test_failed_process_and_characterize_runs_leave_nothing(tmp_path):
    (tmp_path / "bad.tif").write_bytes(b"not a tiff")
    r = cli("process", tmp_path / "bad.tif", "--out", tmp_path / "p")
    assert r.returncode == 2
    r = cli("characterize", "--frames-from", tmp_path / "nowhere", "--out", tmp_path / "c")
    assert r.returncode == 2
    r = cli("characterize", "--frames-from", tmp_path / "nowhere", "--out", tmp_path / "c", "--emva-export", tmp_path / "e")
    assert r.returncode == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.tif"]


def test_stale_temporary_folders_of_dead_runs_are_removed_and_said(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = socket.gethostname().replace("-", "_")
    stale = tmp_path / f".cmosnoise-tmp-{host}-{dead.pid}-abc123"
    stale.mkdir()
    (stale / "raw.tiff").write_bytes(b"x" * 1000)
    alive = tmp_path / f".cmosnoise-tmp-{host}-{os.getpid()}-def456"  # this process is alive: left alone
    alive.mkdir()
    r = cli("simulate", *SMALL, "--out", tmp_path / "run")
    assert r.returncode == 0, r.stderr
    assert not stale.exists() and alive.exists()
    assert "removed 1 temporary folder(s) left by interrupted runs" in r.stderr and str(stale) in r.stderr


def test_dng_files_follow_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        assert cli("simulate", *SMALL, "--format", "dng", "--out", tmp_path / "run").returncode == 0
    finally:
        os.umask(old)
    modes = {p.stat().st_mode & 0o777 for p in (tmp_path / "run" / "dng").iterdir()}
    assert modes == {0o644}
    assert (tmp_path / "run" / "raw.tiff").stat().st_mode & 0o777 == 0o644


# ------------------------------------------------------------------ two runs at once, signals
def _start(args, cwd=None):
    return subprocess.Popen([sys.executable, "-m", "cmosnoise", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=cwd)


def test_two_runs_on_one_folder_at_once_never_mix(tmp_path):
    out = tmp_path / "run"
    size = ["--set", "sensor.width=640", "--set", "sensor.height=480", "--frames", "40", "--no-progress", "--process",
            "--overwrite"]
    procs = [_start(["simulate", *size, "--seed", str(seed), "--out", out]) for seed in (11, 12)]
    try:
        results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    finally:
        for p in procs:
            _stop(p)
    codes = sorted(code for code, _ in results)
    assert codes in ([0, 0], [0, 2]), results
    for code, err in results:
        if code == 2:
            assert "is being written by another cmosnoise run" in err and "Traceback" not in err
    # whole: every file from the same run
    seed = yaml.safe_load((out / "config.yaml").read_text())["seed"]
    assert json.loads((out / "summary.json").read_text())["seed"] == seed
    with tifffile.TiffFile(out / "raw.tiff") as tf:
        assert tf.shaped_metadata[0]["seed"] == seed
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_a_signal_mid_run_cleans_up_and_exits_quietly(tmp_path, signum):
    out = tmp_path / "run"
    proc = _start(["simulate", "--set", "sensor.width=640", "--set", "sensor.height=480", "--frames", "2000",
                   "--no-progress", "--out", out])
    try:
        deadline = time.monotonic() + 120
        while not _leftovers(tmp_path) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert _leftovers(tmp_path), "the run never started writing"
        time.sleep(0.5)  # mid-run: frames are being written
        os.kill(proc.pid, signum)
        code = proc.wait(timeout=60)
        err = proc.stderr.read()
    finally:
        _stop(proc)
    assert code == 128 + signum, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists() and _leftovers(tmp_path) == []


def test_ctrl_c_while_starting_exits_130_without_a_traceback(tmp_path):
    proc = _start(["simulate", *SMALL, "--out", tmp_path / "run"])
    try:
        time.sleep(0.3)  # still importing SciPy and numba
        os.kill(proc.pid, signal.SIGINT)
        code = proc.wait(timeout=60)
        err = proc.stderr.read()
    finally:
        _stop(proc)
    assert code == 130 and "Traceback" not in err, err
    assert not (tmp_path / "run").exists() and _leftovers(tmp_path) == []
