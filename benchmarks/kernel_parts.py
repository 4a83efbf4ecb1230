"""Where the frame kernel's time goes: the 1920 x 1080 RGGB photo frame with terms of its plan switched off.

    python benchmarks/kernel_parts.py [--threads 1] [--repeats 6]

Each line is the best of --repeats frames of the fused kernel with some terms
of the frame plan removed (``dataclasses.replace`` on ``Exposure.plan()``):
the differences between lines are what shot noise (Poisson draws: the
first branch-free pass, the PTRS tests, the inversion below a mean of 10)
and the source follower's normals cost. It guides work on the kernel; the
speed targets are measured by ``bench_chain.py``.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from cmosnoise import Sensor, load_config
from cmosnoise.engine import kernel


def best_ms(plan: kernel.FramePlan, repeats: int) -> float:
    kernel.render(plan, 0)
    best = float("inf")
    for k in range(repeats):
        t0 = time.perf_counter()
        kernel.render(plan, k)
        best = min(best, time.perf_counter() - t0)
    return 1000 * best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=6)
    args = ap.parse_args()
    from cmosnoise.engine.jit import numba

    numba.set_num_threads(args.threads)
    cfg = load_config(extra={"sensor": {"width": 1920, "height": 1080, "cfa": "RGGB"}})
    plan = Sensor(cfg, seed=1).expose("photo").plan()
    mean = plan.noisy_e
    print(f"photo at 1920 x 1080, {args.threads} thread(s): {100 * np.mean(mean < 10):.1f} % of pixels below a mean "
          f"of 10 e- (inversion), the rest PTRS; median {np.median(mean):.0f} e-")
    quiet = dict(row_sigma_e=None, col_gain=None, col_sigma_e=None, col_offset_e=None)
    lines = [
        ("every term", plan),
        ("no shot noise (its mean instead)", dataclasses.replace(plan, noisy_e=None, exact_e=mean)),
        ("no source follower", dataclasses.replace(plan, sf_sigma_e=None)),
        ("shot noise alone", dataclasses.replace(plan, sf_sigma_e=None, **quiet)),
        ("nothing but the ADC", dataclasses.replace(plan, noisy_e=None, exact_e=mean, sf_sigma_e=None, **quiet)),
    ]
    for label, p in lines:
        print(f"  {label:34s} {best_ms(p, args.repeats):8.1f} ms/frame")


if __name__ == "__main__":
    main()
