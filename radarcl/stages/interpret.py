"""The down-range interpreter, eq. 12, on whole frames (paper §3.3, Fig. 10).

``Interpreter`` wraps ``kernels/interpret.cl``; it is equivalent to
``radarcl.oracle.interpret(profiles, noise, mask, config, bin_spacing_m, flags)``: pulses,
counts and flags identical, evidence identical on noise bins and within
``EVIDENCE_UNITS_TOL`` fixed-point unit on pulse bins (float32 vs float64 logs; see
tests/test_interpret.py). Evidence is int32 in ``radarcl.logodds`` units.
"""

from dataclasses import dataclass

import numpy as np

from radarcl import logodds, oracle
from radarcl.config import InterpretConfig
from radarcl.errors import ConfigError
from radarcl.stages import beam_batch, check_array, work_group_size

# Beams per work-group. One work-item walks one beam; any size is correct.
DEFAULT_LOCAL_SIZE = 16


@dataclass(frozen=True)
class InterpretResult:
    """Evidence and pulses of one frame; ``batch`` is the frame's beam shape."""

    evidence: np.ndarray   # int32 (*batch, n_bins), logodds units
    pulses: np.ndarray     # int32 (*batch, max_pulses, 4): start, end, peak, wide; -1 unused
    n_pulses: np.ndarray   # int32 (*batch,): pulses found, may exceed max_pulses
    flags: np.ndarray      # uint8 (*batch,): oracle.FLAG_* bits

    @property
    def valid(self):
        """Beams that give evidence."""
        return (self.flags & oracle.NO_EVIDENCE_FLAGS) == 0


class Interpreter:
    """A compiled eq. 12 plan for frames of one shape.

    runtime: a ``radarcl.cl.Runtime``; batch: the beam shape, e.g. (64, 4) or (400,);
    n_bins: bins per profile; bin_spacing_m: range between bins (bin j sits at j x spacing);
    config: an ``InterpretConfig``; local_size: beams per work-group.
    """

    def __init__(self, runtime, batch, n_bins, bin_spacing_m, config=None, *, local_size=None):
        import pyopencl as cl

        self.runtime = runtime
        self.config = config if config is not None else InterpretConfig()
        if not isinstance(self.config, InterpretConfig):
            raise ConfigError(f"config must be an InterpretConfig, got {type(self.config).__name__}")
        self.batch, self.n_beams = beam_batch(batch)
        self.n_bins = int(n_bins)
        if self.n_bins < 1:
            raise ConfigError(f"n_bins must be positive, got {n_bins!r}")
        self.bin_spacing_m = float(bin_spacing_m)
        self.first_bin, self.last_bin = self.config.bin_interval(self.bin_spacing_m, self.n_bins)
        self.wide_bins = self.config.wide_bins(self.bin_spacing_m)
        self.e_high, self.e_low = (int(v) for v in logodds.to_fixed([self.config.e_high, self.config.e_low]))
        self._kernel = runtime.kernels("interpret", dict(N_BINS=self.n_bins,
                                                         MAX_PULSES=self.config.max_pulses))["interpret"]
        self._kernel.set_scalar_arg_dtypes([None, None, None, None, np.float32] + [np.int32] * 6
                                           + [None] * 4)
        self.local_size = work_group_size(runtime, self._kernel, local_size, DEFAULT_LOCAL_SIZE)
        self.evidence_buf = runtime.empty(4 * self.n_beams * self.n_bins)
        self.pulses_buf = runtime.empty(16 * self.n_beams * self.config.max_pulses)
        self.n_pulses_buf = runtime.empty(4 * self.n_beams)
        self.flags_buf = runtime.empty(self.n_beams)
        self._no_flags = runtime.to_device(np.zeros(self.n_beams, np.uint8))
        self._cl = cl

    @property
    def input_shape(self):
        """Shape of a frame of profiles: (*batch, n_bins)."""
        return (*self.batch, self.n_bins)

    def check_flags(self, flags):
        """Per-beam flags as a contiguous uint8 array of shape ``batch``, or ShapeError."""
        return check_array(flags, self.batch, np.uint8, "flags")

    def enqueue(self, profiles_buf, noise_buf, mask_buf, flags_buf=None, wait_for=None):
        """Launch on device buffers (profiles float32, CFAR noise float32 and mask uint8,
        per-beam uint8 flags or None). Results stay in ``evidence_buf``, ``pulses_buf``,
        ``n_pulses_buf``, ``flags_buf``. Returns the kernel event."""
        ls = self.local_size
        gsize = (-(-self.n_beams // ls) * ls,)
        return self._kernel(self.runtime.queue, gsize, (ls,), profiles_buf, noise_buf, mask_buf,
                            self._no_flags if flags_buf is None else flags_buf,
                            float(self.config.k_occ), self.e_high, self.e_low, self.first_bin,
                            self.last_bin, self.wide_bins, self.n_beams, self.evidence_buf,
                            self.pulses_buf, self.n_pulses_buf, self.flags_buf, wait_for=wait_for)

    def download(self, wait_for=None):
        """Copy the last results to the host (blocking) as an InterpretResult."""
        cl, q = self._cl, self.runtime.queue
        evidence = np.empty(self.input_shape, np.int32)
        pulses = np.empty((*self.batch, self.config.max_pulses, 4), np.int32)
        n_pulses = np.empty(self.batch, np.int32)
        flags = np.empty(self.batch, np.uint8)
        for host, buf in ((evidence, self.evidence_buf), (pulses, self.pulses_buf),
                          (n_pulses, self.n_pulses_buf), (flags, self.flags_buf)):
            cl.enqueue_copy(q, host, buf, wait_for=wait_for)
        return InterpretResult(evidence, pulses, n_pulses, flags)

    def __call__(self, profiles, noise, mask, flags=None):
        """Interpret one frame given on the host (blocking): profiles and noise float32,
        mask bool or uint8, all (*batch, n_bins); flags uint8 (*batch,) or None."""
        rt = self.runtime
        profiles = check_array(profiles, self.input_shape, np.float32, "profiles")
        noise = check_array(noise, self.input_shape, np.float32, "noise")
        mask = check_array(mask, self.input_shape, None, "mask")
        if flags is not None:
            flags = self.check_flags(flags)
        bufs = [rt.to_device(profiles), rt.to_device(noise), rt.to_device(mask.astype(np.uint8)),
                None if flags is None else rt.to_device(flags)]
        return self.download(wait_for=[self.enqueue(*bufs)])
