"""``python -m cmosnoise``: the command line."""

from .app.cli import main

main()
