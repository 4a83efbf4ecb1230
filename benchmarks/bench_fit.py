"""Seconds `cmosnoise fit` takes on a VGA data set: 40 photon-transfer levels, 100-frame dark stacks at 3 temperatures.

The data set is `cmosnoise measure`'s (the default sensor at 25, 45 and 65 C:
at each a 100-frame dark stack and three 8-frame ones, and 40 flat pairs
plus a 16-frame flat at 25 C), written as .npy files; the fit reads them
from disk. Timed in one process after a warm-up (the frame kernel loaded),
with and without the round trip (which simulates the whole measurement again
and fits it a second time).

    python benchmarks/bench_fit.py [--json docs/numbers/fit_speed.json] [--figures docs/img]

``--figures`` also writes two of fit_report.html's plots of that fit for the
README: the per-pixel temporal noise (fit_fig7.png) and the 65 C dark-current
map (fit_dark65.png).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json")
    ap.add_argument("--figures")
    args = ap.parse_args()

    from cmosnoise import load_config
    from cmosnoise.app import fitting
    from cmosnoise.app.cli import run

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        manifest = fitting.write_measurement(load_config(), tmp / "lab", temperatures=[25.0, 45.0, 65.0])
        made = time.perf_counter() - t0
        frames = sum(1 for _ in (tmp / "lab").glob("*.npy"))
        rows = []
        for label, extra in [("fit, no round trip", ["--no-round-trip"]), ("fit with the round trip", [])]:
            t0 = time.perf_counter()
            assert run(["-q", "fit", "--frames-from", str(manifest), "--out", str(tmp / "out"), "--overwrite", *extra]) == 0
            rows.append({"label": label, "seconds": time.perf_counter() - t0})
        if args.figures:
            from cmosnoise.analysis import fit
            from cmosnoise.app import fit_report
            from cmosnoise.io import stacks

            res = fit.fit_dataset(stacks.load(manifest), load_config())
            sf = res["plots"]["source_follower"]
            names = ["thermal_sigma_e", "gumbel_loc_e", "gumbel_scale_e", "tail_ppm_above", "tail_max_e"]
            out = Path(args.figures)
            (out / "fit_fig7.png").write_bytes(fit_report.sigma_plot(
                sf, names, "Per-pixel temporal noise (paper Fig. 7)",
                "sqrt(pixel variance less dark shot and quantizer), e- rms", True))
            (out / "fit_dark65.png").write_bytes(fit_report.dark_map_plot(res["_maps"][65.0], res["dark"][65.0], 65.0))
    doc = {"command": "python benchmarks/bench_fit.py", "machine": f"{platform.machine()}, {os.cpu_count()} logical CPUs",
           "data_set": "VGA, 40 flat levels, 100-frame dark stacks at 25, 45 and 65 C", "files": frames,
           "write_seconds": made, "rows": rows}
    for r in rows:
        print(f"{r['label']:28s} {r['seconds']:6.1f} s")
    print(f"(writing the data set: {made:.1f} s, {frames} files)")
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
