"""PyTorch datasets that synthesize noisy raw samples on the fly, with their ground truth.

The samples are those of :mod:`cmosnoise.app.dataset` (the same recipe and
index give the same bits as a data set's shard), made when a
``DataLoader`` asks for them. Reached as ``cmosnoise.torch`` (the optional
extra ``pip install 'cmosnoise[torch]'``).

A sample is a dict of tensors:

- ``noisy``, ``expected``, ``perfect``: the noisy raw, the expected raw and
  the perfect image, packed by colour (R, G, G, B: (4, H/2, W/2); a
  monochrome sensor (1, H, W)) and normalized, ``(DN - black) / (white -
  black)`` (float32);
- ``mask``: the defect bits, packed alike (int32);
- ``raw``: the noisy raw as it is, (H, W) int32 DN;
- ``meta``: the sample's settings (camera, K, black and white level, light, ...), a dict.
"""

from __future__ import annotations

import json
import math

import numpy as np
import torch
from torch.utils.data import Dataset, IterableDataset, get_worker_info

from ..errors import CmosnoiseError
from ..model import cfa as cfa_mod
from ..model.sensor import check_device
from . import dataset as ds


def pack(a, pattern: str):
    """(H, W) -> (4, H/2, W/2) in the order R, G, G, B of ``pattern`` (monochrome: (1, H, W)); a NumPy array or a
    tensor (on any device), returned as the same kind."""
    if cfa_mod.is_mono(pattern):
        return a[None]
    planes = [a[0::2, 0::2], a[0::2, 1::2], a[1::2, 0::2], a[1::2, 1::2]]  # in the pattern's order
    greens = [i for i, ch in enumerate(pattern) if ch == "G"]
    order = [pattern.index("R"), greens[0], greens[1], pattern.index("B")]
    stack = torch.stack if isinstance(a, torch.Tensor) else np.stack
    return stack([planes[i] for i in order])


def to_tensors(arrays: dict, columns: dict, device=None) -> dict:
    """A sample's arrays and columns as :mod:`cmosnoise.torch` gives them, on ``device`` (a torch device; default
    the CPU). A raw still on the GPU (a device array) becomes a tensor over its memory, without a copy; the
    normalization and packing are the same float32 operations on either device (the same bits)."""
    black, white = columns["black_level_dn"], columns["white_level_dn"]
    scale = 1.0 / (white - black)
    pattern = columns["cfa"]

    def tensor(a):
        if hasattr(a, "copy_to_host"):  # the GPU kernel's frame
            from ..engine.frame import cuda_kernel

            if cuda_kernel.simulated():  # numba's simulator keeps it on the host
                return torch.from_numpy(a.copy_to_host()).to(device)
            return cuda_kernel.to_torch(a).to(device)
        return torch.from_numpy(np.ascontiguousarray(a)).to(device)

    def norm(a):
        t = tensor(a).to(torch.float32)
        return pack((t - torch.tensor(black, dtype=torch.float32, device=t.device))
                    * torch.tensor(scale, dtype=torch.float32, device=t.device), pattern).contiguous()

    meta = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in columns.items()}
    raw = tensor(arrays["raw"])
    return {"noisy": norm(arrays["raw"]), "expected": norm(arrays["expected_raw"]), "perfect": norm(arrays["perfect_dn"]),
            "mask": pack(tensor(arrays["mask"]).to(torch.int32), pattern).contiguous(),
            "raw": raw.to(torch.int32), "meta": meta}


def collate(batch: list[dict]) -> dict:
    """A batch: each tensor stacked along a new first axis, ``meta`` kept as a list of the samples' dicts."""
    out = {k: torch.stack([b[k] for b in batch]) for k in batch[0] if k != "meta"}
    out["meta"] = [b["meta"] for b in batch]
    return out


def _recipe(samples, crop, cameras, images, seed, light_e, integration_time_s, temperature_c, overrides,
            white_threshold_e_per_s, level=(0.003, 0.9)) -> tuple[ds.Recipe, ds.Sources]:
    sources = ds.Sources()
    names = []
    for i, item in enumerate(images if images is not None else ds.BUILTIN_SCENES):
        if isinstance(item, str):
            names.append(item)
        else:
            name = f"array:{i}"
            sources.images[name] = np.asarray(item, np.float64)
            names.append(name)
    crop = (crop, crop) if isinstance(crop, int) else tuple(crop)
    recipe = ds.Recipe(samples=samples, crop=crop, seed=seed, cameras=tuple(cameras),
                       camera_files=ds.camera_files(cameras), sources=tuple(names),
                       light_e=light_e and tuple(light_e), level=tuple(level),
                       integration_time_s=integration_time_s and tuple(integration_time_s),
                       temperature_c=temperature_c and tuple(temperature_c), overrides=tuple(overrides),
                       white_threshold_e_per_s=white_threshold_e_per_s)
    return ds.check(recipe, sources), sources


class NoisyRawDataset(Dataset):
    """A map-style dataset of ``samples`` noisy raw crops with their truth, made on the fly.

    Parameters
    ----------
    samples : int
        Its length.
    crop : int or (int, int)
        Sample size in pixels, even.
    cameras : sequence of str
        Presets (``sony-imx900``, ``sony-a7s2@iso=1600``) and virtual camera families (``led``, ``eld``,
        ``eld:nikon-d850``), as ``cmosnoise dataset --camera``.
    images : sequence, optional
        Image paths, or arrays: linear RGB (rows, cols, 3), or clean raw mosaics (rows, cols) in [0, 1] of the
        white with the sensor's CFA phase at (0, 0) (a user's own clean raws). Default: the built-in scenes.
    seed : int
        Sample ``i`` depends on (seed, i) alone.
    level, light_e, integration_time_s, temperature_c, overrides, white_threshold_e_per_s
        As ``cmosnoise dataset``'s --level, --light, --exposure, --temperature, --set, --white-threshold.
    fresh_noise : bool
        False: the same sample for the same index in every epoch. True: epoch ``e`` (:meth:`set_epoch`) draws
        frame ``e`` of each sample's sensor: new temporal noise, the same scene, sensor and truth.
    device : {"cpu", "cuda"}
        ``"cuda"``: each frame is made by the GPU kernel and stays there, and the tensors live on the GPU (the
        same values; in numba's CUDA simulator, on the CPU). Use it with ``num_workers=0`` (one process holds the
        GPU).
    """

    def __init__(self, samples: int, crop=512, cameras=("led",), images=None, seed: int = 0,
                 light_e=None, level=(0.003, 0.9), integration_time_s=None, temperature_c=None, overrides=(),
                 white_threshold_e_per_s=None, fresh_noise: bool = False, device: str = "cpu"):
        self.recipe, self.sources = _recipe(samples, crop, cameras, images, seed, light_e, integration_time_s,
                                            temperature_c, overrides, white_threshold_e_per_s, level)
        self.fresh_noise = fresh_noise
        self.epoch = 0
        check_device(device)
        self.device = device

    def set_epoch(self, epoch: int) -> None:
        """The epoch about to start (with ``fresh_noise``, its frames are new noise)."""
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return self.recipe.samples

    def _index(self, index) -> int:
        index = int(index)
        if not 0 <= index < len(self):
            raise IndexError(f"index {index} is outside 0 .. {len(self) - 1}")
        return index

    def sample(self, index: int) -> tuple[dict, dict]:
        """(arrays, columns) of sample ``index`` as a data set's shard holds them."""
        return ds.make_sample(self.recipe, self._index(index), self.sources, self.epoch if self.fresh_noise else 0,
                              device=self.device, on_device=self.device == "cuda")

    def _target(self):
        """The torch device the tensors go to (None: the CPU)."""
        if self.device != "cuda":
            return None
        from ..engine.frame import cuda_kernel

        return "cpu" if cuda_kernel.simulated() else "cuda"

    def __getitem__(self, index: int) -> dict:
        return to_tensors(*self.sample(int(index)), device=self._target())

    def __getitems__(self, indices) -> list[dict]:
        """Several samples, as ``[self[i] for i in indices]``; on the GPU their frames in one launch
        (:func:`cmosnoise.dataset.make_samples`). A ``DataLoader`` with a ``batch_size`` asks for a batch this
        way."""
        if self.device != "cuda":
            return [self[i] for i in indices]
        made = ds.make_samples(self.recipe, [self._index(i) for i in indices], self.sources, self.epoch if self.fresh_noise else 0,
                               device="cuda", on_device=True)
        return [to_tensors(arrays, columns, device=self._target()) for arrays, columns in made]


class ShardDataset(Dataset):
    """A map-style dataset of a data set folder that ``cmosnoise dataset`` wrote (HDF5, npz or FITS shards):
    sample ``i`` as :class:`NoisyRawDataset` gives it, read from disk instead of made.

    The folder's ``dataset.json`` and each shard pass the input gate (:func:`cmosnoise.app.dataset.read_shard`);
    a worker process keeps the last shard it read, so a ``DataLoader`` that reads in order (or a sampler over
    whole shards) decodes each shard once.

    Parameters
    ----------
    folder : str or Path
        The data set's folder.

    Examples
    --------
    ::

        from torch.utils.data import DataLoader
        from cmosnoise.torch import ShardDataset, collate

        for batch in DataLoader(ShardDataset("train"), batch_size=16, num_workers=4, collate_fn=collate):
            noisy, target = batch["noisy"], batch["expected"]
    """

    def __init__(self, folder):
        from pathlib import Path

        self.folder = Path(folder)
        manifest = ds.read_manifest(self.folder)
        self.recipe = ds.Recipe.from_json(json.dumps(manifest["recipe"]))
        self.shards = list(manifest["shards"])
        expected = [self.recipe.shard_name(k) for k in range(self.recipe.shards())]
        if self.shards != expected:
            raise CmosnoiseError(f"{self.folder / 'dataset.json'}: its shards are not the recipe's "
                                    f"({len(self.shards)} named, {len(expected)} expected)")
        missing = [name for name in self.shards if not (self.folder / name).is_file()]
        if missing:
            raise CmosnoiseError(f"--data {str(self.folder)!r} lacks {len(missing)} of its {len(self.shards)} "
                                    f"shards ({missing[0]}, ...): complete it with cmosnoise dataset --resume")
        self._cached: tuple[int, tuple[dict, dict]] | None = None
        self._counted: dict[int, int] = {}  # an HDF5 shard's number of samples, from its header

    def __len__(self) -> int:
        return self.recipe.samples

    def sample(self, index: int) -> tuple[dict, dict]:
        """(arrays, columns) of sample ``index`` as its shard holds them (each array (rows, cols))."""
        index = int(index)
        if not 0 <= index < len(self):
            raise IndexError(f"index {index} is outside 0 .. {len(self) - 1}")
        shard, at = divmod(index, self.recipe.shard_size)
        path = self.folder / self.shards[shard]
        want = len(self.recipe.shard_range(shard))
        if path.suffix.lower() == ".h5":  # one sample a chunk: a shuffled order reads what an ordered one does
            if shard not in self._counted:
                import h5py

                with h5py.File(path, "r") as f:
                    self._counted[shard] = ds._h5_header(path, f)
            held = self._counted[shard]
        else:  # npz and FITS decode whole: the last shard kept
            if self._cached is None or self._cached[0] != shard:
                self._cached = (shard, ds.read_shard(path))
            held = len(self._cached[1][0][ds.ARRAYS[0]])
        if held != want:
            raise CmosnoiseError(f"{path}: holds {held} samples where its recipe puts {want} (a short or foreign "
                                 "shard): remake it with cmosnoise dataset")
        if path.suffix.lower() == ".h5":
            return ds.read_sample(path, at)
        arrays, columns = self._cached[1]
        return {k: v[at] for k, v in arrays.items()}, {k: v[at] for k, v in columns.items()}

    def __getitem__(self, index: int) -> dict:
        return to_tensors(*self.sample(index))


class NoisyRawIterableDataset(IterableDataset):
    """The same samples as :class:`NoisyRawDataset`, streamed in order; ``batch_size`` samples at a time go to
    one ``DataLoader`` worker, in turn, so batches of that size are the same for any number of workers.

    ``samples=None`` streams the most a data set holds, 10^9. Other parameters as :class:`NoisyRawDataset`.
    """

    def __init__(self, samples: int | None = None, batch_size: int = 1, **kwargs):
        self.inner = NoisyRawDataset(samples if samples is not None else ds.MAX_SAMPLES, **kwargs)
        self.batch_size = int(batch_size)

    def set_epoch(self, epoch: int) -> None:
        self.inner.set_epoch(epoch)

    def __iter__(self):
        info = get_worker_info()
        worker, workers = (info.id, info.num_workers) if info is not None else (0, 1)
        total = len(self.inner)
        batches = math.ceil(total / self.batch_size)
        for b in range(worker, batches, workers):  # a batch's samples together (on the GPU: one launch)
            yield from self.inner.__getitems__(range(b * self.batch_size, min(total, (b + 1) * self.batch_size)))
