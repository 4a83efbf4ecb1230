"""From raw frames to pictures (docs/model.md section 5), each step switchable.

Steps, in order:

1. black-level subtraction;
2. dark calibration: subtract a master dark (mean of dark frames of the same
   sensor instance at the same temperature and exposure);
3. defect correction on the CFA image: ``off``, ``median`` (single defects)
   or ``map`` (a defect map from the master dark; removes couplets too),
   then one's own corrector where ``defects.corrector`` names one
   (``module:function``, :func:`cmosnoise.defects.load_corrector`; or a
   callable given to :class:`Processor`);
4. demosaicing (``bilinear``, ``malvar2004``, ``menon2007``);
5. crosstalk colour-mixing compensation: the inverse of the 3 x 3 matrix the
   kernel and the CFA induce. It needs whole RGB pixels, so it follows the
   demosaicing;
6. white balance (the sensor's responsivities, given gains, or grey world);
7. sRGB gamma and 8-bit output.

Monochrome sensors skip 4 to 6. The **pre-processing view** (``pre=True``)
stops short of dark calibration and defect correction, like the paper's
Fig. 9 "pre-processing" images; ``preview.png`` shows it.

Examples
--------
>>> from cmosnoise import Processor, Sensor
>>> sensor = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7)
>>> proc = Processor(sensor.config.processing, sensor.raw_info())
>>> proc.render(sensor.expose("photo").frame(0), pre=True).shape    # the preview: no dark calibration
(48, 64, 3)
"""

from __future__ import annotations

import numpy as np

from .. import inputs
from ..config import ProcessingSection
from ..errors import CmosnoiseError
from ..model import cfa as cfa_mod
from ..model.raw_info import RawInfo
from ..model.stages import crosstalk
from . import calibration, defects, reconstruction


class Processor:
    """The processing chain for frames of one sensor (one shape, CFA, black level).

    Parameters
    ----------
    settings : ProcessingSection
        The processing chain's settings (``config.processing``).
    info : RawInfo
        What the frames are: CFA, black level, bits, scene white, crosstalk kernel.
    master_dark : (rows, cols) array, DN, optional
        A master dark for dark calibration (black level included).
    corrector : callable, optional
        One's own defect corrector, ``(raw, meta) -> raw`` in DN, black included (as
        :func:`cmosnoise.defects.load_corrector` gives one), run after ``settings.defects.method``; default: the
        one ``settings.defects.corrector`` names, if any.

    Examples
    --------
    >>> from cmosnoise import Processor, Sensor
    >>> sensor = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7)
    >>> picture = Processor(sensor.config.processing, sensor.raw_info()).render(sensor.expose("photo").frame(0))
    >>> picture.shape, picture.dtype
    ((48, 64, 3), dtype('uint8'))
    """

    def __init__(self, settings: ProcessingSection, info: RawInfo, master_dark: np.ndarray | None = None,
                 corrector=None):
        self.settings = settings
        # one's own corrector: a callable (raw, meta) -> raw given here, or settings.defects.corrector loaded
        spec = settings.defects.corrector
        self.corrector = corrector if corrector is not None else (defects.load_corrector(spec) if spec else None)
        self._corrector_name = getattr(corrector, "__name__", "corrector") if corrector is not None else spec
        self.info = info
        self.master_dark = master_dark
        self.mono = cfa_mod.is_mono(info.cfa)
        self._wb_gains: np.ndarray | None = None
        self.mixing = None
        self._compensation = None  # inverse of the mixing matrix, when compensation is on
        if info.crosstalk_kernel_pct is not None and not self.mono:
            self.mixing = crosstalk.channel_mixing_matrix(crosstalk.kernel_fractions(info.crosstalk_kernel_pct), info.cfa)
            if settings.crosstalk_compensation:
                self._compensation = np.linalg.inv(self.mixing)
        self.defect_map = None
        if settings.defects.method == "map":
            if master_dark is None:
                raise CmosnoiseError(
                    "processing.defects.method = 'map' needs a master dark: set processing.dark_frames > 0 "
                    "(cmosnoise simulate --dark-frames N) or give --dark (cmosnoise process)"
                )
            self.defect_map = defects.defect_map(
                master_dark.astype(np.float32) - np.float32(info.black_level_dn), settings.defects.threshold_sigma
            )

    @property
    def white_above_black(self) -> float:
        s, i = self.settings, self.info
        white = s.white_dn if s.white_dn is not None else (i.white_dn if i.white_dn is not None else i.white_level_dn)
        return max(float(white) - i.black_level_dn, 1e-9)

    def check_raw(self, raw) -> np.ndarray:
        """``raw`` as an array if it is a raw frame this processor can take; else one :class:`CmosnoiseError`
        naming the argument (a NaN would reach the compiled demosaicing).

        Parameters
        ----------
        raw : array_like
            2-D (rows, cols) of at least 2 x 2, integer or real codes (float: every value finite), of the master
            dark's shape where there is one.

        Returns
        -------
        ndarray, (rows, cols)
        """
        raw = inputs.check_frame(raw, "raw")
        self.check_shape(raw.shape)
        return raw

    def check_shape(self, shape: tuple[int, int]) -> None:
        if self.master_dark is not None and self.master_dark.shape != tuple(shape):
            raise CmosnoiseError(
                f"master dark is {self.master_dark.shape[0]} x {self.master_dark.shape[1]} but the raw frames are "
                f"{shape[0]} x {shape[1]}: a master dark must come from the same sensor"
            )

    # ------------------------------------------------------------ CFA domain
    def cfa_image(self, raw: np.ndarray, pre: bool = False) -> np.ndarray:
        """Steps 1 to 3: signal above black (DN), dark-calibrated and defect-corrected.

        Parameters
        ----------
        raw : ndarray, (rows, cols)
            A raw frame, DN.
        pre : bool
            Stop after the black level's subtraction (the pre-processing view).

        Returns
        -------
        ndarray, (rows, cols)
            float32 DN above black.
        """
        raw = self.check_raw(raw)
        img = calibration.subtract_black(raw, self.info.black_level_dn)
        if pre:
            return img
        if self.master_dark is not None:
            img = calibration.subtract_dark(img, self.master_dark, self.info.black_level_dn)
        method = self.settings.defects.method
        if method == "median":
            img, _ = defects.correct_isolated(img, self.info.cfa, self.settings.defects.threshold_sigma)
        elif method == "map":
            img = defects.correct_with_map(img, self.info.cfa, self.defect_map)
        if self.corrector is not None:
            img = self._own_correction(img)
        return img

    def _own_correction(self, img: np.ndarray) -> np.ndarray:
        """``img`` (DN above black) through one's own corrector, which takes and gives raw DN, black included."""
        black = float(self.info.black_level_dn)
        meta = {"cfa": self.info.cfa, "black_level_dn": black, "white_level_dn": float(self.info.white_level_dn)}
        out = defects.run_corrector(self.corrector, img.astype(np.float64) + black, meta,
                                    f"processing.defects.corrector {self._corrector_name!r}")
        return (out - black).astype(img.dtype)

    # ------------------------------------------------------------ colour
    def linear_rgb(self, cfa_img: np.ndarray, half: bool = False) -> np.ndarray:
        """Steps 4 to 6: linear light with scene white at 1.

        Parameters
        ----------
        cfa_img : ndarray, (rows, cols)
            :meth:`cfa_image`'s output.
        half : bool
            Demosaic at half resolution (:func:`reconstruction.superpixel`, one pixel per 2 x 2 cell, for
            previews; a mono image is averaged over 2 x 2 instead).

        Returns
        -------
        ndarray
            (rows, cols, 3), or (rows, cols) for mono; halved with ``half``.
        """
        x = cfa_img / np.float32(self.white_above_black)
        if self.mono:
            if half:
                r, c = x.shape[0] // 2 * 2, x.shape[1] // 2 * 2
                x = x[:r, :c].reshape(r // 2, 2, c // 2, 2).mean(axis=(1, 3))
            return x
        if half:
            rgb = reconstruction.superpixel(x, self.info.cfa)
        else:
            rgb = reconstruction.demosaic(x, self.info.cfa, self.settings.demosaic)
        if self._compensation is not None:
            rgb = reconstruction.apply_matrix(rgb, self._compensation)
        return rgb * self.white_balance_gains(rgb)

    def white_balance_gains(self, rgb: np.ndarray) -> np.ndarray:
        wb = self.settings.white_balance
        if wb.mode == "none":
            return np.ones(3, np.float32)
        if wb.mode == "gains":
            return np.asarray(wb.gains, np.float32)
        if wb.mode == "sensor":
            resp = np.asarray(self.info.responsivity, np.float64)
            return np.where(resp > 0, 1.0 / np.where(resp > 0, resp, 1.0), 1.0).astype(np.float32)
        if self._wb_gains is None:  # grey world: from the first frame, then fixed (no flicker in video)
            self._wb_gains = reconstruction.grey_world_gains(rgb)
        return self._wb_gains

    def render(self, raw: np.ndarray, pre: bool = False, half: bool = False) -> np.ndarray:
        """A raw frame as an 8-bit sRGB picture (the full chain, or the pre-processing view); ``half``: at half size.

        With numba installed, a Bayer mosaic's steps after the CFA domain run
        as one pass, with the same bits: at half size
        (:func:`reconstruction.superpixel_srgb8`), and at full size with
        bilinear demosaicing (:func:`reconstruction.bilinear_srgb8`); grey
        world, if chosen, takes its gains from the first frame's steps.

        Parameters
        ----------
        raw : ndarray, (rows, cols)
            A raw frame, DN.
        pre : bool
            The pre-processing view instead of the full chain.
        half : bool
            At half size.

        Returns
        -------
        ndarray, (rows, cols, 3) uint8
            The sRGB picture ((rows, cols) for mono).
        """
        raw = self.check_raw(raw)
        if not pre:
            return self.render_cfa(self.cfa_image(raw), half)
        if self._one_pass(raw.shape, half):
            self.check_shape(raw.shape)
            return self._picture(raw, self.info.black_level_dn, half)
        return reconstruction.encode_srgb8(self.linear_rgb(self.cfa_image(raw, pre=True), half))

    def render_cfa(self, cfa_img: np.ndarray, half: bool = False) -> np.ndarray:
        """Steps 4 to 7 of a CFA image already calibrated and corrected (:meth:`cfa_image`'s output): the
        8-bit sRGB picture :meth:`render` gives of its raw frame, bit for bit, without steps 1 to 3 again.

        Parameters
        ----------
        cfa_img : ndarray, (rows, cols)
            float32 DN above black, dark-calibrated and defect-corrected.
        half : bool
            At half size.

        Returns
        -------
        ndarray, (rows, cols, 3) uint8
            The sRGB picture ((rows, cols) for mono).
        """
        if self._one_pass(cfa_img.shape, half):
            return self._picture(cfa_img, 0.0, half)
        return reconstruction.encode_srgb8(self.linear_rgb(cfa_img, half))

    def _one_pass(self, shape: tuple[int, ...], half: bool) -> bool:
        """Whether steps 4 to 7 run as one compiled pass (same bits as the steps one by one)."""
        one_pass = half or (self.settings.demosaic == "bilinear" and min(shape) > reconstruction.EDGE_PAD)
        return bool(one_pass and not self.mono and reconstruction.one_pass_ready()
                    and (self.settings.white_balance.mode != "grey_world" or self._wb_gains is not None))

    def _picture(self, img: np.ndarray, offset: float, half: bool) -> np.ndarray:
        picture = reconstruction.superpixel_srgb8 if half else reconstruction.bilinear_srgb8
        return picture(img, self.info.cfa, offset, self.white_above_black, self._compensation,
                       self.white_balance_gains(None))


# ------------------------------------------------------------------ reading
def read_dark(path) -> np.ndarray:
    """A master dark from a file: the mean of a dark-frame stack, or an already averaged frame.

    Parameters
    ----------
    path : str or Path
        A TIFF of dark frames (frames, rows, cols), or one averaged frame (rows, cols), DN.

    Returns
    -------
    (rows, cols) float32 array, DN
        The master dark, black level included.
    """
    from ..io.raw_tiff import read_raw_tiff

    data, _ = read_raw_tiff(path, "dark file")
    if data.dtype.kind not in "uif":
        raise CmosnoiseError(f"dark file {str(path)!r}: pixel type {data.dtype} is not image data")
    if data.ndim == 2:
        data = data[None]
    if data.ndim != 3:
        raise CmosnoiseError(f"dark file {str(path)!r}: shape {data.shape}; expected (rows, cols) or (frames, rows, cols)")
    if not np.isfinite(data).all():
        raise CmosnoiseError(f"dark file {str(path)!r} contains NaN or infinite values")
    return calibration.master_dark(iter(data))
