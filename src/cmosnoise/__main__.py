"""``python -m cmosnoise``: the command line."""

from .app.entry import main

main()
