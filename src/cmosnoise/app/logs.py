"""Other libraries' loggers, kept quiet while a command runs (the command says what matters in its own words)."""

from __future__ import annotations

import contextlib
import logging


@contextlib.contextmanager
def quieted(names: tuple[str, ...], level: int = logging.ERROR):
    """Raise the level of the loggers ``names`` to ``level`` inside the block; their own levels come back after."""
    loggers = [logging.getLogger(n) for n in names]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(level)
    try:
        yield
    finally:
        for lg, old in zip(loggers, levels):
            lg.setLevel(old)
