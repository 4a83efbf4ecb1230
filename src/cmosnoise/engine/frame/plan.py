"""A frame's plan, and the one table of the frame chain's temporal stages.

:class:`FramePlan` holds what every frame of an exposure shares (the mean
charges, the maps, the ADC). :data:`STAGES` declares each stage that acts
on every frame (in the order its comment explains): its name (as :mod:`cmosnoise.model.seeds`
names it), the temporal stream it draws (a row of the plan's ``keys``), the
kernels' switches that turn its blocks on (each with what turns it on), the
plan fields it reads, and its scalars in the GPU's per-plan table. Everything
the three executable copies of the chain (:mod:`cmosnoise.model.reference`,
the CPU kernel :mod:`.kernel`, the GPU kernel :mod:`.cuda_device`) agree on by
position is derived from it here, by name: the flags array's order
(:data:`SWITCHES`, ``S_*``, :func:`switches`), the key rows (:data:`KEY_ROWS`,
``KEY_*``) and the GPU table's columns (:data:`NUMBERS`, :data:`INTS`, read
through :mod:`.cuda_table`). A new temporal stage is one row here.

The compiled loops take the derived indices as constants. numba's on-disk
cache of the frame kernel is therefore keyed on this file as well as on the
kernel's own (:func:`cmosnoise.engine.jit.keyed_on`): a change of the table
recompiles the kernel instead of loading an older table's indices.
"""

from __future__ import annotations

import collections
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .. import samplers, telegraph


@dataclass(frozen=True)
class FramePlan:
    """What a frame needs that does not change from frame to frame (per sensor and exposure).

    Arrays cover the frame, or its ``window`` (a tile):
    ``noisy_e``/``exact_e``/``sf_sigma_e``/``offset_e`` (rows, cols) float32,
    e-; ``row_offset_e`` (rows,), ``col_sigma_e``, ``col_offset_e``,
    ``col_gain`` (cols,) float64; ``shape`` is always the whole frame's (it
    addresses the random numbers). ``keys`` holds the two key words of the
    streams of :data:`KEY_ROWS`, in its order, (len(KEY_ROWS), 2)
    uint64 (read noise after the gain takes the source follower's second normal).
    A ``None`` switches that term off.
    """

    shape: tuple[int, int]
    keys: np.ndarray
    sequence: int
    full_well_e: float
    noisy_e: np.ndarray | None = None
    exact_e: np.ndarray | None = None
    normal_above_e: float = math.inf
    sf_sigma_e: np.ndarray | None = None
    row_sigma_e: float | None = None
    row_offset_e: np.ndarray | None = None
    col_sigma_e: np.ndarray | None = None
    col_offset_e: np.ndarray | None = None
    col_gain: np.ndarray | None = None
    #: the 1/f row offsets (row_noise.spectrum = one_over_f): ``row_flicker(frame, sequence)`` gives the window's
    #: rows' offsets of a frame, (rows,) float64 e-, added to ``row_offset_e`` (``row_sigma_e`` is then 0)
    row_flicker: Callable[[int, int], np.ndarray] | None = None
    #: the columns' offsets that change from frame to frame (each amplifier's 1/f noise, the even and odd banks'
    #: offsets): ``col_flicker(frame, sequence)``, (cols,) float64 e-, added to ``col_offset_e`` (with 1/f noise
    #: ``col_sigma_e`` is 0)
    col_flicker: Callable[[int, int], np.ndarray] | None = None
    #: (K output DN/e-, black level output DN, the ADC's top code, output DN per ADC code); None: float32 e-
    adc: tuple[float, float, int, int] | None = None
    #: the charge-to-voltage transfer (stage 5b): a nonlinearity.Curve (a cubic, or a table)
    nonlinearity: object | None = None
    offset_e: np.ndarray | None = None  #: per-pixel offsets (rows, cols) float32, e- (stage 5c)
    #: each pixel's 1/f flicker level (source_follower.flicker one_over_f without CDS): ``pixel_flicker(frame,
    #: sequence)`` gives the window's (rows, cols) float32 e-, added to ``offset_e`` (then never None)
    pixel_flicker: Callable[[int, int], np.ndarray] | None = None
    cell_offsets_dn: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  #: black level per 2 x 2 cell position
    frame_black_sigma_dn: float = 0.0  #: the black level's error per frame, DN (keys row 4)
    #: (normal | tukey_lambda, scale DN, shape): from the sine normal of the source follower's block (keys row 1)
    read_noise: tuple[str, float, float] | None = None
    #: source-follower random telegraph noise (stage 6b): the traps, their temporal key, and the CDS interval (s;
    #: None: no CDS, the trap's level)
    traps: telegraph.Telegraphs | None = None
    trap_key: tuple[int, int] = (0, 0)
    cds_interval_s: float | None = None
    #: blinking white pixels (stage 4b): the pixels (size: the rate step, e-/s) and their temporal key
    blinkers: telegraph.Telegraphs | None = None
    blink_key: tuple[int, int] = (0, 0)
    frame_period_s: float = 1.0  #: frame k starts at k frame_period_s (s)
    exposure_s: float = 1.0  #: the exposure of a frame, s (blinking pixels integrate their rate over it)
    blink_noisy: bool = True  #: whether the dark charge is in ``noisy_e`` (with shot noise) or in ``exact_e``
    #: the rectangle of the frame the arrays cover, (row0, row1, col0, col1); None: the whole frame. A tile's plan
    #: holds arrays of its window only (per-pixel maps (h, w), row maps (h,), column maps (w,)); the random numbers
    #: stay addressed by the frame's pixel index
    window: tuple[int, int, int, int] | None = None

    @property
    def origin(self) -> tuple[int, int]:
        """Where the arrays' first pixel sits in the frame, (row, col)."""
        return (0, 0) if self.window is None else (self.window[0], self.window[2])

    @property
    def region(self) -> tuple[int, int, int, int]:
        """The rectangle the arrays cover, (row0, row1, col0, col1): the window, or the whole frame."""
        if self.window is None:
            return 0, self.shape[0], 0, self.shape[1]
        r0, r1, c0, c1 = self.window
        return r0, r1, c0, c1

    def row_offsets(self, frame: int) -> np.ndarray | None:
        """The rows' offsets in frame ``frame``, (rows,) float64 e-: ``row_offset_e``, plus the frame's 1/f row
        offsets when the row noise has them (every copy of the chain adds them so, as one array)."""
        if self.row_flicker is None or self.row_offset_e is None:
            return self.row_offset_e
        return self.row_offset_e + self.row_flicker(int(frame), int(self.sequence))

    def offsets(self, frame: int) -> np.ndarray | None:
        """The pixels' offsets in frame ``frame``, (rows, cols) float32 e-: ``offset_e``, plus each pixel's 1/f
        flicker level of the frame when it has one (one array for every copy of the chain)."""
        if self.pixel_flicker is None or self.offset_e is None:
            return self.offset_e
        return self.offset_e + self.pixel_flicker(int(frame), int(self.sequence))

    def col_offsets(self, frame: int) -> np.ndarray | None:
        """The columns' offsets in frame ``frame``, (cols,) float64 e-: ``col_offset_e``, plus each column
        amplifier's 1/f noise of the frame when it has one."""
        if self.col_flicker is None or self.col_offset_e is None:
            return self.col_offset_e
        return self.col_offset_e + self.col_flicker(int(frame), int(self.sequence))

    @property
    def blink_mean_e(self) -> np.ndarray:
        """The mean charge that holds the dark charge: ``noisy_e`` or ``exact_e``."""
        mean = self.noisy_e if self.blink_noisy else self.exact_e
        if mean is None:
            raise ValueError("a plan with blinking pixels holds their dark charge in noisy_e or exact_e")
        return mean

    @functools.cached_property
    def loggam_table(self) -> np.ndarray:
        """``loggam(n)`` for the counts PTRS's log test meets in this plan (:func:`samplers.loggam_table`)."""
        if self.noisy_e is None:
            return samplers.loggam_table(0.0)
        return samplers.loggam_table(min(float(self.noisy_e.max()), self.normal_above_e))


#: One temporal stage of the frame chain: its ``name`` (a stage of :data:`cmosnoise.model.seeds.STAGE_IDS`), the
#: ``key`` of the stream it draws (a row of :attr:`FramePlan.keys`; None: it draws none of its own), its
#: ``switches``, the plan ``fields`` it reads, and its scalars in the GPU's per-plan table, float (``numbers``) and
#: integer (``ints``).
Stage = collections.namedtuple("Stage", ("name", "key", "switches", "fields", "numbers", "ints"))
#: One switch of the kernels: its ``name``, what it means, and ``on(plan, asked)``, whether a frame of ``plan``
#: has it on (``asked``: :class:`Asked`, what the call asks and what the frame's region holds).
Switch = collections.namedtuple("Switch", ("name", "doc", "on"))
#: What a kernel call asks for beside its plan: the charge at the ADC input (``electrons``), and whether any
#: source-follower trap (``traps``) or blinking pixel (``blinkers``) lies inside the frame's region.
Asked = collections.namedtuple("Asked", ("electrons", "traps", "blinkers"))

#: The frame chain's temporal stages. The loops read each switch, key row and GPU column by an index this module
#: derives from the table by name, never by a typed number. The rows' order is the flags array's order, and the
#: compiled CPU kernel's speed depends on it: with the switches in the chain's order (shot noise, blinking
#: pixels, nonlinearity, ...) the 1080p frame took 38.7 ms on one thread, in this order (the order the kernel
#: was tuned in) 34.1 (benchmarks/kernel_parts.py, AVX-512, the same run). Append a new stage's row at the end.
STAGES = (
    Stage("shot_noise", "shot_noise",
          (Switch("noisy", "a mean charge with shot noise: plan.noisy_e", lambda p, a: p.noisy_e is not None),
           Switch("exact", "a mean charge without shot noise: plan.exact_e", lambda p, a: p.exact_e is not None)),
          ("noisy_e", "exact_e", "normal_above_e", "full_well_e"), ("normal_above", "full_well"), ()),
    Stage("source_follower", "source_follower",
          (Switch("source_follower", "the source follower's noise: plan.sf_sigma_e",
                  lambda p, a: p.sf_sigma_e is not None),),
          ("sf_sigma_e", "pixel_flicker"), (), ()),
    Stage("row_noise", "row_noise",
          (Switch("row", "row noise: plan.row_sigma_e", lambda p, a: p.row_sigma_e is not None),),
          ("row_sigma_e", "row_offset_e", "row_flicker"), ("row_sigma",), ()),
    Stage("column_noise", "column_noise",
          (Switch("column", "column noise and gain: plan.col_gain", lambda p, a: p.col_gain is not None),),
          ("col_sigma_e", "col_offset_e", "col_gain", "col_flicker"), (), ()),
    Stage("adc", None,
          (Switch("adc", "the ADC, codes out: plan.adc", lambda p, a: p.adc is not None),
           Switch("electrons", "the charge at the ADC input out too: asked for, or the ADC off",
                  lambda p, a: a.electrons or p.adc is None)),
          ("adc",), ("k_adc", "black", "top", "step"), ()),
    Stage("nonlinearity", None,
          (Switch("nonlinearity", "the charge-to-voltage curve: plan.nonlinearity",
                  lambda p, a: p.nonlinearity is not None),),
          ("nonlinearity",), ("nl_scale", "nl_a", "nl_b", "nl_c"), ("nl_size",)),
    Stage("pixel_offset", None,
          (Switch("offset", "per-pixel offsets: plan.offset_e", lambda p, a: p.offset_e is not None),),
          ("offset_e",), (), ()),
    Stage("read_noise", None,  # its normal is the source follower's second (scheme 3)
          (Switch("read", "read noise after the gain: plan.read_noise, with the ADC",
                  lambda p, a: p.adc is not None and p.read_noise is not None),),
          ("read_noise",), ("read_scale",), ("read_kind",)),
    Stage("source_follower_rts", None,
          (Switch("traps", "source-follower traps inside the frame's region", lambda p, a: a.traps),),
          ("traps", "trap_key", "cds_interval_s"), ("cds_interval",), ("cds",)),
    Stage("dark_current_rts", None,
          (Switch("blinkers", "blinking pixels inside the frame's region", lambda p, a: a.blinkers),
           Switch("blink_exact", "the blinking pixels' dark charge without shot noise: not plan.blink_noisy",
                  lambda p, a: not p.blink_noisy)),
          ("blinkers", "blink_key", "frame_period_s", "exposure_s", "blink_noisy"), ("frame_period", "exposure"), ()),
    Stage("black_level", "black_level", (), ("cell_offsets_dn", "frame_black_sigma_dn"), ("frame_black_sigma",),
          ()),
)

#: the plan fields no stage owns: where and which frames the random numbers address
ADDRESS_FIELDS = ("shape", "keys", "sequence", "window")

#: The kernels' switches, each (name, what turns it on), in the order of the flags array that the CPU's and the
#: GPU's pixel loops read (:func:`switches` makes it)
SWITCHES = tuple((s.name, s.doc) for stage in STAGES for s in stage.switches)
_SWITCH_ROWS = tuple(s for stage in STAGES for s in stage.switches)
_SWITCH = {name: i for i, (name, _) in enumerate(SWITCHES)}
S_NOISY, S_EXACT, S_SF = _SWITCH["noisy"], _SWITCH["exact"], _SWITCH["source_follower"]
S_ROW, S_COL, S_ADC, S_ELECTRONS = _SWITCH["row"], _SWITCH["column"], _SWITCH["adc"], _SWITCH["electrons"]
S_NL, S_OFFSET, S_READ = _SWITCH["nonlinearity"], _SWITCH["offset"], _SWITCH["read"]
S_TRAPS, S_BLINKERS, S_BLINK_EXACT = _SWITCH["traps"], _SWITCH["blinkers"], _SWITCH["blink_exact"]
#: how many switches a plan has (the flags array's length)
N_SWITCHES = len(SWITCHES)

#: The rows of :attr:`FramePlan.keys`: each temporal stream's stage, as :func:`cmosnoise.model.seeds.stream_key`
#: names it, in row order (the read noise after the gain takes the source follower's second normal)
KEY_ROWS = tuple(stage.key for stage in STAGES if stage.key is not None)
_KEY = {name: i for i, name in enumerate(KEY_ROWS)}
KEY_SHOT, KEY_SF, KEY_ROW = _KEY["shot_noise"], _KEY["source_follower"], _KEY["row_noise"]
KEY_COL, KEY_BLACK = _KEY["column_noise"], _KEY["black_level"]

#: the GPU's per-plan table's columns: each plan's scalars (float64) and integers (int64), by name
#: (:mod:`.cuda_table` gives the device their indices)
NUMBERS = tuple(n for stage in STAGES for n in stage.numbers)
INTS = tuple(n for stage in STAGES for n in stage.ints)


def switches(plan: FramePlan, electrons: bool, traps: bool, blinkers: bool) -> np.ndarray:
    """The kernels' switches of ``plan``, (N_SWITCHES,) bool, each at its place in :data:`SWITCHES`.

    Parameters
    ----------
    plan : FramePlan
    electrons : bool
        Whether the charge at the ADC input is asked for.
    traps, blinkers : bool
        Whether some source-follower traps (blinking pixels) lie inside the frame's region.

    Returns
    -------
    (N_SWITCHES,) bool array
    """
    asked = Asked(electrons, traps, blinkers)
    return np.array([bool(s.on(plan, asked)) for s in _SWITCH_ROWS])
