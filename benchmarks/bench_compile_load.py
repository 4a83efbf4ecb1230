"""A first run on a busy machine: one background build, joined by a second command, and compiled loops within
300 s (#75).

    python benchmarks/bench_compile_load.py [--busy 2] [--limit 600] [--json docs/numbers/compile_load.json]

With an empty numba cache (a folder of its own) and ``--busy`` processes
keeping the cores busy (pure-Python loops, one each), as a user's machine
under load: the ``cmosnoise`` command runs ``simulate`` (the default sensor,
one frame) and starts the background build; ``python -m cmosnoise`` runs it
again at once and must join that build, not start another; then a run every
``--every`` seconds until one takes the compiled loops (no "NumPy" in its
line, ``frame_kernel`` in its timings). Printed and written: the build's
pid, whether the second run joined it, how many builds were started (their
logs in the run's temporary folder), each run's time and line, and the
seconds from the first run's start to the first run on compiled loops.
Every process it started is stopped by its id at the end.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BURN = "while True:\n    pass\n"


def _run(cmd: list[str], env: dict, out: Path) -> tuple[float, subprocess.CompletedProcess]:
    t0 = time.perf_counter()
    r = subprocess.run([*cmd, "simulate", "--frames", "1", "--no-progress", "--out", str(out)], env=env,
                       capture_output=True, text=True, timeout=900)
    return time.perf_counter() - t0, r


def _compiled(out: Path, r: subprocess.CompletedProcess) -> bool:
    if r.returncode != 0 or "NumPy" in r.stderr:
        return False
    stages = json.loads((out / "summary.json").read_text())["timings_s"]["stages"]
    return "frame_kernel" in stages


def _stop_group(pid: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pid, signal.SIGKILL)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--busy", type=int, default=2, help="processes keeping the cores busy")
    ap.add_argument("--limit", type=float, default=600.0, help="give up after this many seconds")
    ap.add_argument("--every", type=float, default=15.0, help="seconds between the later runs")
    ap.add_argument("--json", help="also write the result here")
    a = ap.parse_args()
    console = shutil.which("cmosnoise", path=str(Path(sys.executable).parent)) or shutil.which("cmosnoise")
    if console is None:
        sys.exit("the cmosnoise command is not installed beside this interpreter")
    tmp = Path(tempfile.mkdtemp(prefix="bench-compile-"))
    (tmp / "tmp").mkdir()
    env = {k: v for k, v in os.environ.items() if k != "CMOSNOISE_COMPILE"}
    env.update(NUMBA_CACHE_DIR=str(tmp / "cache"), TMPDIR=str(tmp / "tmp"))
    burners = [subprocess.Popen([sys.executable, "-c", BURN]) for _ in range(a.busy)]
    runs: list[dict] = []
    build_pid = None
    try:
        start = time.perf_counter()
        took, first = _run([console], env, tmp / "r0")
        if "(pid " in first.stderr:
            build_pid = int(first.stderr.split("(pid ")[1].split(")")[0])
        runs.append({"by": "cmosnoise", "at_s": 0.0, "s": took, "compiled": _compiled(tmp / "r0", first),
                     "line": first.stderr.strip()[-300:]})
        at = time.perf_counter() - start
        took, second = _run([sys.executable, "-m", "cmosnoise"], env, tmp / "r1")
        joined = build_pid is not None and f"another process builds them (pid {build_pid}, " in second.stderr
        runs.append({"by": "python -m cmosnoise", "at_s": at, "s": took, "compiled": _compiled(tmp / "r1", second),
                     "line": second.stderr.strip()[-300:]})
        ready = None
        k = 2
        while time.perf_counter() - start < a.limit:
            time.sleep(a.every)
            at = time.perf_counter() - start
            took, r = _run([console], env, tmp / f"r{k}")
            ok = _compiled(tmp / f"r{k}", r)
            runs.append({"by": "cmosnoise", "at_s": at, "s": took, "compiled": ok, "line": r.stderr.strip()[-300:]})
            print(f"{at:6.0f} s: a run of {took:5.1f} s, {'compiled loops' if ok else 'NumPy specification'}",
                  flush=True)
            k += 1
            if ok:
                ready = at
                break
        builds = len(list((tmp / "tmp").glob("cmosnoise-compile-*.log")))
    finally:
        for b in burners:
            b.kill()
            b.wait()
        if build_pid is not None:
            _stop_group(build_pid)
        shutil.rmtree(tmp, ignore_errors=True)
    result = {"command": "python benchmarks/bench_compile_load.py " + " ".join(sys.argv[1:]),
              "cores": os.cpu_count(), "busy_processes": a.busy, "build_pid": build_pid,
              "second_run_joined": joined, "builds_started": builds, "compiled_after_s": ready,
              "within_300_s": ready is not None and ready <= 300, "runs": runs}
    print(f"one build (pid {build_pid}); the python -m run joined it: {joined}; builds started: {builds}; "
          f"compiled loops from {ready if ready is None else round(ready)} s after the first run's start "
          f"(cores {os.cpu_count()}, {a.busy} busy processes)")
    if a.json:
        Path(a.json).write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
