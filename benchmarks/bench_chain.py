"""Frames per second of the full chain at 1920 x 1080 RGGB, next to a plain NumPy reference,
and the time to process one frame into a picture.

The reference does the least any simulator must: a Poisson draw, Gaussian
read noise, and quantization to uint16, on the same mean image. Both are
timed in the same run, so their ratio is meaningful on a busy machine.

    python benchmarks/bench_chain.py [--frames 20] [--repeats 3] [--cli-frames 50]

It prints, per frame: the fused frame kernel on 1 and 2 threads, the NumPy
implementation of the same scheme (the fallback without numba, and what
``detail=True`` runs), the reference, and ``cmosnoise simulate`` end to end
(a separate process, TIFF writing and run statistics included, compile
cache warm: wall clock per frame with its start-up included; the run's own
per-frame time from summary.json: sensor set-up, frames, TIFF, statistics;
and what each further frame costs, from the same command run with twice the
frames; each command the best of --cli-repeats runs), each with its ratio to
the reference. Each ratio is taken against the reference timed alternately
with it (the column "reference"), so a slow spell of a shared machine falls
on both sides. The start-up is a one-frame run's wall clock less one further
frame.
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

import numpy as np

from cmosnoise import Sensor, load_config


def per_frame(fn, frames: int) -> float:
    """Seconds per frame of ``fn(k)`` over ``frames`` frames."""
    t0 = time.perf_counter()
    for k in range(frames):
        fn(k)
    return (time.perf_counter() - t0) / frames


def best_fps(fn, frames: int, repeats: int) -> float:
    return 1 / min(per_frame(fn, frames) for _ in range(repeats))


def against_reference(fn, frames: int, repeats: int, reference, ref_frames: int) -> tuple[float, float]:
    """Seconds per frame of ``fn`` and of ``reference``, timed alternately (reference, fn, ..., reference) and
    the best of each kept: two bests from the same minute, so a slow spell of a shared machine does not
    fall on one side of the ratio only."""
    t_fn = t_ref = float("inf")
    for _ in range(repeats):
        t_ref = min(t_ref, per_frame(reference, ref_frames))
        t_fn = min(t_fn, per_frame(fn, frames))
    return t_fn, min(t_ref, per_frame(reference, ref_frames))


def numpy_reference(mean_e: np.ndarray, k_gain: float):
    """The reference: ``fn(k)`` draws a frame of Poisson charge on ``mean_e`` (e-), adds Gaussian read noise
    (2 e-) and quantizes (``k_gain`` DN/e-, black level 64, 12 bits) to uint16, with NumPy's generator."""
    mean = mean_e.astype(np.float64)
    rng = np.random.default_rng(0)

    def reference(_k):
        n = rng.poisson(mean) + rng.normal(0.0, 2.0, mean.shape)
        return np.clip(np.rint(n * k_gain + 64), 0, 4095).astype(np.uint16)

    return reference


def cost_arguments(doc: str, json_help: str = "also write the results here"):
    """The command line of a stage-cost benchmark (--frames, --repeats, --threads, --json), numba's threads set."""
    import argparse

    import numba

    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", help=json_help)
    a = ap.parse_args()
    numba.set_num_threads(a.threads)
    return a


def stage_costs(cases, frames: int, repeats: int, size=(1920, 1080)) -> list[dict]:
    """Each case ``(label, configuration extra)`` at ``size``: ms a frame of the ``photo`` scene and its ratio to
    :func:`numpy_reference`, timed alternately with it (the first case is the baseline others are read against).

    The cases take turns, round by round (``repeats`` rounds, the best of each kept): the reference's first
    rounds run some 10 % slower (its arrays' first pages), which timed one case after the other fell on the
    first case alone and moved the ratio of ratios by as much (measured: 99 against 90 ms a frame).
    """
    from cmosnoise import Sensor, load_config

    made = []
    for label, extra in cases:
        sensor = Sensor(load_config(extra={**extra, "sensor": {**extra.get("sensor", {}), "width": size[0],
                                                               "height": size[1]}}), seed=0)
        shot = sensor.expose("photo")
        shot.frame(0)  # compile
        made.append((label, shot, numpy_reference(shot.mean_charge_e, sensor.transfer.gain_dn_per_e)))
    best = [(float("inf"), float("inf"))] * len(made)
    for _ in range(repeats):
        for i, (_label, shot, ref) in enumerate(made):
            t, t_ref = against_reference(shot.frame, frames, 1, ref, max(frames // 4, 2))
            best[i] = (min(best[i][0], t), min(best[i][1], t_ref))
    rows = []
    for (label, _shot, _ref), (t, t_ref) in zip(made, best):
        rows.append({"label": label, "ms": 1e3 * t, "ref_ms": 1e3 * t_ref, "ratio": t / t_ref})
        print(f"{label}: {1e3 * t:.1f} ms/frame, reference {1e3 * t_ref:.1f} ms, ratio {t / t_ref:.3f}")
    return rows


def stage_cost(a, off: str, on: str, extra: dict) -> tuple[list[dict], float]:
    """A stage's cost per frame: the rows of :func:`stage_costs` for the default chain (``off``) and with ``extra``
    (``on``), and the ratio of their ratios less 1."""
    rows = stage_costs(((off, {}), (on, extra)), a.frames, a.repeats)
    return rows, rows[1]["ratio"] / rows[0]["ratio"] - 1


def save_cost(a, rows: list[dict], cost: float, **more) -> None:
    """Write a stage-cost measurement to ``--json`` (when given): the CPU, threads, frames, rows and cost."""
    if a.json:
        Path(a.json).write_text(json.dumps({**cpu(), "threads": a.threads, "frames": a.frames, "repeats": a.repeats,
                                            "rows": rows, "cost": cost, **more}, indent=1))


def cpu() -> dict:
    """The processor the ratios belong to: its model and the widest vectors numba compiles for here.

    The kernel's branch-free passes are SIMD code, the reference mostly scalar, so their ratio depends on
    the vector width: record it with every measurement.
    """
    import platform

    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            model = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), model)
    except OSError:
        pass
    from cmosnoise.engine import jit  # sets the vector width the package compiles with

    return {"cpu": model, "vectors": jit.vectors(), "numba": jit.numba.__version__}


def _run(cmd: list[str]) -> None:
    r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ})
    if r.returncode:
        sys.exit(f"{' '.join(cmd)} failed ({r.returncode}):\n{r.stderr}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scene", default="photo")
    ap.add_argument("--width", type=int, default=1920, help="the sensor's width (the suite's smoke run: 320)")
    ap.add_argument("--height", type=int, default=1080, help="the sensor's height")
    ap.add_argument("--cli-frames", type=int, default=50)
    ap.add_argument("--cli-repeats", type=int, default=3, help="runs of each command line; the best is kept")
    ap.add_argument("--json", help="also write the results here (docs/numbers/speed.json feeds the README)")
    args = ap.parse_args()

    cfg = load_config(extra={"sensor": {"width": args.width, "height": args.height, "cfa": "RGGB"}})
    # the first sensor of a process also loads the compiled fixed-pattern loops (numba's registries with them);
    # a second one of the same size is what each further sensor costs
    t0 = time.perf_counter()
    Sensor(cfg, seed=2)
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    sensor = Sensor(cfg, seed=1)
    t_fixed = time.perf_counter() - t0
    t0 = time.perf_counter()
    shot = sensor.expose(args.scene)
    t_expose = time.perf_counter() - t0
    on = [k for k, v in sensor.stages_on().items() if v]

    reference = numpy_reference(shot.mean_charge_e, sensor.transfer.gain_dn_per_e)
    import numba

    shot.frame(0)  # compile or load the kernel outside the timing
    reference(0)
    threads = numba.get_num_threads()
    rows = []  # (label, seconds per frame, the reference's seconds per frame timed alongside)
    for n in sorted({1, threads}):
        numba.set_num_threads(n)
        rows.append((f"frame kernel, {n} thread(s)",
                     *against_reference(shot.frame, args.frames, args.repeats, reference, args.frames)))
    numba.set_num_threads(threads)
    rows.append(("NumPy implementation (no numba)",
                 *against_reference(lambda k: shot.frame(k, detail=True), 2, 1, reference, args.frames)))
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "cmosnoise", "simulate", "--frames", str(args.cli_frames), "--no-progress",
               "--set", f"sensor.width={args.width}", "--set", f"sensor.height={args.height}", "--scene", args.scene]
        _run(cmd + ["--out", f"{tmp}/warm"])  # warm the compile cache
        # the same command with twice the frames: the difference is what each further frame costs, start-up
        # (imports, fixed pattern, scene, summary, preview) taken out. Each is timed --cli-repeats times,
        # alternating with the reference, and the best kept: a shared machine's slow moments inflate single runs.
        double = [a if a != str(args.cli_frames) else str(2 * args.cli_frames) for a in cmd]
        single = [a if a != str(args.cli_frames) else "1" for a in cmd]
        wall = wall2 = wall1 = ref_cli = float("inf")
        for i in range(args.cli_repeats):
            ref_cli = min(ref_cli, per_frame(reference, args.frames))
            t0 = time.perf_counter()
            _run(cmd + ["--out", f"{tmp}/o{i}"])
            w = time.perf_counter() - t0
            if w < wall:
                with open(f"{tmp}/o{i}/summary.json") as fh:
                    wall, loop = w, json.load(fh)["timings_s"]["per_frame"]
            t0 = time.perf_counter()
            _run(double + ["--out", f"{tmp}/d{i}"])
            wall2 = min(wall2, time.perf_counter() - t0)
            t0 = time.perf_counter()
            _run(single + ["--out", f"{tmp}/s{i}"])
            wall1 = min(wall1, time.perf_counter() - t0)
        ref_cli = min(ref_cli, per_frame(reference, args.frames))
        rows.append((f"cmosnoise simulate --frames {args.cli_frames}", wall / args.cli_frames, ref_cli))
        rows.append(("  its frame loop (summary.json)", loop, ref_cli))
        rows.append((f"  each further frame ({2 * args.cli_frames} vs {args.cli_frames})",
                     max(wall2 - wall, 1e-9) / args.cli_frames, ref_cli))
        # a one-frame run less one further frame: measured directly, not as the difference of two long runs
        start_up = wall1 - (wall2 - wall) / args.cli_frames
    nthreads = threads
    t_ref = min(r[2] for r in rows)
    rows.append(("NumPy reference (Poisson+Gauss+q)", t_ref, t_ref))

    print(f"cmosnoise full chain, {args.width} x {args.height} {cfg.sensor.cfa}, stages on: {', '.join(on)}")
    host = cpu()
    print("  on {cpu} ({vectors}), numba {numba}".format(**host))
    print(f"  sensor set-up (fixed pattern)     {t_fixed * 1000:8.1f} ms (once per sensor; the first of a process "
          f"{t_first * 1000:.0f} ms, loading the compiled loops)")
    print(f"  expose scene '{args.scene}'            {t_expose * 1000:8.1f} ms (once per scene)")
    print(f"  {'':36s} {'frames/s':>10s} {'ms/frame':>10s} {'reference':>10s} {'x reference':>12s}")
    for label, t, ref in rows:
        print(f"  {label:36s} {1 / t:10.1f} {1000 * t:10.1f} {1000 * ref:10.1f} {t / ref:12.2f}")

    from cmosnoise import calibration
    from cmosnoise.config import ProcessingSection
    from cmosnoise.isp.process import Processor

    processing = []
    raw = shot.frame(0)
    master = calibration.master_dark(sensor.dark_frames(4))
    print(f"  processing one {args.width} x {args.height} frame into an 8-bit picture (best of --repeats, after a "
          "warm-up):")
    for label, settings in [
        ("pre-processing view", ProcessingSection()),
        ("dark cal + median defects", ProcessingSection(dark_frames=4, defects={"method": "median"})),
        ("dark cal + defect map", ProcessingSection(dark_frames=4, defects={"method": "map"})),
        ("dark cal + map + Malvar 2004", ProcessingSection(dark_frames=4, defects={"method": "map"}, demosaic="malvar2004")),
        ("dark cal + map + Menon 2007", ProcessingSection(dark_frames=4, defects={"method": "map"}, demosaic="menon2007")),
    ]:
        proc = Processor(settings, sensor.raw_info(), master)
        pre = label.startswith("pre")
        proc.render(raw, pre=pre)
        fps = best_fps(lambda _k, proc=proc, pre=pre: proc.render(raw, pre=pre), 3, args.repeats)
        print(f"  {label:32s} {1000 / fps:10.1f} ms")
        processing.append({"label": label, "ms": 1000 / fps})

    if args.json:
        import platform

        command = "python benchmarks/bench_chain.py " + " ".join(
            f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items() if k not in ("json",))
        data = {
            "machine": f"{os.cpu_count()} cores, {platform.processor() or platform.machine()}, numba threads {nthreads}",
            **host,
            "command": command,
            "fixed_ms": t_fixed * 1000, "first_sensor_ms": t_first * 1000, "expose_ms": t_expose * 1000, "cli_start_up_s": start_up,
            "rows": [{"label": label.strip(), "fps": 1 / t, "ms": 1000 * t, "ref_ms": 1000 * ref, "ratio": t / ref}
                     for label, t, ref in rows],
            "processing": processing,
        }
        with open(args.json, "w") as f:
            json.dump(data, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
