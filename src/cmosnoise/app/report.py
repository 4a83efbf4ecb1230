"""The run report: one self-contained HTML file (images embedded, no network, no server).

It holds the resolved parameters grouped by stage, the noise budget (table
and bar chart), the histograms the paper plots (dark-current map, Figs. 5
and 6; per-pixel temporal noise, Fig. 7), the perfect, raw and processed
images side by side, a zoom on the densest white pixels with the couplets
circled (Fig. 9), and the key figures of ``summary.json``.
"""

from __future__ import annotations

import datetime
import html
import json
import math

import numpy as np

from .._version import __version__
from ..analysis import noise_budget, white_pixels
from ..isp.reconstruction import encode_srgb8
from ..model import scene as scene_mod
from . import plots

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2em auto;max-width:1200px;color:#222;padding:0 1em}
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.8em}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ddd;padding:.25em .6em;text-align:left;font-size:.92em}
th{background:#f3f3f3}td.num{text-align:right;font-variant-numeric:tabular-nums}
.row{display:flex;flex-wrap:wrap;gap:1em}.row figure{margin:0}figcaption{font-size:.9em;color:#555;max-width:420px}
img.pix{image-rendering:pixelated}.params{display:flex;flex-wrap:wrap;gap:1.2em;align-items:flex-start}
"""


def _fmt(v, digits: int = 6) -> str:
    if isinstance(v, float):
        if math.isfinite(v) and 1e9 > abs(v) >= 10 ** (digits - 1):
            return f"{v:.0f}"  # large values as whole numbers, not 1e+04
        return f"{v:.{digits}g}"
    if isinstance(v, (list, tuple, dict)):
        return html.escape(json.dumps(v))
    return html.escape(str(v))


def _flatten(d: dict, prefix: str = "") -> list[tuple[str, object]]:
    out = []
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out += _flatten(v, key + ".")
        else:
            out.append((key, v))
    return out


def _table(rows, header=None, cls="", digits: int = 6) -> str:
    """An HTML table; floats to ``digits`` significant figures (4 for measured figures, 6 for parameters)."""
    h = "".join(f"<th>{html.escape(str(c))}</th>" for c in header) if header else ""
    body = "".join(
        "<tr>" + "".join(f'<td class="num">{_fmt(c, digits)}</td>' if isinstance(c, (int, float)) else f"<td>{_fmt(c, digits)}</td>"
                         for c in r) + "</tr>"
        for r in rows
    )
    return f'<table class="{cls}">' + (f"<tr>{h}</tr>" if h else "") + body + "</table>"


def _img(png: bytes, alt: str, width: int | None = None, pixelated: bool = False) -> str:
    w = f' width="{width}"' if width else ""
    cls = ' class="pix"' if pixelated else ""
    return f'<img src="{plots.data_uri(png)}" alt="{html.escape(alt)}"{w}{cls}>'


def _figure(png: bytes, caption: str, width: int | None = 380, pixelated: bool = False) -> str:
    return f"<figure>{_img(png, caption, width, pixelated)}<figcaption>{html.escape(caption)}</figcaption></figure>"


#: pictures wider than this are shown reduced (block means), with 1:1 crops of the centre beside them
OVERVIEW_MAX_WIDTH = 960


def _overview_step(shape: tuple[int, int]) -> int:
    return max(1, -(-shape[1] // OVERVIEW_MAX_WIDTH))


def _overview(img: np.ndarray, step: int) -> np.ndarray:
    """The picture reduced by whole blocks of ``step`` x ``step`` pixels (their mean), uint8."""
    if step == 1 or img is None:
        return img
    h, w = (img.shape[0] // step) * step, (img.shape[1] // step) * step
    x = img[:h, :w].astype(np.float32)
    x = x.reshape(h // step, step, w // step, step, *img.shape[2:]).mean(axis=(1, 3))
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


def build(sensor, summary: dict, raw0: np.ndarray, processor, pre_view: np.ndarray, processed: np.ndarray) -> str:
    """The report's HTML text; ``pre_view`` and ``processed`` are frame 0 through the processor (8-bit)."""
    c = sensor.config
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>cmosnoise run report</title><style>{CSS}</style></head><body>"]
    parts.append(f"<h1>cmosnoise run report</h1><p>cmosnoise {__version__}, {datetime.datetime.now():%Y-%m-%d %H:%M}; "
                 f"{sensor.shape[1]} x {sensor.shape[0]} {html.escape(sensor.cfa)} sensor, seed {c.seed}, scene "
                 f"<code>{html.escape(c.scene.source)}</code>, {summary['frames']} frame(s) from frame {summary['first_frame']}.</p>")

    # ---- key figures
    kf = summary["key_figures"]
    tn = summary["temporal_noise"]
    rows = [
        ("mean signal", summary["signal"]["mean_e"], "e-"),
        ("mean signal", summary["signal"]["mean_dn"], "DN"),
        ("temporal noise, predicted", tn["predicted_rms_e"], "e- rms"),
        ("temporal noise, measured (frame differences)", tn["rms_e"] if tn["rms_e"] is not None else "needs 2 frames", "e- rms"),
        ("dark temporal noise", kf["dark_temporal_noise_e"], "e- rms"),
        ("saturation", kf["saturation_e"], "e-"),
        ("dynamic range", kf["dynamic_range_db"], "dB"),
    ]
    rows += [(f"SNR at {lvl} e-: temporal / with fixed pattern (its rms holds every pixel, hot ones included)",
              f"{v:.1f} / {kf['snr_total_db_at_signal_e'][lvl]:.1f}", "dB")
             for lvl, v in kf["snr_temporal_db_at_signal_e"].items()]
    dc = summary.get("dark_current")
    if dc and "map" in dc:
        rows += [
            (f"ppm above {dc['threshold_aA']:.0f} aA ({dc['threshold_e_per_s']:.0f} e-/s), map", dc["map"]["ppm"], "ppm"),
            ("white-pixel threshold from", dc["threshold_source"], ""),
            ("ppm above threshold, configured", dc["ppm_expected"], "ppm"),
            ("white pixels (map) / couplets / couplets expected at random",
             f"{dc['map']['white_pixels']} / {dc['map']['couplets']} / {dc['map']['couplets_expected_random']:.1f}", ""),
            ("white pixels (frame 0) / couplets / expected at random",
             f"{dc['frame0']['white_pixels']} / {dc['frame0']['couplets']} / {dc['frame0']['couplets_expected_random']:.1f}", ""),
        ]
    parts.append("<h2>Key figures</h2>" + _table(rows, ["quantity", "value", "unit"], "keyfigures", digits=4))

    # ---- images
    t = sensor.transfer
    white = processor.white_above_black
    perfect_rgb = scene_mod.render(c.scene.source, sensor.shape, c.scene.scale, c.scene.fit, c.scene.window,
                                   c.scene.source_size)
    raw_view = encode_srgb8((raw0.astype(np.float32) - t.black_level_dn) / white)
    perfect = encode_srgb8(perfect_rgb if not processor.mono else perfect_rgb @ scene_mod.LUMINANCE)
    step = _overview_step(sensor.shape)
    note = f", 1:{step}" if step > 1 else ""
    views = [(perfect, "perfect image (the scene at the sensor's resolution)"),
             (raw_view, "raw frame 0 (CFA samples as grey, black level removed)"),
             (pre_view, "pre-processing view (preview.png)"),
             (processed, "through the processing chain (processed.png)" if processed is not None
              else "through the processing chain: no step beyond the preview's is on")]
    imgs = [_figure(plots.image_png_bytes(_overview(img, step)), cap + note) for img, cap in views]
    parts.append("<h2>Images</h2><div class='row'>" + "".join(imgs) + "</div>")
    if step > 1:  # the whole picture is shrunk: show the noise at 1:1 as well
        r0, c0, size = sensor.shape[0] // 2 - 128, sensor.shape[1] // 2 - 128, 256
        crops = [_figure(plots.image_png_bytes(img[r0:r0 + size, c0:c0 + size]), f"{cap.split(' (')[0]}, centre at 1:1", 300,
                         pixelated=True) for img, cap in views]
        parts.append("<div class='row'>" + "".join(crops) + "</div>")

    # ---- noise budget
    nb = summary["noise_budget"]
    names = noise_budget.by_size(nb["dark"], nb["scene_mean"])  # the bar chart's order: largest first
    label = noise_budget.SOURCE_NAMES.get
    rows = [(label(n, n), nb["dark"]["temporal_rms_e"].get(n, 0.0), nb["scene_mean"]["temporal_rms_e"].get(n, 0.0))
            for n in names]
    rows.append(("total (temporal)", nb["dark"]["temporal_total_e"], nb["scene_mean"]["temporal_total_e"]))
    fp_names = noise_budget.by_size(nb["dark"], nb["scene_mean"], "fixed_pattern_rms_e")
    rows += [(f"fixed pattern: {label(n, n)}", nb["dark"]["fixed_pattern_rms_e"].get(n, 0.0), nb["scene_mean"]["fixed_pattern_rms_e"].get(n, 0.0)) for n in fp_names]
    fig, ax = plots.figure(figsize=(6.4, 3.6))
    plots.noise_budget_bars(ax, nb["dark"], nb["scene_mean"])
    parts.append("<h2>Noise budget</h2><div class='row'>"
                 + _table(rows, ["source", "at dark [e- rms]", f"at the scene mean, {nb['scene_mean']['signal_e']:.0f} e- [e- rms]"], "budget",
                          digits=4)
                 + _figure(plots.to_png_bytes(fig), f"dominant temporal source at the scene mean: {nb['scene_mean']['dominant_temporal']}", 520)
                 + "</div>")

    # ---- histograms
    hist = []
    fp = sensor.fixed_pattern
    if fp.dark_rate is not None:
        fig, ax = plots.figure(figsize=(6.4, 4))
        plots.dark_current_histogram(ax, fp.dark_rate, fp.dark_state, f"Dark-current map at {c.sensor.temperature_c:g} C ({fp.dark_state.family} body)")
        hist.append(_figure(plots.to_png_bytes(fig), "dark-current non-uniformity, log counts (paper Figs. 5 and 6)", 520))
    if fp.flicker_sigma is not None:
        fig, ax = plots.figure(figsize=(6.4, 4))
        tail = c.source_follower.flicker.tail
        plots.temporal_noise_histogram(ax, fp.flicker_sigma, sensor.flicker_model, tail.threshold_e if tail else None,
                                       "Flicker/RTS sigma per pixel", "flicker/RTS sigma [e- rms]")
        hist.append(_figure(plots.to_png_bytes(fig), "per-pixel temporal (flicker/RTS) noise, log counts (paper Fig. 7)", 520))
    if hist:
        parts.append("<h2>Distributions</h2><div class='row'>" + "".join(hist) + "</div>")

    # ---- couplets
    if fp.dark_rate is not None and fp.dark_state.threshold is not None:
        mask = fp.dark_rate > fp.dark_state.threshold
        if mask.any():
            h, w = min(64, sensor.shape[0]), min(96, sensor.shape[1])
            all_pairs = white_pixels.couplet_pairs(mask, sensor.cfa)
            target = mask
            if len(all_pairs):  # zoom where the couplets are densest
                target = np.zeros_like(mask)
                target[all_pairs[:, 0, 0], all_pairs[:, 0, 1]] = True
            r0, c0 = plots.densest_window(target, (h, w))
            crop = pre_view[r0 : r0 + h, c0 : c0 + w]
            fig, ax = plots.figure(figsize=(6.4, 6.4 * h / w))
            # sensor coordinates on the axes: pixel (r, c) covers [c, c + 1) x [r, r + 1)
            ax.imshow(crop, interpolation="nearest", extent=(c0, c0 + w, r0 + h, r0))
            inside = ((all_pairs[:, :, 0] >= r0) & (all_pairs[:, :, 0] < r0 + h)
                      & (all_pairs[:, :, 1] >= c0) & (all_pairs[:, :, 1] < c0 + w)).all(axis=1) if len(all_pairs) else []
            pairs = all_pairs[inside] if len(all_pairs) else all_pairs
            plots.circle_couplets(ax, pairs + 0.5, scale=1.0, radius=2.2)
            ax.set_title(f"Densest white pixels, rows {r0}-{r0 + h - 1}, cols {c0}-{c0 + w - 1}: "
                         f"{len(pairs)} of the map's {len(all_pairs)} couplet(s) circled", fontsize=9)
            ax.set_xlabel("sensor column")
            ax.set_ylabel("sensor row")
            parts.append("<h2>White pixels and couplets</h2>" + _figure(plots.to_png_bytes(fig), f"pre-processing view, zoomed; circled: {len(pairs)} of the map's {len(all_pairs)} couplet(s) (paper Fig. 9)", 640))

    # ---- parameters
    cfg = c.to_dict()
    tables = []
    for section, value in cfg.items():
        rows = _flatten(value) if isinstance(value, dict) else [("", value)]
        tables.append(f"<div><h3>{html.escape(section)}</h3>{_table(rows, ['key', 'value'], 'params')}</div>")
    parts.append("<h2>Parameters</h2><div class='params'>" + "".join(tables) + "</div>")
    parts.append("</body></html>")
    return "".join(parts)
