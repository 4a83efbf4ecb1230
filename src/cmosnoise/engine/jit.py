"""numba for the package's compiled loops, imported here once, with the host's full vector width.

On a CPU with AVX-512, LLVM prefers 256-bit vectors unless told otherwise
(its ``prefer-256-bit`` tuning). The frame kernel's branch-free passes (the
Philox blocks, the PTRS quick test, Box-Muller) run faster with 512-bit
vectors: on the development machine ``benchmarks/bench_chain.py`` put the
1080p kernel at 0.40 of its NumPy reference on one thread and 0.21 on two
before, 0.32 and 0.18 after (``NUMBA_CPU_FEATURES`` set to the host's plain
features, and a cache folder of its own, measures the before). So, unless
``NUMBA_CPU_NAME`` or ``NUMBA_CPU_FEATURES`` is already set, this sets
``NUMBA_CPU_FEATURES`` (and, where numba was imported first, its
``config.CPU_FEATURES``, which numba reads when it first compiles) to the
host's own features plus ``-prefer-256-bit`` where the host has AVX-512;
elsewhere it changes nothing. Where numba had already compiled something
before cmosnoise was imported, it is too late: :func:`vectors` says so, and
the frame kernel's compile message with it. Child processes (worker pools, the
tests' command lines) inherit it, so every process keys numba's on-disk
cache the same way.

The bits do not change: vector width changes how many pixels one
instruction takes, not the IEEE arithmetic of each (``fastmath`` is off, so
no fused multiply-add or reordering), and the tests hold the compiled
kernel to the NumPy implementation bit for bit.

``numba`` is None where numba is not installed (the NumPy paths run).
"""

from __future__ import annotations

import hashlib
import logging
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: the loops compile in the foreground
    fcntl = None


def host_features() -> str | None:
    """The host CPU's features as LLVM names them (``+avx2,-avx512f,...``), or None where llvmlite cannot say."""
    try:
        import llvmlite.binding as ll

        return ll.get_host_cpu_features().flatten()
    except Exception:  # no llvmlite (no numba), or a host LLVM cannot describe
        return None


#: set when numba had compiled something before cmosnoise was imported: the vector width was numba's default then
TOO_LATE = False


def vectors() -> str:
    """The widest vectors numba compiles for in this process: ``"AVX-512"``, ``"AVX-512 (256-bit preferred)"``
    (numba had compiled before cmosnoise was imported, with LLVM's default tuning), ``"AVX2"`` or ``"SSE/other"``."""
    features = set((os.environ.get("NUMBA_CPU_FEATURES") or host_features() or "").split(","))
    if "+avx512f" in features:
        return "AVX-512 (256-bit preferred)" if TOO_LATE or "-prefer-256-bit" not in features else "AVX-512"
    return "AVX2" if "+avx2" in features else "SSE/other"


def _widest_vectors() -> None:
    global TOO_LATE
    if os.environ.get("NUMBA_CPU_NAME") or os.environ.get("NUMBA_CPU_FEATURES"):
        return  # the user's choice
    features = host_features()
    if features is None or "+avx512f" not in features.split(","):  # leave numba's defaults
        return
    wanted = features + ",-prefer-256-bit"
    if "numba" in sys.modules:  # imported first: its CPU target reads the features when it first compiles
        from numba.core import registry

        if "_toplevel_target_context" in vars(registry.cpu_target):  # it has compiled already: too late
            TOO_LATE = True
            return
        sys.modules["numba"].config.CPU_FEATURES = wanted
    os.environ["NUMBA_CPU_FEATURES"] = wanted


_widest_vectors()

try:
    import numba
except ImportError:  # pragma: no cover - exercised where numba is missing
    numba = None

if numba is not None and not os.environ.get("NUMBA_THREADING_LAYER") and numba.config.THREADING_LAYER == "default":
    # a fork-safe threading layer (TBB, a non-GNU OpenMP, or numba's own workqueue): a process that has run the
    # kernel may fork (a PyTorch DataLoader's workers, multiprocessing's default on Linux). GNU OpenMP, which
    # numba would take where libgomp is present (PyTorch brings one), ends every forked child.
    numba.config.THREADING_LAYER = "forksafe"

#: held around every launch of the package's parallel loops: one launch at a time in a process. The fork-safe
#: workqueue layer aborts the whole process when two threads launch parallel loops at once (a run's aside thread,
#: the explorer's figure thread beside its pictures, a Dask worker's threads); the loops use every core anyway.
ONE_LAUNCH = threading.RLock()


def cached_for_this_machine(dispatcher) -> bool:
    """Whether numba's on-disk cache holds a compile of ``dispatcher`` for this machine and vector width (any
    argument types); True where numba's internals cannot say (nothing is announced then).

    Parameters
    ----------
    dispatcher : numba dispatcher
        A function compiled with ``cache=True``.

    Returns
    -------
    bool
    """
    try:
        index = dispatcher._cache._cache_file._load_index()  # {(signature, magic tuple, ...): file}
        magic = dispatcher.targetctx.codegen().magic_tuple()
        return any(key[1] == magic for key in index)
    except Exception:  # numba's internals moved
        return True


def keyed_on(dispatcher, *modules) -> None:
    """Make numba's on-disk cache of ``dispatcher`` stale whenever the source of one of ``modules`` changes, as it
    is when its own file does.

    numba keys a cached compile on the function's own file (its time and size) and takes other modules' globals
    as constants of the machine code. A loop that reads indices derived in another module (the frame kernel's
    switches, from :mod:`.frame.plan`'s table) would otherwise load an older table's indices after that module
    changed. The modules' stamps join the file's in the cache index's stamp; where numba's internals cannot
    take them, the dispatcher is not cached on disk at all (slower to start, never stale).

    Parameters
    ----------
    dispatcher : numba dispatcher
        A function compiled with ``cache=True``.
    *modules : module
        The modules whose sources its machine code depends on.
    """
    stamps = tuple((os.stat(m.__file__).st_mtime, os.stat(m.__file__).st_size) for m in modules)
    try:
        cache_file = dispatcher._cache._cache_file
        cache_file._source_stamp = (cache_file._source_stamp, stamps)
    except Exception:  # numba's internals moved: no disk cache rather than a stale one
        from numba.core.caching import NullCache

        dispatcher._cache = NullCache()


_ANNOUNCED: set = set()
_ANNOUNCE_LOCK = threading.Lock()


def announce(what: str, *dispatchers) -> None:
    """Say once a process, before the first call of ``what``'s compiled loops, that they are being compiled for
    this machine, where none of them is in memory or in numba's on-disk cache (a fresh installation, or a
    changed source). On the command line the message shows on stderr.

    Parameters
    ----------
    what : str
        What the loops are, as the message names them ("the summary's reductions").
    *dispatchers : numba dispatchers
        The loops.
    """
    with _ANNOUNCE_LOCK:
        if what in _ANNOUNCED:
            return
        _ANNOUNCED.add(what)
    if any(d.overloads for d in dispatchers) or any(cached_for_this_machine(d) for d in dispatchers):
        return
    logging.getLogger(__name__).info(f"compiling {what} for this machine (once; a few seconds) ...")


#: the environment variable that says how the compiled loops are first made where numba's on-disk cache holds
#: none for this machine: ``foreground`` (compiled in this process when first called: the library's default) or
#: ``background`` (this process runs the NumPy specification, the same bits, while ``cmosnoise compile`` builds
#: them in a process of its own for the next run: the command line's default, so a first picture does not wait
#: for compilers)
COMPILE_ENV = "CMOSNOISE_COMPILE"
MODES = ("foreground", "background")


def compile_mode() -> str:
    """How this process first makes compiled loops that numba's cache lacks: ``"foreground"`` or
    ``"background"`` (:data:`COMPILE_ENV`; foreground where it is unset, or where the system has no file locks)."""
    mode = os.environ.get(COMPILE_ENV) or "foreground"
    if mode not in MODES:
        from ..errors import CmosnoiseError

        raise CmosnoiseError(f"{COMPILE_ENV}={mode!r}: allowed are {', '.join(MODES)}")
    return mode if fcntl is not None else "foreground"


def build_files() -> tuple[Path, Path]:
    """(lock, log) of the background compile for this installation, vector width and numba cache folder.

    The compiling process holds an exclusive lock on the lock file (its pid
    written in it) for as long as it runs; the log holds what it printed.
    Both are in the system's temporary folder, named by a digest of what
    keys numba's cache, so two installations never wait for each other.
    """
    # what keys numba's cache: the package's sources, the interpreter's version (not its path: `cmosnoise` and
    # `python -m cmosnoise` may name one interpreter by two paths), the cache folder and the target
    key = "|".join([str(Path(__file__).resolve().parent), sys.implementation.cache_tag,
                    os.environ.get("NUMBA_CACHE_DIR", ""), os.environ.get("NUMBA_CPU_NAME", ""),
                    os.environ.get("NUMBA_CPU_FEATURES", "")])
    base = Path(tempfile.gettempdir()) / f"cmosnoise-compile-{hashlib.sha256(key.encode()).hexdigest()[:12]}"
    return base.with_suffix(".lock"), base.with_suffix(".log")


def sources_stamp() -> str:
    """A digest of the installed package's sources (each ``.py`` file's path, size and modification time): a
    build that finds it changed was overtaken by an install (``pip install`` while it ran), so what it compiles
    is keyed on sources that are gone (numba keys its cache on each file's stamp)."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        try:
            st = p.stat()
        except OSError:  # a file an install is replacing now
            continue
        h.update(f"{p.relative_to(root)}|{st.st_size}|{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def failure_file() -> Path:
    """Where a background compile that failed leaves its reason (beside :func:`build_files`' lock and log), for
    the next run to say; a build that ends well removes it."""
    return build_files()[0].with_suffix(".failed")


def build_state() -> str:
    """What the log of the compile running now says of it: its process, how long it has run and its last step
    (``pid 1234, 35 s so far, at step 2 of 3: every stage on``); empty where nothing can be read."""
    lock, log = build_files()
    parts = []
    try:
        pid = lock.read_text().split()[0]
        parts.append(f"pid {int(pid)}")
        parts.append(f"{max(0.0, time.time() - lock.stat().st_mtime):.0f} s so far")
    except (OSError, ValueError, IndexError):
        pass
    try:
        steps = [line for line in log.read_text(errors="replace").splitlines() if line.startswith("step ")]
    except OSError:
        steps = []
    if steps:
        parts.append("at " + steps[-1].split(": compiling")[0].split(" ...")[0])
    return ", ".join(parts)


def last_failure() -> str | None:
    """The reason the last background compile failed (:func:`failure_file`'s first line), or None."""
    try:
        text = failure_file().read_text(errors="replace").strip()
    except OSError:
        return None
    return text.splitlines()[0] if text else "no reason written"


#: the background compile this process started: {"process": subprocess.Popen}
_BUILD: dict = {}
_BUILD_LOCK = threading.Lock()


#: the environment variable naming a file descriptor that already holds the build lock (a child of start_build)
LOCK_FD_ENV = "CMOSNOISE_COMPILE_LOCK_FD"


def building() -> bool:
    """Whether a compile of the package's loops is running now for this installation (this process's
    background compile, or any process holding :func:`build_files`' lock)."""
    proc = _BUILD.get("process")
    if proc is not None and proc.poll() is None:
        return True
    if fcntl is None:  # pragma: no cover
        return False
    lock, _ = build_files()
    try:
        fd = os.open(lock, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return False
    except OSError:  # held exclusively: a compile runs
        return True
    finally:
        os.close(fd)  # releases the shared lock, if taken


def build_process() -> subprocess.Popen | None:
    """The background compile this process started, or None."""
    return _BUILD.get("process")


def start_build() -> subprocess.Popen | None:
    """Start ``python -m cmosnoise compile --background`` in a session of its own, once a process, unless a
    compile runs already; returns the process it started, or None.

    It outlives this process (so a short command leaves it to finish for the
    next), writes its log to :func:`build_files`' log, and compiles in the
    foreground mode itself.
    """
    with _BUILD_LOCK:
        if "process" in _BUILD or building():
            return None
        lock, log = build_files()
        held = None
        if fcntl is not None:  # the lock taken here and handed to the child: no second build can start between
            held = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:  # another process took it a moment ago: its build runs
                os.close(held)
                return None
        env = {**os.environ, COMPILE_ENV: "foreground", **({LOCK_FD_ENV: str(held)} if held is not None else {})}
        try:
            with open(log, "w") as fh:
                _BUILD["process"] = subprocess.Popen(
                    [sys.executable, "-m", "cmosnoise", "compile", "--background"], stdin=subprocess.DEVNULL,
                    stdout=fh, stderr=subprocess.STDOUT, env=env, start_new_session=True, close_fds=True,
                    pass_fds=() if held is None else (held,))
        finally:
            if held is not None:
                os.close(held)  # the child's copy holds the lock now
        return _BUILD["process"]


def compiled(what: str, *dispatchers, say: bool = True) -> bool:
    """Whether to run ``what``'s compiled loops now (True), or the NumPy specification beside them (False: the
    same bits). The one gate every compiled loop's caller passes.

    True where the loops are in memory or in numba's on-disk cache for this
    machine. In the background mode (:func:`compile_mode`) False while a
    background compile runs (this process's or another's: numba's index is
    then not read at every call), and False where they are missing and a
    background compile is started here (once a process), said once; True
    (compiled here) where that compile ended without them. In the foreground
    mode True, after saying once that they compile (``say``).

    Parameters
    ----------
    what : str
        What the loops are, as a message names them ("the summary's reductions").
    *dispatchers : numba dispatchers
        The loops (compiled with ``cache=True``).
    say : bool
        Whether to say that they compile here (False where the caller says it itself).

    Returns
    -------
    bool
        False also where numba is not installed.
    """
    if numba is None:
        return False
    if any(d.overloads for d in dispatchers):  # the compiled variants, a dict (.signatures lists them: 15 us)
        return True
    if compile_mode() == "background":
        if building():  # a syscall, no file read: the NumPy specification until the build ends
            _say_building(None)
            return False
        if not any(cached_for_this_machine(d) for d in dispatchers):
            started = start_build()
            if started is not None:
                _say_building(started)
                return False
    if say:
        announce(what, *dispatchers)
    return True


def _say_building(started: subprocess.Popen | None) -> None:
    with _ANNOUNCE_LOCK:
        if "building" in _ANNOUNCED:
            return
        _ANNOUNCED.add("building")
    _, log = build_files()
    if started is not None:
        who = f"`cmosnoise compile` (pid {started.pid}) builds them"
    else:
        state = build_state()
        who = "another process builds them" + (f" ({state})" if state else "")
    failed = last_failure() if started is not None else None
    before = (f"the last background compile failed ({failed}; its log: {log}), so it starts again; " if failed
              else "")
    logging.getLogger(__name__).info(
        f"{before}the compiled loops are not built for this machine yet: this run takes the NumPy specification "
        f"(the same bits, slower on large frames) while {who} in the background for the next run (about a "
        f"minute on 2 idle cores; log: {log})")


__all__ = ["numba", "host_features", "vectors", "ONE_LAUNCH", "cached_for_this_machine", "keyed_on", "announce", "compiled",
           "compile_mode", "COMPILE_ENV", "build_files", "building", "start_build", "build_process", "failure_file",
           "build_state", "last_failure"]
