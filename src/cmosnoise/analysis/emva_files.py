"""EMVA 1288 descriptor files: a :class:`~.characterize.Measurement` written as TIFF frames and a descriptor
(:func:`export`), and read back from one, of any tool (:func:`load`, every file through :mod:`cmosnoise.inputs`).

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> from cmosnoise import Sensor, characterize, emva_files
>>> m = characterize.measure(Sensor({"sensor": {"width": 32, "height": 24}}, seed=1), steps=8, stack_frames=4,
...                          keep_frames=True)
>>> descriptor = emva_files.export(m, Path(tempfile.mkdtemp()))
>>> back = emva_files.load(descriptor)                   # what any EMVA 1288 tool reads, read back
>>> descriptor.name, back.shape, back.bits
('EMVA1288_descriptor.txt', (24, 32), 12)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import inputs
from ..errors import CmosnoiseError
from ..io.stacks import DESCRIPTOR  # the file name export writes and load reads
from .characterize import Measurement, dsnu_of_pair, pair_stats


def export(m: Measurement, folder: Path) -> Path:
    """Write the frames as TIFFs and an EMVA 1288 descriptor file (exposure in ns, photons per pixel).

    Parameters
    ----------
    m : Measurement
        A measurement with its frames (``keep_frames=True``).
    folder : Path
        Where the descriptor and ``images/`` go.

    Returns
    -------
    Path
        The descriptor file.
    """
    import tifffile

    images = folder / "images"
    images.mkdir(parents=True, exist_ok=True)
    lines = ["# EMVA 1288 measurement written by cmosnoise", "v 3.0", f"n {m.bits} {m.shape[1]} {m.shape[0]}"]

    def add(header: str, name: str, frames):
        lines.append(header)
        for j, f in enumerate(frames):
            rel = f"images/{name}_{j:03d}.tif"
            tifffile.imwrite(folder / rel, f.astype(np.uint16), photometric="minisblack")
            lines.append(f"i {rel}")

    for i, (t, p) in enumerate(zip(m.texp_s, m.mu_p)):
        add(f"b {t * 1e9:.1f} {p:.4f}", f"b_{i:03d}", m.frames[f"b_{i:03d}"])
    for i, t in enumerate(m.texp_s):
        add(f"d {t * 1e9:.1f}", f"d_{i:03d}", m.frames[f"d_{i:03d}"])
    add(f"b {m.stack_texp_s * 1e9:.1f} {m.stack_mu_p:.4f}", "b_stack", m.stack_bright)
    add(f"d {m.stack_texp_s * 1e9:.1f}", "d_stack", m.stack_dark)
    path = folder / DESCRIPTOR
    path.write_text("\n".join(lines) + "\n")
    return path


def load(descriptor: Path) -> Measurement:
    """A :class:`Measurement` from an EMVA 1288 descriptor file and its images (e.g. a real camera's).

    Parameters
    ----------
    descriptor : Path
        An EMVA 1288 descriptor file, or the folder that holds one.

    Returns
    -------
    Measurement
    """
    import tifffile

    from ..io.stacks import descriptor_path, parse_descriptor

    bits, shape, entries = parse_descriptor(descriptor_path(Path(descriptor)))

    def read(paths):
        out = []
        for p in paths:
            inputs.check_image_pixels(p, "EMVA image", inputs.MAX_FRAME_PIXELS, inputs.MAX_FRAME_PIXELS)
            try:
                img = tifffile.imread(p)
            except Exception as exc:
                raise CmosnoiseError(f"EMVA image cannot be read: {' '.join(str(exc).split())[:200]}") from None
            if img.shape != shape:
                raise CmosnoiseError(f"EMVA image {str(p)!r} is {img.shape[-1] if img.ndim else 0} x "
                                     f"{img.shape[0] if img.ndim else 0} (shape {img.shape}); the descriptor says "
                                     f"{shape[1]} x {shape[0]}")
            out.append(img)
        return out

    bright_pairs = sorted((e for e in entries if e[0] == "b" and len(e[3]) == 2), key=lambda e: e[1])
    dark_pairs = {round(e[1], 12): e for e in entries if e[0] == "d" and len(e[3]) == 2}
    stacks_b = [e for e in entries if e[0] == "b" and len(e[3]) > 2]
    stacks_d = [e for e in entries if e[0] == "d" and len(e[3]) > 2]
    if len(bright_pairs) < 3 or not stacks_b or not stacks_d:
        raise CmosnoiseError("an EMVA descriptor needs at least 3 bright pairs with dark pairs, and a bright and a dark stack")
    times = sorted({round(e[1], 12) for e in bright_pairs})
    if len(times) < 3 or times[0] < 0:
        raise CmosnoiseError(f"EMVA descriptor: the bright pairs have {len(times)} distinct exposure time(s) "
                             f"({', '.join(f'{t * 1e9:g}' for t in times[:5])} ns); the series needs at least 3 "
                             "distinct times >= 0")
    texp, mu_p, mu_y, mu_yd, s2_y, s2_yd, max_yd = [], [], [], [], [], [], []
    dsnu_short = None
    for _, t, p, paths in bright_pairs:
        d = dark_pairs.get(round(t, 12))
        if d is None:
            raise CmosnoiseError(f"EMVA descriptor: no dark pair at exposure {t * 1e9:g} ns")
        a, b = read(paths)
        da, db = read(d[3])
        my, sy = pair_stats(a, b)
        md, sd = pair_stats(da, db)
        for column, value in ((texp, t), (mu_p, p), (mu_y, my), (s2_y, sy), (mu_yd, md), (s2_yd, sd)):
            column.append(value)
        max_yd.append(max(float(da.max()), float(db.max())))
        if len(texp) == 1:  # the pairs come sorted by exposure time: the shortest
            dsnu_short = dsnu_of_pair(da, db)
    sb, sdk = stacks_b[0], stacks_d[0]
    return Measurement(
        bits, shape, *map(np.array, (texp, mu_p, mu_y, mu_yd, s2_y, s2_yd)), sb[1], sb[2],
        np.stack(read(sb[3])), np.stack(read(sdk[3])), np.array(max_yd), dsnu_shortest_dn2=dsnu_short,
    )
