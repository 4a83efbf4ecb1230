"""``cmosnoise evaluate``: score denoisers and defect correctors on a generated data set, beside baselines.

A method is a built-in baseline (:data:`BASELINES`), a Python callable
``module:function`` (raw in, raw out: ``f(raw)`` or ``f(raw, meta)`` with
the sample's settings), or the outputs a method already wrote
(``--outputs DIR``: ``sample_NNNNNN.npy`` or ``.tif``, one per sample). Each
method runs on every sample of the set; the scores come from
:mod:`cmosnoise.analysis.scoring`: PSNR and SSIM against the truth, and
defects left by kind. Written: ``scores.csv`` (a row per sample and
method), ``summary.csv`` (per method, camera, mode and light level),
plots, and ``report.html`` (self-contained).
"""

from __future__ import annotations

import html
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .. import inputs
from .._version import __version__
from ..analysis import scoring
from ..errors import CmosnoiseError
from ..isp import calibration
from ..isp import defects as isp_defects
from . import dataset as ds
from . import plots

#: the built-in methods: name -> what it is
BASELINES = {
    "none": "the noisy frame itself (what every method must beat)",
    "median": "the single-defect corrector of a typical ISP: a pixel outside its same-colour neighbours' range by "
              "6 robust sigmas is replaced by their median (isp.defects.correct_isolated)",
    "dark-map": "a defect map from 8 dark frames of the sample's sensor (6 robust sigmas above the master dark's "
                "median); mapped pixels replaced by their healthy same-colour neighbours' median "
                "(isp.defects.correct_with_map); dead and gain pixels, dark in the dark, stay off the map",
    "gaussian": "a Gaussian blur of each CFA colour plane, sigma 1 plane pixel (scipy.ndimage): a plain denoiser",
    "bm3d": "BM3D (the bm3d package of its authors, Tampere University; the extra cmosnoise[bm3d]) on each CFA "
            "colour plane, its noise sigma estimated from the plane (scikit-image's estimate_sigma): a strong "
            "classical denoiser, about a second per 128 x 128 plane",
}
#: the baselines run when no --method is given (bm3d is slow: asked for by name)
DEFAULT_METHODS = ("none", "median", "dark-map", "gaussian")
#: light levels the summary groups samples by, e- at the scene's white
LIGHT_BINS = (0, 100, 1000, math.inf)
#: dark frames the dark-map baseline averages
DARK_FRAMES = 8


def _user_method(spec: str) -> Callable:
    if ":" not in spec:
        raise CmosnoiseError(f"--method {spec!r}: give a built-in ({', '.join(BASELINES)}) or module:function")
    return isp_defects.load_corrector(spec, "--method")


def _gaussian(raw: np.ndarray, meta: dict) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    out = raw.astype(np.float64)
    cells, step = _planes_of(raw, meta)
    for i, j in cells:
        out[i::step, j::step] = gaussian_filter(out[i::step, j::step], 1.0, mode="reflect")
    return out


def _planes_of(raw: np.ndarray, meta: dict):
    step = 1 if meta["cfa"] == "none" else 2
    return [(i, j) for i in range(step) for j in range(step)], step


def _bm3d(raw: np.ndarray, meta: dict) -> np.ndarray:
    try:
        import bm3d
    except ImportError:
        raise CmosnoiseError("--method bm3d needs the bm3d package: pip install 'cmosnoise[bm3d]'") from None
    from skimage.restoration import estimate_sigma

    black, white = meta["black_level_dn"], meta["white_level_dn"]
    x = (raw.astype(np.float64) - black) / (white - black)
    out = x.copy()
    cells, step = _planes_of(raw, meta)
    for i, j in cells:
        plane = x[i::step, j::step]
        sigma = float(estimate_sigma(plane))
        if sigma > 0:
            out[i::step, j::step] = bm3d.bm3d(plane, sigma)
    return out * (white - black) + black


def _median(raw: np.ndarray, meta: dict) -> np.ndarray:
    return isp_defects.correct_isolated(raw.astype(np.float64), meta["cfa"])[0]


def _dark_map(raw: np.ndarray, meta: dict) -> np.ndarray:
    from ..model.sensor import Sensor

    sensor = Sensor(ds.load_sample_config(meta["config"]))
    dark = calibration.master_dark(sensor.dark_frames(DARK_FRAMES)) - meta["black_level_dn"]
    return isp_defects.correct_with_map(raw.astype(np.float64), meta["cfa"], isp_defects.defect_map(dark))


def method(spec: str) -> Callable:
    """The callable ``(raw, meta) -> output`` of a --method."""
    return {"none": lambda raw, meta: raw.astype(np.float64), "median": _median, "dark-map": _dark_map,
            "gaussian": _gaussian, "bm3d": _bm3d}.get(spec) or _user_method(spec)


def _read_output(folder: Path, index: int, shape: tuple[int, int]) -> np.ndarray:
    """A method's output for sample ``index``, read only where its header says it is one frame of ``shape``."""
    for suffix in (".npy", ".tif", ".tiff"):
        p = folder / f"sample_{index:06d}{suffix}"
        if p.exists() or p.is_symlink():
            rows, cols, planes = inputs.check_image_pixels(p, "--outputs file", inputs.MAX_FRAME_PIXELS)
            if (rows, cols, planes) != (*shape, 1):
                raise CmosnoiseError(f"--outputs file {str(p)!r} is {cols} x {rows} in {planes} plane(s); sample "
                                     f"{index} is one {shape[1]} x {shape[0]} frame")
            try:
                if suffix == ".npy":
                    return np.load(p, allow_pickle=False)
                import tifffile

                return tifffile.imread(p, key=0)
            except Exception as exc:
                raise CmosnoiseError(f"--outputs file {str(p)!r} cannot be read: "
                                     f"{inputs.decoder_message(exc)}") from None
    raise CmosnoiseError(f"--outputs {str(folder)!r} has no sample_{index:06d}.npy or .tif")


def score(data: str | Path, methods: list[str], outputs: str | Path | None = None, target: str = "expected",
          progress: Callable[[int, int], None] | None = None):
    """Every method on every sample of the data set ``data``: a pandas DataFrame, a row per (sample, method)."""
    import pandas as pd

    data = Path(data)
    total = ds.read_manifest(data)["recipe"]["samples"]  # checked: a JSON object of a recipe and its shards
    if target not in ("expected", "perfect"):
        raise CmosnoiseError(f"--target {target!r}: expected (the expected raw) or perfect (the perfect image)")
    runs = {m: method(m) for m in methods}
    if outputs is not None:
        outputs = Path(outputs)
        if not outputs.is_dir():
            raise CmosnoiseError(f"--outputs {str(outputs)!r} is not a folder")
        runs["outputs"] = lambda raw, meta: _read_output(outputs, meta["sample"], raw.shape)
    rows, done = [], 0
    for arrays, columns in ds.read(data):
        for i in range(len(arrays["raw"])):
            meta = {k: (v[i].item() if isinstance(v[i], np.generic) else v[i]) for k, v in columns.items()}
            raw = arrays["raw"][i]
            if target == "expected":  # the expected raw without its defects
                truth = scoring.defect_free(arrays["expected_raw"][i], arrays["mask"][i], meta["cfa"])
            else:
                truth = arrays["perfect_dn"][i]
            for name, run in runs.items():
                out = isp_defects.run_corrector(run, raw, meta, f"method {name!r} on sample {meta['sample']}")
                row = {"sample": meta["sample"], "method": name, "camera": meta["camera"], "mode": meta["mode"],
                       "iso": meta["iso"], "gain_db": meta["gain_db"], "k_dn_per_e": meta["k_dn_per_e"],
                       "light_e": meta["light_e"], "ratio": _ratio(meta), "clipped_share": meta.get("clipped_share", 0.0),
                       "source": meta["source"],
                       **scoring.image_scores(out, truth, meta["black_level_dn"], meta["white_level_dn"],
                                              _ratio(meta), meta["cfa"])}
                left = scoring.defects_left(raw, out, arrays["expected_raw"][i], arrays["mask"][i], meta["cfa"])
                for kind, v in left.items():
                    row[f"{kind}_visible"], row[f"{kind}_left"] = v["visible"], v["left"]
                rows.append(row)
            done += 1
            if progress:
                progress(done, total)
    return pd.DataFrame(rows)


#: a sample with more of its pixels at the white level than this is left out of the tables (counted): its scores
#: measure the clip, not the method
MAX_CLIPPED_SHARE = 0.01


def _ratio(meta: dict) -> float:
    """A sample's exposure ratio (1 for a data set made before ratios were recorded)."""
    r = meta.get("ratio", 1.0)
    return float(r) if r is not None and math.isfinite(float(r)) and float(r) >= 1 else 1.0


def scored(scores):
    """The rows the tables average: samples that do not clip (:data:`MAX_CLIPPED_SHARE`), and how many were left
    out."""
    keep = scores["clipped_share"].fillna(0.0) <= MAX_CLIPPED_SHARE
    return scores[keep], int(scores.loc[~keep, "sample"].nunique())


def _means() -> dict:
    """Each image score of :data:`.scoring.SCORES` as a pandas aggregation: its mean, under its own name."""
    return {name: (name, "mean") for name, *_ in scoring.SCORES}


def summarize(scores):
    """Per method, camera, mode and light level: each image score's mean over the samples that do not clip
    (:func:`scored`; NaN scores, an output equal to its target, left out), and the defects visible and left by
    kind."""
    s = scored(scores)[0].copy()
    s["light"] = _light_bin(s["light_e"])
    counts = [c for c in s.columns if c.endswith("_visible") or c.endswith("_left")]
    g = s.groupby(["method", "camera", "mode", "light"], sort=True, dropna=False)
    out = g.agg(samples=("sample", "count"), **_means(), **{c: (c, "sum") for c in counts}).reset_index()
    return out


def scene_table(scores):
    """Mean PSNR (dB) per source image (rows) and method (columns), with each source's number of samples.

    Parameters
    ----------
    scores : pandas.DataFrame
        :func:`score`'s rows (``source``, ``method``, ``psnr_raw_db``, ``sample``).

    Returns
    -------
    pandas.DataFrame
        Indexed by source; a column per method, in the scores' order, and ``samples``.
    """
    methods = list(dict.fromkeys(scores["method"]))
    scores = scored(scores)[0]
    table = scores.pivot_table(index="source", columns="method", values="psnr_raw_db",
                               aggfunc="mean").reindex(columns=methods)  # a method's column kept if all NaN
    table.columns.name = None
    table["samples"] = scores.groupby("source")["sample"].nunique()
    return table


def _light_bin(light):
    import pandas as pd

    labels = [f"{lo:g}-{hi:g} e-" if math.isfinite(hi) else f">{lo:g} e-" for lo, hi in zip(LIGHT_BINS, LIGHT_BINS[1:])]
    return pd.cut(light, LIGHT_BINS, labels=labels, right=False).astype(str)


def gain_label(iso, gain_db, mode) -> str:
    """A sample's gain as the PSNR plot names it: ``ISO 1600``, ``3 dB``, with its mode (``HCG``) where it has one;
    ``""`` for a camera without a gain table (a virtual camera's samples)."""
    parts = []
    if iso is not None and math.isfinite(float(iso)):
        parts.append(f"ISO {float(iso):g}")
    elif gain_db is not None and math.isfinite(float(gain_db)):
        parts.append(f"{float(gain_db):g} dB")
    if isinstance(mode, str) and mode:
        parts.append(mode)
    return " ".join(parts)


def psnr_figure(scores):
    """PSNR against light, a panel per camera, a series per method and gain (colour: the method; marker: the
    gain), on one light axis shared by the panels.

    Parameters
    ----------
    scores : pandas.DataFrame
        :func:`score`'s rows.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.lines import Line2D

    kept = scored(scores)[0].copy()
    cameras = list(dict.fromkeys(scores["camera"]))
    methods = list(dict.fromkeys(scores["method"]))
    cols = min(3, len(cameras))
    rows = -(-len(cameras) // cols)
    fig, axes = plots.figure(rows, cols, figsize=(4.6 * cols, 3.6 * rows), sharex=True, sharey=True, squeeze=False,
                             layout="constrained")
    lo, hi = float(scores["light_e"].min()), float(scores["light_e"].max())
    kept["gain"] = [gain_label(i, g, m) for i, g, m in zip(kept["iso"], kept["gain_db"], kept["mode"])]
    markers, colours = "osD^v<>ph*", [f"C{j}" for j in range(10)]
    for ax, camera in zip(axes.flat, cameras):
        ax.set_xscale("log")
        ax.set_xlim(lo / 1.5, hi * 1.5)  # set first: one light level alone would make an empty range
        ax.set_autoscalex_on(False)
        of = kept[kept["camera"] == camera]
        gains = sorted(set(of["gain"]), key=lambda g: (len(g), g))
        for (name, gain), g in of.groupby(["method", "gain"], sort=False):
            g = g.sort_values("light_e")
            ax.plot(g["light_e"], g["psnr_raw_db"], markers[gains.index(gain) % len(markers)], ms=4, alpha=0.75,
                    color=colours[methods.index(name) % len(colours)],
                    **({"mfc": "none", "zorder": 3} if name == "none" else {}))  # the noisy input hollow, on top
        ax.set_title(camera, fontsize=10)
        ax.grid(alpha=0.3)
        if len(of):  # a legend of colours (the methods) and one of markers (this camera's gains)
            handles = [Line2D([], [], ls="", marker="o", ms=5, color=colours[j % len(colours)], label=m,
                              mfc="none" if m == "none" else None)
                       for j, m in enumerate(methods) if m in set(of["method"])]
            handles += [Line2D([], [], ls="", marker=markers[j % len(markers)], ms=5, color="0.35", label=gain)
                        for j, gain in enumerate(gains) if gain]
            ax.legend(handles=handles, fontsize=7, ncol=1 + (len(handles) > 9))
        else:
            ax.text(0.5, 0.5, "every sample clips", transform=ax.transAxes, ha="center", va="center", color="0.3")
    for ax in axes.flat[len(cameras):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("light at the scene's white (e-)")
    for ax in axes[:, 0]:
        ax.set_ylabel("PSNR, packed raw at the ratio (dB)")
    return fig


def _plots(scores) -> dict[str, bytes]:
    out = {"psnr_vs_light.png": plots.to_png_bytes(psnr_figure(scores))}
    fig, ax = plots.figure(figsize=(6.4, 3.4))
    methods = list(dict.fromkeys(scores["method"]))
    kinds = list(scoring.KINDS)
    width = 0.8 / max(1, len(methods))
    for j, name in enumerate(methods):
        g = scores[scores["method"] == name]
        frac = [g[f"{k}_left"].sum() / max(1, g[f"{k}_visible"].sum()) for k in kinds]
        ax.bar(np.arange(len(kinds)) + j * width, frac, width, label=name)
    ax.set_xticks(np.arange(len(kinds)) + 0.4 - width / 2, kinds)
    ax.set_ylabel("visible defects left (fraction)")
    ax.set_ylim(0, 1.05)
    if not any(scores[f"{k}_visible"].sum() for k in kinds):  # an empty chart would read as "every one removed"
        ax.text(0.5, 0.5, "no defect is visible in these samples' noisy frames", transform=ax.transAxes,
                ha="center", va="center", fontsize=9, color="0.3")
    ax.legend(fontsize=8)
    out["defects_left.png"] = plots.to_png_bytes(fig)
    return out


def report_html(scores, summary, pictures: dict[str, bytes], data: Path, target: str) -> str:
    manifest = ds.read_manifest(data)
    r = manifest["recipe"]
    kept, left_out = scored(scores)
    per_method = kept.groupby("method", sort=False).agg(
        **_means(), **{c: (c, "sum") for c in scores.columns if c.endswith("_visible") or c.endswith("_left")})
    per_scene = scene_table(scores)

    def cell(v) -> str:  # numbers right-aligned, floats to 4 digits
        if isinstance(v, (float, np.floating)):
            return f"<td class='num'>{v:.4g}</td>"
        if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
            return f"<td class='num'>{v}</td>"
        return f"<td>{html.escape(str(v))}</td>"

    def table(df) -> str:
        head = "".join(f"<th>{html.escape(str(c))}</th>" for c in [df.index.name or "", *df.columns])
        body = "".join(f"<tr><td>{html.escape(str(i))}</td>" + "".join(cell(v) for v in row) + "</tr>"
                       for i, row in zip(df.index, df.itertuples(index=False)))
        return f"<table><tr>{head}</tr>{body}</table>"

    methods = "".join(f"<li><b>{html.escape(m)}</b>: {html.escape(BASELINES.get(m, 'your method'))}</li>"
                      for m in per_method.index)
    # the PSNR plot has a panel per camera: the page's width, the others side by side
    figs = "".join(f"<figure{' class=wide' if name.startswith('psnr') else ''}><img src='{plots.data_uri(png)}' "
                   f"alt='{html.escape(name)}'>"
                   f"<figcaption>{html.escape(name)}</figcaption></figure>" for name, png in pictures.items())
    css = ("body{font-family:sans-serif;max-width:1100px;margin:1em auto;color:#222}table{border-collapse:collapse;"
           "font-size:13px;margin:.5em 0}td,th{border:1px solid #ccc;padding:2px 6px}td.num{text-align:right}"
           "figure{display:inline-block;margin:.5em}img{max-width:520px}figure.wide{display:block}figure.wide img{max-width:100%}")
    return (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>cmosnoise evaluation</title>"
            f"<style>{css}</style></head><body><h1>cmosnoise evaluation</h1>"
            f"<p>cmosnoise {__version__}; data set {html.escape(str(data))}: {r['samples']} samples of "
            f"{r['crop'][0]} x {r['crop'][1]}, cameras {html.escape(', '.join(r['cameras']))}, "
            + (f"light {r['light_e'][0]:g} to {r['light_e'][1]:g} e-" if r.get("light_e") else
               f"white at {r.get('level', [0, 0])[0]:g} to {r.get('level', [0, 0])[1]:g} of each camera's "
               "saturation")
            + f". PSNR and SSIM as the low-light raw denoising literature reports them: packed raw, black "
            f"subtracted, normalised to white, amplified by each sample's exposure ratio and clipped to [0, 1] "
            f"(psnr_raw_db, ssim_raw), the same through a fixed sRGB pipeline (psnr_srgb_db, ssim_srgb), and over "
            f"the whole code range without a ratio (psnr_code_range_db); {left_out} sample(s) with more than "
            f"{MAX_CLIPPED_SHARE:.0%} of their pixels at the white level left out of the tables; PSNR and SSIM "
            f"against the "
            f"{'expected raw without its defects (the fixed pattern kept)' if target == 'expected' else 'perfect image'}; a defect is "
            f"visible when the noisy frame departs from its healthy neighbours by {scoring.Z_VISIBLE:g} robust "
            f"sigmas, left when the output still does, counted in pixels by kind ({', '.join(scoring.KINDS)}). "
            f"A defect map made from dark frames (dark-map) cannot see dead or gain pixels: in the dark they "
            f"read as their neighbours do, so it leaves them; they are counted apart from the white pixels it "
            f"removes.</p><h2>Methods</h2><ul>{methods}</ul>"
            f"<h2>Per method</h2>{table(per_method)}<h2>Plots</h2>{figs}"
            f"<h2>Per scene</h2><p>Mean PSNR (dB) of each method on the samples cut from each source image: a "
            f"denoiser that blurs loses most on fine detail (the zone plate's rings beyond a colour plane's "
            f"Nyquist frequency, the Siemens star's centre).</p>{table(per_scene)}"
            f"<h2>Per method, camera, mode and light level</h2>{table(summary.set_index('method'))}</body></html>")


def run(data: str | Path, methods: list[str], out: str | Path, outputs: str | Path | None = None,
        target: str = "expected", overwrite: bool = False, progress=None) -> Path:
    """Score ``methods`` on the data set ``data``; write scores.csv, summary.csv, the plots and report.html to ``out``."""
    from ..io.output import OutputFolder

    folder = OutputFolder(out, overwrite=overwrite)
    for m in methods:  # every method loads before any work
        method(m)
    scores = score(data, methods, outputs, target, progress)
    summary = summarize(scores)
    pictures = _plots(scores)
    with folder as tmp:
        scores.to_csv(tmp / "scores.csv", index=False)
        summary.to_csv(tmp / "summary.csv", index=False)
        for name, png in pictures.items():
            (tmp / name).write_bytes(png)
        (tmp / "report.html").write_text(report_html(scores, summary, pictures, Path(data), target))
    return Path(out)
