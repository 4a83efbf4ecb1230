"""DLPack with ctypes alone (engine/dlpack.py, #31): the structs, the hand-over, and who frees what.

The consumers here are NumPy's and PyTorch's own ``from_dlpack`` (host memory: the layout of the structs is read by
code that is not ours) and our reader fed by NumPy's and PyTorch's own producers. On a GPU the same structs carry
device type 2 (CUDA); in numba's simulator a frame's view offers the host memory that stands for the GPU's."""

import gc
import weakref

import numpy as np
import pytest

from cmosnoise import Sensor
from cmosnoise.engine import dlpack
from cmosnoise.engine.frame import cuda_kernel
from cmosnoise.errors import CmosnoiseError

torch = pytest.importorskip("torch", reason="the DLPack tests read and write PyTorch tensors: pip install '.[torch]'")


class Owner:
    """Memory with a weak reference to tell when it is let go."""

    def __init__(self, array):
        self.array = array


def _view(a, owner):
    return dlpack.View(a.ctypes.data, a.shape, a.strides, a.dtype, (dlpack.CPU, 0), owner)


@pytest.mark.parametrize("dtype", [np.uint16, np.float32, np.float64, np.int64, np.uint8, np.bool_])
def test_numpy_and_pytorch_read_our_tensors_without_a_copy(dtype):
    base = (np.arange(60) % 7).astype(dtype).reshape(5, 12)
    for a in (base, base[1:4, ::3], base.T):  # contiguous, strided, transposed
        got = np.from_dlpack(_view(a, Owner(a)))
        assert got.dtype == a.dtype and got.shape == a.shape and np.array_equal(got, a)
        assert np.shares_memory(got, base)
        t = torch.from_dlpack(_view(a, Owner(a)))
        assert t.data_ptr() == a.ctypes.data and np.array_equal(t.numpy(), a)


def test_the_owner_lives_until_the_consumer_lets_go():
    a = np.arange(12.0)
    owner = Owner(a)
    ref = weakref.ref(owner)
    got = np.from_dlpack(_view(a, owner))
    del owner
    gc.collect()
    assert ref() is not None and got.sum() == 66.0  # the consumer holds it
    held = len(dlpack._HELD)
    del got
    gc.collect()
    assert ref() is None and len(dlpack._HELD) == held - 1  # its deleter ran
    # a capsule nobody consumed frees its tensor when it is collected
    owner = Owner(a)
    ref = weakref.ref(owner)
    capsule = _view(a, owner).__dlpack__()
    del owner, capsule
    gc.collect()
    assert ref() is None


def test_we_read_numpys_and_pytorchs_tensors():
    a = np.arange(24, dtype=np.float32).reshape(4, 6)[:, 1::2]
    t = dlpack.read(a)
    assert t.device == (dlpack.CPU, 0) and t.shape == (4, 3) and t.strides == a.strides and t.dtype == a.dtype
    assert t.data == a.__array_interface__["data"][0] and np.array_equal(np.asarray(t), a)
    x = torch.arange(10, dtype=torch.int16).reshape(2, 5)
    tx = dlpack.read(x)
    assert tx.shape == (2, 5) and tx.dtype == np.int16 and tx.data == x.data_ptr()
    assert np.array_equal(np.asarray(tx), x.numpy())
    with pytest.raises(TypeError, match="not an integer, float or bool"):
        dlpack.capsule(a.ctypes.data, (1,), (8,), np.complex64, (dlpack.CPU, 0), a)


@pytest.mark.gpu
def test_frames_left_on_the_device_go_out_and_come_in_by_dlpack():
    """A batch of frames made on the device leaves by DLPack without PyTorch in the way, and a mean charge offered
    only by DLPack comes in (the simulator's device memory is host memory: device type CPU)."""
    shot = Sensor({"sensor": {"width": 16, "height": 12}}, seed=2, device="cuda").expose("flat:0.3")
    raw, _ = shot.frames_on_device([0, 1])
    view = cuda_kernel.dlpack_view(raw)
    assert view.__dlpack_device__() == ((dlpack.CPU, 0) if cuda_kernel.simulated() else (dlpack.CUDA, 0))
    if cuda_kernel.simulated():
        out = np.from_dlpack(view)
        assert np.array_equal(out, raw.copy_to_host()) and np.array_equal(out[1], shot.frame(1))

    class OnlyDLPack:  # an array that speaks nothing but DLPack (as JAX's do)
        def __init__(self, a):
            self.a = a

        def __dlpack__(self, stream=None):
            return self.a.__dlpack__()

        def __dlpack_device__(self):
            return self.a.__dlpack_device__()

    means = shot.plan().noisy_e
    if cuda_kernel.simulated():
        plan = shot.device_plan().with_means(noisy_e=OnlyDLPack(np.ascontiguousarray(means)))
        again, _ = plan.render([0, 1], np.zeros((2, 2), np.int64), means.shape, False)
        assert np.array_equal(again.copy_to_host(), raw.copy_to_host())
    else:  # a host array is refused where a GPU's is wanted
        with pytest.raises(CmosnoiseError, match="expected one on the GPU"):
            cuda_kernel.as_device_array(OnlyDLPack(np.ascontiguousarray(means)))
