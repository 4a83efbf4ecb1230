"""A sensor too large to hold whole, made in tiles: time per pixel and peak memory against the 1080p frame kernel.

For each size, ``cmosnoise simulate --tile SIZE`` of the default sensor (one frame of a flat grey scene, written
to a tiled raw.tiff in a temporary folder) runs in a child process: its wall time, its peak resident memory
(``wait4``'s ``ru_maxrss``) and its summary's split (the tiles' set-up, the frame kernel). In another child, a
1920 x 1080 frame of the default sensor on the same threads (the fastest of at least ``--repeats`` frames and two
seconds of them, bench_setup's ``fastest``, the kernel loaded first) gives the kernel's own time per pixel, and a
frame of one tile of the 400 MP sensor (its window's arrays) the kernel's in a tile. "run ratio": the tiled run's
wall time (set-up, frames, writing) per pixel over the 1080p kernel's (a frame's, with ``--many N``: the largest
size again with N frames, each tile's set-up made once for all of them and its frames written into their pages
as the tile comes, and from the two runs of that size each frame's time after the first,
:func:`frames_after_set_up`); with ``--runs N``, the fastest of N runs (this machine is shared: one run's time
moves by some 10 %). The run's set-up and frame times are thread time summed over its tiles: two tiles are made
at once.

    python benchmarks/bench_tiles.py [--sizes 50,400] [--many 4] [--runs 3] [--tile 2048] [--threads 2] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_setup import fastest  # this folder's: a script's own folder is on its path

#: (width, height) of each size in megapixels
SIZES = {50: (8192, 6144), 100: (11552, 8672), 400: (20000, 20000)}


def _fastest(render, repeats: int) -> float:
    """The fastest frame after a first one (the kernel loaded): bench_setup's timing, for at least ``repeats``
    frames and two seconds."""
    render(0)
    return fastest(render, repeats)[0]


def kernel_1080p(repeats: int, tile: int) -> dict:
    """The frame kernel's time per pixel on a 1080p frame, and on one tile of a 400 MP sensor (its window's
    arrays), each the fastest of at least ``repeats`` frames (:func:`_fastest`)."""
    from cmosnoise import Sensor
    from cmosnoise.model import tiles

    ex = Sensor({"sensor": {"width": 1920, "height": 1080}}).expose("flat:0.5")
    best = _fastest(ex.frame, repeats)
    w, h = SIZES[400]
    tiling = tiles.Tiling({"sensor": {"width": w, "height": h}}, tile, "flat:0.5")
    region = tiling.regions[len(tiling.regions) // 2]
    shot = tiling.exposure(region)
    in_tile = _fastest(lambda k: shot.frame(k, region=region), repeats)
    pixels = (region[1] - region[0]) * (region[3] - region[2])
    return {"frame_s": best, "ns_per_pixel": 1e9 * best / (1920 * 1080), "tile_frame_s": in_tile,
            "tile_ns_per_pixel": 1e9 * in_tile / pixels}


def tiled_run(width: int, height: int, tile: int, env: dict, frames: int = 1) -> dict:
    with tempfile.TemporaryDirectory(prefix="cmosnoise-tiles-") as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "-m", "cmosnoise", "-q", "simulate", "--tile", str(tile), "--scene", "flat:0.5",
               "--frames", str(frames), "--set", f"sensor.width={width}", "--set", f"sensor.height={height}",
               "-o", str(out)]
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        if os.waitstatus_to_exitcode(status) != 0:
            raise SystemExit(f"{' '.join(cmd)} failed")
        proc.returncode = 0
        summary = json.loads((out / "summary.json").read_text())
        raw_bytes = (out / "raw.tiff").stat().st_size
    pixels = width * height
    t = summary["timings_s"]
    return {"width": width, "height": height, "pixels": pixels, "frames": frames, "tile": tile,
            "tiles": summary["tiles"]["count"], "wall_s": wall, "sys_s": usage.ru_stime,
            "peak_bytes": usage.ru_maxrss * 1024, "raw_bytes": raw_bytes,
            "set_up_s": t["set_up"], "frame_s": t["frame_s"], "total_s": t["total"],
            "ns_per_pixel": 1e9 * wall / (pixels * frames), "frame_ns_per_pixel": 1e9 * t["frame_s"] / pixels,
            "set_up_ns_per_pixel": 1e9 * t["set_up"] / pixels}


def frames_after_set_up(one: dict, many: dict, ref: dict) -> dict:
    """A frame's time beyond the first, from two runs of one size (1 frame and N): the N-frame run's wall time less
    the 1-frame run's, over N - 1. What the tiles' frames cost once their set-up (each tile's fixed pattern, made
    once for all its frames) is paid: the same terms as the 1080p kernel's time, which leaves out its sensor's
    set-up. Also the tiles' set-up in frames' worth: its thread time over one frame's (the N-frame run's)."""
    extra = many["frames"] - one["frames"]
    frame_s = (many["wall_s"] - one["wall_s"]) / extra
    ns = 1e9 * frame_s / one["pixels"]
    return {"frames": [one["frames"], many["frames"]], "frame_s": frame_s, "ns_per_pixel": ns,
            "ratio": ns / ref["ns_per_pixel"], "set_up_frames": many["set_up_s"] / many["frame_s"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="50,400", help="megapixels, of " + ", ".join(map(str, SIZES)))
    ap.add_argument("--tile", type=int, default=2048)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5, help="1080p frames timed, the fastest kept")
    ap.add_argument("--json", help="also write the results here")
    ap.add_argument("--many", type=int, default=0, help="also run the largest size with this many frames")
    ap.add_argument("--runs", type=int, default=1,
                    help="tiled runs of each size, the fastest kept (as the kernel's fastest frame)")
    ap.add_argument("--kernel", action="store_true", help=argparse.SUPPRESS)  # a child: the 1080p kernel
    a = ap.parse_args()
    if a.kernel:
        print(json.dumps(kernel_1080p(a.repeats, a.tile)))
        return
    env = {**os.environ, "NUMBA_NUM_THREADS": str(a.threads)}
    out = subprocess.run([sys.executable, __file__, "--kernel", "--repeats", str(a.repeats), "--tile", str(a.tile)],
                         env=env, check=True, capture_output=True, text=True).stdout
    ref = json.loads(out.strip().splitlines()[-1])
    ref["tile_ratio"] = ref["tile_ns_per_pixel"] / ref["ns_per_pixel"]
    print(f"frame kernel: 1080p {ref['frame_s'] * 1000:.1f} ms = {ref['ns_per_pixel']:.1f} ns/pixel; a {a.tile} tile "
          f"of the 400 MP sensor {ref['tile_ns_per_pixel']:.1f} ns/pixel ({ref['tile_ratio']:.2f} x; {a.threads} "
          "threads)")
    rows = []
    runs = max(1, a.runs)
    sizes = [(int(s), 1) for s in a.sizes.split(",")]
    for mp, frames in sizes + ([(sizes[-1][0], a.many)] if a.many > 1 else []):
        w, h = SIZES[mp]
        r = min((tiled_run(w, h, a.tile, env, frames) for _ in range(runs)), key=lambda t: t["wall_s"])
        r["runs"] = runs
        r["kernel_ratio"] = r["frame_ns_per_pixel"] / ref["ns_per_pixel"]
        r["run_ratio"] = r["ns_per_pixel"] / ref["ns_per_pixel"]
        rows.append(r)
        print(f"{mp:4d} MP ({w} x {h}), {frames} frame(s), in {r['tiles']} tiles of {a.tile}: {r['wall_s']:.1f} s "
              f"({r['ns_per_pixel']:.1f} ns a pixel a frame, {r['run_ratio']:.1f} x the 1080p kernel's; system time "
              f"{r['sys_s']:.1f} s; the tiles' set-up "
              f"{r['set_up_s']:.1f} s and frames {r['frame_s']:.1f} s of thread time, overlapping), "
              f"peak {r['peak_bytes'] / 2**30:.2f} GiB, raw.tiff {r['raw_bytes'] / 2**30:.2f} GiB")
    extra = {}
    if a.many > 1:
        extra["after_set_up"] = after = frames_after_set_up(rows[-2], rows[-1], ref)
        print(f"each frame after the first, {sizes[-1][0]} MP: {after['frame_s']:.2f} s = {after['ns_per_pixel']:.1f} "
              f"ns/pixel ({after['ratio']:.2f} x the 1080p kernel's); the tiles' set-up {after['set_up_frames']:.2f} "
              "frames' worth of thread time")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"threads": a.threads, "cpu_count": os.cpu_count(), "kernel_1080p": ref, "rows": rows, **extra},
                      f, indent=1)


if __name__ == "__main__":
    main()
