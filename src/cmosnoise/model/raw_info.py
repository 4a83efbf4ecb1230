"""What raw frames are: CFA, black level, bit depth, scene white and crosstalk.

A :class:`RawInfo` travels with raw frames (TIFF metadata, DNG tags) and
tells the processing chain how to read them, whether they came from a
simulated :class:`~cmosnoise.model.sensor.Sensor` or from a file.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class RawInfo:
    """What processing needs to know about raw frames.

    Parameters
    ----------
    cfa : str
        RGGB, BGGR, GRBG, GBRG, or none.
    black_level_dn : float
        The black level, DN.
    bits : int
        The ADC's bits (the white level is ``2**bits - 1``).
    white_dn : float, optional
        The raw code of scene white (None: the white level).
    crosstalk_kernel_pct : (3, 3) array or dict of them, optional
        The sensor's crosstalk kernel(s), percent, for compensation.
    responsivity : (float, float, float)
        The R, G and B pixels' relative responsivity.
    extra : dict
        Anything else a file's metadata held.

    Examples
    --------
    >>> from cmosnoise import Sensor
    >>> info = Sensor({"sensor": {"width": 64, "height": 48}}).raw_info()
    >>> info.cfa, info.black_level_dn, info.bits
    ('RGGB', 64.0, 12)
    """

    cfa: str
    black_level_dn: float
    bits: int
    white_dn: float | None = None
    crosstalk_kernel_pct: object = None
    responsivity: tuple[float, float, float] = (1.0, 1.0, 1.0)
    extra: dict = field(default_factory=dict)

    @property
    def white_level_dn(self) -> int:
        return 2**self.bits - 1

    @classmethod
    def from_metadata(cls, meta: dict) -> RawInfo:
        return cls(
            cfa=meta["cfa"],
            black_level_dn=float(meta["black_level_dn"]),
            bits=int(meta["bits"]),
            white_dn=meta.get("scene_white_dn"),
            crosstalk_kernel_pct=meta.get("crosstalk_kernel_pct"),
            responsivity=tuple(meta.get("channel_responsivity", (1.0, 1.0, 1.0))),
        )
