"""`cmosnoise dataset`: each sample from (seed, index) alone, the same bytes however it is made, simulate
reproduces it, --resume after a SIGTERM loses and repeats nothing, bad input is one line."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml
from conftest import ANOTHER_CPU, DASK, X86_64, cli, free_port, stop_process, wait_for_port

from cmosnoise import Sensor
from cmosnoise.analysis import ground_truth as gt
from cmosnoise.app import dataset as ds
from cmosnoise.model import scene as scene_mod

SMALL = ["--crop", "48x64", "--shard-size", "3", "--light", "20:2000"]
CAMERAS = ["--camera", "led", "--camera", "eld:nikon-d850", "--camera", "sony-imx900", "--camera", "sony-a7s2@iso=1600"]


def shard_bytes(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.glob("shard-*"))}


def same_bytes(folder, expected):
    """The shards of ``folder`` are ``expected``'s bytes; where not, say whether their contents differ too and where
    the first differing byte is."""
    got = shard_bytes(folder)
    assert list(got) == list(expected)
    for name, data in got.items():
        if data != expected[name]:
            first = next(i for i, (a, b) in enumerate(zip(data, expected[name])) if a != b)
            arrays, columns = ds.read_shard(folder / name)
            pytest.fail(f"{name}: bytes differ from byte {first} of {len(data)} (lengths {len(data)}, "
                        f"{len(expected[name])}); the arrays {list(arrays)} were read back")


@pytest.mark.slow
def test_the_same_bytes_in_one_process_on_a_local_cluster_and_on_a_scheduler(tmp_path):
    args = ["-q", "dataset", "-n", "7", *SMALL, *CAMERAS, "--set", "defects.enabled=true",
            "--set", "defects.dead_ppm=5000"]
    assert cli(*args, "--out", tmp_path / "one").returncode == 0
    one = shard_bytes(tmp_path / "one")
    assert list(one) == ["shard-00000.h5", "shard-00001.h5", "shard-00002.h5"]
    r = cli(*args, "--workers", "2", "--out", tmp_path / "two")
    assert r.returncode == 0, r.stderr
    same_bytes(tmp_path / "two", one)
    port = free_port()
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    procs = [subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--dashboard-address", "127.0.0.1:0", "--no-show"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)]
    try:
        wait_for_port(port, procs[0])
        procs.append(subprocess.Popen([DASK, "worker", f"tcp://127.0.0.1:{port}", "--host", "127.0.0.1",
                                       "--nthreads", "1", "--nworkers", "1", "--no-dashboard"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env))
        r = cli(*args, "--scheduler", f"tcp://127.0.0.1:{port}", "--out", tmp_path / "sched")
        assert r.returncode == 0, r.stderr
        same_bytes(tmp_path / "sched", one)
    finally:
        for proc in reversed(procs):
            stop_process(proc)


def test_a_sample_is_what_simulate_and_the_api_make_with_its_settings(tmp_path):
    assert cli("-q", "dataset", "-n", "4", *SMALL, *CAMERAS, "--out", tmp_path / "d").returncode == 0
    arrays, columns = next(ds.read(tmp_path / "d"))
    for i in range(3):
        text = str(columns["config"][i])
        (tmp_path / f"s{i}.yaml").write_text(text)
        r = cli("-q", "simulate", "--config", tmp_path / f"s{i}.yaml", "--out", tmp_path / f"sim{i}")
        assert r.returncode == 0, r.stderr
        import tifffile

        raw = tifffile.imread(tmp_path / f"sim{i}" / "raw.tiff").reshape(arrays["raw"][i].shape)
        assert np.array_equal(raw, arrays["raw"][i])
        # and through the Python API, with the truth
        sensor = Sensor(yaml.safe_load(text))
        shot = sensor.expose()
        truth = gt.truth(shot)
        assert np.array_equal(shot.frame(0), arrays["raw"][i])
        assert np.array_equal(truth.expected_raw, arrays["expected_raw"][i])
        assert np.array_equal(truth.mask, arrays["mask"][i])
        assert columns["sample"][i] == i


def test_a_sample_depends_on_its_index_alone():
    recipe = ds.Recipe(samples=100, crop=(32, 32), cameras=("led", "sony-imx900"), seed=5)
    a, ca = ds.make_sample(recipe, 37)
    b, cb = ds.make_sample(ds.Recipe(samples=5000, crop=(32, 32), cameras=("led", "sony-imx900"), seed=5,
                                     shard_size=7), 37)
    assert all(np.array_equal(a[k], b[k]) for k in ds.ARRAYS) and ca == cb
    c, _ = ds.make_sample(ds.Recipe(samples=100, crop=(32, 32), cameras=("led", "sony-imx900"), seed=6), 37)
    assert not np.array_equal(a["raw"], c["raw"])
    # the corner is even: the CFA phase of the source is kept
    assert ca["window_row"] % 2 == 0 and ca["window_col"] % 2 == 0
    img = scene_mod.source_image(ca["source"], (ds.BUILTIN_SIZE, ds.BUILTIN_SIZE))
    assert 0 <= ca["window_row"] <= img.shape[0] - 32




def test_what_a_process_shares_between_samples_changes_no_setting():
    """A camera's saturation at a gain is worked out once per process (Sources.saturations): each sample's
    settings (its light, level, ratio and configuration) are what a fresh process gives them."""
    recipe = ds.Recipe(samples=40, crop=(32, 32), cameras=("led", "sony-imx900", "sony-a7s2", "sony-a7s2@iso=1600"),
                       seed=4)
    shared = ds.Sources()
    for i in range(24):
        a, b = ds.settings(recipe, i, shared), ds.settings(recipe, i, ds.Sources())
        assert a.columns == b.columns and a.config == b.config
    assert 1 < len(shared.saturations) < 24  # named cameras' gains shared, each virtual camera its own

def test_a_sample_merged_into_its_cameras_template_is_the_whole_validation(monkeypatch):
    """A sample's configuration is its camera's (with the overrides) validated once per process, the sample's keys
    merged in (Sources.template, sample_config): over every named camera and virtual family, gains, ranges of
    temperature and exposure, an override beside the sample's keys and one that sets a key of theirs (which must
    win), each sample's configuration and columns are what the whole validation of its merged data gives."""
    from cmosnoise.config import virtual_cameras
    from cmosnoise.config.loading import config_values

    cameras = ("led", "sony-imx900", "sony-a7s2", "sony-a7s2@iso=1600", "zwo-asi294mm", "sony-imx571",
               *virtual_cameras.FAMILIES)
    recipes = [ds.Recipe(samples=40, crop=(32, 48), cameras=cameras, seed=9, temperature_c=(20.0, 60.0),
                         integration_time_s=(0.001, 0.1)),
               ds.Recipe(samples=40, crop=(32, 32), cameras=cameras, seed=2, overrides=("prnu.sigma_pct=1.5",)),
               ds.Recipe(samples=40, crop=(32, 32), cameras=cameras, seed=3, light_e=(20.0, 2000.0),
                         overrides=("sensor.temperature_c=47", "row_noise.enabled=true"))]
    made = {}
    for r, recipe in enumerate(recipes):
        shared = ds.Sources()
        made[r] = [ds.settings(recipe, i, shared) for i in range(30)]
        assert sum(t is not None for t in shared.templates.values()) >= 1
    assert all(st.config.sensor.temperature_c == 47 for st in made[2])  # the override wins over the sample's
    monkeypatch.setattr(ds.Sources, "template", lambda self, *args: None)  # every sample wholly validated
    for r, recipe in enumerate(recipes):
        whole = ds.Sources()
        for i, fast in enumerate(made[r]):
            slow = ds.settings(recipe, i, whole)
            assert fast.columns == slow.columns, (r, i)
            assert fast.config == slow.config and config_values(fast.config) == config_values(slow.config), (r, i)
            assert fast.config.to_yaml() == slow.config.to_yaml(), (r, i)


def test_built_in_scenes_are_drawn_at_a_crop_larger_than_their_size():
    """A crop taller than BUILTIN_SIZE (a 5 MP crop is 1944 x 2592) draws the built-in at the crop's side: the
    sample is made (no "the source is 1024 x 1024" error), its corner is on the scene, and its config alone
    makes the same frame (the scene's size recorded in it)."""
    rows = ds.BUILTIN_SIZE + 2
    recipe = ds.Recipe(samples=4, crop=(rows, 16), cameras=("led",), seed=2, sources=("siemens",))
    assert ds.builtin_shape(recipe.crop) == (rows, ds.BUILTIN_SIZE)
    assert ds.builtin_shape((64, 64)) == (ds.BUILTIN_SIZE, ds.BUILTIN_SIZE)  # smaller crops: the sets made before
    arrays, columns = ds.make_sample(recipe, 1)
    assert arrays["raw"].shape == (rows, 16) and columns["window_row"] == 0
    config = yaml.safe_load(columns["config"])
    assert config["scene"]["source_size"] == [rows, ds.BUILTIN_SIZE]
    assert np.array_equal(Sensor(config).expose().frame(0), arrays["raw"])

_DIGEST_SAMPLES = ("import hashlib\n"
                   "import numpy as np\n"
                   "from cmosnoise.app import dataset as ds\n"
                   "r = ds.Recipe(samples=6, crop=(128, 128), cameras=('led', 'eld', 'sony-imx900'), seed=3,\n"
                   "              overrides=('defects.enabled=true', 'defects.dead_ppm=2000', 'defects.stuck_ppm=2000'))\n"
                   "h = hashlib.sha256()\n"
                   "for i in range(r.samples):\n"
                   "    a, _ = ds.make_sample(r, i)\n"
                   "    for k in ds.ARRAYS:\n"
                   "        h.update(np.ascontiguousarray(a[k]).tobytes())\n"
                   "print(h.hexdigest())\n")


@pytest.mark.skipif(not X86_64, reason="x86-64 dispatch targets and BLAS kernels")
@pytest.mark.slow
def test_samples_and_their_truths_do_not_depend_on_the_cpu():
    """The noisy raws and every truth (expected raw, perfect image, mask) of samples over three camera families,
    made in a child process as another CPU would make them (conftest.ANOTHER_CPU: NumPy's baseline loops, OpenBLAS's
    Prescott kernels, libm without its FMA variants, each of which gives other last bits), are the same bytes: the
    expected raw's compiled pass calls exp, sin and erfc through libm, and the truths' NumPy parts take exp and
    log from NumPy."""
    made = [subprocess.run([sys.executable, "-c", _DIGEST_SAMPLES], capture_output=True, text=True, check=True,
                           env={**os.environ, **extra}).stdout for extra in ({}, ANOTHER_CPU)]
    assert made[0] == made[1] and len(made[0].strip()) == 64, made


@pytest.mark.parametrize("fmt", ["npz", "fits"])
def test_npz_and_fits_hold_what_hdf5_holds(tmp_path, fmt):
    args = ["-q", "dataset", "-n", "4", *SMALL, "--camera", "sony-imx900"]
    assert cli(*args, "--out", tmp_path / "h").returncode == 0
    assert cli(*args, "--format", fmt, "--out", tmp_path / fmt).returncode == 0
    for (a, ca), (b, cb) in zip(ds.read(tmp_path / "h"), ds.read(tmp_path / fmt)):
        for k in ds.ARRAYS:
            assert np.array_equal(a[k], b[k]), k
        for k in ds.COLUMNS:
            assert [str(v).rstrip() for v in ca[k]] == [str(v).rstrip() for v in cb[k]], k  # FITS drops trailing blanks
    again = tmp_path / f"{fmt}2"
    assert cli(*args, "--format", fmt, "--out", again).returncode == 0
    assert shard_bytes(again) == shard_bytes(tmp_path / fmt)


@pytest.mark.slow
def test_resume_after_sigterm_loses_nothing_and_repeats_nothing(tmp_path):
    args = ["dataset", "-n", "24", "--crop", "64", "--shard-size", "2", "--camera", "sony-imx900"]
    assert cli("-q", *args, "--out", tmp_path / "full").returncode == 0
    full = shard_bytes(tmp_path / "full")
    part = tmp_path / "part"
    proc = subprocess.Popen([sys.executable, "-m", "cmosnoise", "-q", *args, "--out", str(part)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while len(list(part.glob("shard-*"))) < 2:  # let it make a few shards, then stop it
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGTERM)
        proc.wait(timeout=60)
    finally:
        stop_process(proc)
    made = {p.name: p.stat().st_mtime_ns for p in part.glob("shard-*")}
    assert 2 <= len(made) < 12, "stopped too late to test a resume"
    assert all(full[name] == (part / name).read_bytes() for name in made)  # what was written is whole
    r = cli(*args, "--out", part)
    assert r.returncode == 2 and "--resume" in r.stderr
    r = cli(*args, "--resume", "--out", part)
    assert r.returncode == 0, r.stderr
    assert f"{len(made)} of 12 shard(s) already made" in r.stdout
    assert shard_bytes(part) == full
    assert {n: (part / n).stat().st_mtime_ns for n in made} == made  # nothing made twice
    assert not list(part.glob(".*tmp*"))


@pytest.mark.parametrize("args, needle", [
    (["--crop", "33"], "--crop"),
    (["--format", "zarr"], "--format 'zarr'"),
    (["--camera", "nikon"], "--camera 'nikon'"),
    (["--camera", "sony-a7s2@iso=123"], "not in the gain table"),
    (["--light", "5:1"], "--light"),
    (["--set", "defects.dead_ppm=-1"], "defects.dead_ppm"),
    (["--crop", "4096"], "the built-in scenes are drawn at most 12 MP"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, args, needle):
    r = cli("dataset", "-n", "3", *args, "--out", tmp_path / "bad")
    assert r.returncode == 2, r.stderr
    assert needle in r.stderr and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "bad").exists()
