"""EMVA 1288 evaluation: the results a lab reports, from a :class:`~.characterize.Measurement` alone.

The system gain K from the photon-transfer curve, the temporal dark noise
from the dark variance extrapolated to zero exposure, the dark current from
the dark mean's growth with exposure time, the saturation capacity at the
variance maximum, SNR max, dynamic range, DSNU and PRNU (:func:`evaluate`);
and the comparison table with what a configuration implies (:func:`table`,
:func:`footnotes`).

Examples
--------
>>> from cmosnoise import emva_evaluation
>>> emva_evaluation.agrees("system_gain_K_dn_per_e", 0.403, 0.404)   # within the comparison's tolerance
True
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import CmosnoiseError
from ..model.stages import adc
from ..model.stages.nonlinearity import linearity_error
from . import emva
from .characterize import Measurement


def _fit_through_origin(x, y):
    return float(np.sum(x * y) / np.sum(x * x))


def _saturation_index(s2_y: np.ndarray) -> int:
    """Index of the variance maximum (EMVA 1288: the saturation point)."""
    return int(np.argmax(s2_y))


#: a fit needs this many exposure times
MIN_FIT_POINTS = 3
#: the dark series is fitted where no dark pixel is above this fraction of the way to saturation
DARK_FIT_LIMIT = 0.9

#: a dark current below this many standard errors of its slope is "below what this series resolves", and its
#: upper bound is the slope (or 0) plus as many: a one-sided 99.87 % bound
DARK_RESOLVE_Z = 3.0


def _slope(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Least squares line: (slope, its standard error from the residuals, intercept): ``scipy.stats.linregress``."""
    from scipy import stats

    fit = stats.linregress(np.asarray(x, np.float64), np.asarray(y, np.float64))
    return float(fit.slope), float(fit.stderr), float(fit.intercept)


def small_signal_gain(mu_p: np.ndarray, y: np.ndarray, v: np.ndarray, s2_y: np.ndarray,
                      s2_ydark: np.ndarray) -> tuple[float, float]:
    """The small-signal conversion gain K0 (DN/e-): the gain at no signal, where a nonlinearity has not yet bent
    the response.

    Under a nonlinearity ``f`` (output e- per collected e-, ``f'(0) = 1``) the mean is ``y = K0 f(eta mu_p)`` and
    the shot noise's variance ``v = K0^2 f'(x)^2 x``; EMVA 1288's through-the-origin slope of ``v`` against ``y``
    (the photon-transfer K) is then ``K0`` times a mean of ``f'(x)^2 x / f(x)``: 2.2 % high for a 0.5 %
    linearity error. The mean response is measured far more precisely than the variance, so it gives ``f``: a
    polynomial ``P(mu_p) = c1 mu_p + ... + c4 mu_p^4`` fitted to ``y`` (relative least squares) is
    ``K0 f(eta mu_p)``, with ``c1 = K0 eta``, and the variance becomes ``v = K0 z``, ``z = P'(mu_p)^2 mu_p / c1``.
    ``K0`` is the weighted through-the-origin slope of ``v`` on ``z`` (weights ``1 / (s2_y^2 + s2_ydark^2)``, the
    inverse variance of the pair estimators' difference up to a constant). On a linear sensor ``z = y`` and ``K0``
    is the photon-transfer K.

    Parameters
    ----------
    mu_p : (n,) array
        Photons per pixel of the points below 70 % of saturation (any quantity proportional to the exposure).
    y, v : (n,) arrays
        Mean signal above dark (DN) and temporal variance above dark (DN^2) there.
    s2_y, s2_ydark : (n,) arrays
        The bright and dark temporal variances, DN^2.

    Returns
    -------
    (float, float)
        K0 and its standard error (from the weighted residuals), DN/e-; NaN with fewer than 3 points.
    """
    mu_p, y, v = (np.asarray(a, np.float64) for a in (mu_p, y, v))
    ok = (y > 0) & (mu_p > 0)
    mu_p, y, v = mu_p[ok], y[ok], v[ok]
    s2_y, s2_ydark = np.asarray(s2_y, np.float64)[ok], np.asarray(s2_ydark, np.float64)[ok]
    n = len(y)
    if n < 3:
        return math.nan, math.nan
    scale = float(mu_p.max())
    t = mu_p / scale
    powers = np.arange(1, min(4, n - 2) + 1)
    basis = t[:, None] ** powers
    c = np.linalg.lstsq(basis / y[:, None], np.ones(n), rcond=None)[0]  # relative residuals (y - P) / y
    slope = (basis / t[:, None]) @ (c * powers)  # dP/dt
    z = slope**2 * t / c[0]
    w = 1.0 / np.maximum(s2_y**2 + s2_ydark**2, 1e-300)
    szz = float(np.sum(w * z * z))
    k0 = float(np.sum(w * z * v)) / szz
    res = v - k0 * z
    return k0, math.sqrt(float(np.sum(w * res**2)) / (n - 1) / szz)


#: what needs the system gain K (e- values), for when the series cannot give it
_NEEDS_K = ("system_gain_K_dn_per_e", "small_signal_gain_K_dn_per_e", "inverse_gain_e_per_dn", "quantum_efficiency",
            "temporal_dark_noise_e",
            "saturation_capacity_e", "snr_max", "snr_max_db", "absolute_sensitivity_threshold_photons",
            "dynamic_range", "dynamic_range_db", "dark_current_mean_e_per_s", "dark_current_var_e_per_s",
            "dsnu_e", "dsnu_column_e", "dsnu_row_e", "dsnu_pixel_e", "dsnu_shortest_e")


def evaluate(m: Measurement) -> dict:
    """EMVA 1288 results from a :class:`Measurement`, frames only (DN, e-, photons).

    Quantities the frames cannot give are ``None``, with the reason in
    ``unavailable`` (quantity -> why): the system gain K when the temporal
    variance does not grow with the signal (no shot noise), the dark
    series when white pixels near saturation in all but a few exposure
    times. The dark series is fitted only over exposure times where no dark
    pixel is near saturation (``dark_fit_points``), and the PRNU leaves out
    the defect pixels (``prnu_excluded_pixels``, :func:`emva.defect_pixels`).

    Parameters
    ----------
    m : Measurement
        A measurement series (:func:`cmosnoise.analysis.characterize.measure`, or a lab's through
        :func:`cmosnoise.analysis.emva_files.load`).

    Returns
    -------
    dict
        Each quantity by its key (units in its name: ``_dn_per_e``, ``_e``, ``_pct``, ...), ``unavailable`` and
        what was left out.
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
    k0, se_k0 = small_signal_gain(m.mu_p[lin], y[lin], v[lin], m.s2_y[lin], m.s2_ydark[lin])
    r = _fit_through_origin(m.mu_p[lin], y[lin])  # DN/photon
    qe = r / k
    # dark variance and mean against exposure time, where no dark pixel nears saturation:
    # intercept = sigma_y.dark^2, slopes = dark current
    limit = m.mu_ydark[0] + DARK_FIT_LIMIT * (float(np.max(m.mu_y)) - m.mu_ydark[0])
    dark_ok = np.nonzero(m.max_ydark < limit)[0]
    se_m = se_v = math.nan
    if len(dark_ok) >= MIN_FIT_POINTS:
        slope_v, se_v, s2_ydark0 = _slope(m.texp_s[dark_ok], m.s2_ydark[dark_ok])
        slope_m, se_m, _ = _slope(m.texp_s[dark_ok], m.mu_ydark[dark_ok])
    else:
        slope_v = slope_m = s2_ydark0 = math.nan
        why = (f"white pixels come within {100 * (1 - DARK_FIT_LIMIT):.0f} % of saturation in the dark in all but "
               f"{len(dark_ok)} of the {len(m.texp_s)} exposure times (a fit needs {MIN_FIT_POINTS}): "
               "use more --steps (shorter first exposures)")
        for key in ("temporal_dark_noise_e", "temporal_dark_noise_dn", "dark_current_mean_e_per_s",
                    "dark_current_var_e_per_s", "absolute_sensitivity_threshold_photons", "dynamic_range",
                    "dynamic_range_db"):
            unavailable.setdefault(key, why)
    if m.dark_texp_s is not None:  # a dark-current series: the dark current from it
        slope_m, se_m, _ = _slope(m.dark_texp_s, m.dark_mu_dn)
        slope_v, se_v, _ = _slope(m.dark_texp_s, m.dark_s2_dn2)
        for key in ("dark_current_mean_e_per_s", "dark_current_var_e_per_s"):
            unavailable.pop(key, None)
    bounds = {}
    for key, slope, se, kk in (("dark_current_mean_e_per_s", slope_m, se_m, k), ("dark_current_var_e_per_s", slope_v,
                                                                                  se_v, k * k)):
        # (a series without temporal noise has se = 0: its slope is exact, resolved)
        if math.isfinite(slope) and math.isfinite(kk) and se > 0 and not slope > DARK_RESOLVE_Z * se:
            bounds[key] = (max(slope, 0.0) + DARK_RESOLVE_Z * se) / kk
    # the quantizer's variance, step^2 / 12 DN^2 (EMVA 1288's 1/12 where the output is the ADC's codes): a camera
    # that writes a 14-bit ADC in a 16-bit range has codes 4 DN apart, which its frames show
    step = adc.code_step(adc.code_grid(m.stack_bright) | adc.code_grid(m.stack_dark))
    q_var = step**2 / 12
    s2_ydark0 = max(s2_ydark0, q_var + 1e-12) if math.isfinite(s2_ydark0) else math.nan
    sigma_y_dark = math.sqrt(s2_ydark0)
    sigma_d = math.sqrt(s2_ydark0 - q_var) / k
    u_e_sat = y[i_sat] / k
    u_p_sat = m.mu_p[i_sat]
    u_p_min = (sigma_y_dark / k + 0.5) / qe
    sp_b = emva.spatial_variances(m.stack_bright)
    sp_d = emva.spatial_variances(m.stack_dark)
    dsnu = emva.dsnu(m.stack_dark)
    # the DSNU's spatial variance at the noise floor: the stack mean's temporal share (sigma^2 / L) estimated over
    # N pixels has standard error sqrt(2 / N) sigma^2 / L (what :func:`agrees` allows near 0), e-^2
    n_pix = m.stack_dark[0].size
    dsnu_var_se = (math.sqrt(2 / n_pix) * emva.temporal_variance_stack(m.stack_dark) / len(m.stack_dark) / k**2
                   if math.isfinite(k) else math.nan)
    defects = emva.defect_pixels(m.stack_bright, m.stack_dark, float(np.max(m.mu_y)))
    prnu = emva.prnu(m.stack_bright, m.stack_dark, exclude=defects)
    try:  # EMVA 1288's linearity error: the mean signal against the photons, 5 to 95 % of saturation
        le_min, le_max = linearity_error(m.mu_p, y, float(y[i_sat]))
    except ValueError:
        le_min = le_max = math.nan
        unavailable["linearity_error_min_pct"] = unavailable["linearity_error_max_pct"] = (
            "fewer than 3 exposure times between 5 and 95 % of saturation")
    out = {
        "system_gain_K_dn_per_e": k,
        "system_gain_se_dn_per_e": se_k,
        "small_signal_gain_K_dn_per_e": k0 if math.isfinite(k) else math.nan,
        "small_signal_gain_se_dn_per_e": se_k0 if math.isfinite(k) else math.nan,
        "linearity_error_min_pct": le_min,
        "linearity_error_max_pct": le_max,
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
        "dark_current_mean_se_e_per_s": se_m / k,
        "dark_current_var_se_e_per_s": se_v / k**2,
        "dsnu_e": dsnu["total"] / k,
        "dsnu_var_se_e2": dsnu_var_se,
        "dsnu_shortest_e": (math.sqrt(max(m.dsnu_shortest_dn2, 0.0)) / k if m.dsnu_shortest_dn2 is not None
                            else math.nan),
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
        "dark_series_points": 0 if m.dark_texp_s is None else int(len(m.dark_texp_s)),
        "dark_series_longest_s": math.nan if m.dark_texp_s is None else float(np.max(m.dark_texp_s)),
        "dark_series_excluded_pixels": int(m.dark_excluded),
        "output_step_dn": step,
    }
    out = {key: (None if isinstance(val, float) and not math.isfinite(val) else val) for key, val in out.items()}
    out["unavailable"] = unavailable
    out["unresolved"] = bounds
    return out


#: quantities whose measured and model values agree only up to a definition:
#: EMVA's saturation is the variance maximum, below the full well when PRNU
#: spreads the pixels' clipping points
DEFINITION_NOTES = {
    "saturation_capacity_e": "EMVA: mean at the variance maximum; the model gives the full well (or ADC full scale)",
    "snr_max": "from the saturation capacity: sqrt(mu_e.sat), so below the model's as mu_e.sat is",
    "dynamic_range_db": "from the saturation capacity: follows mu_e.sat's definition",
}

#: how closely a fitted sensor must reproduce a measured EMVA 1288 quantity (relative, or in percentage points
#: for the linearity error): the limits the fit's round trip and its foreign-data tests hold it to
AGREEMENT_LIMITS = {"system_gain_K_dn_per_e": 0.03, "temporal_dark_noise_e": 0.05, "dsnu_e": 0.10, "prnu_pct": 0.10,
                    "dark_current_mean_e_per_s": 0.10, "saturation_capacity_e": 0.05, "quantum_efficiency": 0.05}
LINEARITY_POINTS = 0.25


#: standard errors of the difference of two DSNU variances within which two DSNUs at the noise floor agree
FLOOR_Z = 5.0


def agrees(key: str, measured: float, simulated: float, dsnu_var_se_e2: float | None = None) -> bool | None:
    """Whether ``simulated`` reproduces ``measured`` within :data:`AGREEMENT_LIMITS` (None: no limit for it).

    A DSNU is the square root of a spatial variance less the temporal share; on a sensor without a fixed dark
    pattern both are at the noise floor, where a relative limit means nothing: they also agree where their
    variances differ by at most :data:`FLOOR_Z` times ``dsnu_var_se_e2``, the standard error of that difference
    (each side's ``evaluate()["dsnu_var_se_e2"]``, in quadrature).

    Parameters
    ----------
    key : str
        The quantity.
    measured, simulated : float
        Its two values.
    dsnu_var_se_e2 : float, optional
        For ``dsnu_e``: the standard error of the two variances' difference, e-^2.

    Returns
    -------
    bool or None
    """
    if key in ("linearity_error_min_pct", "linearity_error_max_pct"):
        return bool(abs(simulated - measured) <= LINEARITY_POINTS)
    if (key == "dsnu_e" and dsnu_var_se_e2 is not None and math.isfinite(dsnu_var_se_e2)
            and abs(simulated**2 - measured**2) <= FLOOR_Z * dsnu_var_se_e2):
        return True
    if key not in AGREEMENT_LIMITS or not measured:
        return None
    return bool(abs(simulated / measured - 1) <= AGREEMENT_LIMITS[key])


TABLE_ROWS = [
    ("system_gain_K_dn_per_e", "System gain K", "DN/e-", "{:.4f}"),
    ("small_signal_gain_K_dn_per_e", "  small-signal K0 (at no signal)", "DN/e-", "{:.4f}"),
    ("quantum_efficiency", "Quantum efficiency eta", "", "{:.3f}"),
    ("temporal_dark_noise_e", "Temporal dark noise sigma_d", "e-", "{:.3f}"),
    ("saturation_capacity_e", "Saturation capacity mu_e.sat", "e-", "{:.0f}"),
    ("snr_max", "SNR max", "", "{:.1f}"),
    ("dynamic_range_db", "Dynamic range", "dB", "{:.1f}"),
    ("dark_current_mean_e_per_s", "Dark current (from mean)", "e-/s", "{:.3g}"),
    ("dark_current_var_e_per_s", "Dark current (from variance)", "e-/s", "{:.3g}"),
    ("linearity_error_min_pct", "Linearity error min", "%", "{:.3f}"),
    ("linearity_error_max_pct", "Linearity error max", "%", "{:.3f}"),
    ("dsnu_e", "DSNU1288", "e-", "{:.3f}"),
    ("dsnu_column_e", "  of which column (VFPN)", "e-", "{:.3f}"),
    ("dsnu_shortest_e", "DSNU at the shortest exposure", "e-", "{:.3f}"),
    ("prnu_pct", "PRNU1288", "%", "{:.3f}"),
]


def table(measured: dict, model: dict | None) -> list[tuple[str, str, str, str, str]]:
    """Rows (quantity, unit, measured, model, deviation %) for printing; "n/a" where the frames cannot give it.

    Parameters
    ----------
    measured : dict
        :func:`evaluate`'s result.
    model : dict or None
        :func:`cmosnoise.analysis.characterize.model_values`, or None.

    Returns
    -------
    list of (str, str, str, str, str)
    """
    rows = []
    bounds = measured.get("unresolved", {})
    for key, label, unit, fmt in TABLE_ROWS:
        mv = measured.get(key)
        xv = (model or {}).get(key)
        dev = ""
        if key in bounds:  # below what the series resolves: its upper bound, no deviation
            rows.append((label, unit, f"< {fmt.format(bounds[key])}", _cell(fmt, xv) if xv is not None else "", ""))
            continue
        if xv is not None and float(fmt.format(xv)) != 0 and mv is not None and np.isfinite(mv):  # no % of a 0
            dev = f"{100 * (mv - xv) / xv:+.2f}"
        rows.append((label, unit, _cell(fmt, mv) if mv is not None else "n/a", _cell(fmt, xv) if xv is not None else "",
                     dev))
    return rows


def _cell(fmt: str, value: float) -> str:
    """``value`` in ``fmt``; a rounding error's residue (below 1e-12, e.g. a dark current of -5e-15 e-/s) as 0."""
    return fmt.format(0.0 if abs(value) < 1e-12 else value)


def footnotes(measured: dict) -> list[str]:
    """Why a quantity is n/a, what was left out, and the quantities that agree only up to a definition.

    Parameters
    ----------
    measured : dict
        :func:`evaluate`'s result.

    Returns
    -------
    list of str
    """
    labels = {key: label.strip() for key, label, _, _ in TABLE_ROWS}
    out = []
    reasons: dict[str, list[str]] = {}
    for key, why in measured.get("unavailable", {}).items():
        if key in labels:
            reasons.setdefault(why, []).append(labels[key])
    for why, names in reasons.items():
        out.append(f"n/a: {', '.join(names)}: {why}")
    k, k0, se0 = (measured.get(key) for key in ("system_gain_K_dn_per_e", "small_signal_gain_K_dn_per_e",
                                                  "small_signal_gain_se_dn_per_e"))
    if k is not None and k0 is not None and se0 is not None and abs(k - k0) > DARK_RESOLVE_Z * se0:
        out.append(f"System gain K: the photon-transfer K ({k:.4g}) is {100 * (k / k0 - 1):+.1f} % off the "
                   f"small-signal K0 ({k0:.4g} +- {se0:.1g} DN/e-), a nonlinearity's doing; EMVA 1288's e- "
                   "figures (QE, sigma_d, DSNU, saturation) use K: times K/K0 they are small-signal ones")
    step = measured.get("output_step_dn") or 1
    if step > 1:
        out.append(f"the codes are {step} DN apart (an ADC of {step.bit_length() - 1} bit(s) fewer than the output's "
                   f"range): the quantization noise taken out of sigma_d is {step}^2/12 = {step**2 / 12:.3g} DN^2, "
                   "not 1/12")
    longest = measured.get("dark_series_longest_s")
    for key, bound in measured.get("unresolved", {}).items():
        where = (f"its longest dark exposure {longest:.4g} s" if longest else "the photon-transfer series' dark pairs")
        out.append(f"{labels[key]}: below what this series resolves (< {bound:.3g} e-/s, a {DARK_RESOLVE_Z:g}-sigma "
                   f"upper bound; {where}): longer --dark-exposures resolve it")
    if measured.get("dark_series_points"):
        excluded = measured.get("dark_series_excluded_pixels") or 0
        out.append(f"dark current: from a dark series of {measured['dark_series_points']} pairs to {longest:.4g} s"
                   + (f", {excluded} white pixel(s) near saturation left out" if excluded else ""))
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


