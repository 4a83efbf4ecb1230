"""What 1/f noise in time (#76) costs a frame at 1920 x 1080 RGGB, against the white default.

Each case is timed alternately with the plain NumPy reference of bench_chain.py (the ratio of the two ratios is
the cost, free of a shared machine's slow spells): a pixel's 1/f flicker through CDS (#76 asks at most 1.5x),
the row noise 1/f in readout order, each column amplifier 1/f over frames, the two column banks per frame.
Then a pixel's 1/f flicker level without CDS (each pixel bridged on the host) per pixel at 256 x 256.

    python benchmarks/bench_flicker.py [--frames 20] [--repeats 5] [--threads 2] [--json FILE]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

from bench_chain import cost_arguments, cpu, stage_costs  # noqa: E402

from cmosnoise import Sensor, load_config  # noqa: E402

T = {"sensor": {"frame_rate_hz": 30}}
CASES = (
    ("white (the default)", T),
    ("pixel flicker one_over_f, through CDS at 2e-5 s",
     {**T, "source_follower": {"flicker": {"spectrum": "one_over_f"}, "rts": {"cds_interval_s": 2e-5}}}),
    ("row noise one_over_f in readout order", {**T, "row_noise": {"spectrum": "one_over_f"}}),
    ("column noise one_over_f over frames", {**T, "column_noise": {"temporal": {"spectrum": "one_over_f"}}}),
    ("two column banks, 0.5 e- a frame",
     {**T, "column_noise": {"alternating": {"enabled": True, "temporal_sigma_e": 0.5}}}),
)


def main() -> None:
    import json

    a = cost_arguments(__doc__)
    rows = stage_costs(CASES, a.frames, a.repeats)
    base = rows[0]["ratio"]
    for r in rows:
        r["cost"] = r["ratio"] / base
        print(f"{r['label']}: {r['cost']:.2f}x the white frame")
    size = 256 if a.frames >= 4 else 32
    sensor = Sensor(load_config(extra={**T, "sensor": {"frame_rate_hz": 30, "width": size, "height": size},
                                       "source_follower": {"flicker": {"spectrum": "one_over_f"},
                                                           "rts": {"cds": False}}}), seed=0)
    shot = sensor.expose("photo")
    shot.frame(0)
    t0 = time.perf_counter()
    for k in range(1, 4):
        shot.frame(k)
    per_pixel_us = (time.perf_counter() - t0) / 3 / size**2 * 1e6
    print(f"pixel flicker one_over_f without CDS: {per_pixel_us:.1f} us a pixel ({size} x {size}; "
          f"a 1080p frame some {per_pixel_us * 1920 * 1080 / 1e6:.0f} s)")
    if a.json:
        Path(a.json).write_text(json.dumps({**cpu(), "threads": a.threads, "frames": a.frames, "rows": rows,
                                            "no_cds_us_per_pixel": per_pixel_us}, indent=1))


if __name__ == "__main__":
    main()
