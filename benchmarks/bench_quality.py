"""What `cmosnoise quality` and each image-quality metric cost on a 12 MP sensor, against a frame timed in the run.

The issue's targets (#61): ``cmosnoise quality`` of a 12 MP sensor at 6 illuminances under a minute after the
first compile (2 cores); each metric on a 12 MP image under a second. Each time is the fastest of ``--repeats``:

- **frame**: one frame of the default sensor at the size (the reference timed beside the rest);
- **quality, 6 illuminances**: :func:`cmosnoise.analysis.quality.measure` of the same sensor at 1 to 1000 lux,
  8 frames of each chart (what the command measures; the charts are crops of their own size, so the sensor's
  size enters through the viewing conditions only);
- **each metric on a whole 12 MP image**: the visual luminance noise, the three colour visual noises (ISO 15739,
  S-CIELAB, CPIQ) and both bandings of a 12 MP grey, the e-SFR of a 12 MP edge and of its raw green pixels, the
  colour error of a 12 MP ColorChecker mosaic (its patch means and the fit).

    python benchmarks/bench_quality.py [--megapixels 12] [--repeats 3] [--chart-frames 8] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

from bench_optics import fastest  # the fastest of n calls, as the optics benchmark times it


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--megapixels", type=float, default=12.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--chart-frames", type=int, default=8,
                    help="frames of each chart in the quality.measure row (the command's 8; the suite's smoke run 2)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    import numpy as np

    from cmosnoise import Sensor, load_config
    from cmosnoise.analysis import colour_error, quality, sfr, visual_noise
    from cmosnoise.engine import jit
    from cmosnoise.model import charts

    width = int(round(math.sqrt(args.megapixels * 1e6 * 4 / 3) / 2) * 2)
    height = int(round(width * 3 / 4 / 2) * 2)
    size = [f"sensor.width={width}", f"sensor.height={height}"]
    cfg = load_config(overrides=size)
    shot = Sensor(cfg, seed=0).expose("photo")
    shot.frame(0)  # compiled and warm
    frame_s = fastest(lambda: shot.frame(1), args.repeats)
    lux = [1, 3, 10, 30, 100, 1000]
    quality.measure(cfg, lux[:1], frames=2)  # the compiles and caches of the first call
    rows = [{"label": "one frame of the sensor (reference)", "s": frame_s}]
    rows.append({"label": f"quality.measure, {len(lux)} illuminances, {args.chart_frames} frames of each chart",
                 "s": fastest(lambda: quality.measure(cfg, lux, frames=args.chart_frames), args.repeats)})
    rng = np.random.default_rng(0)
    grey = np.clip(0.18 + 0.01 * rng.standard_normal((height, width)), 0, None)
    rows.append({"label": "visual luminance noise of a whole grey",
                 "s": fastest(lambda: visual_noise.visual_luminance_noise(grey, height), args.repeats)})
    grey_rgb = np.clip(0.18 + 0.01 * rng.standard_normal((height, width, 3)), 0, None).astype(np.float32)
    view = visual_noise.print_viewing(height)
    for variant, label in [("iso15739_2013", "ISO 15739 visual noise"), ("scielab", "S-CIELAB"),
                           ("cpiq", "CPIQ visual noise")]:
        rows.append({"label": f"{label} of a whole colour grey",
                     "s": fastest(lambda v=variant: visual_noise.visual_noise(grey_rgb, v, view), args.repeats)})
    rows.append({"label": "column banding of a whole grey",
                 "s": fastest(lambda: visual_noise.banding(grey, "columns", height), args.repeats)})
    rows.append({"label": "row banding of a whole grey",
                 "s": fastest(lambda: visual_noise.banding(grey, "rows", height), args.repeats)})
    edge = charts.edge((height, width))[..., 0] + 0.002 * rng.standard_normal((height, width))
    region = charts.truth("edge", (height, width))["region"]
    rows.append({"label": "e-SFR of a whole edge (its region: 60 % of the rows, half the columns)",
                 "s": fastest(lambda: sfr.esfr(edge, region), args.repeats)})
    rows.append({"label": "raw e-SFR of the same edge's green pixels (two grids of a quarter each)",
                 "s": fastest(lambda: sfr.raw_channel(edge, cfg.sensor.cfa, region), args.repeats)})
    mosaic = Sensor(load_config(overrides=[*size, "light.enabled=true", "light.illuminance_lux=300",
                                           "light.spectral_qe=Nikon 5100 (NPL)", "light.qe_peak=0.6",
                                           "light.ir_cut_nm=680"]), seed=0).expose("colorchecker").frame(0)
    patches = charts.truth("colorchecker", (height, width))["patches"]

    def colour():
        cam = colour_error.mosaic_patch_means(mosaic, cfg.sensor.cfa, patches, 64.0)
        return colour_error.colour_error(cam)

    rows.append({"label": "colour error of a whole ColorChecker mosaic", "s": fastest(colour, args.repeats)})
    for r in rows:
        r["frames_worth"] = r["s"] / frame_s
    data = {"megapixels": width * height / 1e6, "width": width, "height": height, "cores": os.cpu_count(),
            "vectors": jit.vectors(), "rows": rows}
    for r in rows:
        print(f"{r['label']:<75} {r['s']:8.3f} s  ({r['frames_worth']:.2f} frames)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(data, f, indent=2)
            f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
