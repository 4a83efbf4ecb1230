"""Random streams keyed by what they are for (docs/model.md section 1).

A sensor instance is a configuration plus a seed. Each stage draws its fixed
pattern from a counter-based stream keyed by ``(seed, FIXED, stage, part)``
with counter (pixel, 0, 0, block), and its temporal noise from one keyed by
``(seed, TEMPORAL, stage)`` with counter (pixel, frame, sequence, try). So
frame ``k``, and any rectangle of any fixed map, is the same whether made one
by one, in chunks, out of order, cropped, in tiles or on different machines,
and switching one stage on or off, or changing one parameter, leaves every
other random number unchanged.

Examples
--------
>>> from cmosnoise import seeds
>>> seeds.fixed_key(0, "prnu") == seeds.fixed_key(0, "prnu")   # a map's key: (seed, stage) alone
True
"""

import functools

import numpy as np

from ..engine.fixed_maps import pixel_index  # noqa: F401 - the address of a pixel, where the stages look for it
from ..engine.samplers import Stream

FIXED = 0
TEMPORAL = 1

#: frame series ("sequences") of one sensor instance: each has its own temporal noise
SEQ_SCENE = 0  #: the run's frames
SEQ_DARK_CALIBRATION = 1  #: the dark frames averaged into a master dark
SEQ_EMVA_BRIGHT = 100  #: EMVA 1288 photon-transfer series, bright pairs
SEQ_EMVA_DARK = 101  #: EMVA 1288 photon-transfer series, dark pairs
SEQ_EMVA_STACK_BRIGHT = 102  #: EMVA 1288 bright stack (spatial statistics)
SEQ_EMVA_STACK_DARK = 103  #: EMVA 1288 dark stack
SEQ_EMVA_DARK_SERIES = 104  #: EMVA 1288 dark-current series (long dark pairs, for a cooled sensor)

#: stage numbers of docs/model.md section 2; they key the random streams.
STAGE_IDS = {
    "prnu": 2,
    "crosstalk": 3,
    "dark_current": 4,
    "shot_noise": 5,
    "source_follower": 6,
    "row_noise": 7,
    "column_noise": 8,
    "pixel_offset": 10,
    "black_level": 11,
    "read_noise": 12,  # keys no stream since scheme 3: its noise is the source follower's sine normal
    "source_follower_rts": 13,
    "dark_current_rts": 14,
    "defects": 15,
    "row_noise_flicker": 16,  # the 1/f row offsets in readout order (row_noise.spectrum = one_over_f)
    "column_noise_flicker": 17,  # each column amplifier's 1/f noise over frames
    "column_noise_alternating": 18,  # the even and the odd columns' banks' offsets per frame
    "source_follower_flicker": 19,  # each pixel's 1/f flicker level without CDS
}


@functools.lru_cache(maxsize=1024)  # a pure function; a SeedSequence costs some 9 us, five of them a sensor
def fixed_key(seed: int, stage: str, part: int = 0) -> tuple[int, int]:
    """The two 32-bit key words of a stage's fixed map ``part``, from ``(seed, FIXED, stage, 2**31 + part)``.

    A map drawn from it is addressed per pixel (or per row, per column), as
    the temporal noise: pixel ``i``'s value depends on (seed, stage, part, i)
    alone, so any rectangle of the map is made without the rest
    (:mod:`cmosnoise.engine.fixed_maps`). ``part`` separates the maps of one
    stage (e.g. column sigma, VFPN offsets, column gains), so switching one
    off leaves the others.

    Parameters
    ----------
    seed : int
        The sensor instance's seed.
    stage : str
        The stage's name (a key of ``STAGE_IDS``).
    part : int
        Which of the stage's maps.

    Returns
    -------
    (int, int)
        Philox4x32's two key words.
    """
    ss = np.random.SeedSequence(seed, spawn_key=(FIXED, STAGE_IDS[stage], 2**31 + part))
    k0, k1 = ss.generate_state(2, np.uint32)
    return int(k0), int(k1)


def stream_key(seed: int, stage: str) -> tuple[int, int]:
    """The two 32-bit key words of a stage's temporal noise (Philox4x32), from ``(seed, TEMPORAL, stage)``.

    Parameters
    ----------
    seed : int
        The sensor instance's seed.
    stage : str
        The stage's name (a key of ``STAGE_IDS``).

    Returns
    -------
    (int, int)
        Philox4x32's two key words.
    """
    ss = np.random.SeedSequence(seed, spawn_key=(TEMPORAL, STAGE_IDS[stage]))
    k0, k1 = ss.generate_state(2, np.uint32)
    return int(k0), int(k1)


def temporal_stream(seed: int, stage: str, frame: int, sequence: int = SEQ_SCENE) -> Stream:
    """A stage's temporal random numbers in frame ``frame`` (0-based) of frame series ``sequence``.

    Counter-based (docs/model.md section 1): the draw of pixel ``i`` depends on
    nothing but (seed, stage, frame, sequence, i), so frames, crops, threads
    and machines never change a bit.

    Parameters
    ----------
    seed : int
        The sensor instance's seed.
    stage : str
        The stage's name (a key of ``STAGE_IDS``).
    frame : int
        The frame's index, >= 0.
    sequence : int
        The frame series (the scene's, a master dark's, ...).

    Returns
    -------
    Stream
        Draws addressed by pixel index (:class:`cmosnoise.engine.samplers.Stream`).
    """
    if frame < 0:
        raise ValueError(f"frame index must be >= 0, got {frame}")
    return Stream(stream_key(seed, stage), int(frame), int(sequence))
