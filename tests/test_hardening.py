"""Hardening: an output folder whole or absent, clean interrupts, no leftovers.

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
from conftest import cli

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
    # a 2-frame stack would read back as a pair: the export that could not be loaded again is refused before any work
    r = cli("characterize", "--stack-frames", "2", "--out", tmp_path / "c", "--emva-export", tmp_path / "e")
    assert r.returncode == 2 and "--stack-frames 2 with --emva-export" in r.stderr
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


@pytest.mark.slow
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


def _wait_for_the_commands_handlers(proc, timeout=30.0):
    """Wait until the command's own signal handlers are in (cmosnoise.app.entry.main installs one for SIGTERM,
    which the interpreter leaves at its default), so that a signal reaches the command and not the interpreter's
    start-up: a SIGINT while `site` runs the .pth files is Python's own fatal error (status 1, a traceback no
    program can catch), seen on a loaded CI machine with a fixed 0.3 s sleep. Linux: SigCgt in /proc; elsewhere
    the old fixed wait."""
    status = f"/proc/{proc.pid}/status"
    if not os.path.exists(status):
        time.sleep(0.3)
        return
    bit = 1 << (int(signal.SIGTERM) - 1)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        with open(status) as f:
            caught = next((int(line.split()[1], 16) for line in f if line.startswith("SigCgt:")), 0)
        if caught & bit:
            return
        time.sleep(0.002)
    raise AssertionError("the command never installed its signal handlers")


def test_ctrl_c_while_starting_exits_130_without_a_traceback(tmp_path):
    proc = _start(["simulate", *SMALL, "--out", tmp_path / "run"])
    try:
        _wait_for_the_commands_handlers(proc)  # from here it imports SciPy and numba for about a second
        os.kill(proc.pid, signal.SIGINT)
        code = proc.wait(timeout=60)
        err = proc.stderr.read()
    finally:
        _stop(proc)
    assert code == 130 and "Traceback" not in err, err
    assert not (tmp_path / "run").exists() and _leftovers(tmp_path) == []


def test_an_interrupt_a_library_swallows_still_stops_the_command(tmp_path, monkeypatch):
    """A signal whose exception is raised inside a C callback (LLVM's, through ctypes, while numba loads the
    kernel) cannot unwind: ctypes reports it as unraisable and carries on. The command must still end as
    interrupted (130), with no output and no traceback. Seen with a Ctrl-C about a second into `simulate`."""
    import signal as sig
    import sys as _sys
    import types

    from conftest import cli

    from cmosnoise import errors
    from cmosnoise.app import run as run_mod

    original = run_mod.simulate

    def swallowing(*args, **kwargs):
        try:  # what ctypes does with an exception in a callback
            errors.signal_received(sig.SIGINT)
        except errors.Terminated as exc:
            _sys.unraisablehook(types.SimpleNamespace(exc_type=type(exc), exc_value=exc, exc_traceback=None,
                                                      err_msg="on calling ctypes callback function", object=None))
        return original(*args, **kwargs)

    monkeypatch.setattr(run_mod, "simulate", swallowing)
    r = cli("simulate", *SMALL, "--out", tmp_path / "run")
    assert r.returncode == 130 and "Traceback" not in r.stderr and "Terminated" not in r.stderr, (r.returncode, r.stderr)
    assert not (tmp_path / "run").exists() and _leftovers(tmp_path) == []


# ------------------------------------------------------------------ values the schema took but the physics could not
@pytest.mark.parametrize("setting, needle", [
    ("exposure.peak_rate_e_per_s=1.0e30", "exposure.peak_rate_e_per_s"),
    ("sensor.channel_responsivity=[1.0e308, 1, 1]", "sensor.channel_responsivity"),
    ("scene.scale=1.0e-300", "scene.scale"),
    ("adc.full_scale_e=.inf", "adc.full_scale_e"),
    ("sensor.full_well_e=1.0e-300", "sensor.full_well_e"),
    ("dark_current.points=[{temperature_c: 25, distribution: gamma, mean_e_per_s: 5, std_e_per_s: 1.0e-300}]", "std"),
    ("dark_current.points=[{temperature_c: 25, distribution: lognormal, mean_e_per_s: .inf, std_e_per_s: 1}]", "mean_e_per_s"),
    ("dark_current.points=[{temperature_c: 25, distribution: lognormal, mean_e_per_s: 1.0e300, std_e_per_s: 1}]", "mean_e_per_s"),
    ("dark_current.points.0.tail.max_e_per_s=.inf", "max_e_per_s"),
    ("crosstalk.kernel_pct=[[1, 1, 1], [1, 0, 1], [1, 1, 1]]", "centre"),
    ("crosstalk.kernel_pct=[[0, 0, 0], [0, 0, 0], [0, 0, 0]]", "centre"),
    ("prnu.sigma_pct=.nan", "prnu.sigma_pct"),
    ("run.first_frame=4294967296", "run.first_frame"),  # frame 2**32 would share frame 0's noise (a 32-bit counter)
])
def test_values_beyond_physics_are_one_line_errors(tmp_path, setting, needle):
    for command in (["simulate", *SMALL, "--out", tmp_path / "run"], ["config"]):
        r = cli(*command, "--set", setting)
        assert r.returncode == 2 and needle in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_hostile_files_are_refused_before_they_are_read(tmp_path):
    (tmp_path / "laughs.yaml").write_text('a: &a ["x", "x"]\nb: &b [*a, *a]\nc: &c [*b, *b]\nd: [*c, *c]\n')
    (tmp_path / "deep.yaml").write_text("a: " + "[" * 3000 + "]" * 3000 + "\n")
    (tmp_path / "keys.yaml").write_text("".join(f"k{i}: 1\n" for i in range(20000)))
    (tmp_path / "huge.yaml").write_text("a: 1\n" + "#" * 1_100_000 + "\n")
    for name, needle in [("laughs.yaml", "aliases"), ("deep.yaml", "nested more than"), ("huge.yaml", "larger than"),
                         ("keys.yaml", "and 19995 more")]:
        r = cli("config", "--config", tmp_path / name)
        assert r.returncode == 2 and needle in r.stderr, (name, r.stderr)
        assert len(r.stderr) < 800, (name, len(r.stderr))  # one short line, not the expanded value or 20000 keys
    for path in ["/dev/zero", str(tmp_path)]:
        assert cli("config", "--config", path).returncode == 2
        r = cli("simulate", *SMALL[:4], "--scene", path, "--out", tmp_path / "o")
        assert r.returncode == 2 and "Traceback" not in r.stderr


def test_a_decompression_bomb_scene_is_refused_from_its_header(tmp_path):
    import numpy as np
    from PIL import Image

    Image.fromarray(np.zeros((9000, 8000), np.uint8)).save(tmp_path / "bomb.png")  # 72 MP, a few hundred kB
    assert (tmp_path / "bomb.png").stat().st_size < 1_000_000
    t0 = time.monotonic()
    r = cli("simulate", *SMALL[:4], "--scene", tmp_path / "bomb.png", "--out", tmp_path / "o")
    assert r.returncode == 2 and "8000 x 9000 pixels" in r.stderr and "megapixels" in r.stderr
    assert time.monotonic() - t0 < 10 and not (tmp_path / "o").exists()


def test_a_run_that_cannot_fit_in_memory_is_refused_with_the_estimate(tmp_path):
    t0 = time.monotonic()
    r = cli("simulate", "--set", "sensor.width=30000", "--set", "sensor.height=30000", "--out", tmp_path / "o")
    assert r.returncode == 2 and "needs about" in r.stderr and "GB available" in r.stderr
    assert time.monotonic() - t0 < 10 and list(tmp_path.iterdir()) == []
    from cmosnoise import CmosnoiseError, load_config
    from cmosnoise.model import footprint

    cfg = load_config(extra={"sensor": {"width": 1920, "height": 1080}})
    need = footprint.estimate_bytes(cfg)
    footprint.check_fits(cfg, available=need)
    with pytest.raises(CmosnoiseError, match="needs about"):
        footprint.check_fits(cfg, available=need - 1)


# ------------------------------------------------------------------ process and characterize inputs
def _raw_file(path, meta_over=None, shape=(3, 32, 48), photometric="minisblack"):
    import numpy as np

    meta = {"cfa": "RGGB", "black_level_dn": 64, "bits": 12, **(meta_over or {})}
    data = (np.arange(np.prod(shape)) % 900 + 64).astype(np.uint16).reshape(shape)
    tifffile.imwrite(path, data, photometric=photometric, metadata=meta)
    return path


@pytest.mark.parametrize("meta, needle", [
    ({"crosstalk_kernel_pct": "garbage"}, "crosstalk.kernel_pct"),
    ({"crosstalk_kernel_pct": [[0, 0, 0], [0, 0, 0], [0, 0, 0]]}, "centre"),
    ({"crosstalk_kernel_pct": [[100, 100, 100], [100, 100, 100], [100, 100, 100]]}, "sums to 900"),
    ({"channel_responsivity": "abc"}, "channel_responsivity"),
    ({"bits": 999999}, "adc.bits"),
    ({"cfa": "XYZW"}, "sensor.cfa"),
])
def test_process_validates_the_raw_files_metadata(tmp_path, meta, needle):
    r = cli("process", _raw_file(tmp_path / "raw.tif", meta), "--out", tmp_path / "p")
    assert r.returncode == 2 and needle in r.stderr and "metadata is not valid" in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["raw.tif"]


def test_process_refuses_an_rgb_picture_and_a_master_dark_out_of_range(tmp_path):
    import numpy as np

    rgb = tmp_path / "rgb.tif"
    tifffile.imwrite(rgb, np.zeros((64, 64, 3), np.uint8), photometric="rgb", metadata={"cfa": "RGGB", "black_level_dn": 0, "bits": 8})
    r = cli("process", rgb, "--out", tmp_path / "p")
    assert r.returncode == 2 and "RGB" in r.stderr and "one CFA sample per pixel" in r.stderr
    raw = _raw_file(tmp_path / "raw.tif")
    tifffile.imwrite(tmp_path / "dark.tif", np.full((32, 48), -1e30, np.float32))
    r = cli("process", raw, "--dark", tmp_path / "dark.tif", "--out", tmp_path / "p")
    assert r.returncode == 2 and "are not raw codes of 12 bits" in r.stderr
    assert not (tmp_path / "p").exists()


def test_process_streams_the_frames(tmp_path):
    """A stack is read frame by frame: Python's peak allocation stays near one frame's processing, not the stack."""
    import tracemalloc

    raw = _raw_file(tmp_path / "raw.tif", shape=(120, 96, 128))  # 2.9 MB of codes
    stack_bytes = 120 * 96 * 128 * 2
    # once before, so the imports and the compiled loops' loading (or compiling: 38 MB) are not measured, as
    # when an earlier test of the session has run the command
    assert cli("process", _raw_file(tmp_path / "warm.tif"), "--out", tmp_path / "warm").returncode == 0
    tracemalloc.start()
    try:
        r = cli("process", raw, "--out", tmp_path / "p")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "p" / "summary.json").read_text())["frames"] == 120
    assert peak < stack_bytes / 2, (peak, stack_bytes)


def test_characterize_inputs_are_checked(tmp_path):
    import numpy as np

    (tmp_path / "bin.txt").write_bytes(b"\x00\xff\xfe binary")
    r = cli("characterize", "--frames-from", tmp_path / "bin.txt", "--out", tmp_path / "c")
    assert r.returncode == 2 and "not a text file" in r.stderr
    (tmp_path / "e").mkdir()
    img = np.zeros((8, 8), np.uint16)
    lines = ["n 12 8 8"]
    for j, t in enumerate([0, 0, 0]):
        for kind in "bd":
            for q in range(2):
                tifffile.imwrite(tmp_path / "e" / f"{kind}{j}{q}.tif", img)
            lines += [f"{kind} {t} 10" if kind == "b" else f"{kind} {t}", f"i {kind}{j}0.tif", f"i {kind}{j}1.tif"]
    for kind in "bd":
        for q in range(3):
            tifffile.imwrite(tmp_path / "e" / f"s{kind}{q}.tif", img)
        lines += [f"{kind} 5 10" if kind == "b" else f"{kind} 5"] + [f"i s{kind}{q}.tif" for q in range(3)]
    (tmp_path / "e" / "EMVA1288_descriptor.txt").write_text("\n".join(lines) + "\n")
    r = cli("characterize", "--frames-from", tmp_path / "e", "--out", tmp_path / "c")
    assert r.returncode == 2 and "distinct exposure time" in r.stderr, r.stderr
    desc = tmp_path / "e" / "EMVA1288_descriptor.txt"
    desc.write_text(desc.read_text().replace("b 0 10", "b 1 10", 1).replace("d 0", "d 1", 1)
                    .replace("b 0 10", "b 2 10", 1).replace("d 0", "d 2", 1))  # 3 distinct times: 1, 2, 0
    tifffile.imwrite(tmp_path / "e" / "b00.tif", np.zeros((8, 9), np.uint16))
    r = cli("characterize", "--frames-from", tmp_path / "e", "--out", tmp_path / "c")
    assert r.returncode == 2 and "the descriptor says 8 x 8" in r.stderr, r.stderr
    (tmp_path / "e" / "EMVA1288_descriptor.txt").write_text("n 999999 8 8\n")
    r = cli("characterize", "--frames-from", tmp_path / "e", "--out", tmp_path / "c")
    assert r.returncode == 2 and "1 to 16 bits" in r.stderr
    r = cli("characterize", "--set", "sensor.width=32", "--set", "sensor.height=32", "--steps", "8",
            "--stack-frames", "2", "--out", tmp_path / "c")
    assert r.returncode == 0, r.stderr  # the smallest series allowed works on a small sensor
    assert cli("characterize", "--steps", "7", "--out", tmp_path / "c2").returncode == 2
    assert not (tmp_path / "c2").exists() and _leftovers(tmp_path) == []


# ------------------------------------------------------------------ the Python API
def test_the_api_raises_cmosnoise_errors_that_name_the_argument():
    import numpy as np

    from cmosnoise import CmosnoiseError, Sensor

    small = {"sensor": {"width": 16, "height": 12}}
    s = Sensor(small)  # a dict is a configuration
    assert s.shape == (12, 16)
    cases = [
        (lambda: Sensor(seed=1.5), "seed = 1.5"),
        (lambda: Sensor(3), "config: expected"),
        (lambda: Sensor("nowhere.yaml"), "does not exist"),
        (lambda: s.capture(frames=0), "frames = 0"),
        (lambda: s.frame if False else s.expose("flat:0.5").frame(1.7), "1.7"),
        (lambda: list(s.dark_frames(-1)), "n = -1"),
        (lambda: s.expose(np.full((12, 16), np.nan)), "NaN"),
        (lambda: s.expose(-np.ones((12, 16, 3))), "negative"),
        (lambda: s.expose(np.ones((12, 16, 4))), "(12, 16, 4)"),
        (lambda: s.expose(np.ones((5, 5))), "(5, 5)"),
    ]
    for call, needle in cases:
        with pytest.raises(CmosnoiseError, match=None) as info:
            call()
        assert needle in str(info.value), (needle, str(info.value))
        assert isinstance(info.value, ValueError)
    grey = s.expose(np.full((12, 16, 1), 0.5)).frame(0)  # (rows, cols, 1) is a grey scene
    assert np.array_equal(grey, s.expose(np.full((12, 16, 3), 0.5)).frame(0))
    assert Sensor(s.config, seed=2.0).config.seed == 2
