"""Stage 15, manufacturing defects: dead, stuck, low- and high-gain pixels, hot clusters, bad columns and rows.

A fixed pattern at rates in parts per million, each pixel (or line) drawn
from Philox under the stage's fixed key (docs/model.md section 1), so a tile
of the pattern is the same tile of the whole sensor:

- pixel ``i``'s kind from the first uniform of block (i, 0, 0, 0): below
  ``dead_ppm 1e-6`` dead, then stuck, low gain, high gain, in that order of
  the cumulative rates; its level or factor from block (i, 1, 0, 0);
- a cluster starts at pixel ``i`` when block (i, 2, 0, 0)'s first uniform is
  below ``clusters.ppm 1e-6``; its size from block (i, 3, 0, 0) by the size
  weights; it grows by adding, at try ``j``, the neighbour (up, down, left or
  right) of a member, both from block (i, 4, j, 0), until it has its size;
- column ``c`` from blocks (c, 5, 0, 0) (kind) and (c, 6, 0, 0) (size, sign);
  row ``r`` from (r, 7, 0, 0) and (r, 8, 0, 0).

What each does (all fixed; the temporal noise acts on them as on any pixel):

- a dead pixel collects no charge (photo and dark); a low- or high-gain
  pixel, and every pixel of a gain line, collects ``factor`` times its charge
  (before shot noise);
- a cluster's pixels are hot: each adds ``rate_e_per_s`` times the
  integration time to its dark charge;
- an offset line adds its offset (e-) at the readout, with the fixed row and
  column offsets (stages 7 and 8);
- a stuck pixel or line reads ``round(level * top code)`` whatever it
  collected (with the ADC off: ``level * full well`` e-).

The kind codes are bits, so a pixel that is two things carries both in the
ground truth's mask (:mod:`cmosnoise.analysis.ground_truth`). As
``cmosnoise.pixel_defects`` it stands beside the ISP's correction of these
pixels, ``cmosnoise.defect_correction`` (``cmosnoise.defects``).

Examples
--------
>>> from cmosnoise import pixel_defects
>>> pixel_defects.cluster_size([0.5, 0.5], [0.2, 0.7]).tolist()
[2, 3]
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields

import numpy as np

from ...engine.philox import uniform_pair
from ...engine.telegraph import in_region
from .random_telegraph import affected

#: kind bits (the defect mask's, :data:`cmosnoise.analysis.ground_truth.MASK_BITS`)
CLUSTER, DEAD, STUCK, LOW_GAIN, HIGH_GAIN, BAD_COLUMN, BAD_ROW = 4, 8, 16, 32, 64, 128, 256
#: a line's kind
LINE_OFFSET, LINE_GAIN, LINE_STUCK = 1, 2, 3
#: tries a cluster gets to grow per pixel of its size (at a corner some neighbours are outside)
_TRIES_PER_PIXEL = 16
_WORD_PIXEL, _WORD_PIXEL_VALUE, _WORD_CLUSTER, _WORD_CLUSTER_SIZE, _WORD_GROW = 0, 1, 2, 3, 4
_WORD_COLUMN, _WORD_ROW = 5, 7  # and + 1: the line's size and sign


@dataclass(frozen=True)
class Lines:
    """Bad columns or rows.

    Parameters
    ----------
    index : (n,) int64 array
        The lines, ascending.
    kind : (n,) array
        Each line's kind (LINE_OFFSET, LINE_GAIN, LINE_STUCK).
    value : (n,) float64 array
        Its offset (e-), gain factor, or stuck level (a fraction of the top code).
    """

    index: np.ndarray
    kind: np.ndarray
    value: np.ndarray

    def of(self, kind: int) -> tuple[np.ndarray, np.ndarray]:
        """(indices, values) of the lines of one kind."""
        keep = self.kind == kind
        return self.index[keep], self.value[keep]


@dataclass(frozen=True)
class Defects:
    """A sensor's defects. Pixels are addressed ``r * cols + c`` (uint64, ascending).

    Parameters
    ----------
    shape : (rows, cols)
        The sensor's.
    pixel_index : (n,) uint64 array
        The defective pixels.
    pixel_kind : (n,) uint8 array
        DEAD, STUCK, LOW_GAIN or HIGH_GAIN.
    pixel_value : (n,) float64 array
        The stuck level (a fraction of the top code) or the gain factor (0 for dead).
    cluster_index : (m,) uint64 array
        The hot pixels of every cluster.
    cluster_id : (m,) int64 array
        The pixel each one's cluster started from.
    cluster_sizes : (k,) int64 array
        Each cluster's size, in the order of their start.
    hot_e_per_s : float
        A cluster pixel's extra dark current, e-/s.
    columns, rows : Lines
        The bad lines.
    """

    shape: tuple[int, int]
    pixel_index: np.ndarray
    pixel_kind: np.ndarray
    pixel_value: np.ndarray
    cluster_index: np.ndarray
    cluster_id: np.ndarray
    cluster_sizes: np.ndarray
    hot_e_per_s: float
    columns: Lines
    rows: Lines

    @property
    def nbytes(self) -> int:
        parts = [getattr(self, f.name) for f in fields(self)] + [getattr(lines, f.name) for lines in (self.columns, self.rows)
                                                                 for f in fields(lines)]
        return sum(a.nbytes for a in parts if isinstance(a, np.ndarray))

    def kind_of(self, kind: int) -> tuple[np.ndarray, np.ndarray]:
        """(pixel indices, values) of the pixel defects of one kind."""
        keep = self.pixel_kind == kind
        return self.pixel_index[keep], self.pixel_value[keep]

    @functools.cached_property
    def has_charge_effect(self) -> bool:
        """Whether a pixel's mean charge changes (dead, gain pixels or lines, clusters)."""
        return bool(np.any(self.pixel_kind != STUCK) or self.cluster_index.size
                    or np.any(self.columns.kind == LINE_GAIN) or np.any(self.rows.kind == LINE_GAIN))

    @functools.cached_property
    def has_offsets(self) -> tuple[bool, bool]:
        """(rows, columns): whether any line carries an offset."""
        return bool(np.any(self.rows.kind == LINE_OFFSET)), bool(np.any(self.columns.kind == LINE_OFFSET))

    @functools.cached_property
    def has_stuck(self) -> bool:
        """Whether a pixel or a line reads a stuck code (asked every frame: worked out once)."""
        return bool(np.any(self.pixel_kind == STUCK) or np.any(self.columns.kind == LINE_STUCK)
                    or np.any(self.rows.kind == LINE_STUCK))


def _pick(levels, u: np.ndarray) -> np.ndarray:
    """One of ``levels`` per uniform, each with probability 1 / len(levels)."""
    levels = np.asarray(levels, np.float64)
    return levels[np.minimum((u * levels.size).astype(np.int64), levels.size - 1)]


def _between(bounds, u: np.ndarray) -> np.ndarray:
    lo, hi = bounds
    return lo + u * (hi - lo)


def _lines(section, key: tuple[int, int], count: int, word: int) -> Lines:
    ppm = (section.offset_ppm, section.gain_ppm, section.stuck_ppm)
    index, u = affected(sum(ppm), key, (1, count), word)
    cuts = np.cumsum(ppm) * 1e-6
    kind = 1 + np.searchsorted(cuts, u, side="right")  # u < cuts[0]: offset, < cuts[1]: gain, else stuck
    kind = np.minimum(kind, LINE_STUCK).astype(np.uint8)
    k0, k1 = (np.uint64(w) for w in key)
    zero = np.zeros(index.shape, np.uint64)
    a1, a2 = uniform_pair(index, zero + np.uint64(word + 1), zero, zero, k0, k1)
    value = np.where(kind == LINE_OFFSET, _between(section.offset_e, a1) * np.where(a2 < 0.5, -1.0, 1.0),
                     np.where(kind == LINE_GAIN, _between(section.gain, a1), _pick(section.stuck_levels, a1)))
    return Lines(index.astype(np.int64), kind, value.astype(np.float64))


def cluster_size(weights, u: np.ndarray) -> np.ndarray:
    """Cluster sizes from uniforms by the inverse CDF of the sizes' relative weights.

    Parameters
    ----------
    weights : sequence of float
        The relative weights of sizes 2, 3, ...
    u : array
        Uniforms in [0, 1).

    Returns
    -------
    int array, the shape of ``u``
        Sizes 2, 3, ...
    """
    w = np.asarray(weights, np.float64)
    cdf = np.cumsum(w) / w.sum()
    return 2 + np.minimum(np.searchsorted(cdf, u, side="right"), w.size - 1)


def _grow(seed: int, size: int, shape: tuple[int, int], k0, k1) -> list[int]:
    """The pixels of the cluster that starts at ``seed``: it grows by a random neighbour of a random member."""
    rows, cols = shape
    members = [int(seed)]
    tries = np.arange(_TRIES_PER_PIXEL * size, dtype=np.uint64)
    zero = np.zeros(tries.shape, np.uint64)
    u_member, u_dir = uniform_pair(zero + np.uint64(seed), zero + np.uint64(_WORD_GROW), tries, zero, k0, k1)
    steps = ((-1, 0), (1, 0), (0, -1), (0, 1))
    for a, b in zip(u_member, u_dir):
        if len(members) == size:
            break
        r, c = divmod(members[min(int(a * len(members)), len(members) - 1)], cols)
        dr, dc = steps[min(int(b * 4), 3)]
        r, c = r + dr, c + dc
        if 0 <= r < rows and 0 <= c < cols and r * cols + c not in members:
            members.append(r * cols + c)
    return members


def draw(section, key: tuple[int, int], shape: tuple[int, int]) -> Defects:
    """The defects of a ``defects`` section on a sensor (see the module docstring for the streams).

    Parameters
    ----------
    section : DefectsSection
        The configuration's ``defects``.
    key : (int, int)
        The stage's fixed Philox key.
    shape : (rows, cols)
        The sensor's.

    Returns
    -------
    Defects
    """
    rows, cols = shape
    k0, k1 = (np.uint64(w) for w in key)
    s = section
    ppm = (s.dead_ppm, s.stuck_ppm, s.low_gain_ppm, s.high_gain_ppm)
    index, u = affected(sum(ppm), key, shape, _WORD_PIXEL)
    cuts = np.cumsum(ppm) * 1e-6
    which = np.minimum(np.searchsorted(cuts, u, side="right"), 3)
    kind = np.array([DEAD, STUCK, LOW_GAIN, HIGH_GAIN], np.uint8)[which]
    zero = np.zeros(index.shape, np.uint64)
    a1, _ = uniform_pair(index, zero + np.uint64(_WORD_PIXEL_VALUE), zero, zero, k0, k1)
    value = np.select([kind == DEAD, kind == STUCK, kind == LOW_GAIN],
                      [np.zeros_like(a1), _pick(s.stuck_levels, a1), _between(s.low_gain, a1)],
                      _between(s.high_gain, a1))
    seeds, _ = affected(s.clusters.ppm, key, shape, _WORD_CLUSTER)
    zero = np.zeros(seeds.shape, np.uint64)
    su, _ = uniform_pair(seeds, zero + np.uint64(_WORD_CLUSTER_SIZE), zero, zero, k0, k1)
    sizes = cluster_size(s.clusters.size_weights, su)
    members, ids, grown_sizes = [], [], []
    for seed, size in zip(seeds, sizes):
        grown = _grow(int(seed), int(size), shape, k0, k1)
        members += grown
        ids += [int(seed)] * len(grown)
        grown_sizes.append(len(grown))
    # two clusters that touch share their pixels once (the first to start keeps them)
    members, first = np.unique(np.asarray(members, np.uint64), return_index=True)
    return Defects(
        shape=(rows, cols), pixel_index=index, pixel_kind=kind, pixel_value=value.astype(np.float64),
        cluster_index=members, cluster_id=np.asarray(ids, np.int64)[first],
        cluster_sizes=np.asarray(grown_sizes, np.int64), hot_e_per_s=float(s.clusters.rate_e_per_s),
        columns=_lines(s.columns, key, cols, _WORD_COLUMN), rows=_lines(s.rows, key, rows, _WORD_ROW))


def _lines_inside(lines: Lines, kind: int, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    index, value = lines.of(kind)
    keep = (index >= lo) & (index < hi)
    return index[keep] - lo, value[keep]


def collected(photo_e: np.ndarray, dark_e: np.ndarray | None, defects: Defects, region: tuple[int, int, int, int],
              exposure_s: float) -> tuple[np.ndarray, np.ndarray | None]:
    """The mean photo- and dark charge of ``region`` with the defects (new arrays; the inputs are kept).

    Parameters
    ----------
    photo_e, dark_e : ndarray, (rows, cols) float32
        The region's mean photo-charge and dark charge without defects, e- (``dark_e`` None: no dark current).
    defects : Defects
    region : (row0, row1, col0, col1)
        Where ``photo_e`` sits on the sensor.
    exposure_s : float
        The integration time, s (a hot pixel's charge is its rate times it).

    Returns
    -------
    photo, dark : ndarray, (rows, cols) float32
        Gain lines, then gain and dead pixels, scale both; a cluster's pixels
        add their hot charge to ``dark`` (made of zeros when ``dark_e`` is None
        and a cluster falls in the region). Each pixel sees the same
        operations in the same order whatever the region, so a tile is the
        same tile of the whole.
    """
    r0, r1, c0, c1 = region
    cols = defects.shape[1]
    out = [photo_e.copy(), None if dark_e is None else dark_e.copy()]
    for a in out:
        if a is None:
            continue
        at, g = _lines_inside(defects.rows, LINE_GAIN, r0, r1)
        a[at, :] *= g[:, None].astype(np.float32)
        at, g = _lines_inside(defects.columns, LINE_GAIN, c0, c1)
        a[:, at] *= g[None, :].astype(np.float32)
        gains = defects.pixel_kind != STUCK
        r, c, keep = in_region(defects.pixel_index[gains], region, cols)
        a[r, c] *= defects.pixel_value[gains][keep].astype(np.float32)
    r, c, _ = in_region(defects.cluster_index, region, cols)
    if r.size:
        if out[1] is None:
            out[1] = np.zeros_like(out[0])
        out[1][r, c] += np.float32(defects.hot_e_per_s * exposure_s)
    return out[0], out[1]


def line_offsets(defects: Defects) -> tuple[np.ndarray, np.ndarray]:
    """The offset lines' offsets at the readout.

    Parameters
    ----------
    defects : Defects

    Returns
    -------
    (rows,) and (cols,) float64 arrays
        Per row and per column, e-; 0 off the offset lines.
    """
    rows, cols = defects.shape
    out = []
    for lines, n in ((defects.rows, rows), (defects.columns, cols)):
        a = np.zeros(n)
        at, v = lines.of(LINE_OFFSET)
        a[at] = v
        out.append(a)
    return out[0], out[1]


def stick(raw: np.ndarray, defects: Defects, region: tuple[int, int, int, int], top: float,
          rounded: bool | None = None) -> np.ndarray:
    """``raw`` with the stuck rows, then columns, then pixels at their level.

    Parameters
    ----------
    raw : (rows, cols) array
        The region's frame; changed in place.
    defects : Defects
    region : (row0, row1, col0, col1)
        Where ``raw`` sits on the sensor.
    top : float
        The top code (or the full well, e-, for the ideal readout).
    rounded : bool, optional
        ``round(level * top)`` (a code) or ``level * top``; default: rounded for an unsigned-integer ``raw``.

    Returns
    -------
    array
        ``raw``.
    """
    r0, r1, c0, c1 = region
    rounded = raw.dtype.kind == "u" if rounded is None else rounded

    def value(level):
        v = np.asarray(level) * top
        return np.rint(v) if rounded else v

    at, lv = _lines_inside(defects.rows, LINE_STUCK, r0, r1)
    raw[at, :] = value(lv)[:, None]
    at, lv = _lines_inside(defects.columns, LINE_STUCK, c0, c1)
    raw[:, at] = value(lv)[None, :]
    index, lv = defects.kind_of(STUCK)
    r, c, keep = in_region(index, region, defects.shape[1])
    raw[r, c] = value(lv[keep])
    return raw


def stuck_pixels(defects: Defects, top: float, rounded: bool) -> tuple[np.ndarray, np.ndarray]:
    """Every stuck pixel of the whole sensor once, with the value :func:`stick` gives it.

    Rows, then columns, then pixels, the later winning where they meet, as
    :func:`stick` sets them; for a kernel that sets them in parallel (the GPU's).

    Parameters
    ----------
    defects : Defects
    top : float
        The top code (or the full well, e-).
    rounded : bool
        ``round(level * top)``, or ``level * top``.

    Returns
    -------
    (n,) int64 and (n,) float64 arrays
        The flat pixel indices and their values.
    """
    rows, cols = defects.shape

    def value(level):
        v = np.asarray(level, np.float64) * top
        return np.rint(v) if rounded else v

    at, lv = _lines_inside(defects.rows, LINE_STUCK, 0, rows)
    parts = [((at[:, None] * cols + np.arange(cols)).ravel(), np.repeat(value(lv), cols))]
    at, lv = _lines_inside(defects.columns, LINE_STUCK, 0, cols)
    parts.append(((np.arange(rows)[:, None] * cols + at).ravel(), np.tile(value(lv), rows)))
    index, lv = defects.kind_of(STUCK)
    parts.append((np.asarray(index, np.int64), value(lv)))
    index = np.concatenate([p[0] for p in parts]).astype(np.int64)
    values = np.concatenate([p[1] for p in parts])
    last = index.size - 1 - np.unique(index[::-1], return_index=True)[1]  # each pixel's last setting
    return index[last], values[last]
