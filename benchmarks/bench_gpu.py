"""The GPU kernel on a real NVIDIA GPU: the CPU kernel's bits, then frames per second.

    python benchmarks/bench_gpu.py [--json results.json] [--quick]

**Bits.** A 1920 x 1080 frame of every preset (and of the default sensor, and
of every stage on) from the GPU equals the CPU kernel's, and 100 frames of the
default sensor made in one batch equal the CPU's frame by frame; the batch
of crops at random corners equals the crops of the whole frames; the frames
handed to PyTorch share the GPU's memory (no copy).

**Speed** at 1920 x 1080 and 3840 x 2160, the default sensor and every stage
on: the GPU kernel alone (a batch of frames made on the device and left
there, timed between two device synchronizations), end to end to host memory
(the batch copied back), the CPU kernel on this machine's cores and the NumPy
reference of benchmarks/bench_chain.py, timed in the same run. And 512 x 512
training crops with their truth: random crops of fresh frames of one
exposure, made in batches on the GPU, with the truth's crops (expected raw,
mask) cut from that exposure's truth, which is made once; and ``cmosnoise
dataset``'s samples with ``--device cuda``, each its own sensor
(``dataset.make_samples``, 64 to a launch): whole samples (their set-up and
truth on the host), and the upload of their plans and the launch alone.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_chain import cpu as cpu_info  # noqa: E402
from bench_chain import numpy_reference  # noqa: E402

from cmosnoise import Sensor, frames_together, load_config  # noqa: E402
from cmosnoise.analysis import ground_truth  # noqa: E402
from cmosnoise.app.compiling import EVERY_STAGE  # noqa: E402
from cmosnoise.config.loading import preset_names  # noqa: E402
from cmosnoise.engine.frame import cuda_kernel, kernel  # noqa: E402

#: every stage on at realistic rates (the tests' EVERY is denser, to meet a 64 x 48 frame): what `cmosnoise compile`
#: warms up, the one definition
EVERY = EVERY_STAGE


def sized(extra: dict | None, width: int, height: int) -> dict:
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in (extra or {}).items()}
    out["sensor"] = {**out.get("sensor", {}), "width": width, "height": height}
    return out


def pair(extra, width, height, preset=None, seed=3):
    cfg = load_config(preset=preset, extra=sized(extra, width, height))
    return Sensor(cfg, seed=seed).expose("photo"), Sensor(cfg, seed=seed, device="cuda").expose("photo")


def check_bits(quick: bool) -> dict:
    out = {}
    cases = [("default", None, None), ("every-stage", EVERY, None)]
    cases += [(name, None, name) for name in preset_names()]
    for name, extra, preset in cases:
        cpu, gpu = pair(extra, 1920, 1080, preset)
        frames = [0, 1, 4_000_000_000]
        raw, e = gpu.frames_on_device(frames, electrons=True)
        raw, e = raw.copy_to_host(), e.copy_to_host()
        same = all(np.array_equal(raw[b], cpu._render(k)[0]) and np.array_equal(e[b], cpu._render(k)[1])
                   for b, k in enumerate(frames))
        out[f"1080p {name}: 3 frames, raw and electrons"] = same
        print(f"bits {name}: {same}", flush=True)
    cpu, gpu = pair(None, 1920, 1080)
    n = 20 if quick else 100
    raw = gpu.frames_on_device(list(range(n)))[0].copy_to_host()
    out[f"1080p default: {n} frames in one batch"] = all(np.array_equal(raw[k], cpu.frame(k)) for k in range(n))
    print(f"bits {n} frames in one batch: {out[f'1080p default: {n} frames in one batch']}", flush=True)
    rng = np.random.default_rng(1)
    corners = np.stack([rng.integers(0, 1080 - 512, 16), rng.integers(0, 1920 - 512, 16)], axis=1)
    frames = rng.integers(0, 1000, 16)
    cpu, gpu = pair(EVERY, 1920, 1080)
    crops = gpu.frames_on_device(frames, region=(0, 512, 0, 512), corners=corners)[0].copy_to_host()
    out["512 x 512 crops of every stage at 16 random corners and frames"] = all(
        np.array_equal(crops[b], cpu.frame(int(k), region=(r, r + 512, c, c + 512)))
        for b, (k, (r, c)) in enumerate(zip(frames, corners)))
    print(f"bits crops: {out['512 x 512 crops of every stage at 16 random corners and frames']}", flush=True)
    # different sensors in one launch: every preset's 512 x 512 sensor, a frame each (the data set's batches)
    shots = [Sensor(load_config(preset=name, extra=sized(None, 512, 512)), seed=11 + q).expose("photo")
             for q, name in enumerate(preset_names())]
    raw = frames_together(shots, frames=list(range(len(shots))))[0].copy_to_host()
    key = f"512 x 512: {len(shots)} presets' sensors in one launch"
    out[key] = all(
        np.array_equal(raw[b], shot.frame(b)) for b, shot in enumerate(shots))
    print(f"bits {key}: {out[key]}", flush=True)
    try:
        import torch

        raw = gpu.frames_on_device([0, 1])[0]
        t = cuda_kernel.to_torch(raw)
        out["torch tensor shares the frames' memory"] = (t.data_ptr() == raw.__cuda_array_interface__["data"][0]
                                                         and t.is_cuda and tuple(t.shape) == raw.shape)
        mean = torch.as_tensor(gpu.plan().noisy_e, device="cuda")
        again = gpu.device_plan().with_means(noisy_e=mean).render([0, 1])[0].copy_to_host()
        out["a torch tensor as the mean charge gives the same frames"] = bool(np.array_equal(again, raw.copy_to_host()))
    except ImportError:
        out["torch"] = "not installed"
    return out


def timed(fn, repeats: int) -> float:
    """Median seconds of ``fn()`` over ``repeats`` calls, after one warm-up."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def speed(width: int, height: int, name: str, extra, batch: int, repeats: int) -> dict:
    cuda = cuda_kernel.kernels().cuda
    cpu, gpu = pair(extra, width, height)
    plan = gpu.device_plan()
    frames = iter(range(10**9))

    def kernel_alone():
        plan.render([next(frames) for _ in range(batch)])
        cuda.synchronize()

    def to_host():
        raw, _ = plan.render([next(frames) for _ in range(batch)])
        raw.copy_to_host()

    t_gpu = timed(kernel_alone, repeats) / batch
    t_host = timed(to_host, repeats) / batch
    cpu_plan = cpu.plan()
    t_cpu = timed(lambda: kernel.render(cpu_plan, next(frames)), 3)
    reference = numpy_reference(cpu.photo_mean_e, cpu.sensor.transfer.gain_dn_per_e)
    t_ref = timed(lambda: reference(0), 3)
    row = {"size": f"{width} x {height}", "sensor": name, "batch": batch,
           "gpu_kernel_fps": 1 / t_gpu, "gpu_to_host_fps": 1 / t_host, "cpu_kernel_fps": 1 / t_cpu,
           "numpy_reference_fps": 1 / t_ref, "gpu_over_cpu": t_cpu / t_gpu,
           "gpu_pixels_per_s": width * height / t_gpu, "device_plan_mb": plan.nbytes() / 2**20}
    print(json.dumps(row), flush=True)
    return row


def blocks(repeats: int) -> list[dict]:
    """The pixel kernel's threads per block against its speed (1080p, default sensor), and its registers."""
    cuda = cuda_kernel.kernels().cuda
    _, gpu = pair(None, 1920, 1080)
    plan = gpu.device_plan()
    rows = []
    for block in (64, 128, 256, 512):
        plan.block = block

        def run():
            plan.render(list(range(32)))
            cuda.synchronize()

        rows.append({"block": block, "gpu_kernel_fps": 32 / timed(run, repeats)})
    plan.block = cuda_kernel.BLOCK
    regs = cuda_kernel.kernels().pixels.get_regs_per_thread()  # {signature: registers}, or one number
    regs = max(regs.values()) if isinstance(regs, dict) else regs
    for r in rows:
        r["registers"] = regs
        print(json.dumps(r), flush=True)
    return rows


def training_crops(name: str, extra, batch: int, repeats: int) -> dict:
    """512 x 512 crops with truth per second: fresh frames of one exposure at random corners, in batches."""
    cuda = cuda_kernel.kernels().cuda
    cpu, gpu = pair(extra, 3840, 2160)
    t0 = time.perf_counter()
    truth = ground_truth.truth(cpu)
    t_truth = time.perf_counter() - t0
    expected = cuda.to_device(np.ascontiguousarray(truth.expected_raw.astype(np.float32)))
    mask = cuda.to_device(np.ascontiguousarray(truth.mask))
    plan = gpu.device_plan()
    rng = np.random.default_rng(0)
    frames = iter(range(10**9))

    def one_batch():
        corners = np.stack([rng.integers(0, 2160 - 512, batch) & ~1, rng.integers(0, 3840 - 512, batch) & ~1], axis=1)
        raw, _ = plan.render([next(frames) for _ in range(batch)], corners, (512, 512))
        # the truth's crops at the same corners, one launch each: (batch, 512, 512) on the device
        truths = cuda_kernel.crops(expected, corners, (512, 512)), cuda_kernel.crops(mask, corners, (512, 512))
        cuda.synchronize()
        return raw, truths

    t = timed(one_batch, repeats) / batch
    row = {"what": f"512 x 512 crops with truth ({name}, one 3840 x 2160 exposure)", "batch": batch,
           "samples_per_s": 1 / t, "truth_once_s": t_truth}
    print(json.dumps(row), flush=True)
    return row


def dataset_samples(camera: str, batch: int, repeats: int, crop: int = 512) -> dict:
    """``cmosnoise dataset``'s samples with ``--device cuda``: each its own sensor (camera, gain, seed, scene), set
    up and its truth made on the host, the frames of ``batch`` of them in one launch (dataset.make_samples); and,
    of that, the upload of their plans and the launch alone."""
    from cmosnoise.app import dataset as ds

    cuda = cuda_kernel.kernels().cuda
    recipe = ds.Recipe(samples=ds.MAX_SAMPLES, crop=(crop, crop), cameras=(camera,), seed=1)
    sources = ds.Sources()
    starts = iter(range(0, ds.MAX_SAMPLES, batch))

    def whole():
        s = next(starts)
        ds.make_samples(recipe, range(s, s + batch), sources, device="cuda")

    t_whole = timed(whole, repeats) / batch
    shots = [ds._exposure(recipe, i, sources, "cuda")[0] for i in range(batch)]
    plans, stuck = [s.plan() for s in shots], [s.stuck_pixels() for s in shots]
    t_upload = timed(lambda: cuda_kernel.DevicePlan(plans, stuck), repeats) / batch
    plan = cuda_kernel.DevicePlan(plans, stuck)

    def launch():
        plan.render([0] * batch)
        cuda.synchronize()

    t_launch = timed(launch, repeats) / batch
    parts = sample_parts(recipe, sources, batch, repeats)
    # the same samples on this machine's CPU, in the same run: one process, then the per-sample rate times the
    # cores (the data set's --workers runs one process a core; its shards share nothing)
    cpu_starts = iter(range(0, ds.MAX_SAMPLES, 8))

    def cpu_whole():
        s = next(cpu_starts)
        ds.make_samples(recipe, range(s, s + 8), sources, device="cpu")

    t_cpu = timed(cpu_whole, max(2, repeats // 3)) / 8
    cores = os.cpu_count() or 1
    row = {"what": f"{crop} x {crop} data set samples ({camera}: a sensor each), launches of {batch}",
           "batch": batch, "samples_per_s": 1 / t_whole, "upload_per_s": 1 / t_upload,
           "launch_per_s": 1 / t_launch, "cpu_samples_per_s_one_process": 1 / t_cpu,
           "cpu_samples_per_s_all_cores": cores / t_cpu, "cores": cores,
           "gpu_over_cpu_one_process": t_cpu / t_whole, "gpu_over_cpu_all_cores": t_cpu / (cores * t_whole),
           "ms_per_sample": parts}
    print(json.dumps(row), flush=True)
    return row


def sample_parts(recipe, sources, batch: int, repeats: int) -> dict:
    """Where a GPU data set sample's time goes, in ms a sample (median over ``repeats`` batches of ``batch``):
    the host's set-up (settings, sensor, maps, the crop exposed), the plans' upload, the launch, the copy back,
    and the truth (perfect image, expected raw, mask) with the sample's columns, made on the host."""
    from cmosnoise.app import dataset as ds

    cuda = cuda_kernel.kernels().cuda
    starts = iter(range(10**6, ds.MAX_SAMPLES, batch))
    times = {"set_up": [], "upload": [], "launch": [], "copy_back": [], "truth": []}
    for _ in range(repeats + 1):
        s = next(starts)
        t0 = time.perf_counter()
        made = [ds._exposure(recipe, i, sources, "cuda") for i in range(s, s + batch)]
        t1 = time.perf_counter()
        plan = cuda_kernel.DevicePlan([shot.plan() for shot, _ in made], [shot.stuck_pixels() for shot, _ in made])
        cuda.synchronize()
        t2 = time.perf_counter()
        raw, _ = plan.render(list(range(batch)))
        cuda.synchronize()
        t3 = time.perf_counter()
        raws = raw.copy_to_host()
        t4 = time.perf_counter()
        for b, (shot, st) in enumerate(made):
            ds._finish(recipe, shot, st, raws[b])
        t5 = time.perf_counter()
        for key, a, b in (("set_up", t0, t1), ("upload", t1, t2), ("launch", t2, t3), ("copy_back", t3, t4),
                          ("truth", t4, t5)):
            times[key].append((b - a) / batch * 1e3)
    return {key: float(np.median(v[1:])) for key, v in times.items()}  # the first batch compiles: left out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="also write the results here")
    ap.add_argument("--quick", action="store_true", help="fewer frames and repeats")
    ap.add_argument("--skip-bits", action="store_true")
    ap.add_argument("--only-training", action="store_true", help="the training crops alone")
    ap.add_argument("--only-dataset", action="store_true", help="the data set's samples alone (GPU and CPU)")
    a = ap.parse_args()
    cuda_kernel.check()
    import numba

    doc = {"device": cuda_kernel.describe(), "host": {**cpu_info(), "cores": os.cpu_count(),
                                                       "python": platform.python_version()},
           "numba_cuda": getattr(__import__("numba.cuda", fromlist=["x"]), "__version__", None) or _version("numba-cuda"),
           "numba": numba.__version__}
    print(json.dumps(doc), flush=True)
    repeats = 3 if a.quick else 10
    if a.only_training:
        for row in (training_crops("default", None, 256, repeats), training_crops("every stage", EVERY, 256, repeats)):
            print(f"{row['what']}: {row['samples_per_s']:.0f} / s")
        for camera in ("led", "sony-imx900"):
            row = dataset_samples(camera, 64, repeats)
            print(f"{row['what']}: {row['samples_per_s']:.0f} / s (plans uploaded {row['upload_per_s']:.0f} / s, "
                  f"frames made {row['launch_per_s']:.0f} / s)")
        return
    if a.only_dataset:
        doc["dataset"] = [dataset_samples(camera, 64, repeats) for camera in ("led", "sony-imx900")]
        if a.json:
            a.json.write_text(json.dumps(doc, indent=1))
        return
    def save():  # after every section: a run cut by a time limit keeps what it measured
        if a.json:
            a.json.write_text(json.dumps(doc, indent=1))

    t0 = time.perf_counter()
    doc["bits"] = {} if a.skip_bits else check_bits(a.quick)
    doc["bits_s"] = time.perf_counter() - t0
    save()
    doc["speed"] = []
    for args in ((1920, 1080, "default", None, 32), (1920, 1080, "every stage", EVERY, 32),
                 (3840, 2160, "default", None, 8), (3840, 2160, "every stage", EVERY, 8)):
        doc["speed"].append(speed(*args, repeats))
        save()
    doc["blocks"] = blocks(repeats)
    doc["training"] = [training_crops("default", None, 256, repeats), training_crops("every stage", EVERY, 256, repeats)]
    save()
    doc["dataset"] = [dataset_samples(camera, 64, repeats) for camera in ("led", "sony-imx900")]
    save()
    print("\nbits:", "all equal" if all(v is True for v in doc["bits"].values()) else doc["bits"], list(doc["bits"]))
    print(f"{'size':>12} {'sensor':>12} {'GPU kernel':>11} {'GPU->host':>10} {'CPU kernel':>11} {'NumPy ref':>10}")
    for r in doc["speed"]:
        print(f"{r['size']:>12} {r['sensor']:>12} {r['gpu_kernel_fps']:>11.0f} {r['gpu_to_host_fps']:>10.0f} "
              f"{r['cpu_kernel_fps']:>11.1f} {r['numpy_reference_fps']:>10.1f}")
    for r in doc["training"]:
        print(f"{r['what']}: {r['samples_per_s']:.0f} / s")
    for r in doc["dataset"]:
        print(f"{r['what']}: {r['samples_per_s']:.0f} / s on the GPU, {r['cpu_samples_per_s_one_process']:.1f} / s "
              f"in one CPU process ({r['cpu_samples_per_s_all_cores']:.0f} / s on {r['cores']} cores); ms a sample: "
              + ", ".join(f"{k} {v:.2f}" for k, v in r["ms_per_sample"].items()))
    print("threads per block:", ", ".join(f"{r['block']}: {r['gpu_kernel_fps']:.0f} fps" for r in doc["blocks"]),
          f"({doc['blocks'][0]['registers']} registers a thread)")


def _version(name: str):
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


if __name__ == "__main__":
    main()
