"""``cmosnoise quality``: a sensor and its processing through the test charts at a list of illuminances.

The measurements are :mod:`cmosnoise.analysis.quality`'s (its :data:`~cmosnoise.analysis.quality.METRICS` table
is what every output iterates); this module writes what a user keeps: ``quality.json``, ``quality.csv`` (one row
per illuminance), the plots (SNR and visual noise against lux, the MTF curve, the ColorChecker's errors) and a
self-contained ``report.html``. With a second configuration (``--compare``) both are measured on ``instances``
sensor instances (seeds 0, 1, ...; the same seed gives both the same random numbers wherever their parameters
agree, so the differences are paired) and each difference is given with its standard error over the instances.
"""

from __future__ import annotations

import csv
import datetime
import html
import io
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .._version import __version__
from ..analysis import quality
from ..errors import CmosnoiseError
from ..io.output import OutputFolder, write_json
from . import plots
from .report import CSS, _figure, _table

#: the illuminances a run takes by default, lux: a dim room to daylight shade
DEFAULT_LUX = (1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)
#: a difference is called clear where it exceeds this many of its standard errors
CLEAR_Z = 3.0


def run(config, out: Path, overwrite: bool = False, lux=DEFAULT_LUX, frames: int = 8, seed: int = 0,
        compare=None, instances: int = 3, names: tuple[str, str] = ("A", "B"), compare_from: str = "",
        picture_height_cm: float = quality.visual_noise.PICTURE_HEIGHT_CM,
        viewing_distance_cm: float = quality.visual_noise.VIEWING_DISTANCE_CM,
        display_pixel_pitch_mm: float = quality.visual_noise.DISPLAY_PIXEL_PITCH_MM,
        display_distance_cm: float = quality.visual_noise.DISPLAY_DISTANCE_CM, colour_reference: str = "spectral",
        progress: Callable[[int, int], None] | None = None) -> dict:
    """Measure ``config`` (and ``compare``) and write the folder ``out``; returns the document of quality.json.

    Parameters
    ----------
    config, compare : Config
        The sensor(s); ``compare`` None: one sensor, instance ``seed``.
    out : Path
        The output folder (whole or absent).
    lux : sequence of float
        Illuminances, increasing, lux.
    frames : int
        Frames of each chart at each illuminance.
    instances : int
        With ``compare``: sensor instances (seeds 0 to instances - 1), at least 2.
    names : (str, str)
        What the two are called in tables and plots.
    compare_from : str
        Where the second configuration came from, for the summary (e.g. "A with sensor.temperature_c=65").
    picture_height_cm, viewing_distance_cm, display_pixel_pitch_mm, display_distance_cm, colour_reference
        The viewing conditions and the colour error's reference (:func:`cmosnoise.analysis.quality.measure`).
    progress : callable, optional
        ``progress(done, total)``, told after each measured sensor instance.
    """
    folder = OutputFolder(out, overwrite)
    kw = {"frames": frames, "picture_height_cm": picture_height_cm, "viewing_distance_cm": viewing_distance_cm,
          "display_pixel_pitch_mm": display_pixel_pitch_mm, "display_distance_cm": display_distance_cm,
          "colour_reference": colour_reference}
    if compare is None:
        a = quality.measure(config, lux, seed=seed, **kw)
        if progress:
            progress(1, 1)
        doc = {"a": a, "b": None, "difference": None, "names": list(names)}
    else:
        if instances < 2:
            raise CmosnoiseError(f"--instances {instances}: a comparison's spread needs at least 2 sensor instances")
        runs = {"a": [], "b": []}
        for s in range(instances):
            for key, cfg in (("a", config), ("b", compare)):
                runs[key].append(quality.measure(cfg, lux, seed=s, **kw))
                if progress:
                    progress(2 * s + (key == "b") + 1, 2 * instances)
        doc = {"a": runs["a"][0], "b": runs["b"][0], "difference": difference(runs["a"], runs["b"]),
               "instances": instances, "names": list(names), "compare_from": compare_from}
    doc["cmosnoise_version"] = __version__
    doc["sources"] = {m.name: m.source for m in quality.METRICS}
    with folder as tmp:
        write_json(tmp / "quality.json", doc)
        (tmp / "quality.csv").write_text(table_csv(doc))
        pngs = {"snr.png": snr_plot(doc), "visual_noise.png": visual_plot(doc)}
        if doc["a"].get("sfr"):
            pngs["mtf.png"] = mtf_plot(doc)
        if doc["a"].get("colour"):
            pngs["colorchecker.png"] = colour_plot(doc)
        for name, png in pngs.items():
            (tmp / name).write_bytes(png)
        (tmp / "report.html").write_text(build_report(doc, pngs), encoding="utf-8")
    return doc


def difference(a_runs: list[dict], b_runs: list[dict]) -> dict:
    """Each metric's B - A at each illuminance over paired instances: mean, standard error (the paired
    differences' sample standard deviation over sqrt(n)) and whether it is clear (``|mean| > CLEAR_Z se``)."""
    out = {}
    for name in a_runs[0]["metrics"]:
        rows = []
        for i in range(len(a_runs[0]["lux"])):
            d = [b["metrics"][name][i] - a["metrics"][name][i] for a, b in zip(a_runs, b_runs)
                 if a["metrics"][name][i] is not None and b["metrics"][name][i] is not None]
            if len(d) < 2:
                rows.append({"mean": None, "se": None, "clear": False})
                continue
            mean, se = float(np.mean(d)), float(np.std(d, ddof=1) / math.sqrt(len(d)))
            rows.append({"mean": mean, "se": se, "clear": bool(abs(mean) > CLEAR_Z * se) if se > 0 else mean != 0})
        out[name] = rows
    for key in ("snr10_lux", "snr1_lux"):
        d = [b[key] - a[key] for a, b in zip(a_runs, b_runs) if a.get(key) is not None and b.get(key) is not None]
        out[key] = ({"mean": float(np.mean(d)), "se": float(np.std(d, ddof=1) / math.sqrt(len(d)))}
                    if len(d) >= 2 else None)
    return out


def _cell(v, digits: int = 3) -> str:
    if v is None:
        return "n/a"
    return f"{v:.{digits}g}"


def table_csv(doc: dict) -> str:
    """One row per illuminance: each metric of A (and B, and B - A with its standard error)."""
    buf = io.StringIO()
    w = csv.writer(buf)
    names = [m.name for m in quality.METRICS if m.name in doc["a"]["metrics"]]
    head = ["lux"] + [f"{doc['names'][0]}:{n}" for n in names]
    if doc["b"] is not None:
        head += [f"{doc['names'][1]}:{n}" for n in names] + [f"diff:{n}" for n in names] + [f"diff_se:{n}" for n in names]
    w.writerow(head)
    for i, v in enumerate(doc["a"]["lux"]):
        row = [v] + [doc["a"]["metrics"][n][i] for n in names]
        if doc["b"] is not None:
            row += [doc["b"]["metrics"][n][i] for n in names]
            row += [doc["difference"][n][i]["mean"] for n in names] + [doc["difference"][n][i]["se"] for n in names]
        w.writerow(["" if x is None else x for x in row])
    return buf.getvalue()


def console_rows(doc: dict) -> tuple[list[str], list[list[str]]]:
    """The console's table: a column per illuminance, a row per metric (B's and B - A's under A's)."""
    lux = doc["a"]["lux"]
    head = ["metric", "unit"] + [f"{v:g}" for v in lux]
    rows = []
    for m in quality.METRICS:
        if m.name not in doc["a"]["metrics"]:
            continue
        rows.append([m.label if doc["b"] is None else f"{m.label} ({doc['names'][0]})", m.unit]
                    + [_cell(x) for x in doc["a"]["metrics"][m.name]])
        if doc["b"] is not None:
            rows.append([f"  {doc['names'][1]}", m.unit] + [_cell(x) for x in doc["b"]["metrics"][m.name]])
            rows.append([f"  {doc['names'][1]} - {doc['names'][0]}", m.unit]
                        + [("n/a" if d["mean"] is None else f"{d['mean']:+.3g} ± {d['se']:.2g}" + (" *" if d["clear"] else ""))
                           for d in doc["difference"][m.name]])
    return head, rows


def summary_lines(doc: dict) -> list[str]:
    """SNR10 and SNR1 with the conditions they hold at, the viewing conditions, and what was assumed."""
    out = []
    for key, label in ((doc["names"][0], "a"), (doc["names"][1], "b")):
        r = doc[label]
        if r is None:
            continue
        who = f"{key}: " if doc["b"] is not None else ""
        out.append(f"{who}SNR10 of the raw green pixels (photo-charge over temporal noise) "
                   f"{_lux(r.get('snr10_lux'), r.get('snr10_lux_side'), r['lux'])} (model "
                   f"{_lux(r.get('snr10_lux_predicted'))}), SNR1 {_lux(r.get('snr1_lux'), r.get('snr1_lux_side'), r['lux'])} "
                   f"(model {_lux(r.get('snr1_lux_predicted'))}), an 18 % grey at f/{r['f_number']:g}, "
                   f"{r['integration_time_s']:g} s, {r['illuminant']}")
        out += [f"{who}{line}" for line in r.get("notes", [])]
        dr = r.get("dynamic_range")
        if dr and dr.get("db") is not None:
            out.append(f"{who}dynamic range (ISO 15739's form: the grey's saturation at {dr['saturation_lux']:.4g} "
                       f"lux over its SNR 1 at {dr['snr1_lux']:.3g} lux, scene-referred) {dr['db']:.1f} dB")
        ns = r.get("noise_speed")
        if ns:
            out.append(f"{who}ISO 12232 noise-based speed (the output luminance's noise in one picture; a colour "
                       f"camera's colour-difference noise not counted): S40 {_speed(ns['excellent'])}, S10 "
                       f"{_speed(ns['acceptable'])}")
        if r.get("light_switched_on"):
            out.append(f"{who}light was off in the configuration: switched on with its light section's defaults "
                       f"({r['illuminant']}, f/{r['f_number']:g}), each illuminance set in turn")
    a = doc["a"]
    out.append(f"viewing: print, the {a['picture_rows']}-row picture {a['picture_height_cm']:g} cm high from "
               f"{a['viewing_distance_cm']:g} cm; the just-detectable visual noise there is "
               f"{a['visual_threshold_l']:.3g} L* (banding in JND: 1 is the threshold)")
    d = a.get("viewing", {}).get("display")
    if d:
        out.append(f"viewing: display at 100 %, {d['display_pixel_pitch_mm']:g} mm pixels from "
                   f"{d['viewing_distance_cm']:g} cm ({d['pixels_per_degree']:.0f} pixels per degree): the display "
                   "banding rows")
    ref = a.get("colour_reference")
    if ref:
        seen = (f"{ref['chart']} under {ref['illuminant']}, {ref['observer']}, {ref['adaptation']}"
                if ref["reference"] == "spectral" else ref["chart"])
        out.append(f"colour error against {seen}; {ref['fit']}; {ref['difference']}")
    if doc["b"] is not None:
        a_name, b_name = doc["names"]
        if doc.get("compare_from"):
            out.insert(0, f"{b_name}: {doc['compare_from']}")
        out.append(f"{a_name} and {b_name}: sensor instance 0; {b_name} - {a_name}: the mean ± standard error of the "
                   f"paired differences over {doc['instances']} sensor instances; * clear (beyond {CLEAR_Z:g} "
                   "standard errors)")
    return out


def _speed(point: dict) -> str:
    if point["speed"] is None and point.get("side") == "below":
        return f"above the lowest lux measured's (SNR {point['snr']:g} reached there already)"
    if point["speed"] is None:
        return f"beyond the lux measured (SNR {point['snr']:g} not reached)"
    speed = f"{point['speed']:.0f}" if point["speed"] >= 10 else f"{point['speed']:.2g}"  # ISO speeds are whole
    return f"{speed} (SNR {point['snr']:g} at {point['lux']:.3g} lux, H {point['exposure_lux_s']:.3g} lux s)"


def _lux(v, side: str | None = None, lux=None) -> str:
    if v is not None:
        return f"{v:.3g} lux"
    if side == "below" and lux:
        return f"reached at or below {min(lux):g} lux, the lowest measured"
    return "beyond the lux measured"


# ------------------------------------------------------------------ plots
def _each(doc: dict):
    yield doc["names"][0], doc["a"], "C0"
    if doc["b"] is not None:
        yield doc["names"][1], doc["b"], "C1"


def _finished(fig, ax, xlabel: str, ylabel: str, title: str) -> bytes:
    """A plot's labels, title, legend and grid (both scales' grid lines), as PNG bytes."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, which="both")
    return plots.to_png_bytes(fig)


def snr_plot(doc: dict) -> bytes:
    fig, ax = plots.figure(figsize=(6.0, 4.0))
    for name, r, colour in _each(doc):
        lux = np.array(r["lux"])
        for key, style, what in (("snr_green", "o-", "raw green"), ("snr_green_predicted", ":", "raw green, model"),
                                 ("snr_luminance", "s--", "output luminance")):
            y = np.array([np.nan if v is None else v for v in r["metrics"].get(key, [None] * len(lux))], float)
            if np.isfinite(y).any():
                ax.loglog(lux, y, style, color=colour, ms=4, label=f"{name}: {what}", alpha=0.6 if ":" in style else 1)
        if r.get("snr10_lux"):
            ax.axvline(r["snr10_lux"], color=colour, lw=0.8, ls="-.")
    ax.axhline(10, color="0.5", lw=0.8, ls=":")
    ax.axhline(1, color="0.5", lw=0.8, ls=":")
    a = doc["a"]
    return _finished(fig, ax, f"illuminance on the scene [lux] (f/{a['f_number']:g}, {a['integration_time_s']:g} s)",
                     "SNR of an 18 % grey", "SNR against illuminance (dash-dot: SNR10)")


def visual_plot(doc: dict) -> bytes:
    fig, ax = plots.figure(figsize=(6.0, 4.0))
    for name, r, colour in _each(doc):
        lux = np.array(r["lux"])
        for key, style, what in (("visual_noise_l", "o-", "visual luminance noise / threshold"),
                                 ("banding_columns", "s--", "column banding"), ("banding_rows", "^:", "row banding")):
            vals = r["metrics"].get(key)
            if vals is None:
                continue
            y = np.array([np.nan if v is None else v for v in vals], float)
            if key == "visual_noise_l":
                y = y / r["visual_threshold_l"]
            ax.loglog(lux, y, style, color=colour, ms=4, label=f"{name}: {what}")
    ax.axhline(1, color="0.3", lw=1, ls=":", label="threshold (1 JND)")
    a = doc["a"]
    return _finished(fig, ax, "illuminance on the scene [lux]", "visibility [just-noticeable differences]",
                     f"Visibility ({a['picture_height_cm']:g} cm picture from {a['viewing_distance_cm']:g} cm)")


def mtf_plot(doc: dict) -> bytes:
    fig, ax = plots.figure(figsize=(6.0, 4.0))
    for name, r, colour in _each(doc):
        s = r.get("sfr")
        if s:
            ax.plot(s["frequency"], s["sfr"], "-", color=colour, label=f"{name} at {s['lux']:g} lux")
            if s.get("se"):
                f, v, e = (np.asarray(s[k], float) for k in ("frequency", "sfr", "se"))
                ax.fill_between(f, v - 2 * e, v + 2 * e, color=colour, alpha=0.15, lw=0)
    ax.axvline(0.5, color="0.5", lw=0.8, ls=":", label="Nyquist")
    ax.axhline(0.5, color="0.5", lw=0.8, ls="--")
    ax.set_xlim(0, 1)
    return _finished(fig, ax, "spatial frequency [cycles/pixel]", "SFR",
                     "ISO 12233 e-SFR of the output luminance (slanted edge; shaded: 2 standard errors)")


def colour_plot(doc: dict) -> bytes:
    fig, ax = plots.figure(figsize=(6.4, 3.2))
    width = 0.4 if doc["b"] is not None and doc["b"].get("colour") else 0.8
    for k, (name, r, colour) in enumerate(_each(doc)):
        c = r.get("colour")
        if not c:
            continue
        x = np.arange(len(c["de2000"])) + (k - 0.5) * width * (width < 0.8)
        ax.bar(x, c["de2000"], width, color=colour, label=f"{name} at {c['lux']:g} lux")
    names = doc["a"]["colour"]["names"]
    ax.set_xticks(np.arange(len(names)), names, rotation=75, fontsize=6)
    ax.axhline(1, color="0.3", lw=0.8, ls=":", label="about 1 JND")
    ax.set_ylabel("CIEDE2000")
    ax.set_title("ColorChecker: colour error per patch after a fitted 3 x 3 matrix")
    ax.legend(fontsize=7)
    return plots.to_png_bytes(fig)


# ------------------------------------------------------------------ report
def build_report(doc: dict, pngs: dict) -> str:
    """The self-contained page: the conditions, the table, the plots, and each metric's source."""
    head, rows = console_rows(doc)
    head = head[:2] + [f"{h} lux" for h in head[2:]]
    title = "cmosnoise quality" + (f": {doc['names'][0]} against {doc['names'][1]}" if doc["b"] is not None else "")
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<style>{CSS}</style></head><body><h1>{html.escape(title)}</h1>",
             f"<p>cmosnoise {html.escape(__version__)}, {datetime.date.today().isoformat()}; "
             f"{doc['a']['frames']} frames of each chart at each illuminance.</p><ul>"]
    parts += [f"<li>{html.escape(line)}</li>" for line in summary_lines(doc)]
    parts.append("</ul><h2>Metrics</h2>")
    parts.append(_table(rows, head, digits=4))
    captions = {"snr.png": "SNR of an 18 % grey against illuminance: the raw green channel (e-, with the noise "
                           "model's prediction) and the output luminance",
                "visual_noise.png": "Visual luminance noise over its just-detectable level, and the row and column "
                                    "banding's visibility, in just-noticeable differences",
                "mtf.png": "The e-SFR of the slanted edge at the brightest illuminance",
                "colorchecker.png": "CIEDE2000 of each ColorChecker patch at the brightest illuminance"}
    for name, png in pngs.items():
        parts.append(_figure(png, captions.get(name, name), width=560))
    parts.append("<h2>How each metric is measured</h2>")
    parts.append(_table([[m.label, m.unit, "higher" if m.better == "higher" else "lower", m.source]
                         for m in quality.METRICS if m.name in doc["a"]["metrics"]],
                        ["metric", "unit", "better", "definition and source"]))
    parts.append("</body></html>")
    return "".join(parts)


# ------------------------------------------------------------------ threshold search
def parse_find(text: str) -> tuple[str, float, float]:
    """``--find KEY=LOW:HIGH`` read, or a one-line error."""
    key, sep, rng = text.partition("=")
    low, colon, high = rng.partition(":")
    try:
        if not (sep and colon and key.strip()):
            raise ValueError
        return key.strip(), float(low), float(high)
    except ValueError:
        raise CmosnoiseError(f"--find {text!r}: give KEY=LOW:HIGH, e.g. column_noise.vfpn_sigma_e=0:20") from None


def parse_until(text: str) -> tuple[str, float]:
    """``--until METRIC=LIMIT`` read, or a one-line error."""
    name, sep, value = text.partition("=")
    try:
        if not sep:
            raise ValueError
        limit = float(value)
    except ValueError:
        raise CmosnoiseError(f"--until {text!r}: give METRIC=LIMIT, e.g. banding_columns=1 (metrics: "
                             f"{', '.join(quality.BY_NAME)})") from None
    if name.strip() not in quality.BY_NAME:
        raise CmosnoiseError(f"--until {text!r}: {name.strip()!r} is not a metric; choose from "
                             f"{', '.join(quality.BY_NAME)}")
    return name.strip(), limit


def run_threshold(config, out: Path, overwrite: bool, find: str, until: str, lux: float, instances: int = 5,
                  frames: int = 4) -> dict:
    """``cmosnoise quality --find``: :func:`cmosnoise.analysis.quality.threshold` into ``out`` (threshold.json,
    threshold.png)."""
    key, low, high = parse_find(find)
    metric, limit = parse_until(until)
    folder = OutputFolder(out, overwrite)
    r = quality.threshold(config, key, low, high, metric, limit, lux, instances, frames)
    r["cmosnoise_version"] = __version__
    r["sentence"] = threshold_sentence(r)
    with folder as tmp:
        write_json(tmp / "threshold.json", r)
        (tmp / "threshold.png").write_bytes(threshold_plot(r))
    return r


def _range(values: list[float]) -> str:
    """Values over sensor instances as ``a`` or ``a to b``."""
    lo, hi = min(values), max(values)
    return f"{lo:.3g}" if f"{lo:.3g}" == f"{hi:.3g}" else f"{lo:.3g} to {hi:.3g}"


def threshold_sentence(r: dict) -> str:
    m = quality.BY_NAME[r["metric"]]
    unit = f" {m.unit}" if m.unit else ""
    if r["mean"] is None:
        ends = [(p[0][1], p[-1][1]) for p in r["points"] if p]
        lo = [a for a, _ in ends]
        hi = [b for _, b in ends]
        where = ("above" if min(lo + hi) > r["limit"] else "below" if max(lo + hi) < r["limit"] else "on one side of")
        return (f"{m.label} does not cross {r['limit']:g}{unit} between {r['key']} = {r['low']:g} and {r['high']:g} "
                f"at {r['lux']:g} lux on any of {r['instances']} sensor instances: it is {where} it at both ends "
                f"({_range(lo)}{unit} at {r['low']:g}, {_range(hi)}{unit} at {r['high']:g})")
    side = "largest" if r["below_at"] == "low" else "smallest" if r["below_at"] == "high" else "value of"
    good = "below" if m.better == "lower" else "above"
    spread = (f" ± {r['se']:.2g} (standard error; {r['min']:.4g} to {r['max']:.4g} over "
              f"{sum(x is not None for x in r['crossings'])} sensor instances)" if r["se"] is not None else "")
    missed = sum(x is None for x in r["crossings"])
    return (f"the {side} {r['key']} at which {m.label} stays {good if side != 'value of' else 'at'} "
            f"{r['limit']:g}{unit} at {r['lux']:g} lux: {r['mean']:.4g}{spread}"
            + (f"; {missed} instance(s) do not cross it in the interval" if missed else ""))


def threshold_plot(r: dict) -> bytes:
    m = quality.BY_NAME[r["metric"]]
    fig, ax = plots.figure(figsize=(6.0, 4.0))
    for s, pts in enumerate(r["points"]):
        x, y = zip(*pts)
        ax.plot(x, y, ".-", ms=3, lw=0.8, label=f"sensor instance {s}")
    ax.axhline(r["limit"], color="0.3", ls=":", label=f"limit {r['limit']:g}")
    if r["mean"] is not None:
        ax.axvline(r["mean"], color="k", lw=1, label=f"crossing {r['mean']:.4g}")
    return _finished(fig, ax, r["key"], f"{m.label} [{m.unit}]" if m.unit else m.label,
                     f"Where {m.label} crosses {r['limit']:g} at {r['lux']:g} lux")
