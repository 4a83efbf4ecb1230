"""`cmosnoise sweep` on Dask: real LocalClusters, and a separately started `dask scheduler` and `dask worker`.

Every process a test starts is stopped by its id.
"""

import math
import os
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest
from conftest import DASK, cli, free_port, stop_process, wait_for_port

from cmosnoise import CmosnoiseError, load_config
from cmosnoise.app import sweep as sw

SMALL = ["--set", "sensor.width=64", "--set", "sensor.height=48", "--scene", "flat:0.3"]


def _dask(*args, env):
    return subprocess.Popen([DASK, *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)


def _scheduler(port, env):
    """A `dask scheduler` on the loopback address, listening when this returns."""
    proc = _dask("scheduler", "--host", "127.0.0.1", "--port", str(port), "--dashboard-address", "127.0.0.1:0",
                 "--no-show", env=env)
    wait_for_port(port, proc)
    return proc


def _sorted(path):
    return pd.read_csv(path).sort_values(["point", "instance"]).reset_index(drop=True)


def test_vary_grammar():
    a = sw.parse_vary("sensor.temperature_c=25,45,65")
    assert a.keys == ("sensor.temperature_c",) and a.values == ((25,), (45,), (65,))
    b = sw.parse_vary("sensor.width,sensor.height=640x480,2592x1944")
    assert b.keys == ("sensor.width", "sensor.height") and b.values == ((640, 480), (2592, 1944))
    c = sw.parse_vary("prnu.sigma_pct=0.5:2.0:4")
    assert c.values == ((0.5,), (1.0,), (1.5,), (2.0,))
    assert len(sw.grid([a, b, c])) == 3 * 2 * 4
    for bad, needle in [("prnu.sigma_pct", "KEY=VALUES"), ("prnu.sigma_pct=1:2:x", "start:stop:count"),
                        ("sensor.width,sensor.height=640", "for 2 keys"), ("=1,2", "dotted"), ("a.b=1,,2", "empty")]:
        with pytest.raises(CmosnoiseError, match=needle):
            sw.parse_vary(bad)


def test_wilson_interval_and_instance_seeds():
    lo, hi = sw.wilson(8, 10)
    assert lo == pytest.approx(0.4902, abs=1e-3) and hi == pytest.approx(0.9433, abs=1e-3)  # the textbook values
    assert sw.wilson(0, 20)[0] == 0.0 and sw.wilson(20, 20)[1] == pytest.approx(1.0)
    import numpy as np

    s = [sw.instance_seed(7, i) for i in range(4)]
    assert len(set(s)) == 4 and all(0 <= x < 2**63 for x in s)
    assert s[2] == sw.instance_seed(7, 2) and s[0] != sw.instance_seed(8, 0)
    state = np.random.SeedSequence(7, spawn_key=(3,)).generate_state(2, np.uint32)
    assert s[3] == (int(state[0]) << 31) ^ int(state[1])


@pytest.mark.parametrize("args, needle", [
    (["--vary", "sensor.nonsense=1,2"], "unknown key"),
    (["--vary", "prnu.sigma_pct=1,-3"], "prnu.sigma_pct"),
    (["--vary", "prnu.sigma_pct=1:2"], "start:stop:count"),
    (["--vary", "prnu.sigma_pct=1:2:0"], "count from 1"),
    (["--vary", "prnu.sigma_pct=1,2", "--spec", "couplets<<3"], "METRIC OP NUMBER"),
    (["--vary", "prnu.sigma_pct=1,2", "--spec", "nonsense<=3"], "unknown metric"),
    (["--scheduler", "tcp://127.0.0.1:1"], "cannot connect"),
    (["--metric", "nonsense"], "--metric"),
])
def test_bad_input_is_one_line_before_any_task(tmp_path, monkeypatch, args, needle):
    from cmosnoise.app import cluster

    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT", "1s")  # nothing listens on port 1: no need to wait 10 s
    r = cli("sweep", *SMALL, "--instances", "2", *args, "--out", tmp_path / "s")
    assert r.returncode == 2 and needle in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not (tmp_path / "s").exists()


@pytest.mark.slow
def test_results_do_not_depend_on_the_workers_or_the_cluster(tmp_path):
    base = ["sweep", *SMALL, "--vary", "sensor.temperature_c=25,65", "--vary", "prnu.sigma_pct=0.5,2",
            "--instances", "3", "--spec", "couplets<=0"]
    assert cli(*base, "--workers", "1", "--out", tmp_path / "w1").returncode == 0
    r = cli(*base, "--workers", "2", "--out", tmp_path / "w2")
    assert r.returncode == 0, r.stderr
    one, two = _sorted(tmp_path / "w1" / "results.csv"), _sorted(tmp_path / "w2" / "results.csv")
    assert len(one) == 4 * 3
    pd.testing.assert_frame_equal(one, two)
    # a cluster made of a separately started scheduler and worker, on the loopback address
    port = free_port()
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    procs = [_scheduler(port, env)]
    try:
        procs.append(_dask("worker", f"tcp://127.0.0.1:{port}", "--host", "127.0.0.1", "--nthreads", "1",
                           "--nworkers", "1", "--no-dashboard", env=env))
        r = cli(*base, "--scheduler", f"tcp://127.0.0.1:{port}", "--out", tmp_path / "sched")
        assert r.returncode == 0, r.stderr
        pd.testing.assert_frame_equal(one, _sorted(tmp_path / "sched" / "results.csv"))
    finally:
        for proc in reversed(procs):
            stop_process(proc)
    # the outputs: summary with yield intervals, a plot per metric, the index, sweep.yaml that reruns it
    summary = pd.read_csv(tmp_path / "w1" / "summary.csv")
    assert len(summary) == 4 and {"yield", "yield_lo", "yield_hi", "couplets_mean", "couplets_p95"} <= set(summary)
    assert all(summary["yield_lo"] <= summary["yield"]) and all(summary["yield"] <= summary["yield_hi"])
    names = {p.name for p in (tmp_path / "w1").iterdir()}
    assert {"results.csv", "summary.csv", "sweep.yaml", "index.html", "yield.png", "couplets.png"} <= names
    r = cli("sweep", "--from", tmp_path / "w1" / "sweep.yaml", "--workers", "1", "--out", tmp_path / "again")
    assert r.returncode == 0, r.stderr
    pd.testing.assert_frame_equal(one, _sorted(tmp_path / "again" / "results.csv"))


@pytest.mark.slow
def test_resume_finishes_an_interrupted_sweep_with_the_same_rows(tmp_path):
    args = ["sweep", *SMALL, "--vary", "sensor.temperature_c=25,65", "--instances", "3", "--workers", "1"]
    assert cli(*args, "--out", tmp_path / "full").returncode == 0
    full = _sorted(tmp_path / "full" / "results.csv")
    assert cli(*args, "--out", tmp_path / "part").returncode == 0
    lines = (tmp_path / "part" / "results.csv").read_text().splitlines()
    (tmp_path / "part" / "results.csv").write_text("\n".join(lines[:3]) + "\n")  # as if stopped after 2 rows
    r = cli(*args, "--out", tmp_path / "part")
    assert r.returncode == 2 and "--resume" in r.stderr  # not silently overwritten
    r = cli(*args, "--resume", "--out", tmp_path / "part")
    assert r.returncode == 0, r.stderr
    pd.testing.assert_frame_equal(full, _sorted(tmp_path / "part" / "results.csv"))
    r = cli(*args[:-4], "--instances", "4", "--workers", "1", "--resume", "--out", tmp_path / "part")
    assert r.returncode == 2 and "another sweep" in r.stderr


@pytest.mark.slow
def test_a_yield_study_over_a_list_item_runs_in_one_command(tmp_path):
    """The white-pixel target of one characterization point, varied in one sweep (a list item, by its index): the
    yield on the default flat field falls with the ppm, and each point's rows are those of a sweep with the value
    set (--set), as the shell loop of sweeps gave them."""
    from scipy import stats

    vga = ["--preset", "paper-fig9-vga", "--set", "sensor.temperature_c=65", "--set", "sensor.width=320",
           "--set", "sensor.height=240", "--instances", "20", "--spec", "couplets_after_correction<=0", "--workers", "2"]
    r = cli("sweep", *vga, "--vary", "dark_current.points.0.tail.ppm_above=1000,4000", "--out", tmp_path / "y")
    assert r.returncode == 0, r.stderr
    assert "scene: flat:0.5 (the yield study's default" in r.stdout  # which scene, and why
    index = (tmp_path / "y" / "index.html").read_text()
    assert "scene flat:0.5" in index and "the yield study&#x27;s default" in index
    summary = pd.read_csv(tmp_path / "y" / "summary.csv")
    assert summary["dark_current.points.0.tail.ppm_above"].tolist() == [1000, 4000]
    passed = (summary["yield"] * 20).round().astype(int).tolist()
    assert passed[0] == 20  # expected couplets at 1000 ppm: 0.3 per instance, and the corrector removes them
    # falling: one-sided Fisher exact test of the two pass counts at 5 % (the expected 20 of 20 against 14 of 20
    # gives p = 0.01, so the seeded run passes with margin; equal yields give p = 1)
    assert stats.fisher_exact([[passed[0], 20 - passed[0]], [passed[1], 20 - passed[1]]], "greater").pvalue < 0.05
    both = _sorted(tmp_path / "y" / "results.csv")
    r = cli("sweep", *vga, "--set", "dark_current.points.0.tail.ppm_above=4000", "--scene", "flat:0.5",
            "--out", tmp_path / "one")
    assert r.returncode == 0, r.stderr
    one = _sorted(tmp_path / "one" / "results.csv")
    metrics = [*sw.METRICS, "pass"]
    pd.testing.assert_frame_equal(both[both["point"] == 1][metrics].reset_index(drop=True), one[metrics])
    r = cli("sweep", *SMALL, "--vary", "dark_current.points.5.tail.ppm_above=10,20", "--out", tmp_path / "bad")
    assert r.returncode == 2 and "dark_current.points has 3 item(s)" in r.stderr


def test_keys_that_move_together_across_list_items():
    """Two characterization points' targets varied as one axis: each point's configuration has both, the rest kept."""
    p = sw.plan(load_config(), ["dark_current.points.0.tail.ppm_above,dark_current.points.1.tail.ppm_above=50x100,100x200"],
                1, scene="flat:0.5")
    tails = [[pt["tail"]["ppm_above"] for pt in c["dark_current"]["points"]] for c in p.configs]
    assert tails == [[50, 100, 200], [100, 200, 200]]  # the 65 C point keeps its default 200 ppm


@pytest.mark.slow
def test_python_api_returns_a_dataframe():
    cfg = load_config(extra={"sensor": {"width": 64, "height": 48}})
    df = sw.run(cfg, ["prnu.sigma_pct=1,2"], instances=2, scene="flat:0.5", workers=1)
    assert list(df["point"]) == [0, 0, 1, 1] and list(df["instance"]) == [0, 1, 0, 1]
    assert set(sw.METRICS) <= set(df.columns) and df["prnu.sigma_pct"].tolist() == [1, 1, 2, 2]
    assert all(math.isfinite(v) for v in df["temporal_noise_e"])


@pytest.mark.slow
def test_image_quality_metrics_are_sweep_responses_with_their_own_numbers(tmp_path):
    """--quality-lux adds `quality`'s metric registry to every row: the same numbers as `quality.measure` of that
    point's configuration and instance seed; a --spec on one of them makes the yield; the page names them with
    their lux and unit. More column FPN gives more column banding on every instance (common random numbers)."""
    from cmosnoise.analysis import quality

    qe = ["--set", "sensor.quantum_efficiency=0.6"]
    r = cli("sweep", *SMALL, *qe, "--vary", "column_noise.vfpn_sigma_e=1,6", "--instances", "2", "--frames", "2",
            "--quality-lux", "10", "--spec", "banding_columns<=1", "--workers", "1", "--out", tmp_path / "s")
    assert r.returncode == 0, r.stderr
    df = _sorted(tmp_path / "s" / "results.csv")
    names = [m.name for m in quality.METRICS]
    assert set(names) <= set(df.columns)
    row = df.iloc[3]  # point 1 (6 e-), instance 1 (a row of floats: its seed is read from its own column)
    cfg = sw.point_config(load_config(overrides=["sensor.width=64", "sensor.height=48", "sensor.quantum_efficiency=0.6"]),
                          {"column_noise.vfpn_sigma_e": 6})
    own = quality.measure(cfg, [10.0], frames=2, seed=int(df["seed"].iloc[3]))["metrics"]
    for name in names:
        v = own[name][0]
        assert (math.isnan(row[name]) if v is None else row[name] == v), (name, row[name], v)
    for j in (0, 1):
        b = df[df["instance"] == j]["banding_columns"].tolist()
        assert b[1] > b[0], b
    assert df["pass"].tolist() == [int(v <= 1) for v in df["banding_columns"]]
    page = (tmp_path / "s" / "index.html").read_text()
    assert "column banding, print at 10 lux, JND" in page.replace("\u200b", "")
    assert (tmp_path / "s" / "banding_columns.png").exists()


@pytest.mark.parametrize("args, needle", [
    (["--spec", "banding_columns<=1"], "(with --quality-lux)"),
    (["--quality-lux", "10", "--set", "light.spectral_qe=[[900, 0.5], [1000, 0.4]]"],
     "--quality-lux at sweep point (the base): light: the illuminant"),
    (["--quality-lux", "-3", "--set", "sensor.quantum_efficiency=0.5"], "--quality-lux -3"),
])
def test_quality_responses_are_checked_before_any_task(tmp_path, args, needle):
    r = cli("sweep", *SMALL, "--instances", "2", *args, "--out", tmp_path / "s")
    assert r.returncode == 2 and needle in r.stderr, r.stderr
    assert not (tmp_path / "s").exists()


@pytest.mark.slow
def test_a_worker_that_dies_mid_sweep_changes_nothing(tmp_path):
    """Two separately started workers; one is killed (SIGKILL) while tasks run: its tasks run again elsewhere."""
    args = [*SMALL, "--vary", "prnu.sigma_pct=0.5,1,2", "--instances", "6"]
    assert cli("sweep", *args, "--workers", "1", "--out", tmp_path / "ref").returncode == 0
    port = free_port()
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    procs = [_scheduler(port, env)]
    try:
        for _ in range(2):  # --no-nanny: the worker is the process we kill, nothing restarts it
            procs.append(_dask("worker", f"tcp://127.0.0.1:{port}", "--host", "127.0.0.1", "--nthreads", "1",
                               "--no-nanny", "--no-dashboard", env=env))
        sweep = subprocess.Popen([sys.executable, "-m", "cmosnoise", "sweep", *args, "--scheduler", f"tcp://127.0.0.1:{port}",
                                  "--out", str(tmp_path / "killed")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append(sweep)
        results = tmp_path / "killed" / "results.csv"
        deadline = time.monotonic() + 120
        while not (results.exists() and len(results.read_text().splitlines()) >= 4):  # a few rows written
            assert sweep.poll() is None and time.monotonic() < deadline, sweep.stderr.read() if sweep.poll() else "slow"
            time.sleep(0.05)
        os.kill(procs[1].pid, signal.SIGKILL)
        assert sweep.wait(timeout=300) == 0, sweep.stderr.read()
    finally:
        for proc in reversed(procs):
            stop_process(proc)
    pd.testing.assert_frame_equal(_sorted(tmp_path / "ref" / "results.csv"), _sorted(results))


@pytest.mark.slow
def test_the_sweep_page_fits_a_1440_pixel_window_with_readable_names(tmp_path, page):
    """#63: the index's table overflowed a 1440-pixel window (the yield interval's columns off screen) and showed
    raw names (snr_db_at_100e_mean). Two keys varied, a spec: every column is on screen, named for a person."""
    r = cli("-q", "sweep", *SMALL, "--vary", "sensor.temperature_c=25,65", "--vary", "prnu.sigma_pct=0.5,2",
            "--instances", "2", "--spec", "couplets<=0", "--workers", "1", "--out", tmp_path / "s")
    assert r.returncode == 0, r.stderr
    index = tmp_path / "s" / "index.html"
    text = index.read_text()
    assert "SNR at 100 e- (dB; hot pixels in the rms)" in text and "snr_db_at_100e_mean" not in text
    assert "yield (Wilson 95 %)" in text
    page.set_viewport_size({"width": 1440, "height": 900})
    page.goto(index.as_uri())
    box = page.evaluate("(() => { const t = document.querySelector('.table'); "
                        "return [t.scrollWidth, t.clientWidth, document.documentElement.scrollWidth]; })()")
    assert box[0] <= box[1] and box[2] <= 1440, box
