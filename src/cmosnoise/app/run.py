"""The jobs: simulate frames of a scene and write them with their record; process raw files.

``simulate(config, out)`` writes into ``out``:

- ``raw.tiff``: raw frames, uint16 DN, (frames, rows, cols), CFA/black level/bits in the metadata
- ``config.yaml``: the resolved configuration, seed included (re-running it reproduces raw.tiff)
- ``summary.json``: key figures (signal and temporal noise in e- and DN, stages, timings)
- ``preview.png``: frame 0 as a picture, the pre-processing view (no dark calibration, no defect correction)
- with processing on: ``processed.png`` (frame 0 through the whole chain), ``processed.mp4``
  (several frames), ``master_dark.tiff`` (with dark calibration)
- with ``run.dng``: ``dng/frame_NNNNNN.dng``, every raw frame as a DNG
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..analysis import white_pixels
from ..analysis.run_stats import RunStats
from ..config import Config, ProcessingSection, load_config, merge_updates
from ..engine.frame import kernel
from ..errors import CmosnoiseError
from ..io.dng import write_dng
from ..io.output import OutputFolder, write_json, write_png
from ..io.raw_tiff import RawTiffReader, SeriesWriter, create_raw_tiff, write_float_tiff
from ..io.video import VideoWriter
from ..isp import calibration
from ..isp.process import Processor, read_dark
from ..model import footprint, tiles
from ..model import scene as scene_mod
from ..model.raw_info import RawInfo
from ..model.sensor import Sensor, check_device
from ..model.spec import SensorSpec, resolve
from .summary import build_summary, run_metadata, sensor_figures


def _corrected(processor, raw: np.ndarray, first: list) -> np.ndarray:
    """``raw`` calibrated and defect-corrected (:meth:`Processor.cfa_image`); the first frame asked for is kept in
    ``first`` (as (raw, image)) and given again when asked for once more, so that frame 0's picture, video frame
    and count of the defects left share one correction (one's own corrector runs once a frame)."""
    if first and first[0][0] is raw:
        return first[0][1]
    img = processor.cfa_image(raw)
    if not first:
        first.append((raw, img))
    return img


def simulate(config: SensorSpec | Config, out: str | Path, progress: Callable[[int], contextlib.AbstractContextManager] | None = None,
             phase: Callable[[str], None] | None = None, overwrite: bool = False, device: str = "cpu",
             tile: int | None = None, client=None) -> dict:
    """Run the simulation of ``config`` and write the results into ``out``; returns the summary.

    ``progress``, if given, is called with the frame count and returns a
    context manager whose value is called once per frame (``advance()``).
    ``phase``, if given, is told what the run does outside the frames' progress (each can take seconds on a
    large sensor): ``"set-up"`` (the fixed pattern), ``"scene"`` (the mean charge), ``"dark"`` (a master
    dark's frames), ``"frames"`` (the progress bar takes over), ``"summary"`` (with the pictures), ``"report"``.
    An existing non-empty ``out`` is replaced as a whole with ``overwrite``,
    else refused (:class:`~cmosnoise.io.output.OutputFolder`). ``device``:
    where frames are made (``"cpu"`` or ``"cuda"``, :class:`~cmosnoise.model.sensor.Sensor`; the same bits).
    ``tile``: make the sensor tile by tile, ``tile`` pixels a side (:mod:`.tiled`: memory bounded by a few tiles,
    raw.tiff tiled, the same bits as a whole run's), on the Dask ``client``'s workers where one is given;
    ``progress`` then counts tiles times frames.
    """
    phase = phase or (lambda _name: None)
    spec, tile = _checked(config, device, tile)
    config = spec.config
    folder = OutputFolder(out, overwrite)  # fails early if out cannot be written or exists
    folder.check_space(output_bytes(config) * (2 if tile is not None and config.run.frames > 1 else 1))
    if tile is not None:
        from . import tiled  # it builds on this module's summary

        with folder as tmp:
            summary = tiled.simulate_tiled(spec, tmp, tile, progress, phase, client)
            write_json(tmp / "summary.json", summary)
        return summary
    # Two more threads take work nothing waits for: loading the compiled kernel while this thread draws the
    # fixed pattern, the summary's figures of the sensor alone while this thread makes the scene and the frames,
    # and frame 0's pictures while the rest of the summary is built (PNG encoding and most of NumPy's work release
    # the GIL; the compiled loops take turns, engine.jit.ONE_LAUNCH).
    with folder as tmp, ThreadPoolExecutor(2, thread_name_prefix="cmosnoise-aside") as aside:
        t_start = time.perf_counter()
        aside.submit(kernel.preload)
        phase("set-up")
        sensor = Sensor(spec, device=device)
        prepared = aside.submit(sensor_figures, sensor)  # from the maps alone, beside the scene and the frames
        phase("scene")
        shot = sensor.expose()
        n, first = config.run.frames, config.run.first_frame
        transfer = sensor.transfer
        proc_cfg = config.processing
        info = sensor.raw_info()

        master = None
        t0 = time.perf_counter()
        if proc_cfg.dark_frames > 0:
            phase("dark")
            master = calibration.master_dark(sensor.dark_frames(proc_cfg.dark_frames))
            write_float_tiff(tmp / "master_dark.tiff", master, {"frames": proc_cfg.dark_frames, **asdict(info)})
        t_dark = time.perf_counter() - t0
        processor = Processor(proc_cfg, info, master)

        stats = RunStats(transfer.max_code)
        frame0: list[np.ndarray] = []
        rendered0: list[np.ndarray] = []
        cfa0: list = []  # frame 0 calibrated and corrected: its picture's and the defects' count's (_corrected)
        video = None
        video_info = None
        fps = video_rate(proc_cfg.video_fps, shot.frame_period_s)
        if config.run.dng:
            (tmp / "dng").mkdir()
        t_process = 0.0

        def pictures():
            """Frame 0's pictures, written as PNG: the preview, and the processed one when processing is on."""
            pre_view = processor.render(frame0[0], pre=True)
            write_png(tmp / "preview.png", pre_view)
            processed, t = rendered0[0] if rendered0 else None, 0.0
            if processed is None and (proc_cfg.enabled or config.run.report):
                tp = time.perf_counter()
                processed = processor.render_cfa(_corrected(processor, frame0[0], cfa0))
                t = time.perf_counter() - tp
            if proc_cfg.enabled:
                write_png(tmp / "processed.png", processed)
            return pre_view, processed, t

        stamps: list[float] = []  # when each frame was made: the steady time per frame, apart from the set-up

        crops = worst_telegraph(sensor) if proc_cfg.enabled and n > 1 else []
        crop_video = None

        def frames(advance):
            nonlocal t_process, video, video_info, crop_video
            stamps.append(time.perf_counter())
            for k, (raw, electrons) in enumerate(shot.frames_with_electrons(n, first), start=first):
                stats.update(raw, electrons)
                if not frame0:
                    frame0.extend([raw, electrons])
                if config.run.dng:
                    write_dng(tmp / "dng" / f"frame_{k:06d}.dng", raw, sensor.cfa, transfer.black_level_dn,
                              transfer.max_code, processor.mixing, info.responsivity, iso=config.sensor.iso,
                              exposure_s=config.exposure.integration_time_s)
                if proc_cfg.enabled and n > 1:
                    tp = time.perf_counter()
                    picture = processor.render_cfa(_corrected(processor, raw, cfa0))
                    if video is None:  # frame 0's picture sets the display gain, the same for every frame
                        gain = display_gain(picture) if proc_cfg.video_stretch else 1.0
                        video_info = {"fps": fps, "display_gain": gain, "frames": n}
                        video = VideoWriter(tmp / "processed.mp4", fps, comment=(
                            f"cmosnoise {config.seed}: {n} frames at {fps:g} frames/s; display gain {gain:g} "
                            "(1: the processed pictures as they are)"), gain=gain)
                    video.append(picture)
                    if crops:  # the worst flickering pixels, close up: the raw codes, each pixel its own
                        if crop_video is None:
                            crop_scale = crop_gain(raw, crops, transfer.black_level_dn)
                            video_info["rts_crops_scale"] = crop_scale
                            crop_video = VideoWriter(tmp / "rts_crops.mp4", fps, comment=(
                                f"cmosnoise {config.seed}: the {len(crops)} largest random telegraph pixels (outlined "
                                f"in red), {2 * CROP_HALF} raw pixels around each, {CROP_ZOOM} times; grey = "
                                f"(code - black) x {crop_scale:.4g}"))
                        crop_video.append(crop_strip(raw, crops, transfer.black_level_dn, crop_scale))
                    if k == first:
                        rendered0.append(picture)  # frame 0's processed picture, reused below
                    t_process += time.perf_counter() - tp
                advance()
                stamps.append(time.perf_counter())
                yield raw

        meta = run_metadata(sensor)
        phase("frames")
        cm = progress(n) if progress else contextlib.nullcontext(lambda: None)
        dtype = "uint16" if config.adc.enabled else "float32"
        try:  # each frame written from the writer's thread while the next is made
            offset = create_raw_tiff(tmp / "raw.tiff", n, sensor.shape, meta, dtype)
            with SeriesWriter(tmp / "raw.tiff", offset, sensor.shape, dtype) as out, cm as advance:
                for raw in frames(advance):
                    out.write(raw)
        finally:
            if video is not None:
                video.close()
            if crop_video is not None:
                crop_video.close()
        if video_info is not None and crops:
            video_info["rts_crops"] = crops
        t_frames = time.perf_counter() - t_start


        phase("summary")
        job = aside.submit(pictures)  # while this thread builds the summary (not in the loop: it took the kernel's cores)
        (tmp / "config.yaml").write_text(config.to_yaml())
        t0 = time.perf_counter()
        summary = build_summary(sensor, shot, stats, t_frames, n, frame0[1], prepared.result())
        t_summary = time.perf_counter() - t0  # the summary's own time counts in the run's total
        summary["timings_s"]["summary"] = round(t_summary, 6)
        # The steady time per frame is the median of the frames after frame 0, and what the frames took beyond
        # it counts as set-up (frame 0's wait for the compiled kernel, a frame that waited for the machine). A run
        # that compiled the kernel (a machine's first) has none to give (None): the summary figures' loops then
        # compile beside its frames, under the launch lock, and two of the four frames after frame 0 of a 640 x
        # 480 run waited 1.1 and 2.5 s for them (measured; a frame takes 5 ms)
        steady = _steady_frame_s(stamps, n, bool(sensor.timings.get("kernel_compile")))
        summary["timings_s"]["frame_s"] = None if steady is None else round(steady, 6)
        summary["timings_s"]["set_up"] = round(max(t_frames - n * (steady or 0.0), 0.0), 6)
        t0 = time.perf_counter()
        pre_view, processed, t = job.result()
        t_pictures = time.perf_counter() - t0  # what frame 0's pictures took beyond the summary beside them
        t_process += t
        summary["timings_s"]["pictures_after_summary"] = round(t_pictures, 6)
        # everything from the set-up to the last output but the report: set-up, frames, summary and pictures
        summary["timings_s"]["total"] = round(t_frames + t_summary + t_pictures, 6)
        summary["processing"] = processing_summary(processor, t_dark, t_process)
        if proc_cfg.enabled:  # what the chain leaves of the defects in the first frame (the paper's Fig. 9 count)
            summary["processing"]["left"] = white_pixels.left_after_correction(
                _corrected(processor, frame0[0], cfa0), shot.photo_mean_e, transfer.gain_dn_per_e, sensor.cfa)
        if video_info is not None:
            summary["processing"]["video"] = video_info
        rts = telegraph_pixels(sensor)
        if rts is not None:  # where the flickering pixels are: every one, beside the summary's worst few
            rts.to_csv(tmp / "rts_pixels.csv", index=False, float_format="%.17g")  # every digit, whatever prints
        write_json(tmp / "summary.json", summary)
        if config.run.report:
            from . import report

            phase("report")
            (tmp / "report.html").write_text(report.build(sensor, summary, frame0[0], processor, pre_view, processed))
    return summary


def _checked(config: SensorSpec | Config, device: str, tile: int | None) -> tuple[SensorSpec, int | None]:
    """A run's configuration resolved and checked before anything is drawn or written: a file scene recorded by
    its absolute path (config.yaml reruns from anywhere) and refused if bad, the DNG's ADC, the device, the tile
    and the memory the run needs."""
    spec = resolve(config)
    source = spec.config.scene.source
    if Path(source).is_file():
        scene_mod.check_file(source)  # a bad scene file is refused before the sensor is set up
        spec = spec.with_config(merge_updates(spec.config, {"scene": {"source": str(Path(source).resolve())}}))
    config = spec.config
    if config.run.dng and not config.adc.enabled:
        raise CmosnoiseError("run.dng = true needs adc.enabled = true: a DNG holds integer raw codes, not electrons")
    check_device(device)
    if tile is None:
        footprint.check_fits(config)
        return spec, None
    from . import tiled

    tile = tiles.check_size(tile)
    if device != "cpu":
        raise CmosnoiseError(f"--device {device} with --tile: tiles are made by the CPU kernel (the GPU makes "
                             "whole frames, or crops of one exposure)")
    tiled.check(config)
    tiled.check_fits(config, tile)
    return spec, tile


def _steady_frame_s(stamps: list[float], n: int, compiled_here: bool) -> float | None:
    """The steady time per frame: the median of the frames after frame 0 (what the frames took beyond it is
    set-up), None for a run that compiled the kernel (the summary figures' loops then compile beside its
    frames, under the launch lock)."""
    if compiled_here:
        return None
    if n > 1:
        return float(np.median(np.diff(stamps[1:])))
    return stamps[-1] - stamps[0]


def processing_summary(processor: Processor, t_dark: float, t_process: float) -> dict:
    s = processor.settings
    out = {
        "enabled": s.enabled,
        "dark_frames": s.dark_frames,
        "defects": s.defects.method,
        **({"corrector": s.defects.corrector} if s.defects.corrector else {}),
        "crosstalk_compensation": s.crosstalk_compensation and processor.mixing is not None,
        "white_balance": s.white_balance.mode,
        "demosaic": s.demosaic,
        "dark_calibration_s": round(t_dark, 6),
        "processing_s": round(t_process, 6),
    }
    if processor.mixing is not None:
        out["crosstalk_mixing_matrix"] = processor.mixing.round(6).tolist()
    if processor.defect_map is not None:
        out["defect_map_pixels"] = int(processor.defect_map.sum())
    if s.enabled and s.dark_frames == 0 and s.defects.method == "off":
        out["note"] = ("processed.png equals preview.png: no step beyond the preview's is on "
                       "(add --dark-frames N or set processing.defects.method)")
    return out


def video_rate(video_fps: float | None, frame_period_s: float) -> float:
    """processed.mp4's frames per second: ``video_fps`` where set, else the sensor's own rate (1 / its frame
    period), kept within 1 to 240 (what players show)."""
    if video_fps is not None:
        return float(video_fps)
    return float(min(240.0, max(1.0, 1.0 / frame_period_s)))


def display_gain(picture: np.ndarray) -> float:
    """The display stretch of a dark scene's video: the gain that lifts the 99.5th percentile of ``picture`` (8-bit)
    to 235 where it is below 128 (mid-grey), at most 16; 1 for a scene bright enough to be seen as it is."""
    top = float(np.percentile(picture, 99.5))
    if top >= 128:
        return 1.0
    return round(min(16.0, 235.0 / max(top, 1.0)), 3)


#: rts_crops.mp4: how many random telegraph pixels, the pixels on each side of each, and the magnification
CROP_COUNT, CROP_HALF, CROP_ZOOM = 4, 16, 8


def worst_telegraph(sensor: Sensor, count: int = CROP_COUNT) -> list[dict]:
    """The ``count`` random telegraph pixels with the largest steps in electrons a frame: a trap's amplitude
    (e-), a blinking pixel's rate step times the integration time; each with ``kind``, ``row``, ``col``,
    ``step_e``, and the crop (row0, row1, col0, col1) of :data:`CROP_HALF` pixels on each side, inside the
    sensor. Empty without random telegraph noise."""
    table = telegraph_pixels(sensor)
    if table is None or table.empty:
        return []
    t = sensor.config.exposure.integration_time_s
    step = np.where(table["kind"] == "trap", table["size"], table["size"] * t)
    rows, cols = sensor.shape
    out, seen = [], set()
    for i in np.argsort(-step, kind="stable"):
        r, c = int(table["row"].iloc[i]), int(table["col"].iloc[i])
        if (r, c) in seen:
            continue
        seen.add((r, c))
        r0 = min(max(r - CROP_HALF, 0), max(rows - 2 * CROP_HALF, 0))
        c0 = min(max(c - CROP_HALF, 0), max(cols - 2 * CROP_HALF, 0))
        out.append({"kind": str(table["kind"].iloc[i]), "row": r, "col": c, "step_e": float(step[i]),
                    "crop": [r0, min(r0 + 2 * CROP_HALF, rows), c0, min(c0 + 2 * CROP_HALF, cols)]})
        if len(out) == count:
            break
    return out


def crop_gain(raw: np.ndarray, crops: list[dict], black: float) -> float:
    """The grey scale of rts_crops.mp4: frame 0's 99.5th percentile above black, over every crop, shown at 235
    (the same for every frame, so a pixel that flickers is seen to)."""
    values = np.concatenate([raw[a:b, c:d].ravel() for a, b, c, d in (cr["crop"] for cr in crops)]).astype(np.float64)
    top = float(np.percentile(values - black, 99.5))
    return 235.0 / top if top > 0 else 1.0


def crop_strip(raw: np.ndarray, crops: list[dict], black: float, scale: float) -> np.ndarray:
    """The crops of a raw frame side by side as grey (each pixel its own code: no demosaicing spreads a flicker),
    each :data:`CROP_ZOOM` times, its telegraph pixel outlined in red, 2 black pixels apart: (h, w, 3) uint8."""
    tiles = []
    side = 2 * CROP_HALF
    for crop in crops:
        r0, r1, c0, c1 = crop["crop"]
        part = np.zeros((side, side), np.float64)
        got = raw[r0:r1, c0:c1].astype(np.float64) - black
        part[:got.shape[0], :got.shape[1]] = got
        grey = np.clip(np.rint(part * scale), 0, 255).astype(np.uint8)
        big = np.repeat(np.repeat(grey, CROP_ZOOM, axis=0), CROP_ZOOM, axis=1)
        rgb = np.repeat(big[..., None], 3, axis=2)
        y, x = (crop["row"] - r0) * CROP_ZOOM, (crop["col"] - c0) * CROP_ZOOM
        for edge in (rgb[y - 1:y, x - 1:x + CROP_ZOOM + 1], rgb[y + CROP_ZOOM:y + CROP_ZOOM + 1, x - 1:x + CROP_ZOOM + 1],
                     rgb[y - 1:y + CROP_ZOOM + 1, x - 1:x], rgb[y - 1:y + CROP_ZOOM + 1, x + CROP_ZOOM:x + CROP_ZOOM + 1]):
            edge[...] = (255, 40, 40)
        tiles += [rgb, np.zeros((rgb.shape[0], 2, 3), np.uint8)]
    return np.concatenate(tiles[:-1], axis=1)


def telegraph_pixels(sensor: Sensor):
    """Every random telegraph pixel of ``sensor``, as a pandas DataFrame (None with both stages off): ``kind``
    (trap: the source follower's, through CDS; blinking: dark current), ``row``, ``col``, ``slot`` (the trap's
    number in its pixel), ``size`` (e- for a trap, e-/s for a blinking pixel), ``tau_low_s``, ``tau_high_s``."""
    import pandas as pd

    fp, cols = sensor.fixed_pattern, sensor.shape[1]
    parts = []
    for kind, pop in (("trap", fp.traps if sensor.config.source_follower.enabled else None), ("blinking", fp.blinkers)):
        if pop is None:
            continue
        index = pop.index.astype(np.int64)
        parts.append(pd.DataFrame({"kind": kind, "row": index // cols, "col": index % cols,
                                   "slot": pop.slot.astype(np.int64), "size": pop.size, "tau_low_s": pop.tau_low_s,
                                   "tau_high_s": pop.tau_high_s}))
    return pd.concat(parts, ignore_index=True) if parts else None


def output_bytes(config) -> int:
    """Bytes a run writes, estimated: the raw frames (uint16, or float32 electrons without the ADC), their DNG
    copies, a master dark, and 64 kB plus 4 bytes a pixel for the pictures and the rest."""
    pixels = config.sensor.width * config.sensor.height
    per_frame = pixels * (2 if config.adc.enabled else 4) * (2 if config.run.dng else 1)
    extra = pixels * 4 * (1 + (config.processing.dark_frames > 0) + config.processing.enabled)
    return config.run.frames * per_frame + extra + 65536


def process_file(raw_path, settings: ProcessingSection, out, dark_path=None, overrides: dict | None = None,
                 overwrite: bool = False) -> dict:
    """Process a raw TIFF into ``out``: processed.png (frame 0), processed.mp4 (several frames), summary.json.

    The frames are read one at a time (a stack of any length fits in
    memory); the file's metadata is validated with the configuration's
    schema; a master dark must be finite codes within the raw's range.
    """
    import time

    name = str(raw_path)
    with RawTiffReader(raw_path) as reader:
        meta = {**reader.meta, **(overrides or {})}
        info = _raw_info(meta, name)
        master = read_dark(dark_path) if dark_path is not None else None
        if master is not None and (float(master.min()) < 0 or float(master.max()) > info.white_level_dn):
            raise CmosnoiseError(f"dark file {str(dark_path)!r}: values from {float(master.min()):g} to {float(master.max()):g} DN "
                                 f"are not raw codes of {info.bits} bits (0 to {info.white_level_dn})")
        processor = Processor(settings, info, master)
        processor.check_shape(reader.shape)
        folder = OutputFolder(out, overwrite)
        with folder as tmp:
            t0 = time.perf_counter()
            # a raw file records no frame rate: 10 frames/s unless processing.video_fps says
            video = VideoWriter(tmp / "processed.mp4", settings.video_fps or 10.0) if len(reader) > 1 else None
            try:
                for k, frame in enumerate(reader):
                    if int(frame.max()) > info.white_level_dn:
                        raise CmosnoiseError(f"raw file {name!r}, frame {k}: codes up to {int(frame.max())} do not fit "
                                             f"{info.bits} bits; give --bits")
                    picture = processor.render(frame)
                    if k == 0:
                        write_png(tmp / "processed.png", picture)
                        write_png(tmp / "preview.png", processor.render(frame, pre=True))
                    if video is not None:
                        video.append(picture)
            finally:
                if video is not None:
                    video.close()
            elapsed = time.perf_counter() - t0
            result = {
                "raw": name, "frames": len(reader), "rows": int(reader.shape[0]), "cols": int(reader.shape[1]),
                "cfa": info.cfa, "black_level_dn": info.black_level_dn, "bits": info.bits,
                "dark": None if dark_path is None else str(dark_path),
                "settings": settings.model_dump(mode="json"),
                "ms_per_frame": 1000 * elapsed / (len(reader) + 1),
            }
            write_json(tmp / "summary.json", result)
    return result


def _raw_info(meta: dict, name: str) -> RawInfo:
    """The processing's view of a raw file's metadata, validated with the configuration's schema."""
    missing = [k for k in ("cfa", "black_level_dn", "bits") if k not in meta]
    if missing:
        flags = {"cfa": "--cfa", "black_level_dn": "--black-level", "bits": "--bits"}
        raise CmosnoiseError(f"raw file {name!r} does not record {', '.join(missing)}; give {', '.join(flags[m] for m in missing)}")
    sensor = {"cfa": meta["cfa"]}
    if "channel_responsivity" in meta:
        sensor["channel_responsivity"] = meta["channel_responsivity"]
    data = {"sensor": sensor, "adc": {"bits": meta["bits"], "black_level_dn": meta["black_level_dn"]}}
    if meta.get("crosstalk_kernel_pct") is not None:
        data["crosstalk"] = {"kernel_pct": meta["crosstalk_kernel_pct"]}
    if meta.get("scene_white_dn") is not None:
        data["processing"] = {"white_dn": meta["scene_white_dn"]}
    try:
        cfg = load_config(extra=data)
    except CmosnoiseError as exc:
        raise CmosnoiseError(f"raw file {name!r}: its metadata is not valid: "
                             f"{str(exc).removeprefix('invalid configuration: ')}") from None
    return RawInfo.from_metadata({
        "cfa": cfg.sensor.cfa, "black_level_dn": cfg.adc.black_level_dn, "bits": cfg.adc.bits,
        "scene_white_dn": cfg.processing.white_dn, "channel_responsivity": cfg.sensor.channel_responsivity,
        "crosstalk_kernel_pct": cfg.crosstalk.kernel_pct if "crosstalk" in data else None,
    })
