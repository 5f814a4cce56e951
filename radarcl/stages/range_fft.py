"""Range FFT of whole frames: window, zero padding, FFT, magnitude or power (paper §3.2).

``RangeFFT`` wraps ``kernels/range_fft.cl``; it is equivalent to
``radarcl.oracle.range_profile(samples, n_fft, window=..., output=..., gain=...)`` and
``radarcl.oracle.beam_flags(samples, clip_level)``, within ``RANGE_FFT_RTOL`` of the
float64 oracle (see tests/test_range_fft.py).

Bad samples: a beam with a NaN or Inf sample is flagged ``FLAG_NONFINITE``, one with a float
sample beyond ``oracle.sample_limit`` (its power would overflow float32) ``FLAG_OVERRANGE``;
both are written as NaN, counted in ``RangeFFTResult.n_invalid``, and give no evidence
downstream; their paired beam is unaffected. Real beams are paired in one complex FFT: the
weaker of a pair whose peaks differ by more than ``oracle.PAIR_RATIO`` is flagged
``FLAG_CROSSTALK`` and gives no evidence (int16 input never reaches it). A beam that reaches
``clip_level`` is flagged ``FLAG_CLIPPED`` and counted.

Work memory: the kernel's two complex ping-pong buffers (2 x n_fft x vector_width complex64 per
work-group) live in local memory where the device's holds them, the faster path; otherwise in a
global scratch buffer the plan allocates once, one slice per work-group (``scratch_space`` says
which), so every n_fft up to ``MAX_FFT`` runs on any device, a GPU with 16 KiB of local memory
included. Both paths do the same arithmetic in the same order.
"""

import math
import numbers
from dataclasses import dataclass

import numpy as np

from radarcl import oracle
from radarcl.cl.limits import size_text
from radarcl.config.stage_config import is_power_of_two
from radarcl.errors import ConfigError, DeviceCapabilityError, ShapeError
from radarcl.stages import Port, Stage, beam_batch, build, count

# PoCL does not vectorise across work-items here, so the lanes of float16 (8 beam pairs) carry
# the SIMD; GPUs vectorise across work-items and take vector_width 1 and n_fft/4 workers.
# Full groups of real beams load each sample row as two vectors with the checks per lane
# (lane by lane with branches the loads took half the kernel): bench range-fft, upload +
# kernel vs scipy.fft, 1.37 / 1.15 -> 0.95 / 0.90 at n_fft 512 / 1024 (PoCL 3.1, Zen 5).
MAX_FFT = 1 << 16              # the longest transform the tests check against the oracle
CPU_LOCAL_SIZE = 16
CPU_VECTOR_WIDTH = 8
VECTOR_WIDTHS = (1, 2, 4, 8)
_INPUT_KINDS = {np.dtype(np.float32): 0, np.dtype(np.int16): 1, np.dtype(np.complex64): 2}


@dataclass(frozen=True)
class RangeFFTResult:
    """Profiles (*batch, n_bins) float32 and per-beam flags (*batch,) uint8."""

    profiles: np.ndarray
    flags: np.ndarray

    @property
    def valid(self):
        """Boolean mask of beams that may give evidence (no NaN/Inf or out-of-range sample, no
        crosstalk from a far stronger paired beam)."""
        return (self.flags & oracle.NO_EVIDENCE_FLAGS) == 0

    @property
    def n_invalid(self):
        """Beams that give no evidence: a NaN, Inf or out-of-range sample, or crosstalk."""
        return int(np.count_nonzero(~self.valid))

    @property
    def n_clipped(self):
        """Beams with at least one sample at the clip level."""
        return int(np.count_nonzero(self.flags & oracle.FLAG_CLIPPED))


class RangeFFT(Stage):
    """A compiled range-FFT plan for frames of one shape and dtype.

    runtime: a ``radarcl.cl.Runtime``.
    batch: the beam shape of a frame, e.g. (n_az, n_el) = (64, 4), or (1,) for one chirp.
    n_samples: samples per beam; n_fft: padded length, a power of two >= max(n_samples, 4).
    dtype: float32 or int16 (real ADC samples) or complex64 (I/Q).
    window: "hann" or "rect". output: "magnitude" or "power".
    gain: optional (n_bins,) factor per bin, e.g. ``oracle.range_gain`` for r^k compensation.
    clip_level: |sample| at or above this flags the beam CLIPPED (default: int16 rails
        for int16 input, never for floats).
    local_size: work-group size (a power of two dividing n_fft/4); default 16 on a CPU device,
        n_fft/4 (or the device limit) on a GPU, halved to what the built kernel allows
        (CL_KERNEL_WORK_GROUP_SIZE); a local_size the built kernel cannot run is refused.
    vector_width: jobs (beam pairs, or I/Q beams) per work-group, one per SIMD lane: 1, 2, 4, 8;
        default 8 on a CPU device (halved until its buffers fit the device's local memory; 8
        with global work buffers when no width fits), 1 on a GPU.

    Float outputs stay finite: samples beyond ``oracle.sample_limit(n_samples)`` are flagged.

    After construction ``scratch_space`` is "local" or "global" (where the work buffers live),
    ``local_bytes`` the local memory a work-group uses and ``scratch_bytes`` the global scratch
    buffer's size (0 on the local path).
    """

    def __init__(self, runtime, batch, n_samples, n_fft, *, dtype=np.int16, window="hann",
                 output="magnitude", gain=None, clip_level=None, local_size=None, vector_width=None):
        self.runtime = runtime
        self.batch, self.n_beams = beam_batch(batch)
        self.n_samples = count(n_samples, "n_samples", lo=2)
        if not is_power_of_two(n_fft) or n_fft < max(self.n_samples, 4) or n_fft > MAX_FFT:
            raise ConfigError(f"n_fft must be a power of two >= max(n_samples, 4) = {max(self.n_samples, 4)} "
                              f"(eq. 11 pads, never truncates) and <= {MAX_FFT}, got {n_fft!r}")
        self.n_fft = int(n_fft)
        try:
            self.dtype = np.dtype(dtype)
        except TypeError:
            raise ConfigError(f"dtype must be one of float32, int16, complex64, got {dtype!r}") from None
        if self.dtype not in _INPUT_KINDS:
            raise ConfigError(f"dtype must be one of float32, int16, complex64, got {self.dtype}")
        self.complex_input = self.dtype == np.complex64
        self.n_bins = self.n_fft if self.complex_input else self.n_fft // 2
        if output not in oracle.OUTPUTS:
            raise ConfigError(f"output must be one of {oracle.OUTPUTS}, got {output!r}")
        self.window_kind, self.output = window, output
        w = oracle.window_coefficients(window, self.n_samples)

        # Calibration: divide by the window's coherent gain (squared for power), times gain.
        calibration = (1.0 / w.sum()) ** (2 if output == "power" else 1)
        per_bin = np.full(self.n_bins, calibration)
        if gain is not None:
            gain = np.asarray(gain)
            if gain.dtype.kind not in "iuf":
                raise ShapeError(f"gain must be real numbers with shape ({self.n_bins},), got {gain.shape} {gain.dtype}")
            gain = gain.astype(np.float64)
            if gain.shape != (self.n_bins,) or not np.isfinite(gain).all():
                raise ShapeError(f"gain must be finite with shape ({self.n_bins},), got {gain.shape}")
            per_bin = per_bin * gain
        if clip_level is None:
            clip_level = 32767.0 if self.dtype == np.int16 else math.inf
        if isinstance(clip_level, (bool, str, bytes)) or not isinstance(clip_level, numbers.Real):
            raise ConfigError(f"clip_level must be a positive number (|sample| that flags a beam clipped), "
                              f"got {clip_level!r}")
        self.clip_level = float(clip_level)
        if math.isnan(self.clip_level) or self.clip_level <= 0:
            raise ConfigError(f"clip_level must be positive, got {clip_level!r}")

        m = 1 << max(1, math.ceil(math.log2(self.n_samples)))  # sub-transform length >= n_samples
        limits = runtime.limits                # every device limit from here, never runtime.device
        beams_per_job = 1 if self.complex_input else 2

        def buffer_bytes(width):             # the two complex ping-pong buffers of a work-group
            return 2 * self.n_fft * np.dtype(np.complex64).itemsize * width

        def flag_bytes(width):               # job_flags and job_peak: one int per beam of the group
            return 2 * 4 * beams_per_job * width

        def fits_local(width):
            return buffer_bytes(width) + flag_bytes(width) <= limits.local_mem_size

        if vector_width is None:
            # The widest lane count up to the device default whose buffers fit local memory
            # (PoCL reports 512 KiB on some CPUs, 4 MiB on others); where none fits, the
            # default width with global work buffers, whose size does not depend on the width.
            default_width = CPU_VECTOR_WIDTH if runtime.is_cpu else 1
            vector_width = default_width
            while vector_width > 1 and not fits_local(vector_width):
                vector_width //= 2
            if not fits_local(vector_width):
                vector_width = default_width
                while vector_width > 1 and flag_bytes(vector_width) > limits.local_mem_size:
                    vector_width //= 2
        if vector_width not in VECTOR_WIDTHS:
            raise ConfigError(f"vector_width must be one of {VECTOR_WIDTHS}, got {vector_width!r}")
        self.vector_width = int(vector_width)
        # Local memory is faster: global work buffers only where the local ones do not fit.
        self.scratch_space = "local" if fits_local(self.vector_width) else "global"
        if self.scratch_space == "local":
            self.local_bytes = buffer_bytes(self.vector_width) + flag_bytes(self.vector_width)
            self.scratch_bytes = 0
        else:
            self.local_bytes = flag_bytes(self.vector_width)
            self.scratch_bytes = self.n_groups * buffer_bytes(self.vector_width)
            if self.local_bytes > limits.local_mem_size:
                raise DeviceCapabilityError(
                    f"the range FFT with vector_width {self.vector_width} needs {self.local_bytes} bytes of local "
                    f"memory for its beam flags; {limits.name} has {limits.local_mem_size}"
                    + (" (use a smaller vector_width)" if self.vector_width > 1 else ""))
            if self.scratch_bytes > limits.max_mem_alloc_size:
                raise DeviceCapabilityError(
                    f"n_fft = {self.n_fft} with vector_width {self.vector_width} needs "
                    f"{buffer_bytes(self.vector_width) + flag_bytes(self.vector_width)} bytes of local memory per "
                    f"work-group, more than the {limits.local_mem_size} of {limits.name}, "
                    f"so its work buffers go to global memory: {self.n_groups} work-groups x "
                    f"{buffer_bytes(self.vector_width)} bytes = {size_text(self.scratch_bytes)} in one buffer, "
                    f"more than the largest buffer the device allows, {size_text(limits.max_mem_alloc_size)} "
                    f"(process fewer beams per frame)")

        max_ls = min(self.n_fft // 4, limits.max_work_group_size)
        requested = local_size
        if local_size is None:
            preferred = CPU_LOCAL_SIZE if runtime.is_cpu else max_ls
            local_size = 1 << int(math.log2(min(preferred, max_ls)))
        if not is_power_of_two(local_size) or local_size > max_ls:
            raise ConfigError(f"local_size must be a power of two <= {max_ls} (n_fft/4 and the "
                              f"device limit), got {local_size!r}")
        defines = dict(N_FFT=self.n_fft, N_SAMPLES=self.n_samples, M=m, LOG2_M=int(math.log2(m)),
                       P=self.n_fft // m, LOG2_P=int(math.log2(self.n_fft // m)), N_BINS=self.n_bins,
                       VEC=self.vector_width, INPUT_KIND=_INPUT_KINDS[self.dtype],
                       WINDOWED=window != "rect", POWER=output == "power",
                       CHECK_FINITE=self.dtype != np.int16, SAMPLE_LIMIT=oracle.sample_limit(self.n_samples),
                       SCRATCH_GLOBAL=self.scratch_space == "global")
        # LOCAL_SIZE is fixed before the build (reqd_work_group_size), but only the built kernel
        # says how many work-items it can run (its registers and local memory): a defaulted size
        # is halved to that and built again, a requested one is refused.
        while True:
            self._kernel = build(runtime, "range_fft", dict(defines, LOCAL_SIZE=local_size))["range_fft"]
            kernel_limit = runtime.max_local_size(self._kernel)
            if local_size <= kernel_limit:
                break
            if requested is not None:
                raise ConfigError(f"local_size {local_size} is more than the {kernel_limit} work-items {limits.name} "
                                  f"runs this build of the range-FFT kernel with (CL_KERNEL_WORK_GROUP_SIZE); use "
                                  f"local_size <= {kernel_limit}, or leave it out")
            if kernel_limit < 1:
                raise DeviceCapabilityError(f"the range-FFT kernel needs at least one work-item per work-group; "
                                            f"{limits.name} allows {kernel_limit} for it")
            local_size = 1 << int(math.log2(kernel_limit))
        self.local_size = int(local_size)
        import pyopencl.array as cla

        j = np.arange(self.n_fft)
        q = runtime.queue
        self._constants = dict(
            window=cla.to_device(q, w.astype(np.float32)),
            twiddle=cla.to_device(q, np.exp(-2j * np.pi * j / self.n_fft).astype(np.complex64)),
            scale=cla.to_device(q, per_bin.astype(np.float32)))
        if self.scratch_space == "global":
            runtime.hold(self, self.scratch_bytes, "the range FFT's global work buffers")
            self._scratch = runtime.empty(self.scratch_bytes)
        else:                                  # the kernel takes the argument but never reads it
            self._scratch = runtime.empty(np.dtype(np.complex64).itemsize * self.vector_width)   # one cvec
        self._allocate([Port("samples", self.input_shape, self.dtype, "a frame")],
                       [Port("profiles", (*self.batch, self.n_bins), np.dtype(np.float32), "range profiles"),
                        Port("flags", self.batch, np.dtype(np.uint8), "beam flags")])

    @property
    def input_shape(self):
        """Shape one frame must have: (*batch, n_samples)."""
        return (*self.batch, self.n_samples)

    @property
    def n_jobs(self):
        """FFTs per frame: beam pairs for real input, beams for complex."""
        return self.n_beams if self.complex_input else (self.n_beams + 1) // 2

    @property
    def n_groups(self):
        """Work-groups per frame: one per vector_width jobs."""
        return -(-self.n_jobs // self.vector_width)

    def check(self, samples, name="samples"):
        """Raise ShapeError unless ``samples`` is one frame of this plan's shape and dtype."""
        return self.check_input(name, samples)

    def upload(self, samples):
        """Copy a checked frame into the plan's input array; returns the copy event."""
        return super().upload(samples=samples)[0]

    def enqueue(self, samples=None, wait_for=None):
        """Launch on a device array of samples (default: this plan's, as ``upload`` filled it);
        results stay in ``arrays["profiles"]`` and ``arrays["flags"]``. Returns the kernel
        event (for chaining stages without host round trips)."""
        gsize = (self.n_groups * self.local_size,)
        return self._kernel(self.runtime.queue, gsize, (self.local_size,), wait_for=wait_for,
                            samples=self.device("samples", samples), clip_level=self.clip_level,
                            n_beams=self.n_beams, profiles=self.arrays["profiles"], flags=self.arrays["flags"],
                            scratch=self._scratch, **self._constants)

    def _result(self, profiles, flags):
        return RangeFFTResult(profiles, flags)

    def __call__(self, samples):
        """Process one frame: (*batch, n_samples) -> RangeFFTResult (blocking)."""
        copy = self.upload(samples)
        return self.download(wait_for=[self.enqueue(wait_for=[copy])])
