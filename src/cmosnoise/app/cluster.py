"""The Dask helpers every distributed command shares (``sweep``, ``dataset``, a tiled ``simulate``): a client of an
existing scheduler or of a LocalCluster on the loopback address, a value kept on the worker that runs a task, a
task's result with a worker's failure as one line, and a quiet shutdown.

A LocalCluster's workers are processes of one thread each (``NUMBA_NUM_THREADS=1``): a command's parallelism is
its tasks, not threads inside them.
"""

from __future__ import annotations

import os
from collections.abc import Callable

from ..errors import CmosnoiseError

#: how long a client tries an existing scheduler's address before ``--scheduler`` is said to be unreachable
CONNECT_TIMEOUT = "10s"


def connect(scheduler: str | None, workers: int | None, say: Callable[[str], None] = lambda m: None):
    """A Dask client: an existing scheduler's, or a LocalCluster of processes on this machine (loopback).

    Parameters
    ----------
    scheduler : str or None
        An existing scheduler's address (``tcp://host:8786``), or None for a LocalCluster.
    workers : int or None
        The LocalCluster's worker processes (default: the core count).
    say : callable
        Told what was started.

    Returns
    -------
    (distributed.Client, LocalCluster or None)
    """
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=CONNECT_TIMEOUT), None
        except (OSError, TimeoutError) as exc:
            raise CmosnoiseError(f"--scheduler {scheduler}: cannot connect ({exc.__class__.__name__}: "
                                 f"{' '.join(str(exc).split())[:160]})") from None
        except ValueError as exc:
            raise CmosnoiseError(f"--scheduler {scheduler!r}: {exc}") from None
    n = workers or os.cpu_count() or 1
    # the worker processes' own Dask logging at ERROR: a signal cancels their tasks, which Dask logs as warnings
    # on the console (read from the environment when a spawned process imports distributed)
    quiet = {"DASK_LOGGING__DISTRIBUTED": "error"}
    saved = {k: os.environ.get(k) for k in quiet}
    os.environ.update(quiet)
    try:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0",
                               env={"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", **quiet})
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    client = Client(cluster)
    say(f"Dask: a LocalCluster of {n} worker process(es); dashboard {client.dashboard_link}")
    return client, cluster


def worker_attribute(name: str, make: Callable[[], object], anywhere: bool = True):
    """A value kept on the Dask worker that runs this task, made by ``make()`` on its first task; outside a
    worker, ``make()``'s value kept nowhere (``anywhere``) or None.

    Parameters
    ----------
    name : str
        The value's name on the worker.
    make : callable
        Makes it.
    anywhere : bool
        Outside a worker, make it all the same (True) or give None (False).

    Returns
    -------
    object
    """
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return make() if anywhere else None
    attribute = "_cmosnoise_" + name
    value = getattr(worker, attribute, None)
    if value is None:
        value = make()
        setattr(worker, attribute, value)
    return value


def task_result(future, what: str):
    """A Dask future's result; a worker's failure past its retries as one line naming ``what``, not Dask's
    traceback.

    Parameters
    ----------
    future : distributed.Future
    what : str
        What the task was, for the message.

    Returns
    -------
    object
        The task's result.
    """
    try:
        return future.result()
    except CmosnoiseError:
        raise
    except Exception as exc:
        first = (str(exc).strip().splitlines() or [""])[0][:200]
        raise CmosnoiseError(f"{what} failed: {type(exc).__name__}: {first}") from None


def disconnect(client, cluster) -> None:
    """Close the Dask client and cluster without their shutdown chatter (closed streams, cancelled heartbeats).

    Parameters
    ----------
    client : distributed.Client
    cluster : LocalCluster or None
    """
    import logging

    from .logs import quieted

    with quieted(("distributed", "tornado", "asyncio"), logging.CRITICAL):
        client.close()
        if cluster is not None:
            cluster.close()
