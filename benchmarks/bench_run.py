"""A large sensor made whole: the one-frame ``simulate`` at 50 MP, and its summary against a frame.

Two measurements, each in a child process of its own:

- ``cmosnoise simulate`` of the default configuration at 8192 x 6144 (the bundled photo as the scene, one frame,
  every output: raw.tiff, the preview PNG, summary.json), ``--repeats`` times: its wall time from the command
  line (imports included), its peak resident memory (``wait4``'s ``ru_maxrss``) and its summary's split (set-up,
  the frame, the summary after the frames, and the sensor's own figures made beside the scene and the frames);
- the summary alone, on a sensor of the same size: the frame kernel's time (the fastest of ``--repeats`` frames)
  and the whole summary's work done in one thread after the frame, without the pictures beside it
  (``summary.sensor_figures`` then ``summary.build_summary``, on a fresh sensor each time so nothing is kept from the
  last), the fastest of ``--repeats``. "frames' worth": the summary's time over the frame's.

    python benchmarks/bench_run.py [--megapixels 50] [--repeats 3] [--threads 2] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: (width, height) of each size in megapixels
SIZES = {1: (1152, 864), 12: (4000, 3000), 50: (8192, 6144), 100: (11552, 8672)}  # 1: the suite's smoke run


def command_line(width: int, height: int, env: dict) -> dict:
    """One ``cmosnoise simulate`` in a child: its wall time, peak memory and summary timings."""
    with tempfile.TemporaryDirectory(prefix="cmosnoise-run-") as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "-m", "cmosnoise", "-q", "simulate", "--set", f"sensor.width={width}",
               "--set", f"sensor.height={height}", "-o", str(out)]
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed")
        t = json.loads((out / "summary.json").read_text())["timings_s"]
    return {"wall_s": wall, "peak_bytes": usage.ru_maxrss * 1024, "set_up_s": t["set_up"], "frame_s": t["frame_s"],
            "summary_s": t["summary"], "summary_aside_s": t["summary_aside"], "total_s": t["total"]}


def summary_alone(width: int, height: int, repeats: int) -> dict:
    """The frame kernel's time and the whole summary's, one after the other in this process."""
    from cmosnoise import Sensor
    from cmosnoise.analysis.run_stats import RunStats
    from cmosnoise.app import summary

    config = {"sensor": {"width": width, "height": height}}
    frame_s, summary_s = math.inf, math.inf
    for k in range(repeats + 1):  # the first round loads what is compiled: not counted
        sensor = Sensor(config)
        shot = sensor.expose()
        stats = RunStats(sensor.transfer.max_code)
        t0 = time.perf_counter()
        raw, electrons = next(iter(shot.frames_with_electrons(1, k)))
        t1 = time.perf_counter()
        stats.update(raw, electrons)
        t2 = time.perf_counter()
        summary.build_summary(sensor, shot, stats, 0.0, 1, electrons, summary.sensor_figures(sensor))
        t3 = time.perf_counter()
        if k:
            frame_s, summary_s = min(frame_s, t1 - t0), min(summary_s, t3 - t2)
    return {"frame_s": frame_s, "summary_s": summary_s, "frames_worth": summary_s / frame_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--megapixels", type=int, default=50, choices=sorted(SIZES))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    width, height = SIZES[args.megapixels]
    if args.child:
        print(json.dumps(summary_alone(width, height, args.repeats)))
        return
    env = {**os.environ, "NUMBA_NUM_THREADS": str(args.threads)}
    alone = json.loads(subprocess.run([sys.executable, __file__, "--child", "--megapixels", str(args.megapixels),
                                       "--repeats", str(args.repeats)], env=env, check=True, capture_output=True,
                                      text=True).stdout.strip().splitlines()[-1])
    runs = [command_line(width, height, env) for _ in range(args.repeats)]
    walls = sorted(r["wall_s"] for r in runs)
    result = {"threads": args.threads, "cpu_count": os.cpu_count(), "width": width, "height": height,
              "pixels": width * height, "runs": runs, "wall_min_s": walls[0], "wall_median_s": walls[len(walls) // 2],
              "wall_max_s": walls[-1], "summary_alone": alone}
    print(f"{width} x {height}: simulate {walls[0]:.1f} / {walls[len(walls) // 2]:.1f} / {walls[-1]:.1f} s "
          f"(min / median / max of {len(runs)}); summary alone {alone['summary_s']:.2f} s = "
          f"{alone['frames_worth']:.2f} frames' worth (frame {alone['frame_s']:.2f} s)")
    for r in runs:
        print(f"  wall {r['wall_s']:.1f} s, peak {r['peak_bytes'] / 2**30:.2f} GiB: set-up {r['set_up_s']:.2f} s, "
              f"frame {r['frame_s']:.2f} s, summary {r['summary_s']:.2f} s (+{r['summary_aside_s']:.2f} s aside)")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
