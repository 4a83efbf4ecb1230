"""The one exception type for mistakes a user can fix.

The command line turns a :class:`CmosnoiseError` into one line on stderr and
exit status 2; anything else is a bug and keeps its traceback. It is a
``ValueError``, so code that catches bad values catches it too.
"""


class CmosnoiseError(ValueError):
    """Bad input: the message names the parameter, the value and what is allowed."""
