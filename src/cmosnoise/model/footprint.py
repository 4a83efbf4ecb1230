"""How much memory a sensor or a run needs, estimated from its size before anything is drawn.

Measured with ``/usr/bin/time -f %M`` on ``cmosnoise simulate`` (2 cores,
Python 3.11): about 230 MB for the interpreter and libraries, then per pixel
about 117 bytes for a plain run (fixed-pattern maps, the exposure's mean
images, one frame in flight, statistics), some 35 more with processing or
the report (1080p: 473 and 545 MB in all), and Menon 2007 demosaicing about
100 more (4K with it: 2.3 GB). The estimate rounds these up.
"""

from __future__ import annotations

from ..config import Config
from ..errors import CmosnoiseError
from ..inputs import available_bytes  # noqa: F401 (one place for the fact; callers read it here too)

BASE_BYTES = 300_000_000
PER_PIXEL = {"sensor": 60, "run": 130, "processing": 50, "malvar2004": 60, "menon2007": 130}


def estimate_bytes(config: Config, run: bool = True, pixels: int | None = None) -> int:
    """Peak memory (bytes) of a :class:`~cmosnoise.Sensor` of ``config`` (``run=False``) or of a ``simulate`` run;
    ``pixels``: the pixels it holds at once, where not the whole sensor (a window, a run's tiles in flight)."""
    if pixels is None:
        pixels = config.sensor.width * config.sensor.height
    per = PER_PIXEL["run"] if run else PER_PIXEL["sensor"]
    if run and (config.processing.enabled or config.run.report or config.processing.dark_frames > 0):
        per += PER_PIXEL["processing"] + PER_PIXEL.get(config.processing.demosaic, 0)
    return BASE_BYTES + per * pixels


def check_fits(config: Config, run: bool = True, available: int | None = None, pixels: int | None = None,
               tiled: bool = False) -> None:
    """Raise :class:`CmosnoiseError` when ``config`` would need more memory than is available (``pixels``: those
    held at once, as :func:`estimate_bytes` takes them; ``tiled``: they are a tiled run's)."""
    need = estimate_bytes(config, run, pixels)
    have = available if available is not None else available_bytes()
    if have is not None and need > have:
        w, h = config.sensor.width, config.sensor.height
        what = f"a {w} x {h} sensor ({w * h / 1e6:.0f} MP)"
        if pixels is not None:
            what += f" in pieces of {pixels / 1e6:.1f} MP at once"
        fix = ("make --tile smaller" if tiled else
               "make sensor.width and sensor.height smaller, make it in tiles (simulate --tile 2048)")
        raise CmosnoiseError(
            f"{what} needs about {need / 1e9:.1f} GB of memory"
            f"{' for this run' if run else ''}; this machine has {have / 1e9:.1f} GB available: "
            f"{fix}, or use a machine with more memory"
        )
