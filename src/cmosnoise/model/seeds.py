"""Random streams keyed by what they are for (MODEL.md section 1).

A sensor instance is a configuration plus a seed. Each stage draws its fixed
pattern from a stream keyed by ``(seed, FIXED, stage)`` and its temporal noise
in frame ``k`` from a stream keyed by ``(seed, TEMPORAL, stage, k)``. So frame
``k`` is the same whether frames are made one by one, in chunks, out of order
or on different machines, and switching one stage on or off leaves every other
stage's random numbers unchanged.
"""

import numpy as np

FIXED = 0
TEMPORAL = 1

#: frame series ("sequences") of one sensor instance: each has its own temporal noise
SEQ_SCENE = 0  #: the run's frames
SEQ_DARK_CALIBRATION = 1  #: the dark frames averaged into a master dark
SEQ_EMVA_BRIGHT = 100  #: EMVA 1288 photon-transfer series, bright pairs
SEQ_EMVA_DARK = 101  #: EMVA 1288 photon-transfer series, dark pairs
SEQ_EMVA_STACK_BRIGHT = 102  #: EMVA 1288 bright stack (spatial statistics)
SEQ_EMVA_STACK_DARK = 103  #: EMVA 1288 dark stack

#: stage numbers of MODEL.md section 2; they key the random streams.
STAGE_IDS = {
    "prnu": 2,
    "crosstalk": 3,
    "dark_current": 4,
    "shot_noise": 5,
    "source_follower": 6,
    "row_noise": 7,
    "column_noise": 8,
}


def fixed_rng(seed: int, stage: str, part: int = 0) -> np.random.Generator:
    """Generator for a stage's fixed pattern; the same for every frame.

    ``part`` separates the fixed maps of one stage (e.g. column sigma,
    VFPN offsets, column gains), so switching one off leaves the others.
    """
    ss = np.random.SeedSequence(seed, spawn_key=(FIXED, STAGE_IDS[stage], part))
    return np.random.Generator(np.random.PCG64(ss))


def temporal_rng(seed: int, stage: str, frame: int, sequence: int = 0) -> np.random.Generator:
    """Generator for a stage's temporal noise in frame ``frame`` (0-based).

    ``sequence`` separates frame series taken at other times by the same
    sensor, such as the dark frames of a dark calibration (sequence 1), so
    that their noise never repeats the scene frames'.
    """
    if frame < 0:
        raise ValueError(f"frame index must be >= 0, got {frame}")
    key = (TEMPORAL, STAGE_IDS[stage], frame) if sequence == 0 else (TEMPORAL, STAGE_IDS[stage], frame, sequence)
    ss = np.random.SeedSequence(seed, spawn_key=key)
    return np.random.Generator(np.random.PCG64(ss))
