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
from radarcl.node_pairs import N_CLASSES, NODES, node_shape
from radarcl.sensor_model import BinModel
from radarcl.stages import Port, Stage, beam_batch, build, count, spacing, work_group_size
from radarcl.stages.interpret_nodes import InterpretNodes, classes_needed

# Beams per work-group. One work-item walks one beam; any size is correct.
DEFAULT_LOCAL_SIZE = 16


@dataclass(frozen=True)
class InterpretResult:
    """Evidence and pulses of one frame; ``batch`` is the frame's beam shape."""

    evidence: np.ndarray   # int32 (*batch, n_bins), logodds units; detstats: (*batch, n_bins, classes, 4, 2) node pairs
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
    config: an ``InterpretConfig``; local_size: beams per work-group; bin_model: for a model with
    node pairs (``EvidenceModel.knowledge``: the detection-statistics model), the
    ``sensor_model.BinModel`` of this sensor, CFAR and voxel (its tables go to the device once;
    ``radarcl.models`` says what each model puts there). With detstats the evidence is
    (*batch, n_bins, *node_pairs.node_shape(classes)) int32 node pairs
    (``node_pairs.unpack_nodes``) of the first ``classes`` classes of target: None, those the
    bin model's scene has (``interpret_nodes.classes_needed``: 1 without a terrain class, whose
    nodes would all be 0; the fusion is then built with the same count), or 2 for both;
    equivalent to ``radarcl.oracle.interpret_detstats``: node values identical to the oracle's
    until a beam's first pulse and within ``EVIDENCE_UNITS_TOL`` after it (except, with "snr"
    evidence, a node whose float32 and float64 opportunity round to 0 on different sides of 1/2,
    where one has the evidence and the other 0; the seeded tests keep far from it).
    With "snr" evidence the walk leaves the nodes to ``nodes``, an ``InterpretNodes``
    (kernels/interpret_nodes.cl; ``nodes_options``: its keyword options, e.g. ``lanes``), which the
    model launches after it; otherwise ``nodes`` is None.
    """

    def __init__(self, runtime, batch, n_bins, bin_spacing_m, config=None, *, local_size=None, bin_model=None,
                 nodes_options=None, classes=None):
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
        self.model = self.config.evidence_model
        # a model's hook written before node_use takes three arguments: it gets none, and makes every node
        self._hook_takes_node_use = _takes_keyword(self.model.after_kernel, "node_use")
        self.node_pairs = self.model.knowledge       # evidence per class and rho2 node, not one value per bin
        if self.node_pairs and not isinstance(bin_model, BinModel):
            raise ConfigError(f"the {self.model.summary} interpreter needs its sensor_model.BinModel (bin_model=...)")
        if self.node_pairs and bin_model.opportunity.shape != (self.n_bins, N_CLASSES, NODES):
            raise ConfigError(f"the bin model has {bin_model.opportunity.shape[0]} bins; the profiles have {self.n_bins}")
        self.bin_model = bin_model if self.node_pairs else None
        self.classes = None                          # node pairs' classes of target (node_shape)
        if self.node_pairs:
            needed = classes_needed(bin_model.opportunity)
            self.classes = needed if classes is None else classes
            if self.classes not in (needed, N_CLASSES):
                allowed = " or ".join(str(c) for c in sorted({needed, N_CLASSES}))
                why = ": its terrain class has opportunity" if needed == N_CLASSES else ""
                raise ConfigError(f"classes must be {allowed} (None: {needed}) for this bin model, got {classes!r}{why}")
        elif classes is not None:
            raise ConfigError(f"classes are for a model with node pairs; the {self.model.summary} interpreter has "
                              "one value per bin")
        if self.node_pairs and bin_model.graded and np.shape(bin_model.ln_snr) != bin_model.opportunity.shape:
            raise ConfigError(f"the bin model's ln_snr is {np.shape(bin_model.ln_snr)}, its opportunity "
                              f"{bin_model.opportunity.shape}: 'snr' evidence needs both per bin, class and node")
        defines = dict(N_BINS=self.n_bins, MAX_PULSES=self.config.max_pulses, NODES=NODES,
                       **self.model.defines(self.bin_model))
        if self.node_pairs:
            defines["CLASSES"] = self.classes
        self.kernels = build(runtime, "interpret", defines)
        self._kernel = self.kernels["interpret"]
        self.nodes = None
        if self.node_pairs and bin_model.graded:    # "snr" evidence: the nodes are a second launch's
            self.nodes = InterpretNodes(runtime, self.n_beams, self.n_bins, self.first_bin, self.last_bin, bin_model,
                                        self.classes, **(nodes_options or {}))
        elif nodes_options:
            raise ConfigError(f"nodes_options are for the detection-statistics model with 'snr' evidence; the "
                              f"{self.model.summary} interpreter{' with detection evidence' if self.node_pairs else ''} "
                              "has no node kernel")
        self.local_size = work_group_size(runtime, self._kernel, local_size, DEFAULT_LOCAL_SIZE)
        f32, u8, i32 = np.dtype(np.float32), np.dtype(np.uint8), np.dtype(np.int32)
        shape = self.input_shape
        out_shape = (*shape, *node_shape(self.classes)) if self.node_pairs else shape
        self._allocate([Port("profiles", shape, f32, "profiles"), Port("noise", shape, f32, "noise"),
                        Port("mask", shape, u8, "mask"), Port("flags_in", self.batch, u8, "flags")],
                       [Port("evidence", out_shape, i32, "evidence nodes" if self.node_pairs else "evidence"),
                        Port("pulses", (*self.batch, self.config.max_pulses, 4), i32, "pulses"),
                        Port("n_pulses", self.batch, i32, "pulse counts"),
                        Port("flags_out", self.batch, u8, "flags")])
        import pyopencl.array as cla

        self._no_flags = cla.zeros_like(self.arrays["flags_in"])     # "no flags from upstream"
        self._tables = self.model.device_tables(runtime.queue, self)

    @property
    def input_shape(self):
        """Shape of a frame of profiles: (*batch, n_bins)."""
        return (*self.batch, self.n_bins)

    def check_flags(self, flags):
        """Per-beam flags as a contiguous uint8 array of shape ``batch``, or ShapeError."""
        return self.check_input("flags_in", flags)

    def enqueue(self, profiles=None, noise=None, mask=None, flags=None, wait_for=None, node_use=None):
        """Launch on device arrays (profiles float32, CFAR noise float32 and mask uint8, e.g. a
        ``Cfar``'s ``arrays``; per-beam uint8 flags or None for none; None for the others means
        this plan's own, as ``upload`` filled them). Results stay in ``arrays["evidence"]``,
        ``["pulses"]``, ``["n_pulses"]``, ``["flags_out"]``. ``node_use``: the node pairs the
        frame's voxels read (a still plan's ``StillTable.node_use``, or a moving frame's bound,
        ``Fusion.node_reach``; ``InterpretNodes.enqueue``), the others left as they were; None:
        all. Returns the kernel event."""
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
        use = {} if node_use is None or not self._hook_takes_node_use else dict(node_use=node_use)
        return self.model.after_kernel(self, done, profiles, **use)

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


def _takes_keyword(function, name):
    """Whether ``function`` accepts the keyword argument ``name`` (by name, or through **kwargs)."""
    import inspect

    try:
        parameters = inspect.signature(function).parameters.values()
    except (TypeError, ValueError):
        return False
    return any(p.name == name or p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters)
