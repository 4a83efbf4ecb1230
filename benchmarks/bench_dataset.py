"""Training samples with their truth per second, next to getframes 2.6.1's pair generator and a NumPy reference,
and the memory of a large set.

    python benchmarks/bench_dataset.py [--samples 40] [--crop 512] [--repeats 3] [--memory 10000]

The truth's cost is also given alone: each led sample's truth over its own
noisy frame (one thread), their median, mean and largest ratio.

The source images are read in the warm-up call that compiles the kernel, as
getframes' set-up is paid by its first pair and as ``cmosnoise dataset``
reads them once for all the shards it makes in a process.

Each sample is a 512 x 512 crop: its own sensor instance (set-up), one noisy
frame, and its truth (expected raw, perfect image, defect mask), as
``cmosnoise dataset`` makes them (``make_sample``; writing the shards is
timed separately, end to end with ``cmosnoise dataset``). Cameras: ``led``
(LED's virtual cameras: shot noise, Tukey-lambda read noise, row noise,
black-level offsets, as the learned-denoising literature) and
``sony-imx900`` (the whole chain: PRNU, dark current, source follower,
pixel offsets, nonlinearity). One worker is this process on one thread
(``numba.set_num_threads(1)``); two workers are two processes of one thread
each, the samples split between them.

Beside them, timed in the same run and alternately:

- getframes 2.6.1, ``getframes.dataset.pairs`` on its ``zwo_asi2600mm``
  preset cut to 512 x 512 (``precision="float32"``), random star fields: a raw
  frame and its truth (the noise-free electrons) per pair;
- the NumPy reference: a Poisson draw, Gaussian read noise and quantization
  on the same mean image, and that mean as the truth.

``--memory N`` also makes an N-sample set (64 x 64 crops, hdf5) with
``cmosnoise dataset`` in a child process, and one of N / 10 samples, and
prints both peak resident sizes: flat in N when the shards stream.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np


def _one_thread():
    import numba

    numba.set_num_threads(1)


_SOURCES: dict = {}  # this process's source images, read at its first call (as one dataset run reads them once)


def ours(recipe_json: str, indices: list[int]) -> int:
    from cmosnoise.app import dataset as ds

    _one_thread()
    recipe = ds.Recipe.from_json(recipe_json)
    sources = _SOURCES.setdefault(recipe_json, ds.Sources())
    for i in indices:
        ds.make_sample(recipe, i, sources)
    return len(indices)


def getframes_pairs(n: int, crop: int) -> float:
    import getframes as gf

    cam = gf.Camera.from_preset("zwo_asi2600mm", precision="float32").with_config(resolution=(crop, crop))
    scenes = gf.dataset.random_star_fields(n=n + 1, shape=cam.resolution, seed=0)
    it = iter(gf.dataset.pairs(camera=cam, scenes=scenes, exposure=1.0, seed=1))
    next(it)  # its first pair pays for the set-up
    t0 = time.perf_counter()
    for _ in it:
        pass
    return n / (time.perf_counter() - t0)


def numpy_reference(n: int, crop: int) -> float:
    rng = np.random.default_rng(0)
    mean = rng.uniform(10, 3000, (crop, crop))
    t0 = time.perf_counter()
    for _ in range(n):
        raw = np.clip(np.rint((rng.poisson(mean) + rng.normal(0, 2.0, mean.shape)) * 0.4 + 64), 0, 4095)
        raw.astype(np.uint16), mean.astype(np.float32)
    return n / (time.perf_counter() - t0)


def truth_cost(recipe_json: str, n: int) -> dict:
    """Each of samples 1 to n's truth (``ground_truth.truth``) over its noisy frame, one thread, each timed once:
    the median, mean and largest ratio, and the K (DN/e-) of the sample with the largest."""
    from cmosnoise.analysis import ground_truth
    from cmosnoise.app import dataset as ds

    _one_thread()
    recipe = ds.Recipe.from_json(recipe_json)
    sources = ds.Sources()
    ratios, gains = [], []
    for i in range(n + 1):
        shot, _ = ds._exposure(recipe, i, sources, "cpu")
        t0 = time.perf_counter()
        shot.frame(0)
        t1 = time.perf_counter()
        ground_truth.truth(shot, recipe.white_threshold_e_per_s)
        t2 = time.perf_counter()
        if i:  # sample 0 compiles
            ratios.append((t2 - t1) / (t1 - t0))
            gains.append(shot.sensor.transfer.gain_dn_per_e)
    r = np.array(ratios)
    return {"samples": n, "median": float(np.median(r)), "mean": float(r.mean()), "max": float(r.max()),
            "max_k_dn_per_e": float(gains[int(r.argmax())])}


def rate(recipe_json: str, n: int, workers: int) -> float:
    if workers == 1:
        ours(recipe_json, [0])  # compile, the sources read
        t0 = time.perf_counter()
        ours(recipe_json, list(range(1, n + 1)))
        return n / (time.perf_counter() - t0)
    with ProcessPoolExecutor(workers) as pool:
        list(pool.map(ours, [recipe_json] * workers, [[0]] * workers))  # each worker warm
        t0 = time.perf_counter()
        list(pool.map(ours, [recipe_json] * workers, [list(range(1 + w, n + 1, workers)) for w in range(workers)]))
        return n / (time.perf_counter() - t0)


def peak_rss_mb(samples: int) -> float:
    code = ("import resource, sys\nfrom cmosnoise.app.cli import run\n"
            f"code = run(['-q', 'dataset', '-n', '{samples}', '--crop', '64', '--camera', 'led', '--out', sys.argv[1]])\n"
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)\n")
    with tempfile.TemporaryDirectory() as tmp:
        r = subprocess.run([sys.executable, "-c", code, os.path.join(tmp, "d")], capture_output=True, text=True,
                           check=True)
    return float(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=40)
    ap.add_argument("--crop", type=int, default=512)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--memory", type=int, default=0, help="also the peak memory of an N-sample set and of N / 10")
    ap.add_argument("--json", help="also write the rows here (docs/readme_numbers.py section dataset_speed)")
    a = ap.parse_args()
    rows = []
    from cmosnoise.app import dataset as ds

    print(f"{a.crop} x {a.crop} samples with truth per second (best of {a.repeats}; {os.cpu_count()} cores)")
    print(f"{'':34s}{'samples/s':>10s}{'per core':>10s}{'x getframes/core':>18s}{'x NumPy ref':>13s}")
    gf = max(getframes_pairs(a.samples, a.crop) for _ in range(a.repeats))
    ref = max(numpy_reference(a.samples, a.crop) for _ in range(a.repeats))
    print(f"{'getframes 2.6.1 pairs (1 process)':34s}{gf:10.1f}{gf:10.1f}{1.0:18.2f}{gf / ref:13.2f}")
    print(f"{'NumPy reference (1 process)':34s}{ref:10.1f}{ref:10.1f}{ref / gf:18.2f}{1.0:13.2f}")
    rows += [{"label": "getframes 2.6.1 pairs", "workers": 1, "per_s": gf},
             {"label": "NumPy reference", "workers": 1, "per_s": ref}]
    for camera in ("led", "sony-imx900"):
        recipe = ds.Recipe(samples=a.samples + 1, crop=(a.crop, a.crop), cameras=(camera,), seed=1).to_json()
        for workers in (1, 2):
            r = max(rate(recipe, a.samples, workers) for _ in range(a.repeats))
            print(f"{f'cmosnoise {camera}, {workers} worker(s)':34s}{r:10.1f}{r / workers:10.1f}"
                  f"{r / workers / gf:18.2f}{r / ref:13.2f}")
            rows.append({"label": f"cmosnoise {camera}", "workers": workers, "per_s": r})
    led = ds.Recipe(samples=a.samples + 1, crop=(a.crop, a.crop), cameras=("led",), seed=1).to_json()
    with ProcessPoolExecutor(1) as pool:  # one thread, in a process of its own
        truth = pool.submit(truth_cost, led, a.samples).result()
    print(f"led truth over its frame, {a.samples} samples: median {truth['median']:.2f}, mean {truth['mean']:.2f}, "
          f"largest {truth['max']:.2f} (K {truth['max_k_dn_per_e']:.1f} DN/e-)")
    if a.memory:
        small, large = peak_rss_mb(a.memory // 10), peak_rss_mb(a.memory)
        print(f"peak memory of cmosnoise dataset, 64 x 64 crops: {a.memory // 10} samples {small:.0f} MB, "
              f"{a.memory} samples {large:.0f} MB")
    if a.json:
        import json
        import platform

        with open(a.json, "w") as fh:
            json.dump({"command": "python benchmarks/bench_dataset.py " + " ".join(sys.argv[1:-2]),
                       "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
                       "crop": a.crop, "samples": a.samples, "rows": rows, "truth_cost": truth,
                       **({"memory": {"samples": [a.memory // 10, a.memory], "peak_mb": [small, large]}}
                          if a.memory else {})}, fh, indent=2)


if __name__ == "__main__":
    main()
