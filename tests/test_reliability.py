"""Faults and hostile input at the command line: each test reproduces the attack or the fault and checks the
refusal (one line, exit 2, nothing written) or the recovery. Every process a test starts is stopped by its id."""

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pandas as pd
import pytest
import tifffile
from conftest import cli, stop_process

SMALL = ["--set", "sensor.width=64", "--set", "sensor.height=48", "--scene", "flat:0.3"]


def _snapshot(folder):
    """{relative path: bytes} of every file in a folder."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _sweep(out, *extra, instances=4):
    return cli("sweep", *SMALL, "--vary", "prnu.sigma_pct=0.5,1.0", "--instances", instances, "--workers", 1,
               "--out", out, *extra)


def _spawn_sweep(out, *extra, instances=400):
    return subprocess.Popen([sys.executable, "-m", "cmosnoise", "sweep", *SMALL, "--vary", "prnu.sigma_pct=0.5,1.0",
                             "--instances", str(instances), "--workers", "1", "--out", str(out), *extra],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _wait_rows(path, n, proc, timeout_s=120):
    deadline = time.monotonic() + timeout_s
    while not (path.exists() and path.read_text().count("\n") > n):
        assert proc.poll() is None, proc.stderr.read()
        assert time.monotonic() < deadline, "no rows came"
        time.sleep(0.2)


@pytest.mark.slow
def test_an_interrupted_sweep_overwrite_keeps_the_old_sweep_byte_identical(tmp_path):
    out = tmp_path / "sweep"
    r = _sweep(out)
    assert r.returncode == 0, r.stderr
    before = _snapshot(out)
    proc = _spawn_sweep(out, "--overwrite")
    try:
        tmp_rows = None
        deadline = time.monotonic() + 120
        while tmp_rows is None:  # the new sweep writes beside out, in its temporary folder
            found = list(tmp_path.glob(".cmosnoise-tmp-*/out/results.csv"))
            if found and found[0].read_text().count("\n") > 3:
                tmp_rows = found[0]
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read() if proc.poll() else "slow"
            time.sleep(0.2)
        assert _snapshot(out) == before  # while it runs, the old sweep is untouched
        os.kill(proc.pid, signal.SIGTERM)
        proc.wait(60)
    finally:
        stop_process(proc)
    assert proc.returncode == 128 + signal.SIGTERM
    assert _snapshot(out) == before
    assert not list(tmp_path.glob(".cmosnoise-tmp-*")) and not list(tmp_path.glob(".cmosnoise-lock-*"))


@pytest.mark.slow
def test_a_second_sweep_on_a_running_sweeps_folder_exits_2(tmp_path):
    out = tmp_path / "sweep"
    proc = _spawn_sweep(out)
    try:
        _wait_rows(out / "results.csv", 2, proc)
        for extra in (["--resume"], ["--overwrite"], []):
            r = _sweep(out, *extra, instances=400)
            assert r.returncode == 2, (extra, r.stderr)
            assert ("being written by another cmosnoise run" in r.stderr or "already exists" in r.stderr), r.stderr
    finally:
        stop_process(proc)


@pytest.mark.slow
def test_resume_repairs_a_cut_last_row_and_equals_an_undisturbed_run(tmp_path):
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    assert _sweep(whole).returncode == 0
    assert _sweep(cut).returncode == 0
    results = cut / "results.csv"
    lines = results.read_bytes().splitlines(keepends=True)
    # the last two rows lost and the one before them half written: what a kill or a full disk mid-row leaves
    results.write_bytes(b"".join(lines[:-3]) + lines[-3][: len(lines[-3]) // 2])
    r = _sweep(cut, "--resume")
    assert r.returncode == 0, r.stderr
    text = results.read_text()
    assert text.endswith("\n") and text.count("\n") == 1 + 2 * 4  # the header and 8 rows, none twice

    def rows(path):
        return pd.read_csv(path).sort_values(["point", "instance"]).reset_index(drop=True)

    pd.testing.assert_frame_equal(rows(results), rows(whole / "results.csv"))
    assert (cut / "summary.csv").read_bytes() == (whole / "summary.csv").read_bytes()


def test_sweep_task_errors_are_found_before_any_task_runs(tmp_path):
    text = tmp_path / "scene.png"
    text.write_text("not a picture")
    cases = [
        (["--scene", str(text)], "cannot be read"),
        (["--vary", "sensor.width,sensor.height=64x48,30000x30000"], "needs about"),
    ]
    for extra, needle in cases:
        out = tmp_path / "s"
        r = cli("sweep", "--set", "sensor.width=64", "--set", "sensor.height=48", "--instances", 1, "--workers", 1,
                "--out", out, *extra)
        assert r.returncode == 2 and needle in r.stderr and r.stderr.count("\n") == 1, r.stderr
        assert not out.exists()


def test_sweep_from_refuses_a_list_an_alias_bomb_and_a_device(tmp_path):
    lst = tmp_path / "list.yaml"
    lst.write_text("- 1\n- 2\n")
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text('a: &a ["x","x","x","x","x","x","x","x","x"]\nb: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\n'
                    'c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]\nd: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]\n')
    zero = tmp_path / "zero.yaml"
    zero.symlink_to("/dev/zero")
    for path, needle in [(lst, "not a sweep.yaml"), (bomb, "aliases"), (zero, "a device")]:
        r = cli("sweep", "--from", path, "--out", tmp_path / "s")
        assert r.returncode == 2 and needle in r.stderr and r.stderr.count("\n") == 1, r.stderr


KILL_BETWEEN_RENAMES = textwrap.dedent("""
    import os, signal, sys
    from pathlib import Path
    from cmosnoise.io.output import OutputFolder

    real = os.rename

    def rename(a, b):  # the first rename of the swap (out moved aside) happens, then the process is killed
        real(a, b)
        os.kill(os.getpid(), signal.SIGKILL)

    out = Path(sys.argv[1])
    with OutputFolder(out, overwrite=True) as tmp:
        (tmp / "result.txt").write_text("new")
        os.rename = rename
""")


def test_a_kill_between_the_overwrite_renames_is_recovered_by_the_next_run(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "result.txt").write_text("old")
    proc = subprocess.run([sys.executable, "-c", KILL_BETWEEN_RENAMES, str(out)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == -signal.SIGKILL
    assert not out.exists()  # killed between the two renames: neither the old nor the new is in place
    assert len(list(tmp_path.glob(".cmosnoise-old-*"))) == 1 and len(list(tmp_path.glob(".cmosnoise-tmp-*"))) == 1
    # the next run beside it puts the completed results in place and says so (then refuses: out is not empty)
    r = cli("simulate", *SMALL, "--out", out)
    assert "restored the completed results of an interrupted run" in r.stderr, r.stderr
    assert (out / "result.txt").read_text() == "new"
    assert not list(tmp_path.glob(".cmosnoise-old-*")) and not list(tmp_path.glob(".cmosnoise-tmp-*"))
    assert r.returncode == 2 and "already exists" in r.stderr


def test_the_old_folder_is_restored_when_only_it_survived(tmp_path):
    import socket

    out = tmp_path / "run"
    # a dead run of this host, by name: no pid is above 2**22 (Linux's largest pid_max)
    old = tmp_path / f".cmosnoise-old-{socket.gethostname().replace('-', '_')}-{2**22 + 12345}-x"
    (old / "out").mkdir(parents=True)
    (old / "out" / "result.txt").write_text("old")
    (old / "target").write_text(str(out))
    r = cli("simulate", *SMALL, "--out", tmp_path / "other")
    assert r.returncode == 0 and "restored the previous results of an interrupted run" in r.stderr, r.stderr
    assert (out / "result.txt").read_text() == "old" and not old.exists()


def _fifo(path):
    os.mkfifo(path)
    return path


def test_devices_and_fifos_are_refused_within_a_second(tmp_path):
    zero = tmp_path / "zero"
    zero.symlink_to("/dev/zero")
    cases = [
        (["simulate", "--config", "{f}.yaml", "--out", tmp_path / "o"], "config file"),
        (["fit", "--frames-from", "{f}.yaml", "--out", tmp_path / "o"], "manifest"),
        (["characterize", "--frames-from", "{f}.txt", "--out", tmp_path / "o"], "EMVA descriptor"),
        (["sweep", "--from", "{f}.yaml", "--out", tmp_path / "o"], "--from"),
        (["process", "{f}.tiff", "--out", tmp_path / "o"], "raw file"),
        (["simulate", *SMALL[:4], "--scene", "{f}.png", "--out", tmp_path / "o"], "scene"),
    ]
    for kind in ("device", "fifo"):
        for args, what in cases:
            suffix = next(a for a in args if isinstance(a, str) and a.startswith("{f}"))[3:]
            path = tmp_path / f"{kind}-{what.replace(' ', '_').strip('-')}{suffix}"
            if kind == "device":
                path.symlink_to("/dev/zero")
            else:
                _fifo(path)
            argv = [str(path) if a == "{f}" + suffix else a for a in args]
            result = {}
            t = threading.Thread(target=lambda result=result, argv=argv: result.update(r=cli(*argv)), daemon=True)
            t0 = time.monotonic()
            t.start()
            t.join(10)
            assert not t.is_alive(), f"{argv} blocked on a {kind}"
            r = result["r"]
            assert time.monotonic() - t0 < 1.0, argv
            assert r.returncode == 2 and ("a device" in r.stderr or "a pipe" in r.stderr), (argv, r.stderr)
            assert r.stderr.count("\n") == 1 and not (tmp_path / "o").exists()


def test_a_raw_file_with_a_huge_page_is_refused_from_its_header(tmp_path):
    path = tmp_path / "huge.tiff"
    tifffile.imwrite(path, np.zeros((64, 64), np.uint16))
    with tifffile.TiffFile(path, mode="r+b") as tf:  # the header now claims 40000 x 40000 (3.2 GB decoded)
        tf.pages[0].tags["ImageWidth"].overwrite(40000)
        tf.pages[0].tags["ImageLength"].overwrite(40000)
    for args in (["process", path], ["process", tmp_path / "ok.tiff", "--dark", path]):
        tifffile.imwrite(tmp_path / "ok.tiff", np.zeros((2, 16, 16), np.uint16))
        r = cli(*args, "--cfa", "none", "--black-level", 0, "--bits", 12, "--out", tmp_path / "o")
        assert r.returncode == 2 and "40000 x 40000" in r.stderr and "megapixels" in r.stderr, r.stderr
    assert "dark file" in r.stderr  # --dark is named as such


def test_strict_scalars_and_finite_json(tmp_path):
    for setting, needle in [("sensor.width=1:2", "base-60"), ("seed=true", "expected a number"),
                            ("seed=017", "octal")]:
        r = cli("config", "--set", setting)
        assert r.returncode == 2 and needle in r.stderr, r.stderr
    r = cli("fit", "--frames-from", tmp_path / "m.yaml", "--threshold-e-per-s", "inf", "--out", tmp_path / "f")
    assert r.returncode == 2 and "finite" in r.stderr
    from cmosnoise.io.output import write_json

    write_json(tmp_path / "x.json", {"a": float("inf"), "b": [np.nan, 1.5], "c": np.float32("-inf")})
    assert (tmp_path / "x.json").read_text().split() == ['{', '"a":', 'null,', '"b":', '[', 'null,', '1.5', '],', '"c":', 'null', '}']


def test_a_name_too_long_and_export_inside_out_are_one_line(tmp_path):
    r = cli("simulate", *SMALL, "--out", tmp_path / ("x" * 300))
    assert r.returncode == 2 and "300 bytes long" in r.stderr and r.stderr.count("\n") == 1
    out = tmp_path / "c"
    r = cli("characterize", "--set", "sensor.width=32", "--set", "sensor.height=24", "--steps", 8,
            "--emva-export", out, "--out", out)
    assert r.returncode == 2 and "two separate folders" in r.stderr and not out.exists()


def test_a_run_larger_than_the_free_space_is_refused(tmp_path, monkeypatch):
    import collections
    import shutil

    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10**9, 10**9 - 10**6, 10**6))
    # 1000 frames of 64 x 48 uint16 are 6 MB: more than the 1 MB "free"
    r = cli("simulate", *SMALL, "--frames", 1000, "--out", tmp_path / "o")
    assert r.returncode == 2 and "GB free" in r.stderr and not (tmp_path / "o").exists()


FULL_DISK = textwrap.dedent("""
    import resource, signal, sys
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG, as a full disk with ENOSPC
    resource.setrlimit(resource.RLIMIT_FSIZE, (20000, 20000))
    from cmosnoise.app.cli import run
    sys.exit(run(sys.argv[1:]))
""")


@pytest.mark.slow
def test_a_write_that_fails_midway_is_one_line_and_leaves_nothing(tmp_path):
    out = tmp_path / "o"
    proc = subprocess.run([sys.executable, "-c", FULL_DISK, "simulate", *SMALL, "--frames", "20", "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().count("\n") == 0 and "nothing was written" in proc.stderr
    assert not out.exists() and not list(tmp_path.glob(".cmosnoise-*"))


def test_a_lock_file_left_by_a_killed_run_is_removed(tmp_path):
    from cmosnoise.io.output import _LOCK

    stale = tmp_path / f"{_LOCK}0123456789abcdef"
    stale.write_text("pid 1 on elsewhere")
    r = cli("simulate", *SMALL, "--out", tmp_path / "o")
    assert r.returncode == 0, r.stderr
    assert not stale.exists() and not list(tmp_path.glob(f"{_LOCK}*"))
