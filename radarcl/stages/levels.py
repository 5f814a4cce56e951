"""A polar scan's 8-bit levels -> float32 power on the device, right before the CFAR.

``Levels`` wraps ``kernels/levels.cl``; it is equivalent to
``radarcl.io.polar_png.levels_to_power(levels, db_per_level)``, bit for bit: both index the
same float32 ``polar_png.power_table``. A scan then travels to the device (and waits in a
drive's read-ahead queue) as its levels, a quarter of the bytes of its power, and the host
spends no time on the conversion. A scan that holds its rows' differences (a PNG's "Sub" rows,
``polar_png.PolarScan.differenced``) travels as those, and the device takes their running sums
first (``differenced``): the host only inflates the file.
"""

import numpy as np

from radarcl.errors import ConfigError
from radarcl.io.polar_png import power_table
from radarcl.stages import Port, Stage, beam_batch, build, work_group_size

DEFAULT_LOCAL_SIZE = 64
# Levels per work-item: one vector load and store each on a CPU (PoCL does not vectorise across
# work-items), one level per work-item on a GPU. Any width is correct (the tests run each).
CPU_VECTOR_WIDTH = 16
VECTOR_WIDTHS = (1, 4, 8, 16)


class Levels(Stage):
    """A compiled conversion for frames of one shape.

    runtime: a ``radarcl.cl.Runtime``; shape: one frame's levels, e.g. (400, 3768);
    db_per_level: decibels of power per level (``polar_png.PolarScan.db_per_level``; change it
    with ``set_db_per_level``); power: a float32 device array of ``shape`` to write the power
    into (e.g. a ``Cfar``'s ``arrays["profiles"]``; default: one of its own);
    local_size: work-items per group (default 64, capped by the device); vector_width: levels
    per work-item, one of 1, 4, 8, 16 (default 16 on a CPU device, 1 on a GPU; frames of row
    differences take a row per work-item, 16 differences at a time, whatever the width).
    """

    def __init__(self, runtime, shape, db_per_level=1.0, *, power=None, local_size=None, vector_width=None):
        self.runtime = runtime
        self.shape, self.n = beam_batch(shape)
        if vector_width is None:
            vector_width = CPU_VECTOR_WIDTH if runtime.is_cpu else 1
        if vector_width not in VECTOR_WIDTHS:
            raise ConfigError(f"vector_width must be one of {VECTOR_WIDTHS}, got {vector_width!r}")
        self.vector_width = int(vector_width)
        kernels = build(runtime, "levels", dict(VEC=self.vector_width))
        self._kernel, self._differenced = kernels["levels"], kernels["levels_differenced"]
        self.local_size = work_group_size(runtime, [self._kernel, self._differenced], local_size, DEFAULT_LOCAL_SIZE)
        out = Port("power", self.shape, np.dtype(np.float32), "power")
        inputs = [Port("levels", self.shape, np.dtype(np.uint8), "levels"),
                  Port("table", (256,), np.dtype(np.float32), "power table")]
        if power is None:
            self._allocate(inputs, [out])
        else:                               # the next stage's input: no buffer of its own
            self._allocate(inputs, [])
            self._ports["power"] = out
            self.outputs = (out,)
            self.arrays["power"] = self.device("power", power)
        self.db_per_level = None
        self.set_db_per_level(db_per_level)

    def set_db_per_level(self, db_per_level):
        """Convert with ``polar_png.power_table(db_per_level)`` from now on (a blocking copy of
        256 floats when it changes; FrameFormatError for a scale whose levels overflow float32)."""
        if db_per_level != self.db_per_level:
            table = power_table(db_per_level)
            self.runtime.queue.finish()             # a conversion still queued reads the old table
            super().upload(table=table)[0].wait()
            self.db_per_level = db_per_level

    def check(self, levels, name="levels"):
        """Raise ShapeError unless ``levels`` is one uint8 frame of this plan's shape."""
        return self.check_input(name, levels)

    def upload(self, levels):
        """Copy a checked frame of levels into the plan's input array; returns the copy event."""
        return super().upload(levels=levels)[0]

    def enqueue(self, levels=None, wait_for=None, differenced=False):
        """Launch on a device array of levels (default: this plan's, as ``upload`` filled it);
        ``differenced``: its rows (the last axis) hold their levels' differences, the first its
        level (``polar_png.PolarScan.differenced``). The power lands in ``arrays["power"]``.
        Returns the kernel event."""
        ls = self.local_size
        levels = self.device("levels", levels)
        if differenced:
            row_len = self.shape[-1]
            rows = self.n // row_len
            return self._differenced(self.runtime.queue, (-(-rows // ls) * ls,), (ls,), wait_for=wait_for,
                                     coded=levels, table=self.arrays["table"], n_rows=rows, row_len=row_len,
                                     power=self.arrays["power"])
        items = -(-self.n // self.vector_width)
        return self._kernel(self.runtime.queue, (-(-items // ls) * ls,), (ls,), wait_for=wait_for,
                            levels=levels, table=self.arrays["table"], n=self.n, power=self.arrays["power"])

    def _result(self, power):
        return power

    def __call__(self, levels, differenced=False):
        """One frame of levels (shape) uint8 -> its power (shape) float32 (blocking);
        ``differenced`` as ``enqueue``."""
        copy = self.upload(levels)
        return self.download(wait_for=[self.enqueue(wait_for=[copy], differenced=differenced)])

