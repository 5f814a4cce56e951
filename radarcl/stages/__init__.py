"""One plan object per kernel file: an expensive constructor, a cheap checked call.

Every stage has the same surface (``Stage``), as silx's ``OpenclProcessing`` does: device
arrays allocated once in the constructor (``arrays``, one ``pyopencl.array.Array`` per input and
output named after its kernel argument), ``check`` (host frame -> checked array), ``upload``
(host -> its input arrays), ``enqueue`` (launch on device arrays: its own, or another stage's
outputs when chained, each checked for shape, dtype and context), ``download`` (outputs -> a
result object) and ``__call__`` (all four, blocking).

The constants the kernels share with Python (beam flags, the fixed-point log-odds unit, the grid
limit) are defined in Python only and reach every build as ``-D`` (``COMMON_DEFINES``);
``kernels/radarcl_common.h`` refuses to compile without them.
"""

from dataclasses import dataclass

import numpy as np

from radarcl import logodds, oracle
from radarcl.cl.limits import size_text
from radarcl.errors import ConfigError, DeviceCapabilityError, ShapeError
from radarcl.gridspec import GRID_LIMIT

COMMON_DEFINES = dict(
    FLAG_NONFINITE=oracle.FLAG_NONFINITE, FLAG_CLIPPED=oracle.FLAG_CLIPPED,
    FLAG_BAD_PROFILE=oracle.FLAG_BAD_PROFILE, FLAG_SILENT=oracle.FLAG_SILENT,
    FLAG_OVERRANGE=oracle.FLAG_OVERRANGE, FLAG_CROSSTALK=oracle.FLAG_CROSSTALK,
    NO_EVIDENCE_FLAGS=oracle.NO_EVIDENCE_FLAGS, PAIR_RATIO=oracle.PAIR_RATIO, PROFILE_LIMIT=oracle.PROFILE_LIMIT,
    LOGODDS_SCALE=float(logodds.SCALE), EVIDENCE_LIMIT_NATS=float(logodds.EVIDENCE_LIMIT_NATS),
    KNOWLEDGE_SCALE=logodds.KNOWLEDGE_SCALE,
    GRID_LIMIT=GRID_LIMIT,
)


def build(runtime, stem, defines):
    """``runtime.kernels(stem, ...)`` with the shared constants added to ``defines``."""
    clash = set(defines) & set(COMMON_DEFINES)
    if clash:
        raise ConfigError(f"{stem}: defines {sorted(clash)} are shared constants and come from radarcl")
    return runtime.kernels(stem, {**COMMON_DEFINES, **defines})


def beam_batch(batch):
    """A frame's beam shape as a tuple of positive ints, and its number of beams."""
    try:
        shape = tuple(_integer(b, "batch") for b in batch)
    except TypeError:
        raise ConfigError(f"batch must be a shape (a tuple of positive integers), got {batch!r}") from None
    if not shape or min(shape) < 1:
        raise ConfigError(f"batch must be a non-empty shape of positive sizes, got {batch!r}")
    return shape, int(np.prod(shape))


def count(value, what, lo=1):
    """An integer >= ``lo`` (not a bool, not 64.7), or ConfigError naming ``what``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < lo:
        raise ConfigError(f"{what} must be an integer >= {lo}, got {value!r}")
    return int(value)


def spacing(value, what="bin_spacing_m"):
    """A positive finite number of metres, or ConfigError."""
    import math

    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or value <= 0:
        raise ConfigError(f"{what} must be a positive finite number [m], got {value!r}")
    return float(value)


def _integer(value, what):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{what} must hold integers, got {value!r}")
    return int(value)


def work_group_size(runtime, kernels, requested, default):
    """``requested`` (or ``default``, capped by the device) checked against the compiled limit of
    ``kernels`` (one kernel, or a list launched with the same size): what a register-heavy GPU
    build allows can be less than the device's maximum."""
    kernels = kernels if isinstance(kernels, (list, tuple)) else [kernels]
    limit = min(runtime.max_local_size(k) for k in kernels)
    size = min(default, limit) if requested is None else requested
    if isinstance(size, bool) or not (isinstance(size, (int, np.integer)) and 1 <= size <= limit):
        raise ConfigError(f"local_size must be an integer in [1, {limit}], got {requested!r}")
    return int(size)


def check_array(array, shape, dtype, what):
    """``array`` as a contiguous ndarray, or ShapeError "expected <what> of shape S D, got ...".
    dtype None accepts any dtype."""
    array = np.asarray(array)
    if array.shape != tuple(shape) or (dtype is not None and array.dtype != dtype):
        wanted = np.dtype(dtype) if dtype is not None else "(any dtype)"
        raise ShapeError(f"expected {what} of shape {tuple(shape)} {wanted}, got {array.shape} {array.dtype}")
    return np.ascontiguousarray(array)


@dataclass(frozen=True)
class Port:
    """A device array of a stage: the kernel argument it is passed as, its shape and dtype, and
    what to call it in an error message."""

    name: str
    shape: tuple
    dtype: np.dtype
    what: str
    aliases: tuple = ()      # other shapes of the same elements a device array may have


class Stage:
    """The surface every plan shares (see the module docstring).

    A subclass builds its kernel, then calls ``_allocate(inputs, outputs)`` with its ``Port``s,
    and implements ``enqueue`` and ``_result``.
    """

    runtime = None
    inputs = ()
    outputs = ()

    def _allocate(self, inputs, outputs):
        import pyopencl.array as cla

        self.inputs, self.outputs = tuple(inputs), tuple(outputs)
        q = self.runtime.queue
        limit = self.runtime.limits.max_mem_alloc_size
        sizes = [float(np.prod(p.shape, dtype=np.float64)) * np.dtype(p.dtype).itemsize
                 for p in self.inputs + self.outputs]
        for p, nbytes in zip(self.inputs + self.outputs, sizes):   # before the driver refuses with a code
            if nbytes > limit:
                raise DeviceCapabilityError(f"{type(self).__name__}: {p.what} {tuple(p.shape)} {np.dtype(p.dtype)} "
                                            f"takes {size_text(nbytes)}, more than the largest buffer of "
                                            f"{self.runtime.name}, {size_text(limit)} (radarcl info)")
        self.runtime.hold(self, sum(sizes), f"{type(self).__name__}'s buffers")
        self.arrays = {p.name: cla.empty(q, p.shape, p.dtype) for p in self.inputs + self.outputs}
        self._ports = {p.name: p for p in self.inputs + self.outputs}

    def check_input(self, name, array):
        """Host ``array`` for input ``name`` as a contiguous ndarray, or ShapeError."""
        p = self._ports[name]
        return check_array(array, p.shape, p.dtype, p.what)

    def upload(self, **host):
        """Copy checked host arrays into the inputs named by the keywords (non-blocking);
        returns the copy events. Every array is checked before anything is copied."""
        import pyopencl as cl

        checked = {name: self.check_input(name, a) for name, a in host.items()}
        return [cl.enqueue_copy(self.runtime.queue, self.arrays[name].data, a, is_blocking=False)
                for name, a in checked.items()]

    def device(self, name, array=None):
        """The device array for input ``name``: this stage's own when ``array`` is None, or
        ``array`` (a ``pyopencl.array.Array`` of this context) checked for shape and dtype."""
        import pyopencl.array as cla

        if array is None:
            return self.arrays[name]
        p = self._ports[name]
        if not isinstance(array, cla.Array):
            raise ShapeError(f"expected {p.what} as a device array (pyopencl.array.Array) of shape {p.shape} "
                             f"{np.dtype(p.dtype)}, got {type(array).__name__}")
        if array.shape in p.aliases and array.dtype == p.dtype and array.flags.c_contiguous:
            array = array.reshape(p.shape)
        if array.shape != tuple(p.shape) or array.dtype != p.dtype:
            raise ShapeError(f"expected {p.what} of shape {tuple(p.shape)} {np.dtype(p.dtype)} on the device, "
                             f"got {array.shape} {array.dtype}")
        if array.context != self.runtime.context:
            raise ShapeError(f"{p.what} lives in another OpenCL context than this plan")
        if not array.flags.c_contiguous:
            raise ShapeError(f"{p.what} must be a contiguous device array")
        return array

    def download(self, wait_for=None):
        """Copy the outputs to the host (blocking) and return the stage's result object."""
        import pyopencl as cl

        host = {}
        for p in self.outputs:
            host[p.name] = np.empty(p.shape, p.dtype)
            cl.enqueue_copy(self.runtime.queue, host[p.name], self.arrays[p.name].data, wait_for=wait_for)
        return self._result(**host)

    def _result(self, **host):
        raise NotImplementedError

    def enqueue(self, *args, **kwargs):
        """Launch the kernel; returns its event."""
        raise NotImplementedError
