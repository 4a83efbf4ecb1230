"""The command line as a user runs it: outputs, reproducibility, and clear errors."""

import json
import os

import numpy as np
import pytest
import tifffile
import yaml
from conftest import cli as run
from conftest import cli_subprocess


def test_simulate_writes_the_four_outputs(tmp_path):
    out = tmp_path / "run1"
    r = run("simulate", "--scene", "flat:0.5", "--frames", "3", "--seed", "7",
            "--set", "prnu.sigma_pct=2", "--set", "sensor.width=96", "--set", "sensor.height=64", "--out", out)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "preview.png", "raw.tiff", "summary.json"]
    with tifffile.TiffFile(out / "raw.tiff") as tf:
        data = tf.asarray()
        meta = tf.shaped_metadata[0]
        assert tf.pages[0].tags[33422].value == bytes([0, 1, 1, 2])  # RGGB
    assert data.shape == (3, 64, 96) and data.dtype == np.uint16
    assert meta["cfa"] == "RGGB" and meta["black_level_dn"] == 64 and meta["bits"] == 12
    cfg = yaml.safe_load((out / "config.yaml").read_text())
    assert cfg["seed"] == 7 and cfg["prnu"]["sigma_pct"] == 2 and cfg["run"]["frames"] == 3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == 3 and summary["stages"]["prnu"] is True
    assert summary["signal"]["mean_e"] > 0 and summary["temporal_noise"]["rms_e"] > 0
    # the run's total counts its parts after the set-up: the frames, the summary, the wait for the pictures
    t = summary["timings_s"]
    assert min(t["summary_aside"], t["summary"], t["pictures_after_summary"]) >= 0
    if t["frame_s"] is None:  # this run compiled the kernel (the first test of a session to make a frame): no
        assert t["stages"]["kernel_compile"] > 0  # steady frame time, by design
    else:
        parts = t["set_up"] + 3 * t["frame_s"] + t["summary"] + t["pictures_after_summary"]  # 3 frames: steady
        # each figure is rounded to 1 us (at most 0.5 us off): total, set_up, summary, pictures and 3 times frame_s
        assert abs(t["total"] - parts) <= 0.5e-6 * 7 + 1e-12
    import imageio.v3 as iio
    assert iio.imread(out / "preview.png").shape == (64, 96, 3)

    # the written config reproduces raw.tiff bit for bit
    again = tmp_path / "again"
    r = run("simulate", "--config", out / "config.yaml", "--out", again)
    assert r.returncode == 0, r.stderr
    np.testing.assert_array_equal(tifffile.imread(again / "raw.tiff"), data)


def test_the_time_per_frame_is_the_steady_one_and_a_stalled_frame_counts_as_set_up(tmp_path):
    """A frame that waits (on a first run: for a loop compiled beside the frames) does not make the steady time
    per frame: it is the median of the frames after frame 0, and the wait goes to the set-up."""
    import contextlib
    import time

    from cmosnoise import load_config
    from cmosnoise.app import run as run_mod

    calls = []

    @contextlib.contextmanager
    def progress(_total):
        def advance():
            calls.append(1)
            if len(calls) == 3:  # frame 2 of 6 stalls for 0.5 s
                time.sleep(0.5)
        yield advance

    cfg = load_config(extra={"sensor": {"width": 64, "height": 48}, "run": {"frames": 6}})
    t = run_mod.simulate(cfg, tmp_path / "o", progress=progress)["timings_s"]
    # 64 x 48 frames take well under 10 ms each; the mean of the five after frame 0 would be over 0.1 s
    assert len(calls) == 6 and t["frame_s"] < 0.05 and t["set_up"] >= 0.5, t


def test_first_frame_option_reproduces_a_slice_of_a_longer_run(tmp_path):
    common = ["--scene", "ramp", "--seed", "4", "--set", "sensor.width=40", "--set", "sensor.height=30"]
    assert run("simulate", *common, "--frames", "10", "--out", tmp_path / "a").returncode == 0
    assert run("simulate", *common, "--first-frame", "3", "--frames", "3", "--out", tmp_path / "b").returncode == 0
    a = tifffile.imread(tmp_path / "a" / "raw.tiff")
    b = tifffile.imread(tmp_path / "b" / "raw.tiff")
    np.testing.assert_array_equal(a[3:6], b)


def test_simulate_with_no_arguments_uses_the_bundled_photo(tmp_path):
    r = cli_subprocess("simulate", cwd=tmp_path)  # the real entry point, as the README runs it
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "cmosnoise-out" / "raw.tiff").exists()
    assert "480x640" in r.stdout


def test_presets_and_config_commands(tmp_path):
    r = run("presets")
    assert r.returncode == 0 and "paper-fig3-prnu" in r.stdout
    r = run("config", "--preset", "paper-fig3-prnu")
    assert r.returncode == 0
    cfg = yaml.safe_load(r.stdout)
    assert cfg["prnu"]["sigma_pct"] == 10 and cfg["sensor"]["width"] == 14
    (tmp_path / "my.yaml").write_text(r.stdout)
    r = run("simulate", "--config", tmp_path / "my.yaml", "--out", tmp_path / "o")
    assert r.returncode == 0, r.stderr


@pytest.fixture
def bad_inputs(tmp_path):
    (tmp_path / "junk.png").write_text("not an image")
    a = np.ones((8, 8))
    a[2, 2] = np.nan
    np.save(tmp_path / "nan.npy", a)
    (tmp_path / "afile").write_text("x")
    return tmp_path


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--set", "prnu.sigma_pct=1", "--set", "prnu.colour=2"], "unknown key 'prnu.colour'"),
        (["--set", "prnu.sigma_pct=-3"], "prnu.sigma_pct = -3"),
        (["--set", "crosstalk.kernel_pct=[[5,5,5],[5,70,5],[5,5,5]]"], "sums to 110 %"),
        (["--set", "adc.bits=6"], "adc.bits = 6"),
        (["--scene", "{tmp}/missing.png"], "no such file"),
        (["--scene", "{tmp}/junk.png"], "cannot be read"),
        (["--scene", "{tmp}/nan.npy"], "NaN"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_no_output(bad_inputs, args, needle):
    out = bad_inputs / "out"
    args = [a.replace("{tmp}", str(bad_inputs)) for a in args]
    r = (cli_subprocess if "prnu.colour=2" in args else run)("simulate", *args, "--out", out)  # one as a real process
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists()
    assert not [p for p in bad_inputs.iterdir() if p.name.startswith(".cmosnoise-tmp")]


def test_unwritable_output_folder_is_a_clear_error(bad_inputs):
    # a folder below a regular file can never be created, even by root
    r = run("simulate", "--out", bad_inputs / "afile" / "sub")
    assert r.returncode == 2 and "cannot be written" in r.stderr and "Traceback" not in r.stderr
    r = run("simulate", "--out", bad_inputs / "afile")
    assert r.returncode == 2 and "is a file" in r.stderr


def test_read_only_parent_is_a_clear_error(tmp_path):
    """A parent folder that exists but cannot be written. Root writes through file modes, so as root
    (CI) the parent is /sys, where the kernel refuses new folders to everyone."""
    if os.geteuid() == 0:
        r = run("simulate", "--out", "/sys/cmosnoise-out")
        assert r.returncode == 2 and "cannot be written" in r.stderr and "Traceback" not in r.stderr
        assert not os.path.exists("/sys/cmosnoise-out")
        return
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        r = run("simulate", "--out", ro / "out")
        assert r.returncode == 2 and "cannot be written" in r.stderr
    finally:
        ro.chmod(0o700)


def test_error_during_the_run_leaves_an_existing_folder_untouched(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    r = run("simulate", "--scene", tmp_path / "missing.png", "--out", out)
    assert r.returncode == 2
    assert [p.name for p in out.iterdir()] == ["keep.txt"]


def test_a_file_scene_is_recorded_by_absolute_path(tmp_path):
    import imageio.v3 as iio

    (tmp_path / "a").mkdir()
    iio.imwrite(tmp_path / "a" / "s.png", np.full((20, 30, 3), 100, np.uint8))
    r = run("simulate", "--scene", "s.png", "--set", "sensor.width=30", "--set", "sensor.height=20", "--out", tmp_path / "o",
            cwd=tmp_path / "a")
    assert r.returncode == 0, r.stderr
    cfg = yaml.safe_load((tmp_path / "o" / "config.yaml").read_text())
    assert cfg["scene"]["source"] == str((tmp_path / "a" / "s.png").resolve())
    r = run("simulate", "--config", tmp_path / "o" / "config.yaml", "--out", tmp_path / "o2", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "o2" / "raw.tiff"), tifffile.imread(tmp_path / "o" / "raw.tiff"))


# ------------------------------------------------------------------ discoverability
SMALL = ["--set", "sensor.width=64", "--set", "sensor.height=48"]


def _leaf_keys(d, prefix=""):
    for k, v in d.items():
        if isinstance(v, dict) and v:
            yield from _leaf_keys(v, f"{prefix}{k}.")
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                yield from _leaf_keys(item, f"{prefix}{k}.N.")
        else:
            yield f"{prefix}{k}"


def test_config_prints_every_key_and_explain_describes_each(tmp_path):
    text = run("config").stdout
    data = yaml.safe_load(text)
    assert data["scene"]["scale"] is None and "mean_aA" in data["dark_current"]["points"][0]  # nulls are shown
    explain = run("config", "--explain").stdout
    described = {line.split("  (")[0] for line in explain.splitlines() if not line.startswith(" ")}
    missing = set(_leaf_keys(data)) - described
    assert not missing, f"keys without an explanation: {sorted(missing)}"
    lines = explain.splitlines()
    keys = [i for i, line in enumerate(lines) if not line.startswith(" ")]
    undescribed = [lines[i] for i in keys if i + 1 == len(lines) or not lines[i + 1].startswith("    ")]
    assert not undescribed, f"keys without a description: {undescribed}"
    assert "shot_noise.gaussian_above_e  (float | null; default null; >= 100)" in explain
    (tmp_path / "c.yaml").write_text(text)
    assert run("config", "--config", tmp_path / "c.yaml").stdout == text  # prints back as it reads


def test_set_reaches_list_items_and_says_what_is_wrong():
    r = run("config", "--set", "dark_current.points.1.mean_e_per_s=5", "--set", "sensor.channel_responsivity.2=0.7")
    data = yaml.safe_load(r.stdout)
    assert data["dark_current"]["points"][1]["mean_e_per_s"] == 5
    assert data["dark_current"]["points"][0]["mean_e_per_s"] == 8  # the others kept
    assert data["sensor"]["channel_responsivity"] == [1.0, 1.0, 0.7]
    r = run("config", "--set", "dark_current.points.7.mean_e_per_s=5")
    assert r.returncode == 2 and "has 3 item(s)" in r.stderr
    r = run("config", "--set", "dark_current.points.first.mean_e_per_s=5")
    assert r.returncode == 2 and "index it with a number" in r.stderr


def test_version_quiet_verbose_and_any_case_cfa(tmp_path):
    r = run("--version")
    assert r.returncode == 0 and r.stdout.startswith("cmosnoise ") and "scheme" in r.stdout
    r = run("-q", "simulate", *SMALL, "--out", tmp_path / "q")
    assert r.returncode == 0 and r.stdout == "" and (tmp_path / "q" / "raw.tiff").exists()
    r = run("-v", "simulate", *SMALL, "--out", tmp_path / "v")
    assert "files: config.yaml, preview.png, raw.tiff, summary.json" in r.stdout and "time: total" in r.stdout
    r = run("simulate", *SMALL, "--set", "sensor.cfa=gbrg", "--out", tmp_path / "g")
    assert r.returncode == 0 and yaml.safe_load((tmp_path / "g" / "config.yaml").read_text())["sensor"]["cfa"] == "GBRG"
    raw = tifffile.imread(tmp_path / "g" / "raw.tiff")
    tifffile.imwrite(tmp_path / "cam.tiff", raw)  # a camera's raw: no metadata
    r = run("process", tmp_path / "cam.tiff", "--cfa", "gbrg", "--black-level", "64", "--bits", "12", "--out", tmp_path / "p")
    assert r.returncode == 0, r.stderr
    assert "GBRG" in r.stdout


def test_flat_without_a_level_is_an_error(tmp_path):
    r = run("simulate", *SMALL, "--scene", "flat", "--out", tmp_path / "f")
    assert r.returncode == 2 and "flat:LEVEL" in r.stderr and not (tmp_path / "f").exists()


def test_help_does_not_import_the_model_or_scipy():
    """`cmosnoise --help` (and the parsing of any command) loads neither the model nor scipy.special: a fifth
    of a second of a start-up that only prints."""
    import subprocess
    import sys

    code = ("import sys, contextlib, io\n"
            "from cmosnoise.app.cli import run\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n"
            "        run(['--help'])\n"
            "    except SystemExit:\n"
            "        pass\n"
            "print(sorted(m for m in ('scipy.special', 'cmosnoise.model.spec', 'numba') if m in sys.modules))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "[]", r.stdout
