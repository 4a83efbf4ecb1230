"""What random telegraph noise costs a frame, at 1920 x 1080 RGGB, and what frame 10^6 alone costs at VGA.

The default chain is timed without RTS, and again with 1000 ppm source-follower RTS pixels (one trap each,
CDS) and 100 ppm blinking white pixels; each against the plain NumPy reference of bench_chain.py timed
alternately with it, so the ratio of the two ratios is RTS's cost, free of a shared machine's slow spells
(#29 asks at most +20 %). Then frame 1 000 000 of a VGA sensor with RTS, made alone (#29: under a second).

    python benchmarks/bench_telegraph.py [--frames 20] [--repeats 5] [--threads 2] [--json FILE]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

from bench_chain import cost_arguments, save_cost, stage_cost  # noqa: E402

from cmosnoise import Sensor, load_config  # noqa: E402

RTS_ON = {
    "source_follower": {"rts": {"enabled": True, "ppm": 1000}},
    "dark_current": {"rts": {"enabled": True, "ppm": 100}},
    "sensor": {"frame_rate_hz": 30},
}


def main() -> None:
    a = cost_arguments(__doc__, "also write the results here (docs/numbers/telegraph_cost.json feeds the README)")
    rows, cost = stage_cost(a, "without RTS (the default)",
                            "1000 ppm source-follower RTS pixels and 100 ppm blinking pixels", RTS_ON)
    print(f"RTS costs {100 * cost:+.1f} % per frame ({a.threads} threads; the issue allows +20 %)")
    vga = Sensor(load_config(extra=RTS_ON), seed=0).expose("photo")
    vga.frame(0)
    t0 = time.perf_counter()
    vga.frame(1_000_000)
    far = time.perf_counter() - t0
    print(f"frame 1 000 000 alone at 640 x 480 with RTS: {1e3 * far:.1f} ms")
    save_cost(a, rows, cost, frame_1e6_vga_ms=1e3 * far)


if __name__ == "__main__":
    main()
