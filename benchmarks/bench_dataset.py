"""Training samples with their truth per CPU-second, next to getframes 2.6.1's pair generator and a NumPy
Poisson-Gaussian synthesis of the same crops, and the memory of a large set.

    python benchmarks/bench_dataset.py [--samples 40] [--crop 256 512] [--repeats 3] [--memory 10000]
    python benchmarks/bench_dataset.py --phases [--crop 256]   # where a sample's time goes

Every rate is samples per CPU-second (``time.process_time`` of each process
that makes them, summed over the workers), each at its best of the repeats,
all timed in one run. The repeats are interleaved (each times every row
once), and each ratio is the median, with its range, of the repeats' own
ratios to the references timed in the same repeat: on a shared machine a
rate moves by a third between runs, and a ratio of two rates measured
minutes apart moves less.

Each sample is a crop as ``cmosnoise dataset`` makes it (``make_sample``): its
own sensor instance (set-up), one noisy frame, and its truth (expected raw,
perfect image, defect mask); writing the shards is timed separately, end to
end with ``cmosnoise dataset``. Cameras: ``led`` (LED's virtual cameras:
shot noise, Tukey-lambda read noise, row noise, black-level offsets, as the
learned-denoising literature) and ``sony-imx900`` (the whole chain: PRNU,
dark current, source follower, pixel offsets, nonlinearity). One worker is
this process's child on one thread (``numba.set_num_threads(1)``); two
workers are two processes of one thread each, the samples split between
them. The source images are read in the warm-up call that compiles the
kernel, as ``cmosnoise dataset`` reads them once for all the shards a
process makes; the warm-up also makes one sample (past the timed ones) of
each camera and gain the timed samples use, as a data set's first samples
do: a gain row's set-up is made once a process (its nonlinearity solved, its
template validated) and shared by every later sample of that row. What it
costs is printed apart (``set-up a camera and gain``: the first sample of a
gain row against a later one's median), once a process and row: 2 x 50 ms
over a data set of thousands of samples, but a third of a 20-sample run.

Beside them, in the same run:

- the NumPy reference, the ten-line script the field writes, on **the same
  crops** of each camera's samples (the same source image, corner, light and
  K, read from the samples' settings before the clock starts): the crop
  sliced from the linear source, mosaicked through the CFA, a Poisson draw
  of its electrons, Gaussian read noise of 2 e-, the sample's K and black
  level, rounding and the white-level clip to uint16, and the mean
  (float32) as its truth;
- getframes 2.6.1, ``getframes.dataset.pairs`` on its ``zwo_asi2600mm``
  preset cut to the crop (``precision="float32"``), random star fields: a
  raw frame and its truth (the noise-free electrons) per pair.

The truth's cost is also given alone: each led sample's truth over its own
noisy frame (one thread), their median, mean and largest ratio.

``--memory N`` also makes an N-sample set (64 x 64 crops, hdf5) with
``cmosnoise dataset`` in a child process, and one of N / 10 samples, and
prints both peak resident sizes: flat in N when the shards stream.
"""

from __future__ import annotations

import argparse
import multiprocessing
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


#: every worker forked from a fresh interpreter (a fork server that has imported cmosnoise and made nothing): a
#: worker forked from this process would inherit its caches, filled by the reference's samples (same_crops makes
#: the very samples timed: their gain rows solved, their sections' YAML); a spawned one pays the imports each
#: time (some 3 s: 9 of them made the suite's smallest run 34 s)
_FRESH = multiprocessing.get_context("forkserver")
_FRESH.set_forkserver_preload(["cmosnoise.app.dataset", "cmosnoise.analysis.ground_truth"])

_SOURCES: dict = {}  # this process's source images, read at its first call (as one dataset run reads them once)


def ours(recipe_json: str, indices: list[int]) -> tuple[int, float]:
    """Samples ``indices`` of the recipe, made here: (how many, the CPU-seconds they took)."""
    from cmosnoise.app import dataset as ds

    _one_thread()
    recipe = ds.Recipe.from_json(recipe_json)
    sources = _SOURCES.setdefault(recipe_json, ds.Sources())
    for source in recipe.sources:  # every source read once per process, before the clock (as a dataset run)
        sources.image(source, ds.builtin_shape(recipe.crop))
    t0 = time.process_time()
    for i in indices:
        ds.make_sample(recipe, i, sources)
    return len(indices), time.process_time() - t0


def _gain_key(columns: dict) -> tuple:
    """A sample's camera and gain (its row of the gain table), as text: what its set-up is shared by."""
    return tuple(str(columns[k]) for k in ("camera", "mode", "iso", "gain_db"))


def warm_indices(recipe_json: str, n: int, look: int = 400) -> list[int]:
    """One sample past samples 1 to n (n + 1 onwards) of each camera and gain those samples use but sample 0
    does not: made before the clock, they set up each gain row as a data set's first samples do, without warming
    the timed samples' own values."""
    from cmosnoise.app import dataset as ds

    recipe = ds.Recipe.from_json(recipe_json)
    sources = _SOURCES.setdefault(recipe_json, ds.Sources())
    wanted = ({_gain_key(ds.settings(recipe, i, sources).columns) for i in range(1, n + 1)}
              - {_gain_key(ds.settings(recipe, 0, sources).columns)})
    out = []
    for i in range(n + 1, n + 1 + look):
        key = _gain_key(ds.settings(recipe, i, sources).columns)
        if key in wanted:
            out.append(i)
            wanted.discard(key)
        if not wanted:
            break
    return out


def warm(recipe_json: str, n: int) -> list[float]:
    """This process warm: sample 0 (compiled, sources read), then one sample of each further camera and gain
    of samples 1 to n (:func:`warm_indices`); the CPU-seconds of each of those."""
    ours(recipe_json, [0])
    return [ours(recipe_json, [i])[1] for i in warm_indices(recipe_json, n)]


def setup_ms(recipe_json: str, n: int) -> float | None:
    """What setting up a camera and gain costs, ms, in a fresh process of one thread: the first sample of each
    gain row after sample 0's against the median of the next samples (samples 1 to n); None where they use no
    other (led's virtual cameras have no gain table)."""
    firsts = warm(recipe_json, n)
    if not firsts:
        return None
    later = [ours(recipe_json, [i])[1] for i in range(1, n + 1)]
    return float(np.median(firsts) - np.median(later)) * 1e3


def getframes_pairs(n: int, crop: int) -> float:
    """getframes' pairs per CPU-second."""
    import getframes as gf

    cam = gf.Camera.from_preset("zwo_asi2600mm", precision="float32").with_config(resolution=(crop, crop))
    scenes = gf.dataset.random_star_fields(n=n + 1, shape=cam.resolution, seed=0)
    it = iter(gf.dataset.pairs(camera=cam, scenes=scenes, exposure=1.0, seed=1))
    next(it)  # its first pair pays for the set-up
    t0 = time.process_time()
    for _ in it:
        pass
    return n / (time.process_time() - t0)


def same_crops(recipe_json: str, n: int) -> list[dict]:
    """What the NumPy reference needs of samples 1 to n, read before its clock starts: each crop's source image,
    corner, CFA channel map, light (e- at the white), K, black and white levels."""
    from cmosnoise.app import dataset as ds
    from cmosnoise.model import cfa as cfa_mod

    recipe = ds.Recipe.from_json(recipe_json)
    sources = ds.Sources()
    out = []
    for i in range(1, n + 1):
        st = ds.settings(recipe, i, sources)
        arrays, c = ds.make_sample(recipe, i, sources)
        img = sources.image(c["source"], ds.builtin_shape(recipe.crop))
        h, w = recipe.crop
        channel = cfa_mod.channel_map(c["cfa"], (h, w)).astype(np.intp)  # mono: the green
        out.append({"img": img, "row": c["window_row"], "col": c["window_col"], "shape": (h, w),
                    "channel": channel, "light": c["light_e"], "k": c["k_dn_per_e"],
                    "black": c["black_level_dn"], "white": c["white_level_dn"], "seed": st.columns["seed"]})
    return out


def numpy_reference(crops: list[dict]) -> float:
    """The ten-line Poisson-Gaussian script on the same crops: samples per CPU-second."""
    rng = np.random.default_rng(0)
    t0 = time.process_time()
    for s in crops:
        (h, w), r, c = s["shape"], s["row"], s["col"]
        crop = s["img"][r:r + h, c:c + w]
        mosaic = crop if crop.ndim == 2 else np.take_along_axis(crop, s["channel"][..., None], 2)[..., 0]
        electrons = mosaic * s["light"]
        noisy = rng.poisson(electrons) + rng.normal(0.0, 2.0, electrons.shape)
        raw = np.clip(np.rint(noisy * s["k"] + s["black"]), 0, s["white"]).astype(np.uint16)
        truth = (electrons * s["k"] + s["black"]).astype(np.float32)
        del raw, truth
    return len(crops) / (time.process_time() - t0)


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


def phases(recipe_json: str, n: int) -> dict:
    """Where a sample's time goes, one thread, ms a sample over samples 1 to n (each warm): its settings and
    configuration, its sensor (resolved, its maps drawn), the crop through the CFA, the exposure, the frame, the
    truth and the configuration's YAML (the shard's column)."""
    from cmosnoise.analysis import ground_truth
    from cmosnoise.app import dataset as ds
    from cmosnoise.model import scene as scene_mod
    from cmosnoise.model.sensor import Sensor

    recipe = ds.Recipe.from_json(recipe_json)
    warm(recipe_json, n)  # compiled, every source read, each camera and gain set up (as the rates' workers)
    sources = _SOURCES[recipe_json]
    spent: dict = {}

    def tick(name, t0):
        t = time.perf_counter()
        spent[name] = spent.get(name, 0.0) + t - t0
        return t

    for i in range(1, n + 1):
        t = time.perf_counter()
        st = ds.settings(recipe, i, sources)
        t = tick("settings", t)
        c = st.config
        sensor = Sensor(c)
        t = tick("sensor", t)
        size = tuple(c.scene.source_size or (ds.BUILTIN_SIZE, ds.BUILTIN_SIZE))
        img = scene_mod.window_cfa(sources.image(c.scene.source, size), tuple(c.scene.window), sensor.shape,
                                   sensor.cfa, sensor.spec.channel_responsivity)
        t = tick("crop through the CFA", t)
        shot = sensor.expose(img)
        t = tick("exposure", t)
        shot.frame(0)
        t = tick("frame", t)
        ground_truth.truth(shot, recipe.white_threshold_e_per_s)
        t = tick("truth", t)
        c.to_yaml()
        tick("configuration's YAML", t)
    return {k: v / n * 1e3 for k, v in spent.items()}


def rate(recipe_json: str, n: int, workers: int) -> float:
    """Samples 1 to n per CPU-second, made by ``workers`` processes of one thread each (each warm first)."""
    # each worker warm as it starts: compiled, sources read, each camera and gain set up (as a data set's first
    # samples)
    with ProcessPoolExecutor(workers, mp_context=_FRESH, initializer=warm,
                             initargs=(recipe_json, n)) as pool:
        done = list(pool.map(ours, [recipe_json] * workers,
                             [list(range(1 + w, n + 1, workers)) for w in range(workers)]))
    return sum(k for k, _ in done) / sum(t for _, t in done)


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
    ap.add_argument("--crop", type=int, nargs="+", default=[256, 512], help="crop sides, pixels")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--memory", type=int, default=0, help="also the peak memory of an N-sample set and of N / 10")
    ap.add_argument("--json", help="also write the rows here (docs/readme_numbers.py section dataset_speed)")
    ap.add_argument("--phases", action="store_true", help="only where a sample's time goes, per camera and crop")
    a = ap.parse_args()
    if a.phases:
        from cmosnoise.app import dataset as ds

        for crop in a.crop:
            for camera in ("led", "sony-imx900"):
                recipe = ds.Recipe(samples=a.samples + 1, crop=(crop, crop), cameras=(camera,), seed=1).to_json()
                with ProcessPoolExecutor(1, mp_context=_FRESH) as pool:  # one thread, in a process of its own
                    ms = pool.submit(phases, recipe, a.samples).result()
                print(f"{crop} x {crop} {camera}, ms a sample: " + ", ".join(f"{k} {v:.2f}" for k, v in ms.items())
                      + f"; total {sum(ms.values()):.2f}")
        return
    rows: list = []
    setups: dict = {}
    from cmosnoise.app import dataset as ds

    print(f"samples with truth per CPU-second, the best of {a.repeats} repeats; against NumPy and getframes: the "
          f"median (and range) of each repeat's ratio to the references timed just before it; {os.cpu_count()} cores")
    print(f"{'':42s}{'per CPU-s':>10s}{'x NumPy, same crops':>24s}{'x getframes':>24s}")

    def row(crop, label, workers, rates, numpy, gf):
        """A row: the best rate; each repeat's ratio to the references of that repeat (median, least, most)."""
        out = {"crop": crop, "label": label, "workers": workers, "per_cpu_s": max(rates)}
        for key, ref in (("against_numpy", numpy), ("against_getframes", gf)):
            paired = None if ref is None else [r / q for r, q in zip(rates, ref)]
            out[key] = None if paired is None else float(np.median(paired))
            out[key + "_range"] = None if paired is None else [min(paired), max(paired)]
        shown = ["" if out[k] is None else f"{out[k]:.2f} ({out[k + '_range'][0]:.2f}-{out[k + '_range'][1]:.2f})"
                 for k in ("against_numpy", "against_getframes")]
        named = label if label.startswith(("getframes", "NumPy")) else f"{label}, {workers} worker(s)"
        print(f"{f'{crop} x {crop}: {named}':42s}{out['per_cpu_s']:10.1f}{shown[0]:>24s}"
              f"{shown[1]:>24s}")
        rows.append(out)

    for crop in a.crop:
        recipes, crops = {}, {}
        for camera in ("led", "sony-imx900"):
            recipes[camera] = ds.Recipe(samples=a.samples + 1, crop=(crop, crop), cameras=(camera,),
                                        seed=1).to_json()
            crops[camera] = same_crops(recipes[camera], a.samples)
            with ProcessPoolExecutor(1, mp_context=_FRESH) as pool:  # one thread, in a fresh process of its own
                setup = pool.submit(setup_ms, recipes[camera], a.samples).result()
            shown = "no further gain row" if setup is None else f"{setup:8.1f} ms, once a process and gain row"
            print(f"{f'{crop} x {crop}: {camera} set-up a camera and gain':42s}{shown}")
            setups[f"{crop} {camera}"] = setup
        # the repeats interleaved: each times getframes, then per camera the NumPy script and our one and two
        # workers, so that a ratio compares rates measured minutes apart at most, not a whole run apart (the
        # machine's speed drifts by a third between runs)
        gf: list = []
        ref: dict = {camera: [] for camera in recipes}
        ours_r: dict = {(camera, w): [] for camera in recipes for w in (1, 2)}
        for _ in range(a.repeats):
            gf.append(getframes_pairs(a.samples, crop))
            for camera, recipe in recipes.items():
                ref[camera].append(numpy_reference(crops[camera]))
                for workers in (1, 2):
                    ours_r[camera, workers].append(rate(recipe, a.samples, workers))
        row(crop, "getframes 2.6.1 pairs", 1, gf, None, gf)
        for camera in recipes:
            row(crop, f"NumPy reference, {camera}'s crops", 1, ref[camera], ref[camera], gf)
            for workers in (1, 2):
                row(crop, f"cmosnoise {camera}", workers, ours_r[camera, workers], ref[camera], gf)
    led = ds.Recipe(samples=a.samples + 1, crop=(a.crop[0], a.crop[0]), cameras=("led",), seed=1).to_json()
    with ProcessPoolExecutor(1, mp_context=_FRESH) as pool:  # one thread, in a process of its own
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
                       "crops": a.crop, "samples": a.samples, "repeats": a.repeats, "rows": rows, "setup_ms": setups, "truth_cost": truth,
                       **({"memory": {"samples": [a.memory // 10, a.memory], "peak_mb": [small, large]}}
                          if a.memory else {})}, fh, indent=2)


if __name__ == "__main__":
    main()
