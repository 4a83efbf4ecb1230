"""The paper's figures, regenerated with this tool (``cmosnoise figures --out DIR``).

Each function runs one of the paper's experiments and returns a
:class:`Figure`: file name, PNG bytes, a caption that states the parameters,
and the facts the figure shows, measured (so a test can check them).
:func:`write_gallery` writes them all with an ``index.html``.
"""

from __future__ import annotations

import html
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .._version import __version__
from ..analysis import white_pixels
from ..config import load_config, merge_updates
from ..isp import calibration
from ..isp.process import Processor
from ..model.sensor import Sensor
from . import plots


class Figure(NamedTuple):
    name: str  #: file name of the PNG
    png: bytes
    caption: str
    facts: dict  #: what the figure shows, measured from the data it plots


def fig3_prnu(seed: int = 0):
    cfg = load_config(preset="paper-fig3-prnu")
    sensor = Sensor(cfg, seed=seed)
    e = sensor.transfer.to_electrons(sensor.capture()[0])
    fig, (a, b) = plots.figure(1, 2, figsize=(10.5, 4.2), layout="constrained")  # keeps the colour bar's label clear
    im = a.imshow(e, cmap="gray", interpolation="nearest")
    fig.colorbar(im, ax=a, label="signal [e-]", fraction=0.046, pad=0.03)
    a.set_xticks(range(0, e.shape[1], 2))
    a.set_yticks(range(0, e.shape[0], 2))
    a.set_title("14 x 14 flat field, 10 % PRNU")
    a.set_xlabel("column")
    a.set_ylabel("row")
    b.hist(e.ravel(), bins=20, color="C0", alpha=0.8, label="pixels")
    x = np.linspace(e.min() - 50, e.max() + 50, 200)
    from scipy import stats

    b.plot(x, stats.norm(1000, 100).pdf(x) * e.size * (np.ptp(e) / 20), "C1-", label="Normal(1000, 100) e-")
    b.set_xlabel("signal [e-]")
    b.set_ylabel("pixels per bin")
    b.set_title(f"mean {e.mean():.0f} e-, std {e.std(ddof=1):.0f} e- ({100 * e.std(ddof=1) / e.mean():.1f} %)")
    b.legend()
    facts = {"pixels": int(e.size), "mean_e": float(e.mean()), "prnu_pct": float(100 * e.std(ddof=1) / e.mean())}
    return Figure("fig3_prnu.png", plots.to_png_bytes(fig), (
        "Fig. 3: 10 % PRNU on a flat grey scene of mean 1000 e-, 14 x 14 monochrome pixels (preset paper-fig3-prnu; "
        f"only PRNU on, 12-bit ADC, seed {seed})."), facts)


def _dark_maps(temps, shape=(400, 500), seed=0, tails=True):
    base = load_config(overrides=[f"sensor.height={shape[0]}", f"sensor.width={shape[1]}"])
    pts = base.model_dump(mode="json")["dark_current"]["points"]
    if not tails:
        pts = [{k: v for k, v in p.items() if k != "tail"} for p in pts]
    out = {}
    for t in temps:
        cfg = merge_updates(base, {"sensor": {"temperature_c": t}, "dark_current": {"points": pts}})
        s = Sensor(cfg, seed=seed)
        out[t] = (s.dark_rate.astype(np.float64), s.dark_state)
    return out


def fig5_dark_temperatures(seed: int = 0):
    maps = _dark_maps([25, 45, 65], seed=seed)
    fig, ax = plots.figure(figsize=(7.5, 4.6))
    bins = np.linspace(-4, 12, 161)
    for t, (m, st) in maps.items():
        z = ((m - st.mean) / st.std).ravel()
        ax.hist(z, bins=bins, histtype="step", lw=1.5, label=f"{t} C: {st.family} body, mean {st.mean:.0f} e-/s, std {st.std:.1f} e-/s")
    plots.log_histogram_axes(ax, "(dark current - body mean) / body std  [shifted and scaled]",
                             "Dark-current distribution at 25, 45 and 65 C")
    facts = {"families": {t: st.family for t, (m, st) in maps.items()},
             "map_mean_e_per_s": {t: float(m.mean()) for t, (m, st) in maps.items()}}
    return Figure("fig5_dark_temperatures.png", plots.to_png_bytes(fig), (
        "Fig. 5: shifted and scaled dark-current histograms of one sensor instance (400 x 500 pixels, default "
        "characterization points: logistic at 25 C, inverse Gaussian at 45 C, lognormal at 65 C, each with a uniform "
        f"white-pixel tail). The shape, not only the location, changes with temperature. Seed {seed}."), facts)


def fig6_body_and_tail(seed: int = 0):
    full = _dark_maps([65], seed=seed)[65]
    body = _dark_maps([65], seed=seed, tails=False)[65][0]
    rate, state = full
    tail = rate - body
    fig, (a, b) = plots.figure(1, 2, figsize=(12, 4.4))
    plots.dark_current_histogram(a, rate, state, "Body + tail at 65 C (the sensor's map)")
    top = rate.max() * 1.02
    bins = np.linspace(0, top, 200)
    b.hist(body.ravel(), bins=bins, alpha=0.7, label=f"body: {state.family}, mean {state.mean:.0f} e-/s, std {state.std:.0f} e-/s")
    b.hist(tail[tail > 0].ravel(), bins=bins, alpha=0.7, color="C3", label=f"tail: Uniform(0, {state.tail_max:.0f}) e-/s for {100 * state.tail_fraction:.3f} %")
    plots.log_histogram_axes(b, "dark current [e-/s per pixel]", "The two distributions, apart")
    facts = {"pixels": int(rate.size), "above_threshold": int((rate > state.threshold).sum()),
             "ppm_configured": float(state.expected_ppm_above()), "threshold_e_per_s": float(state.threshold)}
    return Figure("fig6_body_and_tail.png", plots.to_png_bytes(fig), (
        "Fig. 6: two distributions give the realistic histogram: a lognormal body (320 e-/s mean, 130 e-/s std at 65 C) "
        "plus a uniform tail whose fraction is solved so that 200 ppm of pixels lie above 250 aA (1560 e-/s). "
        f"400 x 500 pixels, seed {seed}."), facts)


class _TotalSigma:
    """Distribution of sqrt(thermal^2 + flicker^2) given the flicker-sigma distribution."""

    def __init__(self, flicker, thermal):
        self.flicker, self.thermal = flicker, thermal

    def cdf(self, s):
        s = np.asarray(s, dtype=np.float64)
        inner = np.sqrt(np.maximum(s**2 - self.thermal**2, 0.0))
        return np.where(s < self.thermal, 0.0, self.flicker.cdf(inner))


def fig7_temporal_noise(seed: int = 0, frames: int = 100):
    cfg = load_config(extra={
        "sensor": {"width": 300, "height": 300, "cfa": "none"}, "prnu": {"enabled": False}, "crosstalk": {"enabled": False},
        "dark_current": {"enabled": False}, "row_noise": {"enabled": False}, "column_noise": {"enabled": False},
        "adc": {"enabled": False},
        "source_follower": {"thermal_sigma_e": 1.0, "flicker": {"gumbel_loc_e": 1.5, "gumbel_scale_e": 0.4,
                                                                 "tail": {"ppm_above": 2000, "threshold_e": 5.0, "max_e": 15.0}}},
    })
    sensor = Sensor(cfg, seed=seed)
    shot = sensor.expose("flat:0")
    e = np.stack([shot.frame(k, detail=True).electrons for k in range(frames)]).astype(np.float64)
    sigma = e.std(axis=0, ddof=1)
    fig, ax = plots.figure(figsize=(7.5, 4.6))
    plots.temporal_noise_histogram(ax, sigma, _TotalSigma(sensor.flicker_model, 1.0), 5.0,
                                   f"Per-pixel temporal noise measured over {frames} dark frames")
    true_var = 1.0 + sensor.fixed_pattern.flicker_sigma.astype(np.float64) ** 2  # each pixel's own variance
    facts = {"frames": frames, "mean_measured_var_e2": float(np.mean(sigma**2)), "mean_true_var_e2": float(true_var.mean()),
             "se_mean_var_e2": float(np.sqrt(np.mean(2 * true_var**2 / (frames - 1)) / true_var.size))}
    return Figure("fig7_temporal_noise.png", plots.to_png_bytes(fig), (
        f"Fig. 7: temporal noise of each pixel measured over {frames} dark frames (300 x 300 pixels): thermal 1 e- plus "
        "a flicker/RTS sigma per pixel from a Gumbel body (location 1.5 e-, scale 0.4 e-) and a uniform tail "
        f"(2000 ppm above 5 e-, up to 15 e-). The line is the model, before the estimator's own spread. Seed {seed}."), facts)


def fig9_couplets(seed: int = 0):
    panels = {}
    for name in ("paper-fig9-vga", "paper-fig9-5m"):
        cfg = load_config(preset=name)
        sensor = Sensor(cfg, seed=seed)
        shot = sensor.expose()
        raw = shot.frame(0)
        master = calibration.master_dark(sensor.dark_frames(cfg.processing.dark_frames))
        proc = Processor(cfg.processing, sensor.raw_info(), master)
        k = sensor.transfer.gain_dn_per_e
        residual = proc.cfa_image(raw) - shot.photo_mean_e * k
        panels[name] = dict(
            sensor=sensor, pre=proc.render(raw, pre=True), post=proc.render(raw),
            white=sensor.dark_rate > sensor.dark_state.threshold,
            left=np.abs(residual) > 150 * k,
        )
    facts = {name: {"couplets_map": white_pixels.count_couplets(p["white"], "RGGB"),
                    "couplets_after_processing": white_pixels.count_couplets(p["left"], "RGGB")}
             for name, p in panels.items()}
    big = panels["paper-fig9-5m"]
    rows, cols = big["sensor"].shape
    pairs = white_pixels.couplet_pairs(big["left"], "RGGB")
    target = np.zeros((rows, cols), bool)
    if len(pairs):
        target[pairs[:, 0, 0], pairs[:, 0, 1]] = True
    h, w = 96, 128
    r0, c0 = plots.densest_window(target if target.any() else big["white"], (h, w))
    frac = (r0 / rows, c0 / cols, h / rows, w / cols)  # the same part of the scene at both resolutions
    fig, axes = plots.figure(2, 2, figsize=(11, 8.6))
    for i, name in enumerate(("paper-fig9-vga", "paper-fig9-5m")):
        p = panels[name]
        pr, pc = p["sensor"].shape
        a0, b0 = int(frac[0] * pr), int(frac[1] * pc)
        hh, ww = max(int(round(frac[2] * pr)), 4), max(int(round(frac[3] * pc)), 4)
        scale = 512 / ww
        for j, (view, mask, label) in enumerate(((p["pre"], p["white"], "pre-processing"),
                                                 (p["post"], p["left"], "post-processing (dark cal + median)"))):
            ax = axes[i, j]
            ax.imshow(view[a0 : a0 + hh, b0 : b0 + ww], interpolation="nearest", extent=(0, ww * scale, hh * scale, 0))
            cp = white_pixels.couplet_pairs(mask[a0 : a0 + hh, b0 : b0 + ww], "RGGB")
            plots.circle_couplets(ax, cp + 0.5, scale=scale, radius=max(3 * scale, 16), color="cyan")
            ax.set_title(f"{'VGA' if 'vga' in name else '5 MP'} {label}: {len(cp)} couplet(s)")
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle("500 e- peak after 0.25 s; 65 C, dark body mean 500 e-/s, tail adding up to 80000 e-/s, 4000 ppm > 250 aA; dark cal on")
    return Figure("fig9_couplets.png", plots.to_png_bytes(fig), (
        "Fig. 9: the same part of the scene on a VGA and a 5 MP sensor with the paper's worst-case dark current "
        "(presets paper-fig9-vga and paper-fig9-5m). Left: before processing, couplets of white pixels circled; right: "
        "after dark calibration (8 dark frames) and median defect correction, couplets that survive circled. More pixels "
        f"at the same ppm means more couplets, and the median corrector cannot remove them. Seed {seed}."), facts)


def fig10_vfpn(seed: int = 0, levels=(30, 120, 500, 2000)):
    fig, axes = plots.figure(2, 2, figsize=(11, 8.4))
    base = load_config(preset="paper-fig10-vfpn", overrides=["scene.source=photo"])
    sensor = Sensor(base, seed=seed)
    column_std = {}
    for ax, peak in zip(axes.ravel(), levels):
        s = sensor.with_exposure(peak / base.exposure.peak_rate_e_per_s)
        shot = s.expose()
        detail = shot.frame(0, detail=True)
        raw = detail.raw
        # column means of (charge - its expectation): VFPN plus the shot noise the column mean leaves
        column_std[peak] = float(np.std((detail.electrons - shot.mean_charge_e).mean(axis=0), ddof=1))
        proc = Processor(base.processing, s.raw_info())
        ax.imshow(proc.render(raw), cmap="gray", vmin=0, vmax=255)
        ax.set_title(f"peak {peak} e-: sigma_VFPN / peak = {100 * 6 / peak:.1f} %")
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle("sigma_VFPN = 6 e- with photon shot noise, four light levels (each shown with its peak as white)")
    facts = {"vfpn_sigma_e": base.column_noise.vfpn_sigma_e, "rows": sensor.shape[0], "cols": sensor.shape[1],
             "column_mean_std_e": column_std}
    return Figure("fig10_vfpn.png", plots.to_png_bytes(fig), (
        f"Fig. 10: column fixed-pattern noise of 6 e- rms (preset paper-fig10-vfpn, photo scene, monochrome 640 x 480) at "
        f"peak signals of {', '.join(map(str, levels))} e-. Plain in low light, hard to see at high light, where shot "
        f"noise and the larger signal hide it. Seed {seed}."), facts)


def fig11_full(seed: int = 0):
    cfg = load_config(preset="paper-fig11-full")
    sensor = Sensor(cfg, seed=seed)
    raw = sensor.expose().frame(0)
    proc = Processor(cfg.processing, sensor.raw_info())
    from ..isp.reconstruction import encode_srgb8
    from ..model import scene as scene_mod

    perfect = encode_srgb8(scene_mod.render("photo", sensor.shape))
    fig, axes = plots.figure(1, 2, figsize=(12, 4.8))
    for ax, img, title in zip(axes, (perfect, proc.render(raw)), ("perfect image", "every noise source on")):
        ax.imshow(img)
        ax.set_title(title)
        ax.set_xticks([])
        ax.set_yticks([])
    facts = {"stages": sensor.stages_on()}
    return Figure("fig11_full.png", plots.to_png_bytes(fig), (
        "Fig. 11: the whole chain with exaggerated values (preset paper-fig11-full): 4 % PRNU, crosstalk, dark current at "
        "45 C with 2000 ppm white pixels, 4 e- thermal noise, heavy flicker, 1.5 e- row noise, noisy columns and 3 e- "
        f"VFPN, 400 e- peak, 10-bit ADC; pre-processing view. Seed {seed}."), facts)


FIGURES: list[Callable] = [fig3_prnu, fig5_dark_temperatures, fig6_body_and_tail, fig7_temporal_noise,
                           fig9_couplets, fig10_vfpn, fig11_full]


def write_gallery(folder: Path, seed: int = 0, progress: Callable[[str], None] | None = None) -> list[tuple[str, str]]:
    """Write every figure and ``index.html`` into ``folder``; returns (file, caption) pairs."""
    items = []
    for f in FIGURES:
        if progress:
            progress(f.__name__)
        figure = f(seed=seed)
        (folder / figure.name).write_bytes(figure.png)
        items.append((figure.name, figure.caption))
    cards = "".join(
        f"<figure><a href='{n}'><img src='{n}' alt='{html.escape(c[:60])}'></a><figcaption>{html.escape(c)}</figcaption></figure>"
        for n, c in items
    )
    (folder / "index.html").write_text(
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>cmosnoise: the paper's figures</title><style>"
        "body{font-family:system-ui,sans-serif;max-width:1150px;margin:2em auto;padding:0 1em;color:#222}"
        "figure{margin:0 0 2.5em}img{max-width:100%;border:1px solid #ddd}figcaption{color:#444;margin-top:.4em}"
        "</style></head><body><h1>The paper's figures, regenerated with cmosnoise</h1>"
        f"<p>Gow et al., IEEE TED 2007, experiments re-run with cmosnoise {__version__} "
        f"(<code>cmosnoise figures --seed {seed}</code>).</p>" + cards + "</body></html>"
    )
    return items
