"""The one exception type for mistakes a user can fix.

The command line turns a :class:`CmosnoiseError` into one line on stderr and
exit status 2; anything else is a bug and keeps its traceback. It is a
``ValueError``, so code that catches bad values catches it too.
"""


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


def signal_received(signum: int, _frame=None):
    """The signal handler of a command: remember the signal, and unwind with :class:`Terminated`."""
    _received.append(signum)
    raise Terminated(signum)


def check_terminated() -> None:
    """Raise :class:`Terminated` if a signal arrived whose exception something swallowed (before committing output)."""
    if _received:
        raise Terminated(_received[0])


def clear_terminated() -> None:
    _received.clear()
