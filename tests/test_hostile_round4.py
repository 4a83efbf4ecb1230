"""Reliability, round 4 (#59): hostile files refused from their structure, every reader bounded before it decodes,
messages that say what was kept, signals that end a command in seconds, the API refusing what the CLI refuses.

Each hostile file is made here, small on disk; the peak memory of a refusal is measured with tracemalloc (NumPy's
and h5py's arrays are traced), in the process that refuses it, but for the walk of a 100 000-page chain, which
tracemalloc slows a hundredfold: its peak resident memory is measured in a child of its own.
"""

import json
import os
import signal
import struct
import subprocess
import sys
import textwrap
import time
import tracemalloc

import h5py
import numpy as np
import pytest
from conftest import cli, stop_process

from cmosnoise import Sensor, inputs
from cmosnoise.errors import CmosnoiseError

#: a refusal from a file's structure takes at most this long (the issue's bound), and this much memory. The time
#: is this process's CPU time (``time.process_time``): the suite's other worker on a 2-core machine stretched the
#: wall time of a 1.2 s walk past 2 s (CI's clean clone: 2.38 s), and a timing is not a test's verdict on a
#: shared machine; the CPU time is the command's own work
FAST_S = 2.0
SMALL_MEMORY = 100e6


# ------------------------------------------------------------------ hostile TIFFs, made by hand
def _ifd(width: int, height: int, following: int, strip_at: int = 8) -> bytes:
    """A classic little-endian TIFF directory of one 8-bit grey strip, pointing to the directory at ``following``."""
    entries = [(256, 4, 1, width), (257, 4, 1, height), (258, 3, 1, 8), (259, 3, 1, 1), (262, 3, 1, 1),
               (273, 4, 1, strip_at), (277, 3, 1, 1), (278, 4, 1, height), (279, 4, 1, width * height)]
    out = struct.pack("<H", len(entries))
    for tag, kind, count, value in entries:
        out += struct.pack("<HHI", tag, kind, count) + (struct.pack("<HH", value, 0) if kind == 3 else
                                                          struct.pack("<I", value))
    return out + struct.pack("<I", following)


IFD_BYTES = len(_ifd(1, 1, 0))


def looping_tiff(path) -> int:
    """Two one-pixel pages whose chain points back to the first: tifffile follows it for ever."""
    first, second = 16, 16 + IFD_BYTES
    data = b"II*\0" + struct.pack("<I", first) + b"\0" * 8 + _ifd(1, 1, second) + _ifd(1, 1, first)
    path.write_bytes(data)
    return len(data)


def many_page_tiff(path, pages: int = 300_000) -> int:
    """``pages`` one-pixel pages in a chain (the probe's 30 MB file)."""
    data = bytearray(b"II*\0" + struct.pack("<I", 16) + b"\0" * 8)
    for k in range(pages):
        data += _ifd(1, 1, 16 + (k + 1) * IFD_BYTES if k < pages - 1 else 0)
    path.write_bytes(bytes(data))
    return len(data)


def huge_tiff(path, side: int = 20000) -> None:
    """One page whose header says ``side`` x ``side`` (0.8 MB zlib in the probe; a few bytes here: the header
    is all a refusal reads)."""
    path.write_bytes(b"II*\0" + struct.pack("<I", 16) + b"\0" * 8 + _ifd(side, side, 0))


def _popen(request, args, **kw) -> subprocess.Popen:
    """A process this test starts, stopped by its id when the test ends, whatever happened."""
    proc = subprocess.Popen(args, **kw)
    request.addfinalizer(lambda: stop_process(proc))
    return proc


def _one_line(stderr: str) -> bool:
    """One line said, the compile messages of a fresh compile cache aside."""
    return len([x for x in stderr.strip().splitlines() if " compil" not in x]) == 1


def _timed_memory(fn):
    """``fn()``'s result, its time, and its peak traced memory (a second call under tracemalloc, which slows
    Python's allocations too much to be timed)."""
    t0 = time.process_time()
    result = fn()
    took = time.process_time() - t0
    tracemalloc.start()
    try:
        fn()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return result, took, peak


@pytest.mark.parametrize("make, needle", [(looping_tiff, "loops back"),  # 300 000 pages take 25 s: the full suite's
                                          pytest.param(many_page_tiff, "more than 100000 pages", marks=pytest.mark.slow)])
def test_a_looping_or_many_page_tiff_is_refused_from_its_structure_by_simulate_and_process(tmp_path, make, needle):
    bad = tmp_path / "bad.tif"
    size = make(bad)
    assert size < 40e6
    for args in (["simulate", "--scene", bad, "--set", "sensor.width=64", "--set", "sensor.height=48"],
                 ["process", bad]):
        t0 = time.process_time()
        r = cli(*args, "--out", tmp_path / "out")
        took = time.process_time() - t0
        assert r.returncode == 2 and needle in r.stderr and _one_line(r.stderr), r.stderr
        assert took < FAST_S, (args[0], took)
        assert not (tmp_path / "out").exists()
    renamed = tmp_path / "bad.png"  # by its bytes, whatever its name
    bad.rename(renamed)

    def refused():
        with pytest.raises(CmosnoiseError, match=needle):
            inputs.check_image_pixels(renamed, "scene", 10**9)

    t0 = time.process_time()
    refused()
    assert time.process_time() - t0 < FAST_S
    # the memory bound is the gate's that both commands pass, measured once, in a child of its own by the growth
    # of its peak resident memory over the walk: tracemalloc slows the walk of a chain of 100 000 pages a
    # hundredfold (48 s against 0.5 on CI's kind of machine), and a resident set counts what it does not see
    # (the walker's buffers, a memory map) as well
    probe = textwrap.dedent(f"""\
        import resource
        from cmosnoise import inputs
        from cmosnoise.errors import CmosnoiseError
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        try:
            inputs.check_image_pixels({str(renamed)!r}, "scene", 10**9)
        except CmosnoiseError as exc:
            print("refused:", exc)
        print(1024 * (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before))
        """)
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and needle in r.stdout, r.stdout + r.stderr
    assert int(r.stdout.split()[-1]) < SMALL_MEMORY, r.stdout


def test_the_walker_reads_every_page_tifffile_reads(tmp_path):
    """The hand-walked chain against tifffile's own pages: classic and BigTIFF, both byte orders, tiles, RGB."""
    import tifffile

    cases = {"stack.tif": (np.zeros((5, 30, 40), np.uint16), {}),
             "big.tif": (np.zeros((3, 30, 40), np.uint16), {"bigtiff": True, "metadata": None}),
             "rgb.tif": (np.zeros((30, 40, 3), np.uint8), {"photometric": "rgb"}),
             "tiles.tif": (np.zeros((2, 64, 80), np.uint16), {"tile": (16, 16), "byteorder": ">"})}
    for name, (a, kw) in cases.items():
        tifffile.imwrite(tmp_path / name, a, **kw)
        with tifffile.TiffFile(tmp_path / name) as tf:
            pages = [(p.imagelength, p.imagewidth) for p in tf.pages]
        rows, cols, planes = inputs.tiff_planes(tmp_path / name, "x")
        assert planes == len(pages) and (rows, cols) == max(pages), name
    # a DNG written by cmosnoise: its raw is in a sub-IFD, which the bound counts
    from cmosnoise.io.dng import write_dng

    sensor = Sensor({"sensor": {"width": 64, "height": 48}})
    write_dng(tmp_path / "f.dng", sensor.expose().frame(0), "RGGB", 64.0, 4095)
    rows, cols, planes = inputs.tiff_planes(tmp_path / "f.dng", "x")
    assert rows * cols >= 64 * 48


def test_a_header_past_the_end_or_a_truncated_page_is_one_line(tmp_path):
    for data, needle in [(b"II*\0" + struct.pack("<I", 10_000), "past the file's end"),
                         (b"II*\0" + struct.pack("<I", 8) + struct.pack("<H", 500) + b"\0" * 20, "run past"),
                         (b"XX*\0\0\0\0\0", "not a TIFF")]:
        p = tmp_path / "t.tif"
        p.write_bytes(data)
        with pytest.raises(CmosnoiseError, match=needle):
            inputs.tiff_planes(p, "scene")


# ------------------------------------------------------------------ a data set's files
@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ds") / "d"
    r = cli("-q", "dataset", "-n", "2", "--crop", "16", "--out", folder)
    assert r.returncode == 0, r.stderr
    return folder


def _copy(dataset, tmp_path):
    import shutil

    shutil.copytree(dataset, tmp_path / "d")
    return tmp_path / "d"


def _evaluate(folder, tmp_path, *extra):
    r, took, peak = _timed_memory(lambda: cli("evaluate", "--data", folder, "--method", "none", *extra,
                                              "--out", tmp_path / "e"))
    assert r.returncode == 2 and _one_line(r.stderr), r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "e").exists()
    return r.stderr, took, peak


def _manifest(folder, change):
    m = json.loads((folder / "dataset.json").read_text())
    (folder / "dataset.json").write_text(json.dumps(change(m)))


def _rewrite_h5(folder, change):
    p = folder / "shard-00000.h5"
    with h5py.File(p, "r") as f:
        arrays = {k: f[k][()] for k in f if k != "settings"}
        settings = {k: f["settings"][k][()] for k in f["settings"]}
    change(arrays, settings)
    p.unlink()
    with h5py.File(p, "w") as f:
        for k, v in arrays.items():
            f[k] = v
        for k, v in settings.items():
            f[f"settings/{k}"] = v


@pytest.mark.parametrize("case, needle", [
    ("not json", "not JSON"),
    ("a list", "JSON list"),
    ("no recipe", "no recipe"),
    ("no shards", "no list of shards"),
    ("samples a string", "recipe.samples"),
    ("a shard outside the folder", "not a shard file"),
    ("a sparse 3 GB manifest", "larger than"),
    ("a FIFO shard", "a pipe (FIFO)"),
    ("a gzip bomb", "decodes to"),
    ("no mask", "no 'mask' array"),
    ("shapes that differ", "share one shape"),
    ("an unknown CFA", "cfa 'XYZW'"),
    ("a NaN black level", "must be finite"),
    ("an object array", "expected numbers"),
    ("a truncated shard", "cannot be read"),
])
def test_evaluate_refuses_every_hostile_data_set_in_one_line(dataset, tmp_path, case, needle):
    d = _copy(dataset, tmp_path)
    shard = d / "shard-00000.h5"
    if case == "not json":
        (d / "dataset.json").write_text("{not json")
    elif case == "a list":
        (d / "dataset.json").write_text("[1, 2]")
    elif case == "no recipe":
        _manifest(d, lambda m: {k: v for k, v in m.items() if k != "recipe"})
    elif case == "no shards":
        _manifest(d, lambda m: {k: v for k, v in m.items() if k != "shards"})
    elif case == "samples a string":
        _manifest(d, lambda m: {**m, "recipe": {**m["recipe"], "samples": "two"}})
    elif case == "a shard outside the folder":
        _manifest(d, lambda m: {**m, "shards": ["../../etc/passwd"]})
    elif case == "a sparse 3 GB manifest":
        with open(d / "dataset.json", "r+b") as fh:
            fh.truncate(3_000_000_000)
    elif case == "a FIFO shard":
        shard.unlink()
        os.mkfifo(shard)
    elif case == "a gzip bomb":  # 3.2 GB when decoded, unwritten chunks of a compressed dataset: a few kB on disk
        with h5py.File(shard, "r+") as f:
            del f["raw"]
            f.create_dataset("raw", shape=(2, 40_000, 40_000), dtype=np.uint16, chunks=(1, 1000, 1000),
                             compression="gzip")
        assert shard.stat().st_size < 1e6
    elif case == "no mask":
        _rewrite_h5(d, lambda a, s: a.pop("mask"))
    elif case == "shapes that differ":
        _rewrite_h5(d, lambda a, s: a.update(mask=a["mask"][:, :8]))
    elif case == "an unknown CFA":
        _rewrite_h5(d, lambda a, s: s.update(cfa=np.array([b"XYZW"] * 2)))
    elif case == "a NaN black level":
        _rewrite_h5(d, lambda a, s: s.update(black_level_dn=np.array([np.nan, 64.0])))
    elif case == "an object array":
        _rewrite_h5(d, lambda a, s: a.update(raw=np.array([[["x"] * 16] * 16] * 2, dtype="S1")))
    elif case == "a truncated shard":
        shard.write_bytes(shard.read_bytes()[:1000])
    err, took, peak = _evaluate(d, tmp_path)
    assert needle in err, err
    assert took < 5 and peak < SMALL_MEMORY, (took, peak)


def test_npz_and_fits_shards_are_bounded_before_they_decode(dataset, tmp_path):
    from cmosnoise.app import dataset as ds

    arrays, columns = ds.read_shard(dataset / "shard-00000.h5")
    # an npz whose zip directory says 3.4 GB: refused from the directory, nothing inflated
    p = tmp_path / "shard-00000.npz"
    np.savez(p, **arrays, **{f"settings.{k}": v for k, v in columns.items()})
    data = bytearray(p.read_bytes())
    at = data.rfind(b"PK\x01\x02")  # the last member's central directory entry: its uncompressed size
    struct.pack_into("<I", data, at + 24, 3_400_000_000)
    p.write_bytes(bytes(data))
    with pytest.raises(CmosnoiseError, match="decodes to"):
        ds.read_shard(p)
    p.write_bytes(bytes(data[:200]))  # a truncated npz
    with pytest.raises(CmosnoiseError, match="not a readable .npz"):
        ds.read_shard(p)
    # a FITS file whose header promises more data than it holds
    from astropy.io import fits

    f = tmp_path / "shard-00000.fits"
    fits.PrimaryHDU(np.zeros((2, 64, 64), np.uint16)).writeto(f)
    f.write_bytes(f.read_bytes()[:2880 + 1000])
    with pytest.raises(CmosnoiseError, match="does not hold"):
        ds.read_shard(f)
    f.write_bytes(b"SIMPLE  =                    T" + b" " * 50)
    with pytest.raises(CmosnoiseError, match="past the file's end"):
        ds.read_shard(f)


def test_outputs_and_a_summary_are_read_only_where_their_headers_allow(dataset, tmp_path):
    outs = tmp_path / "outs"
    outs.mkdir()
    huge_tiff(outs / "sample_000000.tif", 40000)
    err, took, peak = _evaluate(dataset, tmp_path, "--outputs", outs)
    assert "megapixels" in err and peak < SMALL_MEMORY, err
    huge_tiff(outs / "sample_000000.tif", 20)  # a frame of another size: refused from its header too
    err, took, peak = _evaluate(dataset, tmp_path, "--outputs", outs)
    assert "sample 0 is one 16 x 16 frame" in err, err
    # compare on summaries: sparse, nested past the parser, keyless, wrongly typed
    run = tmp_path / "run"
    assert cli("-q", "simulate", "--set", "sensor.width=64", "--set", "sensor.height=48", "--out", run).returncode == 0
    good = (run / "summary.json").read_text()
    for body, needle in [(None, "larger than"), ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
                         ("{}", "it has no signal"), (json.dumps({**json.loads(good), "key_figures": [1]}), "key_figures"),
                         (json.dumps({**json.loads(good), "frames": "2"}), "frames")]:
        if body is None:
            with open(run / "summary.json", "wb") as fh:
                fh.truncate(3_000_000_000)
        else:
            (run / "summary.json").write_text(body)
        r = cli("compare", run, run, "--out", tmp_path / "c")
        assert r.returncode == 2 and needle in r.stderr and _one_line(r.stderr), r.stderr


def test_fit_refuses_frames_that_would_not_fit_in_memory_from_their_header(tmp_path, monkeypatch):
    """Two 20000 x 20000 frames (the probe's zlib TIFFs; headers alone here): the fit's accumulators would take
    29 GB; refused from the header on a machine with 4 GB available, before a frame is decoded."""
    for name in ("a.tif", "b.tif"):
        huge_tiff(tmp_path / name)
    (tmp_path / "manifest.yaml").write_text(textwrap.dedent("""\
        cfa: none
        black_level_dn: 0
        stacks:
          - {kind: dark, exposure_s: 0.01, files: [a.tif]}
          - {kind: flat, exposure_s: 0.01, files: [b.tif]}
        """))
    monkeypatch.setattr(inputs, "available_bytes", lambda: 4_000_000_000)
    r, took, peak = _timed_memory(lambda: cli("fit", "--frames-from", tmp_path / "manifest.yaml", "--out", tmp_path / "f"))
    assert r.returncode == 2 and "memory" in r.stderr and _one_line(r.stderr), r.stderr
    assert took < FAST_S and peak < SMALL_MEMORY


# ------------------------------------------------------------------ configuration
@pytest.mark.parametrize("args, needle", [
    (["--set", "sensor.width=0b101"], "binary number"),
    (["--set", "seed=" + "9" * 5000], "5000 digits"),
    (["--preset", "../../some/file.yaml"], "unknown preset"),
])
def test_configuration_values_are_never_read_silently_otherwise(args, needle):
    r = cli("config", *args)
    assert r.returncode == 2 and needle in r.stderr and _one_line(r.stderr), r.stderr
    assert len(r.stderr) < 400


# ------------------------------------------------------------------ the explorer's bounds
def test_the_explorer_bounds_its_dark_frames():
    from cmosnoise import load_config
    from cmosnoise.app.workbench import BadRequest, validate

    base = load_config(extra={"sensor": {"width": 64, "height": 48}}).model_dump(mode="json")
    with pytest.raises(BadRequest, match="processing.dark_frames = 100000"):
        validate({**base, "processing": {**base["processing"], "dark_frames": 100000}})
    validate({**base, "processing": {**base["processing"], "dark_frames": 16}})


# ------------------------------------------------------------------ messages and signals
def _until_rows(path, rows, proc, limit=180):
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit:
        assert proc.poll() is None, proc.stderr.read()
        try:
            if len(path.read_text().splitlines()) - 1 >= rows:
                return
        except OSError:
            pass
        time.sleep(0.05)
    raise AssertionError("no rows")


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_stopped_sweep_says_which_rows_it_kept_and_dask_stays_quiet(tmp_path, sig, request):
    out = tmp_path / "sw"
    args = [sys.executable, "-m", "cmosnoise", "sweep", "--set", "sensor.width=64", "--set", "sensor.height=48",
            "--vary", "sensor.temperature_c=25,35,45,55,65,75", "--instances", "4", "--workers", "1", "--out", out]
    proc = _popen(request, args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _until_rows(out / "results.csv", 3, proc)
    proc.send_signal(sig)
    t0 = time.monotonic()
    err = proc.communicate(timeout=30)[1]
    assert time.monotonic() - t0 < 5
    kept = len((out / "results.csv").read_text().splitlines()) - 1
    assert proc.returncode == 128 + sig, err
    assert f"{kept} of 24 rows kept in" in err and "--resume" in err and "nothing was written" not in err, err
    assert "distributed" not in err and "CancelledError" not in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.slow
def test_a_stopped_dataset_resume_says_which_shards_it_kept(tmp_path, request):
    out = tmp_path / "ds"
    base = [sys.executable, "-m", "cmosnoise", "-q", "dataset", "-n", "400", "--crop", "64", "--shard-size", "4",
            "--out", out]
    proc = _popen(request, base, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    # Each run has its own deadline, long enough for a cold compile on two busy cores (CI's clean clone took
    # over 120 s once, and the resume was then stopped inside its compile): the signal goes when shards exist.
    t0 = time.monotonic()
    while len(list(out.glob("shard-*.h5"))) < 2 and time.monotonic() - t0 < 400:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    err = proc.communicate(timeout=30)[1]
    assert proc.returncode == 130 and "of 100 shards" in err and "--resume completes it" in err, err
    proc = _popen(request, [*base, "--resume"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    before = len(list(out.glob("shard-*.h5")))
    t1 = time.monotonic()
    while len(list(out.glob("shard-*.h5"))) < before + 2 and time.monotonic() - t1 < 400:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    err = proc.communicate(timeout=30)[1]
    kept = len(list(out.glob("shard-*.h5")))
    assert proc.returncode == 130 and f"{kept} of 100 shards" in err and "nothing was written" not in err, err


def test_a_signal_a_library_swallowed_stops_the_data_set_at_the_next_shard_and_says_what_it_kept(
        tmp_path, monkeypatch):
    """CI's clean clone once stopped a data set with its SIGINT swallowed (inside a compile's callback): the
    job made every shard in the watchdog's grace and then said "nothing was written". The swallowed signal now
    stops the job after the shard it was in, and the message counts the shards kept."""
    from cmosnoise import errors
    from cmosnoise.app import dataset as ds

    real = ds.shard_bytes

    def swallowing(recipe_json, shard, *a, **k):
        data = real(recipe_json, shard, *a, **k)
        if shard == 1:
            errors._received.append(signal.SIGINT)  # what signal_received records before a library eats its raise
        return data

    monkeypatch.setattr(ds, "shard_bytes", swallowing)
    errors.clear_terminated()
    recipe = ds.Recipe(samples=12, crop=(32, 32), cameras=("led",), seed=2, shard_size=2)
    try:
        with pytest.raises(errors.Terminated) as caught:
            ds.build(recipe, tmp_path / "ds")
    finally:
        errors.clear_terminated()
    assert sorted(f.name for f in (tmp_path / "ds").glob("shard-*")) == [recipe.shard_name(0), recipe.shard_name(1)]
    assert caught.value.kept == f"2 of 6 shards (4 of 12 samples) kept in {tmp_path / 'ds'}; --resume completes it"


def test_a_full_disk_after_one_folder_was_committed_says_so(tmp_path, monkeypatch):
    """characterize --emva-export: --out is committed, then the export's disk fills: the message names what was
    written instead of "nothing was written"."""
    from cmosnoise.analysis import emva_files

    def full(*_a, **_k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(emva_files, "export", full)
    r = cli("characterize", "--set", "sensor.width=32", "--set", "sensor.height=24", "--steps", "8",
            "--stack-frames", "3", "--emva-export", tmp_path / "emva", "--out", tmp_path / "out")
    assert r.returncode == 1 and "No space left" in r.stderr, r.stderr
    assert "nothing was written" not in r.stderr and str(tmp_path / "out") in r.stderr, r.stderr
    assert (tmp_path / "out" / "characterization.json").exists() and not (tmp_path / "emva").exists()


def _stuck_simulate(request, around: str, setup: str = "", **popen):
    """A ``simulate`` whose job is stuck where every exception is swallowed, the first signal's too, wherever it
    lands (as inside a compiler's callback), inside the context manager ``around`` (after ``setup``); started,
    and its "ready" read."""
    code = textwrap.dedent(f"""
        import sys, time
        from cmosnoise.app import run as jobs
        {setup}

        def stuck(*a, **k):
            with {around} as tmp:
                if tmp is not None:
                    (tmp / 'half').write_text('x')
                said = False
                while True:
                    try:
                        if not said:
                            said = True
                            print('ready', flush=True)
                        time.sleep(0.05)
                    except BaseException:
                        pass

        jobs.simulate = stuck
        from cmosnoise.app.cli import run
        sys.exit(run(['simulate', '--set', 'sensor.width=64', '--set', 'sensor.height=48']))
        """)
    proc = _popen(request, [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                  **popen)
    assert proc.stdout.readline().strip() == "ready", proc.stderr.read()
    return proc


@pytest.mark.slow
def test_a_command_that_swallows_its_signal_is_ended_within_seconds_with_its_folder_absent(tmp_path, request):
    """The watchdog: a job stuck where the signal's exception is swallowed (as inside a compiler's callback) is
    ended GRACE_S after the signal, its temporary output removed, with one line and status 128 + the signal."""
    proc = _stuck_simulate(request, f"OutputFolder({str(tmp_path / 'out')!r})",
                           "from cmosnoise.io.output import OutputFolder")
    proc.send_signal(signal.SIGTERM)
    t0 = time.monotonic()
    err = proc.communicate(timeout=30)[1]
    assert time.monotonic() - t0 < 6, err
    assert proc.returncode == 143 and "stopped after" in err and "nothing was written" in err, err
    assert os.listdir(tmp_path) == [], os.listdir(tmp_path)  # neither the folder nor its temporary


@pytest.mark.slow
def test_a_job_ended_by_the_watchdog_still_says_what_it_kept(tmp_path, request):
    """A data set stopped inside a compile (its signal swallowed): the watchdog's line names the shards kept, not
    "nothing was written" (CI met this: a resume stopped while numba compiled said it had written nothing)."""
    proc = _stuck_simulate(request, 'keeping(lambda: "3 of 9 shards kept in ds; --resume completes it")',
                           "from cmosnoise.errors import keeping", cwd=tmp_path)
    proc.send_signal(signal.SIGINT)
    err = proc.communicate(timeout=30)[1]
    assert proc.returncode == 130 and "stopped after" in err, err
    assert "3 of 9 shards kept in ds; --resume completes it" in err and "nothing was written" not in err, err


# ------------------------------------------------------------------ the API refuses what the CLI refuses
def test_the_api_validates_its_arguments_in_one_line():
    from cmosnoise.isp.process import Processor

    sensor = Sensor({"sensor": {"width": 64, "height": 48}})
    shot = sensor.expose()
    p = Processor(sensor.config.processing, sensor.raw_info())
    for call, needle in [
        (lambda: sensor.expose(np.ones((48, 64, 3), complex)), "real numbers"),
        (lambda: sensor.expose(np.ones((48, 64, 3), object)), "real numbers"),
        (lambda: shot.frames(-3), "n = -3"),
        (lambda: shot.frames(2, first=-1), "frame = -1"),
        (lambda: shot.frame(1.5), "whole number"),
        (lambda: p.render(np.full((48, 64), np.nan, np.float32)), "NaN or infinite"),
        (lambda: p.render(np.full((48, 64), np.inf)), "NaN or infinite"),
        (lambda: p.render(np.zeros((2, 48, 64))), "one frame"),
        (lambda: p.render(np.zeros((48, 64), complex)), "integer or real codes"),
        (lambda: p.render("raw"), "integer or real codes"),
        (lambda: p.render(np.full((48, 64), 1e300)), "within"),  # finite, but float32 overflows: it crashed too
    ]:
        with pytest.raises(CmosnoiseError, match=needle):
            call()


def test_a_huge_data_set_with_a_crop_no_source_holds_is_refused_before_any_work(tmp_path):
    t0 = time.monotonic()
    r = cli("dataset", "--samples", "1000000000", "--crop", "4096", "--out", tmp_path / "d")
    assert r.returncode == 2 and "--crop 4096x4096" in r.stderr and time.monotonic() - t0 < 10, r.stderr
    assert not (tmp_path / "d").exists()


def test_a_signal_while_the_interpreter_exits_says_the_command_had_finished(tmp_path, request):
    """The command is over (its folder committed); a SIGTERM while the interpreter shuts down (here an atexit
    hook that takes a while, as Dask's threads can) says so in one line and keeps the command's status."""
    code = textwrap.dedent("""
        import atexit, sys, time
        atexit.register(lambda: (print('exiting', flush=True), time.sleep(20)))
        sys.argv = ['cmosnoise', '-q', 'config']
        from cmosnoise.app.entry import main
        main()
        """)
    proc = _popen(request, [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    while line and line.strip() != "exiting":
        line = proc.stdout.readline()
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=20)[1]
    assert proc.returncode == 0 and "SIGTERM while exiting; the command had already finished (status 0)" in err, err


# ------------------------------------------------------------------ what a new user meets (#63)
def test_a_camera_raw_given_as_the_scene_is_read_as_a_mosaic_or_refused_in_one_line(tmp_path):
    """#63: a DNG was read as a linear grey picture (its mosaic and black level as light). Now a raw photograph is
    read as a mosaic (#60, tests/test_raw_scene.py), by its suffix or by its tags whatever its name; one that
    LibRaw cannot read, or one of the wrong size, is refused in one line."""
    from cmosnoise.io.dng import write_dng

    sensor = Sensor({"sensor": {"width": 64, "height": 48}})
    write_dng(tmp_path / "frame.dng", sensor.expose().frame(0), "RGGB", 64.0, 4095)
    (tmp_path / "frame.tif").write_bytes((tmp_path / "frame.dng").read_bytes())
    (tmp_path / "photo.nef").write_bytes(b"not really")
    for scene in ("frame.dng", "frame.tif"):
        r = cli("simulate", "--scene", tmp_path / scene, "--set", "sensor.width=64", "--set", "sensor.height=48",
                "--out", tmp_path / scene.replace(".", "_"))
        assert r.returncode == 0, (scene, r.stderr)
    for scene, size, needle in [("photo.nef", 48, "not a raw photograph LibRaw reads"),
                                ("frame.dng", 40, "a raw scene is used at its own resolution")]:
        r = cli("simulate", "--scene", tmp_path / scene, "--set", "sensor.width=64", "--set", f"sensor.height={size}",
                "--out", tmp_path / "out")
        assert r.returncode == 2 and needle in r.stderr and _one_line(r.stderr), (scene, r.stderr)
        assert not (tmp_path / "out").exists()


def test_the_first_runs_hint_names_how_to_run_again():
    from cmosnoise.app.cli import _speed

    said = _speed({"frame_s": None, "set_up": 40.0, "stages": {"kernel_compile": 31.0}})
    assert "run again (with --overwrite, or another --out)" in said


def test_help_shows_every_option_name_whole_at_80_columns():
    import os

    env = {**os.environ, "COLUMNS": "80"}
    r = subprocess.run([sys.executable, "-m", "cmosnoise", "simulate", "--help"], capture_output=True, text=True,
                       env=env, timeout=60)
    assert r.returncode == 0 and "--white-threshold" in r.stdout and "--threshold-e-..." not in r.stdout
    assert max(len(x) for x in r.stdout.splitlines()) <= 80


def test_the_video_runs_at_the_sensors_rate_stretched_for_a_dark_scene_and_the_flickering_pixels_are_named(tmp_path):
    """#63: processed.mp4 at the sensor's frame rate (not 10 frames/s), a dark scene's video stretched for display
    (the gain in summary.json), and every random telegraph pixel's position in rts_pixels.csv: the populations
    the sensor drew."""
    import imageio.v3 as iio
    import pandas as pd

    sets = ["--set", "sensor.width=96", "--set", "sensor.height=64", "--set", "source_follower.rts.enabled=true",
            "--set", "source_follower.rts.ppm=3000", "--set", "dark_current.rts.enabled=true",
            "--set", "dark_current.rts.ppm=3000", "--set", "exposure.integration_time_s=0.04"]
    r = cli("-q", "simulate", "--scene", "flat:0.02", *sets, "--frames", "4", "--process", "--out", tmp_path / "v")
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "v" / "summary.json").read_text())
    video = summary["processing"]["video"]
    assert video["fps"] == 25.0 and iio.immeta(tmp_path / "v" / "processed.mp4")["fps"] == 25.0
    assert video["display_gain"] > 1.5
    rts = pd.read_csv(tmp_path / "v" / "rts_pixels.csv")
    from cmosnoise import load_config

    sensor = Sensor(load_config(tmp_path / "v" / "config.yaml"))
    fp = sensor.fixed_pattern
    for kind, pop in (("trap", fp.traps), ("blinking", fp.blinkers)):
        got = rts[rts["kind"] == kind]
        assert len(got) == pop.index.size > 0
        assert np.array_equal(got["row"] * 96 + got["col"], pop.index.astype(np.int64))
        assert np.array_equal(got["size"], pop.size)
    largest = summary["random_telegraph"]["source_follower"]["largest"][0]
    top = int(np.argmax(fp.traps.size))
    assert (largest["row"], largest["col"]) == divmod(int(fp.traps.index[top]), 96)
    bright = cli("-q", "simulate", "--scene", "flat:0.5", *sets, "--frames", "2", "--process", "--out", tmp_path / "b")
    assert bright.returncode == 0
    assert json.loads((tmp_path / "b" / "summary.json").read_text())["processing"]["video"]["display_gain"] == 1.0


def test_the_compiled_picture_never_indexes_outside_its_table(tmp_path):
    """Codes that overflow float32 on their way through the compensation matrix gave NaN, and NaN an index far
    outside the sRGB table: a segmentation fault (found by the API fuzz test in CI). In a child process, so a
    crash fails this test and not the run."""
    code = textwrap.dedent("""
        import numpy as np
        from cmosnoise.isp import reconstruction as rc
        img = np.full((24, 32), 3e38, np.float32)
        img[::2, 1::2] = -3e38
        matrix = np.array([[1.2, -0.1, -0.1], [-0.1, 1.2, -0.1], [-0.1, -0.1, 1.2]], np.float32)
        for f in (rc.bilinear_srgb8, rc.superpixel_srgb8):
            out = f(img, "RGGB", 0.0, 1.0, matrix, np.ones(3, np.float32))
            assert out.dtype == np.uint8
        print("ok")
        """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and r.stdout.strip() == "ok", (r.returncode, r.stderr[-2000:])


def test_the_worst_flickering_pixels_get_a_close_up_video(tmp_path):
    """#63: a crop video around the worst few random telegraph pixels, their positions in summary.json."""
    import imageio.v3 as iio

    from cmosnoise import load_config
    from cmosnoise.app.run import CROP_ZOOM, telegraph_pixels

    sets = ["--set", "sensor.width=96", "--set", "sensor.height=64", "--set", "source_follower.rts.enabled=true",
            "--set", "source_follower.rts.ppm=3000", "--set", "dark_current.rts.enabled=true",
            "--set", "dark_current.rts.ppm=3000"]
    r = cli("-q", "simulate", "--scene", "flat:0.02", *sets, "--frames", "3", "--process", "--out", tmp_path / "v")
    assert r.returncode == 0, r.stderr
    crops = json.loads((tmp_path / "v" / "summary.json").read_text())["processing"]["video"]["rts_crops"]
    table = telegraph_pixels(Sensor(load_config(tmp_path / "v" / "config.yaml")))
    steps = np.where(table["kind"] == "trap", table["size"], table["size"] * 0.03)
    worst = table.iloc[np.argsort(-steps, kind="stable")[:4]]
    assert [(c["row"], c["col"]) for c in crops] == list(zip(worst["row"], worst["col"]))
    assert [c["step_e"] for c in crops] == sorted((c["step_e"] for c in crops), reverse=True)
    for c in crops:
        r0, r1, c0, c1 = c["crop"]
        assert r0 <= c["row"] < r1 and c0 <= c["col"] < c1 and (r1 - r0, c1 - c0) == (32, 32)
    frames = iio.imread(tmp_path / "v" / "rts_crops.mp4", index=None)
    assert frames.shape[0] == 3 and frames.shape[1] == 32 * CROP_ZOOM
    assert frames.shape[2] == 4 * 32 * CROP_ZOOM + 3 * 2
