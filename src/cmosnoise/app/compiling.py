"""``cmosnoise compile``: the package's compiled loops built for this machine now, into numba's on-disk cache.

Every compiled loop (the frame kernel, the fixed-pattern loops, the summary's
reductions, the pictures' demosaicing, ...) is compiled for the machine it
first runs on and kept in numba's cache; later runs load it. On the command
line a run that finds them missing does not wait for the compilers (about
40 s of a 2-core machine for the default run, measured with ``time``): it
makes its frames with the NumPy specification (the same bits) and starts this
command in the background, in a session of its own, for the next run
(:func:`cmosnoise.engine.jit.compiled`). Run it yourself to build
everything at once, e.g. in a container image after ``pip install``.

What it compiles is what three runs use, and their ground truth (a data
set's): the default sensor with processing, a sensor with every stage
on, and one behind a lens (:data:`WARM_UPS`). A configuration whose
arrays take other types compiles those variants at its first run, and says so.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from ..engine import jit

#: every stage on (the random telegraph loops, the Tukey-lambda table, pixel offsets with their tail, the
#: nonlinear curve, the black level per frame, defects), beside the default sensor
EVERY_STAGE = {"sensor": {"frame_rate_hz": 30}, "column_noise": {"gain_sigma_pct": 1.0},
               "row_noise": {"fixed_sigma_e": 0.5},
               "pixel_offset": {"enabled": True, "sigma_e": 4.0,
                                "tail": {"ppm_above": 200, "threshold_e": 20, "max_e": 200}},
               "nonlinearity": {"enabled": True, "linearity_error_pct": [-1.2, 0.6]},
               "black_level": {"channel_offsets_dn": [1.5, -0.5, 0.25, 2.0], "frame_sigma_dn": 0.3},
               "read_noise": {"enabled": True, "distribution": "tukey_lambda", "scale_dn": 1.2, "shape": -0.05},
               "source_follower": {"rts": {"enabled": True, "ppm": 1000}},
               "dark_current": {"rts": {"enabled": True, "ppm": 50}},
               "defects": {"enabled": True}}

#: a lens in front of the sensor: a PSF (the blur's mosaic), shading and a chief-ray angle with its QE loss and
#: leaning crosstalk (the lens's field loops)
LENS = {"optics": {"psf": "gaussian", "relative_illumination": "cos4", "chief_ray_angle": [[0, 0], [1, 25]],
                   "angle_relative_qe": [[0, 1], [20, 0.7]]},
        "crosstalk": {"kernel_at_angle_pct": [[0.6, 4, 1.9], [3, 76, 8], [0.6, 4, 1.9]]}}

#: (what, the configuration's changes from the defaults): the runs whose loops are built, each 2 frames with
#: processing (the run statistics compare frames; processed.png takes the pictures' loops)
WARM_UPS = (("the default sensor", {}), ("every stage on", EVERY_STAGE), ("a lens", LENS))

#: how often a build starts over on sources installed while it ran (:func:`_start_over`), at most
MAX_RESTARTS = 3
#: the environment variable counting a build's restarts
RESTARTS_ENV = "CMOSNOISE_COMPILE_RESTARTS"


def _start_over(fd: int, background: bool, say: Callable[[str], None]) -> None:
    """Replace this process by a new build of the sources installed now, holding the same lock (the same pid, the
    same log, the lock never let go), said once: an install while a build ran (``pip install`` of the package)
    left it compiling sources that are gone."""
    n = int(os.environ.get(RESTARTS_ENV, "0") or 0) + 1
    say(f"the package was installed again while this build ran (its sources changed): starting over on the new "
        f"sources (restart {n} of at most {MAX_RESTARTS})")
    os.set_inheritable(fd, True)
    env = {**os.environ, jit.LOCK_FD_ENV: str(fd), RESTARTS_ENV: str(n), jit.COMPILE_ENV: "foreground"}
    args = [sys.executable, "-m", "cmosnoise", "compile", *(["--background"] if background else [])]
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, args, env)


def _write_failure(reason: str) -> None:
    """Leave ``reason`` where the next run reads it (:func:`.jit.last_failure`), written whole or not at all."""
    path = jit.failure_file()
    try:
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(f"{reason}\n{time.strftime('%Y-%m-%d %H:%M:%S')}\n")
        os.replace(tmp, path)
    except OSError:
        pass


def build(background: bool = False, say: Callable[[str], None] = print) -> dict[str, float] | None:
    """Compile (or load) every loop the runs of :data:`WARM_UPS` use, holding :func:`.jit.build_files`' lock.

    Parameters
    ----------
    background : bool
        Started by a run (:func:`.jit.start_build`): at a lower priority, and
        nothing done where another process holds the lock. Otherwise it waits
        for that process, then loads what it built.
    say : callable
        Told each step, one line each.

    Returns
    -------
    dict or None
        Seconds each warm-up run took (its compile included); None where a
        background build found another running.
    """
    from ..analysis import ground_truth
    from ..config.loading import load_config
    from ..model.sensor import Sensor
    from .run import simulate

    lock, _ = jit.build_files()
    inherited = os.environ.pop(jit.LOCK_FD_ENV, None)  # start_build took the lock and handed it over
    fd = int(inherited) if inherited and inherited.isdigit() else os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    mode = os.environ.get(jit.COMPILE_ENV)
    os.environ[jit.COMPILE_ENV] = "foreground"  # this process is the one that compiles
    try:
        if jit.fcntl is not None and not inherited:
            try:
                jit.fcntl.flock(fd, jit.fcntl.LOCK_EX | jit.fcntl.LOCK_NB)
            except OSError:
                if background:
                    say("another process is compiling the loops for this installation: nothing to do")
                    return None
                say("another process is compiling the loops for this installation: waiting for it ...")
                jit.fcntl.flock(fd, jit.fcntl.LOCK_EX)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        if background:
            os.nice(10)  # the run that started it goes first
        times = {}
        stamp = jit.sources_stamp()
        restarts = int(os.environ.get(RESTARTS_ENV, "0") or 0)

        def overtaken() -> bool:
            return restarts < MAX_RESTARTS and jit.sources_stamp() != stamp

        try:
            with tempfile.TemporaryDirectory(prefix="cmosnoise-compile-") as tmp:
                for i, (what, extra) in enumerate(WARM_UPS):
                    if overtaken():
                        break
                    # "step i of n: what ..." is what a run that finds this build running reads of it
                    say(f"step {i + 1} of {len(WARM_UPS)}: {what}: compiling what its run uses (or loading it "
                        "from numba's cache) ...")
                    t0 = time.perf_counter()
                    config = load_config(extra={**extra, "run": {"frames": 2}, "processing": {"enabled": True}})
                    simulate(config, Path(tmp) / str(i))
                    ground_truth.expected_raw(Sensor(config).expose())  # a data set's truth
                    times[what] = time.perf_counter() - t0
                    say(f"{what}: {times[what]:.1f} s")
        except BaseException as exc:  # the next run says so, with the log (a Ctrl-C too: the loops are not all built)
            _write_failure(f"{type(exc).__name__}: {exc}".strip().splitlines()[0][:300])
            raise
        if overtaken():  # an install during a step: its temporary folder is gone, the lock still held
            _start_over(fd, background, say)
        jit.failure_file().unlink(missing_ok=True)
        return times
    finally:
        os.close(fd)  # releases the lock
        if mode is None:
            os.environ.pop(jit.COMPILE_ENV, None)
        else:
            os.environ[jit.COMPILE_ENV] = mode
