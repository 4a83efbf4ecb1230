"""A sensor's set-up (its fixed pattern) against its size, and against a frame of the same sensor.

For each size, in a fresh process (so each peak is its own): ``Sensor()`` of the default configuration at that
size, with how far its resident memory rose during it (the high-water mark of ``/proc/self/status``, reset
before, less the resident size then: some maps live in pages of their own, ``engine/buffers.py``, which
tracemalloc does not see) against the bytes of the maps it keeps; then timed, the fastest of ``--repeats``
(the compiled loops loaded first on a 64 x 48 sensor, so no compile is counted); then a frame of the default
scene (the exposure made first), the fastest of as many. Set-up is linear in pixels when its time per pixel
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

#: (width, height) of each size in megapixels (4:3)
SIZES = {1: (1152, 864), 12: (4000, 3000), 50: (8192, 6144)}


def _resident() -> tuple[int, int]:
    """This process's resident size and its high-water mark, bytes (Linux)."""
    with open("/proc/self/status") as f:
        fields = dict(line.split(":", 1) for line in f)
    return (int(fields["VmRSS"].split()[0]) * 1024, int(fields["VmHWM"].split()[0]) * 1024)


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
    setup = math.inf
    for _ in range(repeats):  # the fastest of a few: a shared machine's slow spells only ever add
        del sensor
        t0 = time.perf_counter()
        sensor = Sensor(cfg)
        setup = min(setup, time.perf_counter() - t0)
    fp = sensor.fixed_pattern
    kept = sum(nbytes(getattr(fp, f)) for f in fp.__dataclass_fields__ if getattr(fp, f) is not None)
    ex = sensor.expose()
    ex.frame(0)
    frame = math.inf
    for k in range(1, repeats + 1):
        t0 = time.perf_counter()
        ex.frame(k)
        frame = min(frame, time.perf_counter() - t0)
    return {"width": width, "height": height, "pixels": width * height, "setup_s": setup,
            "setup_ns_per_pixel": 1e9 * setup / (width * height), "frame_s": frame,
            "frames_worth": setup / frame, "setup_rise_bytes": peak, "maps_bytes": kept}


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
            json.dump({"threads": a.threads, "repeats": a.repeats, "rows": rows, "per_pixel_spread": spread,
                       "cpu_count": os.cpu_count(), "finite": all(math.isfinite(p) for p in per)}, f, indent=1)


if __name__ == "__main__":
    main()
