"""The ``cmosnoise`` command line (Typer)."""

from __future__ import annotations

import contextlib
import logging
import math
import os
import re
import signal
import sys
import threading
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from ..config import load_config, preset_data, preset_names
from ..errors import (
    CmosnoiseError,
    Terminated,
    check_terminated,
    command_over,
    command_started,
    signal_received,
    written,
    written_note,
)

if TYPE_CHECKING:
    from ..model.spec import SensorSpec


def _sensor(config: Path | None, preset: str | None, overrides: list[str] | None, extra: dict | None = None) -> SensorSpec:
    """The resolved sensor of the command line's --config, --preset, --set and options (physics checked).

    The model is imported here, not with the module: ``cmosnoise --help`` and the parsing of every command
    do without it (and without scipy.special, a fifth of a second)."""
    from ..model.spec import resolve

    notes: list[str] = []
    spec = resolve(load_config(config, preset, overrides, extra, notes))
    for line in notes:  # settings that do nothing, or a section switched on: one line each, on stderr
        err_console.print(f"cmosnoise: note: {line}", highlight=False, markup=False, soft_wrap=True)
    return spec


app = typer.Typer(
    help="Simulate CMOS image-sensor noise (Gow et al. model) and see what it does to pictures.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    # click's own help layout: option names whole at any width (rich's table cut them at 80 columns), flags
    # without a metavar, a value's type in capitals
    rich_markup_mode=None,
)
err_console = Console(stderr=True)


_WHITE_UNITS = {"": "e_per_s", "e-/s": "e_per_s", "e/s": "e_per_s", "aa": "aA"}


def _white_threshold(text: str) -> tuple[float, str]:
    """``--white-threshold``: (value, unit of a ``dark_current.white_threshold_*`` key) from a number of e-/s or a
    number with its unit (``1560e-/s``, ``250aA``)."""
    m = re.fullmatch(r"\s*([-+]?[0-9.]+(?:[eE][-+]?\d+)?)\s*(e-/s|e/s|aA|aa|AA)?\s*", text)
    unit = _WHITE_UNITS.get((m.group(2) or "").lower()) if m else None
    try:
        value = float(m.group(1)) if m else math.nan
    except ValueError:
        value = math.nan
    if unit is None or not (math.isfinite(value) and value >= 0):
        raise CmosnoiseError(f"--white-threshold {text!r}: give a dark current of 0 or more in e-/s or aA, e.g. "
                             "1560 (e-/s), 1560e-/s or 250aA")
    return value, unit


def _white_e_per_s(text: str | None) -> float | None:
    """``--white-threshold`` in e-/s (None without one)."""
    if text is None:
        return None
    from ..model.units import aa_to_e_per_s

    value, unit = _white_threshold(text)
    return aa_to_e_per_s(value) if unit == "aA" else value


def white_threshold_set(text: str | None) -> list[str]:
    """``--white-threshold`` as a ``--set`` of ``dark_current.white_threshold_e_per_s`` or ``..._aA`` (none without
    one)."""
    if text is None:
        return []
    value, unit = _white_threshold(text)
    return [f"dark_current.white_threshold_{unit}={value!r}"]


def _version(value: bool):
    if value:
        from .._version import __version__
        from ..engine.frame.kernel import generator_info

        g = generator_info()
        typer.echo(f"cmosnoise {__version__} (random-number scheme {g['scheme_version']}, numpy {g['numpy']}, "
                   f"numba {g['numba']}, frame kernel: {g['frame_kernel']})")
        raise typer.Exit()


@app.callback()
def _options(
    ctx: typer.Context,
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="print the version and exit"),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="print nothing but errors (no summary line, no progress bars)"),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="also print the output files and where the time went"),
):
    """Simulate CMOS image-sensor noise (Gow et al. model) and see what it does to pictures."""
    ctx.obj = {"verbosity": -1 if quiet else (1 if verbose else 0)}


def _level(ctx: typer.Context) -> int:
    """-1 (-q), 0 or 1 (-v): set by the app's options; a command's context inherits ``obj`` from it."""
    return ctx.obj.get("verbosity", 0) if isinstance(ctx.obj, dict) else 0


def _say(ctx: typer.Context, text: str, level: int = 0) -> None:
    """Print ``text`` if the verbosity (-q: -1, default 0, -v: 1) reaches ``level``."""
    if _level(ctx) >= level:
        typer.echo(text)


#: one's own defect corrector for the processing chain (simulate --process, process)
CorrectorOpt = typer.Option(None, "--corrector", help="your own defect corrector, module:function (raw DN in, raw "
                                                     "DN out, as evaluate --method takes it), run after "
                                                     "processing.defects.method; sets processing.defects.corrector")


def _run_overrides(scene, frames, first_frame, seed, process=None, dark_frames=None, formats=None, report=False,
                   corrector=None) -> dict:
    extra: dict = {}
    if corrector is not None:
        extra.setdefault("processing", {}).setdefault("defects", {})["corrector"] = corrector
        extra["processing"]["enabled"] = True  # a corrector is asked for to be used: as --process
    if report:
        extra.setdefault("run", {})["report"] = True
    if process:
        extra.setdefault("processing", {})["enabled"] = True
    if dark_frames is not None:
        extra.setdefault("processing", {})["dark_frames"] = dark_frames
        if dark_frames > 0:
            extra["processing"]["enabled"] = True
    for f in formats or []:
        if f.lower() not in ("tiff", "dng"):
            raise CmosnoiseError(f"--format {f!r}: use tiff (always written) or dng")
        if f.lower() == "dng":
            extra.setdefault("run", {})["dng"] = True
    if scene is not None:
        extra.setdefault("scene", {})["source"] = scene
    if frames is not None:
        extra.setdefault("run", {})["frames"] = frames
    if first_frame is not None:
        extra.setdefault("run", {})["first_frame"] = first_frame
    if seed is not None:
        extra["seed"] = seed
    return extra


@contextlib.contextmanager
def _counting(ctx: typer.Context, label: str, unit: str = ""):
    """A progress bar on stderr (a terminal, not -q) for a job that reports ``progress(done, total)``: yields that
    callback."""
    columns = [TextColumn(f"[bold]{label}"), BarColumn(), MofNCompleteColumn(), *([TextColumn(unit)] if unit else []),
               TimeRemainingColumn()]
    with Progress(*columns, console=err_console, disable=not (err_console.is_terminal and _level(ctx) >= 0)) as bar:
        task = bar.add_task(label, total=None)
        yield lambda done, total: bar.update(task, completed=done, total=total)


def _speed(timings: dict, pixels: int | None = None) -> str:
    """A run's time per frame and its set-up, as simulate's line says them (a tiled run: its time per pixel,
    ``pixels`` a frame's)."""
    if pixels is not None:  # tiles: set-up and frames overlap on two threads, so only the wall time says it
        return f"{timings['total']:.1f} s in all, {1e9 * timings['total'] / pixels / max(timings['frames'], 1):.1f} ns/pixel"
    if timings["frame_s"] is None:  # a run that compiled the kernel (a machine's first): no frame of it is steady
        return (f"{timings['set_up']:.1f} s, the frame kernel's compile ({timings['stages']['kernel_compile']:.0f} s) "
                "included: run again (with --overwrite, or another --out) for the time per frame")
    return f"{timings['frame_s'] * 1000:.1f} ms/frame after {timings['set_up']:.2f} s of set-up"


@contextlib.contextmanager
def _status(ctx: typer.Context):
    """A spinner on stderr (a terminal, not -q) that shows what a long job does now: yields ``(phase(text),
    say(line))``; a line said clears the spinner first, so the two never share a line."""
    if not (err_console.is_terminal and _level(ctx) >= 0):
        yield (lambda text: None), (lambda line: _say(ctx, line))
        return
    with err_console.status("") as status:
        def say(line: str) -> None:
            status.stop()
            _say(ctx, line)
            status.start()

        yield (lambda text: status.update(f"[bold]{text}")), say


def _progress_factory(enabled: bool | None, pixels: int, unit: str = "frames"):
    def factory(n: int):
        show = enabled if enabled is not None else (err_console.is_terminal and n * pixels >= 5_000_000)
        if not show:
            return contextlib.nullcontext(lambda: None)

        @contextlib.contextmanager
        def cm():
            with Progress(
                TextColumn("[bold]simulating"), BarColumn(), MofNCompleteColumn(), TextColumn(unit),
                TimeRemainingColumn(), console=err_console, transient=False,
            ) as p:
                task = p.add_task("frames", total=n)
                yield lambda: p.advance(task)

        return cm()

    return factory


ConfigOpt = typer.Option(None, "--config", "-c", help="YAML configuration file")
PresetOpt = typer.Option(None, "--preset", "-p", help="start from a preset (see `cmosnoise presets`)")
SetOpt = typer.Option(None, "--set", "-s", help="override one key, e.g. --set prnu.sigma_pct=2 (repeatable)")
DeviceOpt = typer.Option("cpu", "--device", help="where frames are made: cpu, or cuda (an NVIDIA GPU: pip install "
                         "'cmosnoise[cuda]'); the same bits")
WhiteThresholdOpt = typer.Option(None, "--white-threshold", help="count white pixels above this dark current at "
                                 "every temperature: e-/s, or with its unit, e.g. 1560e-/s or 250aA (default: the "
                                 "nearest characterization point's tail threshold)")
OverwriteOpt = typer.Option(False, "--overwrite", help="replace an existing non-empty output folder as a whole (else refused)")


@app.command()
def simulate(
    ctx: typer.Context,
    config: Path | None = ConfigOpt,
    preset: str | None = PresetOpt,
    scene: str | None = typer.Option(None, "--scene", help="photo, flat:LEVEL, ramp, colorchecker, zoneplate, siemens, or an image path"),
    frames: int | None = typer.Option(None, "--frames", "-n", help="number of frames"),
    first_frame: int | None = typer.Option(None, "--first-frame", help="index of the first frame"),
    seed: int | None = typer.Option(None, "--seed", help="sensor instance seed"),
    set_: list[str] | None = SetOpt,
    out: Path = typer.Option(Path("cmosnoise-out"), "--out", "-o", help="output folder"),
    process: bool = typer.Option(False, "--process", help="also write processed.png (and processed.mp4) through the processing chain"),
    dark_frames: int | None = typer.Option(None, "--dark-frames", help="dark calibration: make a master dark from N dark frames"),
    corrector: str | None = CorrectorOpt,
    format_: list[str] | None = typer.Option(None, "--format", help="extra raw format: dng (raw.tiff is always written)"),
    report: bool = typer.Option(False, "--report", help="also write report.html (self-contained run report)"),
    progress: bool | None = typer.Option(None, "--progress/--no-progress", help="progress bar (default: on a terminal, for long runs)"),
    white_threshold: str | None = WhiteThresholdOpt,
    device: str = DeviceOpt,
    tile: int | None = typer.Option(None, "--tile", help="make the sensor tile by tile, SIZE pixels a side (a "
                                       "multiple of 16, e.g. 2048): memory bounded by a few tiles, raw.tiff tiled, "
                                       "the same bits; for sensors too large to hold whole"),
    scheduler: str | None = typer.Option(None, "--scheduler", help="with --tile: make the tiles on an existing "
                                            "Dask scheduler, e.g. tcp://host:8786"),
    workers: int | None = typer.Option(None, "--workers", min=1, max=1024, help="with --tile: make the tiles on "
                                          "a LocalCluster of this many worker processes"),
    overwrite: bool = OverwriteOpt,
):
    """Simulate raw frames of a scene; write raw.tiff, config.yaml, summary.json and preview.png."""
    from .run import simulate as run_simulate

    spec = _sensor(config, preset, [*(set_ or []), *white_threshold_set(white_threshold)], _run_overrides(scene, frames, first_frame, seed, process, dark_frames, format_, report,
                                                 corrector))
    cfg = spec.config
    if _level(ctx) < 0:
        progress = False
    show = progress if progress is not None else (err_console.is_terminal
                                                  and cfg.run.frames * cfg.sensor.width * cfg.sensor.height >= 5_000_000)
    status = err_console.status("") if show else None
    if (scheduler or workers) and tile is None:
        raise CmosnoiseError("--scheduler and --workers make a run's tiles on Dask: give --tile SIZE too")
    texts = {"set-up": "drawing the fixed pattern" + (" (the sparse populations, for every tile)" if tile else ""),
             "scene": "rendering the scene and its mean charge",
             "dark": f"averaging {cfg.processing.dark_frames} dark frames into a master dark",
             "summary": "writing preview.png and measuring the summary (noise budget, white pixels)",
             "report": "writing report.html"}

    def phase(name: str) -> None:  # a spinner for what comes before and after the frames' progress bar
        if status is None:
            return
        if name == "frames":  # the frames' own progress bar takes over
            status.stop()
            return
        status.update(f"[bold]{texts.get(name, name)}")
        status.start()

    client = cluster = None
    try:
        if scheduler or workers:
            from .cluster import connect

            client, cluster = connect(scheduler, workers, lambda m: _say(ctx, m))
        pixels = cfg.sensor.width * cfg.sensor.height
        summary = run_simulate(spec, out, progress=_progress_factory(progress, pixels if tile is None else tile * tile,
                                                                     "tiles" if tile else "frames"),
                               phase=phase, overwrite=overwrite, device=device, tile=tile, client=client)
    finally:
        if status is not None:
            status.stop()
        if client is not None:
            from .cluster import disconnect

            disconnect(client, cluster)
    sig, tn = summary["signal"], summary["temporal_noise"]
    noise = f", temporal noise {tn['rms_e']:.2f} e- ({tn['rms_dn']:.2f} DN)" if tn["rms_e"] is not None else ""
    _say(
        ctx,
        f"wrote {summary['frames']} frame(s) {cfg.sensor.height}x{cfg.sensor.width} {cfg.sensor.cfa} to {out}/ "
        + (f"in {summary['tiles']['count']} tiles of {summary['tiles']['size']} " if "tiles" in summary else "")
        + f"(mean {sig['mean_e']:.1f} e-, {sig['mean_dn']:.1f} DN{noise}; "
        f"{_speed(summary['timings_s'], pixels if 'tiles' in summary else None)})"
    )
    if "tiles" in summary:
        _say(ctx, "not made in tiles: " + ", ".join(summary["tiles"]["not_made"]) + " (they need the whole frame)")
    dc = summary.get("dark_current") or {}
    if "map" in dc:
        _say(ctx, f"white pixels: {dc['map']['white_pixels']} in the dark-current map ({dc['map']['ppm']:.0f} ppm) above "
                  f"{dc['threshold_e_per_s']:.4g} e-/s ({dc['threshold_aA']:.4g} aA), threshold: {dc['threshold_source']}"
                  + ("" if dc["threshold_source"].startswith("fixed") else "; --white-threshold fixes one"))
    for warning in summary.get("warnings", []):
        _say(ctx, f"warning: {warning}")
    if "note" in summary["processing"]:
        _say(ctx, f"note: {summary['processing']['note']}")
    if "left" in summary["processing"]:
        p, left = summary["processing"], summary["processing"]["left"]
        steps = [f"{p['dark_frames']} dark frames" if p["dark_frames"] else "no dark calibration",
                 f"defects {p['defects']}" + (f" and {p['corrector']}" if p.get("corrector") else "")]
        _say(ctx, f"processing left {left['pixels']} pixels more than {left['tolerance_e']:g} e- off the scene in "
                  f"frame {cfg.run.first_frame}, {left['couplets']} couplets among them ({', '.join(steps)})")
    if _level(ctx) >= 1:
        _say(ctx, "files: " + ", ".join(sorted(p.name for p in out.iterdir())))
        t = summary["timings_s"]
        stages = ", ".join(f"{k} {v:.3f} s" for k, v in t["stages"].items())
        _say(ctx, f"time: total {t['total']:.3f} s ({stages}); processing {summary['processing']['processing_s']:.3f} s")
        _say(ctx, f"random numbers: {summary['generator']['scheme']} (version {summary['generator']['scheme_version']})")


@app.command()
def process(
    ctx: typer.Context,
    raw: Path = typer.Argument(..., help="raw frames: a TIFF (frames, rows, cols) or (rows, cols) of uint16 codes"),
    dark: Path | None = typer.Option(None, "--dark", help="dark frames (averaged into a master dark) or a master dark"),
    config: Path | None = ConfigOpt,
    set_: list[str] | None = SetOpt,
    cfa: str | None = typer.Option(None, "--cfa", help="RGGB, BGGR, GRBG, GBRG or none (default: from the file's metadata)"),
    black_level: float | None = typer.Option(None, "--black-level", help="black level, DN (default: from the metadata)"),
    bits: int | None = typer.Option(None, "--bits", help="bit depth (default: from the metadata)"),
    corrector: str | None = CorrectorOpt,
    out: Path = typer.Option(Path("cmosnoise-processed"), "--out", "-o", help="output folder"),
    overwrite: bool = OverwriteOpt,
):
    """Process raw frames that already exist (from cmosnoise or a real camera) into pictures."""
    from .run import process_file

    cfg = load_config(config, None, set_, extra=_run_overrides(None, None, None, None, corrector=corrector) or None)
    if cfa is not None:
        cfa = "none" if cfa.lower() == "none" else cfa.upper()
    overrides = {k: v for k, v in {"cfa": cfa, "black_level_dn": black_level, "bits": bits}.items() if v is not None}
    result = process_file(raw, cfg.processing, out, dark, overrides, overwrite)
    _say(ctx, f"processed {result['frames']} frame(s) {result['rows']}x{result['cols']} {result['cfa']} into {out}/ "
               f"({result['ms_per_frame']:.0f} ms/frame)")


@app.command()
def characterize(
    ctx: typer.Context,
    config: Path | None = ConfigOpt,
    preset: str | None = PresetOpt,
    set_: list[str] | None = SetOpt,
    seed: int | None = typer.Option(None, "--seed", help="sensor instance seed"),
    steps: int = typer.Option(40, "--steps", min=8, max=1000, help="exposure times in the photon-transfer series"),
    stack_frames: int = typer.Option(16, "--stack-frames", min=2, max=10000, help="frames per stack for DSNU and PRNU"),
    emva_export: Path | None = typer.Option(None, "--emva-export", help="also write the frames and an EMVA 1288 descriptor here"),
    frames_from: Path | None = typer.Option(None, "--frames-from", help="characterize frames from an EMVA 1288 descriptor (folder or file) instead"),
    like: Path | None = typer.Option(None, "--like", help="measure the configuration with the exposure times, photons "
                                        "and stack sizes of this EMVA 1288 data set (folder or descriptor), for a "
                                        "side-by-side comparison with it"),
    dark_exposures: str = typer.Option("auto", "--dark-exposures", help="a dark-current series' exposure times, s, "
                                       "comma-separated (e.g. 60,120,300,600); 'auto': long enough to resolve the "
                                       "configured dark current (none where the photon-transfer series does); "
                                       "'none': no series"),
    out: Path = typer.Option(Path("cmosnoise-characterization"), "--out", "-o", help="output folder"),
    overwrite: bool = OverwriteOpt,
):
    """EMVA 1288 characterization: measured values next to the values the configuration implies."""
    from rich.table import Table

    from ..analysis.emva_evaluation import TABLE_ROWS, table
    from .characterizing import run as characterize_job

    if like is not None and frames_from is not None:
        raise CmosnoiseError("--like measures a configuration on another data set's plan; --frames-from reads frames "
                             "instead: give one of the two")
    dark = _dark_exposures(dark_exposures)
    if frames_from is not None and dark_exposures != "auto":
        raise CmosnoiseError("--dark-exposures measures a dark series on the configuration; --frames-from reads "
                             "frames instead: give one of the two")
    spec = None
    if frames_from is None or config or preset or set_:
        spec = _sensor(config, preset, set_, {"seed": seed} if seed is not None else None)
    with Progress(TextColumn("[bold]measuring"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                  console=err_console, disable=not err_console.is_terminal or _level(ctx) < 0) as p:
        def progress(total: int):
            task = p.add_task("series", total=total)
            return lambda: p.advance(task)

        done = characterize_job(spec, out, overwrite, frames_from, steps, stack_frames, emva_export, progress, like,
                                dark)
    results, model, reference = done["measured"], done["model"], done["reference"]
    tab = Table(title="EMVA 1288 characterization" + (" (measured vs. the configuration)" if model else ""))
    cols = ["quantity", "unit", "measured", "model", "deviation %"] + (["emva1288"] if reference else [])
    for col in cols:
        tab.add_column(col, justify="left" if col == "quantity" else "right")
    for (key, _, _, fmt), row in zip(TABLE_ROWS, table(results, model)):
        ref = [fmt.format(reference[key]) if reference and key in reference else ""] if reference else []
        tab.add_row(*row, *ref)
    if _level(ctx) >= 0:
        Console().print(tab)
        for line in done["notes"]:
            typer.echo(f"  {line}")
        if reference:
            missing = [label.strip() for key, label, _, _ in TABLE_ROWS
                       if key in reference and not math.isfinite(reference[key])]
            if missing:
                typer.echo(f"  emva1288 gave no value (nan) for: {', '.join(missing)}")
    spectra = ", noise_spectra.png" if (Path(out) / "noise_spectra.png").exists() else ""
    _say(ctx, f"wrote characterization.json, photon_transfer.png, snr.png{spectra} to {out}/"
               + (f"; EMVA 1288 data set to {emva_export}/" if emva_export else ""))


def _dark_exposures(text: str):
    """--dark-exposures: "auto", "none" (None) or the exposure times, s."""
    word = text.strip().lower()
    if word in ("auto", "none"):
        return None if word == "none" else "auto"
    try:
        times = [float(part) for part in word.split(",") if part.strip()]
    except ValueError:
        times = []
    if len(times) < 3 or any(not (math.isfinite(t) and t > 0) for t in times) or len(set(times)) < len(times):
        raise CmosnoiseError(f"--dark-exposures {text!r}: expected 'auto', 'none' or 3 or more different exposure "
                             "times in seconds, each > 0, comma-separated (e.g. 60,120,300,600)")
    return times


@app.command()
def figures(
    ctx: typer.Context,
    out: Path = typer.Option(Path("cmosnoise-figures"), "--out", "-o", help="output folder"),
    seed: int = typer.Option(0, "--seed", help="sensor instance seed"),
    overwrite: bool = OverwriteOpt,
):
    """Regenerate the paper's figures (3, 5, 6, 7, 9, 10, 11) as PNGs with an index.html gallery."""
    from ..io.output import OutputFolder
    from .figures import write_gallery

    with OutputFolder(out, overwrite) as tmp, Progress(
            TextColumn("[bold]figure"), TextColumn("{task.description}"), console=err_console,
            disable=not err_console.is_terminal or _level(ctx) < 0) as p:
            task = p.add_task("", total=None)
            items = write_gallery(tmp, seed, progress=lambda name: p.update(task, description=name))
    _say(ctx, f"wrote {len(items)} figures and index.html to {out}/")


@app.command()
def explore(
    config: Path | None = ConfigOpt,
    preset: str | None = PresetOpt,
    set_: list[str] | None = SetOpt,
    scene: str | None = typer.Option(None, "--scene", help="start scene: a built-in name or an image file"),
    port: int = typer.Option(8765, "--port", min=1, max=65535, help="TCP port"),
    host: str = typer.Option("127.0.0.1", "--host", help="address to listen on (default loopback only; another is reachable by others)"),
    no_browser: bool = typer.Option(False, "--no-browser", help="do not open the page in a browser"),
    white_threshold: str | None = WhiteThresholdOpt,
):
    """A local web page: two sensors side by side, every parameter, the picture follows at once."""
    import socket

    from .explore import serve

    cfg = _sensor(config, preset, [*(set_ or []), *white_threshold_set(white_threshold)]).config
    try:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.bind((host, port))
    except OSError as exc:
        raise CmosnoiseError(f"--host {host} --port {port} cannot be used: {exc.strerror or exc} (another server on it? "
                             "give --port)") from None
    serve(cfg, scene, host, port, not no_browser, say=lambda m: typer.echo(m, err=True))


@app.command()
def sweep(
    ctx: typer.Context,
    config: Path | None = ConfigOpt,
    preset: str | None = PresetOpt,
    set_: list[str] | None = SetOpt,
    scene: str | None = typer.Option(None, "--scene", help="scene of every instance (default: the configuration's)"),
    vary: list[str] | None = typer.Option(None, "--vary", help="KEY=v1,v2 | KEY=start:stop:count | K1,K2=a1xb1,a2xb2 (repeatable: the grid is their product)"),
    instances: int = typer.Option(20, "--instances", min=1, max=1_000_000, help="sensor instances (dies) per point"),
    frames: int = typer.Option(2, "--frames", min=1, max=100, help="frames per instance (2: temporal noise from their difference)"),
    spec: list[str] | None = typer.Option(None, "--spec", help="pass/fail per instance, e.g. couplets_after_correction<=0 (repeatable: all must hold)"),
    metric: list[str] | None = typer.Option(None, "--metric", help="plot only these metrics (repeatable; every metric is in results.csv)"),
    quality_lux: float | None = typer.Option(None, "--quality-lux", help="also measure each instance's image "
                                             "quality (visual noise, banding in JND, SNR, MTF, colour error: "
                                             "`cmosnoise quality`'s metrics) through the charts at this "
                                             "illuminance, lux; --spec and --metric take them"),
    scheduler: str | None = typer.Option(None, "--scheduler", help="an existing Dask scheduler, e.g. tcp://host:8786 (default: a LocalCluster here)"),
    workers: int | None = typer.Option(None, "--workers", min=1, max=1024, help="LocalCluster worker processes (default: the core count)"),
    resume: bool = typer.Option(False, "--resume", help="continue the sweep in --out: skip the rows results.csv already holds"),
    overwrite: bool = OverwriteOpt,
    from_: Path | None = typer.Option(None, "--from", help="rerun a sweep.yaml (its base configuration, grid, instances and spec)"),
    white_threshold: str | None = WhiteThresholdOpt,
    device: str = DeviceOpt,
    out: Path = typer.Option(Path("cmosnoise-sweep"), "--out", "-o", help="output folder"),
):
    """Parameter studies and yield over many sensor instances, on Dask (a LocalCluster, or --scheduler)."""
    from . import sweep as sw

    if from_ is not None:
        try:
            opts = sw.sweep_from_yaml(from_)
        except (OSError, KeyError, TypeError, ValueError) as exc:
            raise CmosnoiseError(f"--from {str(from_)!r} is not a sweep.yaml: {exc}") from None
        base = _sensor(None, None, white_threshold_set(white_threshold), opts["base"]).config  # merged over the defaults, checked
        vary, instances, frames, scene, spec = opts["vary"], opts["instances"], opts["frames"], opts["scene"], opts["specs"]
        quality_lux = opts["quality_lux"] if opts["quality_lux"] is not None else quality_lux
    else:
        base = _sensor(config, preset, [*(set_ or []), *white_threshold_set(white_threshold)]).config
    with _counting(ctx, "sweep") as progress:
        df = sw.run(base, vary or [], instances, out, frames, scene, spec, scheduler, workers, resume, overwrite,
                    progress=progress, say=lambda m: _say(ctx, m), metrics=metric, device=device,
                    quality_lux=quality_lux)
    points = df["point"].nunique()
    msg = f"wrote {len(df)} row(s) ({points} point(s) x {instances} instance(s)) to {out}/results.csv, summary.csv, plots, index.html"
    if "pass" in df:
        msg += f"; overall yield {df['pass'].mean():.3f}"
    _say(ctx, msg)


@app.command()
def compare(
    ctx: typer.Context,
    run_a: Path = typer.Argument(..., help="a cmosnoise simulate output folder"),
    run_b: Path = typer.Argument(..., help="another one"),
    out: Path | None = typer.Option(None, "--out", "-o", help="also write compare.txt, compare.json and "
                                       "compare.html (the previews side by side and their difference) here"),
    instances: int = typer.Option(8, "--instances", help="further instances of each run that "
                                  "measure each figure's sampling error"),
    white_threshold: str | None = typer.Option(None, "--white-threshold", help="count both runs' white pixels "
                                                  "above this dark current: e-/s, or 1560e-/s, 250aA (default: "
                                                  "run A's threshold)"),
    overwrite: bool = OverwriteOpt,
):
    """Two runs side by side: key figures, noise budget and white pixels, each difference against sampling error."""
    from . import compare as cmp

    with _counting(ctx, "compare", "instances") as progress:
        result = cmp.run(run_a, run_b, out, instances, _white_e_per_s(white_threshold), overwrite, progress)
    if _level(ctx) >= 0:
        typer.echo(cmp.text_table(result), nl=False)
    if out is not None:
        _say(ctx, f"wrote compare.txt, compare.json and compare.html to {out}/")


@app.command()
def quality(
    ctx: typer.Context,
    config: Path | None = ConfigOpt,
    preset: str | None = PresetOpt,
    set_: list[str] | None = SetOpt,
    lux: str = typer.Option("1,3,10,30,100,300,1000", "--lux", help="illuminances on the scene, lux, "
                            "comma-separated, increasing"),
    frames: int = typer.Option(8, "--frames", min=2, max=1000, help="frames of each chart at each illuminance"),
    seed: int | None = typer.Option(None, "--seed", help="sensor instance seed (without --compare)"),
    compare_config: Path | None = typer.Option(None, "--compare", help="a second configuration (YAML) to set "
                                                  "beside the first: each difference with its spread over "
                                                  "--instances sensor instances"),
    compare_preset: str | None = typer.Option(None, "--compare-preset", help="the second configuration from a "
                                                 "preset (with --compare-set)"),
    compare_set: list[str] | None = typer.Option(None, "--compare-set", help="the second configuration: the "
                                                    "first with this key changed, e.g. --compare-set "
                                                    "sensor.temperature_c=65 (repeatable)"),
    instances: int = typer.Option(3, "--instances", max=100, help="with a comparison or a search: sensor "
                                  "instances (seeds 0, 1, ...) each spread comes from"),
    find: str | None = typer.Option(None, "--find", help="search instead: the value of one parameter, KEY=LOW:HIGH, "
                                       "at which the --until metric crosses its limit (bisection on each of "
                                       "--instances sensor instances, at the one --lux)"),
    until: str | None = typer.Option(None, "--until", help="with --find: METRIC=LIMIT, e.g. banding_columns=1"),
    picture_height_cm: float = typer.Option(20.0, "--picture-height-cm", help="print viewing: the picture's "
                                            "height, cm"),
    viewing_distance_cm: float = typer.Option(50.0, "--viewing-distance-cm", help="print viewing: the distance, cm"),
    display_pitch_mm: float = typer.Option(0.254, "--display-pixel-pitch-mm", help="display viewing at 100 %: the "
                                           "screen's pixel pitch, mm"),
    display_distance_cm: float = typer.Option(60.0, "--display-distance-cm", help="display viewing: the distance, cm"),
    colour_reference: str = typer.Option("spectral", "--colour-reference", help="what the colour error compares "
                                         "with: spectral (the chart's own spectra under the light) or xrite "
                                         "(X-Rite's published values)"),
    out: Path = typer.Option(Path("cmosnoise-quality"), "--out", "-o", help="output folder"),
    overwrite: bool = OverwriteOpt,
):
    """Image quality through the test charts at each illuminance: SNR and SNR10, visual noise, banding, MTF, colour
    error; with --compare, a second configuration beside the first."""
    from rich.table import Table

    from ..analysis.quality import check_lux
    from . import quality as job

    try:
        levels = [float(v) for v in lux.split(",") if v.strip()]
    except ValueError:
        raise CmosnoiseError(f"--lux {lux[:80]!r}: give illuminances in lux, comma-separated (e.g. 1,10,100)") from None
    try:  # bounded before any work: at most MAX_LUX_POINTS illuminances, each within the range
        levels = check_lux(levels)
    except CmosnoiseError as exc:
        raise CmosnoiseError(f"--{exc}") from None
    # --lux gives the illuminances: light switched on by --set without one takes the first (each is set in turn)
    keys = [s.split("=", 1)[0].strip() for s in set_ or []]
    lit = ([f"light.illuminance_lux={levels[0]!r}"] if levels and "light.enabled" in keys
           and not {"light.illuminance_lux", "light.luminance_cd_m2"} & set(keys) else [])
    spec = _sensor(config, preset, [*lit, *(set_ or [])], {"seed": seed} if seed is not None else None)
    if find is not None or until is not None:
        if find is None or until is None:
            raise CmosnoiseError("--find and --until go together: the parameter's interval and the metric's limit")
        job.parse_find(find), job.parse_until(until)  # their syntax first: one line each
        if len(levels) != 1:
            raise CmosnoiseError(f"--lux {lux!r}: a threshold search holds at one illuminance; give one value")
        r = job.run_threshold(spec.config, out, overwrite, find, until, levels[0], instances, frames)
        if _level(ctx) >= 0:
            typer.echo(r["sentence"])
        _say(ctx, f"wrote threshold.json and threshold.png to {out}/")
        return
    other, origin = None, ""
    if compare_config is not None or compare_preset is not None or compare_set:
        if compare_config is None and compare_preset is None:  # the first configuration with keys changed
            other = _sensor(config, preset, [*(set_ or []), *compare_set]).config
            origin = f"A with {', '.join(compare_set)}"
        else:
            other = _sensor(compare_config, compare_preset, compare_set).config
            origin = " ".join(x for x in (str(compare_config or ""), f"preset {compare_preset}" if compare_preset
                                          else "", ", ".join(compare_set or [])) if x)
    with _counting(ctx, "measuring", "sensors") as progress:
        doc = job.run(spec.config, out, overwrite, levels, frames, spec.config.seed if seed is None else seed, other,
                      instances, compare_from=origin, picture_height_cm=picture_height_cm,
                      viewing_distance_cm=viewing_distance_cm, display_pixel_pitch_mm=display_pitch_mm,
                      display_distance_cm=display_distance_cm, colour_reference=colour_reference,
                      progress=progress)
    if _level(ctx) >= 0:
        head, rows = job.console_rows(doc)
        tab = Table(title="Image quality at each illuminance, lux (an 18 % grey, the edge, the ColorChecker)")
        for col in head:
            if col in ("metric", "unit"):
                tab.add_column(col, justify="left", no_wrap=True)
            else:
                tab.add_column(col, justify="right")
        for row in rows:
            tab.add_row(*row)
        Console().print(tab)
        for line in job.summary_lines(doc):
            typer.echo(f"  {line}")
    files = ["quality.json", "quality.csv", "report.html"]
    _say(ctx, f"wrote {', '.join(files)} and the plots to {out}/")


@app.command()
def fit(
    ctx: typer.Context,
    frames_from: Path = typer.Option(..., "--frames-from", help="a manifest .yaml of stacks, an EMVA 1288 descriptor (file or folder), or a folder of a camera's DNG bursts (each file's ISO and exposure from its tags)"),
    temperature: float | None = typer.Option(None, "--temperature", min=-60, max=150, help="temperature of stacks that give none, and the fitted sensor's, C (default: the hottest measured)"),
    threshold: float | None = typer.Option(None, "--threshold-e-per-s", min=0, help="white-pixel threshold (default: the base's, else 8 robust sigma above the median rate)"),
    cfa: str | None = typer.Option(None, "--cfa", help="CFA of the frames where their metadata lack it: RGGB, BGGR, GRBG, GBRG or none"),
    black_level: float | None = typer.Option(None, "--black-level", min=0, max=65535, help="black level, DN (reported beside the fitted one)"),
    bits: int | None = typer.Option(None, "--bits", min=8, max=16, help="ADC bits where the metadata lack them (default: from the largest code)"),
    config: Path | None = ConfigOpt,
    preset: str | None = PresetOpt,
    round_trip: bool = typer.Option(True, "--round-trip/--no-round-trip", help="simulate the measurement again from the fit and compare"),
    truth: Path | None = typer.Option(None, "--truth", help="the configuration that made the data (a simulated "
                                         "lab): compared parameter by parameter (default: truth.yaml beside the "
                                         "manifest, which cmosnoise measure writes)"),
    out: Path = typer.Option(Path("cmosnoise-fit"), "--out", "-o", help="output folder"),
    overwrite: bool = OverwriteOpt,
):
    """Fit a sensor model to measured frames: config.yaml, fit.json (values, 95 % intervals, methods), fit_report.html."""
    from . import fitting

    if threshold is not None and not math.isfinite(threshold):
        raise CmosnoiseError(f"--threshold-e-per-s {threshold}: give a finite rate, e-/s (or leave it out)")
    if cfa is not None and cfa not in ("RGGB", "BGGR", "GRBG", "GBRG", "none"):
        raise CmosnoiseError(f"--cfa {cfa!r}: expected RGGB, BGGR, GRBG, GBRG or none")
    base = _sensor(config, preset, None, {"sensor": {"cfa": cfa}} if cfa else None).config
    with _status(ctx) as (phase, say):
        doc = fitting.run(frames_from, base, out, overwrite, temperature, threshold, cfa, black_level, bits,
                          with_round_trip=round_trip, say=say, phase=phase, truth=truth)
    if doc.get("settings"):  # one fit per gain setting: a gain table
        for setting, r in doc["settings"].items():
            k = r["parameters"]["system_gain_K_dn_per_e"]
            _say(ctx, f"setting {setting}{' (' + r['mode'] + ')' if r['mode'] else ''}: system gain K = "
                      f"{fitting.describe(k)}")
        _say(ctx, "the lowest setting's parameters in full (fit.json has every setting's):")
    meta = doc.get("meta", {})
    _say(ctx, f"temperature {meta.get('temperature_c')} C: {meta.get('temperature_basis', 'from the data')}")
    for name, p in doc["parameters"].items():
        _say(ctx, f"{name} = {fitting.describe(p)}")
    for name, why in doc["not_fitted"].items():
        _say(ctx, f"not fitted, kept from the base configuration: {name}: {why}")
    if doc.get("selection"):
        _say(ctx, fitting.selection_line(doc["selection"]))
    if doc.get("truth"):
        _say(ctx, fitting.truth_line(doc["truth"]["rows"], doc["truth"]["source"]))
    for what, rows, key in (("round trip", doc.get("round_trip"), "parameter"),
                             ("EMVA 1288 of the fitted sensor on the measured plan", doc.get("emva_round_trip"), "quantity")):
        if rows:
            bad = [r[key] for r in rows if r["agree"] is False]
            judged = [r for r in rows if r["agree"] is not None]
            _say(ctx, f"{what}: {len(judged) - len(bad)} of {len(judged)} agree"
                 + (f"; differ: {', '.join(bad)}" if bad else "")
                 + (f" ({len(rows) - len(judged)} without an interval to judge by)" if len(judged) < len(rows) else ""))
    _say(ctx, f"wrote config.yaml, fit.json and fit_report.html to {out}/")


@app.command()
def measure(
    ctx: typer.Context,
    config: Path | None = ConfigOpt,
    preset: str | None = PresetOpt,
    set_: list[str] | None = SetOpt,
    seed: int | None = typer.Option(None, "--seed", min=0, help="sensor instance (default: the configuration's)"),
    temperatures: str | None = typer.Option(None, "--temperatures", help="comma-separated, C (default: the sensor's)"),
    levels: int = typer.Option(40, "--levels", min=8, max=400, help="flat-field pairs from dark to beyond saturation"),
    long_frames: int = typer.Option(100, "--long-frames", min=4, max=10000, help="frames of the long dark stack at each temperature"),
    isos: str | None = typer.Option(None, "--isos", help="comma-separated settings of the camera's gain table: the "
                                       "whole measurement at each (default: the sensor's own)"),
    format_: str = typer.Option("npy", "--format", help="npy (stacks and a manifest) or dng (a folder of DNG "
                                "bursts, each file's ISO and exposure time in its tags, as a camera writes them)"),
    out: Path = typer.Option(Path("cmosnoise-measurement"), "--out", "-o", help="output folder"),
    overwrite: bool = OverwriteOpt,
):
    """Simulate a lab's measurement of a sensor (.npy stacks and a manifest) for `cmosnoise fit`: try a fit, check a round trip."""
    from ..io.output import OutputFolder
    from . import fitting

    cfg = _sensor(config, preset, set_, {"seed": seed} if seed is not None else None).config
    temps = None
    if temperatures:
        try:
            temps = [float(x) for x in temperatures.split(",") if x.strip()]
        except ValueError:
            raise CmosnoiseError(f"--temperatures {temperatures!r}: expected numbers separated by commas, e.g. 25,45,65") from None
        bad = [t for t in temps if not -60 <= t <= 150]
        if bad or not temps:
            raise CmosnoiseError(f"--temperatures {temperatures!r}: each must be -60 to 150 C")
    settings = None
    if isos is not None:
        try:
            settings = [float(x) for x in isos.split(",") if x.strip()]
        except ValueError:
            raise CmosnoiseError(f"--isos {isos!r}: expected ISO settings separated by commas, e.g. 100,800,3200") from None
        if not settings or any(not 0 < v <= 1e7 for v in settings) or len(set(settings)) != len(settings):
            raise CmosnoiseError(f"--isos {isos!r}: give distinct ISO settings above 0 and at most 1e7, e.g. "
                                 "100,800,3200")
    folder = OutputFolder(out, overwrite)
    with folder as tmp, _counting(ctx, "measure", "frames") as progress:
        where = fitting.write_measurement(cfg, tmp, cfg.seed, temps, levels, long_frames, say=lambda m: _say(ctx, m),
                                          progress=progress, isos=settings, form=format_)
    shown = f"{out}/{where.relative_to(tmp)}"
    what = "its stacks" if format_ == "npy" else "the DNG bursts"
    _say(ctx, f"wrote {shown} ({what}); fit them with: cmosnoise fit --frames-from {shown}")


@app.command("compile")
def compile_cmd(
    ctx: typer.Context,
    background: bool = typer.Option(False, "--background", hidden=True,
                                    help="as a run starts it: at a low priority, and only where none runs"),
):
    """Compile every compiled loop for this machine now (a run that finds them missing uses the same bits' NumPy
    code meanwhile, and starts this in the background)."""
    from ..engine import jit
    from .compiling import build

    if jit.numba is None:
        raise CmosnoiseError("numba is not installed: every command runs the NumPy code, nothing to compile")
    t0 = time.perf_counter()
    times = build(background, say=lambda line: _say(ctx, line))
    if times is not None:
        _say(ctx, f"compiled for this machine ({jit.vectors()}) in {time.perf_counter() - t0:.0f} s; later runs load "
                  "the loops from numba's cache")


@app.command()
def presets():
    """List the presets, one line each."""
    for name in preset_names():
        desc = str(preset_data(name).get("description", "")).strip().splitlines()
        typer.echo(f"{name:24s} {desc[0] if desc else ''}")


@app.command()
def dataset(
    ctx: typer.Context,
    samples: int = typer.Option(..., "--samples", "-n", min=1, max=10**9,  # dataset.MAX_SAMPLES (not imported here)
                                help="how many samples"),
    crop: str = typer.Option("512", "--crop", help="sample size: SIZE or HEIGHTxWIDTH, even (the CFA cell kept)"),
    out: Path = typer.Option(Path("cmosnoise-dataset"), "--out", "-o", help="output folder"),
    format_: str = typer.Option("hdf5", "--format", help="hdf5 (chunked, compressed shards), npz or fits"),
    camera: list[str] | None = typer.Option(None, "--camera", "--preset", "-p", help="a preset (sony-imx900; "
                                               "sony-a7s2@iso=1600 for one setting), a camera file (fit's config.yaml) "
                                               "or a virtual camera family (led, eld, eld:nikon-d850); repeatable: "
                                               "each sample picks one (default: led)"),
    images: Path | None = typer.Option(None, "--images", help="a folder of images to crop (default: the built-in "
                                          "scenes)"),
    level: str = typer.Option("0.003:0.9", "--level", help="the scene's white as a share of each camera's "
                              "saturation, LOW:HIGH (log-uniform): a clean signal that does not clip"),
    light: str | None = typer.Option(None, "--light", help="instead of --level: the charge at the scene's white, "
                                        "LOW:HIGH e- (log-uniform), whatever the camera"),
    reference_level: float = typer.Option(0.9, "--reference-level", help="the level of the reference exposure each "
                                          "sample's exposure ratio (reference / level) is against"),
    allow_clipping: bool = typer.Option(False, "--allow-clipping", help="take a --level above 1 (a white that "
                                        "saturates)"),
    exposure: str | None = typer.Option(None, "--exposure", help="integration time LOW:HIGH s (log-uniform; "
                                           "default: each camera's)"),
    temperature: str | None = typer.Option(None, "--temperature", help="LOW:HIGH C (uniform; default: each "
                                              "camera's)"),
    set_: list[str] | None = SetOpt,
    white_threshold: str | None = typer.Option(None, "--white-threshold", help="dark current above which the "
                                                  "mask calls a pixel white: e-/s, or with its unit, e.g. 1560e-/s or "
                                                  "250aA (default: the model's)"),
    seed: int = typer.Option(0, "--seed", min=0, max=2**62, help="the data set's seed: sample i depends on (seed, i)"),
    shard_size: int = typer.Option(64, "--shard-size", min=1, max=100000, help="samples per shard file"),
    scheduler: str | None = typer.Option(None, "--scheduler", help="make the shards on an existing Dask scheduler"),
    workers: int | None = typer.Option(None, "--workers", min=1, max=1024, help="make the shards on a "
                                          "LocalCluster of this many processes (default: here, one process)"),
    resume: bool = typer.Option(False, "--resume", help="complete the data set in --out: make its missing shards"),
    device: str = DeviceOpt,
    overwrite: bool = OverwriteOpt,
):
    """Training and test data: noisy raw crops with their ground truth (expected raw, perfect image, defect mask)."""
    from . import dataset as ds

    def pair(text: str | None, option: str):
        if text is None:
            return None
        lo, sep, hi = text.partition(":")
        try:
            return (float(lo), float(hi if sep else lo))
        except ValueError:
            raise CmosnoiseError(f"{option} {text!r}: give LOW:HIGH (or one number)") from None

    size = crop.lower().split("x")
    try:
        shape = (int(size[0]), int(size[-1]))
    except ValueError:
        raise CmosnoiseError(f"--crop {crop!r}: give SIZE or HEIGHTxWIDTH in pixels, e.g. 512 or 256x384") from None
    sources = ds.image_sources(images) if images is not None else ds.BUILTIN_SCENES
    white_e_per_s = _white_e_per_s(white_threshold)
    cameras = tuple(camera or ("led",))
    recipe = ds.Recipe(samples=samples, crop=shape, seed=seed, cameras=cameras, camera_files=ds.camera_files(cameras),
                       sources=sources,
                       light_e=pair(light, "--light"), level=pair(level, "--level"),
                       reference_level=reference_level, allow_clipping=allow_clipping,
                       integration_time_s=pair(exposure, "--exposure"),
                       temperature_c=pair(temperature, "--temperature"), overrides=tuple(set_ or ()),
                       white_threshold_e_per_s=white_e_per_s, shard_size=shard_size, format=format_.lower())
    for note in ds.notes(recipe):
        _say(ctx, f"note: {note}")
    with _counting(ctx, "dataset", "samples") as progress:
        ds.build(recipe, out, resume=resume, overwrite=overwrite, scheduler=scheduler, workers=workers,
                 progress=progress, say=lambda m: _say(ctx, m), device=device)
    _say(ctx, f"wrote {samples} sample(s) of {shape[0]} x {shape[1]} in {recipe.shards()} {recipe.format} shard(s) "
              f"to {out}/ (dataset.json names them)")


@app.command()
def evaluate(
    ctx: typer.Context,
    data: Path = typer.Option(..., "--data", help="a data set folder (cmosnoise dataset)"),
    method: list[str] | None = typer.Option(None, "--method", "-m", help="none, median, dark-map, gaussian, bm3d, "
                                               "or your module:function (raw in, raw out); repeatable (default: "
                                               "the first four)"),
    outputs: Path | None = typer.Option(None, "--outputs", help="a folder of your method's outputs, "
                                           "sample_NNNNNN.npy or .tif, scored beside the methods"),
    target: str = typer.Option("expected", "--target", help="expected (the expected raw: the fixed pattern kept) or "
                               "perfect (the perfect image)"),
    out: Path = typer.Option(Path("cmosnoise-evaluation"), "--out", "-o", help="output folder"),
    overwrite: bool = OverwriteOpt,
):
    """Score denoisers and defect correctors on a data set: PSNR, SSIM and defects left, beside baselines."""
    from . import evaluate as ev

    methods = list(method) if method else (["none"] if outputs is not None else list(ev.DEFAULT_METHODS))
    with _counting(ctx, "evaluate", "samples") as progress:
        ev.run(data, methods, out, outputs, target, overwrite, progress=progress)
    _say(ctx, f"scored {', '.join(methods + (['outputs'] if outputs is not None else []))} on {data}: "
              f"{out}/report.html, scores.csv, summary.csv")


@app.command("config")
def config_cmd(
    config: Path | None = ConfigOpt,
    preset: str | None = PresetOpt,
    set_: list[str] | None = SetOpt,
    explain: bool = typer.Option(False, "--explain", help="list every key with its type, default, limits and description instead"),
):
    """Print the fully resolved configuration as YAML, every key (edit it, then use --config)."""
    if explain:
        from ..config.explain import text

        typer.echo(text(), nl=False)
        return
    spec = _sensor(config, preset, set_)
    for note in spec.notes:  # as YAML comments: the output stays a configuration --config reads
        typer.echo(f"# note: {note}")
    typer.echo(spec.config.to_yaml(), nl=False)


def run(argv: list[str] | None = None) -> int:
    """Run the command line on ``argv`` (default: ``sys.argv[1:]``) in this process; returns the exit status.

    A :class:`CmosnoiseError` becomes one line on stderr and status 2, a
    usage error click's message and status 2, Ctrl-C status 130.
    """
    command_started()
    previous = _catch_termination()
    unraisable = sys.unraisablehook
    sys.unraisablehook = _quiet_interrupts(unraisable)
    try:
        from .logs import said

        with warnings.catch_warnings(), _libraries_quiet(argv), said():
            # numerical warnings of NumPy and SciPy (an overflow in a tail far beyond any pixel) are not the
            # user's to read: every result is checked to be finite, and bad input is refused with a message
            warnings.filterwarnings("ignore", category=RuntimeWarning, module=r"(numpy|scipy)(\.|$)")
            result = app(args=argv, prog_name="cmosnoise", standalone_mode=False)
        check_terminated()  # a signal whose exception a library swallowed: the command did not finish as asked
        return result if isinstance(result, int) else 0
    except typer.Exit as exc:
        return exc.exit_code
    except typer.TyperException as exc:  # usage errors: one line, as every other error, status 2
        message = " ".join(str(exc.format_message() if hasattr(exc, "format_message") else exc).split())
        ctx = getattr(exc, "ctx", None)
        where = f" (see {ctx.command_path} --help)" if ctx is not None else ""
        print(f"cmosnoise: error: {message}{where}", file=sys.stderr)
        return getattr(exc, "exit_code", 2)
    except CmosnoiseError as exc:
        message = " ".join(str(exc).split())  # one line, whatever a library put in it
        done = f" ({written_note()})" if written() else ""
        print(f"cmosnoise: error: {message}{done}", file=sys.stderr)
        return 2
    except OSError as exc:  # the machine's fault, not the input's: a full disk, a vanished folder
        where = f" {exc.filename!r}" if getattr(exc, "filename", None) else ""
        print(f"cmosnoise: error: cannot read or write{where}: {exc.strerror or exc}{_unwritten(argv, exc)}",
              file=sys.stderr)
        return 1
    except Terminated as exc:
        name = "Ctrl-C" if exc.signum == signal.SIGINT else signal.Signals(exc.signum).name
        print(f"cmosnoise: {_stopped(argv)} ({name}){_unwritten(argv, exc)}", file=sys.stderr)
        return 128 + exc.signum
    except (KeyboardInterrupt, typer.Abort) as exc:
        print(f"cmosnoise: {_stopped(argv)}{_unwritten(argv, exc)}", file=sys.stderr)
        return 130
    finally:
        command_over()
        sys.unraisablehook = unraisable
        for signum, handler in previous.items():
            signal.signal(signum, handler)


#: commands that write no output folder: a signal stops them, it does not cut a result short
_NO_OUTPUT = ("explore", "presets", "config")


def _command(argv) -> str | None:
    args = sys.argv[1:] if argv is None else argv
    return next((a for a in args if not a.startswith("-")), None)


def _stopped(argv) -> str:
    return "stopped" if _command(argv) == "explore" else "interrupted"


def _unwritten(argv, exc: BaseException | None = None) -> str:
    """What a stopped command leaves: what its job said it kept (:func:`~cmosnoise.errors.note_kept`), else
    nothing (an output folder is whole or absent)."""
    kept = getattr(exc, "kept", None)
    if kept:
        return f"; {kept}"
    if written():
        return f"; {written_note()}"
    return "" if _command(argv) in _NO_OUTPUT else "; nothing was written"


@contextlib.contextmanager
def _libraries_quiet(argv):
    """Warnings of the file libraries (tifffile, LibRaw through rawpy, imageio, Pillow) kept off stderr unless
    --verbose: a damaged file's problems are reported by our own one-line error, not by 200 lines of theirs."""
    from .logs import quieted

    args = sys.argv[1:] if argv is None else [str(a) for a in argv]
    if "-v" in args or "--verbose" in args:
        yield
        return
    warnings.filterwarnings("ignore", module=r"(tifffile|rawpy|imageio|PIL|colour_demosaicing)(\.|$)")
    # Dask's client and scheduler (a sweep's, a data set's): what they would log at any moment a signal lands
    # ("Couldn't gather 1 keys, rescheduling", closed streams) is ours to say in one line; a task's failure
    # reaches the command as its exception
    with quieted(("tifffile", "rawpy", "imageio", "PIL")), quieted(("distributed", "tornado", "asyncio"),
                                                                   logging.CRITICAL):
        yield


def _quiet_interrupts(hook):
    """An unraisable-exception hook that keeps quiet about our own interrupts (raised inside a C callback,
    e.g. LLVM's into numba, they cannot unwind; :func:`check_terminated` acts on them instead)."""
    def quiet(info):
        if not isinstance(info.exc_value, (Terminated, KeyboardInterrupt)):
            hook(info)
    return quiet


def _catch_termination() -> dict:
    """SIGINT, SIGTERM and SIGHUP raise :class:`Terminated`: output folders clean up on the way out.

    Returns the handlers it replaced (restored when the command ends). Only
    the main thread can set handlers; elsewhere nothing changes.
    """
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            previous[signum] = signal.signal(signum, signal_received)
    return previous


def main() -> None:
    status = run()
    exit_quietly(status)
    sys.exit(status)


def exit_quietly(status: int) -> None:
    """From here the command is over: a signal while the interpreter shuts down (Dask's threads, atexit) says so
    in one line and ends with the command's own status, instead of dying silently by the signal."""
    if threading.current_thread() is not threading.main_thread():  # pragma: no cover - the console script
        return

    def done(signum, _frame=None):
        name = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
        print(f"cmosnoise: {name} while exiting; the command had already finished (status {status})",
              file=sys.stderr, flush=True)
        os._exit(status)

    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, done)


if __name__ == "__main__":
    main()
