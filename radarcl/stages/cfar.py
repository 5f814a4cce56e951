"""CFAR detection of whole frames of power profiles (paper §3.3, Fig. 6).

``Cfar`` wraps ``kernels/cfar.cl``; it is equivalent to ``radarcl.oracle.cfar(profiles,
config)`` (edge rule "shift", see ``CfarConfig``): noise estimates and ratios within
``CFAR_RTOL`` of the float64 oracle, masks identical except where r_i lies within
``DECISION_MARGIN`` of the threshold (see tests/test_cfar.py).
"""

import dataclasses
from dataclasses import dataclass

import numpy as np

from radarcl import oracle
from radarcl.config.stage_config import CfarConfig
from radarcl.errors import ConfigError
from radarcl.stages import Port, Stage, beam_batch, build, count, work_group_size

_KINDS = {"ca": 0, "go": 1, "so": 2, "os": 3}
# Beams as the lanes of a vector on CPUs (PoCL does not vectorise across work-items): the widest
# was the fastest (docs/measured-figures.md, "Why the code is shaped so"). Any size is correct (the tests run
# several).
DEFAULT_LOCAL_SIZE = 64
CPU_VECTOR_WIDTH = 16
VECTOR_WIDTHS = (1, 2, 4, 8, 16)


@dataclass(frozen=True)
class CfarResult:
    """Per-bin CFAR outputs, each of shape (*batch, n_bins), and per-beam flags (*batch,)."""

    noise: np.ndarray   # float32 n_i, floored
    ratio: np.ndarray   # float32 r_i / n_i, saturated at the largest float32
    mask: np.ndarray    # bool, r_i > alpha n_i
    flags: np.ndarray = None  # uint8 oracle.FLAG_BAD_PROFILE / FLAG_SILENT (``Cfar.__call__``): trust no
    #                           noise, ratio or detection of a flagged beam


class Cfar(Stage):
    """A compiled CFAR plan for frames of one shape.

    runtime: a ``radarcl.cl.Runtime``; batch: the beam shape of a frame, e.g. (64, 4) or (400,);
    n_bins: bins per profile; config: a ``CfarConfig`` (kind, guard, train, pfa, rank, floor);
    local_size: work-items per group along the bins (default 64, capped by the device).
    vector_width: bins per work-item, one per SIMD lane: 1, 2, 4, 8, 16; default 16 on a CPU
        device (PoCL does not vectorise across work-items here), 1 on a GPU.
    Profiles are power (square-law), float32, non-negative; see ``oracle.cfar`` for NaN.
    """

    def __init__(self, runtime, batch, n_bins, config=None, *, local_size=None, vector_width=None):
        self.runtime = runtime
        self.config = config if config is not None else CfarConfig()
        if not isinstance(self.config, CfarConfig):
            raise ConfigError(f"config must be a CfarConfig, got {type(self.config).__name__}")
        self.batch, self.n_beams = beam_batch(batch)
        self.n_bins = self.config.check_profile_length(count(n_bins, "n_bins"))
        self.alpha = float(self.config.alpha)
        if vector_width is None:
            vector_width = CPU_VECTOR_WIDTH if runtime.is_cpu else 1
        if vector_width not in VECTOR_WIDTHS:
            raise ConfigError(f"vector_width must be one of {VECTOR_WIDTHS}, got {vector_width!r}")
        self.vector_width = int(vector_width)
        self._kernel = build(runtime, "cfar", dict(
            N_BINS=self.n_bins, GUARD=self.config.guard, TRAIN=self.config.train,
            KIND=_KINDS[self.config.kind], RANK=self.config.rank or 0, VEC=self.vector_width))["cfar"]
        self.local_size = work_group_size(runtime, self._kernel, local_size, DEFAULT_LOCAL_SIZE)
        f32 = np.dtype(np.float32)
        self._allocate([Port("profiles", self.input_shape, f32, "power profiles")],
                       [Port("noise", self.input_shape, f32, "CFAR noise estimates"),
                        Port("ratio", self.input_shape, f32, "CFAR ratios"),
                        Port("mask", self.input_shape, np.dtype(np.uint8), "CFAR detections")])

    @property
    def input_shape(self):
        """Shape one frame of profiles must have: (*batch, n_bins)."""
        return (*self.batch, self.n_bins)

    def check(self, profiles, name="profiles"):
        """Raise ShapeError unless ``profiles`` is one float32 frame of this plan's shape."""
        return self.check_input(name, profiles)

    def upload(self, profiles):
        """Copy a checked frame into the plan's input array; returns the copy event."""
        return super().upload(profiles=profiles)[0]

    def enqueue(self, profiles=None, wait_for=None):
        """Launch on a device array of power profiles (default: this plan's; or e.g. a
        ``RangeFFT``'s ``arrays["profiles"]`` in power); results stay in ``arrays["noise"]``,
        ``["ratio"]`` and ``["mask"]``. Returns the kernel event."""
        ls = self.local_size
        items = -(-self.n_bins // self.vector_width)
        gsize = (-(-items // ls) * ls, self.n_beams)
        a = self.arrays
        return self._kernel(self.runtime.queue, gsize, (ls, 1), wait_for=wait_for,
                            profiles=self.device("profiles", profiles), alpha=self.alpha,
                            noise_floor=float(self.config.noise_floor), n_beams=self.n_beams,
                            noise=a["noise"], ratio=a["ratio"], mask=a["mask"])

    def _result(self, noise, ratio, mask):
        return CfarResult(noise, ratio, mask.astype(bool))

    def __call__(self, profiles):
        """Process one frame of profiles (*batch, n_bins) float32 -> CfarResult (blocking), with
        the beams whose profiles the CFAR cannot judge flagged (``oracle.profile_flags``: in a
        ``Detection`` the interpreter flags them on the device)."""
        copy = self.upload(profiles)
        result = self.download(wait_for=[self.enqueue(wait_for=[copy])])
        return dataclasses.replace(result, flags=oracle.profile_flags(profiles))
