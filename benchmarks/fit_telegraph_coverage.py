"""The random telegraph fit over 20 simulated sensors (#29): does it recover what it was given?

Each sensor (a seed of tests/test_fit_telegraph.py's configuration, 256 x 256 here) makes a 600-frame dark
stack; the fit's ppm should fall in the Clopper-Pearson interval of the configured ppm, its median amplitude
and dwell times within 10 % of the configured laws' medians (lognormal: the median; log-uniform: the geometric
mean of its ends), and its 95 % intervals should hold those truths at least 17 times in 20.

    python benchmarks/fit_telegraph_coverage.py [--sensors 20] [--size 256] [--json FILE]

``--size`` is the sensors' side, pixels: the suite runs it at 64, to see it run (a study needs 256).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))

from test_fit_telegraph import CONFIG, FRAMES  # noqa: E402

from cmosnoise import Sensor  # noqa: E402
from cmosnoise.analysis import fit_telegraph  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sensors", type=int, default=20)
    ap.add_argument("--size", type=int, default=256, help="the sensors' width and height, pixels")
    ap.add_argument("--json")
    a = ap.parse_args()
    rts = CONFIG["source_follower"]["rts"]
    config = {**CONFIG, "sensor": {**CONFIG["sensor"], "width": a.size, "height": a.size}}
    truth = {"amplitude_e": rts["amplitude_e"]["median"],
             "tau_low_s": math.sqrt(rts["tau_capture_s"]["min_s"] * rts["tau_capture_s"]["max_s"]),
             "tau_high_s": math.sqrt(rts["tau_emission_s"]["min_s"] * rts["tau_emission_s"]["max_s"])}
    n_pix = a.size * a.size
    ci = stats.binomtest(round(rts["ppm"] * 1e-6 * n_pix), n_pix).proportion_ci(0.95, method="exact")
    ppm_band = (1e6 * ci.low, 1e6 * ci.high)
    rows = []
    for seed in range(a.sensors):
        sensor = Sensor(config, seed=100 + seed)
        frames = np.stack(list(sensor.expose("flat:0").frames(FRAMES)))
        r = fit_telegraph.fit(frames, sensor.transfer.gain_dn_per_e, 1 / 30)
        row = {"seed": 100 + seed, "ppm": r["ppm"], "ppm_in_band": ppm_band[0] <= r["ppm"] <= ppm_band[1],
               "ppm_covered": r["ppm_ci95"][0] <= rts["ppm"] <= r["ppm_ci95"][1]}
        for name, value in truth.items():
            est, (lo, hi) = r[f"median_{name}"], r[f"median_{name}_ci95"]
            row[name] = est
            row[f"{name}_within_10pct"] = abs(est / value - 1) <= 0.10
            row[f"{name}_covered"] = lo <= value <= hi
        rows.append(row)
        print(row)
    summary = {key: sum(r[key] for r in rows) for key in rows[0] if isinstance(rows[0][key], bool)}
    print(f"of {len(rows)} sensors: {summary}")
    if a.json:
        Path(a.json).write_text(json.dumps({"truth": truth, "ppm_band": ppm_band, "frames": FRAMES, "size": a.size, "rows": rows,
                                            "summary": summary},
                                           indent=1))


if __name__ == "__main__":
    main()
