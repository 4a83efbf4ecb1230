"""DLPack without a framework: arrays handed to JAX, CuPy, PyTorch or NumPy and taken from them by the DLPack
protocol (``__dlpack__`` / ``__dlpack_device__``), with ctypes alone.

A producer builds a ``DLManagedTensor`` (the DLPack 0.8 structs below) over memory another object owns, and hands
it out in a ``PyCapsule`` named ``"dltensor"``; the consumer renames the capsule ``"used_dltensor"`` and calls the
tensor's ``deleter`` when it is done, which releases the owner. A capsule nobody consumed calls the deleter when it
is collected. :class:`View` is the producer (:func:`cmosnoise.engine.frame.cuda_kernel.dlpack` wraps a frame left on the
GPU in one); :func:`read` is the consumer (what :func:`cmosnoise.engine.frame.cuda_kernel.as_device_array` does with an
array that only speaks DLPack).

The deleter is a C callback, so it and the owners of the tensors handed out and not yet deleted live in this
module (:data:`_HELD`): the one piece of module state, which the protocol's C side needs.
"""

from __future__ import annotations

import ctypes

import numpy as np

#: DLDeviceType: where the memory is
CPU, CUDA = 1, 2
#: DLDataTypeCode of NumPy's kinds
_CODES = {"i": 0, "u": 1, "f": 2, "b": 6}
_KINDS = {v: k for k, v in _CODES.items()}


class DLDevice(ctypes.Structure):
    _fields_ = [("device_type", ctypes.c_int32), ("device_id", ctypes.c_int32)]


class DLDataType(ctypes.Structure):
    _fields_ = [("code", ctypes.c_uint8), ("bits", ctypes.c_uint8), ("lanes", ctypes.c_uint16)]


class DLTensor(ctypes.Structure):
    _fields_ = [("data", ctypes.c_void_p), ("device", DLDevice), ("ndim", ctypes.c_int32), ("dtype", DLDataType),
                ("shape", ctypes.POINTER(ctypes.c_int64)), ("strides", ctypes.POINTER(ctypes.c_int64)),
                ("byte_offset", ctypes.c_uint64)]


class DLManagedTensor(ctypes.Structure):
    pass


_DELETER = ctypes.CFUNCTYPE(None, ctypes.POINTER(DLManagedTensor))
DLManagedTensor._fields_ = [("dl_tensor", DLTensor), ("manager_ctx", ctypes.c_void_p), ("deleter", _DELETER)]

_api = ctypes.pythonapi
_api.PyCapsule_New.restype = ctypes.py_object
_api.PyCapsule_New.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p]
_api.PyCapsule_GetPointer.restype = ctypes.c_void_p
_api.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
_api.PyCapsule_SetName.restype = ctypes.c_int
_api.PyCapsule_SetName.argtypes = [ctypes.py_object, ctypes.c_char_p]
_api.PyCapsule_IsValid.restype = ctypes.c_int
_api.PyCapsule_IsValid.argtypes = [ctypes.py_object, ctypes.c_char_p]

#: what each tensor handed out and not yet deleted keeps alive, by its address: (its struct, shape and strides
#: buffers, the memory's owner)
_HELD: dict[int, tuple] = {}


@_DELETER
def _delete(managed) -> None:  # called by the consumer (or the capsule's destructor) once
    _HELD.pop(ctypes.addressof(managed.contents), None)


_CAPSULE_DESTRUCTOR = ctypes.CFUNCTYPE(None, ctypes.c_void_p)


@_CAPSULE_DESTRUCTOR
def _capsule_gone(capsule) -> None:
    """A capsule collected unconsumed (still named "dltensor"): its tensor's deleter runs here."""
    obj = ctypes.cast(capsule, ctypes.py_object)
    if _api.PyCapsule_IsValid(obj, b"dltensor"):
        address = _api.PyCapsule_GetPointer(obj, b"dltensor")
        _HELD.pop(address, None)


def capsule(data: int, shape, strides_bytes, dtype, device: tuple[int, int], owner) -> object:
    """A DLPack capsule over ``data`` (an address), keeping ``owner`` alive until the consumer is done.

    Parameters
    ----------
    data : int
        The first element's address.
    shape : sequence of int
        The array's shape.
    strides_bytes : sequence of int
        Its strides in bytes (multiples of the item size).
    dtype : numpy dtype
        An integer, unsigned, float or bool dtype.
    device : (int, int)
        ``(device_type, device_id)``: (:data:`CPU`, 0) or (:data:`CUDA`, the GPU's number).
    owner : object
        What owns the memory.

    Returns
    -------
    PyCapsule
        Named ``"dltensor"``, as ``__dlpack__`` returns one.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine import dlpack
    >>> a = np.arange(6, dtype=np.uint16).reshape(2, 3)
    >>> view = dlpack.View(a.ctypes.data, a.shape, a.strides, a.dtype, (dlpack.CPU, 0), a)
    >>> np.from_dlpack(view).tolist()
    [[0, 1, 2], [3, 4, 5]]
    """
    dtype = np.dtype(dtype)
    if dtype.kind not in _CODES:
        raise TypeError(f"DLPack: dtype {dtype} is not an integer, float or bool type")
    ndim = len(shape)
    shape_buf = (ctypes.c_int64 * max(ndim, 1))(*[int(v) for v in shape])
    strides_buf = (ctypes.c_int64 * max(ndim, 1))(*[int(s) // dtype.itemsize for s in strides_bytes])
    managed = DLManagedTensor()
    t = managed.dl_tensor
    t.data = ctypes.c_void_p(int(data))
    t.device = DLDevice(*device)
    t.ndim = ndim
    t.dtype = DLDataType(_CODES[dtype.kind], dtype.itemsize * 8, 1)
    t.shape = ctypes.cast(shape_buf, ctypes.POINTER(ctypes.c_int64))
    t.strides = ctypes.cast(strides_buf, ctypes.POINTER(ctypes.c_int64))
    t.byte_offset = 0
    managed.deleter = _delete
    address = ctypes.addressof(managed)
    _HELD[address] = (managed, shape_buf, strides_buf, owner)
    return _api.PyCapsule_New(address, b"dltensor", ctypes.cast(_capsule_gone, ctypes.c_void_p))


class View:
    """An array's memory offered by the DLPack protocol: ``np.from_dlpack(view)``, ``torch.from_dlpack(view)``,
    ``cupy.from_dlpack(view)``, ``jax.dlpack.from_dlpack(view)`` take it without a copy.

    Parameters
    ----------
    data, shape, strides_bytes, dtype, device, owner
        As :func:`capsule` takes them.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine import dlpack
    >>> a = np.ones((2, 2), np.float32)
    >>> view = dlpack.View(a.ctypes.data, a.shape, a.strides, a.dtype, (dlpack.CPU, 0), a)
    >>> view.__dlpack_device__(), np.from_dlpack(view).sum()
    ((1, 0), np.float32(4.0))
    """

    def __init__(self, data: int, shape, strides_bytes, dtype, device: tuple[int, int], owner):
        self._args = (int(data), tuple(int(v) for v in shape), tuple(int(s) for s in strides_bytes), np.dtype(dtype),
                      (int(device[0]), int(device[1])), owner)
        self.shape, self.dtype = self._args[1], self._args[3]

    def __dlpack__(self, stream=None, max_version=None, dl_device=None, copy=None):
        """A capsule over the memory (the work that made it is done: ``stream`` is not waited on)."""
        if copy:
            raise BufferError("DLPack: this view does not copy (copy=True asked for one)")
        return capsule(*self._args)

    def __dlpack_device__(self) -> tuple[int, int]:
        """``(device_type, device_id)`` of the memory."""
        return self._args[4]


class Taken:
    """A consumed DLPack tensor's memory, held until this object is collected (then its deleter runs): the owner a
    wrapping array keeps. ``__cuda_array_interface__`` describes it where it is on a GPU, ``__array_interface__``
    where it is in host memory."""

    def __init__(self, managed_address: int):
        self._managed = ctypes.cast(managed_address, ctypes.POINTER(DLManagedTensor))
        t = self._managed.contents.dl_tensor
        self.device = (int(t.device.device_type), int(t.device.device_id))
        code, bits, lanes = int(t.dtype.code), int(t.dtype.bits), int(t.dtype.lanes)
        if lanes != 1 or code not in _KINDS:
            raise TypeError(f"DLPack: data type code {code}, {bits} bits, {lanes} lanes is not a plain array's")
        self.dtype = np.dtype(f"{_KINDS[code]}{bits // 8}") if code != 6 else np.dtype(bool)
        self.shape = tuple(int(t.shape[i]) for i in range(t.ndim))
        if t.strides:
            self.strides = tuple(int(t.strides[i]) * self.dtype.itemsize for i in range(t.ndim))
        else:  # C order
            self.strides = tuple(int(np.prod(self.shape[i + 1:], dtype=np.int64)) * self.dtype.itemsize
                                 for i in range(t.ndim))
        self.data = int(t.data or 0) + int(t.byte_offset)
        desc = {"shape": self.shape, "strides": self.strides, "typestr": self.dtype.str, "data": (self.data, False),
                "version": 3}
        if self.device[0] == CPU:
            self.__array_interface__ = desc
        else:
            self.__cuda_array_interface__ = {**desc, "stream": None}

    def __del__(self):
        managed = self._managed.contents
        if managed.deleter:
            managed.deleter(self._managed)


def read(obj) -> Taken:
    """Take an array by the DLPack protocol: ``obj.__dlpack__()``'s tensor, consumed (its capsule renamed
    "used_dltensor"), its memory described and held.

    Parameters
    ----------
    obj : object with ``__dlpack__``
        A JAX, CuPy or PyTorch array, a NumPy array, or a :class:`View`.

    Returns
    -------
    Taken
        ``device``, ``shape``, ``strides`` (bytes), ``dtype``, ``data`` (the address), and the array interface
        that fits where it lives.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.engine import dlpack
    >>> a = np.arange(6.0).reshape(2, 3)
    >>> t = dlpack.read(a)
    >>> t.device, t.shape, t.data == a.ctypes.data, np.asarray(t).tolist()
    ((1, 0), (2, 3), True, [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]])
    """
    cap = obj.__dlpack__()
    address = _api.PyCapsule_GetPointer(cap, b"dltensor")
    taken = Taken(address)
    _api.PyCapsule_SetName(cap, b"used_dltensor")  # consumed: the capsule's destructor leaves it to us
    return taken
