"""EMVA 1288 characterization of a simulated (or a real) sensor, from frames alone.

The measurement series follows EMVA 1288 with exposure-time variation under
a constant, uniform irradiation:

- a photon-transfer series: at each of ``steps`` exposure times up to beyond
  saturation, two bright and two dark frames;
- stacks of ``stack_frames`` bright frames (at ~50 % of saturation) and dark
  frames at the same exposure time, for the spatial statistics.

The evaluation (:func:`evaluate`) uses nothing but those frames and the
photon counts, as a lab would: the system gain K from the photon-transfer
curve, the temporal dark noise from the dark variance extrapolated to zero
exposure, the dark current from the dark mean's growth with exposure time,
the saturation capacity at the variance maximum, SNR max, dynamic range,
DSNU and PRNU. :func:`model_values` gives the same quantities as the
simulated sensor instance implies them, for the comparison table.

cmosnoise has no quantum efficiency: the "photons" of a series are the
photo-electrons generated per pixel (eta = 1 before crosstalk's loss to the
substrate and the PRNU gain map).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from .. import inputs
from ..errors import CmosnoiseError
from ..io.stacks import DESCRIPTOR  # the file name export writes and load reads
from ..model.seeds import SEQ_EMVA_BRIGHT, SEQ_EMVA_DARK, SEQ_EMVA_STACK_BRIGHT, SEQ_EMVA_STACK_DARK
from ..model.stages import adc
from . import emva, noise_budget

if TYPE_CHECKING:
    from ..model.sensor import Sensor


#: fewest exposure times of a photon-transfer series: 3 of them below 70 % of saturation
MIN_STEPS = 8


@dataclass
class Measurement:
    """Frames reduced to what EMVA 1288 needs, plus (optionally) the frames themselves."""

    bits: int
    shape: tuple[int, int]
    texp_s: np.ndarray  #: exposure time of each step, s
    mu_p: np.ndarray  #: photons (photo-electrons generated) per pixel at each step
    mu_y: np.ndarray  #: mean of the two bright frames, DN
    mu_ydark: np.ndarray  #: mean of the two dark frames, DN
    s2_y: np.ndarray  #: temporal variance var(A - B)/2, bright, DN^2
    s2_ydark: np.ndarray  #: temporal variance, dark, DN^2
    stack_texp_s: float
    stack_mu_p: float
    stack_bright: np.ndarray  #: (L, rows, cols)
    stack_dark: np.ndarray
    max_ydark: np.ndarray  #: brightest pixel of the two dark frames at each step, DN (to see white pixels saturate)
    frames: dict = field(default_factory=dict)  #: for export: name -> list of frames


def _pair_stats(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    return (float(a.mean()) + float(b.mean())) / 2, emva.temporal_variance(a, b)


def measure(sensor: Sensor, steps: int = 40, stack_frames: int = 16, keep_frames: bool = False,
            progress: Callable[[], None] | None = None) -> Measurement:
    """Run the EMVA 1288 measurement series on ``sensor`` (a :class:`cmosnoise.Sensor`).

    The irradiation is set so that saturation is reached at 1 s; exposure
    times run from 1/steps to 1.3 s. ``steps`` >= MIN_STEPS puts at least
    3 exposure times below 70 % of saturation, where K is fitted.
    """
    if not isinstance(steps, (int, np.integer)) or steps < MIN_STEPS:
        raise CmosnoiseError(f"steps = {steps!r}: the photon-transfer series needs at least {MIN_STEPS} exposure times")
    if not isinstance(stack_frames, (int, np.integer)) or stack_frames < 2:
        raise CmosnoiseError(f"stack_frames = {stack_frames!r}: a stack needs at least 2 frames")
    t = sensor.transfer
    rate = sensor.saturation_e / 1.0  # photo-electrons per second per pixel at scene value 1
    texp = np.linspace(1.3 / steps, 1.3, steps)
    mu_y, mu_yd, s2_y, s2_yd, max_yd = (np.zeros(steps) for _ in range(5))
    frames: dict = {}
    for i, ti in enumerate(texp):
        s = sensor.with_exposure(ti, rate)
        bright = s.expose("flat:1.0", sequence=SEQ_EMVA_BRIGHT)
        dark = s.expose("flat:0", sequence=SEQ_EMVA_DARK)
        a, b = bright.frame(2 * i), bright.frame(2 * i + 1)
        da, db = dark.frame(2 * i), dark.frame(2 * i + 1)
        mu_y[i], s2_y[i] = _pair_stats(a, b)
        mu_yd[i], s2_yd[i] = _pair_stats(da, db)
        max_yd[i] = max(float(da.max()), float(db.max()))
        if keep_frames:
            frames[f"b_{i:03d}"] = [a, b]
            frames[f"d_{i:03d}"] = [da, db]
        if progress:
            progress()
    t50 = 0.5  # half of saturation
    s = sensor.with_exposure(t50, rate)
    sb = s.expose("flat:1.0", sequence=SEQ_EMVA_STACK_BRIGHT)
    sd = s.expose("flat:0", sequence=SEQ_EMVA_STACK_DARK)
    stack_bright = np.stack(list(sb.frames(stack_frames)))
    stack_dark = np.stack(list(sd.frames(stack_frames)))
    if progress:
        progress()
    return Measurement(
        t.bits, sensor.shape, texp, rate * texp, mu_y, mu_yd, s2_y, s2_yd, t50, rate * t50,
        stack_bright, stack_dark, max_yd, frames,
    )


def _fit_through_origin(x, y):
    return float(np.sum(x * y) / np.sum(x * x))


def _saturation_index(s2_y: np.ndarray) -> int:
    """Index of the variance maximum (EMVA 1288: the saturation point)."""
    return int(np.argmax(s2_y))


#: a fit needs this many exposure times
MIN_FIT_POINTS = 3
#: the dark series is fitted where no dark pixel is above this fraction of the way to saturation
DARK_FIT_LIMIT = 0.9

#: what needs the system gain K (e- values), for when the series cannot give it
_NEEDS_K = ("system_gain_K_dn_per_e", "inverse_gain_e_per_dn", "quantum_efficiency", "temporal_dark_noise_e",
            "saturation_capacity_e", "snr_max", "snr_max_db", "absolute_sensitivity_threshold_photons",
            "dynamic_range", "dynamic_range_db", "dark_current_mean_e_per_s", "dark_current_var_e_per_s",
            "dsnu_e", "dsnu_column_e", "dsnu_row_e", "dsnu_pixel_e")


def evaluate(m: Measurement) -> dict:
    """EMVA 1288 results from a :class:`Measurement`, frames only (DN, e-, photons).

    Quantities the frames cannot give are ``None``, with the reason in
    ``unavailable`` (quantity -> why): the system gain K when the temporal
    variance does not grow with the signal (no shot noise), the dark
    series when white pixels near saturation in all but a few exposure
    times. The dark series is fitted only over exposure times where no dark
    pixel is near saturation (``dark_fit_points``), and the PRNU leaves out
    the defect pixels (``prnu_excluded_pixels``, :func:`emva.defect_pixels`).
    """
    unavailable: dict[str, str] = {}
    y = m.mu_y - m.mu_ydark
    v = m.s2_y - m.s2_ydark
    i_sat = _saturation_index(m.s2_y)
    lin = np.nonzero(y <= 0.7 * y[i_sat])[0]
    lin = lin[lin < i_sat]
    if len(lin) < MIN_FIT_POINTS:
        # no variance maximum to speak of (no shot noise: the variance is flat): saturation from the mean instead,
        # where it reaches 98 % of its top (the K test below then says that K cannot be measured)
        i_sat = int(np.argmax(y >= 0.98 * float(np.max(y))))
        lin = np.nonzero(y <= 0.7 * y[i_sat])[0]
        lin = lin[lin < i_sat]
    if len(lin) < MIN_FIT_POINTS:
        raise CmosnoiseError(f"the photon-transfer series has {len(lin)} exposure times below 70 % of saturation, "
                             f"a fit needs {MIN_FIT_POINTS}: use more --steps")
    k = _fit_through_origin(y[lin], v[lin])  # DN/e-
    resid = v[lin] - k * y[lin]
    se_k = math.sqrt(float(np.sum(resid**2)) / (len(lin) - 1) / float(np.sum(y[lin] ** 2)))
    if not k > 5.0 * se_k:
        k = math.nan
        why = (f"needs the system gain K, and the photon-transfer series cannot give it: the temporal variance does "
               f"not grow with the signal (slope {_fit_through_origin(y[lin], v[lin]):.3g} +- {se_k:.2g} DN/e-; "
               "is shot noise off?)")
        unavailable.update({key: why for key in _NEEDS_K})
    r = _fit_through_origin(m.mu_p[lin], y[lin])  # DN/photon
    qe = r / k
    # dark variance and mean against exposure time, where no dark pixel nears saturation:
    # intercept = sigma_y.dark^2, slopes = dark current
    limit = m.mu_ydark[0] + DARK_FIT_LIMIT * (float(np.max(m.mu_y)) - m.mu_ydark[0])
    dark_ok = np.nonzero(m.max_ydark < limit)[0]
    if len(dark_ok) >= MIN_FIT_POINTS:
        slope_v, s2_ydark0 = np.polyfit(m.texp_s[dark_ok], m.s2_ydark[dark_ok], 1)
        slope_m, _ = np.polyfit(m.texp_s[dark_ok], m.mu_ydark[dark_ok], 1)
    else:
        slope_v = slope_m = s2_ydark0 = math.nan
        why = (f"white pixels come within {100 * (1 - DARK_FIT_LIMIT):.0f} % of saturation in the dark in all but "
               f"{len(dark_ok)} of the {len(m.texp_s)} exposure times (a fit needs {MIN_FIT_POINTS}): "
               "use more --steps (shorter first exposures)")
        for key in ("temporal_dark_noise_e", "temporal_dark_noise_dn", "dark_current_mean_e_per_s",
                    "dark_current_var_e_per_s", "absolute_sensitivity_threshold_photons", "dynamic_range",
                    "dynamic_range_db"):
            unavailable.setdefault(key, why)
    s2_ydark0 = max(s2_ydark0, 1 / 12 + 1e-12) if math.isfinite(s2_ydark0) else math.nan
    sigma_y_dark = math.sqrt(s2_ydark0)
    sigma_d = math.sqrt(s2_ydark0 - 1 / 12) / k
    u_e_sat = y[i_sat] / k
    u_p_sat = m.mu_p[i_sat]
    u_p_min = (sigma_y_dark / k + 0.5) / qe
    sp_b = emva.spatial_variances(m.stack_bright)
    sp_d = emva.spatial_variances(m.stack_dark)
    dsnu = emva.dsnu(m.stack_dark)
    defects = emva.defect_pixels(m.stack_bright, m.stack_dark, float(np.max(m.mu_y)))
    prnu = emva.prnu(m.stack_bright, m.stack_dark, exclude=defects)
    out = {
        "system_gain_K_dn_per_e": k,
        "inverse_gain_e_per_dn": 1 / k,
        "quantum_efficiency": qe,
        "responsivity_dn_per_photon": r,
        "temporal_dark_noise_e": sigma_d,
        "temporal_dark_noise_dn": sigma_y_dark,
        "saturation_capacity_e": u_e_sat,
        "saturation_capacity_photons": u_p_sat,
        "snr_max": math.sqrt(u_e_sat),
        "snr_max_db": 20 * math.log10(math.sqrt(u_e_sat)) if u_e_sat > 0 else math.nan,
        "absolute_sensitivity_threshold_photons": u_p_min,
        "dynamic_range": u_p_sat / u_p_min,
        "dynamic_range_db": 20 * math.log10(u_p_sat / u_p_min) if u_p_sat / u_p_min > 0 else math.nan,
        "dark_current_mean_e_per_s": slope_m / k,
        "dark_current_var_e_per_s": slope_v / k**2,
        "dsnu_e": dsnu["total"] / k,
        "dsnu_column_e": dsnu["column"] / k,
        "dsnu_row_e": dsnu["row"] / k,
        "dsnu_pixel_e": dsnu["pixel"] / k,
        "dsnu_dn": dsnu["total"],
        "dsnu_column_dn": dsnu["column"],
        "prnu_pct": 100 * prnu,
        "prnu_excluded_pixels": int(defects.sum()),
        "stack_mean_bright_dn": sp_b["mean"],
        "stack_mean_dark_dn": sp_d["mean"],
        "saturation_index": i_sat,
        "linear_fit_points": int(len(lin)),
        "dark_fit_points": int(len(dark_ok)),
        "series_points": int(len(m.texp_s)),
    }
    out = {key: (None if isinstance(val, float) and not math.isfinite(val) else val) for key, val in out.items()}
    out["unavailable"] = unavailable
    return out


def model_values(sensor: Sensor, stack_texp_s: float = 0.5) -> dict:
    """The same quantities as the simulated sensor instance implies them (its configuration and maps).

    DSNU: the EMVA estimator applied to the expected dark image at the
    stack's exposure time, with the full-well and ADC clips (white pixels
    that saturate count at the saturation level, as in the frames). PRNU:
    the photo-response map (PRNU gain, crosstalk, column gain) of every pixel.
    """
    c = sensor.config
    t = sensor.transfer
    fp = sensor.fixed_pattern
    k = t.gain_dn_per_e
    tv = noise_budget.temporal_variances(sensor, 0.0)
    read_var = sum(v for name, v in tv.items() if name not in ("dark_shot", "quantization", "photon_shot"))
    sat_e = sensor.saturation_e
    s = sensor.with_exposure(1.0, 1.0)
    shot = s.expose("flat:1.0")
    signal = shot.photo_mean_e.astype(np.float64)
    if fp.column_gain is not None:
        signal = signal * fp.column_gain
    qe = float(signal.mean())  # photo-electrons collected per photon
    dark = np.zeros(sensor.shape) if fp.dark_rate is None else fp.dark_rate.astype(np.float64)
    mo = noise_budget.clipped_moments(sensor.with_exposure(stack_texp_s), 0.0)
    expected_dark = mo["mean"]
    if c.adc.enabled:  # the quantizer: undithered where the temporal noise is well below a DN (adds its pattern)
        dn = adc.expected_code(mo["mean"] * k + t.black_level_dn, np.sqrt(mo["var"]) * k)
        expected_dark = (dn - t.black_level_dn) / k
    sp = emva.spatial_variances(expected_dark[None])
    sigma_y_dark = math.sqrt(read_var * k**2 + 1 / 12)
    u_p_min = (sigma_y_dark / k + 0.5) / qe
    return {
        "system_gain_K_dn_per_e": k,
        "inverse_gain_e_per_dn": 1 / k,
        "quantum_efficiency": qe,
        "temporal_dark_noise_e": math.sqrt(read_var),
        "saturation_capacity_e": sat_e,
        "snr_max": math.sqrt(sat_e),
        "dynamic_range_db": 20 * math.log10(sat_e / qe / u_p_min),
        "dark_current_mean_e_per_s": float(dark.mean()),
        "dark_current_var_e_per_s": float(dark.mean()) if c.dark_current.shot_noise else 0.0,
        "dsnu_e": math.sqrt(max(sp["total"], 0.0)),
        "dsnu_column_e": math.sqrt(max(sp["column"], 0.0)),
        "prnu_pct": 100 * float(signal.std(ddof=1) / signal.mean()),  # ddof=1 as the EMVA estimator (matters on tiny sensors)
    }


#: quantities whose measured and model values agree only up to a definition:
#: EMVA's saturation is the variance maximum, below the full well when PRNU
#: spreads the pixels' clipping points
DEFINITION_NOTES = {
    "saturation_capacity_e": "EMVA: mean at the variance maximum; the model gives the full well (or ADC full scale)",
    "snr_max": "from the saturation capacity: sqrt(mu_e.sat), so below the model's as mu_e.sat is",
    "dynamic_range_db": "from the saturation capacity: follows mu_e.sat's definition",
}

TABLE_ROWS = [
    ("system_gain_K_dn_per_e", "System gain K", "DN/e-", "{:.4f}"),
    ("quantum_efficiency", "Quantum efficiency eta", "", "{:.3f}"),
    ("temporal_dark_noise_e", "Temporal dark noise sigma_d", "e-", "{:.3f}"),
    ("saturation_capacity_e", "Saturation capacity mu_e.sat", "e-", "{:.0f}"),
    ("snr_max", "SNR max", "", "{:.1f}"),
    ("dynamic_range_db", "Dynamic range", "dB", "{:.1f}"),
    ("dark_current_mean_e_per_s", "Dark current (from mean)", "e-/s", "{:.2f}"),
    ("dark_current_var_e_per_s", "Dark current (from variance)", "e-/s", "{:.2f}"),
    ("dsnu_e", "DSNU1288", "e-", "{:.3f}"),
    ("dsnu_column_e", "  of which column (VFPN)", "e-", "{:.3f}"),
    ("prnu_pct", "PRNU1288", "%", "{:.3f}"),
]


def table(measured: dict, model: dict | None) -> list[tuple[str, str, str, str, str]]:
    """Rows (quantity, unit, measured, model, deviation %) for printing; "n/a" where the frames cannot give it."""
    rows = []
    for key, label, unit, fmt in TABLE_ROWS:
        mv = measured.get(key)
        xv = (model or {}).get(key)
        dev = ""
        if xv is not None and float(fmt.format(xv)) != 0 and mv is not None and np.isfinite(mv):  # no % of a 0
            dev = f"{100 * (mv - xv) / xv:+.2f}"
        rows.append((label, unit, fmt.format(mv) if mv is not None else "n/a", fmt.format(xv) if xv is not None else "", dev))
    return rows


def footnotes(measured: dict) -> list[str]:
    """Why a quantity is n/a, what was left out, and the quantities that agree only up to a definition."""
    labels = {key: label.strip() for key, label, _, _ in TABLE_ROWS}
    out = []
    reasons: dict[str, list[str]] = {}
    for key, why in measured.get("unavailable", {}).items():
        if key in labels:
            reasons.setdefault(why, []).append(labels[key])
    for why, names in reasons.items():
        out.append(f"n/a: {', '.join(names)}: {why}")
    fit, steps = measured.get("dark_fit_points"), measured.get("series_points")
    if fit is not None and steps is not None and MIN_FIT_POINTS <= fit < steps:
        out.append(f"dark current and sigma_d: fitted over the {fit} shortest of {steps} exposure times (in the longer "
                   "ones white pixels near saturation in the dark)")
    if measured.get("prnu_excluded_pixels"):
        out.append(f"PRNU1288 leaves out {measured['prnu_excluded_pixels']} defect pixel(s) (dark outliers beyond 5 "
                   "robust sigma, or near saturation in the bright stack)")
    for key, note in DEFINITION_NOTES.items():
        out.append(f"{labels[key]}: {note}")
    return out


# ------------------------------------------------------------------ plots
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


# ------------------------------------------------------------------ descriptor files


def export(m: Measurement, folder: Path) -> Path:
    """Write the frames as TIFFs and an EMVA 1288 descriptor file (exposure in ns, photons per pixel)."""
    import tifffile

    images = folder / "images"
    images.mkdir(parents=True, exist_ok=True)
    lines = ["# EMVA 1288 measurement written by cmosnoise", "v 3.0", f"n {m.bits} {m.shape[1]} {m.shape[0]}"]

    def add(header: str, name: str, frames):
        lines.append(header)
        for j, f in enumerate(frames):
            rel = f"images/{name}_{j:03d}.tif"
            tifffile.imwrite(folder / rel, f.astype(np.uint16), photometric="minisblack")
            lines.append(f"i {rel}")

    for i, (t, p) in enumerate(zip(m.texp_s, m.mu_p)):
        add(f"b {t * 1e9:.1f} {p:.4f}", f"b_{i:03d}", m.frames[f"b_{i:03d}"])
    for i, t in enumerate(m.texp_s):
        add(f"d {t * 1e9:.1f}", f"d_{i:03d}", m.frames[f"d_{i:03d}"])
    add(f"b {m.stack_texp_s * 1e9:.1f} {m.stack_mu_p:.4f}", "b_stack", m.stack_bright)
    add(f"d {m.stack_texp_s * 1e9:.1f}", "d_stack", m.stack_dark)
    path = folder / DESCRIPTOR
    path.write_text("\n".join(lines) + "\n")
    return path


def load(descriptor: Path) -> Measurement:
    """A :class:`Measurement` from an EMVA 1288 descriptor file and its images (e.g. a real camera's)."""
    import tifffile

    from ..io.stacks import descriptor_path, parse_descriptor

    bits, shape, entries = parse_descriptor(descriptor_path(Path(descriptor)))

    def read(paths):
        out = []
        for p in paths:
            inputs.check_image_pixels(p, "EMVA image", inputs.MAX_FRAME_PIXELS, inputs.MAX_FRAME_PIXELS)
            try:
                img = tifffile.imread(p)
            except Exception as exc:
                raise CmosnoiseError(f"EMVA image cannot be read: {' '.join(str(exc).split())[:200]}") from None
            if img.shape != shape:
                raise CmosnoiseError(f"EMVA image {str(p)!r} is {img.shape[-1] if img.ndim else 0} x "
                                     f"{img.shape[0] if img.ndim else 0} (shape {img.shape}); the descriptor says "
                                     f"{shape[1]} x {shape[0]}")
            out.append(img)
        return out

    bright_pairs = sorted((e for e in entries if e[0] == "b" and len(e[3]) == 2), key=lambda e: e[1])
    dark_pairs = {round(e[1], 12): e for e in entries if e[0] == "d" and len(e[3]) == 2}
    stacks_b = [e for e in entries if e[0] == "b" and len(e[3]) > 2]
    stacks_d = [e for e in entries if e[0] == "d" and len(e[3]) > 2]
    if len(bright_pairs) < 3 or not stacks_b or not stacks_d:
        raise CmosnoiseError("an EMVA descriptor needs at least 3 bright pairs with dark pairs, and a bright and a dark stack")
    times = sorted({round(e[1], 12) for e in bright_pairs})
    if len(times) < 3 or times[0] < 0:
        raise CmosnoiseError(f"EMVA descriptor: the bright pairs have {len(times)} distinct exposure time(s) "
                             f"({', '.join(f'{t * 1e9:g}' for t in times[:5])} ns); the series needs at least 3 "
                             "distinct times >= 0")
    texp, mu_p, mu_y, mu_yd, s2_y, s2_yd, max_yd = [], [], [], [], [], [], []
    for _, t, p, paths in bright_pairs:
        d = dark_pairs.get(round(t, 12))
        if d is None:
            raise CmosnoiseError(f"EMVA descriptor: no dark pair at exposure {t * 1e9:g} ns")
        a, b = read(paths)
        da, db = read(d[3])
        my, sy = _pair_stats(a, b)
        md, sd = _pair_stats(da, db)
        texp.append(t); mu_p.append(p); mu_y.append(my); s2_y.append(sy); mu_yd.append(md); s2_yd.append(sd)
        max_yd.append(max(float(da.max()), float(db.max())))
    sb, sdk = stacks_b[0], stacks_d[0]
    return Measurement(
        bits, shape, *map(np.array, (texp, mu_p, mu_y, mu_yd, s2_y, s2_yd)), sb[1], sb[2],
        np.stack(read(sb[3])), np.stack(read(sdk[3])), np.array(max_yd),
    )
