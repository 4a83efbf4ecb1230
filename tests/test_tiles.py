"""A sensor of any size in tiles (#33): windows of a sensor, scenes by region, `simulate --tile`, on Dask too.

Every check here is bit-identity against the whole sensor, or a count that must be the same exact number."""

import json

import numpy as np
import pytest
import tifffile
from conftest import cli, refuse_direct_writes, takes_o_direct

from cmosnoise import Sensor, load_config
from cmosnoise.analysis import white_pixels
from cmosnoise.analysis.run_stats import RunStats
from cmosnoise.app import cluster as dask_cluster
from cmosnoise.app.run import simulate
from cmosnoise.errors import CmosnoiseError
from cmosnoise.model import footprint, scene, tiles

ROWS, COLS = 70, 96

#: configurations whose every stage a window must reproduce: per-colour crosstalk (reads the neighbours), the
#: sparse populations (drawn for the whole sensor), every line map, the stages after the gain
CONFIGS = {
    "default": {},
    "per-colour crosstalk": {"crosstalk": {"kernel_pct": {
        "R": [[1, 5, 1], [5, 70, 5], [1, 5, 1]], "G": [[0.9, 4.5, 0.9], [4.5, 78.4, 4.5], [0.9, 4.5, 0.9]],
        "B": [[0.5, 2, 0.5], [2, 90, 2], [0.5, 2, 0.5]]}}},
    "defects": {"defects": {"enabled": True, "dead_ppm": 3000, "stuck_ppm": 3000, "low_gain_ppm": 3000,
                            "high_gain_ppm": 3000, "clusters": {"ppm": 2000},
                            "columns": {"offset_ppm": 20000, "gain_ppm": 20000, "stuck_ppm": 20000},
                            "rows": {"offset_ppm": 20000, "stuck_ppm": 20000}}},
    "telegraph and lines": {"source_follower": {"rts": {"enabled": True, "ppm": 50000}},
                            "dark_current": {"rts": {"enabled": True, "ppm": 50000}},
                            "column_noise": {"vfpn_sigma_e": 2, "gain_sigma_pct": 1},
                            "row_noise": {"fixed_sigma_e": 1}},
    "after the gain": {"pixel_offset": {"enabled": True, "sigma_e": 3},
                       "read_noise": {"enabled": True, "distribution": "tukey_lambda", "scale_dn": 2, "shape": -0.1},
                       "black_level": {"channel_offsets_dn": [1, -2, 0.5, 3], "frame_sigma_dn": 1}},
}


def _config(data, rows=ROWS, cols=COLS, **extra):
    return load_config(extra={**data, "sensor": {"width": cols, "height": rows}, **extra})


@pytest.mark.parametrize("name", list(CONFIGS))
def test_a_window_makes_its_rectangle_of_the_whole_sensor_bit_for_bit(name):
    cfg = _config(CONFIGS[name])
    shot = Sensor(cfg).expose("photo")
    whole = {k: shot.frame(k) for k in (0, 3)}
    detail = shot.frame(1, detail=True)
    rng = np.random.default_rng(11)
    for _ in range(4):  # random windows (even corners), at the edges and inside
        w0, v0 = 2 * int(rng.integers(0, 30)), 2 * int(rng.integers(0, 44))
        w1, v1 = int(rng.integers(w0 + 6, ROWS + 1)), int(rng.integers(v0 + 6, COLS + 1))
        part = Sensor(cfg, window=(w0, w1, v0, v1)).expose("photo")
        # a pixel away from an inner edge (crosstalk reads the neighbours the window does not hold)
        r0, r1 = w0 + (w0 > 0), w1 - (w1 < ROWS)
        c0, c1 = v0 + (v0 > 0), v1 - (v1 < COLS)
        for k, frame in whole.items():
            assert np.array_equal(part.frame(k, region=(r0, r1, c0, c1)), frame[r0:r1, c0:c1]), (k, (w0, w1, v0, v1))
        got = part.frame(1, detail=True, region=(r0, r1, c0, c1))  # the NumPy path, stage by stage
        assert np.array_equal(got.raw, detail.raw[r0:r1, c0:c1])
        assert set(got.contributions) == set(detail.contributions)
        for key, value in detail.contributions.items():
            assert np.array_equal(got.contributions[key], value[r0:r1, c0:c1]), key


def test_every_tile_is_that_rectangle_of_the_whole_frame():
    cfg = _config(CONFIGS["per-colour crosstalk"] | CONFIGS["defects"], rows=101, cols=130)  # odd: cut tiles
    whole = Sensor(cfg).expose("photo")
    frames = [whole.frame(k) for k in range(2)]
    tiling = tiles.Tiling(cfg, 32, "photo")
    assert len(tiling.regions) == 4 * 5 and tiling.regions[-1] == (96, 101, 128, 130)
    for region in tiling.regions:
        r0, r1, c0, c1 = region
        for k, (raw, electrons) in enumerate(tiling.frames(region, 2, electrons=True)):
            assert np.array_equal(raw, frames[k][r0:r1, c0:c1]), (region, k)
            assert electrons.shape == raw.shape
    # the populations were drawn once, with the first tile, and shared
    assert tiling.populations is not None and tiling.populations.defects is not None


def test_scenes_render_any_region_alone():
    shape = (301, 457)
    rng = np.random.default_rng(1)
    for source in ["flat:0.3", "ramp", "colorchecker", "zoneplate", "siemens", "spot", "steps:5", "photo"]:
        whole = scene.render(source, shape)
        for _ in range(5):
            r0, c0 = int(rng.integers(0, 300)), int(rng.integers(0, 456))
            r1, c1 = int(rng.integers(r0 + 1, 302)), int(rng.integers(c0 + 1, 458))
            assert np.array_equal(scene.render(source, shape, region=(r0, r1, c0, c1)), whole[r0:r1, c0:c1]), source
        # a window of the source at its own resolution (scene.window)
        w = scene.render(source, (50, 60), window=(10, 20), source_size=(200, 300))
        assert np.array_equal(scene.render(source, (50, 60), window=(10, 20), source_size=(200, 300),
                                          region=(5, 17, 3, 44)), w[5:17, 3:44])


@pytest.mark.parametrize("frames", [1, 3])
def test_simulate_in_tiles_writes_the_whole_runs_frames_tiled(tmp_path, frames):
    cfg = _config({}, rows=130, cols=200, run={"frames": frames}, scene={"source": "colorchecker"})
    tiled = simulate(cfg, tmp_path / "tiled", tile=64)
    whole = simulate(cfg, tmp_path / "whole")
    a, b = tifffile.imread(tmp_path / "tiled" / "raw.tiff"), tifffile.imread(tmp_path / "whole" / "raw.tiff")
    assert a.shape == (frames, 130, 200) and np.array_equal(a, b)
    with tifffile.TiffFile(tmp_path / "tiled" / "raw.tiff") as tf:
        assert len(tf.pages) == frames and all(p.is_tiled and p.tilewidth == 64 for p in tf.pages)
        assert tf.shaped_metadata[0]["tile"] == 64 and tf.shaped_metadata[0]["cfa"] == "RGGB"
    assert sorted(p.name for p in (tmp_path / "tiled").iterdir()) == ["config.yaml", "raw.tiff", "summary.json"]
    assert tiled["tiles"] == {"size": 64, "count": 3 * 4, "halo": tiles.HALO, "not_made": tiled["tiles"]["not_made"]}
    # the same float64 sums over the same 26 000 pixels, added in another order (tile by tile against row by row):
    # each differs from the exact sum by at most n eps of its absolute sum (n = 26 000 terms, eps = 1.1e-16), so
    # two orders agree within 2 n eps = 5.8e-12 relative for sums of positive terms; 1e-11 allows it. The
    # temporal variance is a difference (S2 - S1^2 / n) / n of two such sums whose second is some 1e-4 of the
    # first here (the frame differences' mean is near 0), so it keeps that bound.
    for key in ("mean_e", "mean_dn", "saturated_fraction", "expected_mean_e", "perfect_mean_e"):
        assert tiled["signal"][key] == pytest.approx(whole["signal"][key], rel=1e-11, abs=0), key
    if frames > 1:
        for key in ("rms_e", "rms_dn"):
            assert tiled["temporal_noise"][key] == pytest.approx(whole["temporal_noise"][key], rel=1e-11), key
    # the white pixels and couplets of the dark map, gathered by position across the tiles: the same counts
    assert tiled["dark_current"]["map"]["white_pixels"] == whole["dark_current"]["map"]["white_pixels"]
    assert tiled["dark_current"]["map"]["couplets"] == whole["dark_current"]["map"]["couplets"]
    assert tiled["dark_current"]["map_mean_e_per_s"] == pytest.approx(whole["dark_current"]["map_mean_e_per_s"],
                                                                       rel=1e-11)  # float64 sums, as above
    assert json.loads((tmp_path / "tiled" / "summary.json").read_text())["tiles"]["count"] == 12


def test_a_tiled_raw_is_laid_out_with_holes_and_filled_tile_by_tile(tmp_path):
    from cmosnoise.io.raw_tiff import DIRECT_ALIGN, TileWriter, create_tiled_raw_tiff, write_raw_tiff

    # tiles of 256 x 256 uint16 (128 KiB: long enough to be holes), 3 x 3 of them a page, the last ones cut
    shape, tile, meta = (600, 520), 256, {"cfa": "RGGB", "bits": 12}
    laid = tmp_path / "laid.tiff"
    offsets = create_tiled_raw_tiff(laid, 2, shape, meta, "uint16", tile)
    assert not np.any(offsets % DIRECT_ALIGN)  # every tile where a direct write may start
    zeros = tmp_path / "zeros.tiff"
    # tifffile writing every tile's zeros, its pages aligned the same way
    write_raw_tiff(zeros, None, 2, shape, meta, "uint16", tile=tile, align=DIRECT_ALIGN)
    assert laid.read_bytes() == zeros.read_bytes()  # the same file, its last tile's hole included
    # holes: 18 tiles of 128 KiB (2.3 MB) take no blocks; the header and tags take a few (Linux file systems
    # for /tmp: ext4, xfs, btrfs, tmpfs, overlayfs all keep holes)
    assert laid.stat().st_blocks * 512 < 18 * tile * tile * 2 / 4
    frames = np.random.default_rng(0).integers(0, 4096, (2, *shape), dtype=np.uint16)
    with TileWriter(laid, tile, "uint16", direct=False) as out:
        for t, (r0, r1, c0, c1) in reversed(list(enumerate(tiles.grid(shape, tile)))):  # any order
            for k in range(2):
                out.write(int(offsets[k, t]), frames[k, r0:r1, c0:c1])
    assert np.array_equal(tifffile.imread(laid), frames)


@pytest.mark.parametrize("dtype, tile", [("uint16", 256), ("float32", 128), ("uint16", 16)])
def test_tiles_written_direct_or_through_the_page_cache_are_the_same_file(tmp_path, monkeypatch, dtype, tile):

    from cmosnoise.io import raw_tiff

    shape, meta = (600, 520), {"cfa": "RGGB", "bits": 12}
    rng = np.random.default_rng(1)
    frames = (rng.integers(0, 4096, (2, *shape)) if dtype == "uint16" else rng.normal(500, 30, (2, *shape)))
    frames = frames.astype(dtype)
    grid = list(enumerate(tiles.grid(shape, tile)))

    def fill(name, direct=True):
        path = tmp_path / name
        offsets = raw_tiff.create_tiled_raw_tiff(path, 2, shape, meta, dtype, tile)
        with raw_tiff.TileWriter(path, tile, dtype, direct=direct) as out:
            for t, (r0, r1, c0, c1) in reversed(grid):
                for k in range(2):
                    out.write(int(offsets[k, t]), frames[k, r0:r1, c0:c1])
            used = out.direct
        return path.read_bytes(), used

    through, used = fill("cache.tiff", direct=False)
    assert not used
    # the file tifffile writes from the same tiles (its edge tiles padded with zeros), byte for byte
    made = tmp_path / "tifffile.tiff"
    raw_tiff.write_raw_tiff(made, (frames[k, r0:r1, c0:c1] for k in range(2) for _, (r0, r1, c0, c1) in grid), 2,
                            shape, meta, dtype, tile=tile, align=raw_tiff.DIRECT_ALIGN)
    assert through == made.read_bytes()
    direct, used = fill("direct.tiff")
    # direct where the file system takes O_DIRECT (ext4, xfs, btrfs, tmpfs from Linux 6.6), except 16 x 16 uint16
    # tiles: 512 bytes, not a multiple of 4096, go through the page cache
    aligned = tile * tile * np.dtype(dtype).itemsize % raw_tiff.DIRECT_ALIGN == 0
    assert used == (aligned and takes_o_direct(tmp_path))
    assert direct == through
    # a file system refusing O_DIRECT at the first write (EINVAL): the rest through the page cache, the same bytes
    calls = refuse_direct_writes(monkeypatch)
    refused, used = fill("refused.tiff")
    assert refused == through and not used
    assert len(calls) == (1 if aligned and takes_o_direct(tmp_path) else 0)
    # an offset off the 4096-byte grid (a file not laid out for direct writes): through the page cache, in place
    monkeypatch.undo()
    nbytes = tile * tile * np.dtype(dtype).itemsize
    scratch = tmp_path / "scratch"
    scratch.write_bytes(bytes(3 * nbytes))
    with raw_tiff.TileWriter(scratch, tile, dtype) as out:
        out.write(512, frames[0, :tile, :tile])
        assert not out.direct
    data = scratch.read_bytes()
    assert data[512:512 + nbytes] == frames[0, :tile, :tile].tobytes() and data[:512] == bytes(512)


def test_couplets_across_tile_edges_are_counted():
    # a dense white map: many couplets straddle the edges of 32-pixel tiles
    cfg = load_config(extra={"sensor": {"width": 128, "height": 96}},
                      overrides=["dark_current.points.0.tail.ppm_above=50000"])
    sensor = Sensor(cfg)
    rate, threshold = sensor.dark_rate, sensor.dark_state.threshold
    whole = white_pixels.report(rate, threshold, sensor.cfa)
    r, c = [], []
    for region in tiles.grid(sensor.shape, 32):
        part = Sensor(cfg, window=region)
        rr, cc = np.nonzero(part.dark_rate > threshold)
        r.append(rr + region[0])
        c.append(cc + region[2])
    r, c = np.concatenate(r), np.concatenate(c)
    order = np.lexsort((c, r))
    pairs = white_pixels.pairs_at(r[order], c[order], sensor.shape, sensor.cfa)
    assert whole["couplets"] > 10 and len(pairs) == whole["couplets"]
    assert np.array_equal(pairs, white_pixels.couplet_pairs(rate > threshold, sensor.cfa))


def test_run_statistics_of_parts_are_those_of_the_whole():
    rng = np.random.default_rng(5)
    frames = [rng.poisson(500, (40, 50)).astype(np.uint16) for _ in range(3)]
    whole = RunStats(4095)
    for f in frames:
        whole.update(f, f.astype(np.float32))
    total = RunStats(4095)
    for cols in (slice(0, 17), slice(17, 50)):
        part = RunStats(4095)
        for f in frames:
            part.update(f[:, cols], f[:, cols].astype(np.float32))
        total.absorb(part)
    got, want = total.result(), whole.result()
    assert got["frames"] == want["frames"] == 3
    # 2 000 float64 terms a sum in two orders: within 2 n eps = 4.4e-13 relative (see the tiled-run test)
    for key in ("mean_e", "mean_dn", "temporal_noise_e", "temporal_noise_dn"):
        assert got[key] == pytest.approx(want[key], rel=1e-12), key
    with pytest.raises(ValueError, match="same frames"):
        short = RunStats(4095)
        short.update(frames[0], frames[0].astype(np.float32))
        total.absorb(short)


@pytest.mark.slow
def test_tiles_on_dask_workers_give_the_same_file(tmp_path):
    cfg = _config({}, rows=100, cols=160, run={"frames": 2}, scene={"source": "photo"})
    simulate(cfg, tmp_path / "here", tile=32)
    client, cluster = dask_cluster.connect(None, 2)
    try:
        summary = simulate(cfg, tmp_path / "dask", tile=32, client=client)
    finally:
        dask_cluster.disconnect(client, cluster)
    assert np.array_equal(tifffile.imread(tmp_path / "here" / "raw.tiff"), tifffile.imread(tmp_path / "dask" / "raw.tiff"))
    here = json.loads((tmp_path / "here" / "summary.json").read_text())
    assert summary["signal"] == here["signal"] and summary["temporal_noise"] == here["temporal_noise"]


def test_a_sensor_too_large_whole_fits_in_tiles():
    cfg = load_config(extra={"sensor": {"width": 20000, "height": 20000}})
    with pytest.raises(CmosnoiseError, match="simulate --tile"):
        footprint.check_fits(cfg, available=4 * 10**9)
    from cmosnoise.app import tiled

    footprint.check_fits(cfg, available=4 * 10**9, pixels=tiled.memory_pixels(2048, 1), tiled=True)
    with pytest.raises(CmosnoiseError, match="make --tile smaller"):
        footprint.check_fits(cfg, available=4 * 10**8, pixels=tiled.memory_pixels(8192, 1), tiled=True)


@pytest.mark.parametrize("args, needle", [
    (["--tile", "100"], "multiple of 16"),
    (["--tile", "64", "--process"], "--process"),
    (["--tile", "64", "--report"], "--report"),
    (["--workers", "2"], "give --tile SIZE too"),
    (["--tile", "64", "--device", "cuda"], "CPU kernel"),
])
def test_bad_tiled_runs_are_one_line_before_anything_is_written(tmp_path, args, needle):
    r = cli("simulate", "--set", "sensor.width=64", "--set", "sensor.height=48", *args, "-o", tmp_path / "out")
    assert r.returncode == 2 and needle in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_bad_windows_are_one_line_errors():
    cfg = _config({})
    with pytest.raises(CmosnoiseError, match="must be even"):
        Sensor(cfg, window=(1, 20, 0, 20))
    with pytest.raises(CmosnoiseError, match="inside the sensor's window"):
        Sensor(cfg, window=(0, 20, 0, 20)).expose().frame(0, region=(10, 30, 0, 10))
    with pytest.raises(CmosnoiseError, match="window's"):
        Sensor(cfg, window=(0, 20, 0, 20)).expose(np.zeros((ROWS, COLS)))


@pytest.mark.parametrize("name, extra", [
    ("monochrome", {"sensor": {"cfa": "none"}}),
    ("ADC off: float32 e-, two frames", {"adc": {"enabled": False}, "run": {"frames": 2}}),
    ("later frames", {"run": {"first_frame": 7, "frames": 2}}),
    ("smaller than a tile", {"sensor": {"width": 40, "height": 30}}),
    ("a window of a picture", {"scene": {"source": "photo", "window": [100, 50], "source_size": [600, 800]}}),
])
def test_tiled_runs_of_other_sensors_and_scenes_are_the_whole_runs(tmp_path, name, extra):
    data = {**extra, "sensor": {"width": 160, "height": 112, **extra.get("sensor", {})}}
    cfg = load_config(extra=data)
    simulate(cfg, tmp_path / "tiled", tile=48)
    simulate(cfg, tmp_path / "whole")
    a, b = tifffile.imread(tmp_path / "tiled" / "raw.tiff"), tifffile.imread(tmp_path / "whole" / "raw.tiff")
    assert a.dtype == b.dtype and np.array_equal(a, b), name
