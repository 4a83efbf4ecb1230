"""How often `cmosnoise fit` switches on a stage the data do not have (its false-positive rate), and how often
it finds one the data have at a small effect: foreign data sets from emva1288's own camera simulator
(tests/emva_dataset.py), one camera and its noise per seed.

- absent: no nonlinearity, no pixel offsets, white dark noise (K 0.4 DN/e-, full well 10 000 e-);
- present: the same camera with pixel offsets of ``--offset-e`` e- and a compressive nonlinearity of
  ``--nonlinearity`` at saturation (the mean photo-charge ``u`` becomes ``u (1 - NL u / full well)``).

Every stage the fit tests (``cmosnoise.analysis.fit.SELECTION_TESTS``) is switched on only where its test's
p-value is below SELECTION_ALPHA / (number of tests): Bonferroni, so that data without any of them switch on
one or more in at most SELECTION_ALPHA of the data sets. About 15 s a data set on two cores.

    python benchmarks/fit_selection.py [--seeds 20] [--json docs/numbers/fit_selection.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
MAKER = HERE.parent / "tests" / "emva_dataset.py"


def one(args: tuple[str, int, float, float]) -> dict:
    """Make the data set ``case`` for ``seed`` and fit it; returns which tests switched their stage on."""
    from cmosnoise.analysis.fit import SELECTION_TESTS
    from cmosnoise.app import fitting
    from cmosnoise.config import load_config

    case, seed, offset_e, nl = args
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data"
        params = ["0.4", "10000", "0", "0", "0"] if case == "absent" else ["0.4", "10000", str(offset_e), str(nl), "0"]
        proc = subprocess.run([sys.executable, str(MAKER), str(data), *params, str(seed)], capture_output=True,
                              text=True, timeout=600)
        if proc.returncode != 0:
            raise RuntimeError(proc.stderr[-2000:])
        doc = fitting.run(data, load_config(), Path(tmp) / "fit", False, with_round_trip=False)
    sel = doc["selection"]
    return {"case": case, "seed": seed, "on": [name for name in SELECTION_TESTS if sel.get(name, {}).get("on")],
            "p": {name: sel[name]["p_value"] for name in sel}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20, help="data sets of each case")
    ap.add_argument("--offset-e", type=float, default=1.0, help="the present case's pixel offsets, e- rms")
    ap.add_argument("--nonlinearity", type=float, default=0.02, help="the present case's compression at saturation")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--json", help="also write the counts here")
    args = ap.parse_args()
    from cmosnoise.analysis.fit import SELECTION_ALPHA, SELECTION_TESTS

    tasks = [(case, seed, args.offset_e, args.nonlinearity) for case in ("absent", "present")
             for seed in range(args.seeds)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(one, tasks))
    counts = {case: {name: sum(name in r["on"] for r in results if r["case"] == case) for name in SELECTION_TESTS}
              for case in ("absent", "present")}
    any_absent = sum(bool(r["on"]) for r in results if r["case"] == "absent")
    print(f"{len(tasks)} fits in {time.perf_counter() - t0:.0f} s; family-wise rate {SELECTION_ALPHA:g} over "
          f"{len(SELECTION_TESTS)} tests (each at {SELECTION_ALPHA / len(SELECTION_TESTS):.3g})")
    print(f"  data sets without any stage that switched one on: {any_absent} of {args.seeds}")
    print(f"  {'stage':36s} {'on, absent':>12s} {'on, present':>12s}")
    for name in SELECTION_TESTS:
        print(f"  {name:36s} {counts['absent'][name]:12d} {counts['present'][name]:12d}")
    if args.json:
        data = {"command": "python benchmarks/fit_selection.py " + " ".join(sys.argv[1:]), "seeds": args.seeds,
                "alpha": SELECTION_ALPHA, "tests": list(SELECTION_TESTS), "offset_e": args.offset_e,
                "nonlinearity": args.nonlinearity, "counts": counts, "any_absent": any_absent}
        with open(args.json, "w") as f:
            json.dump(data, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
