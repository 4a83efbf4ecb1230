"""The ``cmosnoise`` console script: the command line, quiet when interrupted while it starts.

BLAS is kept to one thread (numba's threads do the parallel work).
Importing the command line takes about a second (SciPy, numba). A Ctrl-C,
SIGTERM or SIGHUP in that second ends the process with status 130 (or
128 + the signal) and one line, not a traceback. Nothing has been written yet.
"""

from __future__ import annotations

import os
import signal
import sys


def _interrupted(signum: int) -> None:
    print("cmosnoise: interrupted while starting; nothing was written", file=sys.stderr, flush=True)
    os._exit(128 + int(signum))  # at once: nothing to clean up yet, and no interpreter exit that re-raises SIGINT


def main() -> None:
    # numba's threads do the parallel work. BLAS threads would only compete with them: after a BLAS call they
    # keep spinning for a while, and the next frame kernel ran at half speed. (Set before NumPy is imported;
    # a value in the environment is kept.)
    for var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    # A first run does not wait for the compilers: where numba's cache lacks a loop, this process runs the NumPy
    # specification (the same bits) while `cmosnoise compile` builds the loops in the background for the next
    # run (engine/jit.py, compiled). A value in the environment is kept (foreground: compile here, as the
    # library does).
    os.environ.setdefault("CMOSNOISE_COMPILE", "background")
    received: list[int] = []

    def stop(signum, _frame):
        received.append(signum)
        raise KeyboardInterrupt(signum)

    handlers = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        from .cli import run
    except KeyboardInterrupt as exc:
        _interrupted(exc.args[0] if exc.args and isinstance(exc.args[0], int) else signal.SIGINT)
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)
    if received:  # a library caught the KeyboardInterrupt while importing: the signal still counts
        _interrupted(received[0])
    try:
        status = run()
        from .cli import exit_quietly

        exit_quietly(status)  # the command is over: a signal from here on says so and keeps its status
    finally:
        # The interpreter's exit collects garbage over every object numba, LLVM and SciPy made: 0.15 to 0.2 s
        # after a frame kernel ran, an eighth of a one-frame run. Frozen objects are not scanned; everything
        # is still released by reference counting, files were closed, and the process ends here.
        import gc

        gc.freeze()
    sys.exit(status)


if __name__ == "__main__":
    main()
