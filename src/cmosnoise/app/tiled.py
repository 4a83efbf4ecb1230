"""``simulate --tile SIZE``: a sensor of any size made tile by tile, with memory bounded by a few tiles.

Each tile is made alone (:class:`cmosnoise.model.tiles.Tiling`: its window's fixed maps, scene and mean
charge), its frames are rendered, measured and written, and it is dropped. ``raw.tiff`` is a tiled TIFF whose
tiles are the run's: it is laid out first with every page's tiles in place (holes: a sparse file where the file
system has them, :func:`~cmosnoise.io.raw_tiff.create_tiled_raw_tiff`), each tile's frames are made together (its
set-up once), and they are written into their pages as the tile comes. With Dask (``--workers`` or
``--scheduler``) the tiles go to the workers, a few at a time, and come back in order.

The summary is gathered from the tiles as they pass: the measured signal and temporal noise (the sums of every
tile's pixels, :class:`~cmosnoise.analysis.run_stats.RunStats`), and the dark-current map's mean and white pixels
with their couplets (from the white pixels' positions, so that a couplet across two tiles counts). What needs the
whole frame at once (the noise budget, frame 0's white pixels, the pictures, processing) is not made; the summary
says so.
"""

from __future__ import annotations

import json
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..analysis import figures_of_merit as fom
from ..analysis import white_pixels
from ..analysis.run_stats import RunStats
from ..engine import reduce
from ..errors import CmosnoiseError
from ..io.raw_tiff import TileWriter, create_tiled_raw_tiff
from ..model import footprint, tiles
from ..model.sensor import Sensor
from ..model.spec import SensorSpec, resolve
from .summary import run_metadata, signal_figures, summary_head

#: what a tiled run leaves out, and why (the summary's ``tiles.not_made``)
NOT_MADE = {
    "noise_budget": "a budget is a pass over the whole sensor's maps at once",
    "key_figures": "they are the whole sensor's map statistics",
    "dark_current.frame0": "frame 0's white pixels are judged against the budget's read noise",
    "preview.png": "a picture of the whole frame",
}
#: how many tiles a Dask run keeps in flight per worker
IN_FLIGHT_PER_WORKER = 2


def check(config) -> None:
    """Refuse, in one line, what a tiled run cannot make (before anything is drawn or written).

    Parameters
    ----------
    config : Config
        The run's configuration.
    """
    wants = [name for name, on in (("processing (--process)", config.processing.enabled),
                                   ("dark frames (--dark-frames)", config.processing.dark_frames > 0),
                                   ("a report (--report)", config.run.report),
                                   ("DNG files (--format dng)", config.run.dng)) if on]
    if wants:
        raise CmosnoiseError(f"--tile makes raw.tiff, config.yaml and summary.json tile by tile; {', '.join(wants)} "
                             "need(s) the whole frame at once: leave them out, or run without --tile")


def tile_task(config_data: dict, size: int, region: tuple[int, int, int, int], frames: int, first: int,
              populations=None) -> dict:
    """Everything a run takes from one tile: its frames, its sums and its dark map's white pixels.

    What a Dask worker runs (a pure function of the configuration as data and the tile).

    Parameters
    ----------
    config_data : dict
        The run's configuration as data (``Config.model_dump()``).
    size : int
        The tile side.
    region : (row0, row1, col0, col1)
        The tile.
    frames, first : int
        How many frames, and the first one's number.
    populations : FixedPattern, optional
        The whole sensor's sparse populations (another tile's), so that they are not drawn again.

    Returns
    -------
    dict
        ``raw``: the frames, a list of (h, w) arrays (not stacked: that copies them all, into fresh memory);
        ``stats``: their :class:`RunStats`; ``perfect_e``, ``expected_e``: the sums of the perfect image and of
        the mean charge (e-); ``dark_sum``: of the dark map (e-/s);
        ``white``: the dark map's white pixels (rows, cols) above the threshold; ``set_up_s``,
        ``frames_s``: where its time went (two tiles are made at once: the run's sums of them overlap).
    """
    from ..config.schema import Config
    from .cluster import worker_attribute

    # the worker's tiling of this run, kept between its tasks (a picture decoded once a worker, not once a tile)
    key = json.dumps([config_data, size], sort_keys=True, default=str)
    held = worker_attribute("tiling", dict)
    if held.get("key") != key:
        tiling = tiles.Tiling(resolve(Config.model_validate(config_data)), size)
        tiling.share(populations)
        held.update(key=key, tiling=tiling)
    return tile_result(held["tiling"], region, frames, first)


def tile_result(tiling: tiles.Tiling, region: tuple[int, int, int, int], frames: int, first: int) -> dict:
    """:func:`tile_task`'s work on a tiling already made (its populations and its picture shared by the tiles one
    process makes).

    Parameters
    ----------
    tiling : Tiling
        The sensor in tiles.
    region : (row0, row1, col0, col1)
        The tile.
    frames, first : int
        How many frames, and the first one's number.

    Returns
    -------
    dict
        As :func:`tile_task`.
    """
    t0 = time.perf_counter()
    shot = tiling.exposure(region)
    t1 = time.perf_counter()
    sensor = shot.sensor
    stats = RunStats(sensor.transfer.max_code)
    raws = []
    for raw, electrons in shot.frames_with_electrons(frames, first, region):
        stats.update(raw, electrons)
        raws.append(raw)
    t2 = time.perf_counter()
    w0, _, v0, _ = sensor.region
    r0, r1, c0, c1 = region
    inner = (slice(r0 - w0, r1 - w0), slice(c0 - v0, c1 - v0))
    out = {"raw": raws, "stats": stats,
           "perfect_e": reduce.total(shot.perfect_e[inner]),
           "expected_e": shot.expected_sum(inner),
           "set_up_s": t1 - t0, "frames_s": t2 - t1, "dark_sum": None, "white": None}
    state = sensor.dark_state
    if state is not None:
        out["dark_sum"] = reduce.total(sensor.dark_rate[inner])
        if state.threshold is not None:  # found in the whole window (no copy of the tile's part), kept in the tile
            r, c = reduce.positions_above(sensor.dark_rate, state.threshold)
            keep = (r >= r0 - w0) & (r < r1 - w0) & (c >= c0 - v0) & (c < c1 - v0)
            out["white"] = (r[keep] + w0, c[keep] + v0)
    return out


def simulate_tiled(spec: SensorSpec, tmp: Path, size: int, progress=None, phase: Callable[[str], None] | None = None,
                   client=None) -> dict:
    """Make the run of ``spec`` tile by tile into the folder ``tmp``: raw.tiff (tiled) and the summary.

    Parameters
    ----------
    spec : SensorSpec
        The run's sensor (its ``run`` section: frames, first frame).
    tmp : Path
        The output folder being written (:class:`~cmosnoise.io.output.OutputFolder`'s temporary one).
    size : int
        The tile side (:func:`cmosnoise.model.tiles.grid`).
    progress : callable, optional
        As :func:`~cmosnoise.app.run.simulate`'s: called with the number of tiles times frames.
    phase : callable, optional
        Told ``"set-up"`` (the sparse populations), then ``"frames"``.
    client : distributed.Client, optional
        Make the tiles on its workers.

    Returns
    -------
    dict
        The summary (written to ``summary.json`` by the caller).
    """
    import contextlib

    phase = phase or (lambda _name: None)
    config = spec.config
    size = tiles.check_size(size)
    n, first = config.run.frames, config.run.first_frame
    regions = tiles.grid(spec.shape, size)
    data = config.model_dump()
    t_start = time.perf_counter()
    phase("set-up")
    corner = Sensor(spec, window=tiles.CORNER)  # the sparse populations drawn once, shared by every tile
    populations = corner.fixed_pattern
    dtype = np.dtype("uint16" if config.adc.enabled else "float32")
    stats = RunStats(spec.transfer.max_code)
    sums = {"perfect_e": 0.0, "expected_e": 0.0, "dark_sum": 0.0, "set_up_s": 0.0, "frames_s": 0.0}
    white_r, white_c = [], []

    def results():
        """Each tile's :func:`tile_task` result, in the tiles' order."""
        if client is None:  # two tiles at a time: one's set-up (mostly one core's NumPy) beside the other's frames
            tiling = tiles.Tiling(spec, size)  # one for every tile: the populations and a picture held once
            tiling.share(populations)
            with ThreadPoolExecutor(2, thread_name_prefix="cmosnoise-tile") as pool:
                pending = deque()
                for region in regions:
                    pending.append(pool.submit(tile_result, tiling, region, n, first))
                    if len(pending) > 2:
                        yield pending.popleft().result()
                while pending:
                    yield pending.popleft().result()
            return
        from .cluster import task_result

        shared = client.scatter(populations, broadcast=True)
        ahead = max(1, IN_FLIGHT_PER_WORKER * len(client.scheduler_info().get("workers", {})))
        pending = []  # (tile, future), oldest first: results come back in the tiles' order
        for region in regions:
            pending.append((region, client.submit(tile_task, data, size, region, n, first, shared, pure=False)))
            while len(pending) > ahead:
                done, future = pending.pop(0)
                yield task_result(future, f"tile {done}")
        for done, future in pending:
            yield task_result(future, f"tile {done}")

    meta = run_metadata(corner, tile=size)
    phase("frames")
    cm = progress(len(regions) * n) if progress else contextlib.nullcontext(lambda: None)
    # every page's tiles in place first (holes); each tile's frames then go to their pages as the tile comes
    offsets = create_tiled_raw_tiff(tmp / "raw.tiff", n, spec.shape, meta, dtype.name, size)
    with TileWriter(tmp / "raw.tiff", size, dtype) as out, cm as advance:
        for t, part in enumerate(results()):
            stats.absorb(part["stats"])
            for key in sums:
                sums[key] += part[key] or 0.0
            if part["white"] is not None:
                white_r.append(part["white"][0])
                white_c.append(part["white"][1])
            for k in range(n):
                out.write(int(offsets[k, t]), part["raw"][k])
                advance()
    total = time.perf_counter() - t_start
    (tmp / "config.yaml").write_text(config.to_yaml())
    return _summary(corner, stats, sums, (white_r, white_c), size, len(regions), total)


def _summary(corner: Sensor, stats: RunStats, sums: dict, white, size: int, count: int, total: float) -> dict:
    """The tiled run's summary.json: what the tiles' sums give (module docstring); ``corner``: the sensor's corner
    window, which holds what every tile shares (the configuration, the stages, the dark state)."""
    config = corner.config
    pixels = corner.shape[0] * corner.shape[1]
    measured = stats.result()
    n = config.run.frames
    out = {
        **summary_head(corner, n),
        "tiles": {"size": size, "count": count, "halo": tiles.HALO, "not_made": NOT_MADE},
        "signal": signal_figures(sums["perfect_e"] / pixels, sums["expected_e"] / pixels, measured),
        "temporal_noise": fom.temporal_noise(measured, corner.transfer.gain_dn_per_e),
        "dark_current": None,
        "warnings": [],
        "processing": {"enabled": False, "processing_s": 0.0},
        "timings_s": {"total": round(total, 6), "per_frame": round(total / max(n, 1), 6), "frames": n,
                      "frame_s": round(sums["frames_s"] / max(n, 1), 6), "set_up": round(sums["set_up_s"], 6),
                      "stages": {}},
    }
    state = corner.dark_state
    if state is not None:
        mean = sums["dark_sum"] / pixels
        dc = {"temperature_c": state.temperature_c, "map_mean_e_per_s": mean,
              "mean_dark_e_per_frame": mean * config.exposure.integration_time_s, **fom.threshold_figures(state)}
        if state.threshold is not None:
            r = np.concatenate(white[0]) if white[0] else np.zeros(0, np.int64)
            c = np.concatenate(white[1]) if white[1] else np.zeros(0, np.int64)
            order = np.lexsort((c, r))
            dc["map"] = white_pixels.report_at(r[order], c[order], corner.shape, state.threshold, config.sensor.cfa)
        out["dark_current"] = dc
    return out


#: tiles a run holds at once: two being made (one's set-up beside the other's frames) and one being written
TILES_IN_FLIGHT = 3


def memory_pixels(size: int, frames: int) -> int:
    """Pixels a tiled run holds at once, in the units of :func:`cmosnoise.model.footprint.check_fits` (a run's
    bytes a pixel): :data:`TILES_IN_FLIGHT` tiles' windows, each with its frames kept until written (2 bytes a
    pixel a frame).

    Parameters
    ----------
    size : int
        The tile side.
    frames : int
        The run's frames.

    Returns
    -------
    int

    Examples
    --------
    >>> from cmosnoise.app import tiled
    >>> tiled.memory_pixels(2048, 1) < 20_000_000
    True
    """
    side = size + 2 * tiles.HALO
    per_pixel = footprint.PER_PIXEL["run"]
    return int(TILES_IN_FLIGHT * side * side * (per_pixel + 2 * frames) / per_pixel) + 1


def check_fits(config, size: int) -> None:
    """A tiled run's memory check: what its tiles in flight need (a one-line error naming --tile where not).

    Parameters
    ----------
    config : Config
        The run's configuration.
    size : int
        The tile side.
    """
    footprint.check_fits(config, pixels=memory_pixels(size, config.run.frames), tiled=True)
