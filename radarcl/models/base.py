"""What an evidence model is: the interface every entry of ``radarcl.models.MODELS`` fills.

An evidence model turns one CFAR'd range profile into evidence per bin (kernels/interpret.cl on
the device, its float64 oracle on the host) and says how a map of it is fused and read. The
design, its invariants and how to add one: docs/design/models.md.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Number:
    """A numeric configuration key a model owns: [lo, hi] in ``unit`` (lo excluded with ``lo_open``)."""

    lo: float
    hi: float
    unit: str
    help: str
    lo_open: bool = False


@dataclass(frozen=True)
class Choice:
    """A configuration key a model owns that takes one of ``choices``."""

    choices: tuple
    help: str


class EvidenceModel:
    """One evidence model; subclasses override what differs.

    name: its ``interpret.model`` value; summary: one line for the key's help.
    keys: its own configuration keys {"section.key": Number | Choice} (the interpreter's common keys,
        range and pulses, are everyone's and live in ``radarcl.config.keys``).
    axis_label: the axis of a plot of one beam's evidence (``on_axis``).
    label_keys: key prefixes a configuration's short label names for this model.
    knowledge: the model fuses node pairs (evidence and opportunity per target class and rho2 node,
        ``node_pairs.node_shape``) built from the sensor's ``sensor_model.BinModel`` into a map
        with the knowledge channel (looks), read by its reading; otherwise one evidence value per bin
        is summed into the map as eq. 9 says.
    occludes: eq. 12's family: the first strong pulse is a surface and E_h ramps in range to
        e_high_far (``InterpretConfig``); the calibration then searches the surface level and fits
        the near and far E_h apart.
    per_bin: the model whose one-value-per-bin fusion path a job's own per-bin evidence (raw
        intensity, counts, oracle detections) takes with a configuration of this one.
    fitted: the keys `radarcl calibrate`'s logistic fit estimates for it (empty: none).
    """

    name = None
    summary = ""
    axis_label = "evidence [nat]"
    keys = {}
    label_keys = ()
    knowledge = False
    occludes = False
    per_bin = None
    fitted = ()

    # -- the configuration -------------------------------------------------------------------------
    def reading(self, params):
        """What a map of this model keeps to be read ({"look_limit": ...}) with the [sensor_model]
        values ``params`` (``sensor_model.ModelParams``); None for a map read as its sums."""
        return None

    def describe(self, interpret, params):
        """A few words naming the model and its constants (``interpret``: the ``InterpretConfig``;
        ``params``: the ``sensor_model.ModelParams``), for a figure's title."""
        return self.summary

    # -- the host's tables ---------------------------------------------------------------------------
    def bin_model(self, params, cfar, beam):
        """The host tables the device needs (``sensor_model.BinModel``) or None. ``params``: the
        [sensor_model] values as ``sensor_model.ModelParams``; ``cfar``: the ``CfarConfig``;
        ``beam``: a ``BeamGeometry``."""
        return None

    def terrain_dz(self, params):
        """How far below the sensor the terrain class begins [m] (-inf: no terrain class)."""
        return -np.inf

    # -- the device ----------------------------------------------------------------------------------
    def defines(self, bin_model):
        """The ``-D`` switches of kernels/interpret.cl for this model."""
        return dict(OCCLUSION=int(self.occludes), DETSTATS=0, GRADED=0)

    def device_tables(self, queue, interpreter):
        """The kernel's table arguments (placeholders where this model reads none)."""
        return placeholder_tables(queue)

    def after_kernel(self, interpreter, event, profiles, node_use=None):
        """Device work after kernels/interpret.cl (a model whose evidence the kernel does not make
        writes it here into ``interpreter.arrays["evidence"]``; ``profiles``: the frame on the
        device, ``interpreter.kernels``: the program's kernels; ``node_use``: which node pairs the
        frame's voxels read, as ``Interpreter.enqueue``, passed only where the pipeline knows them (a
        still plan's table, a moving frame's bound) and the hook takes it: a hook without it makes
        every node); returns the last event."""
        return event

    # -- the oracle ----------------------------------------------------------------------------------
    def oracle(self, profiles, noise, mask, config, bin_spacing_m, bin_model=None, flags=None):
        """The float64 evidence of (..., n_bins) profiles, in the form ``comparable`` gives the device's."""
        from radarcl import oracle

        return oracle.interpret(profiles, noise, mask, config, bin_spacing_m, flags)[0]

    def comparable(self, evidence):
        """The device's evidence array as ``oracle`` returns it."""
        return evidence

    def nodes(self, evidence):
        """The fusion oracle's ``nodes`` argument for the device's evidence (None: per-bin evidence)."""
        return None

    def on_axis(self, evidence):
        """Per-bin evidence (..., n_bins) of an upright target on the beam's axis, from ``oracle``'s."""
        return evidence


@dataclass(frozen=True)
class BeamGeometry:
    """What a model's host tables need of the sensor and the grid: bins, their spacing, the
    oversampling of the range FFT (correlated training cells), the beam's half widths [rad], the
    voxel [m] and the nearest range given evidence [m]."""

    n_bins: int
    bin_spacing_m: float
    oversampling: float
    half_az_rad: float
    half_el_rad: float
    voxel_m: float
    range_min_m: float


def placeholder_tables(queue):
    """The table arguments of kernels/interpret.cl for a model that reads none (one-element buffers)."""
    import pyopencl.array as cla

    one = cla.zeros(queue, (1,), np.float32)
    return dict(opportunity=one, miss=one, blocking=one, unblocked=cla.zeros(queue, (1, 2), np.int32), c_det=1.0,
                noise_floor=1.0, state=cla.zeros(queue, (1, 2), np.float32), ln_floors=one)
