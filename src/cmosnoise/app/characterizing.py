"""``cmosnoise characterize``: the EMVA 1288 job, from a sensor or a descriptor to the folder and the table.

The measurement is :mod:`cmosnoise.analysis.characterize`'s, the evaluation
:mod:`cmosnoise.analysis.emva_evaluation`'s, the descriptor files
:mod:`cmosnoise.analysis.emva_files`'; this module writes what a user keeps:
``characterization.json``, the photon-transfer and SNR curves, and the EMVA
data set with ``--emva-export`` (compared with the emva1288 reference
implementation where it is installed).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..analysis import characterize as ch
from ..analysis import emva_evaluation as ev
from ..analysis import emva_files, noise_spectrum
from ..analysis.characterize import Measurement
from ..analysis.emva_reference import reference_results
from ..errors import CmosnoiseError
from ..io.output import OutputFolder, write_json
from ..io.stacks import DESCRIPTOR
from ..model.sensor import Sensor
from ..model.spec import SensorSpec
from ..model.stages.random_telegraph import frame_period_s


def run(spec: SensorSpec | None, out: Path, overwrite: bool = False, frames_from: Path | None = None,
        steps: int = 40, stack_frames: int = 16, emva_export: Path | None = None,
        progress: Callable[[int], Callable[[], None]] | None = None, like: Path | None = None,
        dark_exposures="auto") -> dict:
    """Characterize ``spec``'s sensor (or the frames of the descriptor ``frames_from``, compared with ``spec``
    when given) into ``out``; returns ``{"measured", "model", "notes", "reference"}``.

    ``progress(total)`` returns what is called once per step of the series. ``dark_exposures``: the dark-current
    series (:func:`cmosnoise.analysis.characterize.measure`); with ``like``, only one given explicitly is made.
    """
    folder = OutputFolder(out, overwrite)
    if emva_export is not None:
        a, b = Path(emva_export).resolve(), Path(out).resolve()
        if a == b or a in b.parents or b in a.parents:
            raise CmosnoiseError(f"--emva-export {str(emva_export)!r} and --out {str(out)!r} are the same folder or one "
                                 "holds the other; give two separate folders")
        if stack_frames < 3:  # the descriptor format tells a stack from a pair by its length alone
            raise CmosnoiseError(f"--stack-frames {stack_frames} with --emva-export: an EMVA 1288 descriptor holds pairs "
                                 "of 2 frames, and a stack is what has more; give 3 or more")
    export_folder = OutputFolder(emva_export, overwrite, "--emva-export") if emva_export is not None else None
    model, rate = None, None
    if frames_from is not None:
        m = emva_files.load(frames_from)
        if spec is not None:
            model = ch.model_values(Sensor(spec), series_e=m.mu_p * (spec.config.sensor.qe_mean() or 1.0),
                                    shortest_texp_s=float(np.min(m.texp_s)))
    else:
        sensor = Sensor(spec)
        plan = emva_files.load(like) if like is not None else None
        if isinstance(dark_exposures, str):  # "auto": the series the model asks for (none on another's plan)
            dark_exposures = ch.dark_series_times(sensor) if plan is None else None
        dark_steps = 0 if dark_exposures is None else len(dark_exposures)
        advance = progress((len(plan.texp_s) if plan is not None else steps) + 1 + dark_steps) if progress else None
        if plan is not None:  # another data set's exposure times, photons and stack sizes
            m = ch.measure_like(sensor, plan, keep_frames=emva_export is not None, progress=advance,
                                dark_exposures=dark_exposures)
        else:
            m = ch.measure(sensor, steps, stack_frames, keep_frames=emva_export is not None, progress=advance,
                           dark_exposures=dark_exposures)
        # a simulated stack's frames come back to back at the sensor's rate (a descriptor's carry none)
        rate = 1.0 / frame_period_s(sensor.config.sensor.frame_rate_hz, float(m.stack_texp_s))
        model = ch.model_values(sensor, m.stack_texp_s, series_e=m.mu_p * (sensor.config.sensor.qe_mean() or 1.0),
                                shortest_texp_s=float(np.min(m.texp_s)))
    results = ev.evaluate(m)
    spectra = noise_spectrum.of_stack(m.stack_dark, rate)
    notes = ev.footnotes(results) + [spectra_note(spectra)] + (spec.notes if spec is not None else [])
    series = {"texp_s": m.texp_s, "mu_p": m.mu_p, "mu_y_dn": m.mu_y, "mu_ydark_dn": m.mu_ydark,
              "s2_y_dn2": m.s2_y, "s2_ydark_dn2": m.s2_ydark}
    if m.dark_texp_s is not None:
        series["dark_series"] = {"texp_s": m.dark_texp_s, "mu_dn": m.dark_mu_dn, "s2_dn2": m.dark_s2_dn2}
    light = _light_axis(spec, m) if spec is not None else None
    if light is not None:
        series["focal_plane_lux_s"] = light.pop("focal_plane_lux_s")
    with folder as tmp:
        plot_curves(m, results, tmp)
        plot_spectra(m.stack_dark, tmp / "noise_spectra.png")
        write_json(tmp / "characterization.json", {"measured": results, "model": model, "notes": notes,
                                                   "series": series, "spectra": spectra,
                                                   **({"light": light} if light else {})})
    reference = None
    if export_folder is not None:
        with export_folder as tmp:
            emva_files.export(m, tmp)
        try:
            reference = reference_results(emva_export / DESCRIPTOR)
        except CmosnoiseError:
            reference = None  # emva1288 not installed: nothing to compare with
    return {"measured": results, "model": model, "notes": notes, "reference": reference, "spectra": spectra}


def spectra_note(spectra: dict) -> str:
    """One line on the dark stack's noise in time: each spectrum's verdict and slope, or why it is not given."""
    parts, missing = [], []
    for key, d in spectra.items():
        name = key.replace("_", " ")
        if "not_given" in d:
            missing.append(name)
        else:
            lo, hi = d["interval"]
            parts.append(f"{name} {d['verdict'].replace('_', ' ')} (slope {d['slope']:.2f}, 95 % {lo:.2f} to {hi:.2f}"
                         f"{_corners_said(d.get('corners'))})")
    line = "noise in time, from the dark stack: " + ("; ".join(parts) if parts else "no spectrum")
    if missing:
        line += (f"; {', '.join(missing)} need at least {noise_spectrum.MIN_FRAMES} frames "
                 f"(--stack-frames {noise_spectrum.MIN_FRAMES})")
    return line


def _corners_said(corners: dict | None) -> str:
    """", 1/f from 0.03 to 15 Hz" (a corner beyond the stack's band as its bound: "below 0.5 Hz"), or ""."""
    if not corners or "low_hz" not in corners:
        return ""
    low, high = corners["low_hz"], corners["high_hz"]
    a = f"{low['value']:.3g}" if low["resolved"] else f"below {low['interval'][1]:.3g}"
    b = f"{high['value']:.3g}" if high["resolved"] else f"above {high['interval'][0]:.3g}"
    return f", 1/f from {a} to {b} Hz"


def plot_spectra(stack: np.ndarray, path: Path) -> Path | None:
    """The dark stack's Welch spectra (those it resolves) on log axes, each with its fitted slope over its band;
    None when it resolves none."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

    made = []
    for make in (noise_spectrum.over_frames, lambda a: noise_spectrum.over_frames(a, columns=True),
                 noise_spectrum.readout_order):
        with contextlib.suppress(CmosnoiseError):  # a spectrum the stack cannot resolve is not drawn
            made.append(make(stack))
    if not made:
        return None
    fig = Figure(figsize=(4.2 * len(made), 3.8), dpi=100)
    for i, e in enumerate(made):
        ax = fig.add_subplot(1, len(made), i + 1)
        ok = e.f > 0
        ax.loglog(e.f[ok], e.psd[ok], ".-", ms=3, lw=0.8, label="Welch estimate")
        inside = (e.f >= e.band[0]) & (e.f <= e.band[1])
        ref = np.exp(np.mean(np.log(e.psd[inside]) - e.slope * np.log(e.f[inside])))
        ax.loglog(e.f[inside], ref * e.f[inside] ** e.slope, "-", lw=2,
                  label=f"slope {e.slope:.2f} +- {1.96 * e.slope_se:.2f}: {e.verdict.replace('_', ' ')}")
        ax.set_xlabel(f"frequency [{e.unit}]")
        ax.set_ylabel(f"power [DN^2 per {e.unit.split()[-1]}]")
        ax.set_title(e.series, fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    return path


def _light_axis(spec, m: Measurement) -> dict | None:
    """With light in lux: each step's focal-plane exposure (lux-seconds on the axis) that gives its photo-electrons
    under the configured illuminant and spectral QE, and what converts one to the other; None without it."""
    li = spec.light
    if li is None:
        return None
    e_per_lux_s = spec.peak_rate_e_per_s / li.focal_plane_lux  # e- per pixel per lux-second, a white's
    electrons = np.asarray(m.mu_p, float) * (spec.config.sensor.qe_mean() or 1.0)
    return {"focal_plane_lux_s": electrons / e_per_lux_s, "electrons_per_lux_s": e_per_lux_s,
            "illuminant": spec.config.light.illuminant,
            "note": "each step's photo-electrons (mean over the channels) as the focal-plane exposure that gives them "
                    "under this illuminant and spectral QE"}


def plot_curves(m: Measurement, res: dict, out: Path) -> list[Path]:
    """Photon-transfer and SNR curves as PNGs (labelled axes with units, legend, title)."""
    from matplotlib.figure import Figure

    paths = []
    k = res["system_gain_K_dn_per_e"]
    y = m.mu_y - m.mu_ydark
    v = m.s2_y - m.s2_ydark
    fig = Figure(figsize=(6.4, 4.4), dpi=110)
    ax = fig.add_subplot()
    ax.plot(y, v, "o", ms=4, label="measured")
    xs = np.linspace(0, y[res["saturation_index"]], 50)
    if k is not None:
        ax.plot(xs, k * xs, "-", label=f"fit: K = {k:.4f} DN/e-")
    else:
        ax.text(0.03, 0.95, "K cannot be measured: the variance does not grow with the signal",
                transform=ax.transAxes, va="top", fontsize=8)
    ax.axvline(y[res["saturation_index"]], color="grey", ls=":", label="saturation (variance max)")
    ax.set_xlabel("mean signal above dark, mu_y - mu_y.dark [DN]")
    ax.set_ylabel("temporal variance above dark, s2_y - s2_y.dark [DN^2]")
    ax.set_title("Photon transfer (EMVA 1288)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    paths.append(out / "photon_transfer.png")
    fig.savefig(paths[-1])

    fig = Figure(figsize=(6.4, 4.4), dpi=110)
    ax = fig.add_subplot()
    snr = y / np.sqrt(np.maximum(m.s2_y, 1e-12))
    ok = (y > 0) & (np.arange(len(y)) <= res["saturation_index"])
    ax.loglog(m.mu_p[ok], snr[ok], "o", ms=4, label="measured")
    mp = np.logspace(np.log10(max(m.mu_p[ok].min() / 10, 0.1)), np.log10(res["saturation_capacity_photons"]), 100)
    eta, sd = res["quantum_efficiency"], res["temporal_dark_noise_e"]
    if None not in (k, eta, sd):
        model = eta * mp / np.sqrt(sd**2 + 1 / (12 * k**2) + eta * mp)
        ax.loglog(mp, model, "-", label="EMVA model from the fitted eta, sigma_d, K")
    eta = eta if eta is not None else 1.0
    ax.loglog(mp, np.sqrt(eta * mp), ":", label="ideal (shot noise only)" + ("" if res["quantum_efficiency"] else ", eta = 1"))
    ax.set_xlabel("irradiation mu_p [photons per pixel]")
    ax.set_ylabel("SNR (temporal)")
    ax.set_title("SNR curve (EMVA 1288)")
    ax.legend()
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    paths.append(out / "snr.png")
    fig.savefig(paths[-1])
    return paths


