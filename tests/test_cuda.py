"""The frame kernel on the GPU (engine/frame/cuda_kernel): the CPU kernel's bits, every stage, crops and batches.

Where no GPU is present (CI), numba's CUDA simulator runs the same kernel source (conftest sets
NUMBA_ENABLE_CUDASIM before numba is imported), so small frames: the simulator runs each pixel as Python.
CMOSNOISE_TEST_GPU=1 runs the same tests on a real GPU, at 1920 x 1080 (benchmarks/gpu_check.py adds every
preset at 1080p, 100 frames, and the speed).
"""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import cli

from cmosnoise import Sensor, load_config
from cmosnoise.engine.frame import cuda_kernel
from cmosnoise.errors import CmosnoiseError

SIMULATED = cuda_kernel.simulated()
#: frame size: small in the simulator (each pixel of a frame some 10 to 30 ms of Python there), 1080p on a GPU
WIDTH, HEIGHT = (48, 32) if SIMULATED else (1920, 1080)

#: every stage on, each population dense enough to meet a 48 x 32 frame many times
EVERY = {"sensor": {"frame_rate_hz": 30}, "column_noise": {"gain_sigma_pct": 1.0}, "row_noise": {"fixed_sigma_e": 0.5},
         "pixel_offset": {"enabled": True, "sigma_e": 4.0, "tail": {"ppm_above": 20000, "threshold_e": 20, "max_e": 200}},
         "nonlinearity": {"enabled": True, "linearity_error_pct": [-1.2, 0.6]},
         "black_level": {"channel_offsets_dn": [1.5, -0.5, 0.25, 2.0], "frame_sigma_dn": 0.3},
         "read_noise": {"enabled": True, "distribution": "tukey_lambda", "scale_dn": 1.2, "shape": -0.05},
         "source_follower": {"rts": {"enabled": True, "ppm": 30000, "traps_per_pixel": "poisson",
                                     "tau_capture_s": {"min_s": 1e-6, "max_s": 1e-3},
                                     "tau_emission_s": {"min_s": 1e-6, "max_s": 1e-3}}},
         "dark_current": {"rts": {"enabled": True, "ppm": 30000, "tau_low_s": {"min_s": 0.05, "max_s": 5},
                                  "tau_high_s": {"min_s": 0.05, "max_s": 5}}},
         "defects": {"enabled": True, "dead_ppm": 5000, "stuck_ppm": 5000, "low_gain_ppm": 5000,
                     "high_gain_ppm": 5000, "clusters": {"ppm": 2000},
                     "columns": {"offset_ppm": 20000, "gain_ppm": 20000, "stuck_ppm": 20000},
                     "rows": {"offset_ppm": 20000, "gain_ppm": 20000, "stuck_ppm": 20000}}}


def _merged(*parts: dict) -> dict:
    out: dict = {}
    for part in parts:
        for k, v in part.items():
            out[k] = {**out.get(k, {}), **v} if isinstance(v, dict) else v
    return out


def _pair(config: dict | None = None, preset: str | None = None, seed: int = 5, scene: str = "photo"):
    """The same exposure on the CPU and on the GPU."""
    size = {"sensor": {"width": WIDTH, "height": HEIGHT}}
    cfg = load_config(preset=preset, extra=_merged(config or {}, size))
    return (Sensor(cfg, seed=seed).expose(scene), Sensor(cfg, seed=seed, device="cuda").expose(scene))


VARIANTS = {
    "every-stage": EVERY,
    # the blinking pixels' dark charge without shot noise, a measured nonlinearity table, the normal approximation
    "exact-dark-table-normal": _merged(EVERY, {"dark_current": {"shot_noise": False},
                                               "nonlinearity": {"linearity_error_pct": None,
                                                                "curve_e": [[0, 0], [3000, 2950], [9000, 8500],
                                                                            [20000, 18000]]},
                                               "shot_noise": {"gaussian_above_e": 200.0},
                                               "read_noise": {"distribution": "normal"}}),
    "adc-off": _merged(EVERY, {"adc": {"enabled": False}}),
}


@pytest.mark.parametrize("name", list(VARIANTS))
@pytest.mark.gpu
def test_every_stage_on_equals_the_cpu_kernel_bit_for_bit_with_electrons_and_far_frames(name):
    cpu, gpu = _pair(VARIANTS[name])
    frames = [0, 1_000_000] if SIMULATED else list(range(8)) + [4_000_000_000]
    raw, electrons = gpu.frames_on_device(frames, electrons=True)
    raw, electrons = raw.copy_to_host(), electrons.copy_to_host()
    fp = cpu.sensor.fixed_pattern
    assert fp.traps.index.size > 20 and fp.blinkers.index.size > 20 and fp.defects.has_stuck  # each one met
    for b, k in enumerate(frames):
        expected, expected_e = cpu._render(k)  # the CPU kernel, stuck pixels set
        np.testing.assert_array_equal(raw[b], expected, err_msg=f"frame {k}")
        np.testing.assert_array_equal(electrons[b], expected_e, err_msg=f"frame {k}")


@pytest.mark.parametrize("preset", ["sony-a7s2", "sony-imx900", "sony-imx571", "paper-fig11-full", "zwo-asi294mm", None])
@pytest.mark.gpu
def test_each_preset_equals_the_cpu_kernel(preset):
    cpu, gpu = _pair(preset=preset, seed=9)
    for k in (0, 2):
        np.testing.assert_array_equal(gpu.frame(k), cpu.frame(k), err_msg=f"{preset} frame {k}")


@pytest.mark.parametrize("kind", ["normal", "tukey_lambda"])
@pytest.mark.gpu
def test_read_noise_without_the_source_follower_equals_the_cpu_kernel(kind):
    """Read noise after the gain takes the sine normal of the source follower's block: with that stage off the
    block is still drawn, on either device."""
    cpu, gpu = _pair({"source_follower": {"enabled": False},
                      "read_noise": {"enabled": True, "distribution": kind, "scale_dn": 1.7, "shape": -0.2}}, seed=4)
    for k in (0, 5):
        np.testing.assert_array_equal(gpu.frame(k), cpu.frame(k), err_msg=f"{kind} frame {k}")


@pytest.mark.gpu
def test_a_batch_of_crops_at_different_corners_equals_the_crops_of_the_whole_frames():
    cpu, gpu = _pair(EVERY, seed=7)
    h, w = HEIGHT // 2, WIDTH // 3
    corners = [(0, 0), (HEIGHT - h, WIDTH - w), (HEIGHT // 3, WIDTH // 2 - 1), (1, 1)]
    frames = [4, 4, 9, 2]
    raw, _ = gpu.frames_on_device(frames, region=(0, h, 0, w), corners=corners)
    raw = raw.copy_to_host()
    for b, ((r, c), k) in enumerate(zip(corners, frames)):
        np.testing.assert_array_equal(raw[b], cpu.frame(k)[r:r + h, c:c + w], err_msg=f"item {b}")
    # a region through frame(): the same bits as the CPU's region
    np.testing.assert_array_equal(gpu.frame(9, region=(3, h + 3, 5, w + 5)), cpu.frame(9, region=(3, h + 3, 5, w + 5)))


@pytest.mark.gpu
def test_a_batch_of_different_sensors_in_one_launch_equals_each_sensors_own_frames():
    """#31: crops from different samples (each its own sensor: presets, stages, populations, tables and seeds
    differ) in one launch; each item is its plan's frame bit for bit, whatever the other plans hold."""
    from cmosnoise import frames_together

    size = {"sensor": {"width": WIDTH, "height": HEIGHT}}
    # plans are made on the host (a GPU sensor's maps are the CPU's bits), so the CPU's exposures give them
    cpus = [Sensor(load_config(preset=preset, extra=_merged(config, size)), seed=seed).expose("photo")
            for config, preset, seed in
            [(EVERY, None, 7),  # traps, blinking and stuck pixels, Tukey-lambda read noise, the cubic
             (VARIANTS["exact-dark-table-normal"], None, 8),  # a curve table, normal read noise
             ({}, "sony-imx900", 9),  # no populations at all
             ({}, "paper-fig11-full", 10)]]
    plan = cuda_kernel.DevicePlan([c.plan() for c in cpus], [c.stuck_pixels() for c in cpus])
    which, frames = [3, 0, 2, 1, 0, 2], [1, 4, 0, 2, 4_000_000_000, 5]
    h, w = HEIGHT // 2, WIDTH // 2
    corners = [(0, 0), (HEIGHT - h, WIDTH - w), (3, 5), (1, 2), (2, 4), (HEIGHT // 3, WIDTH // 4)]
    raw, electrons = plan.render(frames, corners, (h, w), electrons=True, plans=which)
    raw, electrons = raw.copy_to_host(), electrons.copy_to_host()
    for b, (q, k, (r, c)) in enumerate(zip(which, frames, corners)):
        expected, expected_e = cpus[q]._render(k)
        np.testing.assert_array_equal(raw[b], expected[r:r + h, c:c + w], err_msg=f"item {b}, plan {q}")
        np.testing.assert_array_equal(electrons[b], expected_e[r:r + h, c:c + w], err_msg=f"item {b}, plan {q}")
    # the model's entry: one frame of each exposure, whole (two of them: the simulator is slow)
    raw, _ = frames_together([cpus[2], cpus[0]], frames=[6, 0])
    for b, (cpu, k) in enumerate(zip([cpus[2], cpus[0]], [6, 0])):
        np.testing.assert_array_equal(raw.copy_to_host()[b], cpu.frame(k), err_msg=f"exposure {b}")


@pytest.mark.slow
def test_plans_of_one_batch_must_share_a_shape_and_the_adc():
    a = _pair(seed=1)[0]
    b = Sensor(load_config(extra={"sensor": {"width": WIDTH // 2, "height": HEIGHT}}), seed=1).expose("photo")
    off = Sensor(load_config(extra={"sensor": {"width": WIDTH, "height": HEIGHT}, "adc": {"enabled": False}}),
                 seed=1).expose("photo")
    with pytest.raises(CmosnoiseError, match="expected one shape and one ADC setting"):
        cuda_kernel.DevicePlan([a.plan(), b.plan()])
    with pytest.raises(CmosnoiseError, match="with the ADC off"):
        cuda_kernel.DevicePlan([a.plan(), off.plan()])
    plan = cuda_kernel.DevicePlan([a.plan(), a.plan()])
    with pytest.raises(ValueError, match="give each item's plan"):
        plan.render([0, 1, 2])
    with pytest.raises(ValueError, match="plan numbers from 0 to 1"):
        plan.render([0, 1], plans=[0, 2])
    # the mean charge of several plans from one (P, rows, cols) array on the GPU; one plan's alone is refused
    # (a GPU array of the wrong shape: a NumPy array is host memory, which a real GPU refuses before its shape)
    cuda = cuda_kernel.kernels().cuda
    means = np.stack([a.plan().noisy_e] * 2).astype(np.float32)
    with pytest.raises(CmosnoiseError, match=rf"expected a float32 array of \(2, {HEIGHT}, {WIDTH}\)"):
        plan.with_means(noisy_e=cuda.to_device(means[0]))
    if not SIMULATED:  # the simulator's "GPU" arrays are host memory
        with pytest.raises(CmosnoiseError, match="noisy_e: .*expected one on the GPU"):
            plan.with_means(noisy_e=means)
    given = plan.with_means(noisy_e=cuda.to_device(means))
    np.testing.assert_array_equal(given.render([3, 4], shape=(4, 6))[0].copy_to_host(),
                                  plan.render([3, 4], shape=(4, 6))[0].copy_to_host())


@pytest.mark.gpu
def test_the_device_arrays_are_the_cuda_array_interface_and_the_plan_is_uploaded_once():
    _, gpu = _pair(seed=3)
    raw, e = gpu.frames_on_device(1)
    assert e is None and raw.shape == (1, HEIGHT, WIDTH) and raw.dtype == np.uint16
    if not SIMULATED:  # the simulator's arrays live on the host and have no such interface
        face = raw.__cuda_array_interface__
        assert face["shape"] == (1, HEIGHT, WIDTH) and face["typestr"] == "<u2"
    plan = gpu.device_plan()
    gpu.frames_on_device([2, 3])
    assert gpu.device_plan() is plan and plan.nbytes() > 0


@pytest.mark.slow
def test_bad_device_and_bad_batches_get_one_line():
    with pytest.raises(CmosnoiseError, match="device = 'gpu': expected one of cpu, cuda"):
        Sensor({}, device="gpu")
    _, gpu = _pair(seed=3)
    with pytest.raises(CmosnoiseError, match="frame = -1"):
        gpu.frames_on_device([0, -1])
    with pytest.raises(ValueError, match="do not fit"):
        gpu.frames_on_device([0], region=(0, 8, 0, 8), corners=[(HEIGHT - 4, 0)])


def test_without_a_gpu_device_cuda_is_one_line_and_exit_2():
    """Outside the simulator on this machine (no GPU, no driver): the command line names the device and what to do."""
    if not SIMULATED:
        pytest.skip("this machine has a GPU")  # pragma: no cover - CMOSNOISE_TEST_GPU=1 on a GPU machine
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    r = subprocess.run([sys.executable, "-m", "cmosnoise", "simulate", "--device", "cuda", "--frames", "1",
                        "--set", "sensor.width=32", "--set", "sensor.height=16", "--out", "unused"],
                       capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 2, r.stderr
    assert "device = 'cuda'" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.gpu
def test_simulate_with_device_cuda_writes_the_cpu_runs_frames(tmp_path):
    common = ["-q", "simulate", "--frames", "2", "--set", f"sensor.width={WIDTH}", "--set", f"sensor.height={HEIGHT}"]
    assert cli(*common, "--out", tmp_path / "cpu").returncode == 0
    r = cli(*common, "--device", "cuda", "--out", tmp_path / "gpu")
    assert r.returncode == 0, r.stderr
    import tifffile

    np.testing.assert_array_equal(tifffile.imread(tmp_path / "gpu" / "raw.tiff"), tifffile.imread(tmp_path / "cpu" / "raw.tiff"))
    summary = json.loads((tmp_path / "gpu" / "summary.json").read_text())
    assert summary["generator"]["frame_kernel"] == "numba-cuda"


# ------------------------------------------------------------------ no multiply-add contraction
_PTX_PROBE = textwrap.dedent('''
    """Compile each kernel of one every-stage batch to PTX for compute 9.0 (NVVM only: no GPU needed), with and
    without strict_arithmetic, and count the float64 multiply-adds."""
    import json, sys, types
    import numba
    import numba.cuda.dispatcher as dispatcher
    from numba import cuda
    # device functions ask the current GPU for its compute capability; there is none: say 9.0
    dispatcher.get_current_device = lambda: types.SimpleNamespace(compute_capability=(9, 0))
    import numpy as np
    from cmosnoise import Sensor
    from cmosnoise.engine.frame import cuda_device, cuda_kernel

    calls = []

    class Launch:
        def __init__(self, name):
            self.name = name
        def __getitem__(self, config):
            return lambda *args: calls.append((self.name, args))

    class Host:  # the launches' arrays, on the host: the same numba types as device arrays
        @staticmethod
        def to_device(a, stream=0):
            return np.array(a)
        @staticmethod
        def device_array(shape, dtype, stream=0):
            return np.zeros(shape, dtype)

    fake = types.SimpleNamespace(cuda=Host, **{n: Launch(n) for n in ("lines", "trap_values", "pixel_sums",
                                                                       "blink_values", "pixels", "stick",
                                                                       "normal_map", "heavy_tail_map",
                                                                       "offset_map")})
    cuda_kernel.check = lambda: None
    cuda_kernel.kernels = lambda: fake
    sensor = Sensor(json.loads(sys.argv[1]), seed=5)
    shot = sensor.expose("photo")
    shot.frames_on_device([0, 1], electrons=True)
    # the fixed maps' kernels, launched as fixed_maps launches them (a heavy-tailed map between two points)
    from cmosnoise.engine import fixed_maps
    from cmosnoise.model.stages.dark_current import LOGIT_GRID
    fixed_maps._on_device = lambda kind, out, args: cuda_kernel.fixed_map(kind, out.shape, *args)
    fixed_maps.normal_map((0, 8, 0, 8), 64, (1, 2), 1.0, 0.02, 0.0, engine="cuda")
    warm = Sensor({**json.loads(sys.argv[1]), "sensor": {"width": 64, "height": 48, "temperature_c": 40}}, seed=5)
    s = warm.dark_state.inversion()
    fixed_maps.heavy_tail_map((0, 8, 0, 8), 64, (1, 2), LOGIT_GRID, s["points"], s["w"], engine="cuda")
    fixed_maps.offset_map((0, 8, 0, 8), 64, (1, 2), 3.0, 0.01, 200.0, engine="cuda")
    out = {}
    for name, args in calls:
        sig = tuple(numba.typeof(a) for a in args)
        fn = getattr(cuda_device, name).py_func
        loose, _ = cuda.compile_ptx(fn, sig, cc=(9, 0))
        with cuda_kernel.strict_arithmetic():
            strict, _ = cuda.compile_ptx(fn, sig, cc=(9, 0))
        out[name] = {"loose_fma": loose.count("fma.rn.f64"), "strict_fma": strict.count("fma.rn.f64"),
                     "strict_mul_rn": strict.count("mul.rn.f64"), "strict_plain_mul": strict.count("mul.f64")}
    print(json.dumps(out))
''')


@pytest.mark.gpu
def test_nvvm_compiles_the_kernels_without_multiply_add_contraction():
    """NVVM contracts ``a * b + c`` into ``fma`` unless told ``-fma=0``: compiled as launched (PTX for compute
    9.0, NVVM alone), every kernel under strict_arithmetic has no float64 ``fma`` and rounds each product on its
    own (``mul.rn``, which ptxas does not fuse); the same kernels compiled without it contract (the check can
    fail). Run outside the simulator: NVVM itself compiles."""
    import json

    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    cfg = _merged(EVERY, {"sensor": {"width": 64, "height": 48}})
    r = subprocess.run([sys.executable, "-c", _PTX_PROBE, json.dumps(cfg)], capture_output=True, text=True,
                       env=env, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    counts = json.loads(r.stdout.strip().splitlines()[-1])
    assert set(counts) == {"lines", "trap_values", "pixel_sums", "blink_values", "pixels", "stick", "normal_map",
                           "heavy_tail_map", "offset_map"}
    for name, c in counts.items():
        assert c["strict_fma"] == 0 and c["strict_plain_mul"] == 0, (name, c)
    assert counts["pixels"]["strict_mul_rn"] > 50 and counts["pixels"]["loose_fma"] > 50, counts["pixels"]
    assert all(counts[k]["loose_fma"] > 0 for k in ("lines", "trap_values", "blink_values", "heavy_tail_map"))


@pytest.mark.gpu
def test_crops_of_a_map_on_the_device_are_the_maps_crops():
    """The truth of a batch of crops: one launch cuts the same corners out of an exposure's map."""
    rng = np.random.default_rng(0)
    source = rng.random((HEIGHT, WIDTH)).astype(np.float32)
    corners = [(0, 0), (HEIGHT - 10, WIDTH - 12), (5, 3)]
    out = cuda_kernel.crops(source, corners, (10, 12)).copy_to_host()
    for b, (r, c) in enumerate(corners):
        np.testing.assert_array_equal(out[b], source[r:r + 10, c:c + 12])
    with pytest.raises(ValueError, match="do not fit"):
        cuda_kernel.crops(source, [(HEIGHT - 5, 0)], (10, 12))


@pytest.mark.gpu
def test_dataset_and_sweep_with_device_cuda_give_the_cpus_bytes_and_numbers(tmp_path, monkeypatch):
    from cmosnoise.app import dataset as ds
    from cmosnoise.app import sweep as sw

    # a shard's samples from different cameras, their frames in launches of GPU_BATCH samples (2: three samples
    # cross a batch's end); crops of 16 x 24, as the simulator's time is its pixels' (a quarter of 32 x 48's)
    recipe = ds.Recipe(samples=3, crop=(16, 24), seed=4, cameras=("led", "sony-imx900"), sources=ds.BUILTIN_SCENES,
                       shard_size=3)
    assert len({ds.settings(recipe, i).columns["camera"] for i in range(3)}) == 2
    monkeypatch.setattr(ds, "GPU_BATCH", 2)
    assert ds.shard_bytes(recipe.to_json(), 0, "cuda") == ds.shard_bytes(recipe.to_json(), 0)
    cfg = {"sensor": {"width": 24, "height": 16}}
    base = load_config(extra=cfg)
    assert sw.run_instance(base.model_dump(), "flat:0.3", 2, 17, device="cuda") == \
        sw.run_instance(base.model_dump(), "flat:0.3", 2, 17)
    with pytest.raises(CmosnoiseError, match="--device 'tpu'"):
        sw.run(base, [], 1, tmp_path / "s", device="tpu")


@pytest.mark.gpu
def test_the_torch_dataset_on_the_gpu_gives_the_cpus_tensors():
    from cmosnoise.torch import NoisyRawDataset

    cpu = NoisyRawDataset(3, crop=(16, 24), seed=2, cameras=("led", "sony-imx900"))  # small: the simulator's
    gpu = NoisyRawDataset(3, crop=(16, 24), seed=2, cameras=("led", "sony-imx900"), device="cuda")  # pixels cost
    assert len({cpu.sample(i)[1]["camera"] for i in range(3)}) == 2  # two cameras among them
    together = gpu.__getitems__([2, 0])  # what a DataLoader with a batch_size asks: one launch
    for i, b in [(0, gpu[0]), (1, gpu[1]), (2, gpu[2]), (2, together[0]), (0, together[1])]:
        a = cpu[i]
        assert b["noisy"].device.type == ("cpu" if SIMULATED else "cuda")
        for key in ("noisy", "expected", "perfect", "mask", "raw"):
            assert a[key].dtype == b[key].dtype and torch_equal(a[key], b[key].cpu()), (i, key)


def torch_equal(a, b) -> bool:
    import torch

    return bool(torch.equal(a, b))


@pytest.mark.gpu
def test_the_fixed_maps_made_on_the_gpu_are_the_cpus():
    """#33: every fixed map's two loops (a normal map; a heavy-tailed map at a point, scaled from it, and between
    two points) run on the GPU from the same sources, and give the compiled CPU loops' bits on a rectangle away
    from the corner (its origin in the counters) and on the whole sensor."""
    from cmosnoise.engine import fixed_maps
    from cmosnoise.model.seeds import fixed_key

    rows, cols = (24, 40) if SIMULATED else (1080, 1920)
    key = fixed_key(3, "prnu")
    for region in [(0, rows, 0, cols), (5, rows - 3, 7, cols - 2)]:
        cpu = fixed_maps.normal_map(region, cols, key, 1.0, 0.02, 0.0, engine="compiled")
        assert np.array_equal(fixed_maps.normal_map(region, cols, key, 1.0, 0.02, 0.0, engine="cuda"), cpu)
    from cmosnoise.model.stages.dark_current import LOGIT_GRID

    sensor = Sensor({"sensor": {"width": cols, "height": rows, "temperature_c": 40}}, seed=3)
    s = sensor.dark_state.inversion()  # 40 C: between two characterization points, the two-point map
    assert len(s["points"]) == 2
    for points, w, scales in [(s["points"], s["w"], (1.0, 1.0)), (s["points"][:1], 0.0, (1.0, 1.0)),
                              (s["points"][:1], 0.0, (1.7, 2.3))]:
        args = ((2, rows, 3, cols), cols, fixed_key(3, "dark_current"), LOGIT_GRID, points, w, *scales)
        cpu = fixed_maps.heavy_tail_map(*args, engine="compiled")
        assert np.array_equal(fixed_maps.heavy_tail_map(*args, engine="cuda"), cpu), (len(points), scales)
    for tail in [(0.0, 0.0), (0.05, 200.0)]:  # the pixel offsets, without and with a tail (5 %: many members)
        args = ((3, rows, 1, cols - 4), cols, fixed_key(3, "pixel_offset"), 2.5, *tail)
        cpu = fixed_maps.offset_map(*args, engine="compiled")
        assert np.array_equal(fixed_maps.offset_map(*args, engine="cuda"), cpu), tail
