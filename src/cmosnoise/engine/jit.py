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

import os
import sys
import threading


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
    if any(d.signatures for d in dispatchers) or any(cached_for_this_machine(d) for d in dispatchers):
        return
    import logging

    logging.getLogger(__name__).info(f"compiling {what} for this machine (once; a few seconds) ...")


__all__ = ["numba", "host_features", "vectors", "ONE_LAUNCH", "cached_for_this_machine", "announce"]
