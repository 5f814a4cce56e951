"""One plan object per kernel file: an expensive constructor, a cheap checked call.

The checks every plan makes the same way live here, so their messages read alike.
"""

import numpy as np

from radarcl.errors import ConfigError, ShapeError


def beam_batch(batch):
    """A frame's beam shape as a tuple of positive ints, and its number of beams."""
    shape = tuple(int(b) for b in batch)
    if not shape or min(shape) < 1:
        raise ConfigError(f"batch must be a non-empty shape of positive sizes, got {batch!r}")
    return shape, int(np.prod(shape))


def work_group_size(runtime, kernel, requested, default):
    """``requested`` (or ``default``, capped by the device) checked against the kernel's limit."""
    limit = runtime.max_local_size(kernel)
    size = min(default, limit) if requested is None else requested
    if not (isinstance(size, (int, np.integer)) and 1 <= size <= limit):
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


def upload(runtime, buffer, array):
    """Copy ``array`` into ``buffer`` (allocated on first use); returns (buffer, copy event)."""
    import pyopencl as cl

    if buffer is None:
        buffer = runtime.empty(array.nbytes)
    return buffer, cl.enqueue_copy(runtime.queue, buffer, array, is_blocking=False)
