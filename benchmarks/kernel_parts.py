"""Where the frame kernel's time goes: the 1920 x 1080 RGGB photo frame with terms of its plan switched off,
the generator scheme's building blocks alone, and what the scheme costs before any PTRS retry.

    python benchmarks/kernel_parts.py [--threads 1] [--repeats 6] [--json FILE]

Each kernel line is the best of --repeats frames of the fused kernel with some
terms of the frame plan removed (``dataclasses.replace`` on ``Exposure.plan()``):
the differences between lines are what shot noise (Poisson draws: the
first branch-free pass, the PTRS tests, the inversion below a mean of 10)
and the source follower's normals cost.

The building blocks are the kernel's own compiled helpers, each alone in a
loop over a frame's worth of values on one thread: a Philox block made into
two uniforms, ``log``, the cosine of a turn, a Box-Muller normal from two
uniforms, a square root and a division (the last two for scale), and shot
noise's first pass (every pixel's Philox block and PTRS quick test, as the
kernel makes it). Their sum with the kernel's "nothing but the ADC" frame
(the row and column terms, the clip, the ADC) is what docs/model.md section 1's
scheme costs per frame on this CPU before any PTRS retry or inversion, set
beside the NumPy reference of ``bench_chain.py`` timed in the same run. It
guides work on the kernel; the speed targets are measured by ``bench_chain.py``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import numpy as np
from bench_chain import best_fps, cpu, numpy_reference, per_frame

from cmosnoise import Sensor, load_config
from cmosnoise.engine.frame import kernel
from cmosnoise.engine.frame.plan import FramePlan
from cmosnoise.engine.jit import numba

_JIT = dict(fastmath=False, error_model="numpy")


def best_ms(fn, repeats: int) -> float:
    """The best of ``repeats`` calls of ``fn()``, in ms, after one call that compiles or warms it."""
    fn()
    return 1000 / best_fps(lambda _k: fn(), 1, repeats)


def kernel_ms(plan: FramePlan, repeats: int) -> float:
    kernel.render(plan, 0)
    return 1000 / best_fps(lambda k: kernel.render(plan, k), 1, repeats)


def building_blocks(plan: FramePlan, repeats: int) -> list[tuple[str, float]]:
    """(label, ms per 1080p frame) of each building block alone, one thread."""
    h = kernel._h
    uniform_pair, log, cos_turn, normal_from = h["uniform_pair"], h["log"], h["cos_turn"], h["normal_from"]

    @numba.njit(**_JIT)
    def uniforms(o1, o2, k0, k1):
        for j in range(o1.size):
            o1[j], o2[j] = uniform_pair(np.uint64(j), np.uint64(3), np.uint64(0), np.uint64(0), k0, k1)

    @numba.njit(**_JIT)
    def logs(x, out):
        for j in range(x.size):
            out[j] = log(x[j])

    @numba.njit(**_JIT)
    def cosines(x, out):
        for j in range(x.size):
            out[j] = cos_turn(x[j])

    @numba.njit(**_JIT)
    def normals(x, y, out):
        for j in range(x.size):
            out[j] = normal_from(x[j], y[j])

    @numba.njit(**_JIT)
    def roots(x, out):
        for j in range(x.size):
            out[j] = np.sqrt(x[j])

    @numba.njit(**_JIT)
    def divisions(x, out):
        for j in range(x.size):
            out[j] = 1.0 / x[j]

    @numba.njit(**_JIT)
    def first_pass(noisy, k0, k1):  # the kernel's first shot-noise pass, row by row, as _render_rows calls it
        rows, w = noisy.shape
        lam, u1, u2, res = np.empty(w), np.empty(w), np.empty(w), np.empty(w)
        small, big = np.empty(w, np.int64), np.empty(w, np.int64)
        left = 0
        for r in range(rows):
            ns, nb = kernel._shot_row(noisy[r], np.uint64(r * w), np.uint64(0), np.uint64(0), k0, k1, lam, u1, u2,
                                      res, small, big, np.inf)
            left += ns + nb
        return left

    n = plan.shape[0] * plan.shape[1]
    k0, k1 = plan.keys[0, 0], plan.keys[0, 1]
    a, b, out = np.empty(n), np.empty(n), np.empty(n)
    uniforms(a, b, k0, k1)  # open uniforms: the values the kernel's log and cosine take
    return [
        ("Philox block to two uniforms", best_ms(lambda: uniforms(out, b, k0, k1), repeats)),
        ("log", best_ms(lambda: logs(a, out), repeats)),
        ("cosine of a turn", best_ms(lambda: cosines(a, out), repeats)),
        ("Box-Muller normal from two uniforms", best_ms(lambda: normals(a, b, out), repeats)),
        ("square root", best_ms(lambda: roots(a, out), repeats)),
        ("division", best_ms(lambda: divisions(a, out), repeats)),
        ("shot noise's first pass (Philox block, PTRS quick test)", best_ms(lambda: first_pass(plan.noisy_e, k0, k1),
                                                                           repeats)),
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=1, help="numba threads for the kernel lines (the blocks take one)")
    ap.add_argument("--repeats", type=int, default=6)
    ap.add_argument("--json", help="also write the results here (docs/numbers/kernel_parts_avx2.json feeds the README)")
    args = ap.parse_args()

    cfg = load_config(extra={"sensor": {"width": 1920, "height": 1080, "cfa": "RGGB"}})
    sensor = Sensor(cfg, seed=1)
    shot = sensor.expose("photo")
    plan = shot.plan()
    mean = plan.noisy_e
    reference = numpy_reference(shot.mean_charge_e, sensor.transfer.gain_dn_per_e)
    t_ref = min(per_frame(reference, 3) for _ in range(2))

    numba.set_num_threads(args.threads)
    print(f"photo at 1920 x 1080, {args.threads} thread(s): {100 * np.mean(mean < 10):.1f} % of pixels below a mean "
          f"of 10 e- (inversion), the rest PTRS; median {np.median(mean):.0f} e-")
    quiet = dict(row_sigma_e=None, col_gain=None, col_sigma_e=None, col_offset_e=None)
    adc_only = dataclasses.replace(plan, noisy_e=None, exact_e=mean, sf_sigma_e=None, **quiet)
    lines = [
        ("every term", plan),
        ("no shot noise (its mean instead)", dataclasses.replace(plan, noisy_e=None, exact_e=mean)),
        ("no source follower", dataclasses.replace(plan, sf_sigma_e=None)),
        ("shot noise alone", dataclasses.replace(plan, sf_sigma_e=None, **quiet)),
        ("nothing but the ADC", adc_only),
    ]
    parts = []
    for label, p in lines:
        parts.append((label, kernel_ms(p, args.repeats)))
        print(f"  {label:34s} {parts[-1][1]:8.1f} ms/frame")

    numba.set_num_threads(1)
    print("building blocks, each alone over 1920 x 1080 values, one thread:")
    blocks = building_blocks(plan, args.repeats)
    for label, ms in blocks:
        print(f"  {label:58s} {ms:8.1f} ms/frame")
    one = dict(blocks)
    if args.threads == 1:  # the kernel lines above are the one-thread frames
        whole_ms, adc_ms = parts[0][1], parts[-1][1]
    else:
        whole_ms, adc_ms = kernel_ms(plan, args.repeats), kernel_ms(adc_only, args.repeats)
    t_ref = min(t_ref, *(per_frame(reference, 3) for _ in range(2)))
    floor_ms = (one["shot noise's first pass (Philox block, PTRS quick test)"] + one["Philox block to two uniforms"]
                + one["Box-Muller normal from two uniforms"] + adc_ms)
    print(f"one thread: the whole kernel {whole_ms:.1f} ms/frame, the NumPy reference {1000 * t_ref:.1f} ms/frame")
    print(f"the scheme before any PTRS retry or inversion (first pass + the source follower's Philox block and "
          f"normal + nothing but the ADC, {adc_ms:.1f} ms): {floor_ms:.1f} ms/frame, "
          f"{floor_ms / (1000 * t_ref):.2f} of the reference")

    if args.json:
        command = "python benchmarks/kernel_parts.py " + " ".join(
            f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items() if k != "json")
        data = {**cpu(), "command": command, "threads": args.threads,
                "parts": [{"label": label, "ms": ms} for label, ms in parts],
                "blocks": [{"label": label, "ms": ms} for label, ms in blocks],
                "adc_ms": adc_ms, "whole_ms": whole_ms, "ref_ms": 1000 * t_ref, "floor_ms": floor_ms}
        with open(args.json, "w") as f:
            json.dump(data, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
