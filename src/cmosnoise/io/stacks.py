"""Measured frame stacks for ``cmosnoise fit``: read from a manifest or an EMVA 1288 descriptor, reduced as read.

A lab's measurement is a list of **stacks**: frames of one kind (``dark``
or ``flat``) at one exposure time and temperature. Two ways to describe
them:

- an EMVA 1288 descriptor (``n bits width height``, ``b time_ns photons``,
  ``d time_ns``, ``i path``), as ``characterize --emva-export`` writes it
  and the standard's reference implementation reads it: every ``b`` or
  ``d`` entry is one stack;
- a manifest YAML::

      cfa: RGGB            # where the files' metadata lack them
      black_level_dn: 64
      bits: 12
      stacks:
        - {kind: dark, exposure_s: 0.01, temperature_c: 25, files: [dark_10ms.tif]}
        - {kind: flat, exposure_s: 0.01, temperature_c: 25, level: 0.4, files: ["flat_04/*.dng"]}
        - {kind: spot, exposure_s: 0.01, temperature_c: 25, files: [spots.tif]}   # crosstalk
        - {kind: dark, exposure_s: 0.005, frame_period_s: 0.0333, files: [dark_100.tif]}  # random telegraph

  ``frame_period_s`` (seconds from one frame's start to the next; default:
  the exposure time, frames back to back) puts the random telegraph fit's
  dwell times in seconds; it reads the longest dark stack of 50 frames or
  more a second time, whole.

  Files are multi-page TIFF, ``.npy`` (2-D, or 3-D with frames first) or
  DNG (one frame each, read by LibRaw through rawpy; its CFA, black level
  and white level are taken from the file). Paths are relative to the
  manifest; a glob expands in sorted order;
- a folder of a camera's DNG bursts (:func:`bursts`), no manifest: each
  file's ISO and exposure time from its tags, its kind from its path (a
  folder or file name holding ``dark``, ``flat`` or ``spot``), a stack the
  files of one folder at one ISO and exposure time::

      bursts/dark/iso100/*.dng        bursts/flat/iso100/level_03/*.dng

Each stack is reduced frame by frame (:class:`StackStats`) so a 100-frame
5 MP stack never sits in memory: per-pixel temporal mean, the per-pixel
temporal variance after each frame's row and column means are removed
(what is left is the pixel's own noise), and every frame's row and column
means (the row and column noise).
"""

from __future__ import annotations

import glob
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from .. import inputs
from ..errors import CmosnoiseError
from ..model.stages import adc

#: an EMVA 1288 descriptor's default file name inside a folder
DESCRIPTOR = "EMVA1288_descriptor.txt"
#: largest manifest or descriptor accepted (they list files; they are small)
MAX_TEXT_BYTES = 10_000_000
SUFFIXES = (".tif", ".tiff", ".npy", ".dng")


# ------------------------------------------------------------------ manifest schema
class StackEntry(BaseModel):
    model_config = ConfigDict(extra="forbid")
    kind: Literal["dark", "flat", "spot"] = Field(
        description="dark (no light), flat (uniform illumination) or spot (light on single, well separated pixels: crosstalk)")
    exposure_s: float = Field(ge=0, le=3600, description="exposure time, s")
    temperature_c: float | None = Field(None, ge=-60, le=150, description="sensor temperature, C")
    level: float | None = Field(None, ge=0, le=1e9, description="relative illumination (any unit; flats)")
    photons: float | None = Field(None, ge=0, le=1e12, description="photons per pixel during the exposure (flats)")
    iso: float | None = Field(None, gt=0, le=1e7, description="the camera's gain setting (ISO) the stack was taken at")
    gain_db: float | None = Field(None, ge=-60, le=120, description="the camera's gain setting (dB) the stack was taken at")
    frame_period_s: float | None = Field(None, gt=0, le=3600, description="seconds from one frame's start to the "
                                            "next (random telegraph dwell times); default: the exposure time")
    files: list[str] = Field(min_length=1, description="files or globs, relative to the manifest")


class Manifest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    cfa: Literal["RGGB", "BGGR", "GRBG", "GBRG", "none"] | None = None
    black_level_dn: float | None = Field(None, ge=0, le=65535)
    bits: int | None = Field(None, ge=8, le=16)
    temperature_c: float | None = Field(None, ge=-60, le=150, description="default for stacks that give none")
    stacks: list[StackEntry] = Field(min_length=1)


# ------------------------------------------------------------------ reduced stacks
@dataclass
class StackStats:
    """One stack reduced to what the fits need (DN)."""

    n: int  #: frames
    mean: np.ndarray  #: (rows, cols) float64, per-pixel temporal mean
    pixel_var: np.ndarray  #: (rows, cols) float64, per-pixel temporal variance (ddof 1) of the frames less their row and column means
    temporal_var: float  #: mean over pixels of the plain per-pixel temporal variance (EMVA's sigma_y^2)
    row_means: np.ndarray  #: (n, rows) float64
    col_means: np.ndarray  #: (n, cols) float64
    max_dn: float
    kind: str = "dark"
    exposure_s: float = 0.0
    temperature_c: float | None = None
    level: float | None = None
    photons: float | None = None
    files: list[str] = field(default_factory=list)
    pixel_m4: np.ndarray | None = None  #: (rows, cols) float64, per-pixel fourth central moment (ddof 0), as pixel_var
    iso: float | None = None  #: the gain setting the stack was taken at (ISO), when the manifest says
    gain_db: float | None = None  #: or in dB
    frame_period_s: float | None = None  #: seconds from one frame's start to the next, when the manifest says
    #: the OR of the stack's first frame's codes (:func:`cmosnoise.model.stages.adc.code_grid`): its lowest bit, the
    #: output DN per ADC code where a camera scales its ADC's codes to a wider range
    code_grid: int = 0
    #: the stack's frames again, one at a time (a fit that needs the whole series: random telegraph pixels)
    reread: Callable[[], Iterator[np.ndarray]] | None = field(default=None, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        return self.mean.shape

    @property
    def period_s(self) -> float:
        """Seconds from one frame's start to the next: the manifest's, or the exposure (frames back to back)."""
        return self.frame_period_s if self.frame_period_s is not None else max(self.exposure_s, 1e-9)

    def series(self, max_bytes: int) -> tuple[np.ndarray, tuple[int, int]]:
        """The stack's frames, (n, rows, cols) float32, read again; where they would take more than ``max_bytes``,
        the middle rows that fit (at least 2). Returns (frames, (first row, last row + 1))."""
        if self.reread is None:
            raise CmosnoiseError("this stack's frames cannot be read again")
        rows, cols = self.shape
        keep = int(min(rows, max(2, max_bytes // max(4 * cols * self.n, 1))))
        r0 = (rows - keep) // 2
        out = np.empty((self.n, keep, cols), np.float32)
        i = 0
        for f in self.reread():
            if i >= self.n:
                break
            out[i] = np.asarray(f)[r0:r0 + keep]
            i += 1
        if i != self.n:
            raise CmosnoiseError(f"the stack held {self.n} frames when reduced and {i} when read again")
        return out, (r0, r0 + keep)


def reduce_stack(frames: Iterator[np.ndarray], **info) -> StackStats:
    """Reduce frames (each (rows, cols)) to a :class:`StackStats`, one frame at a time."""
    s1 = s2 = c1 = c2 = c3 = c4 = None
    rows_, cols_, top = [], [], -math.inf
    grid = 0
    n = 0
    for f in frames:
        if n == 0:  # one frame's codes show the step (tens of thousands of them); reading it once is enough
            grid = adc.code_grid(f)
        x = np.asarray(f, np.float64)
        if s1 is None:
            s1, s2, c1, c2, c3, c4 = (np.zeros(x.shape) for _ in range(6))
        elif x.shape != s1.shape:
            raise CmosnoiseError(f"stack {info.get('name', '')}: frame {n} is {x.shape[1]} x {x.shape[0]}, "
                                 f"the first was {s1.shape[1]} x {s1.shape[0]}: a stack's frames must have one size")
        rm, cm = x.mean(axis=1), x.mean(axis=0)
        g = rm.mean()
        y = x - rm[:, None] - cm[None, :] + g
        y2 = y * y
        s1 += x; s2 += x * x; c1 += y; c2 += y2; c3 += y2 * y; c4 += y2 * y2  # noqa: E702
        rows_.append(rm); cols_.append(cm)  # noqa: E702
        top = max(top, float(x.max()))
        n += 1
    name = info.pop("name", "")
    if n < 2:
        raise CmosnoiseError(f"stack {name}: {n} frame(s); a stack needs at least 2 (temporal noise is a difference of frames)")
    mean = s1 / n
    var = np.maximum(s2 - s1 * mean, 0) / (n - 1)
    cvar = np.maximum(c2 - c1 * c1 / n, 0) / (n - 1)
    mu = c1 / n  # the fourth central moment from the raw sums: E y^4 - 4 mu E y^3 + 6 mu^2 E y^2 - 3 mu^4
    m4 = np.maximum(c4 / n - 4 * mu * c3 / n + 6 * mu * mu * c2 / n - 3 * mu**4, 0)
    return StackStats(mean=mean, pixel_var=cvar, pixel_m4=m4, temporal_var=float(var.mean()), row_means=np.array(rows_),
                      col_means=np.array(cols_), max_dn=top, n=n, code_grid=grid, **info)


@dataclass
class Dataset:
    """A measurement: its stacks and what the files' metadata (or the manifest) say about the sensor."""

    stacks: list[StackStats]
    shape: tuple[int, int]
    bits: int | None
    cfa: str | None
    black_level_dn: float | None
    source: str
    kind: str  #: "emva", "manifest" or "bursts"
    descriptor: Path | None = None  #: the EMVA descriptor, when that was the input
    #: whether every stack's temperature came from the data (the manifest), not from ``load``'s ``temperature_c``
    temperatures_stated: bool = False

    @property
    def code_step(self) -> int:
        """The output DN per ADC code the stacks' codes show (:func:`cmosnoise.model.stages.adc.code_step`): 1 for
        a camera that writes its ADC's codes, 4 for a 14-bit ADC in a 16-bit range."""
        grid = 0
        for s in self.stacks:
            grid |= s.code_grid
        return adc.code_step(grid)

    def of_kind(self, kind: str, temperature_c: float | None = None) -> list[StackStats]:
        return [s for s in self.stacks if s.kind == kind and (temperature_c is None or s.temperature_c == temperature_c)]

    @property
    def temperatures(self) -> list[float]:
        return sorted({s.temperature_c for s in self.stacks if s.temperature_c is not None})

    def settings(self) -> tuple[str, list[float]] | None:
        """The gain settings the stacks were taken at: ("iso" or "gain_db", sorted values), or None when the
        manifest names none (one setting)."""
        for index in ("iso", "gain_db"):
            values = sorted({getattr(s, index) for s in self.stacks if getattr(s, index) is not None})
            if values:
                return index, values
        return None

    def at_setting(self, index: str, value: float) -> Dataset:
        """The stacks taken at one gain setting, as a data set of their own."""
        return Dataset([s for s in self.stacks if getattr(s, index) == value], self.shape, self.bits, self.cfa,
                       self.black_level_dn, f"{self.source} at {index} {value:g}", self.kind, self.descriptor,
                       self.temperatures_stated)


# ------------------------------------------------------------------ files
#: bytes a frame's pixel takes while a stack is reduced and fitted: the frame as float64, six float64 sums, the
#: stack's mean, variance and fourth moment kept, and the fit's maps (measured peaks are 70 to 80 bytes a pixel)
REDUCE_BYTES_PER_PIXEL = 80


@dataclass
class _Meta:
    cfa: str | None = None
    black: float | None = None
    white: int | None = None


def _dng_frames(path: Path, meta: _Meta) -> Iterator[np.ndarray]:
    try:
        import rawpy
    except ImportError:  # pragma: no cover - a declared dependency
        raise CmosnoiseError("reading DNG needs rawpy: pip install rawpy") from None
    try:
        with rawpy.imread(str(path)) as r:
            img = np.array(r.raw_image_visible, copy=True)
            desc = r.color_desc.decode()
            pattern = r.raw_pattern
            if r.num_colors >= 3 and pattern is not None and pattern.shape == (2, 2):
                meta.cfa = "".join(desc[i] for i in pattern.ravel()).replace("G2", "G")
                meta.cfa = meta.cfa if meta.cfa in ("RGGB", "BGGR", "GRBG", "GBRG") else None
            else:
                meta.cfa = "none"
            levels = list(r.black_level_per_channel)
            meta.black = float(np.mean(levels)) if levels else None
            meta.white = int(r.white_level)
    except CmosnoiseError:
        raise
    except Exception as exc:
        raise CmosnoiseError(f"{str(path)!r} cannot be read as a DNG (LibRaw): {' '.join(str(exc).split())[:160]}") from None
    yield img


def _frames_of(path: Path, meta: _Meta) -> Iterator[np.ndarray]:
    """The frames of one file, each (rows, cols)."""
    suffix = path.suffix.lower()
    if not path.exists() and not path.is_symlink():
        raise CmosnoiseError(f"{str(path)!r}: no such file")
    if suffix in (".tif", ".tiff", ".npy"):  # from the header: no frame larger than a sensor, no endless file
        rows, cols, _ = inputs.check_image_pixels(path, "frames file", inputs.MAX_STREAM_PIXELS, inputs.MAX_FRAME_PIXELS)
        # and no frame whose reduction would not fit in memory (the stack's float64 sums, the fits' maps)
        inputs.check_memory(rows * cols * REDUCE_BYTES_PER_PIXEL, f"frames file {str(path)!r} ({cols} x {rows} "
                            "frames)", " (crop the frames to a region first)")
    else:
        inputs.check_regular(path, "frames file")
    if suffix == ".dng":
        yield from _dng_frames(path, meta)
        return
    try:
        if suffix in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(path) as tif:
                for page in tif.pages:
                    a = page.asarray()
                    if a.ndim == 3:  # one page holding a whole (n, rows, cols) series
                        yield from a
                    else:
                        yield a
            return
        if suffix == ".npy":
            a = np.load(path, mmap_mode="r", allow_pickle=False)
            if a.ndim == 2:
                yield np.asarray(a)
            elif a.ndim == 3:
                for f in a:
                    yield np.asarray(f)
            else:
                raise CmosnoiseError(f"{str(path)!r}: an array of shape {a.shape}; expected (rows, cols) or (frames, rows, cols)")
            return
    except CmosnoiseError:
        raise
    except Exception as exc:
        raise CmosnoiseError(f"{str(path)!r} cannot be read: {' '.join(str(exc).split())[:160]}") from None
    raise CmosnoiseError(f"{str(path)!r}: unknown file type {suffix!r}; frames are read from {', '.join(SUFFIXES)}")


def _checked(frames: Iterator[np.ndarray], path: Path) -> Iterator[np.ndarray]:
    n = 0
    for f in frames:
        n += 1
        if f.ndim != 2 or min(f.shape) < 2:
            raise CmosnoiseError(f"{str(path)!r}: a frame of shape {f.shape}; expected (rows, cols)")
        if f.dtype.kind not in "uif":
            raise CmosnoiseError(f"{str(path)!r}: frames of type {f.dtype}; expected integer or float codes")
        if f.dtype.kind == "f" and not np.all(np.isfinite(f)):
            raise CmosnoiseError(f"{str(path)!r}: frames hold NaN or infinite values")
        yield f
    if n == 0:
        raise CmosnoiseError(f"{str(path)!r} holds no readable frame (a damaged or empty file?)")


def _stack(paths: list[Path], meta: _Meta, **info) -> StackStats:
    def frames():
        for p in paths:
            yield from _checked(_frames_of(p, meta), p)
    stats = reduce_stack(frames(), files=[str(p) for p in paths], **info)
    stats.reread = frames
    return stats


def _read_text(path: Path, what: str) -> str:
    return inputs.read_text(path, what, MAX_TEXT_BYTES)


# ------------------------------------------------------------------ EMVA 1288 descriptor
def parse_descriptor(descriptor: Path) -> tuple[int, tuple[int, int], list[tuple[str, float, float | None, list[Path]]]]:
    """An EMVA 1288 descriptor's bits, shape (rows, cols) and entries ``(kind 'b'|'d', exposure s, photons, paths)``."""
    text = _read_text(descriptor, "EMVA descriptor")
    base = descriptor.parent
    bits = shape = None
    entries: list[tuple[str, float, float | None, list[Path]]] = []
    for n, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        tag = parts[0]
        try:
            if tag == "v":
                continue
            if tag == "n":
                bits, shape = int(parts[1]), (int(parts[3]), int(parts[2]))
                if not 1 <= bits <= 16 or min(shape) < 2:
                    raise ValueError("expected 1 to 16 bits and at least 2 x 2 pixels")
            elif tag == "b":
                entries.append(("b", float(parts[1].replace(",", ".")) * 1e-9, float(parts[2].replace(",", ".")), []))
            elif tag == "d":
                entries.append(("d", float(parts[1].replace(",", ".")) * 1e-9, None, []))
            elif tag == "i":
                if not entries:
                    raise ValueError("an image line before any 'b' or 'd' line")
                entries[-1][3].append(base.joinpath(*parts[1].replace("\\", "/").split("/")))
            else:
                raise ValueError(f"unknown line type {tag!r}")
        except (IndexError, ValueError) as exc:
            raise CmosnoiseError(f"EMVA descriptor {str(descriptor)!r}, line {n}: {line.strip()!r}: {exc}") from None
    if bits is None:
        raise CmosnoiseError(f"EMVA descriptor {str(descriptor)!r} has no 'n bits width height' line")
    missing = [p for e in entries for p in e[3] if not p.is_file()]
    if missing:
        more = f" and {len(missing) - 1} more" if len(missing) > 1 else ""
        raise CmosnoiseError(f"EMVA descriptor {str(descriptor)!r} names missing file {str(missing[0])!r}{more}")
    return bits, shape, entries


def descriptor_path(path: Path) -> Path:
    """The descriptor file itself, or the one in folder ``path`` (ours, or another tool's ``*descriptor*.txt``)."""
    if not path.is_dir():
        return path
    found = [path / DESCRIPTOR] if (path / DESCRIPTOR).is_file() else sorted(path.glob("*[Dd]escriptor*.txt"))
    return found[0] if len(found) == 1 else path / DESCRIPTOR


def _from_descriptor(path: Path, temperature_c: float | None) -> Dataset:
    bits, shape, entries = parse_descriptor(path)
    stacks = []
    for i, (tag, t, photons, paths) in enumerate(entries):
        name = f"{'flat' if tag == 'b' else 'dark'} at {t * 1e9:g} ns (entry {i + 1})"
        s = _stack(paths, _Meta(), name=name, kind="flat" if tag == "b" else "dark", exposure_s=t,
                   temperature_c=temperature_c, level=None, photons=photons)
        if s.shape != shape:
            raise CmosnoiseError(f"EMVA descriptor {str(path)!r}: the {name} frames are {s.shape[1]} x {s.shape[0]}; "
                                 f"the descriptor says {shape[1]} x {shape[0]}")
        stacks.append(s)
    return Dataset(stacks, shape, bits, None, None, str(path), "emva", descriptor=path)


# ------------------------------------------------------------------ manifest
def _from_manifest(path: Path, temperature_c: float | None) -> Dataset:
    import yaml

    from ..config.loading import load_yaml_text

    text = _read_text(path, "manifest")
    try:
        data = load_yaml_text(text)
        if not isinstance(data, dict):
            raise CmosnoiseError(f"manifest {str(path)!r} must hold a mapping with 'stacks', not {type(data).__name__}")
        m = Manifest.model_validate(data)
    except ValidationError as exc:
        e = exc.errors()[0]
        where = ".".join(str(x) for x in e["loc"])
        raise CmosnoiseError(f"manifest {str(path)!r}: {where}: {e['msg']} (got {e.get('input')!r})"
                             + (f"; and {len(exc.errors()) - 1} more problem(s)" if len(exc.errors()) > 1 else "")) from None
    except yaml.YAMLError as exc:
        raise CmosnoiseError(f"manifest {str(path)!r} is not valid YAML: {' '.join(str(exc).split())[:160]}") from None
    base = path.parent
    stacks, meta = [], _Meta()
    stated = True
    for i, e in enumerate(m.stacks):
        paths: list[Path] = []
        for pattern in e.files:
            p = base / pattern
            if any(ch in pattern for ch in "*?["):
                hits = sorted(Path(h) for h in glob.glob(str(p)))
                if not hits:
                    raise CmosnoiseError(f"manifest {str(path)!r}: stacks.{i}.files: {pattern!r} matches no file")
                paths += hits
            else:
                paths.append(p)
        temp = e.temperature_c if e.temperature_c is not None else m.temperature_c
        if temp is None:
            stated = False
            temp = temperature_c
        name = f"stacks.{i} ({e.kind}, {e.exposure_s:g} s)"
        stacks.append(_stack(paths, meta, name=name, kind=e.kind, exposure_s=e.exposure_s, temperature_c=temp,
                             level=e.level, photons=e.photons, iso=e.iso, gain_db=e.gain_db,
                             frame_period_s=e.frame_period_s))
    shape = _one_size(stacks, f"manifest {str(path)!r}: the stacks", "one sensor's")
    bits = m.bits if m.bits is not None else _bits_of(meta.white)
    cfa = meta.cfa or m.cfa
    black = meta.black if meta.black is not None else m.black_level_dn
    return Dataset(stacks, shape, bits, cfa, black, str(path), "manifest", temperatures_stated=stated)


def _one_size(stacks: list[StackStats], what: str, whose: str) -> tuple[int, int]:
    """The stacks' one frame size (rows, cols); one line naming ``what`` where they have several."""
    shapes = sorted({s.shape for s in stacks})
    if len(shapes) > 1:
        raise CmosnoiseError(f"{what} have different frame sizes ({', '.join(f'{c} x {r}' for r, c in shapes)}); "
                             f"{whose} frames have one size")
    return shapes[0]


def _bits_of(white: int | None) -> int | None:
    """The ADC bits a file's white level implies (8 to 16), None where no file gave one."""
    return None if white is None else max(8, min(16, int(math.ceil(math.log2(white + 1)))))


# ------------------------------------------------------------------ a folder of DNG bursts
#: the words of a burst's path that name its kind (a folder's or the file's own name holding one)
KINDS = ("dark", "flat", "spot")
#: the most DNG files a folder of bursts is read from
MAX_BURST_FILES = 100_000


def _kind_of(rel: Path) -> str | None:
    """The kind a burst file's path (relative to the folder) names: its innermost part that holds one word of
    :data:`KINDS` (``bursts/dark/iso100/0001.dng``: dark), None where none does or a part holds two."""
    for part in reversed([*rel.parent.parts, rel.stem]):
        hits = [k for k in KINDS if k in part.lower()]
        if len(hits) == 1:
            return hits[0]
        if hits:
            return None
    return None


def burst_files(folder: Path) -> list[Path]:
    """The DNG files under ``folder`` (any depth), sorted by path."""
    found = []
    for p in sorted(folder.rglob("*")):
        if p.suffix.lower() == ".dng" and p.is_file():
            found.append(p)
            if len(found) > MAX_BURST_FILES:
                raise CmosnoiseError(f"--frames-from {str(folder)!r}: more than {MAX_BURST_FILES} DNG files; "
                                     "fit a folder of fewer bursts")
    return found


def bursts(folder: str | Path, temperature_c: float | None = None) -> Dataset:
    """A :class:`Dataset` from a folder of a camera's DNG bursts: no manifest, the files say what they are.

    Each DNG's ISO and exposure time are read from its tags
    (:func:`cmosnoise.io.dng.read_settings`: IFD0 or the camera's EXIF
    IFD), its kind from its path (the innermost folder or file name that
    holds ``dark``, ``flat`` or ``spot``). A stack is the files of one folder
    at one (kind, ISO, exposure time), in name order: darks and flats at each
    ISO the camera was set to, each flat level in a folder of its own (or at
    an exposure time of its own). The stacks' ISOs are the gain table's
    settings (:meth:`Dataset.settings`). The CFA pattern, black and white
    level come from the files (LibRaw); the temperature is ``temperature_c``
    (a DNG holds none).

    Parameters
    ----------
    folder : str or Path
    temperature_c : float, optional
        The sensor's temperature during the bursts, C.

    Returns
    -------
    Dataset
    """
    from .dng import read_settings

    folder = Path(folder)
    files = burst_files(folder)
    if not files:
        raise CmosnoiseError(f"--frames-from {str(folder)!r}: a folder holding an EMVA 1288 descriptor "
                             f"({DESCRIPTOR}), one manifest .yaml, or a camera's DNG bursts (found none of them)")
    groups: dict[tuple, list[Path]] = {}
    for p in files:
        rel = p.relative_to(folder)
        kind = _kind_of(rel)
        if kind is None:
            raise CmosnoiseError(f"{str(p)!r}: neither its name nor its folders' say which burst it is "
                                 f"({', '.join(KINDS)}): put each kind's bursts in a folder named for it, e.g. "
                                 "dark/iso100/")
        try:
            iso, t = read_settings(p)
        except Exception as exc:
            raise CmosnoiseError(f"{str(p)!r} cannot be read as a DNG: {' '.join(str(exc).split())[:160]}") from None
        if iso is None:
            raise CmosnoiseError(f"{str(p)!r} has no ISO tag (ISOSpeedRatings, 34855, in IFD0 or its EXIF IFD): a "
                                 "folder of bursts takes each file's ISO from it; write it, or list the files in a "
                                 "manifest with iso per stack")
        if t is None:
            raise CmosnoiseError(f"{str(p)!r} has no ExposureTime tag (33434): a folder of bursts takes each "
                                 "file's exposure time from it; write it, or list the files in a manifest")
        groups.setdefault((str(p.parent.relative_to(folder)), kind, iso, t), []).append(p)
    stacks, meta = [], _Meta()
    for (where, kind, iso, t), paths in groups.items():
        name = f"{where}/ ({kind}, ISO {iso:g}, {t:g} s, {len(paths)} files)"
        stacks.append(_stack(paths, meta, name=name, kind=kind, exposure_s=t, temperature_c=temperature_c,
                             iso=iso))
    shape = _one_size(stacks, f"--frames-from {str(folder)!r}: the bursts", "one camera's")
    return Dataset(stacks, shape, _bits_of(meta.white), meta.cfa, meta.black, str(folder), "bursts")


def load(path: str | Path, temperature_c: float | None = None) -> Dataset:
    """A :class:`Dataset` from a manifest (``.yaml``/``.yml``), an EMVA 1288 descriptor (file or folder) or a
    folder of DNG bursts (:func:`bursts`).

    ``temperature_c`` is the temperature of stacks that do not give one.
    """
    path = Path(path)
    if not path.exists():
        raise CmosnoiseError(f"--frames-from {str(path)!r}: no such file or folder")
    if path.is_dir() and not descriptor_path(path).is_file():
        manifests = sorted(path.glob("*.yaml")) + sorted(path.glob("*.yml"))
        if not manifests:
            return bursts(path, temperature_c)
        if len(manifests) != 1:
            raise CmosnoiseError(f"--frames-from {str(path)!r}: a folder holding an EMVA 1288 descriptor ({DESCRIPTOR}), "
                                 "one manifest .yaml or a camera's DNG bursts "
                                 f"(found {len(manifests)} .yaml files)")
        path = manifests[0]
    if path.suffix.lower() in (".yaml", ".yml"):
        return _from_manifest(path, temperature_c)
    return _from_descriptor(descriptor_path(path), temperature_c)
