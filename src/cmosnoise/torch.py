"""PyTorch datasets of noisy raw samples with ground truth (the optional extra: ``pip install 'cmosnoise[torch]'``).

::

    from torch.utils.data import DataLoader
    from cmosnoise.torch import NoisyRawDataset, collate

    data = NoisyRawDataset(samples=10000, crop=256, cameras=["led", "sony-imx900"])
    for batch in DataLoader(data, batch_size=16, num_workers=4, collate_fn=collate):
        noisy, target = batch["noisy"], batch["expected"]   # (16, 4, 128, 128), normalized

    # a data set that `cmosnoise dataset` wrote: the same samples, read from its shards
    from cmosnoise.torch import ShardDataset
    train = DataLoader(ShardDataset("train"), batch_size=16, num_workers=4, collate_fn=collate)

See :mod:`cmosnoise.app.torch_data`.
"""

try:
    import torch  # noqa: F401
except ImportError:  # pragma: no cover - the message is the test
    raise ImportError("cmosnoise.torch needs PyTorch: pip install 'cmosnoise[torch]' (or pip install torch)") from None

from .app.torch_data import NoisyRawDataset, NoisyRawIterableDataset, ShardDataset, collate, pack, to_tensors  # noqa: E402

__all__ = ["NoisyRawDataset", "NoisyRawIterableDataset", "ShardDataset", "collate", "pack", "to_tensors"]
