"""The one exception type for mistakes a user can fix.

The command line turns a :class:`CmosnoiseError` into one line on stderr and
exit status 2; anything else is a bug and keeps its traceback. It is a
``ValueError``, so code that catches bad values catches it too.
"""

import contextlib


class CmosnoiseError(ValueError):
    """Bad input: the message names the parameter, the value and what is allowed.

    Examples
    --------
    >>> from cmosnoise import CmosnoiseError, Sensor
    >>> try:
    ...     Sensor(seed=1.5)
    ... except CmosnoiseError as exc:
    ...     print(exc)
    seed = 1.5: expected a whole number >= 0
    """


class Terminated(BaseException):
    """Ctrl-C, SIGTERM or SIGHUP during a command: unwinds like KeyboardInterrupt, so output folders clean up.

    Its own type (not KeyboardInterrupt, which the command-line library
    turns into a silent status 130) so that the command line can say which
    signal stopped it and exit with 128 + its number.
    """

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


#: signals this process's handler has raised :class:`Terminated` for, not yet acted on. Signals are the
#: process's, so this is too: a library can catch the exception (LLVM's callbacks into Python do, through
#: ctypes), and the record keeps the signal from being lost.
_received: list[int] = []


#: how many :func:`signals_deferred` blocks are open (a commit's renames): a signal inside one is remembered and
#: acted on after it, never in the middle
_deferring = [0]
#: output folders committed whole during the current command (what a signal after the commit must not deny)
_written: list[str] = []


#: seconds a command has, after its first signal, to unwind by itself (an exception that a compiler's callback
#: swallowed, a library's C loop): past them the watchdog removes its temporary output and ends the process
GRACE_S = 4.0
#: what the watchdog runs before it ends the process (each removes a temporary output folder)
_cleanups: dict[int, object] = {}
#: set when the current command is over (the watchdog of its signal then does nothing)
_over = [None]
#: what a job keeps on disk as it goes (a data set's shards, a sweep's rows): each says it in words, for the
#: watchdog's line when the job's own handler never ran
_keeping: dict[int, object] = {}


def signal_received(signum: int, _frame=None):
    """The signal handler of a command: remember the signal, and unwind with :class:`Terminated` (after the
    open :func:`signals_deferred` block, if one is open). The first signal also starts a watchdog: a command
    still running :data:`GRACE_S` seconds later (its exception swallowed inside a compile, say) is ended then,
    its temporary output removed first, so that no command outlives a signal by more than a few seconds."""
    first = not _received
    _received.append(signum)
    if first and _over[0] is not None:
        import threading

        threading.Thread(target=_watchdog, args=(signum, _over[0]), name="cmosnoise-signal-watchdog",
                         daemon=True).start()
    if _deferring[0]:
        return
    raise Terminated(signum)


def _watchdog(signum: int, over) -> None:
    import os
    import signal as signals
    import sys

    if over.wait(GRACE_S):
        return
    while _deferring[0] and not over.wait(0.05):  # a commit's renames finish first
        pass
    if over.is_set():
        return
    for fn in list(_cleanups.values()):
        with contextlib.suppress(Exception):  # the process ends either way
            fn()
    name = "Ctrl-C" if signum == signals.SIGINT else signals.Signals(signum).name
    done = f"; {_kept_now() or written_note() or 'nothing was written'}"
    try:
        sys.stderr.write(f"cmosnoise: interrupted ({name}): stopped after {GRACE_S:g} s{done}\n")
        sys.stderr.flush()
    finally:
        os._exit(128 + signum)


def command_started() -> None:
    """A command begins: no signal, nothing written, a fresh watchdog state."""
    import threading

    clear_terminated()
    _over[0] = threading.Event()


def command_over() -> None:
    """The command has ended (by itself, or unwound by its signal): its watchdog stands down."""
    if _over[0] is not None:
        _over[0].set()
    _over[0] = None


def on_hard_exit(key: int, fn=None) -> None:
    """Register ``fn`` (under ``key``) to run before the watchdog ends the process; ``fn`` None removes it."""
    if fn is None:
        _cleanups.pop(key, None)
    else:
        _cleanups[key] = fn


@contextlib.contextmanager
def signals_deferred():
    """A block that a signal does not cut in two (an output folder's renames): the signal is acted on by the
    next :func:`check_terminated` after it."""
    _deferring[0] += 1
    try:
        yield
    finally:
        _deferring[0] -= 1


def note_written(path) -> None:
    """Record that the output folder ``path`` was committed whole (the command line says so if a signal stops the
    command after it)."""
    _written.append(str(path))


def written() -> list[str]:
    """The output folders committed whole during this command."""
    return list(_written)


def written_note() -> str:
    """How a stopped command's message names the output folders committed before it stopped ("" for none)."""
    return f"{', '.join(_written)} had been written whole before it stopped" if _written else ""


def check_terminated() -> None:
    """Raise :class:`Terminated` if a signal arrived whose exception something swallowed (before committing output)."""
    if _received:
        raise Terminated(_received[0])


def clear_terminated() -> None:
    _received.clear()
    _written.clear()


@contextlib.contextmanager
def keeping(what):
    """A block in which a job writes resumable output as it goes: ``what()`` says in words what it has kept so
    far ("" for nothing). The watchdog's line uses it when the job was ended before its own handler could say so
    (a signal swallowed inside a compile), instead of "nothing was written"."""
    key = id(what)
    _keeping[key] = what
    try:
        yield
    finally:
        _keeping.pop(key, None)


def _kept_now() -> str:
    for what in list(_keeping.values()):
        try:
            said = what()
        except Exception:  # noqa: BLE001 - the process ends either way; the plain line stands
            said = ""
        if said:
            return said
    return ""


def note_kept(exc: BaseException, what: str) -> None:
    """Say on ``exc`` (a signal's, a full disk's, any that stops a command) what the command kept on disk before
    it stopped: the command line prints it instead of "nothing was written" (e.g. "10 of 24 rows kept in
    results.csv; --resume completes it"). The first note stands."""
    if not getattr(exc, "kept", None):
        with contextlib.suppress(AttributeError):  # an exception type without a __dict__
            exc.kept = what
