"""colour-science (and colour-demosaicing, which imports it), imported without the global change its import makes.

``import colour`` calls ``numpy.set_printoptions(legacy="1.13")`` for the whole process: NumPy's floats then print
with 12 significant digits, and what is written through their text (pandas' CSV of a float column, for one)
loses digits. cmosnoise imports it only here, and puts NumPy's print options back as they were.

Examples
--------
>>> import numpy as np
>>> from cmosnoise import colour_lib
>>> before = np.get_printoptions()
>>> colour = colour_lib.colour()
>>> np.get_printoptions() == before
True
"""

from __future__ import annotations

import contextlib

__all__ = ["colour", "colour_demosaicing"]


@contextlib.contextmanager
def _printoptions_kept():
    import numpy as np

    kept = np.get_printoptions()
    try:
        yield
    finally:
        np.set_printoptions(**kept)


def colour():
    """The ``colour`` package (colour-science), NumPy's print options as they were.

    Returns
    -------
    module
    """
    with _printoptions_kept():
        import colour as module
    return module


def colour_demosaicing():
    """The ``colour_demosaicing`` package, NumPy's print options as they were.

    Returns
    -------
    module
    """
    with _printoptions_kept():
        import colour_demosaicing as module
    return module
