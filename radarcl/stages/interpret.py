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
from radarcl.config.stage_config import InterpretConfig
from radarcl.errors import ConfigError
from radarcl.sensor_model import N_CLASSES, NODE_SHAPE, NODES, BinModel, pack_nodes
from radarcl.snr_evidence import GAP_CAP, SNR_U, SNR_V, detection_cap
from radarcl.stages import Port, Stage, beam_batch, build, count, spacing, work_group_size

# Beams per work-group. One work-item walks one beam; any size is correct.
DEFAULT_LOCAL_SIZE = 16
# Work-items per work-group of interpret_nodes ("snr" evidence's nodes, eight bins a work-item):
# any size is correct; within any device's work-group limit.
NODES_LOCAL_SIZE = 64


@dataclass(frozen=True)
class InterpretResult:
    """Evidence and pulses of one frame; ``batch`` is the frame's beam shape."""

    evidence: np.ndarray   # int32 (*batch, n_bins), logodds units; detstats: (*batch, n_bins, *NODE_SHAPE) node pairs
    pulses: np.ndarray     # int32 (*batch, max_pulses, 4): start, end, peak, wide; -1 unused
    n_pulses: np.ndarray   # int32 (*batch,): pulses found, may exceed max_pulses
    flags: np.ndarray      # uint8 (*batch,): oracle.FLAG_* bits

    @property
    def valid(self):
        """Beams that give evidence."""
        return (self.flags & oracle.NO_EVIDENCE_FLAGS) == 0


class Interpreter(Stage):
    """A compiled interpreter plan for frames of one shape.

    runtime: a ``radarcl.cl.Runtime``; batch: the beam shape, e.g. (64, 4) or (400,);
    n_bins: bins per profile; bin_spacing_m: range between bins (bin j sits at j x spacing);
    config: an ``InterpretConfig``; local_size: beams per work-group; bin_model: for
    ``config.model == "detstats"``, the ``sensor_model.BinModel`` of this sensor, CFAR and voxel
    (its tables go to the device once). With detstats the evidence is
    (*batch, n_bins, *sensor_model.NODE_SHAPE) int32 node pairs (``sensor_model.unpack_nodes``),
    equivalent to ``radarcl.oracle.interpret_detstats``: node values identical to the oracle's
    until a beam's first pulse and within ``EVIDENCE_UNITS_TOL`` after it (except, with "snr"
    evidence, a node whose float32 and float64 opportunity round to 0 on different sides of 1/2,
    where one has the evidence and the other 0; the seeded tests keep far from it).
    """

    def __init__(self, runtime, batch, n_bins, bin_spacing_m, config=None, *, local_size=None, bin_model=None):
        self.runtime = runtime
        self.config = config if config is not None else InterpretConfig()
        if not isinstance(self.config, InterpretConfig):
            raise ConfigError(f"config must be an InterpretConfig, got {type(self.config).__name__}")
        self.batch, self.n_beams = beam_batch(batch)
        self.n_bins = count(n_bins, "n_bins")
        self.bin_spacing_m = spacing(bin_spacing_m)
        self.first_bin, self.last_bin = self.config.bin_interval(self.bin_spacing_m, self.n_bins)
        self.wide_bins = self.config.wide_bins(self.bin_spacing_m)
        self.e_high, self.e_low, self.e_high_far = (int(v) for v in logodds.to_fixed(
            [self.config.e_high, self.config.e_low, self.config.e_high_far]))
        self.detstats = self.config.model == "detstats"
        if self.detstats and not isinstance(bin_model, BinModel):
            raise ConfigError("the detection-statistics interpreter needs its sensor_model.BinModel (bin_model=...)")
        if self.detstats and bin_model.opportunity.shape != (self.n_bins, N_CLASSES, NODES):
            raise ConfigError(f"the bin model has {bin_model.opportunity.shape[0]} bins; the profiles have {self.n_bins}")
        self.bin_model = bin_model if self.detstats else None
        graded = self.detstats and bin_model.graded
        if graded and np.shape(bin_model.ln_snr) != bin_model.opportunity.shape:
            raise ConfigError(f"the bin model's ln_snr is {np.shape(bin_model.ln_snr)}, its opportunity "
                              f"{bin_model.opportunity.shape}: 'snr' evidence needs both per bin, class and node")
        grid = dict(SNR_NU=SNR_U[2], SNR_NV=SNR_V[2], SNR_U0=float(SNR_U[0]), SNR_V0=float(SNR_V[0]),
                    SNR_U_SCALE=(SNR_U[2] - 1) / (SNR_U[1] - SNR_U[0]),
                    SNR_V_SCALE=(SNR_V[2] - 1) / (SNR_V[1] - SNR_V[0]), GAP_CAP=GAP_CAP) if graded else {}
        kernels = build(runtime, "interpret", dict(N_BINS=self.n_bins, MAX_PULSES=self.config.max_pulses,
                                                   OCCLUSION=int(self.config.model == "occlusion"),
                                                   DETSTATS=int(self.detstats), GRADED=int(graded), **grid))
        self._kernel = kernels["interpret"]
        # "snr" evidence: the beam's walk leaves each bin's blocking, a second kernel its nodes
        self._nodes_kernel = kernels["interpret_nodes"] if graded else None
        self._nodes_local_size = work_group_size(runtime, self._nodes_kernel, None, NODES_LOCAL_SIZE) if graded else 1
        self.local_size = work_group_size(runtime, self._kernel, local_size, DEFAULT_LOCAL_SIZE)
        f32, u8, i32 = np.dtype(np.float32), np.dtype(np.uint8), np.dtype(np.int32)
        shape = self.input_shape
        out_shape = (*shape, *NODE_SHAPE) if self.detstats else shape
        self._allocate([Port("profiles", shape, f32, "profiles"), Port("noise", shape, f32, "noise"),
                        Port("mask", shape, u8, "mask"), Port("flags_in", self.batch, u8, "flags")],
                       [Port("evidence", out_shape, i32, "evidence nodes" if self.detstats else "evidence"),
                        Port("pulses", (*self.batch, self.config.max_pulses, 4), i32, "pulses"),
                        Port("n_pulses", self.batch, i32, "pulse counts"),
                        Port("flags_out", self.batch, u8, "flags")])
        self._no_flags = self.arrays["flags_in"].copy()     # all zero: "no flags from upstream"
        if graded:          # interpret_nodes writes the window's bins only: the others are 0 from here on
            self.arrays["evidence"].fill(0)
        self._no_flags.fill(0)
        self._tables = self._model_tables()

    def _model_tables(self):
        """The detstats tables on the device (placeholders for the other models)."""
        import pyopencl.array as cla

        q = self.runtime.queue
        one = cla.zeros(q, (1,), np.float32)
        tables = dict(opportunity=one, miss=one, blocking=one, unblocked=cla.zeros(q, (1, 2), np.int32), c_det=1.0,
                      ln_snr=one, snr_table=one, snr_cap=one, noise_floor=1.0, blocker_gap=0.0,
                      snr_q=1.0, state=cla.zeros(q, (1, 2), np.float32), ln_floors=one)
        if not self.detstats:
            return tables
        m = self.bin_model
        tables.update(opportunity=cla.to_device(q, m.opportunity.astype(np.float32)),
                      blocking=cla.to_device(q, m.blocking.astype(np.float32)), c_det=(1.0 - m.pfa) / m.pfa)
        if m.graded:                     # the table replaces the misses and the exact unblocked nodes
            snr_cap = detection_cap(m.opportunity, m.snr_table.q, m.bounded).astype(np.float32)
            tables.update(ln_snr=cla.to_device(q, m.ln_snr.astype(np.float32)),
                          snr_table=cla.to_device(q, m.snr_table.values.astype(np.float32)),
                          snr_cap=cla.to_device(q, snr_cap),
                          noise_floor=float(m.noise_floor), blocker_gap=float(m.blocker_gap),
                          snr_q=float(m.snr_table.q),
                          state=cla.zeros(q, (self.n_beams, 2, self.n_bins), np.float32),    # per bin: blocked, tau
                          ln_floors=cla.zeros(q, (self.n_beams,), np.float32))
            # interpret_nodes reads eight bins of a node at once: its tables with the bins last
            self._nodes_tables = {name: cla.to_device(q, np.ascontiguousarray(
                np.asarray(table, np.float32).reshape(self.n_bins, N_CLASSES * NODES).T))
                for name, table in (("opportunity", m.opportunity), ("ln_snr", m.ln_snr), ("snr_cap", snr_cap))}
            return tables
        first, last = self.first_bin, self.last_bin
        unblocked = np.zeros((self.n_bins, N_CLASSES, NODES), np.int64), np.zeros((self.n_bins, N_CLASSES, NODES), np.int64)
        if first <= last:
            with np.errstate(divide="ignore"):
                unblocked[0][first:last + 1] = logodds.to_fixed(np.log(m.miss[first:last + 1]))
            unblocked[1][first:last + 1] = np.rint(m.opportunity[first:last + 1] * logodds.KNOWLEDGE_SCALE)
            unblocked[0][unblocked[1] == 0] = 0                 # no look, no evidence (as the kernel's nodes)
        tables.update(miss=cla.to_device(q, m.miss.astype(np.float32)), unblocked=cla.to_device(q, pack_nodes(*unblocked)))
        return tables

    @property
    def input_shape(self):
        """Shape of a frame of profiles: (*batch, n_bins)."""
        return (*self.batch, self.n_bins)

    def check_flags(self, flags):
        """Per-beam flags as a contiguous uint8 array of shape ``batch``, or ShapeError."""
        return self.check_input("flags_in", flags)

    def enqueue(self, profiles=None, noise=None, mask=None, flags=None, wait_for=None):
        """Launch on device arrays (profiles float32, CFAR noise float32 and mask uint8, e.g. a
        ``Cfar``'s ``arrays``; per-beam uint8 flags or None for none; None for the others means
        this plan's own, as ``upload`` filled them). Results stay in ``arrays["evidence"]``,
        ``["pulses"]``, ``["n_pulses"]``, ``["flags_out"]``. Returns the kernel event."""
        ls = self.local_size
        gsize = (-(-self.n_beams // ls) * ls,)
        a = self.arrays
        profiles = self.device("profiles", profiles)
        done = self._kernel(self.runtime.queue, gsize, (ls,), wait_for=wait_for,
                            profiles=profiles, noise=self.device("noise", noise),
                            mask=self.device("mask", mask),
                            flags_in=self._no_flags if flags is None else self.device("flags_in", flags),
                            k_occ=float(self.config.k_occ), e_high=self.e_high, e_low=self.e_low,
                            first_bin=self.first_bin, last_bin=self.last_bin, wide_bins=self.wide_bins,
                            e_high_far=self.e_high_far, surface_decades=float(self.config.surface_db / 10.0),
                            **self._tables,
                            n_beams=self.n_beams, evidence=a["evidence"], pulses=a["pulses"],
                            n_pulses=a["n_pulses"], flags_out=a["flags_out"])
        if self._nodes_kernel is None:
            return done
        t, ls = self._tables, self._nodes_local_size
        chunks = max(0, (self.last_bin >> 3) - (self.first_bin >> 3) + 1)     # of eight bins meeting the window
        n = self.n_beams * chunks
        if not n:
            return done
        return self._nodes_kernel(self.runtime.queue, (-(-n // ls) * ls,), (ls,), wait_for=[done], profiles=profiles,
                                  flags_out=a["flags_out"], state=t["state"], ln_floors=t["ln_floors"],
                                  snr_table=t["snr_table"], **self._nodes_tables, first_bin=self.first_bin,
                                  last_bin=self.last_bin, blocker_gap=t["blocker_gap"], snr_q=t["snr_q"],
                                  n_chunks=chunks, n_beams=self.n_beams, evidence=a["evidence"])

    def _result(self, evidence, pulses, n_pulses, flags_out):
        return InterpretResult(evidence, pulses, n_pulses, flags_out)

    def __call__(self, profiles, noise, mask, flags=None):
        """Interpret one frame given on the host (blocking): profiles and noise float32,
        mask bool or uint8, all (*batch, n_bins); flags uint8 (*batch,) or None."""
        mask = np.asarray(mask)
        if mask.dtype == bool:
            mask = mask.astype(np.uint8)
        host = dict(profiles=profiles, noise=noise, mask=mask)
        if flags is not None:
            host["flags_in"] = flags
        copies = self.upload(**host)
        done = self.enqueue(flags=None if flags is None else self.arrays["flags_in"], wait_for=copies)
        return self.download(wait_for=[done])
