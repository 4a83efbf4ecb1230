"""cmosnoise.torch: the same samples as a data set's shards, the same batches for any number of DataLoader
workers, fresh noise per epoch only when asked; without PyTorch a clear message."""

import subprocess
import sys

import numpy as np
import pytest
from conftest import cli

from cmosnoise.app import dataset as ds
from cmosnoise.errors import CmosnoiseError

torch = pytest.importorskip("torch", reason="the torch extra: pip install 'cmosnoise[torch]'")
from torch.utils.data import DataLoader  # noqa: E402

from cmosnoise.torch import NoisyRawDataset, NoisyRawIterableDataset, ShardDataset, collate, pack  # noqa: E402

KW = dict(crop=(48, 64), cameras=("led", "sony-imx900", "eld:canon-70d"), seed=3, light_e=(20, 2000))


def test_the_dataset_gives_the_shards_samples_bit_for_bit(tmp_path):
    r = cli("-q", "dataset", "-n", "5", "--crop", "48x64", "--camera", "led", "--camera", "sony-imx900", "--camera",
            "eld:canon-70d", "--seed", "3", "--light", "20:2000", "--out", tmp_path / "d")
    assert r.returncode == 0, r.stderr
    arrays, columns = next(ds.read(tmp_path / "d"))
    data = NoisyRawDataset(5, **KW)
    for i in range(5):
        item = data[i]
        assert np.array_equal(item["raw"].numpy(), arrays["raw"][i].astype(np.int32))
        pattern = columns["cfa"][i]
        black, white = columns["black_level_dn"][i], columns["white_level_dn"][i]
        expect = pack((arrays["expected_raw"][i] - np.float32(black)) * np.float32(1 / (white - black)), pattern)
        assert np.array_equal(item["expected"].numpy(), expect)
        assert item["noisy"].shape == (4, 24, 32) and item["mask"].dtype == torch.int32
        assert item["meta"]["camera"] == columns["camera"][i]


def test_a_data_set_on_disk_reads_as_the_same_tensors_as_the_samples_made_on_the_fly(tmp_path):
    """#63: `cmosnoise dataset`'s shards into a DataLoader without hand-written h5py: ShardDataset's sample i is
    NoisyRawDataset's sample i (the same recipe), tensor for tensor, across shards and in worker processes."""
    r = cli("-q", "dataset", "-n", "5", "--crop", "48x64", "--camera", "led", "--camera", "sony-imx900", "--camera",
            "eld:canon-70d", "--seed", "3", "--light", "20:2000", "--shard-size", "2", "--out", tmp_path / "d")
    assert r.returncode == 0, r.stderr
    disk, made = ShardDataset(tmp_path / "d"), NoisyRawDataset(5, **KW)
    assert len(disk) == 5
    for i in (0, 3, 4, 1):  # out of order: shards read again
        a, b = disk[i], made[i]
        for k in ("noisy", "expected", "perfect", "mask", "raw"):
            assert torch.equal(a[k], b[k]), (i, k)
        assert a["meta"]["camera"] == b["meta"]["camera"] and a["meta"]["sample"] == i
    batches = list(DataLoader(disk, batch_size=2, num_workers=2, collate_fn=collate))
    assert [b["noisy"].shape[0] for b in batches] == [2, 2, 1]
    assert torch.equal(batches[1]["expected"][1], made[3]["expected"])
    (tmp_path / "d" / "shard-00001.h5").unlink()
    with pytest.raises(CmosnoiseError, match="lacks 1 of its 3 shards"):
        ShardDataset(tmp_path / "d")


def test_pack_puts_red_first_whatever_the_pattern():
    a = np.arange(16).reshape(4, 4)
    assert pack(a, "RGGB")[0, 0, 0] == 0 and pack(a, "BGGR")[0, 0, 0] == 5 and pack(a, "GRBG")[0, 0, 0] == 1
    assert pack(a, "BGGR")[3, 0, 0] == 0 and pack(a, "none").shape == (1, 4, 4)


def batches(loader):
    return [(b["noisy"].numpy(), b["mask"].numpy(), [m["sample"] for m in b["meta"]]) for b in loader]


def same(a, b):
    assert len(a) == len(b)
    for (n1, m1, s1), (n2, m2, s2) in zip(a, b):
        assert np.array_equal(n1, n2) and np.array_equal(m1, m2) and s1 == s2


def test_zero_and_two_workers_give_the_same_batches():
    data = NoisyRawDataset(6, **KW)
    zero = batches(DataLoader(data, batch_size=2, num_workers=0, collate_fn=collate))
    same(zero, batches(DataLoader(data, batch_size=2, num_workers=2, collate_fn=collate)))
    stream = NoisyRawIterableDataset(6, batch_size=2, **KW)
    same(zero, batches(DataLoader(stream, batch_size=2, num_workers=0, collate_fn=collate)))
    same(zero, batches(DataLoader(stream, batch_size=2, num_workers=2, collate_fn=collate)))


def test_the_same_sample_every_epoch_unless_fresh_noise():
    data = NoisyRawDataset(2, **KW)
    first = data[1]
    data.set_epoch(1)
    assert torch.equal(data[1]["noisy"], first["noisy"])
    fresh = NoisyRawDataset(2, fresh_noise=True, **KW)
    assert torch.equal(fresh[1]["noisy"], first["noisy"])
    fresh.set_epoch(1)
    again = fresh[1]
    assert not torch.equal(again["noisy"], first["noisy"])
    assert torch.equal(again["expected"], first["expected"])  # the same sensor and scene: the same truth


def test_a_users_clean_raw_mosaic():
    clean = np.random.default_rng(0).uniform(0.1, 0.9, (100, 120))
    data = NoisyRawDataset(3, crop=32, cameras=("sony-imx900@gain_db=0",), images=[clean], seed=1)
    item, (arrays, columns) = data[0], data.sample(0)
    r, c = columns["window_row"], columns["window_col"]
    assert r % 2 == 0 and c % 2 == 0
    # the perfect image is the mosaic's window at the light level (the sensor's responsivity is 1 for every colour)
    perfect_e = clean[r:r + 32, c:c + 32] * columns["light_e"]
    k, black = columns["k_dn_per_e"], columns["black_level_dn"]
    np.testing.assert_allclose(arrays["perfect_dn"], np.minimum(black + k * perfect_e, 4095), rtol=1e-5)
    assert item["noisy"].shape == (4, 16, 16)


def test_without_torch_cmosnoise_imports_and_cmosnoise_torch_says_how_to_install():
    code = ("import sys; sys.modules['torch'] = None\n"
            "import cmosnoise; cmosnoise.Sensor\n"
            "try:\n    import cmosnoise.torch\nexcept ImportError as e:\n    print(e)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "pip install 'cmosnoise[torch]'" in r.stdout


def test_a_stream_without_a_length_starts_and_gives_the_datasets_samples():
    stream = NoisyRawIterableDataset(batch_size=2, **KW)
    first = next(iter(stream))
    assert torch.equal(first["noisy"], NoisyRawDataset(1, **KW)[0]["noisy"])
