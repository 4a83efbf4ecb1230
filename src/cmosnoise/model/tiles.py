"""A sensor of any size in tiles: each tile's fixed maps, scene and mean charge made alone, its frames bit for bit
that rectangle of the whole sensor's.

Every random number of the model is addressed by the pixel (docs/model.md section 1), so a tile needs nothing of
the rest of the sensor but what crosstalk reads: the photo-charge of the neighbouring pixels. A tile is therefore
made as a :class:`~cmosnoise.model.sensor.Sensor` window with a margin of :data:`HALO` pixels around it (cut at the
sensor's edges), and its frames are rendered inside the margin. The sparse populations (random telegraph traps,
blinking pixels, defects) are drawn once for the whole sensor and shared by every tile.

>>> from cmosnoise import Sensor, load_config
>>> from cmosnoise.model import tiles
>>> spec = load_config(extra={"sensor": {"width": 96, "height": 64}})
>>> tiling = tiles.Tiling(spec, 32)
>>> len(tiling.regions), tiling.regions[0]
(6, (0, 32, 0, 32))
>>> part = tiling.frame(tiling.regions[4], 0)                  # frame 0 of one tile, made alone
>>> whole = Sensor(spec).expose().frame(0)
>>> bool((part == whole[32:64, 32:64]).all())
True
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..config import Config
from ..errors import CmosnoiseError
from . import scene as scene_mod
from .fixed_pattern import FixedPattern
from .sensor import Exposure, Sensor, as_spec
from .spec import SensorSpec

#: pixels around a tile that its window holds: crosstalk reads one neighbour; two keep the CFA's 2 x 2 phase
HALO = 2


#: the smallest window: a sensor's first 2 x 2 cell (its stages, its dark state, its populations)
CORNER = (0, 2, 0, 2)


def populations(spec: SensorSpec) -> FixedPattern:
    """The sparse populations of a sensor (random telegraph traps, blinking pixels, defects), drawn once for the
    whole sensor, to share between its tiles: the fixed pattern of its :data:`CORNER` window.

    Parameters
    ----------
    spec : SensorSpec
        The sensor.

    Returns
    -------
    FixedPattern
        Its ``traps``, ``blinkers`` and ``defects`` are the whole sensor's.

    Examples
    --------
    >>> from cmosnoise import load_config
    >>> from cmosnoise.model import tiles
    >>> spec = load_config(extra={"sensor": {"width": 64, "height": 48}, "defects": {"enabled": True}})
    >>> tiles.populations(spec).defects.shape
    (48, 64)
    """
    return Sensor(spec, window=CORNER).fixed_pattern


def grid(shape: tuple[int, int], size: int) -> list[tuple[int, int, int, int]]:
    """The tiles of a sensor, row by row: ``size`` x ``size`` squares, cut at the right and bottom edges.

    Parameters
    ----------
    shape : (rows, cols)
        The sensor's size, pixels.
    size : int
        The tile's side, pixels: even, at least 16 (a raw TIFF's tiles are multiples of 16: use one of those to
        write them).

    Returns
    -------
    list of (row0, row1, col0, col1)
        Every tile, row-major (the order a tiled TIFF stores them in).

    Examples
    --------
    >>> from cmosnoise.model import tiles
    >>> tiles.grid((40, 70), 32)
    [(0, 32, 0, 32), (0, 32, 32, 64), (0, 32, 64, 70), (32, 40, 0, 32), (32, 40, 32, 64), (32, 40, 64, 70)]
    """
    size = check_size(size)
    rows, cols = shape
    return [(r, min(r + size, rows), c, min(c + size, cols)) for r in range(0, rows, size)
            for c in range(0, cols, size)]


def check_size(size) -> int:
    """``size`` as a tile side, or a one-line error naming what is allowed.

    Parameters
    ----------
    size : int
        A tile's side, pixels.

    Returns
    -------
    int

    Examples
    --------
    >>> from cmosnoise.model import tiles
    >>> tiles.check_size(2048)
    2048
    """
    try:
        value = int(size)
        ok = value == size and value >= 16 and value % 16 == 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise CmosnoiseError(f"tile = {size!r}: give a tile side in pixels, a multiple of 16 of at least 16 "
                             "(a TIFF's tiles are multiples of 16), e.g. 1024")
    return value


def window_of(region: tuple[int, int, int, int], shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """The window a tile is made in: ``region`` with :data:`HALO` pixels around it, cut at the sensor's edges.

    Parameters
    ----------
    region : (row0, row1, col0, col1)
        The tile; ``row0`` and ``col0`` even.
    shape : (rows, cols)
        The sensor's size.

    Returns
    -------
    (row0, row1, col0, col1)

    Examples
    --------
    >>> from cmosnoise.model import tiles
    >>> tiles.window_of((0, 32, 32, 64), (48, 64))
    (0, 34, 30, 64)
    """
    r0, r1, c0, c1 = region
    return max(r0 - HALO, 0), min(r1 + HALO, shape[0]), max(c0 - HALO, 0), min(c1 + HALO, shape[1])


class Tiling:
    """A sensor cut in tiles of ``size``, each made alone (its window's fixed maps, scene and mean charge).

    Parameters
    ----------
    config : SensorSpec, Config, dict, str or Path
        The sensor, as :class:`~cmosnoise.model.sensor.Sensor` takes it.
    size : int
        The tile's side, pixels (:func:`grid`).
    scene : str, optional
        A built-in scene or an image file (default: the configuration's); each tile renders its own rectangle.
    sequence : int
        The frame series (:meth:`~cmosnoise.model.sensor.Sensor.expose`).

    Examples
    --------
    >>> from cmosnoise import load_config
    >>> from cmosnoise.model import tiles
    >>> tiling = tiles.Tiling(load_config(extra={"sensor": {"width": 64, "height": 48}}), 32, "flat:0.5")
    >>> [raw.shape for raw in tiling.frames(tiling.regions[1], 2)]
    [(32, 32), (32, 32)]
    """

    def __init__(self, config: SensorSpec | Config | dict | str | Path, size: int, scene: str | None = None,
                 sequence: int = 0):
        self.spec = as_spec(config)
        self.size = check_size(size)
        self.scene = scene
        self.sequence = sequence
        #: every tile, row-major
        self.regions = grid(self.spec.shape, self.size)
        self._populations: FixedPattern | None = None
        c = self.spec.config
        source = scene if scene is not None else c.scene.source
        #: the scene as each tile draws it: a built-in by its name (drawn for the window alone); a picture (a file,
        #: the photo, any source seen through scene.window) decoded once here (scene.prepare), a region per tile
        self._source = source
        self._picture = None
        if scene_mod.builtin_name(source) in (None, "photo") or c.scene.window is not None:
            self._picture = self.spec.focal_plane.prepare(source, c.scene)

    @property
    def populations(self) -> FixedPattern | None:
        """The whole sensor's sparse populations, shared by every tile (drawn with the first tile)."""
        return self._populations

    def share(self, populations: FixedPattern | None) -> None:
        """Take the sparse populations another :class:`Tiling` of the same sensor drew (a Dask worker's copy).

        Parameters
        ----------
        populations : FixedPattern or None
            :attr:`populations` of another tiling of this sensor, or :func:`populations` of it; None: draw them
            with the next tile.

        Examples
        --------
        >>> from cmosnoise import load_config
        >>> from cmosnoise.model import tiles
        >>> spec = load_config(extra={"sensor": {"width": 64, "height": 48}})
        >>> tiling = tiles.Tiling(spec, 32)
        >>> tiling.share(tiles.populations(spec))
        >>> tiling.populations is not None
        True
        """
        self._populations = populations

    def exposure(self, region: tuple[int, int, int, int]) -> Exposure:
        """The exposure of the window around tile ``region``: its fixed maps, scene and mean charge.

        Parameters
        ----------
        region : (row0, row1, col0, col1)
            A tile of :attr:`regions` (or any rectangle with even ``row0`` and ``col0``).

        Returns
        -------
        Exposure
            Its frames' ``region=`` is the tile.

        Examples
        --------
        >>> from cmosnoise import load_config
        >>> from cmosnoise.model import tiles
        >>> tiling = tiles.Tiling(load_config(extra={"sensor": {"width": 64, "height": 48}}), 32)
        >>> shot = tiling.exposure((0, 32, 32, 64))
        >>> shot.sensor.window, shot.frame(0, region=(0, 32, 32, 64)).shape
        ((0, 34, 30, 64), (32, 32))
        """
        window = window_of(region, self.spec.shape)
        sensor = Sensor(self.spec, window=window, populations=self._populations)
        if self._populations is None:
            self._populations = sensor.fixed_pattern
        if self._picture is None:
            return sensor.expose(self._source, sequence=self.sequence)
        # the lens's blocks are fixed to the whole sensor: the tile's signal is that crop of the whole
        signal = self.spec.focal_plane.pixel_signal(self._picture, sensor.cfa, window)
        return Exposure(sensor, signal, self.sequence)

    def frames(self, region: tuple[int, int, int, int], n: int, first: int = 0,
               electrons: bool = False) -> Iterator[np.ndarray | tuple[np.ndarray, np.ndarray]]:
        """Frames ``first`` to ``first + n - 1`` of tile ``region``, one at a time: raw (h, w) uint16 DN (float32
        e- with the ADC off), or (raw, electrons float32 e-) with ``electrons``.

        Parameters
        ----------
        region : (row0, row1, col0, col1)
            The tile.
        n : int
            How many frames.
        first : int
            The first frame's number.
        electrons : bool
            Also the charge at the ADC input.

        Returns
        -------
        iterator
            Each frame equals that rectangle of the whole sensor's frame, bit for bit.

        Examples
        --------
        >>> from cmosnoise import load_config
        >>> from cmosnoise.model import tiles
        >>> tiling = tiles.Tiling(load_config(extra={"sensor": {"width": 64, "height": 48}}), 32)
        >>> [(raw.dtype.name, e.dtype.name) for raw, e in tiling.frames((32, 48, 0, 32), 2, electrons=True)]
        [('uint16', 'float32'), ('uint16', 'float32')]
        """
        shot = self.exposure(region)
        if electrons:
            yield from shot.frames_with_electrons(n, first, region)
            return
        for k in range(first, first + n):
            yield shot.frame(k, region=region)

    def frame(self, region: tuple[int, int, int, int], k: int) -> np.ndarray:
        """Frame ``k`` of tile ``region`` (:meth:`frames`): the tile is made for this call; for several frames of one
        tile, :meth:`frames` makes it once.

        Parameters
        ----------
        region : (row0, row1, col0, col1)
            The tile.
        k : int
            The frame's number.

        Returns
        -------
        (h, w) array
            uint16 DN, or float32 e- with the ADC off.

        Examples
        --------
        >>> from cmosnoise import load_config
        >>> from cmosnoise.model import tiles
        >>> tiling = tiles.Tiling(load_config(extra={"sensor": {"width": 64, "height": 48}}), 32)
        >>> tiling.frame((32, 48, 32, 64), 5).shape
        (16, 32)
        """
        return next(self.frames(region, 1, k))
