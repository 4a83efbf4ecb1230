"""Bias and interval of the source-follower fit on variances drawn as its likelihood assumes, over many fits.

Per pixel: a flicker sigma from the default sensor's model (Gumbel body and
uniform tail), the thermal floor, an optional known part (the default
sensor's dark charge at 65 C in a 5 ms frame, as Gaussian noise or, with
``--poisson``, as Poisson charge the way frames have it), and ``--frames``
samples; the per-pixel sample variances are fitted by
``fit_readout.fit_source_follower``. For the thermal floor and the Gumbel
location and scale it prints, over ``--fits`` fits: the bias, the spread
of the estimates (their standard deviation over seeds), the mean reported
standard error (which should equal that spread), the mean of
(estimate - truth) / standard error (0 for an unbiased fit, within about
3 / sqrt(fits)) and how often the 95 % interval holds the truth.
``--fraction`` sets the grid's bin width in chi-square widths (the fit's
default 0.12; 0.25 was the earlier one).

    python benchmarks/bias_source_follower.py [--fits 40] [--frames 48] [--known [--poisson]] [--fraction 0.12]
"""

from __future__ import annotations

import argparse
import functools

import numpy as np

from cmosnoise import Sensor, load_config
from cmosnoise.analysis import fit_readout
from cmosnoise.model import physics


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fits", type=int, default=40)
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--known", action="store_true", help="add the dark charge of the default sensor at 65 C, 5 ms")
    ap.add_argument("--poisson", action="store_true", help="the known part as Poisson charge (as frames have it), "
                    "not Gaussian noise; the fit is told its fourth cumulant")
    ap.add_argument("--fraction", type=float, default=None)
    args = ap.parse_args()
    if args.fraction is not None:
        fit_readout._Grid.__init__ = functools.partialmethod(fit_readout._Grid.__init__, fraction=args.fraction)

    cfg = load_config(extra={"sensor": {"width": 256, "height": 192, "temperature_c": 65.0}})
    fl, thermal = cfg.source_follower.flicker, cfg.source_follower.thermal_sigma_e
    model = physics.flicker_model(cfg)
    truth = {"thermal_sigma_e": thermal, "gumbel_loc_e": fl.gumbel_loc_e, "gumbel_scale_e": fl.gumbel_scale_e}
    n = cfg.sensor.width * cfg.sensor.height
    known = (np.maximum(Sensor(cfg, seed=0).dark_rate.astype(np.float64).ravel(), 0) * 0.005 if args.known
             else np.zeros(n))
    est = {k: [] for k in truth}
    ses = {k: [] for k in truth}
    covered = {k: 0 for k in truth}
    for seed in range(args.fits):
        rng = np.random.default_rng(seed)
        v = thermal**2 + model.rvs(n, rng) ** 2 + (0.0 if args.poisson else known)
        x = rng.normal(0, 1, (args.frames, n)) * np.sqrt(v)
        if args.poisson:
            x = x + rng.poisson(known, (args.frames, n))
        s2 = x.var(axis=0, ddof=1)
        r = fit_readout.fit_source_follower(s2, known, args.frames, fl.tail.threshold_e,
                                            kappa4=known if args.poisson else None)["fit"]
        for k in truth:
            value, ci = r.interval(k)
            est[k].append(value)
            ses[k].append(r.se(k))
            covered[k] += ci is not None and ci[0] <= truth[k] <= ci[1]
    print(f"{args.fits} fits of {n} pixels, {args.frames} frames, known part "
          f"{('Poisson' if args.poisson else 'Gaussian') if args.known else 'off'}:")
    print(f"  {'':18s} {'bias':>8s} {'spread':>8s} {'mean se':>8s} {'mean z':>7s} {'covered':>8s}")
    for k in truth:
        e, se = np.array(est[k]), np.array(ses[k])
        z = (e - truth[k]) / se
        print(f"  {k:18s} {e.mean() - truth[k]:+8.4f} {e.std(ddof=1):8.4f} {se.mean():8.4f} {z.mean():+7.2f} "
              f"{covered[k]:4d}/{args.fits}")
    print(f"  (mean z within about {3 / np.sqrt(args.fits):.2f} of 0 for an unbiased fit)")


if __name__ == "__main__":
    main()
