"""``fit_report.html``: one self-contained page (plots embedded) showing each fit against the user's own data.

For each stage the measured histogram with the fitted model over it: the
photon-transfer curve; the dark-current map at each temperature with the
chosen family and the tail threshold (the paper's Figs. 5 and 6) and the
table of every family's log-likelihood and AIC; the per-pixel temporal noise
(Fig. 7) with what the fitted source follower predicts for the same
estimator; the per-column noise; the random telegraph pixels' series with
their two levels; the PRNU residual. Then the white pixels
and couplets against random placement, the round trip, and what was not
fitted.
"""

from __future__ import annotations

import datetime
import html
import math

import numpy as np

from .._version import __version__
from . import plots
from .report import CSS, _figure, _table


def ptc_plot(d: dict) -> bytes:
    fig, ax = plots.figure(figsize=(5.2, 3.6))
    mu, v, lin = np.array(d["mu"]), np.array(d["v"]), d["linear"]
    ax.plot(mu, v, "o", ms=3, label="measured levels")
    ax.plot(mu[lin], v[lin], "o", ms=4, mfc="none", color="C1", label="used for K")
    x = np.linspace(0, mu.max(), 50)
    ax.plot(x, d["K"] * x, "-", color="C2", lw=1, label=f"K = {d['K']:.4f} DN/e-")
    ax.axvline(mu[d["saturation_index"]], color="0.5", ls=":", label="saturation (largest variance)")
    ax.set_xlabel("mean signal above dark, DN")
    ax.set_ylabel("temporal variance less dark, DN²")
    ax.set_title("Photon transfer")
    ax.legend(fontsize=8)
    return plots.to_png_bytes(fig)


def dark_map_plot(rates: np.ndarray, res: dict, T: float) -> bytes:
    from ..model.distributions import body

    p = res["parameters"]
    fam, mean, std = p["family"]["value"], res["families"][0]["mean"], res["families"][0]["std"]
    thr = res["threshold"]
    x = rates.ravel()
    fig, ax = plots.figure(figsize=(5.2, 3.6))
    hi = float(np.quantile(x, 0.9999)) if x.size > 1000 else float(x.max())
    lo = float(min(x.min(), 0))
    bins = np.linspace(lo, max(hi, thr * 1.2), 160)
    ax.hist(x, bins=bins, histtype="stepfilled", alpha=0.5, label=f"measured map ({x.size} pixels)")
    c = 0.5 * (bins[1:] + bins[:-1])
    n_body = int((x < thr).sum())
    try:
        d = body(fam, mean, std)
        ax.plot(c, n_body * d.pdf(c) * np.diff(bins)[0] / max(float(d.cdf(thr)), 1e-12), "-", color="C3", lw=1.2,
                label=f"fitted {fam} body")
    except ValueError:
        pass
    ax.axvline(thr, color="k", ls="--", lw=0.8, label=f"tail threshold {thr:.4g} e-/s")
    plots.log_histogram_axes(ax, "dark current, e-/s", f"Dark-current map at {T:g} C (paper Figs. 5, 6)")
    ax.set_ylim(bottom=0.5)
    return plots.to_png_bytes(fig)


def sigma_plot(d: dict, names: list[str], title: str, xlabel: str, with_thermal: bool, seed: int = 0) -> bytes:
    """Measured per-unit sigma estimates and the same estimator under the fitted model (one simulated draw)."""
    s2, known, n = np.asarray(d["s2"]).ravel(), d["known"], d["frames"]
    known = np.broadcast_to(np.asarray(known, np.float64), s2.shape)
    prm = dict(zip(names, d["params"]))
    rng = np.random.default_rng(seed)
    from scipy import stats

    from ..model.heavy_tail import HeavyTail

    # the fitted distribution (docs/model.md section 4: a clipped Gumbel body, a uniform tail for a fraction of units)
    model_sigma = HeavyTail(stats.gumbel_r(loc=prm["gumbel_loc_e"], scale=prm["gumbel_scale_e"]),
                            d.get("tail_fraction", 0.0), d.get("tail_max", 0.0))
    sig = model_sigma.rvs(s2.size, rng)
    th2 = prm.get("thermal_sigma_e", 0.0) ** 2 if with_thermal else 0.0
    v = known + th2 + sig**2
    model = v * rng.chisquare(n - 1, s2.size) / (n - 1)
    meas = np.sqrt(np.maximum(s2 - known, 0))
    simu = np.sqrt(np.maximum(model - known, 0))
    fig, ax = plots.figure(figsize=(5.2, 3.6))
    hi = float(max(np.quantile(meas, 0.99999), np.quantile(simu, 0.99999)))
    bins = np.linspace(0, hi * 1.02, int(min(120, max(12, 2 * math.sqrt(s2.size)))))
    ax.hist(meas, bins=bins, histtype="stepfilled", alpha=0.5, label="measured")
    ax.hist(simu, bins=bins, histtype="step", color="C3", lw=1.2, label="fitted model, same estimator")
    plots.log_histogram_axes(ax, xlabel, title, "count per bin (log)")
    ax.set_ylim(bottom=0.5)
    return plots.to_png_bytes(fig)


def prnu_plot(x: np.ndarray, pct: float) -> bytes:
    from scipy import stats

    fig, ax = plots.figure(figsize=(5.2, 3.6))
    x = 100 * np.asarray(x)
    bins = np.linspace(float(np.quantile(x, 1e-5)), float(np.quantile(x, 1 - 1e-5)), 120)
    ax.hist(x, bins=bins, histtype="stepfilled", alpha=0.5, label="measured (signal / channel mean - 1)")
    sd = float(np.std(x))
    c = 0.5 * (bins[1:] + bins[:-1])
    ax.plot(c, x.size * stats.norm(0, sd).pdf(c) * np.diff(bins)[0], color="C3", lw=1.2,
            label=f"normal, {sd:.3g} % (PRNU {pct:.3g} % after the temporal share)")
    plots.log_histogram_axes(ax, "pixel response deviation, %", "PRNU: the flat's pixel residual")
    ax.set_ylim(bottom=0.5)
    return plots.to_png_bytes(fig)


def telegraph_plot(d: dict, frames: int = 150) -> bytes:
    """Random telegraph pixels in time: each shown pixel's dark series (DN, its first ``frames`` frames) in a panel
    of its own, with the two levels the fit gave it."""
    n = len(d["series"])
    fig, axes = plots.figure(n, 1, figsize=(7.0, 1.3 + 1.2 * n), sharex=True, squeeze=False)
    for i, (series, levels, (r, c)) in enumerate(zip(d["series"], d["levels"], d["pixels"])):
        ax = axes[i, 0]
        x = series[:frames]
        ax.step(np.arange(x.size) * d["period_s"], x, where="post", lw=0.8, color=f"C{i}")
        for level in levels:
            ax.axhline(level, color="0.3", ls=":", lw=0.8)
        ax.set_ylabel("DN")
        ax.set_title(f"pixel ({r}, {c}): levels {', '.join(f'{v:.1f}' for v in levels)} DN", fontsize=9, loc="left")
    axes[-1, 0].set_xlabel(f"time, s (frame number x the frame period, {d['period_s']:g} s)")
    fig.suptitle("Random telegraph pixels of the long dark stack (dotted: the fitted levels)", fontsize=10)
    fig.subplots_adjust(hspace=0.5)
    return plots.to_png_bytes(fig)


def _fmt_ci(p: dict) -> str:
    ci = p.get("ci95")
    return "" if not ci else f"{ci[0]:.4g} to {ci[1]:.4g}"


def build(doc: dict, result: dict, cfg) -> str:
    P = doc["parameters"]
    meta = doc["meta"]
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>cmosnoise fit report</title>"
             f"<style>{CSS}</style></head><body>",
             f"<h1>cmosnoise fit report</h1><p>cmosnoise {__version__}, {datetime.datetime.now():%Y-%m-%d %H:%M}; "
             f"{html.escape(doc['source'])} ({html.escape(doc['input'])}), {meta['shape'][1]} x {meta['shape'][0]} "
             f"{html.escape(meta['cfa'])}, {meta['bits']} bits. <code>config.yaml</code> beside this report is the "
             "fitted sensor: <code>cmosnoise simulate --config config.yaml</code> runs it.</p>"]
    rows = [(name, p["value"], _fmt_ci(p), p.get("basis", "measured")
             + (f" (only {p['identifiable']} is)" if p.get("identifiable") else ""), p["method"]) for name, p in P.items()]
    meta = doc.get("meta", {})
    parts.append(f"<p>Temperature {html.escape(str(meta.get('temperature_c')))} C: "
                 f"{html.escape(meta.get('temperature_basis', 'from the data'))}</p>")
    parts.append("<h2>Fitted parameters</h2>" + _table(rows, ["parameter", "value", "95 % interval", "basis", "method"]))
    truth = doc.get("truth")
    if truth:
        parts.append(f"<h2>Against the configuration that made the data</h2><p>{html.escape(truth['source'])}: each "
                     "fitted value, its 95 % interval and the configured value. About one interval in twenty misses "
                     "by chance.</p>" + _table([(r["parameter"], f"{r['fitted']:.5g}",
                                                 "" if not r["ci95"] else f"{r['ci95'][0]:.4g} to {r['ci95'][1]:.4g}",
                                                 f"{r['truth']:.5g}", {True: "yes", False: "NO", None: "-"}[r["inside"]])
                                                for r in truth["rows"]],
                                               ["parameter", "fitted", "95 % interval", "configured", "inside"]))
    sel = doc.get("selection") or {}
    if sel:
        from ..analysis.fit import SELECTION_ALPHA, SELECTION_TESTS

        parts.append(f"<h2>Stages the data switch on</h2><p>Each stage's absence is tested; it is switched on only "
                     f"where p is below {SELECTION_ALPHA:.0%} / {len(SELECTION_TESTS)} (Bonferroni: data without any "
                     f"of them switch one on in at most {SELECTION_ALPHA:.0%} of data sets).</p>"
                     + _table([(name, f"{t['p_value']:.3g}", f"{t['threshold']:.3g}", "on" if t["on"] else "off",
                                t["test"]) for name, t in sel.items()], ["stage", "p-value", "threshold", "switched",
                                                                         "test"]))
    if doc["not_fitted"]:
        parts.append("<h2>Not fitted (kept from the base configuration)</h2>"
                     + _table(list(doc["not_fitted"].items()), ["parameter", "why, and what it needs"]))
    figs = []
    if "ptc" in result["plots"]:
        figs.append(_figure(ptc_plot(result["plots"]["ptc"]), "Photon transfer: variance over mean, K the slope"))
    parts.append("<h2>Photon transfer</h2><div class='row'>" + "".join(figs) + "</div>")
    for T, res in sorted(result["dark"].items()):
        n_neg = int((result["_maps"][T] <= 0).sum())
        fam_rows = [(f["family"], f["mean"], f["std"], f["loglik"], f["aic"], f["delta_aic"]) if math.isfinite(f["loglik"])
                    else (f["family"], "", "", f"not defined: {n_neg} pixels <= 0 e-/s (a noisy map; longer exposures)", "", "")
                    for f in res["families"]]
        ex = res["exposures_s"]
        wp = res["white_pixels"]
        parts.append(f"<h2>Dark current at {T:g} C</h2><div class='row'>"
                     + _figure(dark_map_plot(result["_maps"][T], res, T), f"Rate map at {T:g} C, the fitted body over it (the paper's Figs. 5 and 6 from these frames)")
                     + "<div>" + _table(fam_rows, ["family", "mean e-/s", "std e-/s", "log-likelihood", "AIC", "delta AIC"], digits=6)
                     + f"<p>From {len(ex)} exposure times, {ex[0]:g} to {ex[-1]:g} s.</p>"
                     + _table([("threshold, e-/s", wp["threshold"]), ("white pixels", wp["white_pixels"]),
                               ("ppm", wp["ppm"]), ("couplets", wp["couplets"]),
                               ("couplets expected at random", wp["couplets_expected_random"]),
                               ("P(this many or more at random)", wp["couplets_p_value_random"])],
                              ["white pixels and couplets", ""], digits=4)
                     + "</div></div>")
    pl = result["plots"]
    if "source_follower" in pl:
        d = pl["source_follower"]
        names = ["thermal_sigma_e", "gumbel_loc_e", "gumbel_scale_e", "tail_ppm_above", "tail_max_e"]
        figs = [_figure(sigma_plot(d, names, "Per-pixel temporal noise (paper Fig. 7)",
                                    "sqrt(pixel variance less dark shot and quantizer), e- rms", True),
                        "Each pixel's temporal noise over the long dark stack (the paper's Fig. 7 from these frames), "
                        "and the same estimate under the fitted source follower (thermal floor, Gumbel flicker body, "
                        "uniform tail)")]
        c = pl["columns"]
        figs.append(_figure(sigma_plot(dict(c), ["gumbel_loc_e", "gumbel_scale_e"], "Per-column temporal noise",
                                        "sqrt(column-mean variance less the pixels' share), e- rms", False),
                            "Each column's temporal noise and the fitted Gumbel"))
        parts.append("<h2>Readout noise</h2><div class='row'>" + "".join(figs) + "</div>")
    if "telegraph" in pl:
        parts.append("<h2>Random telegraph pixels</h2><div class='row'>"
                     + _figure(telegraph_plot(pl["telegraph"]),
                               "The dark series of the pixels with the largest amplitudes and their fitted levels: two "
                               "(a trap or a blinking pixel held over frames, by a hidden Markov model) or three (a "
                               "trap through CDS, by a three-level mixture). These "
                               "pixels are left out of the pixel offsets and the source follower's fit") + "</div>")
    if "prnu" in pl:
        parts.append("<h2>PRNU</h2><div class='row'>"
                     + _figure(prnu_plot(pl["prnu"]["residual"], P["prnu.measured_pct"]["value"]),
                               "The flat's per-pixel response, rows and columns removed") + "</div>")
    if doc.get("round_trip"):
        rows = [(r["parameter"], r["measured"], r["simulated"],
                 "" if r["agree"] is None else ("yes" if r["agree"] else "no")) for r in doc["round_trip"]]
        parts.append("<h2>Round trip</h2><p>The measurement made again from the fitted configuration (same stacks, "
                     "exposure times, temperatures, frame counts and flat levels) and fitted the same way. "
                     "\"Agree\": the two values differ by no more than chance allows, judged over every parameter "
                     "together (one false alarm in 100 fits of a right model).</p>"
                     + _table(rows, ["parameter", "fit of the measured frames", "fit of the simulated frames",
                                     "agree"], digits=5))
    if doc.get("settings"):
        keys = ["system_gain_K_dn_per_e", "read_noise.shape", "read_noise.scale_dn", "source_follower.thermal_sigma_e",
                "row_noise.sigma_e", "black_level_dn"]
        rows = [(setting, r["mode"] or "", *[r["parameters"][k]["value"] if k in r["parameters"] else "" for k in keys])
                for setting, r in doc["settings"].items()]
        parts.append("<h2>Gain settings</h2><p>One fit per setting the stacks were taken at; the configuration's "
                     "gain_table holds each setting's K and what follows it. A conversion-gain step is named where "
                     "the read-noise floor in e- falls by 30 % or more.</p>"
                     + _table(rows, ["setting", "mode", *keys], digits=5))
    if doc.get("emva_round_trip"):
        rows = [(r["quantity"], r["unit"], r["measured"], r["simulated"],
                 (r["simulated"] / r["measured"] - 1) * 100 if r["measured"] and math.isfinite(r["measured"]) else "",
                 "" if r.get("agree") is None else ("yes" if r["agree"] else "no"))
                for r in doc["emva_round_trip"]]
        parts.append("<h2>EMVA 1288 round trip</h2><p>The fitted sensor measured with the data set's own exposure "
                     "times, photons and stack sizes, and both series evaluated the same way. \"Within limits\": K 3 %, "
                     "dark noise 5 %, DSNU, PRNU and dark current 10 %, saturation and QE 5 %, linearity error 0.25 "
                     "points.</p>" + _table(rows, ["quantity", "unit", "measured frames", "simulated from the fit",
                                                   "difference %", "within limits"], digits=4))
    parts.append(f"<h2>Fitted configuration</h2><pre>{html.escape(cfg.to_yaml())}</pre></body></html>")
    return "".join(parts)
