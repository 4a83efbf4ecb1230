"""``cmosnoise compare RUN_A RUN_B``: two runs side by side, each difference weighed against sampling error.

A run is a ``cmosnoise simulate`` folder (``summary.json``, ``config.yaml``,
``preview.png``). Every figure both summaries hold is compared: the measured
signal and temporal noise, the key figures, the noise budget at the scene
mean, the dark-current map and its white pixels.

**Sampling error.** A run is one sensor instance (one seed) and one draw of
its frames, so even two runs of the same configuration differ. How much is
measured, not assumed: ``instances`` further instances of each run's
configuration (seeds ``SeedSequence(run seed, spawn_key=(1000 + i,))``, the
same scene, the run's frame count up to :data:`MAX_FRAMES`) go through the
same summary, and each figure's standard deviation over them is that run's
sampling error ``s``. A difference is beyond sampling error when
``|B - A| > Z_FLAG * sqrt(s_A^2 + s_B^2)``. A figure the instances do not move
(the saturation, a configured read noise) has no sampling error: any
difference of it is a difference of the configurations. Fewer frames than
the run's make the measured temporal noise spread more, never less: the test
errs towards "within sampling error".

**White pixels** are counted against one threshold in both runs:
``--white-threshold`` where given, else run A's (each temperature's own
threshold would make counts at 25 C and 65 C incomparable).
"""

from __future__ import annotations

import html
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import inputs
from ..analysis.figures_of_merit import FIGURE_NAMES
from ..analysis.noise_budget import SOURCE_NAMES
from ..analysis.run_stats import RunStats
from ..config import Config, load_config, merge_updates
from ..errors import CmosnoiseError
from ..io.output import OutputFolder, png_bytes, write_json
from ..model.sensor import Sensor
from ..model.spec import resolve
from .summary import build_summary
from .sweep import instance_seed

#: a difference is flagged beyond this many standard errors of the difference (with 8 instances a side, a
#: Student t of 14 degrees of freedom exceeds 4 with probability 0.0013: about one false flag in 20 comparisons
#: of 40 figures)
Z_FLAG = 4.0
#: instances per run that measure the sampling error
INSTANCES = 8
#: frames per instance at most (the run's own count where it is smaller)
MAX_FRAMES = 4
#: the instances' seeds are spawned from the run's seed past this offset (never the run's own stream)
SPAWN_OFFSET = 1000


@dataclass(frozen=True)
class Run:
    """A run folder: its summary, configuration and preview picture."""

    path: Path
    summary: dict
    config: Config

    @property
    def name(self) -> str:
        return self.path.name or str(self.path)


def load_run(path: str | Path, what: str) -> Run:
    """A ``cmosnoise simulate`` folder; one clear line when it is not one."""
    path = Path(path)
    if not path.is_dir():
        raise CmosnoiseError(f"{what} {str(path)!r}: no such folder (give a cmosnoise simulate output folder)")
    missing = [n for n in ("summary.json", "config.yaml") if not (path / n).is_file()]
    if missing:
        raise CmosnoiseError(f"{what} {str(path)!r} is not a cmosnoise simulate folder: it has no "
                             f"{' or '.join(missing)}")
    summary = inputs.read_json(path / "summary.json", f"{what}'s summary", MAX_SUMMARY_BYTES)
    _check_summary(summary, f"{what} {str(path / 'summary.json')!r}")
    return Run(path, summary, load_config(path / "config.yaml"))


#: the most pixels of a run's preview.png that are decoded (the pictures are left out past it)
MAX_PREVIEW_PIXELS = 100_000_000
#: the most bytes of a run's summary.json that are read (a run's own is some tens of kB)
MAX_SUMMARY_BYTES = 20_000_000
#: the parts of a summary that :func:`figures` reads: dotted path -> the JSON type it must have where present
_SUMMARY_PARTS = {"signal": dict, "temporal_noise": dict, "key_figures": dict, "noise_budget": dict,
                  "noise_budget.scene_mean": dict, "noise_budget.scene_mean.temporal_rms_e": dict,
                  "noise_budget.scene_mean.fixed_pattern_rms_e": dict, "key_figures.snr_temporal_db_at_signal_e": dict,
                  "key_figures.snr_total_db_at_signal_e": dict, "dark_current": dict, "dark_current.map": dict,
                  "dark_current.frame0": dict}
_SUMMARY_NEEDED = ("signal", "temporal_noise", "key_figures", "noise_budget.scene_mean.temporal_rms_e",
                   "noise_budget.scene_mean.fixed_pattern_rms_e")


def _check_summary(summary, name: str) -> None:
    """One line unless ``summary`` has the parts :func:`figures` reads, each of its type."""
    def part(key):
        v = summary
        for k in key.split("."):
            if not isinstance(v, dict) or k not in v:
                return None
            v = v[k]
        return v

    if not isinstance(summary, dict):
        raise CmosnoiseError(f"{name} is not a cmosnoise run summary (a JSON object)")
    for key in _SUMMARY_NEEDED:
        if part(key) is None:
            raise CmosnoiseError(f"{name} is not a cmosnoise run summary: it has no {key}")
    for key, kind in _SUMMARY_PARTS.items():
        v = part(key)
        if v is not None and not isinstance(v, kind):
            raise CmosnoiseError(f"{name}: {key} is a JSON {type(v).__name__}; a run summary's is an object")
    frames = summary.get("frames", 1)
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 1:
        raise CmosnoiseError(f"{name}: frames is {frames!r}; a run summary's is a whole number from 1")


# ------------------------------------------------------------------ the figures
def _label(key: str) -> str:
    parts = key.split(".")
    if parts[0] == "signal":
        return "mean signal, measured (e-)"
    if key == "temporal_noise.rms_e":
        return "temporal noise, measured (e- rms)"
    if key == "temporal_noise.predicted_rms_e":
        return "temporal noise at the scene, predicted (e- rms)"
    if parts[0] == "key_figures":
        name = FIGURE_NAMES.get(parts[1], parts[1])
        return name.replace("{level}", parts[2]) if len(parts) > 2 else name
    if parts[0] == "noise_budget":
        if parts[-1] == "fixed_pattern_total_e":
            return "budget: fixed pattern, total (e- rms)"
        kind = "fixed pattern" if parts[2] == "fixed_pattern_rms_e" else "temporal"
        return f"budget: {SOURCE_NAMES.get(parts[3], parts[3])}, {kind} (e- rms)"
    if parts[0] == "dark_current":
        if parts[1] == "map_mean_e_per_s":
            return "dark current, map mean (e-/s)"
        if parts[1] == "map_median_e_per_s":
            return "dark current, map median (e-/s)"
        where = "map" if parts[1] == "map" else "frame 0"
        return f"{FIGURE_NAMES.get(parts[2], parts[2])}, {where}"
    return key


def figures(summary: dict) -> dict[str, float]:
    """The compared figures of a summary, by dotted key (those it holds: a stage that is off has none)."""
    out: dict[str, float] = {}

    def put(key, value):
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
            out[key] = float(value)

    put("signal.mean_e", summary["signal"].get("mean_e"))
    put("temporal_noise.rms_e", summary["temporal_noise"].get("rms_e"))
    put("temporal_noise.predicted_rms_e", summary["temporal_noise"].get("predicted_rms_e"))
    kf = summary["key_figures"]
    for k in ("saturation_e", "dark_temporal_noise_e", "dynamic_range_db"):
        put(f"key_figures.{k}", kf.get(k))
    for k in ("snr_temporal_db_at_signal_e", "snr_total_db_at_signal_e"):
        for level, v in kf.get(k, {}).items():
            put(f"key_figures.{k}.{level}", v)
    nb = summary["noise_budget"]["scene_mean"]
    for group in ("temporal_rms_e", "fixed_pattern_rms_e"):
        for k, v in nb[group].items():
            put(f"noise_budget.scene_mean.{group}.{k}", v)
    put("noise_budget.scene_mean.fixed_pattern_total_e", nb.get("fixed_pattern_total_e"))
    dc = summary.get("dark_current") or {}
    put("dark_current.map_mean_e_per_s", dc.get("map_mean_e_per_s"))
    put("dark_current.map_median_e_per_s", dc.get("map_median_e_per_s"))
    for where in ("map", "frame0"):
        for k in ("white_pixels", "ppm", "couplets"):
            put(f"dark_current.{where}.{k}", (dc.get(where) or {}).get(k))
    return out


# ------------------------------------------------------------------ sampling error
def instance_summary(config: Config, seed: int, frames: int) -> dict:
    """The summary of one more instance of ``config`` (seed ``seed``, ``frames`` frames), made in memory as
    ``cmosnoise simulate`` makes a run's (nothing written)."""
    spec = resolve(merge_updates(config, {"seed": int(seed), "run": {"frames": int(frames)}}))
    sensor = Sensor(spec)
    shot = sensor.expose()
    stats = RunStats(sensor.transfer.max_code)
    electrons0 = None
    for raw, electrons in shot.frames_with_electrons(frames, spec.config.run.first_frame):
        stats.update(raw, electrons)
        if electrons0 is None:
            electrons0 = electrons
    return build_summary(sensor, shot, stats, 0.0, frames, electrons0)


def with_threshold(config: Config, threshold_e_per_s: float | None) -> Config:
    """``config`` counting white pixels against ``threshold_e_per_s`` (unchanged without one)."""
    if threshold_e_per_s is None or not config.dark_current.enabled:
        return config
    return merge_updates(config, {"dark_current": {"white_threshold_e_per_s": float(threshold_e_per_s),
                                                    "white_threshold_aA": None, "white_threshold_nA_per_cm2": None}})


def sampling_error(run: Run, config: Config, instances: int, advance: Callable[[], None] = lambda: None) -> dict:
    """Each figure's standard deviation over ``instances`` further instances of the run's configuration."""
    frames = max(1, min(int(run.summary.get("frames", 1)), MAX_FRAMES))
    draws: dict[str, list[float]] = {}
    for i in range(instances):
        seed = instance_seed(int(config.seed), SPAWN_OFFSET + i)
        for k, v in figures(instance_summary(config, seed, frames)).items():
            draws.setdefault(k, []).append(v)
        advance()
    return {k: float(np.std(v, ddof=1)) for k, v in draws.items() if len(v) == instances and instances > 1}


def recount(config: Config) -> dict:
    """A run's white pixels and couplets (its map and its frame 0) counted again against ``config``'s threshold:
    its map and frame 0 made again from its configuration, which they depend on alone (seed, frame index and
    parameters)."""
    again = figures(instance_summary(config, int(config.seed), 1))
    return {k: v for k, v in again.items() if k.startswith(("dark_current.map.", "dark_current.frame0."))}


# ------------------------------------------------------------------ the comparison
def compare(a: Run, b: Run, instances: int = INSTANCES, white_threshold_e_per_s: float | None = None,
            progress: Callable[[int, int], None] | None = None) -> dict:
    """Both runs' figures, their difference, its sampling error and whether it is beyond it.

    Returns ``{"rows": [...], "threshold": {...}, "instances": n, "z_flag": Z_FLAG, "flagged": [keys]}``; a row
    is ``{"key", "label", "a", "b", "difference", "relative", "sampling_error", "z", "beyond"}``
    (``sampling_error``: the standard deviation of the difference, sqrt(s_A^2 + s_B^2); ``z``: the difference
    over it, None where it is 0). ``progress(done, total)`` is told the further instances made.
    """
    if not isinstance(instances, int) or not 3 <= instances <= 1000:
        raise CmosnoiseError(f"--instances {instances!r}: give 3 to 1000 (the instances that measure the sampling "
                             "error)")
    thr_a = (a.summary.get("dark_current") or {}).get("threshold_e_per_s")
    thr_b = (b.summary.get("dark_current") or {}).get("threshold_e_per_s")
    thr = white_threshold_e_per_s if white_threshold_e_per_s is not None else thr_a if thr_a is not None else thr_b
    source = ("--white-threshold" if white_threshold_e_per_s is not None
              else f"run A's ({a.summary['dark_current'].get('threshold_source', '')})" if thr_a is not None
              else "run B's" if thr_b is not None else "none: dark current is off in both runs")
    cfg_a, cfg_b = with_threshold(a.config, thr), with_threshold(b.config, thr)
    fa, fb = figures(a.summary), figures(b.summary)
    for own, cfg, f in ((thr_a, cfg_a, fa), (thr_b, cfg_b, fb)):
        if thr is not None and own is not None and own != thr:  # counted against another threshold: count again
            f.update(recount(cfg))
    made = iter(range(1, 2 * instances + 1))  # the instances made, of both runs

    def advance() -> None:
        if progress:
            progress(next(made), 2 * instances)

    sa = sampling_error(a, cfg_a, instances, advance)
    sb = sampling_error(b, cfg_b, instances, advance)
    rows = []
    for key in [k for k in fa if k in fb]:
        va, vb = fa[key], fb[key]
        d = vb - va
        se = math.sqrt(sa.get(key, 0.0) ** 2 + sb.get(key, 0.0) ** 2)
        exact = se == 0.0
        scale = max(abs(va), abs(vb), 1e-300)
        beyond = abs(d) > 1e-9 * scale if exact else abs(d) > Z_FLAG * se
        rows.append({"key": key, "label": _label(key), "a": va, "b": vb, "difference": d,
                     "relative": d / va if va != 0 else None, "sampling_error": se,
                     "z": None if exact else d / se, "beyond": bool(beyond)})
    only = sorted(set(fa) ^ set(fb))
    return {"a": str(a.path), "b": str(b.path), "instances": instances, "z_flag": Z_FLAG,
            "threshold": {"e_per_s": thr, "source": source}, "rows": rows,
            "flagged": [r["key"] for r in rows if r["beyond"]], "only_in_one": only}


def _difference_picture(pa: np.ndarray, pb: np.ndarray) -> np.ndarray:
    """|B - A| of two previews (8-bit RGB), stretched so that the 99.9th percentile is white."""
    d = np.abs(pb.astype(np.int16) - pa.astype(np.int16)).astype(np.float32)
    top = float(np.percentile(d, 99.9)) or 1.0
    return np.clip(d * (255.0 / top), 0, 255).astype(np.uint8)


def _read_png(path: Path) -> np.ndarray | None:
    import imageio.v3 as iio

    try:
        inputs.check_image_pixels(path, "preview", MAX_PREVIEW_PIXELS)  # a run's own is at most the sensor's size
        img = iio.imread(path)
    except Exception:  # no preview (an older or partial folder, or one past the bound): the pictures are left out
        return None
    return img[..., :3] if img.ndim == 3 else np.repeat(img[..., None], 3, axis=2)


def text_table(result: dict) -> str:
    """The comparison as plain text (what the command line prints and compare.txt holds)."""
    head = ("figure", "A", "B", "B - A", "sampling error", "beyond?")
    rows = [(r["label"], f"{r['a']:.5g}", f"{r['b']:.5g}", f"{r['difference']:+.4g}",
             "exact" if r["z"] is None else f"{r['sampling_error']:.3g}", "YES" if r["beyond"] else "")
            for r in result["rows"]]
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(head)]
    line = lambda cells: "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))  # noqa: E731
    out = [f"A: {result['a']}", f"B: {result['b']}",
           f"sampling error: standard deviation over {result['instances']} further instances of each run; "
           f"beyond it: |B - A| > {result['z_flag']:g} x sqrt(s_A^2 + s_B^2)",
           f"white pixels counted above {result['threshold']['e_per_s']:.4g} e-/s, {result['threshold']['source']}"
           if result["threshold"]["e_per_s"] is not None else "white pixels: none (dark current off)", "",
           line(head), line(["-" * w for w in widths]), *(line(r) for r in rows), "",
           f"{len(result['flagged'])} of {len(result['rows'])} figures differ beyond sampling error"]
    if result["only_in_one"]:
        out.append("in one run only (a stage off in the other): " + ", ".join(result["only_in_one"]))
    return "\n".join(out) + "\n"


def _html(result: dict, pictures: dict[str, bytes]) -> str:
    import base64

    def fmt(v, spec):
        return "" if v is None else format(v, spec)

    body = "".join(
        f"<tr class=\"{'beyond' if r['beyond'] else ''}\"><td>{html.escape(r['label'])}</td>"
        f"<td>{fmt(r['a'], '.5g')}</td><td>{fmt(r['b'], '.5g')}</td><td>{fmt(r['difference'], '+.4g')}</td>"
        f"<td>{fmt(100 * r['relative'] if r['relative'] is not None else None, '+.3g')}</td>"
        f"<td>{'exact' if r['z'] is None else fmt(r['sampling_error'], '.3g')}</td>"
        f"<td>{'' if r['z'] is None else fmt(r['z'], '+.2f')}</td><td>{'beyond' if r['beyond'] else ''}</td></tr>"
        for r in result["rows"])
    figs = "".join(f'<figure><img src="data:image/png;base64,{base64.b64encode(png).decode()}" alt="{html.escape(name)}">'
                   f"<figcaption>{html.escape(name)}</figcaption></figure>" for name, png in pictures.items())
    thr = result["threshold"]
    thr_text = (f"White pixels are counted above {thr['e_per_s']:.4g} e-/s in both runs: {html.escape(thr['source'])}."
                if thr["e_per_s"] is not None else "")
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>cmosnoise compare</title>
<style>body{{font:14px system-ui,sans-serif;margin:20px;max-width:1400px}}table{{border-collapse:collapse}}
td,th{{padding:2px 10px;border-bottom:1px solid #ddd;text-align:right}}td:first-child,th:first-child{{text-align:left}}
tr.beyond td{{background:#fde2e1;font-weight:600}}figure{{display:inline-block;margin:4px;width:400px;max-width:100%;vertical-align:top}}
img{{width:100%;height:auto;image-rendering:pixelated}}</style></head><body>
<h1>cmosnoise compare</h1>
<p>A: {html.escape(result['a'])}<br>B: {html.escape(result['b'])}</p>
<p><strong>{len(result['flagged'])} of {len(result['rows'])}</strong> figures differ beyond sampling error. The sampling error
of a figure is its standard deviation over {result['instances']} further instances (seeds) of each run's configuration; a
difference is marked when |B - A| exceeds {result['z_flag']:g} times sqrt(s_A<sup>2</sup> + s_B<sup>2</sup>). "exact": the
instances do not move the figure, so any difference is one of the configurations. {thr_text}</p>
<table><tr><th>figure</th><th>A</th><th>B</th><th>B - A</th><th>%</th><th>sampling error</th><th>z</th><th></th></tr>
{body}</table>
<h2>Frame 0</h2>{figs or "<p>(no preview.png in one of the runs)</p>"}
</body></html>
"""


def run(path_a: str | Path, path_b: str | Path, out: str | Path | None = None, instances: int = INSTANCES,
        white_threshold_e_per_s: float | None = None, overwrite: bool = False,
        progress: Callable[[int, int], None] | None = None) -> dict:
    """Compare two run folders; with ``out``, write compare.txt, compare.json and compare.html there (whole or not
    at all). Returns :func:`compare`'s result."""
    a, b = load_run(path_a, "RUN_A"), load_run(path_b, "RUN_B")
    folder = OutputFolder(out, overwrite) if out is not None else None  # its checks before the work
    result = compare(a, b, instances, white_threshold_e_per_s, progress)
    if folder is None:
        return result
    pa, pb = _read_png(a.path / "preview.png"), _read_png(b.path / "preview.png")
    pictures = {}
    if pa is not None and pb is not None:
        pictures = {f"A: {a.name}": png_bytes(pa), f"B: {b.name}": png_bytes(pb)}
        if pa.shape == pb.shape:
            pictures["|B - A|, stretched to the 99.9th percentile"] = png_bytes(_difference_picture(pa, pb))
    with folder as tmp:
        (tmp / "compare.txt").write_text(text_table(result))
        write_json(tmp / "compare.json", result)
        (tmp / "compare.html").write_text(_html(result, pictures))
    return result
