"""Instances per second of `cmosnoise sweep` on paper-fig9-vga: a plain loop in one process, and Dask with 1 and 2 workers.

The Dask figures count from the first task submitted to the last row written
(the cluster already started, its start-up time printed beside), so their
ratio to the plain loop is Dask's overhead per task.

    python benchmarks/bench_sweep.py [--instances 24] [--json docs/numbers/sweep_speed.json]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--instances", type=int, default=24)
    ap.add_argument("--json")
    args = ap.parse_args()

    from cmosnoise import load_config
    from cmosnoise.app import sweep as sw

    base = load_config(preset="paper-fig9-vga")
    p = sw.plan(base, [], args.instances, 2)
    sw.run_instance(p.configs[0], p.scene, p.frames, sw.instance_seed(base.seed, 0))  # warm: kernel loaded
    t0 = time.perf_counter()
    for i in range(args.instances):
        sw.run_instance(p.configs[0], p.scene, p.frames, sw.instance_seed(base.seed, i))
    rows = [{"label": "plain loop, one process", "per_s": args.instances / (time.perf_counter() - t0), "startup_s": 0.0}]
    for n in (1, 2):
        t0 = time.perf_counter()
        client, cluster = sw.connect(None, n)
        client.run(lambda: __import__("cmosnoise.model.sensor"))  # workers import cmosnoise before the clock starts
        started = time.perf_counter() - t0
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "s"
            out.mkdir()
            sw._write_plan(out, p)
            sw.execute(p, out, client)  # a first pass loads the kernel in every worker
            (out / "results.csv").unlink()  # the timed pass writes its rows anew
            t0 = time.perf_counter()
            sw.execute(p, out, client)
            rows.append({"label": f"Dask LocalCluster, {n} worker(s)", "per_s": args.instances / (time.perf_counter() - t0),
                         "startup_s": started})
        sw.disconnect(client, cluster)
    print(f"cmosnoise sweep, paper-fig9-vga (640 x 480, 2 frames, dark calibration and median correction per instance), "
          f"{args.instances} instances, {os.cpu_count()} cores")
    for r in rows:
        print(f"  {r['label']:34s} {r['per_s']:6.2f} instances/s   ratio to the loop {r['per_s'] / rows[0]['per_s']:.2f}"
              + (f"   (cluster start {r['startup_s']:.1f} s)" if r["startup_s"] else ""))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"machine": f"{os.cpu_count()} cores", "command": f"python benchmarks/bench_sweep.py --instances {args.instances}",
                       "rows": rows}, fh, indent=2)
            fh.write("\n")


if __name__ == "__main__":
    main()
