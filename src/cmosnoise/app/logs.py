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


class _Stderr(logging.Handler):
    """Writes ``cmosnoise: message`` to whatever ``sys.stderr`` is when the record comes (a test's capture too)."""

    def emit(self, record: logging.LogRecord) -> None:
        import sys

        try:
            sys.stderr.write(f"cmosnoise: {record.getMessage()}\n")
            sys.stderr.flush()
        except Exception:  # noqa: BLE001 - a closed stderr must not stop the command
            self.handleError(record)


@contextlib.contextmanager
def said():
    """cmosnoise's own log (``logging.getLogger("cmosnoise")``, what the layers below report: a kernel compiled,
    a folder restored) on stderr at INFO and above while a command runs; as it was after."""
    logger = logging.getLogger("cmosnoise")
    handler, old = _Stderr(logging.INFO), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(old)
