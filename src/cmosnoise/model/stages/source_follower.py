"""Stage 6, source-follower noise (input-referred, e-): thermal plus flicker/RTS.

Thermal noise is ``Normal(0, thermal_sigma_e)`` in every pixel and frame.

Flicker/RTS (paper Section VII-B): each pixel has a fixed temporal sigma,
drawn once from a Fisher-Tippett-Gumbel body (``gumbel_r(loc, scale)``,
clipped at 0) plus a thin uniform tail of very noisy pixels (docs/model.md
section 4, the same heavy-tail map as the dark current). In each frame the
pixel gets ``Normal(0, sigma_i)``. That is the paper's simplification:
the per-pixel noise is Gaussian in time, only its size varies over the array.

With ``flicker.spectrum = one_over_f`` each pixel's flicker is a 1/f
process of its own (McWhorter's Lorentzians, :mod:`cmosnoise.model.one_over_f`).
Through CDS a frame shows the process's change over the CDS interval: its
variance is ``2 (1 - rho(tau))`` of the process's, so the sigmas scale by
``sqrt(D(tau) / D(tau_ref))`` with the interval (``reference_cds_interval_s``
is the one the map's sigmas hold at), and successive frames' changes
correlate by less than ``tau / (2 e T)`` (``T`` the frame period): drawn
white, as the paper does. Without CDS a frame shows the level itself,
``sigma_i x_i(t_k)``, each pixel's process sampled at the frame's time by
exact bridges (:class:`Flicker`): it correlates from frame to frame.

Examples
--------
>>> from cmosnoise import Sensor
>>> fp = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7).fixed_pattern
>>> fp.flicker_sigma.shape, bool((fp.flicker_sigma > 0).all())    # each pixel's flicker sigma, e- rms
((48, 64), True)
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ...engine import gauss_markov
from ...engine.samplers import Stream
from ..distributions import gumbel
from ..heavy_tail import HeavyTail


@functools.lru_cache(maxsize=64)
def flicker_model(gumbel_loc_e: float, gumbel_scale_e: float, ppm_above: float | None = None,
                  threshold_e: float | None = None, max_e: float = 0.0) -> HeavyTail:
    """Distribution of the per-pixel flicker sigma over the array (e-).

    Made once per process for each set of parameters (the tail solve integrates numerically; the result is
    a frozen, read-only model).
    """
    b = gumbel(gumbel_loc_e, gumbel_scale_e)
    if ppm_above is None or threshold_e is None or max_e <= 0:
        return HeavyTail(b, 0.0, 0.0)
    return HeavyTail.from_ppm(b, ppm_above, threshold_e, max_e)


def flicker_sigma_map(model: HeavyTail, region: tuple[int, int, int, int], cols: int,
                      key: tuple[int, int], engine: str = "auto") -> np.ndarray:
    """Fixed per-pixel flicker sigma over a rectangle, from the stage's fixed ``key`` (:meth:`HeavyTail.map`).

    Parameters
    ----------
    model : HeavyTail
        The sigmas' law over the array (:func:`flicker_model`), e-.
    region : (row0, row1, col0, col1)
        The rectangle to make.
    cols : int
        The sensor's width (a pixel's address is ``r * cols + c``).
    key : (int, int)
        The stage's fixed key (:func:`cmosnoise.model.seeds.fixed_key`).
    engine : {"auto", "numpy", "compiled", "cuda"}
        Where the map is made (:func:`cmosnoise.engine.fixed_maps.heavy_tail_map`; the same bits each way).

    Returns
    -------
    (row1 - row0, col1 - col0) float32 array, e- rms
    """
    return model.map(region, cols, key, engine)


def total_sigma(thermal_sigma_e: float, flicker_sigma: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """Each pixel's fixed source-follower sigma, ``sqrt(thermal**2 + flicker_i**2)`` (e-), float32 (rows, cols).

    Thermal and flicker noise are both zero-mean normal in each frame, so
    they are drawn as one normal with this sigma. Computed once per sensor.

    Parameters
    ----------
    thermal_sigma_e : float
        The thermal (white) noise, the same in every pixel, e- rms.
    flicker_sigma : (rows, cols) array, e- rms, or None
        Each pixel's flicker sigma (:func:`flicker_sigma_map`); None: thermal noise alone.
    shape : (rows, cols)
        The map's shape where ``flicker_sigma`` is None.

    Returns
    -------
    (rows, cols) float32 array, e- rms
    """
    if flicker_sigma is None:
        return np.full(shape, thermal_sigma_e, np.float32)
    out = flicker_sigma * flicker_sigma  # then in place: one map's memory, not three (200 MB each at 50 MP)
    out += np.float32(thermal_sigma_e) ** 2
    return np.sqrt(out, out=out)


def noise(sigma_e: np.ndarray, stream: Stream, index: np.ndarray) -> np.ndarray:
    """One frame of source-follower noise (e-), float64: ``sigma_i * Normal(0, 1)`` per pixel.

    Parameters
    ----------
    sigma_e : array, e- rms
        Each pixel's sigma (:func:`total_sigma`).
    stream : Stream
        The frame's stream of the stage (:func:`cmosnoise.model.seeds.temporal_stream`).
    index : int array, the shape of ``sigma_e``
        The pixels' indices ``r * cols + c``.

    Returns
    -------
    float64 array, e-, the shape of ``sigma_e``
    """
    return np.asarray(sigma_e, np.float64) * stream.normal(index)


#: pixels bridged together in one pass of :class:`Flicker` (bounds its arrays: components x pixels x a few nodes)
FLICKER_CHUNK = 1 << 15


@dataclass(frozen=True)
class Flicker:
    """Each pixel's 1/f flicker level in a frame (``flicker.spectrum = one_over_f`` without CDS), e-.

    Parameters
    ----------
    sigma_e : (rows, cols) float32 array
        Each pixel's flicker sigma (the map's), e- rms, over the window.
    spectrum : Spectrum
        The unit-variance process's Lorentzians.
    frame_period_s : float
        Seconds between frames: frame ``k`` is grid point ``k``.
    key : (int, int)
        The stream's key words (``source_follower_flicker``); pixel ``r cols + c`` is its lane.
    origin : (int, int)
        The window's first row and column in the sensor.
    cols : int
        The sensor's width (a pixel's lane is ``r cols + c``).
    """

    sigma_e: np.ndarray
    spectrum: object
    frame_period_s: float
    key: tuple[int, int]
    origin: tuple[int, int]
    cols: int

    def __call__(self, frame: int, sequence: int) -> np.ndarray:
        """Frame ``frame``'s flicker of the window's pixels, (rows, cols) float32 e-.

        Parameters
        ----------
        frame : int
            The frame's number (below ``2**32``).
        sequence : int
            The frame series.

        Returns
        -------
        (rows, cols) float32, e-
            ``sigma_i x_i(frame frame_period_s)``.
        """
        h, w = self.sigma_e.shape
        r0, c0 = self.origin
        lanes = ((np.arange(r0, r0 + h)[:, None] * self.cols) + np.arange(c0, c0 + w)[None, :]).ravel()
        x = np.empty(lanes.size)
        for a in range(0, lanes.size, FLICKER_CHUNK):
            part = lanes[a:a + FLICKER_CHUNK]
            x[a:a + part.size] = gauss_markov.sample(
                self.spectrum.rates_per_s, self.spectrum.weights, self.frame_period_s, int(frame), int(frame) + 1,
                self.key, int(sequence), lanes=part, lane_bits=32)[:, 0]
        return (self.sigma_e.astype(np.float64) * x.reshape(h, w)).astype(np.float32)
