"""``cmosnoise sweep``: parameter studies and yield over many sensor instances (dies), on Dask.

The grid is the product of the ``--vary`` axes; each point runs ``instances``
sensor instances. Instance i of every point has the seed
``SeedSequence(root_seed, spawn_key=(i,))``, so a row of ``results.csv``
depends on nothing but its point and its instance: not on the number of
workers, the order in which tasks finish, or the machine.

A task (:func:`run_instance`) gets a configuration as plain data and a seed,
and returns a small record of metrics, never arrays. Tasks go to a Dask
``distributed`` cluster in bounded batches: a ``LocalCluster`` of processes
by default, or an existing scheduler (``--scheduler tcp://host:8786``). Rows
are appended to ``results.csv`` as tasks finish; ``--resume`` skips the rows
already there.

Examples
--------
>>> from cmosnoise import sweep
>>> axis = sweep.parse_vary("dark_current.points.0.tail.ppm_above=1000,4000")
>>> axis.keys, axis.values
(('dark_current.points.0.tail.ppm_above',), ((1000,), (4000,)))
"""

from __future__ import annotations

import contextlib
import csv
import itertools
import json
import math
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ..config.loading import load_yaml_text
from ..errors import CmosnoiseError, check_terminated, keeping, note_kept
from ..io.output import OutputFolder, resumable_mode
from .cluster import connect, disconnect, task_result, worker_attribute

#: the scene of a yield study (--spec) without --scene: a flat field at half the peak rate
YIELD_SCENE = "flat:0.5"
#: tasks in flight at once: the scheduler's memory does not grow with the sweep
BATCH_PER_WORKER = 4
SPEC_RE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(<=|>=|==|!=|<|>)\s*([-+0-9.eE]+|inf|-inf)\s*$")


# ------------------------------------------------------------------ the grid
@dataclass(frozen=True)
class Axis:
    """Keys that move together and their values (one tuple of values per step).

    Parameters
    ----------
    keys : tuple of str
        Dotted keys.
    values : tuple of tuple
        One tuple of values (one per key) per step.
    """

    keys: tuple[str, ...]
    values: tuple[tuple, ...]


def _scalar(text: str, where: str):
    if re.fullmatch(r"\s*[-+]?\d+(:\d+)+\s*", text):  # YAML 1.1 would read 1:2 as 62 (base 60)
        raise CmosnoiseError(f"{where}: {text.strip()!r}: a range is start:stop:count, e.g. 0.5:2.0:4")
    try:
        return load_yaml_text(text)
    except Exception:
        raise CmosnoiseError(f"{where}: {text!r} is not a value") from None


def parse_vary(text: str) -> Axis:
    """``KEY=v1,v2,...``, ``KEY=start:stop:count`` or ``KEY1,KEY2=a1xb1,a2xb2`` (keys that move together).

    Parameters
    ----------
    text : str
        A ``--vary`` value.

    Returns
    -------
    Axis
    """
    where = f"--vary {text!r}"
    if "=" not in text:
        raise CmosnoiseError(f"{where}: expected KEY=VALUES, e.g. sensor.temperature_c=25,45,65")
    left, _, right = text.partition("=")
    keys = tuple(k.strip() for k in left.split(","))
    if not all(keys) or any(not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z0-9_]+)*", k) for k in keys):
        raise CmosnoiseError(f"{where}: keys must be dotted names such as prnu.sigma_pct")
    right = right.strip()
    if not right:
        raise CmosnoiseError(f"{where}: no values")
    if len(keys) == 1 and right.count(":") == 2 and "," not in right:
        parts = right.split(":")
        try:
            start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            raise CmosnoiseError(f"{where}: a range is start:stop:count, e.g. 0.5:2.0:4") from None
        if count < 1 or count > 10000 or not (math.isfinite(start) and math.isfinite(stop)):
            raise CmosnoiseError(f"{where}: a range needs finite ends and a count from 1 to 10000")
        values = tuple((float(v),) for v in np.linspace(start, stop, count))
    else:
        steps = [s.strip() for s in right.split(",")]
        if any(not s for s in steps):
            raise CmosnoiseError(f"{where}: an empty value in the list")
        values = []
        for s in steps:
            parts = s.split("x") if len(keys) > 1 else [s]
            if len(parts) != len(keys):
                raise CmosnoiseError(f"{where}: {s!r} gives {len(parts)} value(s) for {len(keys)} keys "
                                     "(keys that move together take values like 640x480)")
            values.append(tuple(_scalar(p, where) for p in parts))
        values = tuple(values)
    return Axis(keys, values)


def grid(axes: list[Axis]) -> list[dict]:
    """Every point of the sweep: {key: value} for the product of the axes, in a fixed order.

    Parameters
    ----------
    axes : list of Axis

    Returns
    -------
    list of dict
        Each point as {key: value}.
    """
    points = []
    for combo in itertools.product(*(a.values for a in axes)):
        point = {}
        for axis, vals in zip(axes, combo):
            point.update(dict(zip(axis.keys, vals)))
        points.append(point)
    return points


def point_config(base, point: dict):
    """The base configuration with a point's values, validated (physics included); a number in a key indexes a
    list (``dark_current.points.0.tail.ppm_above``), as ``--set`` does.

    Parameters
    ----------
    base : Config
        The sweep's base configuration.
    point : dict
        {dotted key: value}.

    Returns
    -------
    Config
    """
    from ..config.loading import apply_values, config_values, default_data, validate_data
    from ..model.spec import resolve

    data = apply_values(config_values(base), point, default_data())  # a key that is not there: its own line
    try:
        return resolve(validate_data(data)).config
    except CmosnoiseError as exc:  # a value the schema or the physics refuses: named with its point
        shown = ", ".join(f"{k}={v}" for k, v in point.items())
        raise CmosnoiseError(f"sweep point {shown}: {str(exc)}") from None


def instance_seed(root_seed: int, instance: int) -> int:
    """Instance i's seed: ``SeedSequence(root_seed, spawn_key=(i,))``, as a 63-bit integer.

    Parameters
    ----------
    root_seed : int
        The sweep's seed (the base configuration's).
    instance : int
        The instance's number, from 0.

    Returns
    -------
    int
    """
    state = np.random.SeedSequence(root_seed, spawn_key=(instance,)).generate_state(2, np.uint32)
    return (int(state[0]) << 31) ^ int(state[1])


@dataclass(frozen=True)
class Spec:
    """A pass/fail test of an instance: ``metric op value`` (``--spec couplets_after_correction<=0``).

    Parameters
    ----------
    metric : str
        One of :data:`METRICS`.
    op : str
        <=, >=, <, >, == or !=.
    value : float
    """

    metric: str
    op: str
    value: float

    def passes(self, record: dict) -> bool:
        v = record.get(self.metric)
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return False
        return {"<=": v <= self.value, ">=": v >= self.value, "<": v < self.value, ">": v > self.value,
                "==": v == self.value, "!=": v != self.value}[self.op]


def parse_spec(text: str, known: tuple[str, ...] | None = None) -> Spec:
    """``--spec METRIC OP NUMBER`` checked against ``known`` metrics.

    Parameters
    ----------
    text : str
        The ``--spec`` value, e.g. ``couplets_after_correction<=0``.
    known : tuple of str, optional
        The metrics it may name (default :data:`METRICS`; a plan with ``--quality-lux`` adds the quality metrics).

    Returns
    -------
    Spec
    """
    known = METRICS if known is None else known
    m = SPEC_RE.match(text)
    if not m:
        raise CmosnoiseError(f"--spec {text!r}: expected METRIC OP NUMBER, e.g. couplets_after_correction<=0 "
                             f"(metrics: {', '.join(known)})")
    if m.group(1) not in known:
        more = " (with --quality-lux)" if m.group(1) in quality_metrics() else ""
        raise CmosnoiseError(f"--spec {text!r}: unknown metric {m.group(1)!r}; use one of {', '.join(known)}{more}")
    return Spec(m.group(1), m.group(2), float(m.group(3)))


# ------------------------------------------------------------------ one task: one sensor instance
METRICS = ("mean_e", "temporal_noise_e", "temporal_noise_predicted_e", "snr_db_at_100e", "snr_db_at_1000e",
           "dynamic_range_db", "dark_mean_e_per_s", "ppm_above_threshold", "white_pixels", "couplets",
           "couplets_expected_random", "residual_defects", "couplets_after_correction")


#: what a person reads for each metric (the page's table; results.csv keeps the names above)
METRIC_LABELS = {
    "mean_e": "mean signal (e-)", "temporal_noise_e": "temporal noise (e- rms)",
    "temporal_noise_predicted_e": "temporal noise, predicted (e- rms)",
    "snr_db_at_100e": "SNR at 100 e- (dB; hot pixels in the rms)",
    "snr_db_at_1000e": "SNR at 1000 e- (dB; hot pixels in the rms)", "dynamic_range_db": "dynamic range (dB)",
    "dark_mean_e_per_s": "dark current, mean (e-/s)", "ppm_above_threshold": "dark current above threshold (ppm)",
    "white_pixels": "white pixels", "couplets": "couplets", "couplets_expected_random": "couplets expected at random",
    "residual_defects": "defects left after correction", "couplets_after_correction": "couplets left after correction",
}


def quality_metrics() -> tuple[str, ...]:
    """The image-quality metrics a sweep measures with ``--quality-lux`` (:data:`cmosnoise.analysis.quality.METRICS`,
    the one registry), in its order.

    Returns
    -------
    tuple of str
    """
    from ..analysis import quality

    return tuple(m.name for m in quality.METRICS)


def metric_label(name: str, quality_lux: float | None = None) -> str:
    """What a person reads for a metric: :data:`METRIC_LABELS`, or a quality metric's label, unit and lux.

    Parameters
    ----------
    name : str
        A column of ``results.csv``.
    quality_lux : float, optional
        The illuminance the quality metrics were measured at.

    Returns
    -------
    str
    """
    if name in METRIC_LABELS:
        return METRIC_LABELS[name]
    from ..analysis import quality

    m = quality.BY_NAME.get(name)
    if m is None:
        return name
    unit = f", {m.unit}" if m.unit else ""
    at = f" at {quality_lux:g} lux" if quality_lux is not None else ""
    return f"{m.label}{at}{unit}"


def run_instance(config_data: dict, scene: str, frames: int, seed: int, cache=None, device: str = "cpu",
                 quality_lux: float | None = None) -> dict:
    """The metrics of one sensor instance: a dict of numbers (what a Dask task returns).

    ``cache`` (a :class:`~cmosnoise.model.fixed_pattern.PatternCache`) lends the maps that another point of
    the same seed drew with the same inputs (the worker's own cache); the numbers are the same without it.
    ``device``: where the frames are made (``"cuda"``: the worker's GPU; the same numbers).

    Parameters
    ----------
    config_data : dict
        A point's configuration as data.
    scene : str
        The scene.
    frames : int
        Frames to measure the temporal noise on.
    seed : int
        The instance's seed (:func:`instance_seed`).
    cache : PatternCache, optional
    device : str
        "cpu" or "cuda".
    quality_lux : float, optional
        Also measure the image-quality metrics (:func:`quality_metrics`) of this instance through the charts at
        this illuminance (:func:`cmosnoise.analysis.quality.measure`: the same seed, ``frames`` frames, at least 2).

    Returns
    -------
    dict of str to float
        Every metric of :data:`METRICS` (and of :func:`quality_metrics` with ``quality_lux``; NaN where the data
        give none, e.g. colour on a monochrome sensor).
    """
    from ..analysis import figures_of_merit as fom
    from ..analysis import white_pixels
    from ..analysis.run_stats import RunStats
    from ..config import Config, ProcessingSection
    from ..isp import calibration
    from ..isp.process import Processor
    from ..model.sensor import Sensor

    cfg = Config.model_validate(config_data)
    sensor = Sensor(cfg, seed=seed, cache=cache, device=device)
    shot = sensor.expose(scene)
    t = sensor.transfer
    k = t.gain_dn_per_e
    stats = RunStats(t.max_code)
    raw0 = shot.frame(0)
    stats.update(raw0, raw0)  # raw codes only: the e- sums are not read
    for raw in shot.frames(max(frames, 1) - 1, first=1):
        stats.update(raw, raw)
    measured = stats.result()
    out = {"mean_e": float((measured["mean_dn"] - t.black_level_dn) / k)}
    tn = fom.temporal_noise(measured, k)["rms_e"]
    out["temporal_noise_e"] = math.nan if tn is None else tn
    figures = fom.pane(sensor, shot, levels_e=(100.0, 1000.0))
    out["temporal_noise_predicted_e"] = float(figures["budget"]["temporal_total_e"])
    kf = figures["key_figures"]
    snr = kf.get("snr_total_db_at_signal_e", {})
    out["snr_db_at_100e"] = float(snr.get("100", math.nan))  # key_figures names its levels as text, in e-
    out["snr_db_at_1000e"] = float(snr.get("1000", math.nan))
    out["dynamic_range_db"] = float(kf["dynamic_range_db"])
    dark = figures.get("dark", {})
    out["dark_mean_e_per_s"] = dark.get("mean_e_per_s", math.nan)
    out["ppm_above_threshold"] = dark.get("ppm", math.nan)
    for name in ("white_pixels", "couplets", "couplets_expected_random"):
        out[name] = dark.get(name, math.nan)
    # what survives dark calibration and the chosen defect corrector (median when none is chosen), and one's own
    # corrector after it where processing.defects.corrector names one
    n_dark = cfg.processing.dark_frames or 8
    method = cfg.processing.defects.method if cfg.processing.defects.method != "off" else "median"
    master = calibration.master_dark(sensor.dark_frames(n_dark))
    proc = Processor(ProcessingSection(dark_frames=n_dark, defects={"method": method,
                                                                    "corrector": cfg.processing.defects.corrector}),
                     sensor.raw_info(), master)
    left = white_pixels.left_after_correction(proc.cfa_image(raw0), shot.photo_mean_e, k, sensor.cfa)
    out["residual_defects"] = left["pixels"]
    out["couplets_after_correction"] = left["couplets"]
    names = METRICS
    if quality_lux is not None:
        from ..analysis import quality

        measured = quality.measure(cfg, [float(quality_lux)], frames=max(frames, 2), seed=seed)["metrics"]
        out.update({k: math.nan if v[0] is None else v[0] for k, v in measured.items()})
        names = METRICS + quality_metrics()
    return {m: out.get(m, math.nan) for m in names}


def _worker_cache():
    """The Dask worker's own :class:`PatternCache` (made on its first task; None outside a worker).

    Tasks of one instance (one seed) at several points share the maps whose
    inputs the points do not change. A tenth of the memory available when
    it is made, at most 2 GB, across the worker's threads.
    """
    from ..model import footprint
    from ..model.fixed_pattern import PatternCache

    def make():
        return PatternCache(int(min(2e9, 0.1 * (footprint.available_bytes() or 1e9))))

    return worker_attribute("patterns", make, anywhere=False)


def _task(config_data: dict, scene: str, frames: int, point: int, instance: int, seed: int, device: str = "cpu",
          quality_lux: float | None = None) -> dict:
    """What a worker runs: one instance, tagged with its point and instance.

    An error of the input (a :class:`CmosnoiseError`) is returned as
    ``{"error": message}``, not raised: Dask would retry it and then show a
    traceback; the sweep stops with the one line instead.
    """
    try:
        metrics = run_instance(config_data, scene, frames, seed, _worker_cache(), device, quality_lux)
    except CmosnoiseError as exc:
        return {"point": point, "instance": instance, "error": " ".join(str(exc).split())}
    return {"point": point, "instance": instance, "seed": seed, **metrics}


# ------------------------------------------------------------------ the sweep
@dataclass
class Plan:
    """Everything a sweep needs, checked before any task runs (:func:`plan`).

    Parameters
    ----------
    base : Config
        The base configuration.
    axes : list of Axis
        The varied keys.
    points : list of dict
        The grid's points, {key: value}.
    configs : list of dict
        Each point's configuration as data.
    instances, frames : int
        Instances per point, frames per instance.
    scene : str
        The scene every instance sees.
    specs : list of Spec
        The pass/fail tests.
    plot_metrics : tuple of str
        The metrics plotted.
    scene_why : str
        Why this scene.
    quality_lux : float or None
        The illuminance of the image-quality metrics (``--quality-lux``), or None: not measured.
    """

    base: object  # Config
    axes: list[Axis]
    points: list[dict]
    configs: list[dict]
    instances: int
    frames: int
    scene: str
    specs: list[Spec]
    plot_metrics: tuple[str, ...] = METRICS
    scene_why: str = ""
    quality_lux: float | None = None

    @property
    def metrics(self) -> tuple[str, ...]:
        """Every metric each instance gives: :data:`METRICS`, and the quality metrics with ``quality_lux``."""
        return METRICS + (quality_metrics() if self.quality_lux is not None else ())

    @property
    def keys(self) -> list[str]:
        return [k for a in self.axes for k in a.keys]

    def columns(self) -> list[str]:
        return ["point", *self.keys, "instance", "seed", *self.metrics] + (["pass"] if self.specs else [])

    def to_yaml_data(self) -> dict:
        return {"base": self.base.model_dump(mode="json"), "scene": self.scene, "instances": self.instances,
                "frames": self.frames, "vary": [{"keys": list(a.keys), "values": [list(v) for v in a.values]} for a in self.axes],
                "spec": [f"{s.metric}{s.op}{s.value:g}" for s in self.specs], "quality_lux": self.quality_lux}


def plan(base, vary: list[str], instances: int, frames: int = 2, scene: str | None = None,
         specs: list[str] | None = None, metrics: list[str] | None = None, quality_lux: float | None = None) -> Plan:
    """Check everything a sweep needs before any task runs; returns the plan (``metrics``: those to plot).

    Parameters
    ----------
    base : Config
        The base configuration.
    vary : list of str
        ``--vary`` values.
    instances : int
        Sensor instances per point.
    frames : int
        Frames per instance.
    scene : str, optional
        The scene (default: a flat field for a yield study, else the configuration's).
    specs : list of str, optional
        ``--spec`` values.
    metrics : list of str, optional
        The metrics to plot.
    quality_lux : float, optional
        Also measure the image-quality metrics at this illuminance, lux (``--quality-lux``).

    Returns
    -------
    Plan
    """
    if quality_lux is not None and not (isinstance(quality_lux, (int, float)) and 0 < quality_lux <= 1e7):
        raise CmosnoiseError(f"--quality-lux {quality_lux!r}: give an illuminance above 0 and up to 1e7 lux")
    known = METRICS + (quality_metrics() if quality_lux is not None else ())
    unknown = [m for m in metrics or [] if m not in known]
    if unknown:
        more = "" if quality_lux is not None or unknown[0] not in quality_metrics() else " (with --quality-lux)"
        raise CmosnoiseError(f"--metric {unknown[0]!r}: use one of {', '.join(known)}{more}")
    if not isinstance(instances, int) or not 1 <= instances <= 1_000_000:
        raise CmosnoiseError(f"--instances {instances!r}: give 1 to 1000000")
    if not isinstance(frames, int) or not 1 <= frames <= 100:
        raise CmosnoiseError(f"--frames {frames!r}: give 1 to 100")
    axes = [parse_vary(v) for v in vary or []]
    seen = [k for a in axes for k in a.keys]
    if len(set(seen)) != len(seen):
        raise CmosnoiseError(f"--vary: a key is varied twice ({', '.join(sorted({k for k in seen if seen.count(k) > 1}))})")
    points = grid(axes) if axes else [{}]
    checked = [point_config(base, p) for p in points]
    configs = [c.model_dump(mode="json") for c in checked]
    parsed_specs = [parse_spec(s, known) for s in specs or []]
    from ..analysis import white_pixels
    from ..model import footprint
    from ..model import scene as scene_mod

    if scene:
        why = "given with --scene"
    elif parsed_specs:
        scene, why = YIELD_SCENE, ("the yield study's default: a flat field, so that no detail of a picture "
                                   "counts as a defect; --scene picks another")
    else:
        scene, why = base.scene.source, "the configuration's scene.source"
    if scene_mod.builtin_name(scene) != "flat":  # every row holds residual_defects, plotted or not
        why += ("; residual_defects and couplets_after_correction count what processing leaves beyond "
                f"{white_pixels.DEFECT_TOLERANCE_E:g} e- of the expected signal, and on a scene with detail that includes the detail: "
                "use a flat scene (flat:0.5) for defect yield")

    # what every task would find, found once before any task runs: the scene decodes, each point's sensor fits
    if scene_mod.is_builtin(scene):
        scene_mod.render(scene, (8, 8))
    else:
        if not Path(scene).exists() and not Path(scene).is_symlink():
            raise CmosnoiseError(f"--scene {scene!r}: no such built-in or file")
        scene_mod.load_file(scene)
        scene = str(Path(scene).resolve())
    sizes = {}
    for point, cfg in zip(points, checked):
        sizes.setdefault((cfg.sensor.width, cfg.sensor.height), (point, cfg))
    for point, cfg in sizes.values():
        try:
            footprint.check_fits(cfg)
        except CmosnoiseError as exc:
            shown = ", ".join(f"{k}={v}" for k, v in point.items())
            raise CmosnoiseError(f"sweep point {shown}: {exc}" if shown else str(exc)) from None
    if quality_lux is not None:  # the charts' light: each point's configuration takes lux (a QE, a spectrum)
        from ..analysis import quality

        for point, cfg in zip(points, checked):
            try:
                quality.check_light(cfg)
            except CmosnoiseError as exc:
                shown = ", ".join(f"{k}={v}" for k, v in point.items())
                raise CmosnoiseError(f"--quality-lux at sweep point {shown or '(the base)'}: {exc}") from None
    return Plan(base, axes, points, configs, instances, frames, scene, parsed_specs,
                tuple(metrics) if metrics else known, why, None if quality_lux is None else float(quality_lux))


def wilson(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval (95 %) of a proportion k / n.

    Parameters
    ----------
    k, n : int
        Successes and trials.
    z : float
        The normal quantile (1.96: 95 %).

    Returns
    -------
    (float, float)
        The interval's ends.
    """
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return (max(0.0, centre - half), min(1.0, centre + half))


def repair_rows(path: Path) -> int:
    """Cut a last row that was half written (a kill or a full disk mid-row): ``results.csv`` ends at its last
    whole line. Returns the bytes removed.

    Parameters
    ----------
    path : Path
        ``results.csv``.

    Returns
    -------
    int
    """
    size = path.stat().st_size
    if size == 0:
        return 0
    with open(path, "rb+") as fh:
        fh.seek(max(0, size - 65536))
        tail = fh.read()
        if tail.endswith(b"\n"):
            return 0
        cut = tail.rfind(b"\n")
        keep = (size - len(tail) + cut + 1) if cut >= 0 else 0
        fh.truncate(keep)
    return size - keep


def _done_rows(path: Path, columns: list[str]) -> set[tuple[int, int]]:
    """(point, instance) of every whole row of ``results.csv``, after :func:`repair_rows`."""
    if not path.exists():
        return set()
    repair_rows(path)
    done = set()
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        head = next(reader, None)
        if head is None:
            return set()
        if head != columns:
            raise CmosnoiseError(f"--resume: {str(path)!r} has other columns than this sweep's; it is a different sweep")
        for n, r in enumerate(reader, 2):
            try:
                key = (int(r[0]), int(r[columns.index("instance")]))
                if len(r) != len(columns):
                    raise ValueError
            except (ValueError, IndexError):
                raise CmosnoiseError(f"--resume: {str(path)!r} line {n} is not a row of this sweep; "
                                     "start again with --overwrite") from None
            done.add(key)
    return done


def execute(p: Plan, out: Path, client, resume: bool = False, progress: Callable[[int, int], None] | None = None,
            device: str = "cpu") -> Path:
    """Run every (point, instance) not yet in ``out/results.csv`` on ``client``; rows are appended as tasks finish
    (``device``: where each worker makes the frames).

    Parameters
    ----------
    p : Plan
    out : Path
        The sweep's folder.
    client : distributed.Client
    resume : bool
        Skip the rows already there.
    progress : callable, optional
        Called with (done, total).
    device : str
        "cpu" or "cuda".

    Returns
    -------
    Path
        ``results.csv``.
    """
    from distributed import as_completed

    results = out / "results.csv"
    columns = p.columns()
    done = _done_rows(results, columns) if resume else set()
    # instance by instance: one seed's points in a row, so a worker's cache lends the maps they share
    todo = [(i, j) for j in range(p.instances) for i in range(len(p.points)) if (i, j) not in done]
    total = len(p.points) * p.instances
    if progress:
        progress(len(done), total)
    new = not results.exists() or not resume or results.stat().st_size == 0
    fh = open(results, "w" if new else "a", newline="")  # noqa: SIM115 - closed in the finally below, rows flushed one by one
    writer = csv.writer(fh)
    if new:
        writer.writerow(columns)
        fh.flush()
    try:
        nworkers = max(1, len(client.scheduler_info().get("workers", {})) or 1)
        window = BATCH_PER_WORKER * nworkers

        def submit(item):
            i, j = item
            return client.submit(_task, p.configs[i], p.scene, p.frames, i, j, instance_seed(p.base.seed, j),
                                 device, p.quality_lux, pure=False, retries=2)

        queue = iter(todo)
        running = as_completed([submit(x) for x in itertools.islice(queue, window)])
        finished = len(done)
        for future in running:
            rec = task_result(future, "a sweep task")
            future.release()
            if "error" in rec:
                shown = ", ".join(f"{k}={v}" for k, v in p.points[rec["point"]].items())
                raise CmosnoiseError(f"sweep point {shown or '(the base)'}, instance {rec['instance']}: {rec['error']}")
            row = [rec["point"], *[_cell(p.points[rec["point"]][k]) for k in p.keys], rec["instance"], rec["seed"],
                   *[_cell(rec[m]) for m in p.metrics]]
            if p.specs:
                row.append(int(all(s.passes(rec) for s in p.specs)))
            writer.writerow(row)
            fh.flush()
            finished += 1
            if progress:
                progress(finished, total)
            check_terminated()  # a signal a library swallowed: stop here, the rows so far said, not at the end
            nxt = next(queue, None)
            if nxt is not None:
                running.add(submit(nxt))
    finally:
        fh.close()
    return results


def _rows_kept(results: Path) -> int:
    """Whole rows in ``results.csv`` (its header and a half-written last line left out)."""
    try:
        data = results.read_bytes()
    except OSError:
        return 0
    return max(0, data.count(b"\n") - 1)


def _cell(v):
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf"))
    return v


def summarize(p: Plan, out: Path):
    """summary.csv, a plot per metric (percentile bands), the yield plot, and index.html, from results.csv.

    Parameters
    ----------
    p : Plan
    out : Path
        The sweep's folder.

    Returns
    -------
    pandas.DataFrame
        ``summary.csv``'s rows.
    """
    import pandas as pd

    try:
        df = pd.read_csv(out / "results.csv").sort_values(["point", "instance"])
    except (ValueError, KeyError, OSError) as exc:  # pandas' parser errors are ValueErrors
        raise CmosnoiseError(f"{str(out / 'results.csv')!r} cannot be summarized: {' '.join(str(exc).split())[:200]} "
                             "(--resume repairs a half-written last row)") from None
    rows = []
    for i, point in enumerate(p.points):
        sub = df[df["point"] == i]
        row = {"point": i, **point, "instances": len(sub)}
        for m in p.metrics:
            v = sub[m].astype(float)
            v = v[np.isfinite(v)]
            if len(v):
                row.update({f"{m}_mean": v.mean(), f"{m}_std": v.std(ddof=1) if len(v) > 1 else math.nan,
                            f"{m}_p5": v.quantile(0.05), f"{m}_p50": v.quantile(0.5), f"{m}_p95": v.quantile(0.95)})
        if p.specs:
            k = int(sub["pass"].sum())
            lo, hi = wilson(k, len(sub))
            row.update({"yield": k / len(sub) if len(sub) else math.nan, "yield_lo": lo, "yield_hi": hi})
        rows.append(row)
    summary = pd.DataFrame(rows)
    summary.to_csv(out / "summary.csv", index=False)
    plots = _plots(p, summary, out)
    _index(p, summary, plots, out)
    return summary


def _plots(p: Plan, summary, out: Path) -> list[str]:
    from matplotlib.figure import Figure

    if not p.axes:
        return []
    x_axis = p.axes[0]
    xkey = x_axis.keys[0]
    others = p.axes[1:]
    groups = list(itertools.product(*(a.values for a in others))) if others else [()]
    names = []
    metrics = (["yield"] if p.specs else []) + [m for m in p.plot_metrics if f"{m}_mean" in summary]  # the yield first
    for m in metrics:
        fig = Figure(figsize=(6.4, 4.2), dpi=100)
        ax = fig.add_subplot()
        for g in groups:
            sel = np.ones(len(summary), bool)
            label = []
            for axis, vals in zip(others, g):
                for key, val in zip(axis.keys, vals):
                    sel &= (summary[key] == val).to_numpy()
                label.append(", ".join(f"{key.split('.')[-1]}={val}" for key, val in zip(axis.keys, vals)))
            s = summary[sel]
            xs = s[xkey].to_numpy()
            lab = "; ".join(label) or None
            if m == "yield":
                err = [np.clip(s["yield"] - s["yield_lo"], 0, None), np.clip(s["yield_hi"] - s["yield"], 0, None)]
                ax.errorbar(xs, s["yield"], yerr=err, marker="o", capsize=3, label=lab)
                ax.set_ylim(-0.02, 1.02)
            else:
                line, = ax.plot(xs, s[f"{m}_mean"], marker="o", label=lab)
                ax.fill_between(xs, s[f"{m}_p5"], s[f"{m}_p95"], alpha=0.2, color=line.get_color())
                if m == "couplets" and "couplets_expected_random_mean" in s:
                    ax.plot(xs, s["couplets_expected_random_mean"], ls=":", color=line.get_color())
        ax.set_xlabel(xkey)
        name = metric_label(m, p.quality_lux)
        ax.set_ylabel(name + (" (Wilson 95 % interval)" if m == "yield" else "\nmean; band: 5th to 95th percentile"))
        title = f"{name} over {p.instances} instance(s) per point"
        if m == "couplets":
            title += "\n(dotted: expected at random)"
        if m == "yield":
            title = "yield: " + " and ".join(f"{s.metric} {s.op} {s.value:g}" for s in p.specs)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        if any(lab for lab in ax.get_legend_handles_labels()[1]):
            ax.legend(fontsize=8)
        fig.tight_layout()
        name = f"{m}.png"
        fig.savefig(out / name, bbox_inches="tight")  # long key names and labels are kept whole
        names.append(name)
    return names


def _index(p: Plan, summary, plots: list[str], out: Path) -> None:
    import html

    varied = ", ".join(" & ".join(a.keys) for a in p.axes) or "nothing (one point)"

    def table(metrics: tuple[str, ...], with_yield: bool) -> str:
        means = [f"{m}_mean" for m in metrics]
        shown = summary[[c for c in summary.columns if c in ("point", *p.keys, "instances") or c in means]].copy()
        if with_yield and "yield" in summary:  # the yield and its interval in one column
            shown.insert(len(p.keys) + 2, "yield", [f"{y:.2f} ({lo:.2f} to {hi:.2f})" for y, lo, hi in
                                                    zip(summary["yield"], summary["yield_lo"], summary["yield_hi"])])
        shown = shown.rename(columns=lambda c: metric_label(c[:-5], p.quality_lux) if c.endswith("_mean") else
                             ("yield (Wilson 95 %)" if c == "yield" else c))
        shown = shown.rename(columns=lambda c: re.sub(r"([_.])", "\\1\u200b", c))  # names break at _ and ., not mid-word
        return shown.to_html(index=False, float_format=lambda v: f"{v:.4g}", border=0)

    # the sensor's figures, and the image quality through the charts (--quality-lux) in a table of its own, so
    # that each fits a window
    tables = f'<div class="table">{table(METRICS, True)}</div>'
    if p.quality_lux is not None:
        tables += (f"<h2>Image quality at {p.quality_lux:g} lux</h2><p>Each instance through the test charts "
                   "(an 18 % grey, a slanted edge, the ColorChecker), as <code>cmosnoise quality</code> measures "
                   "them; the mean over the instances.</p>"
                   f'<div class="table">{table(quality_metrics(), False)}</div>')
    imgs = "\n".join(f'<figure><img src="{html.escape(n)}" alt="{html.escape(n)}"></figure>' for n in plots)
    (out / "index.html").write_text(f"""<!doctype html><html><head><meta charset="utf-8"><title>cmosnoise sweep</title>
<style>body{{font:14px system-ui,sans-serif;margin:20px}}figure{{display:inline-block;margin:4px;width:600px;max-width:100%;vertical-align:top}}
.table{{overflow-x:auto;max-width:100%}}table{{border-collapse:collapse;font-size:13px}}
td,th{{padding:2px 6px;border-bottom:1px solid #ddd;text-align:right}}th{{max-width:7.5em;font-weight:600;vertical-align:bottom}}
img{{width:100%;height:auto}}</style></head><body>
<h1>cmosnoise sweep</h1><p>Varied: {html.escape(varied)}; {p.instances} instance(s) per point; scene {html.escape(p.scene)}
({html.escape(p.scene_why)}).
Rows: results.csv; per point: summary.csv; the sweep itself: sweep.yaml.</p>
{tables}
{imgs}
</body></html>
""")


def run(base, vary: list[str], instances: int, out: str | Path | None = None, frames: int = 2, scene: str | None = None,
        specs: list[str] | None = None, scheduler: str | None = None, workers: int | None = None, resume: bool = False,
        overwrite: bool = False, progress=None, say: Callable[[str], None] = lambda m: None,
        metrics: list[str] | None = None, device: str = "cpu", quality_lux: float | None = None):
    """The Python API: run a sweep and return ``results.csv`` as a pandas DataFrame (sorted by point and instance).

    ``base`` is a Config (or anything :class:`~cmosnoise.Sensor` takes as a
    configuration); ``vary`` holds ``--vary`` texts. Without ``out`` the
    files go to a temporary folder that is removed afterwards. ``device``: where
    the workers make the frames (``"cuda"``: their GPU, numba's CUDA target; the same numbers).

    Parameters
    ----------
    base : Config, SensorSpec, dict, str or Path
        The base configuration.
    vary : list of str
        ``--vary`` values.
    instances : int
        Sensor instances per point.
    out : str or Path, optional
        The sweep's folder.
    frames, scene, specs, metrics, quality_lux
        As :func:`plan` takes them.
    scheduler, workers
        As :func:`connect` takes them.
    resume, overwrite : bool
        Continue the sweep in ``out``, or replace it.
    progress : callable, optional
        Called with (done, total).
    say : callable
        Told what is started.
    device : str
        "cpu" or "cuda".

    Returns
    -------
    pandas.DataFrame
    """
    import shutil
    import tempfile

    import pandas as pd

    from ..model.sensor import as_spec, check_device

    base = as_spec(base).config
    check_device(device, "--device")
    p = plan(base, vary, instances, frames, scene, specs, metrics, quality_lux)
    say(f"scene: {p.scene} ({p.scene_why})")
    tmp = None
    if out is None:
        tmp = tempfile.TemporaryDirectory(prefix="cmosnoise-sweep-")
        out = tmp.name
    out = Path(out)
    folder = OutputFolder(out, overwrite=True)  # its checks (not the current folder, writable, name); creates nothing
    mode = _mode(out, p, resume, overwrite)  # every check before the cluster starts
    try:
        with contextlib.ExitStack() as stack:
            # the folder is taken (locked) before the cluster starts: a second sweep on it is refused at once
            if mode == "replace":  # the old sweep stays whole until the new one is complete (simulate's rule)
                work = stack.enter_context(folder)
            else:  # a new folder, or --resume: rows go straight into out, so an interrupted sweep can be resumed
                stack.enter_context(folder.lock)
                mode = _mode(out, p, resume, overwrite)  # again, under the lock: another run may have written
                work = out
            client, cluster = connect(scheduler, workers, say)
            stack.callback(disconnect, client, cluster)

            def kept() -> str:
                if mode == "replace":
                    return f"nothing was written: {out} keeps the sweep it held"
                if not out.exists():
                    return ""
                rows = _rows_kept(out / "results.csv")  # the rows went straight into out: they stay, for --resume
                total = len(p.points) * p.instances
                return (f"{rows} of {total} rows kept in {out / 'results.csv'}; --resume completes them" if rows
                        else f"the sweep's plan kept in {out}; --resume starts it")

            try:
                with keeping(kept):
                    if mode != "resume":
                        work.mkdir(parents=True, exist_ok=True)
                        _write_plan(work, p)
                    execute(p, work, client, mode == "resume", progress, device)
                    check_terminated()
            except BaseException as exc:
                if mode == "new" and not (out / "results.csv").exists():
                    shutil.rmtree(out, ignore_errors=True)
                else:
                    note_kept(exc, kept())
                raise
            summarize(p, work)
    except OSError as exc:
        raise CmosnoiseError(f"--out {str(out)!r} cannot be written: {exc.strerror or exc}") from None
    df = pd.read_csv(out / "results.csv").sort_values(["point", "instance"]).reset_index(drop=True)
    if tmp is not None:
        tmp.cleanup()
    return df


class _NoAliases(yaml.SafeDumper):
    """sweep.yaml is read back with the loader that refuses aliases: never write one."""

    def ignore_aliases(self, data):
        return True


def _plan_text(p: Plan) -> str:
    return yaml.dump(p.to_yaml_data(), Dumper=_NoAliases, sort_keys=False, default_flow_style=None, width=100)


def _write_plan(folder: Path, p: Plan) -> None:
    tmpfile = folder / ".sweep.yaml.tmp"
    tmpfile.write_text(_plan_text(p))
    os.replace(tmpfile, folder / "sweep.yaml")


def _mode(out: Path, p: Plan, resume: bool, overwrite: bool) -> str:
    """"new" (no folder, or an empty one), "resume" (the same sweep's folder, --resume) or "replace" (--overwrite)."""
    return resumable_mode(out, "sweep.yaml", _plan_text(p), resume, overwrite, "sweep")


def sweep_from_yaml(path: Path) -> dict:
    """The options of a ``sweep.yaml`` (to rerun a sweep: ``cmosnoise sweep --from out/sweep.yaml``).

    Parameters
    ----------
    path : Path
        A sweep's ``sweep.yaml``.

    Returns
    -------
    dict
        ``base``, ``scene``, ``instances``, ``frames``, ``vary``, ``specs`` and ``quality_lux`` (None: none).
    """
    from .. import inputs

    text = inputs.read_text(path, "--from", 10_000_000)
    try:
        data = load_yaml_text(text)  # the strict loader: no aliases, bounded nesting
    except yaml.YAMLError as exc:
        raise CmosnoiseError(f"--from {str(path)!r} is not valid YAML: {' '.join(str(exc).split())[:200]}") from None
    if not isinstance(data, dict) or not isinstance(data.get("vary", []), list):
        raise CmosnoiseError(f"--from {str(path)!r} is not a sweep.yaml (a mapping with base, scene, instances, "
                             "frames and vary)")
    vary = []
    for a in data.get("vary", []):
        vals = ",".join("x".join(json.dumps(v) if isinstance(v, str) else repr(v) for v in step) for step in a["values"])
        vary.append(f"{','.join(a['keys'])}={vals}")
    return {"base": data["base"], "scene": data["scene"], "instances": data["instances"], "frames": data["frames"],
            "vary": vary, "specs": data.get("spec", []), "quality_lux": data.get("quality_lux")}
