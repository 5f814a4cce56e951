"""The "snr" evidence's node pairs, after the interpreter's beam walk (the detection-statistics model).

``InterpretNodes`` wraps ``kernels/interpret_nodes.cl``. ``radarcl.stages.interpret.Interpreter``
makes one for a bin model with "snr" evidence and ``radarcl.models.detstats`` launches it after
the walk (``kernels/interpret.cl`` with GRADED), which leaves each bin's blocking and each beam's
noise floor; the two launches together are equivalent to ``radarcl.oracle.interpret_detstats``:
node values within ``EVIDENCE_UNITS_TOL`` of it (float32 logs, blocking and the table's bilinear
read; tests/test_interpret_nodes.py).

Only the classes of target the scene has are computed and stored: a bin model whose terrain class
has no opportunity at any bin (no ground plane: ``sensor_model.terrain_dz`` is -inf) needs
``classes == 1`` (``classes_needed``), and the node array holds the upright class alone
(``node_pairs.node_shape``): the terrain class's pairs would all be 0 (a node without knowledge
carries no evidence), and the fusion takes nothing from a terrain voxel then.
"""

import numpy as np

from radarcl.errors import ConfigError, ShapeError
from radarcl.node_pairs import N_CLASSES, NODES, live_segments, node_shape
from radarcl.sensor_model import BinModel
from radarcl.snr_evidence import GAP_CAP, SNR_U, SNR_V, detection_cap
from radarcl.stages import build, work_group_size

# Work-items per work-group: any size is correct; within any device's work-group limit.
DEFAULT_LOCAL_SIZE = 64
# Bins per work-item, each a vector lane; any choice computes the same floats lane for lane. On a
# CPU 16 (two 256-bit registers' worth of independent work a work-item, or one 512-bit); elsewhere
# 8, as a GPU's work-item holds its vectors in registers the other work-items share.
LANE_CHOICES = (8, 16)
DEFAULT_LANES = {"cpu": 16, "other": 8}


def classes_needed(opportunity):
    """The classes of target a pipeline keeps for a bin model's ``opportunity`` (n_bins, N_CLASSES,
    NODES): 1 where the terrain class has no node with knowledge (its opportunity rounds to 0
    knowledge units at every bin and node, in float32 as the kernels round it and in float64 as
    the host's exact nodes do: then all its nodes are 0, and the fusion need not read them), else 2."""
    return 2 if live_segments(opportunity)[:, 1].any() else 1      # the rule of a node with knowledge: one place


class InterpretNodes:
    """The node kernel for frames of ``n_beams`` beams of ``n_bins`` bins, window [first_bin,
    last_bin] (the interpreter's), from ``bin_model`` (a ``sensor_model.BinModel`` with "snr"
    evidence; its tables go to the device once), of which the first ``classes`` classes are
    computed (``classes_needed``; the pipeline's count, which its node array is laid out for).
    ``lanes``: bins per work-item (8 or 16; None: ``DEFAULT_LANES`` for the device);
    ``local_size``: work-items per work-group."""

    def __init__(self, runtime, n_beams, n_bins, first_bin, last_bin, bin_model, classes, *, lanes=None,
                 local_size=None):
        if not isinstance(bin_model, BinModel) or not bin_model.graded:
            got = "one with 'detection' evidence" if isinstance(bin_model, BinModel) else type(bin_model).__name__
            raise ConfigError(f"the node kernel needs a sensor_model.BinModel with 'snr' evidence, got {got}")
        shape = (n_bins, N_CLASSES, NODES)
        if bin_model.opportunity.shape != shape or np.shape(bin_model.ln_snr) != shape:
            raise ConfigError(f"the bin model's opportunity {bin_model.opportunity.shape} and ln_snr "
                              f"{np.shape(bin_model.ln_snr)} must both be {shape} (bins, classes, nodes)")
        lanes = DEFAULT_LANES["cpu" if runtime.is_cpu else "other"] if lanes is None else lanes
        if lanes not in LANE_CHOICES:
            raise ConfigError(f"lanes must be one of {LANE_CHOICES}, got {lanes!r}")
        self.runtime = runtime
        self.n_beams, self.n_bins, self.first_bin, self.last_bin = n_beams, n_bins, first_bin, last_bin
        self.lanes = lanes
        node_shape(classes)                         # ConfigError for a count no node array has
        self.classes = classes
        q = bin_model.snr_table.q
        self.kernels = build(runtime, "interpret_nodes", dict(
            N_BINS=n_bins, NODES=NODES, CLASSES=self.classes, LANES=lanes,
            SNR_NU=SNR_U[2], SNR_NV=SNR_V[2], SNR_U0=float(SNR_U[0]), SNR_V0=float(SNR_V[0]),
            SNR_U_SCALE=(SNR_U[2] - 1) / (SNR_U[1] - SNR_U[0]), SNR_V_SCALE=(SNR_V[2] - 1) / (SNR_V[1] - SNR_V[0]),
            GAP_CAP=GAP_CAP))
        self._kernel = self.kernels["interpret_nodes"]
        self.local_size = work_group_size(runtime, self._kernel, local_size, DEFAULT_LOCAL_SIZE)
        import pyopencl.array as cla

        queue = runtime.queue
        cap = detection_cap(bin_model.opportunity, q, bin_model.bounded)

        def bins_last(table):
            """(n_bins, classes, nodes) -> (classes, nodes, n_bins) float32: one vector load a node"""
            return cla.to_device(queue, np.ascontiguousarray(np.asarray(table, np.float32).reshape(n_bins, -1).T))

        self.tables = dict(opportunity=bins_last(bin_model.opportunity), ln_snr=bins_last(bin_model.ln_snr),
                           snr_cap=bins_last(cap),
                           snr_table=cla.to_device(queue, bin_model.snr_table.values.astype(np.float32)))
        self.blocker_gap, self.snr_q = float(bin_model.blocker_gap), float(q)
        self._every = cla.zeros(queue, (1,), np.uint32)     # node_use's placeholder: every class computed
        # chunks of LANES bins that meet the window
        self.n_chunks = max(0, last_bin // lanes - first_bin // lanes + 1) if first_bin <= last_bin else 0

    def enqueue(self, profiles, flags, state, ln_floors, evidence, wait_for=None, node_use=None):
        """Launch on the walk's device arrays: ``profiles`` (n_beams, n_bins) float32, its
        ``flags`` (n_beams,) uint8, ``state`` (n_beams, 2, n_bins) float32 (each bin's blocking
        and tau), ``ln_floors`` (n_beams,) float32; writes the node pairs of the window's bins
        into ``evidence`` (n_beams, n_bins, 4 x classes) int2, whose other bins must hold 0.
        ``node_use``: None, or a device array (n_beams, n_bins) uint32 whose bit c says that
        some voxel reads class c's pairs of that bin (a still plan's ``StillTable.node_use``, or
        a moving frame's bound from its beams, ``Fusion.node_reach``):
        then a chunk of ``lanes`` bins computes only the classes one of its bins has, and the
        other pairs keep what they held. Returns the kernel's event (a marker after ``wait_for``
        where the window is empty)."""
        if node_use is not None:
            import pyopencl.array as cla

            want = (self.n_beams, self.n_bins)
            if not isinstance(node_use, cla.Array) or node_use.dtype != np.uint32 or node_use.shape != want:
                got = (f"{node_use.dtype} {node_use.shape}" if isinstance(node_use, cla.Array)
                       else type(node_use).__name__)
                raise ShapeError(f"node_use must be a device array of uint32 {want} (beams, bins), got {got}")
        n, ls = self.n_beams * self.n_chunks, self.local_size
        if not n:
            import pyopencl as cl

            return cl.enqueue_marker(self.runtime.queue, wait_for=wait_for)
        return self._kernel(self.runtime.queue, (-(-n // ls) * ls,), (ls,), wait_for=wait_for,
                            profiles=profiles, flags_out=flags, state=state, ln_floors=ln_floors, **self.tables,
                            first_bin=self.first_bin, last_bin=self.last_bin, blocker_gap=self.blocker_gap,
                            snr_q=self.snr_q, n_chunks=self.n_chunks, n_beams=self.n_beams,
                            node_use=self._every if node_use is None else node_use, selective=int(node_use is not None),
                            evidence=evidence)
