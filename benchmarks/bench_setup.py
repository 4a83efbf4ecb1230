"""A sensor's set-up (its fixed pattern) against its size, and against a frame of the same sensor.

For each size, in a fresh process (so each peak is its own): ``Sensor()`` of the default configuration at that
size, with how far its resident memory rose during it (the high-water mark of ``/proc/self/status``, reset
before, less the resident size then: some maps live in pages of their own, ``engine/buffers.py``, which
tracemalloc does not see) against the bytes of the maps it keeps; then timed, the fastest of at least
``--repeats`` set-ups and of as many as fill ``MIN_TIME_S`` (the compiled loops loaded first on a 64 x 48
sensor, so no compile is counted); then a frame of the default scene (the exposure made first), the fastest of
as many, timed the same way. Set-up is linear in pixels when its time per pixel
is the same at every size; "frames' worth" is set-up time over a frame's.

    python benchmarks/bench_setup.py [--sizes 1,12,50] [--threads 2] [--repeats 10] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable

#: (width, height) of each size in megapixels (4:3)
SIZES = {1: (1152, 864), 12: (4000, 3000), 50: (8192, 6144)}
#: each size's set-ups are timed for at least this long (as many as that takes, ``--repeats`` at the least)
MIN_TIME_S = 2.0


def _resident() -> tuple[int, int]:
    """This process's resident size and its high-water mark, bytes (Linux)."""
    with open("/proc/self/status") as f:
        fields = dict(line.split(":", 1) for line in f)
    return (int(fields["VmRSS"].split()[0]) * 1024, int(fields["VmHWM"].split()[0]) * 1024)


def fastest(make: Callable[[int], object], repeats: int) -> tuple[float, int]:
    """The fastest of ``make(k)`` for k = 1, 2, ... (what it returns dropped before the next), timed at least
    ``repeats`` times and for at least ``MIN_TIME_S`` in all: a shared machine's slow spells only ever add, and a
    small sensor's twenty set-ups (some 11 ms each at 1 MP) last 0.2 s, which one slow spell can cover.
    Returns (seconds, how many were timed)."""
    best, timed, spent = math.inf, 0, 0.0
    while timed < repeats or spent < MIN_TIME_S:
        t0 = time.perf_counter()
        made = make(timed + 1)
        took = time.perf_counter() - t0
        del made
        best, timed, spent = min(best, took), timed + 1, spent + took
    return best, timed


def measure(width: int, height: int, repeats: int) -> dict:
    from cmosnoise import Sensor
    from cmosnoise.model.fixed_pattern import nbytes

    Sensor({"sensor": {"width": 64, "height": 48}}).expose().frame(0)  # load the compiled loops
    cfg = {"sensor": {"width": width, "height": height}}
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # the high-water mark back to the resident size now
    before, _ = _resident()
    sensor = Sensor(cfg)
    peak = _resident()[1] - before
    fp = sensor.fixed_pattern
    kept = sum(nbytes(getattr(fp, f)) for f in fp.__dataclass_fields__ if getattr(fp, f) is not None)
    ex = sensor.expose()
    ex.frame(0)
    del sensor, fp
    setup, setups = fastest(lambda _k: Sensor(cfg), repeats)
    frame, frames = fastest(ex.frame, repeats)
    return {"width": width, "height": height, "pixels": width * height, "setup_s": setup,
            "setup_ns_per_pixel": 1e9 * setup / (width * height), "setups_timed": setups, "frame_s": frame,
            "frames_timed": frames, "frames_worth": setup / frame, "setup_rise_bytes": peak, "maps_bytes": kept}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1,12,50", help="megapixels, of " + ", ".join(map(str, SIZES)))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", help="also write the results here")
    ap.add_argument("--repeats", type=int, default=10, help="time each this many times, keep the fastest")
    ap.add_argument("--one", nargs=2, type=int, help=argparse.SUPPRESS)  # a child: width height
    a = ap.parse_args()
    if a.one:
        print(json.dumps(measure(*a.one, a.repeats)))
        return
    env = {**os.environ, "NUMBA_NUM_THREADS": str(a.threads)}
    rows = []
    for mp in (int(s) for s in a.sizes.split(",")):
        w, h = SIZES[mp]
        out = subprocess.run([sys.executable, __file__, "--one", str(w), str(h), "--repeats", str(a.repeats)], env=env, check=True,
                             capture_output=True, text=True).stdout
        r = json.loads(out.strip().splitlines()[-1])
        rows.append(r)
        print(f"{mp:3d} MP ({w} x {h}): set-up {r['setup_s']:.2f} s = {r['setup_ns_per_pixel']:.1f} ns/pixel, "
              f"{r['frames_worth']:.2f} frames' worth (a frame {r['frame_s']:.2f} s); resident memory rose by "
              f"{r['setup_rise_bytes'] / 2**20:.0f} MiB for {r['maps_bytes'] / 2**20:.0f} MiB of maps kept")
    per = [r["setup_ns_per_pixel"] for r in rows]
    spread = max(per) / min(per) - 1
    print(f"time per pixel varies by {100 * spread:.0f} % over the sizes ({a.threads} threads)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"threads": a.threads, "repeats": a.repeats, "min_time_s": MIN_TIME_S, "rows": rows,
                       "per_pixel_spread": spread, "cpu_count": os.cpu_count(),
                       "finite": all(math.isfinite(p) for p in per)}, f, indent=1)


if __name__ == "__main__":
    main()
