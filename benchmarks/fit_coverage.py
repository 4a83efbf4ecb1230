"""How often each fitted parameter's 95 % interval holds the configured value: 20 simulated sensors per
(sensor, temperature), the round trip ``tests/test_fit_stages.py`` asserts on.

It runs exactly that test's measurements and fits (its ``measure``, ``truth``, ``COMBOS``, ``STAGES`` and
seeds: imported from the test, so the two cannot differ) in two processes, and prints, for each parameter
and (sensor, temperature), how many of the 20 intervals hold the truth, and the source follower's mean
(estimate - truth) / standard error. About two minutes on two cores.

    python benchmarks/fit_coverage.py [--json docs/numbers/fit_coverage.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))

import test_fit_stages as t  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", help="also write the table here (docs/numbers/fit_coverage.json feeds the README)")
    args = ap.parse_args()
    tasks = [(preset, T, seed) for preset, T in t.COMBOS for seed in range(t.STUDY_SEEDS)]
    t0 = time.perf_counter()
    results = t.run_fits(tasks)
    names = [n for stage in t.STAGES.values() for n in stage]
    combos = [f"{p or 'default'}@{T:g}" for p, T in t.COMBOS]
    hits = {n: {c: 0 for c in combos} for n in names}
    z = {n: {c: [] for c in combos} for n in t.STAGES["source_follower"]}
    for (preset, T, _), (P, tr) in zip(tasks, results):
        c = f"{preset or 'default'}@{T:g}"
        for n in names:
            p = P.get(n)
            if p is not None and p["ci95"] is not None:
                lo, hi = p["ci95"]
                hits[n][c] += lo <= tr[n] <= hi
                if n in z and hi > lo:
                    z[n][c].append((p["value"] - tr[n]) / ((hi - lo) / 3.92))
    mean_z = {n: {c: sum(v) / len(v) for c, v in d.items() if v} for n, d in z.items()}
    print(f"{len(tasks)} fits in {time.perf_counter() - t0:.0f} s; intervals holding the truth, of {t.STUDY_SEEDS}:")
    print(f"  {'':40s} " + " ".join(f"{c:>22s}" for c in combos))
    for n in names:
        print(f"  {n:40s} " + " ".join(f"{hits[n][c]:22d}" for c in combos))
    for n, d in mean_z.items():
        print(f"  mean z {n.split('.')[-1]:33s} " + " ".join(f"{d[c]:+22.2f}" for c in combos))
    if args.json:
        data = {"command": "python benchmarks/fit_coverage.py", "seeds": t.STUDY_SEEDS, "size": t.SIZE, "combos": combos,
                "hits": hits, "mean_z": mean_z}
        with open(args.json, "w") as f:
            json.dump(data, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
