"""``cmosnoise fit``: every stage docs/model.md describes, fitted to a measured data set (:class:`~cmosnoise.io.stacks.Dataset`).

What is fitted from what (docs/sensor/fit.md says the same for a lab):

=========================================  ===================================================================
parameter                                  needs
=========================================  ===================================================================
system gain K, full well                   flat stacks (>= 2 frames) at >= 8 levels up to beyond saturation,
                                           each with a dark stack at its exposure time
quantum efficiency (reported only)         the same, with photons per pixel for every flat
black level                                dark stacks at >= 2 exposure times
dark current (family, mean, std, tail)     dark stacks at >= 2 exposure times per temperature
doubling temperatures (body, tail)         the above at >= 2 temperatures
source follower, row noise, column noise,  one long dark stack (>= 4 frames; 50 to 100 recommended), the
VFPN, fixed row offsets                    shortest exposure time is best
PRNU, column gain mismatch                 a flat stack (>= 2 frames; 16+ recommended) near half saturation
                                           and a dark stack at its exposure time
crosstalk (per colour with a CFA)          a spot stack: single lit pixels, 3 or more apart, and a dark
                                           stack at its exposure time
random telegraph pixels (ppm, amplitude,   the long dark stack with >= 50 frames (read a second time, whole),
dwell times)                               its frame period (the manifest's ``frame_period_s``)
=========================================  ===================================================================

Every parameter is reported as ``{value, ci95, method, basis}``; one that the
data cannot give is listed in ``not_fitted`` with what it needs and keeps the
base configuration's value. ``basis`` says how the value was obtained
(:data:`BASES`): measured (with its interval), derived (from measured values,
without an interval of its own), assumed (a value the data cannot see past,
named in the method), or not identifiable (the data give only a combination:
``identifiable`` names the parameter that carries it). The temperature is
``meta["temperature_basis"]``: given, from the data, or assumed.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..errors import CmosnoiseError
from ..estimators import Z95, robust_centre
from ..model import physics
from ..model.spec import resolve
from . import fit_dark, fit_photo, fit_readout, fit_telegraph, noise_spectrum, white_pixels
from .fit_readout import centred_series, sigma_from_variance

#: a dark pixel's mean counts for its dark current only below this fraction of the way from black to saturation
DARK_FIT_LIMIT = 0.9
#: the shortest long dark stack the readout fits accept
MIN_READOUT_FRAMES = 4
#: the shortest dark stack the random telegraph fit reads (a pixel's series must show both levels many times)
MIN_TELEGRAPH_FRAMES = 50
#: the most memory the random telegraph fit's frames may take (the middle rows that fit are read where more)
TELEGRAPH_BYTES = 1 << 30


#: the family-wise false-positive rate of switching on stages the data do not have: each test of
#: :data:`SELECTION_TESTS` switches its stage on only at p < SELECTION_ALPHA / len(SELECTION_TESTS) (Bonferroni),
#: so data without any of them switch one on in at most 1 % of data sets (benchmarks/fit_selection.py measures it)
SELECTION_ALPHA = 0.01
#: the stages a fit switches on from a test (each test's null hypothesis: the stage is absent)
SELECTION_TESTS = ("nonlinearity", "pixel_offset", "pixel_offset.tail", "black_level.frame_sigma_dn",
                   "black_level.channel_offsets_dn", "read_noise.shape")
#: the p-value below which one test switches its stage on
SELECTION_P = SELECTION_ALPHA / len(SELECTION_TESTS)


def _select(selection: dict, name: str, p_value: float, what: str) -> bool:
    """Record test ``name``'s p-value (``what`` it tested) in ``selection``; whether its stage is switched on."""
    on = bool(p_value < SELECTION_P)
    selection[name] = {"p_value": float(p_value), "threshold": SELECTION_P, "on": on, "test": what}
    return on


#: how a fitted value was obtained: fit.json's ``basis``, the console's and the report's, config.yaml's comments
BASES = ("measured", "derived", "assumed", "not identifiable")


def _with_basis(P: dict) -> None:
    """Give every parameter without one its basis: measured where it has an interval (its own, or one per element
    of a kernel or a cell map), else derived."""
    for p in P.values():
        interval = any(p.get(key) is not None for key in ("ci95", "ci95_pct", "ci95_each"))
        p.setdefault("basis", "measured" if interval else "derived")


def _temperature_basis(ds, temperature_c, base) -> str:
    """How the fit's reference temperature was obtained, before stacks without one take it."""
    if all(st.temperature_c is not None for st in ds.stacks):
        return "given (--temperature)" if temperature_c is not None and not ds.temperatures_stated else "from the data"
    return (f"assumed: the data carry none, so the base configuration's sensor.temperature_c "
            f"({base.sensor.temperature_c:g} C); give --temperature or the manifest's temperature_c")


def _p(value, ci95=None, method: str = "", **extra) -> dict:
    out = {"value": value, "ci95": None if ci95 is None else [float(c) for c in ci95], "method": method}
    out.update(extra)
    return out


def _in_electrons(name: str) -> bool:
    """Whether a fitted parameter is in e- or e-/s: measured in DN and divided by K (not K itself, DN per e-)."""
    return name.endswith(("_e", "_e_per_s")) and not name.endswith("_per_e")


def _include_gain_uncertainty(P: dict, k_rel_se: float) -> None:
    """Widen the interval of every parameter in e- or e-/s by K's relative standard error ``k_rel_se``, in
    quadrature on each side: such a parameter is a DN figure over K, only as sure as K."""
    for name, p in P.items():
        if not _in_electrons(name) or p.get("ci95") is None or not isinstance(p.get("value"), (int, float)):
            continue
        v, (lo, hi) = float(p["value"]), p["ci95"]
        g = Z95 * k_rel_se * abs(v)
        new_lo = v - math.hypot(v - lo, g)
        p["ci95"] = [max(new_lo, 0.0) if lo >= 0 else new_lo, v + math.hypot(hi - v, g)]  # a sigma or rate stays >= 0
        p["method"] += "; interval includes K's uncertainty"


def _same(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-9 * max(abs(a), abs(b), 1e-12)


def _dark_at(ds, stack):
    """The dark stack at the same exposure and temperature as ``stack`` (the one with most frames), or None."""
    cands = [d for d in ds.of_kind("dark") if _same(d.exposure_s, stack.exposure_s) and d.temperature_c == stack.temperature_c]
    return max(cands, key=lambda d: d.n) if cands else None


def _intercept(times: np.ndarray, means: np.ndarray, var_means: np.ndarray) -> tuple[float, float, float]:
    """Least-squares line of ``means`` over ``times``: intercept, its standard error, slope."""
    A = np.stack([np.ones_like(times), times], axis=1)
    coef, *_ = np.linalg.lstsq(A, means, rcond=None)
    C = np.linalg.pinv(A.T @ A) @ A.T  # coefficients as linear combinations of the means
    se = math.sqrt(float(np.sum(C[0] ** 2 * var_means)))
    if times.size > 3:  # the residual scatter, when it says more than the noise
        resid = means - A @ coef
        s2 = float(np.sum(resid**2)) / (times.size - 2)
        se = max(se, math.sqrt(s2 * float(np.linalg.pinv(A.T @ A)[0, 0])))
    return float(coef[0]), se, float(coef[1])


def _photon_transfer(ds, P: dict, not_fitted: dict, selection: dict, plots: dict) -> tuple:
    """K from the photon transfer (EMVA 1288), the QE and the mean response's nonlinearity where the photons
    are known, each into ``P`` (or ``not_fitted``): (the transfer's fit, the (signal, variance, flat, dark)
    points, the nonlinearity's fit or None)."""
    rows, cols = ds.shape
    flats = ds.of_kind("flat")
    pts = []
    for f in flats:
        d = _dark_at(ds, f)
        if d is not None:
            pts.append((float(f.mean.mean() - d.mean.mean()), f.temporal_var - d.temporal_var, f, d))
    if len(pts) < 3:
        raise CmosnoiseError(f"system gain K: {len(pts)} flat stack(s) with a dark stack at the same exposure time and "
                             "temperature; the photon transfer needs at least 3 (recommended: 8 to 50 levels up to "
                             "beyond saturation). Everything in electrons depends on K")
    ptc = fit_photo.photon_transfer([p[0] for p in pts], [p[1] for p in pts], frames=[p[2].n for p in pts],
                                    dark_var=[p[3].temporal_var for p in pts], dark_frames=[p[3].n for p in pts])
    k = ptc["K"]
    P["system_gain_K_dn_per_e"] = _p(k, ptc["ci95"], f"photon transfer (EMVA 1288): slope through the origin of "
                                     f"{ptc['fit_points']} levels below 70 % of saturation, each weighted by the "
                                     "inverse of its variance's sampling variance")
    photons = [p[2].photons for p in pts]
    nonlin = None
    if all(ph is not None and ph > 0 for ph in photons):
        npix = rows * cols
        mean_var = [p[2].temporal_var / (npix * p[2].n) + p[3].temporal_var / (npix * p[3].n) for p in pts]
        nonlin = fit_photo.nonlinearity([p[0] for p in pts], [p[1] for p in pts], photons, k,
                                        ptc["saturation_index"], mean_var, alpha=SELECTION_P)
        _select(selection, "nonlinearity", nonlin["p_value"], "F test of a quartic mean response against a line")
        if nonlin["bent"]:  # the QE is the bent response's small-signal slope
            P["quantum_efficiency"] = _p(nonlin["qe"], [nonlin["qe"] - Z95 * nonlin["qe_se"],
                                                        nonlin["qe"] + Z95 * nonlin["qe_se"]],
                                         f"the small-signal slope of the mean signal (e-) over photons, a quartic "
                                         f"through the origin of {nonlin['levels']} levels below saturation")
            P["nonlinearity.acts_on"] = _p(nonlin["acts_on"], None, "the photon transfer's variance follows "
                                           + ("f'(c)^2 c: the conversion bends after the shot noise"
                                              if nonlin["acts_on"] == "charge" else
                                              "the mean: the collection bends before the shot noise"))
        else:
            qe = fit_photo.quantum_efficiency([p[0] for p in pts], photons, k, ptc["saturation_index"], ptc["rel_se"])
            P["quantum_efficiency"] = _p(qe["value"], qe["ci95"], f"photo-electrons (signal / K) over photons per "
                                         f"pixel, {qe['points']} levels below 70 % of saturation")
            not_fitted["nonlinearity"] = (f"the mean signal is a straight line in the photons (F test of a quartic, "
                                          f"p = {nonlin['p_value']:.2g}): left off")
    else:
        why = "needs the photons per pixel of every flat stack (EMVA 'b' lines, manifest 'photons')"
        not_fitted["quantum_efficiency"] = not_fitted["nonlinearity"] = why
    plots["ptc"] = {"mu": ptc["mu"].tolist(), "v": ptc["v"].tolist(), "linear": ptc["linear"].tolist(), "K": k,
                    "saturation_index": ptc["saturation_index"]}
    return ptc, pts, nonlin


def _black_level(ds, t_ref: float, sat_dn: float, P: dict) -> float:
    """The black level (DN) into ``P``: the intercept of the dark mean over the dark stacks' exposure times at
    the reference temperature, or one stack's mean."""
    darks_ref = [d for d in ds.of_kind("dark") if d.temperature_c == t_ref] or ds.of_kind("dark")
    usable = [d for d in darks_ref if float(np.mean(d.mean >= DARK_FIT_LIMIT * sat_dn)) < 0.01]
    times = np.array([d.exposure_s for d in usable])
    if len(set(np.round(times, 12))) >= 2:
        # over the pixels that stay below the limit in every stack (white pixels that clip would bend the line)
        below = np.logical_and.reduce([d.mean < DARK_FIT_LIMIT * sat_dn for d in usable])
        var_m = np.array([float(np.var(d.row_means.mean(axis=1), ddof=1)) / d.n for d in usable])
        b, se_b, _ = _intercept(times, np.array([float(d.mean[below].mean()) for d in usable]), var_m)
        P["black_level_dn"] = _p(b, [b - Z95 * se_b, b + Z95 * se_b],
                                 f"intercept of the dark mean over {len(usable)} dark stacks' exposure times "
                                 "(the black level plus the mean fixed offsets)")
    elif usable:
        d = min(usable, key=lambda d: d.exposure_s)
        b = float(d.mean.mean())
        P["black_level_dn"] = _p(b, None, f"mean of the only dark exposure time ({d.exposure_s:g} s): includes its dark signal")
    else:
        raise CmosnoiseError("black level: no dark stack below saturation; the fit needs dark stacks")
    if ds.black_level_dn is not None:
        P["black_level_dn"]["metadata_dn"] = ds.black_level_dn
    return P["black_level_dn"]["value"]


def fit_dataset(ds, base, temperature_c: float | None = None, threshold_e_per_s: float | None = None,
                seed: int = 0, phase: Callable[[str], None] = lambda name: None) -> dict:
    """Fit ``ds`` (a :class:`~cmosnoise.io.stacks.Dataset`); ``base`` (a Config) gives what is not fitted.

    Returns ``{"parameters": {...}, "not_fitted": {...}, "dark": {T: {...}}, "plots": {...}, "meta": {...}}``.
    ``phase`` is told each part as it starts ("photon transfer", "black level", ...: a progress display's text).
    """
    P: dict = {}
    not_fitted: dict = {}
    plots: dict = {}
    selection: dict = {}
    rows, cols = ds.shape
    # an EMVA 1288 data set is one channel (the standard measures a colour sensor channel by channel): monochrome
    # unless told otherwise; a manifest without a CFA takes the base configuration's
    pattern = ds.cfa or ("none" if ds.kind == "emva" else base.sensor.cfa)
    bits = ds.bits  # the output's range
    if bits is None:
        top = max(s.max_dn for s in ds.stacks)
        bits = next(b for b in range(8, 17) if top < 2**b)
    # codes a step apart: an ADC of fewer bits, its codes scaled to the output's range (a 14-bit ADC in 16 bits);
    # the quantizer's variance is step^2 / 12 DN^2
    step = min(ds.code_step, 2 ** (bits - 8))
    sat_dn = 2**bits - step
    temps = ds.temperatures
    t_basis = _temperature_basis(ds, temperature_c, base)
    t_ref = temperature_c if temperature_c is not None else (temps[-1] if temps else base.sensor.temperature_c)
    for st in ds.stacks:  # stacks measured at no stated temperature: at the reference one
        if st.temperature_c is None:
            st.temperature_c = t_ref
    temps = ds.temperatures

    # ---------------------------------------------------------------- photon transfer
    phase("photon transfer")
    ptc, pts, nonlin = _photon_transfer(ds, P, not_fitted, selection, plots)
    k = ptc["K"]

    # ---------------------------------------------------------------- black level (reference temperature)
    phase("black level")
    black = _black_level(ds, t_ref, sat_dn, P)

    i_sat = ptc["saturation_index"]
    if i_sat < len(ptc["mu"]) - 1:
        brightest = max(pts, key=lambda p: p[0])
        top = float(brightest[2].mean.mean())
        full = (top - black) / k
        adc_e = (sat_dn - black) / k
        if np.mean(brightest[2].mean >= sat_dn - 0.5) > 0.05:
            # pixels sit at the top code: the ADC clips before the well fills, which the data cannot see
            # past; a full well just beyond the ADC's range lets the ADC clip, as measured
            P["full_well_e"] = _p(1.005 * adc_e, None, f"the ADC's range ({adc_e:.0f} e-) clips first: pixels of "
                                  "the brightest flat sit at the top code; the well is put just beyond it",
                                  basis="assumed")
        else:
            P["full_well_e"] = _p(full, None, "the brightest flat's mean above black / K (beyond the saturation point)")
    else:
        not_fitted["full_well_e"] = "the flat levels do not reach saturation (the variance never turns down); add brighter flats"

    # ---------------------------------------------------------------- random telegraph pixels: the longest dark stack
    phase("random telegraph pixels")
    longs = [d for d in ds.of_kind("dark") if d.n >= MIN_READOUT_FRAMES]
    telegraph: dict = {}
    rts_pixels = None
    if longs:  # first: their held levels are neither pixel offsets nor the source follower's noise, so those leave them out
        st = max(longs, key=lambda d: (d.n, -d.exposure_s))
        rts_pixels = _telegraph(st, k, P, not_fitted, seed, telegraph, plots, base.source_follower.rts.cds_interval_s)

    # ---------------------------------------------------------------- dark current at each temperature
    phase("dark current")
    dark_maps: dict[float, np.ndarray] = {}
    slope_var: dict[float, np.ndarray] = {}
    clipped: dict[float, np.ndarray] = {}
    dark_fits: dict[float, dict] = {}
    for T in temps:
        ds_T = [d for d in ds.of_kind("dark") if d.temperature_c == T]
        limit = black + DARK_FIT_LIMIT * (sat_dn - black)
        # a stack where most pixels clip says nothing; where a few white pixels clip, those pixels leave it out
        ok = [d for d in ds_T if float(np.mean(d.mean >= limit)) < 0.01]
        t = np.array([d.exposure_s for d in ok])
        if len(set(np.round(t, 12))) < 2:
            not_fitted[f"dark_current at {T:g} C"] = (f"needs dark stacks at 2 or more exposure times below saturation "
                                                      f"at {T:g} C (has {len(set(np.round(t, 12)))})")
            continue
        rates = fit_dark.rate_map_from_stacks([d.mean for d in ok], list(t), k, limit_dn=limit)
        clipped[T] = fit_dark.clipped_pixels([d.mean for d in ok], limit)
        tc = t - t.mean()
        w = tc / np.sum(tc * tc)
        noise_var = float(np.sum(w**2 * np.array([d.temporal_var / d.n for d in ok]))) / k**2
        # each pixel's slope variance, (e-/s)^2: what its dark shot noise at another exposure is uncertain by
        slope_var[T] = sum(wi**2 * d.pixel_var / d.n for wi, d in zip(w, ok)) / k**2
        thr = threshold_e_per_s
        points = physics.dark_points(base)
        if thr is None and points:  # the base's white-pixel threshold at its nearest point, when above the body
            cand = min(points, key=lambda p: abs(p.temperature_c - T)).threshold
            med, robust = robust_centre(rates)
            if cand is not None and cand > med + 5 * robust:
                thr = cand
        # every pixel's slope shares the frames' whole-map mean noise (row and column noise, averaged)
        common = float(np.sum(w**2 * np.array([np.var(d.row_means.mean(axis=1), ddof=1) / d.n for d in ok]))) / k**2
        res = fit_dark.fit_point(rates, noise_var, thr, common)
        wp = white_pixels.report(rates, res["threshold"], pattern)
        from scipy import stats

        wp["couplets_p_value_random"] = float(stats.poisson.sf(wp["couplets"] - 1, wp["couplets_expected_random"])) \
            if wp["couplets"] > 0 else 1.0
        res["white_pixels"] = wp
        res["exposures_s"] = sorted(set(float(x) for x in t))
        if t_ref == T:  # the pixel offsets: each pixel's intercept, at the reference temperature
            off = fit_dark.pixel_offsets([d.mean for d in ok], list(t), [d.pixel_var for d in ok], [d.n for d in ok],
                                         k, limit, exclude=rts_pixels, tail_alpha=SELECTION_P)
            _select(selection, "pixel_offset", off["p_value"], "the offsets' variance against 0 (one-sided z)")
            _select(selection, "pixel_offset.tail", off["tail_p_value"], "the count above 5 body sigmas against the "
                    "body's share (Poisson)")
            where = (f"each pixel's dark intercept over {len(ok)} exposure times, rows and columns taken out "
                     f"(temporal noise {off['noise_e']:.3g} e- rms): {off['method']}, {off['pixels']} pixels")
            P["pixel_offset.sigma_e"] = _p(off["sigma_e"]["value"], off["sigma_e"]["ci95"], where)
            if off["tail"] is not None:
                tl = off["tail"]
                P["pixel_offset.tail.ppm_above"] = _p(tl["ppm_above"], tl["ci95"], f"pixels whose intercept is above "
                                                      f"{tl['threshold_e']:.4g} e- (exact binomial interval)",
                                                      threshold_e=tl["threshold_e"])
                P["pixel_offset.tail.max_e"] = _p(tl["max_e"], None, "largest intercept above the body")
            plots["pixel_offset"] = {"residual": off["residual_e"]}
            cells, cse = off["cells_dn"].ravel(), off["cells_se_dn"].ravel()
            # the four positions less their mean, sum((c_i - mean)^2 / se^2) ~ chi-square with three degrees of
            # freedom: kept where they differ beyond what their errors allow (95 % level), else one black level
            if _select(selection, "black_level.channel_offsets_dn", float(stats.chi2.sf(np.sum((cells / cse) ** 2), 3)),
                       "the four 2 x 2 positions' intercepts against one (chi-square, 3 dof)"):
                P["black_level.channel_offsets_dn"] = _p(
                    [float(x) for x in cells], None, "each 2 x 2 cell position's mean dark intercept less the four's "
                    "mean (in sensor.cfa's order)", ci95_each=[[float(x - Z95 * e), float(x + Z95 * e)]
                                                                for x, e in zip(cells, cse)])
            # the intercept holds this sensor's mean offset; another instance of the fitted sensor draws its own
            # map, whose mean strays by sigma / sqrt(pixels): the black level's interval carries that spread too
            b = P["black_level_dn"]
            if b["ci95"] is not None:
                half = (b["ci95"][1] - b["ci95"][0]) / 2
                spread = off["sigma_e"]["value"] * k / math.sqrt(rows * cols)
                half = math.sqrt(half**2 + (Z95 * spread) ** 2)
                b["ci95"] = [b["value"] - half, b["value"] + half]
                b["method"] += "; interval includes an instance's mean pixel offset"
        dark_maps[T], dark_fits[T] = rates, res
        for name, p in res["parameters"].items():
            P[f"dark_current[{T:g} C].{name}"] = p
    if len(dark_fits) >= 2:
        Ts = sorted(dark_fits)
        means = [dark_fits[T]["parameters"]["mean_e_per_s"] for T in Ts]
        dbl = fit_dark.doubling(Ts, [m["value"] for m in means], [(m["ci95"][1] - m["ci95"][0]) / (2 * Z95) for m in means])
        P["dark_current.doubling_c"] = _p(dbl["value"], dbl["ci95"], f"log2 of the body mean over {len(Ts)} temperatures")
        hot = Ts[-1]
        td = fit_dark.tail_doubling(dark_maps, dark_fits[hot]["parameters"]["std_e_per_s"]["value"], seed,
                                    exclude=np.logical_or.reduce([clipped[T] for T in Ts]))
        if td is None:
            not_fitted["dark_current.tail_doubling_c"] = "fewer than 10 tail pixels at the hottest temperature"
        else:
            P["dark_current.tail_doubling_c"] = _p(td["value"], td["ci95"], f"median excess of the {td['pixels']} "
                                                   "strongest tail pixels over temperature (bootstrap interval)")
    else:
        not_fitted["dark_current.doubling_c, tail_doubling_c"] = "needs dark current at 2 or more temperatures"

    # ---------------------------------------------------------------- readout: the longest dark stack
    phase("readout noise")
    spectra = _spectra(ds, base)
    if not longs:
        n_max = max((d.n for d in ds.of_kind("dark")), default=0)
        not_fitted["source_follower, row_noise, column_noise (temporal, vfpn)"] = (
            f"needs a dark stack of at least {MIN_READOUT_FRAMES} frames (50 to 100 recommended); the longest has {n_max}")
    else:
        _readout(st, k, black, dark_maps.get(st.temperature_c), slope_var.get(st.temperature_c), P, plots, base, seed,
                 not_fitted, selection, exclude=rts_pixels, step=step, spectra=spectra)

    # ---------------------------------------------------------------- crosstalk from spots
    phase("crosstalk")
    spots = [(sp, _dark_at(ds, sp)) for sp in ds.of_kind("spot")]
    spots = [(sp, d) for sp, d in spots if d is not None]
    crosstalk_off = not spots and pattern == "none"
    if crosstalk_off:  # nothing in a monochrome flat or dark tells crosstalk from PRNU: not measured, not assumed
        not_fitted["crosstalk"] = ("not measured: monochrome data without a spot stack (single lit pixels, with a "
                                   "dark stack at its exposure time); left off, so the PRNU is the pixel-level "
                                   "figure the flats show")
    elif not spots:
        not_fitted["crosstalk"] = ("needs a spot stack (single lit pixels, with a dark stack at its exposure time); "
                                   "kept at the base configuration's kernel")
    else:
        sp, d = max(spots, key=lambda sd: sd[0].n)
        from ..model.stages import crosstalk as xt

        base_k = xt.kernel_fractions(base.crosstalk.kernel_pct)
        ksum = float(np.mean([np.sum(v) for v in base_k.values()])) if isinstance(base_k, dict) else float(np.sum(base_k))
        kt = fit_photo.crosstalk_from_spots(sp, d, pattern, ksum, sat_dn)
        for name, r in kt.items():
            key = "crosstalk.kernel_pct" + ("" if name == "all" else f".{name}")
            P[key] = _p(r["kernel_pct"], None, f"3 x 3 charge around {r['spots']} isolated lit pixels, shared "
                        f"out of the base's total {ksum * 100:.4g} % (a spot shows the sharing, not the loss)",
                        ci95_pct=r["ci95_pct"])
    # ---------------------------------------------------------------- PRNU and column gain
    phase("PRNU and column gain")
    cands = [(f, _dark_at(ds, f)) for f in ds.of_kind("flat")]
    cands = [(f, d) for f, d in cands if d is not None and 0.1 * sat_dn < f.mean.mean() < 0.8 * sat_dn]
    if not cands:
        not_fitted["prnu, column_noise.gain_sigma_pct"] = ("needs a flat stack between 10 % and 80 % of saturation "
                                                           "with a dark stack at its exposure time")
    else:
        target = black + 0.5 * (sat_dn - black)
        f, d = max(cands, key=lambda fd: (min(fd[0].n, fd[1].n), -abs(fd[0].mean.mean() - target)))
        pg = fit_photo.prnu_and_column_gain(f, d, pattern, sat_dn)
        seen = physics.prnu_seen_per_sigma(_with_crosstalk(base, P, crosstalk_off))
        m = pg["prnu_pct"]
        P["prnu.measured_pct"] = _p(m["value"], m["ci95"], f"pixel residual of a {f.n}-frame flat at "
                                    f"{pg['signal_dn']:.0f} DN less its dark, rows and columns removed, "
                                    f"{pg['excluded_pixels']} defect pixels out")
        P["prnu.sigma_pct"] = _p(m["value"] / seen, [c / seen for c in m["ci95"]],
                                 f"the gain map's sigma: measured / {seen:.4f} " + (
                                     "(no crosstalk: not measured)" if crosstalk_off else
                                     "(crosstalk averages neighbours: the "
                                     f"{'fitted' if any(k.startswith('crosstalk.') for k in P) else 'base'} kernel)"))
        g = pg["column_gain_pct"]
        P["column_noise.gain_sigma_pct"] = _p(g["value"], g["ci95"], "the flat's column means, less the pixel and "
                                              "temporal shares")
        plots["prnu"] = {"residual": pg["relative_residual"]}
    _instance_offsets_in_black(P, k, rows, cols)
    _include_gain_uncertainty(P, ptc["rel_se"])
    _with_basis(P)
    return {"parameters": P, "not_fitted": not_fitted, "dark": dark_fits, "plots": plots,
            "_crosstalk_off": crosstalk_off, "selection": selection,
            "_nonlinearity": nonlin if nonlin is not None and nonlin["bent"] else None,
            "_telegraph": telegraph, "spectra": spectra,
            "meta": {"bits": bits - (step.bit_length() - 1), "output_bits": bits, "step_dn": step,
                     "shape": [rows, cols], "cfa": pattern, "temperature_c": t_ref,
                     "temperature_basis": t_basis,
                     "temperatures": temps, "source": ds.source, "input": ds.kind},
            "_maps": dark_maps}


def _stack_period(st, base) -> float:
    """Seconds from one frame of the stack ``st`` to the next: the manifest's frame period, else the base's timing
    (its frame rate, or the exposure: frames back to back)."""
    from ..model.stages.random_telegraph import frame_period_s

    return st.frame_period_s or frame_period_s(base.sensor.frame_rate_hz, st.exposure_s)


def _stack_shares(st, base, spectra: dict) -> dict:
    """What the stack ``st`` sees of the row noise and the column amplifiers where their spectra are 1/f, at the
    default corners of the stack's frame rate (the manifest's frame period, else the base's timing), against
    white noise (:mod:`.noise_spectrum`): ``rows`` (its double-centred row means' variance), ``frame_ratio`` (the
    frame means' spread over the rows', white ``1 / (H - 1)``), ``row_mean`` (the rows' spread in the stack's
    mean image), ``columns`` (a column's variance over the frames), ``column_mean`` (a column's mean over the
    frames); 1 (white's) where the spectrum is white."""
    from ..model import one_over_f

    rows = st.shape[0]
    period = _stack_period(st, base)
    out = {"rows": 1.0, "frame_ratio": 1.0 / (rows - 1), "row_mean": 1.0, "columns": 1.0, "column_mean": 1.0}
    if spectra.get("rows_in_readout_order", {}).get("verdict") == "one_over_f":
        spectrum = one_over_f.lorentzians(*one_over_f.row_corners(1.0 / period, rows))
        out["rows"] = noise_spectrum.seen_share_rows(spectrum, st.n, rows, period / rows)
        out["frame_ratio"] = noise_spectrum.frame_mean_ratio_rows(spectrum, st.n, rows, period / rows)
        out["row_mean"] = noise_spectrum.stack_mean_share_rows(spectrum, st.n, rows, period / rows)
    if spectra.get("columns_over_frames", {}).get("verdict") == "one_over_f":
        spectrum = one_over_f.lorentzians(*one_over_f.column_corners(1.0 / period))
        out["columns"] = noise_spectrum.seen_share_frames(spectrum, st.n, period)
        out["column_mean"] = noise_spectrum.stack_mean_share_frames(spectrum, st.n, period)
    return out


def _column_dof(st, base, part: float, white: float) -> float:
    """The degrees of freedom of a column's variance over the stack's frames where the column amplifiers' noise is
    1/f at the default corners (:func:`.noise_spectrum.variance_dof_frames`)."""
    from ..model import one_over_f

    period = _stack_period(st, base)
    spectrum = one_over_f.lorentzians(*one_over_f.column_corners(1.0 / period))
    return noise_spectrum.variance_dof_frames(spectrum, st.n, period, part, white)


def _spectra(ds, base) -> dict:
    """The longest dark stack's noise in time (:mod:`.noise_spectrum`): each pixel over frames (its own noise, less
    its rows' and columns'), the rows in readout order and the columns over frames, each a summary or why it is
    not given (a stack too short, or one that cannot be read again)."""
    darks = ds.of_kind("dark")
    if not darks:
        return {}
    st = max(darks, key=lambda d: (d.n, -d.exposure_s))

    rate = 1.0 / _stack_period(st, base)
    out = {}

    def pixels():  # the middle rows that hold MAX_PIXELS pixels, read again, less their rows' and columns' means
        if st.n < noise_spectrum.MIN_FRAMES:
            return noise_spectrum.over_frames(np.zeros((st.n, 1, 1)))  # refused, saying what it needs
        rows = -(-noise_spectrum.MAX_PIXELS // st.shape[1])
        frames, _ = st.series(4 * st.shape[1] * st.n * rows)
        return noise_spectrum.over_frames(frames, col_means=st.col_means)

    for key, make in (("pixels_over_frames", pixels),
                      ("rows_in_readout_order", lambda: noise_spectrum.rows_in_readout_order(st.row_means)),
                      ("columns_over_frames", lambda: noise_spectrum.columns_over_frames(st.col_means))):
        try:
            out[key] = {**noise_spectrum.with_corners(make(), rate), "stack_frames": st.n}
        except CmosnoiseError as exc:
            out[key] = {"not_given": str(exc)}
    return out


#: a part of the read noise whose interval reaches this many times the total's upper end is not identifiable
SPLIT_LIMIT = 1.5


def _split_identifiable(P: dict, s2: np.ndarray, known: np.ndarray, frames: int, where: str) -> None:
    """The source follower's total temporal noise, which the per-pixel variances always give, and the split into
    thermal (white) and flicker (a spread of sigmas) marked "not identifiable" where an interval of a part reaches
    past what the total allows (:data:`SPLIT_LIMIT` times its upper end) or cannot be had: only the sum was
    measured."""
    excess = np.asarray(s2, np.float64) - np.asarray(known, np.float64)
    # each pixel's variance over `frames` frames: chi-square, sampling variance 2 s^4 / (frames - 1)
    se = math.sqrt(float(np.mean(2 * np.asarray(s2, np.float64) ** 2 / (frames - 1))) / excess.size)
    total = sigma_from_variance(float(excess.mean()), se)
    P["source_follower.read_noise_total_e"] = _p(total["value"], total["ci95"], "the mean of the pixels' temporal "
                                                 "variance less the dark charge's and the quantizer's (thermal and "
                                                 f"flicker together); {where}", basis="measured")
    top = total["ci95"][1]
    parts = ("source_follower.thermal_sigma_e", "source_follower.flicker.gumbel_loc_e",
             "source_follower.flicker.gumbel_scale_e")
    def beyond(k):  # an interval past what the total allows, or none at all (the likelihood's scores singular)
        p = P.get(k)
        return p is not None and p["value"] is not None and (p["ci95"] is None or p["ci95"][1] > SPLIT_LIMIT * top)

    if any(beyond(k) for k in parts):
        for k in parts:
            if k in P and P[k]["value"] is not None:
                P[k]["basis"] = "not identifiable"
                P[k]["identifiable"] = "source_follower.read_noise_total_e"
                P[k]["method"] += (f"; the split into thermal and flicker is not identifiable from these data (an "
                                   f"interval reaches past the total's {top:.3g} e-): only the total is measured")


def _written(P: dict, name: str, lo: float, hi: float, value: float | None = None) -> float:
    """The value the configuration gets for fitted parameter ``name``: clipped to the schema's ``[lo, hi]``, and
    where that changes it, the parameter says so (``written``, and its method): no silent clipping."""
    v = float(P[name]["value"] if value is None else value)
    out = min(max(v, lo), hi)
    if out != v and P[name].get("written") != out:
        P[name]["written"] = out
        ci = P[name].get("ci95")
        seen = f" (95 % CI {ci[0]:.4g} to {ci[1]:.4g})" if ci else ""
        P[name]["method"] += (f"; outside what the configuration holds ({lo:g} to {hi:g}){seen}: config.yaml has "
                              f"{float(out)}")
    return out


def _instance_offsets_in_black(P: dict, k: float, rows: int, cols: int) -> None:
    """The black level's interval widened by what an instance's mean column and row offsets put in it: the
    intercept holds this sensor's mean VFPN and fixed row offset, another instance of the fitted sensor draws its
    own (sigma / sqrt(columns), sigma / sqrt(rows)), as the pixel offsets' share already is."""
    b = P.get("black_level_dn")
    parts = [(P.get("column_noise.vfpn_sigma_e"), cols), (P.get("row_noise.fixed_sigma_e"), rows)]
    spread2 = sum((p["value"] * k) ** 2 / n for p, n in parts if p is not None and p.get("value"))
    if b is None or b.get("ci95") is None or spread2 <= 0:
        return
    half = math.sqrt(((b["ci95"][1] - b["ci95"][0]) / 2) ** 2 + Z95**2 * spread2)
    b["ci95"] = [b["value"] - half, b["value"] + half]
    b["method"] += "; and an instance's mean column (VFPN) and row offsets"


def _crosstalk_update(P: dict) -> dict | None:
    """The configuration's crosstalk section from the fitted kernels (one per colour when all three are there)."""
    colours = [f"crosstalk.kernel_pct.{c}" for c in "RGB"]

    def kernel(value):
        """A share is >= 0: on a sensor without crosstalk the noise puts some just below 0; clipped, and scaled back
        to the fitted total (what the base's kernel keeps)."""
        total = float(np.sum(value))
        clipped = np.maximum(np.asarray(value, np.float64), 0.0)
        clipped *= total / float(clipped.sum())
        return [[float(x) for x in row] for row in clipped]

    if all(c in P for c in colours):
        return {"enabled": True, "kernel_pct": {c[-1]: kernel(P[c]["value"]) for c in colours}}
    if "crosstalk.kernel_pct" in P:
        return {"enabled": True, "kernel_pct": kernel(P["crosstalk.kernel_pct"]["value"])}
    return None


def _with_crosstalk(base, P: dict, off: bool = False):
    from ..config.loading import merge_updates

    xt = {"enabled": False} if off else _crosstalk_update(P)
    return base if xt is None else merge_updates(base, {"crosstalk": xt})


def _telegraph(st, k: float, P: dict, not_fitted: dict, seed: int, out: dict, plots: dict,
               cds_interval_s: float = 1e-5) -> np.ndarray | None:
    """Random telegraph pixels of the long dark stack ``st`` (:mod:`.fit_telegraph`): its parameters into ``P``,
    the ``source_follower.rts`` section into ``out["section"]`` (None where none was found: off; the held or the
    three-level pixels, whichever are more; a three-level pixel's CDS interval ``cds_interval_s``), the series of
    the three pixels of largest amplitude into ``plots["telegraph"]`` (with their levels). Returns the
    pixels found (flat indices of the whole frame), or None where the stack is too short or cannot be read again."""
    if st.n < MIN_TELEGRAPH_FRAMES or st.reread is None:
        not_fitted["source_follower.rts"] = (f"needs a dark stack of at least {MIN_TELEGRAPH_FRAMES} frames read a "
                                             f"second time (the longest has {st.n}): kept at the base configuration's")
        return None
    frames, (r0, r1) = st.series(TELEGRAPH_BYTES)
    rows, cols = st.shape
    r = fit_telegraph.fit(frames, k, st.period_s, seed)
    cds = fit_telegraph.through_cds(r)  # the population the configuration gets, and the report shows
    shown = r["three_level"] if cds else r
    if shown["pixels"]:
        show = np.argsort(shown["amplitude_e"])[::-1][:3]
        flat = frames.reshape(st.n, -1)
        plots["telegraph"] = {"period_s": st.period_s, "series": [flat[:, shown["pixels"][i]].copy() for i in show],
                              "levels": [shown["levels_dn"][i] for i in show],
                              "pixels": [divmod(shown["pixels"][i] + r0 * cols, cols) for i in show]}
    del frames
    given = "the manifest's" if st.frame_period_s is not None else "frames back to back: the exposure time"
    where = (f"{st.n} dark frames at {st.exposure_s:g} s, {st.period_s:g} s apart ({given}), "
             + ("every row" if (r0, r1) == (0, rows) else f"rows {r0} to {r1 - 1} (memory)") + ": "
             f"{r['candidates']} pixels with a held, excess variance; those a two-state hidden Markov model gives two "
             f"levels {fit_telegraph.SEPARATION:g} sigma apart")
    P["source_follower.rts.ppm"] = _p(r["ppm"], r["ppm_ci95"], where + " (Clopper-Pearson interval)",
                                      pixels=len(r["pixels"]))
    if r["pixels"]:
        for name, what in (("amplitude_e", "distance of the two levels, e-"),
                           ("tau_low_s", "mean dwell time in the lower level (capture), s"),
                           ("tau_high_s", "mean dwell time in the higher level (emission), s")):
            P[f"source_follower.rts.median_{name}"] = _p(r[f"median_{name}"], r[f"median_{name}_ci95"],
                                                         f"median over the pixels found of the {what}; bootstrap interval")
    three = r["three_level"]
    P["source_follower.rts.cds_ppm"] = _p(three["ppm"], three["ppm_ci95"], (
        f"{st.n} dark frames: of {three['candidates']} pixels with an excess variance white in time, those a "
        f"symmetric three-level mixture (a trap through CDS: -A, 0, +A) fits {fit_telegraph.SEPARATION:g} sigma apart "
        "and better than one normal at 5 sigma (Clopper-Pearson interval)"), pixels=len(three["pixels"]))
    if three["pixels"]:
        P["source_follower.rts.cds_median_amplitude_e"] = _p(three["median_amplitude_e"], three["median_amplitude_e_ci95"],
                                                             "median over the three-level pixels of A, e-; bootstrap interval")
        P["source_follower.rts.cds_median_switching"] = _p(
            three["median_switching"], three["median_switching_ci95"],
            "median over the three-level pixels of the fraction of frames at -A or +A, 2 pi0 pi1 (1 - exp(-s tau)); "
            "bootstrap interval")
    if r["pixels"] and three["pixels"]:
        kept, left = ("three-level (CDS)", "held") if cds else ("held", "three-level (CDS)")
        not_fitted["source_follower.rts"] = (
            f"both held ({len(r['pixels'])}) and three-level ({len(three['pixels'])}) pixels were found; one "
            f"source_follower.rts section holds one readout: the {kept} ones are in the configuration, the {left} "
            "ones are not")
    out["section"] = fit_telegraph.section(r, cds=cds, cds_interval_s=cds_interval_s)
    found = np.asarray(r["pixels"] + three["pixels"], np.int64)
    return found + r0 * cols  # the series' rows start at r0


def _readout(st, k: float, black: float, rate_map, rate_var, P: dict, plots: dict, base, seed: int,
             not_fitted: dict, selection: dict, exclude: np.ndarray | None = None, step: int = 1,
             spectra: dict | None = None) -> None:
    """Source follower, row and column noise, VFPN and fixed row offsets from one long dark stack ``st``; the
    read noise's shape (Tukey-lambda) where the pixels' noise is not normal, and the black level's error per
    frame. What cannot be fitted goes to ``not_fitted``; each stage test's p-value to ``selection``. ``step``:
    the output DN per ADC code (the quantizer's variance is ``step^2 / 12`` DN^2)."""
    from scipy import stats

    rows, cols = st.shape
    n = st.n
    corr = 1 - 2 / cols - 2 / rows
    s2 = st.pixel_var / k**2 / corr
    vbar = float(s2.mean())
    if rate_map is not None:
        dark_var = np.maximum(rate_map, 0) * st.exposure_s
        known_var = rate_var * st.exposure_s**2
        how = "dark shot noise from the fitted rate map (and its uncertainty)"
    else:
        dark_var = np.maximum((st.mean - black) / k, 0)
        known_var = None
        how = "dark shot noise from the stack's mean above black (no rate map at this temperature)"
    known = dark_var + step**2 / (12 * k * k) + vbar * (1 / cols + 1 / rows) / corr
    tail = base.source_follower.flicker.tail
    thr = tail.threshold_e if tail is not None else 4 * base.source_follower.flicker.gumbel_loc_e
    q = step**2 / (12 * k * k)  # the quantizer's variance, e-^2; its fourth cumulant -1.2 q^2, the dark charge's its mean
    kappa4 = dark_var - 1.2 * q * q
    if exclude is not None and exclude.size:
        keep = np.ones(rows * cols, bool)
        keep[exclude] = False

        def kept(a):
            return a if np.ndim(a) == 0 else np.broadcast_to(a, (rows, cols)).ravel()[keep]

        s2_fit, known_fit, kappa4, known_var = kept(s2), kept(known), kept(kappa4), (
            None if known_var is None else kept(known_var))
    else:
        s2_fit, known_fit = s2, known
    r = fit_readout.fit_source_follower(s2_fit, known_fit, n, thr, seed=seed, kappa4=kappa4, known_var=known_var)
    f = r["fit"]
    where = (f"{n} frames at {st.exposure_s:g} s: per-pixel variances (chi-square, {n - 1} dof), marginal maximum "
             f"likelihood over all {r['pixels']} pixels (in {f.n_used} classes of equal variance), interval from the scores; {how}")
    for name, key in [("thermal_sigma_e", "source_follower.thermal_sigma_e"),
                      ("gumbel_loc_e", "source_follower.flicker.gumbel_loc_e"),
                      ("gumbel_scale_e", "source_follower.flicker.gumbel_scale_e"),
                      ("tail_ppm_above", "source_follower.flicker.tail.ppm_above"),
                      ("tail_max_e", "source_follower.flicker.tail.max_e")]:
        v, ci = f.interval(name)
        if v is None:
            P[key] = _p(None, None, "no flicker tail seen (not one tail pixel): not fitted, none in the configuration")
        else:
            P[key] = _p(float(v), ci, where)
    _split_identifiable(P, s2_fit, known_fit, n, where)
    seen = _pixel_flicker_seen(st, base, spectra or {})
    if seen < 1.0:  # a 1/f flicker's sigmas as the frames see them: the Gumbel scales with them, exactly
        for key in ("source_follower.flicker.gumbel_loc_e", "source_follower.flicker.gumbel_scale_e"):
            got = P[key]
            if got["value"] is not None:  # judged as seen (_split_identifiable), then scaled
                got["value"] = float(got["value"] / math.sqrt(seen))
                if got["ci95"] is not None:
                    got["ci95"] = [float(c / math.sqrt(seen)) for c in got["ci95"]]
                got["method"] += (f"; over sqrt({seen:.4f}), the share of a 1/f flicker's variance that {n} frames "
                                  "see at the fitted corners (no CDS: the stack's mean takes the rest)")
    P["source_follower.flicker.tail.ppm_above"]["threshold_e"] = thr
    if r.get("no_tail"):
        P["source_follower.flicker.tail.ppm_above"]["method"] = ("the body's own share above the threshold; no tail "
                                                                  "pixels seen, the interval's top is 3 pixels' worth")
    plots["source_follower"] = {"s2": s2.ravel(), "known": known.ravel(), "frames": n,
                                "params": [float(x) for x in f.value], "tail_fraction": r["tail_fraction"],
                                "tail_max": r["tail_max"]}
    # the shape of the pixels' temporal noise: normal, or (ELD's read noise) Tukey-lambda; judged where the pixels
    # share one noise (their variances spread by less than 10 % of the mean, as on ELD's cameras)
    if st.pixel_m4 is not None:
        # what is not the read noise: the dark charge's shot noise and the quantizer's, their variances (DN^2) and
        # fourth cumulants (the Poisson's is its mean; a uniform code's -step^4/120 DN^4)
        known_var, known_k4 = dark_var * k**2 + step**2 / 12, dark_var * k**4 - step**4 / 120
        shp = fit_readout.pixel_noise_shape(st.pixel_var, st.pixel_m4, n, known_var, known_k4,
                                            fit_readout.own_share(rows, cols))
        if shp is not None:
            (kurt, kci), (lam, lci) = shp["kurtosis"], shp["lam"]
            se_kurt = (kci[1] - kci[0]) / (2 * Z95)
            not_normal = _select(selection, "read_noise.shape",
                                 float(2 * stats.norm.sf(abs(kurt) / se_kurt)) if se_kurt > 0 else 1.0,
                                 "the pixels' excess kurtosis against 0 (two-sided z)")
            if not_normal and shp["spread"] < 0.1:
                P["read_noise.shape"] = _p(lam, lci, f"the Tukey-lambda shape whose excess kurtosis is the pixels' noise's, "
                                           f"{kurt:.3g} (95 % CI {kci[0]:.3g} to {kci[1]:.3g}), from their fourth moments "
                                           f"over {n} frames less the dark charge's and the quantizer's")
                P["read_noise.scale_dn"] = _p(*shp["scale_dn"], "the scale that gives the pixels' mean variance (less "
                                              "the dark charge's and the quantizer's); interval from the shape's and "
                                              "that variance's")
            elif not_normal:
                not_fitted["read_noise"] = (
                    f"the pixels' noise is not normal (excess kurtosis {kurt:.3g}, 95 % CI {kci[0]:.3g} to {kci[1]:.3g}) "
                    f"but their sigmas spread by {shp['spread']:.0%}: the flicker model holds it; no Tukey-lambda read "
                    "noise")
    e2, e2_se = fit_readout.frame_error_variance(st.row_means, st.col_means,
                                                 float(np.mean(st.pixel_var)) / fit_readout.own_share(rows, cols),
                                                 row_ratio=_stack_shares(st, base, spectra or {})["frame_ratio"])
    _select(selection, "black_level.frame_sigma_dn", float(stats.norm.sf(e2 / e2_se)) if e2_se > 0 else 1.0,
            "the frames' means' spread beyond the rows', columns' and pixels' share, against 0 (one-sided z)")
    P["black_level.frame_sigma_dn"] = _p(**sigma_from_variance(e2, e2_se),
                                         method=f"the spread of the {n} frames' means less what the rows', columns' "
                                                "and pixels' temporal noise put there")
    # rows: temporal then fixed
    rs = centred_series(st.row_means) / k
    cs = centred_series(st.col_means) / k
    dof = (n - 1) * (rows - 1)  # each row's temporal mean and each frame's mean removed
    v_row = float(np.sum(rs * rs)) / dof
    se = v_row * math.sqrt(2 / dof)
    shares = _stack_shares(st, base, spectra or {})
    share_r, share_c = shares["rows"], shares["columns"]
    P["row_noise.sigma_e"] = _p(**sigma_from_variance((v_row - vbar / cols) / share_r, se / share_r),
                                method=f"variance of the rows' means over {n} frames, less the pixels' share" + (
                                    f"; over {share_r:.3f}, what the stack sees of a 1/f row noise (its spectrum "
                                    "in readout order; the default corners)" if share_r != 1 else ""))
    s2_cols = cs.var(axis=0, ddof=1)
    dof_frames = n
    if share_c != 1:  # the columns' own part of the variance, as a 1/f process over frames shows it to the stack,
        # and the wider spread of a slow process's variance estimate: the likelihood's effective frames
        s2_cols = vbar / rows + (s2_cols - vbar / rows) / share_c
        part = max(float(np.median(s2_cols)) - vbar / rows, 0.0)
        dof_frames = 1 + _column_dof(st, base, part, vbar / rows) * share_c**2 * (
            (part + vbar / rows) / (part * share_c + vbar / rows)) ** 2
    cfit = fit_readout.fit_column_sigma(s2_cols, vbar / rows, dof_frames)
    for name in cfit.names:
        v, ci = cfit.interval(name)
        P[f"column_noise.temporal.{name}"] = _p(float(v), ci, f"each column's mean over {n} frames: chi-square "
                                                f"likelihood of {cols} column variances, interval from the scores")
    plots["columns"] = {"s2": s2_cols, "known": vbar / rows, "frames": n, "params": [float(x) for x in cfit.value]}
    # fixed: a two-way analysis of the stack's mean image (e-), white pixels masked
    img = (st.mean - black) / k
    keep = fit_readout.robust_mask(img)
    for axis, name, series, count in [("col", "column_noise.vfpn_sigma_e", s2_cols, rows),
                                      ("row", "row_noise.fixed_sigma_e", rs.var(axis=0, ddof=1), cols)]:
        cov, se = fit_readout.split_half_covariance(img, keep, axis)
        # the temporal column (row) noise averaged over the frames is common to both halves too (1/f noise
        # averages less: its slow part stays in the stack's mean)
        temporal = (float(np.mean(series)) - vbar / count) / n
        est = cov - (temporal * shares["column_mean"] if axis == "col" else
                     temporal / share_r * shares["row_mean"])
        what = "column" if axis == "col" else "row"
        P[name] = _p(**sigma_from_variance(est, se), method=f"covariance of each {what}'s mean over two halves of the "
                     f"{n}-frame mean image, less the temporal {what} noise ({int((~keep).sum())} outliers out)")


def _fitted_nonlinearity(result: dict, full: float) -> tuple[float, dict | None]:
    """The full well (on the charge before the transfer where the nonlinearity acts on it) and the
    nonlinearity section of the fitted transfer, None where it is not increasing over the full well (noted)."""
    nonlin = result.get("_nonlinearity")
    nl_update = None
    if nonlin is not None:
        # the full well clips the collected charge: on each frame's charge that is before the transfer, so the
        # measured top (output e-) is the transfer of the full well; on the mean charge, the output itself
        if nonlin["acts_on"] == "charge":
            grid = np.linspace(0.0, 2.0 * full, 4001)
            full = float(np.interp(full, nonlin["transfer"](grid), grid))
        c = np.linspace(0.0, full, 1001)
        if np.all(nonlin["slope"](c) > 0):
            # the quartic in the photons as the configuration's cubic in s = c / full well: f(c) = c (1 + a s + b s^2 + ...)
            p1, p2, p3, p4 = nonlin["coefficients"]
            coefficients = [p2 * full / p1**2, p3 * full**2 / p1**3, p4 * full**3 / p1**4]
            nl_update = {"enabled": True, "acts_on": nonlin["acts_on"], "linearity_error_pct": None,
                         "curve_e": None, "coefficients": coefficients}
        else:
            result["not_fitted"]["nonlinearity"] = "the fitted transfer is not increasing over the full well: left off"
    return full, nl_update


def _dark_points(result: dict) -> list[dict]:
    """The dark current's characterization points the fit found, each with a tail where its ppm exceeds the
    body's own; a temperature without dark current to speak of is noted in ``result['not_fitted']``."""
    points = []
    for T, res in sorted(result["dark"].items()):
        p = res["parameters"]
        if not p["mean_e_per_s"]["value"] > 0:  # no dark current to speak of (noise put the mean at or below 0)
            result["not_fitted"][f"dark_current at {T:g} C"] = (
                f"the body's mean is {p['mean_e_per_s']['value']:.3g} e-/s (95 % CI {p['mean_e_per_s']['ci95'][0]:.3g} "
                f"to {p['mean_e_per_s']['ci95'][1]:.3g}): no dark current seen, none in the configuration")
            continue
        point = {"temperature_c": T, "distribution": p["family"]["value"], "mean_e_per_s": p["mean_e_per_s"]["value"],
                 "std_e_per_s": p["std_e_per_s"]["value"], "tail": None}
        from ..model.distributions import body

        try:  # the body's own share above the threshold: a tail adds to it; a ppm below it needs no tail
            own = float(body(point["distribution"], point["mean_e_per_s"], point["std_e_per_s"]).sf(res["threshold"])) * 1e6
        except ValueError:
            own = 0.0
        if p["tail.ppm_above"]["value"] > own * 1.001 and p["tail.ppm_above"]["value"] > 0:
            point["tail"] = {"ppm_above": p["tail.ppm_above"]["value"], "threshold_e_per_s": res["threshold"],
                             "max_e_per_s": p["tail.max_e_per_s"]["value"]}
        points.append(point)
    return points


def _readout_updates(P: dict, result: dict) -> dict:
    """The source follower's, the row noise's and the column noise's fitted sections (a flicker tail only where
    the fitted body can carry it; else noted in ``result['not_fitted']``)."""
    def v(name, default=None):
        return P[name]["value"] if name in P else default

    out: dict = {}
    loc, scale = v("source_follower.flicker.gumbel_loc_e"), v("source_follower.flicker.gumbel_scale_e")
    ppm, mx = v("source_follower.flicker.tail.ppm_above"), v("source_follower.flicker.tail.max_e")
    thr = P["source_follower.flicker.tail.ppm_above"]["threshold_e"]
    tail = None
    base_ppm = fit_readout.ppm_above(thr, loc, scale, 0.0, 0.0)
    if mx is not None and ppm > base_ppm * 1.001 and mx > 0:
        tail = {"ppm_above": ppm, "threshold_e": thr, "max_e": mx}
        from ..model.heavy_tail import UnreachablePpm
        from ..model.stages.source_follower import flicker_model

        try:  # a tail the body and its maximum can give (a fraction of a pixel's ppm often cannot)
            flicker_model(loc, scale, ppm, thr, mx)
        except UnreachablePpm as exc:
            tail = None
            result["not_fitted"]["source_follower.flicker.tail"] = (
                f"the fitted tail ({ppm:.3g} ppm above {thr:g} e-, up to {mx:.3g} e-) cannot be put on the fitted "
                f"body ({exc}); left out: too few tail pixels to model")
    out["source_follower"] = {"enabled": True, "thermal_sigma_e": v("source_follower.thermal_sigma_e"),
                            "flicker": {"enabled": True, "gumbel_loc_e": loc, "gumbel_scale_e": scale, "tail": tail}}
    out["row_noise"] = {"enabled": True, "sigma_e": v("row_noise.sigma_e"), "fixed_sigma_e": v("row_noise.fixed_sigma_e")}
    out["column_noise"] = {"enabled": True, "vfpn_sigma_e": v("column_noise.vfpn_sigma_e"),
                         "temporal": {"gumbel_loc_e": v("column_noise.temporal.gumbel_loc_e"),
                                      "gumbel_scale_e": v("column_noise.temporal.gumbel_scale_e")}}
    # the noise in time: 1/f where the dark stack's spectrum says so (its corners left at their defaults: a stack
    # resolves the slope over its band, not where the 1/f range ends), else white
    spectra = result.get("spectra", {})
    from ..model import one_over_f

    for key, section, default in (("pixels_over_frames", out["source_follower"]["flicker"], one_over_f.pixel_corners),
                                  ("rows_in_readout_order", out["row_noise"], None),
                                  ("columns_over_frames", out["column_noise"]["temporal"], one_over_f.column_corners)):
        found = spectra.get(key, {})
        section["spectrum"] = "one_over_f" if found.get("verdict") == "one_over_f" else "white"
        chosen = _fitted_corners(found, default) if default is not None else None
        if chosen is not None:
            section["corner_hz"] = list(chosen)
    return out


def _fitted_corners(found: dict, default) -> tuple[float, float] | None:
    """The 1/f range a spectrum over frames (``fit.json``'s summary) gives, Hz: a corner the stack resolves is the
    fitted one; one beyond it (below the lowest bin, above Nyquist) keeps its default (``default(rate)``), which
    the data allow. None where the spectrum resolved neither corner."""
    corners, rate = found.get("corners"), found.get("frame_rate_hz")
    if not corners or "low_hz" not in corners or not rate or not (corners["low_hz"]["resolved"]
                                                                   or corners["high_hz"]["resolved"]):
        return None
    lo, hi = default(rate)
    lo = corners["low_hz"]["value"] if corners["low_hz"]["resolved"] else min(lo, corners["low_hz"]["interval"][1])
    hi = corners["high_hz"]["value"] if corners["high_hz"]["resolved"] else max(hi, corners["high_hz"]["interval"][0])
    return (float(lo), float(hi)) if lo < hi else None


def _pixel_flicker_seen(st, base, spectra: dict) -> float:
    """What a pixel's variance over the stack ``st``'s frames sees of its 1/f flicker (no CDS: the level drifts
    from frame to frame, and the pixel's mean over the stack takes a part of it), against white noise's; 1 where
    the pixels' spectrum over frames is not 1/f. At the corners the configuration is given
    (:func:`_fitted_corners`, else the defaults of the stack's rate)."""
    from ..model import one_over_f

    found = spectra.get("pixels_over_frames", {})
    if found.get("verdict") != "one_over_f":
        return 1.0
    period = _stack_period(st, base)
    corners = _fitted_corners(found, one_over_f.pixel_corners) or one_over_f.pixel_corners(1.0 / period)
    return noise_spectrum.seen_share_frames(one_over_f.lorentzians(*corners), st.n, period)


def fitted_config(base, result: dict):
    """``base`` (a Config) with every fitted value: what ``cmosnoise simulate --config`` runs."""
    from ..config.loading import merge_updates

    P, meta = result["parameters"], result["meta"]

    def v(name, default=None):
        return P[name]["value"] if name in P else default

    k, black, bits = v("system_gain_K_dn_per_e"), v("black_level_dn"), meta["bits"]
    out_bits = meta.get("output_bits", bits)
    top = 2 ** (out_bits - bits) * (2**bits - 1)  # the top output code
    black = _written(P, "black_level_dn", 0.0, top - 1, round(black, 3))
    full = v("full_well_e", base.sensor.full_well_e)
    full, nl_update = _fitted_nonlinearity(result, full)
    u: dict = {
        "sensor": {"width": meta["shape"][1], "height": meta["shape"][0], "cfa": meta["cfa"],
                   "full_well_e": round(float(full), 1), "temperature_c": meta["temperature_c"]},
        "adc": {"enabled": True, "bits": bits, "output_bits": out_bits if out_bits != bits else None,
                "black_level_dn": black, "full_scale_e": (top - black) / k, "gain_dn_per_e": None},
    }
    if base.gain_table:  # the data measure one setting: the base's table (whose rows would set K and the read
        # noise again) gives way to the fitted values; fitted_gain_config writes a table from several settings
        u["gain_table"] = []
        u["sensor"].update({"iso": None, "gain_db": None})
    points = _dark_points(result)
    if result["dark"] and not points:
        u["dark_current"] = {"enabled": False}
    if points:
        u["dark_current"] = {"enabled": True, "points": points}
        for name in ("doubling_c", "tail_doubling_c"):
            val = v(f"dark_current.{name}")
            if val is not None and math.isfinite(val) and 0 < val <= 100:
                u["dark_current"][name] = val
    if "source_follower.thermal_sigma_e" in P:
        u.update(_readout_updates(P, result))
    if "section" in result.get("_telegraph", {}):  # random telegraph pixels: those found, or none (off)
        sec = result["_telegraph"]["section"]
        u.setdefault("source_follower", {})["rts"] = sec if sec is not None else {"enabled": False}
    if nl_update is not None:
        u["nonlinearity"] = nl_update
    if "read_noise.shape" in P and "source_follower" in u:
        # the pixels' noise is the read noise after the gain, Tukey-lambda: it takes the source follower's place
        u["read_noise"] = {"enabled": True, "distribution": "tukey_lambda", "shape": v("read_noise.shape"),
                           "scale_dn": v("read_noise.scale_dn")}
        if (result.get("_telegraph") or {}).get("section") is not None:
            result["not_fitted"]["source_follower.rts"] = (
                "random telegraph pixels were found, but the read noise after the gain takes the source follower's "
                "place (its traps with it): left out")
        u["source_follower"] = {"enabled": False}
    black_level: dict = {}
    if "black_level.channel_offsets_dn" in P:
        black_level["channel_offsets_dn"] = v("black_level.channel_offsets_dn")
    sel = result.get("selection", {})
    if "black_level.frame_sigma_dn" in P and sel.get("black_level.frame_sigma_dn", {}).get("on"):
        black_level["frame_sigma_dn"] = v("black_level.frame_sigma_dn")
    if black_level:
        u["black_level"] = black_level
    if "quantum_efficiency" in P and v("quantum_efficiency") > 0:
        # photons per pixel over the fitted configuration's e-: what a crosstalk loss and the PRNU map leave aside;
        # one above 1 is written as 1 (the parameter says so)
        u["sensor"]["quantum_efficiency"] = _written(P, "quantum_efficiency", 0.0, 1.0)
    if "pixel_offset.sigma_e" in P:
        sig = v("pixel_offset.sigma_e")
        off_tail = None
        if "pixel_offset.tail.ppm_above" in P:
            off_tail = {"ppm_above": v("pixel_offset.tail.ppm_above"),
                        "threshold_e": P["pixel_offset.tail.ppm_above"]["threshold_e"],
                        "max_e": max(v("pixel_offset.tail.max_e"), P["pixel_offset.tail.ppm_above"]["threshold_e"])}
        # on only where the data show offsets (the body's test or a tail, SELECTION_TESTS): else the section is off
        u["pixel_offset"] = {"enabled": bool(sel.get("pixel_offset", {}).get("on") or off_tail is not None),
                             "sigma_e": sig, "tail": off_tail}
    xt = {"enabled": False} if result.get("_crosstalk_off") else _crosstalk_update(P)
    if xt is not None:
        u["crosstalk"] = xt
    if "prnu.sigma_pct" in P:
        u["prnu"] = {"enabled": True, "sigma_pct": _written(P, "prnu.sigma_pct", 0.0, 100.0), "measured_pct": None}
        u.setdefault("column_noise", {})["gain_sigma_pct"] = _written(P, "column_noise.gain_sigma_pct", 0.0, 50.0)
    try:
        return resolve(merge_updates(base, u)).config
    except CmosnoiseError as exc:
        raise CmosnoiseError(f"the fitted configuration is not valid: {exc}") from None


#: what a gain setting's row of the fitted gain table carries (docs/model.md stage 9b): the keys that follow the
#: setting in a camera (its noise in e- and in DN, its well, its black level and the offsets after the amplifier);
#: what the pixel does (dark current, crosstalk, PRNU, pixel offsets) is the lowest setting's for all
GAIN_KEYS = ("sensor.full_well_e", "adc.black_level_dn", "source_follower.enabled", "source_follower.thermal_sigma_e",
             "source_follower.flicker.gumbel_loc_e", "source_follower.flicker.gumbel_scale_e", "row_noise.sigma_e",
             "row_noise.fixed_sigma_e", "column_noise.vfpn_sigma_e", "read_noise.enabled", "read_noise.distribution",
             "read_noise.scale_dn", "read_noise.shape", "black_level.frame_sigma_dn", "black_level.channel_offsets_dn")


def read_floor_e(cfg) -> float:
    """The temporal dark noise a fitted configuration implies without dark shot noise and quantization, e-."""
    from ..analysis import noise_budget
    from ..model.sensor import Sensor

    small = cfg.model_copy(update={"sensor": cfg.sensor.model_copy(update={"width": 64, "height": 48})})
    parts = noise_budget.temporal_variances(Sensor(small, seed=0), 0.0)
    return math.sqrt(sum(v for k, v in parts.items() if k not in ("dark_shot", "photon_shot", "quantization")))


def fitted_gain_config(base, index: str, results: dict):
    """``base`` with a gain table fitted from data sets at several settings (``results``: setting -> its
    :func:`fit_dataset`): the configuration of the setting with the lowest read-noise floor in e- (it measures
    the pixel best), plus a ``gain_table`` row per setting with its K and :data:`GAIN_KEYS`, the lowest setting
    picked by ``sensor.iso`` or ``sensor.gain_db``.

    A conversion-gain step is named where the read-noise floor in e- falls most between two settings, by 30 %
    or more: the settings below it are ``LCG``, from it up ``HCG``.
    """
    from ..config.loading import merge_updates

    values = sorted(results)
    configs = {v: fitted_config(base, results[v]) for v in values}
    floors = [read_floor_e(configs[v]) for v in values]
    drops = [(floors[i] - floors[i + 1]) / floors[i] if floors[i] > 0 else 0.0 for i in range(len(values) - 1)]
    step = max(range(len(drops)), key=lambda i: drops[i]) + 1 if drops and max(drops) >= 0.3 else None
    rows = []
    for i, v in enumerate(values):
        c = configs[v].model_dump(mode="json")
        row = {index: v, "k_dn_per_e": results[v]["parameters"]["system_gain_K_dn_per_e"]["value"], "set": {}}
        if step is not None:
            row["mode"] = "LCG" if i < step else "HCG"
        for dotted in GAIN_KEYS:
            node = c
            for part in dotted.split("."):
                node = node[part]
            row["set"][dotted] = node
        rows.append(row)
    # the pixel's own physics (dark current, crosstalk, PRNU, offsets) from the setting that measures it best: the
    # one with the lowest read-noise floor in e-; the setting picked at first is the lowest
    quietest = values[int(np.argmin(floors))]
    updates = {"gain_table": rows, "sensor": {index: values[0]}}
    try:
        return resolve(merge_updates(configs[quietest], updates)).config
    except CmosnoiseError as exc:
        raise CmosnoiseError(f"the fitted gain table is not valid: {exc}") from None
