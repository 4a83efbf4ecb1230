"""The one exception type for mistakes a user can fix.

The command line turns a :class:`CmosnoiseError` into one line on stderr and
exit status 2; anything else is a bug and keeps its traceback. It is a
``ValueError``, so code that catches bad values catches it too.
"""


class CmosnoiseError(ValueError):
    """Bad input: the message names the parameter, the value and what is allowed."""


class Terminated(BaseException):
    """Ctrl-C, SIGTERM or SIGHUP during a command: unwinds like KeyboardInterrupt, so output folders clean up.

    Its own type (not KeyboardInterrupt, which the command-line library
    turns into a silent status 130) so that the command line can say which
    signal stopped it and exit with 128 + its number.
    """

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum
