"""The detection-statistics model ("detstats", radarcl's default): evidence from the CFAR's own
detection statistics per target class and rho2 node, a knowledge channel, correlated looks
counted once (``radarcl.sensor_model`` says the physics; ``radarcl.snr_evidence`` the "snr"
evidence's table). On the device: kernels/interpret.cl with DETSTATS (and GRADED for "snr", whose
nodes kernels/interpret_nodes.cl computes after the walk: the interpreter's ``nodes``).
"""

import numpy as np

from radarcl import logodds, sensor_model
from radarcl.models.base import Choice, EvidenceModel, Number, placeholder_tables
from radarcl.node_pairs import N_CLASSES, NODES, all_classes, pack_nodes, unpack_nodes


class DetStats(EvidenceModel):
    """The detection-statistics model: its parameters are the [sensor_model] keys."""

    name = "detstats"
    summary = "detection statistics"
    axis_label = "evidence on the axis [nat]"
    keys = {
        **{f"sensor_model.{name}": Number(lo, hi, unit, f"detstats: {why}")
           for name, (lo, hi, unit, why) in sensor_model.RANGES.items()},
        "sensor_model.evidence": Choice(sensor_model.EVIDENCE_KINDS,
                                        "detstats: snr, the likelihood ratio of the measured power over the beam's "
                                        "noise floor; detection, the CFAR's outcome alone"),
        "sensor_model.evidence_bound": Choice(sensor_model.EVIDENCE_BOUNDS,
                                              "detstats: detection, a look says no more than a CFAR detection would "
                                              "at its opportunity, either way; none, the measured power's likelihood "
                                              "ratio as it is"),
        "sensor_model.ground_below_m": Number(*sensor_model.GROUND_RANGE[:2], "m",
                                              "detstats: the sensor's height above the ground plane (0: no terrain "
                                              "class)"),
    }
    label_keys = ("sensor_model.evidence",)
    knowledge = True
    per_bin = "paper"          # eq. 12's path fuses one value per bin; its constants go unused there

    def reading(self, params):
        return params.reading

    def describe(self, interpret, params):
        return f"detection statistics ({params.evidence} evidence) on the beam's axis"

    def bin_model(self, params, cfar, beam):
        return sensor_model.BinModel.build(params, cfar, beam.n_bins, beam.bin_spacing_m, beam.oversampling,
                                           beam.half_az_rad, beam.half_el_rad, beam.voxel_m, beam.range_min_m)

    def terrain_dz(self, params):
        return sensor_model.terrain_dz(params)

    def defines(self, bin_model):
        return dict(OCCLUSION=0, DETSTATS=1, GRADED=int(bin_model.graded))

    def device_tables(self, queue, interpreter):
        import pyopencl.array as cla

        tables = placeholder_tables(queue)
        m = interpreter.bin_model
        tables.update(opportunity=cla.to_device(queue, m.opportunity.astype(np.float32)),
                      blocking=cla.to_device(queue, m.blocking.astype(np.float32)), c_det=(1.0 - m.pfa) / m.pfa)
        if m.graded:                     # the table replaces the misses and the exact unblocked nodes
            n_beams, n_bins = interpreter.n_beams, interpreter.n_bins
            tables.update(noise_floor=float(m.noise_floor),
                          state=cla.zeros(queue, (n_beams, 2, n_bins), np.float32),    # per bin: blocked, tau
                          ln_floors=cla.zeros(queue, (n_beams,), np.float32))
            # the beam's walk leaves each bin's blocking; the interpreter's nodes kernel makes the
            # nodes of the window's bins only: the others are 0 from here on. Zeroed by the
            # driver's fill (cla.zeros_like): Array.fill(0) launches an elementwise kernel, which on
            # PoCL takes many times as long over a spinning radar's tens of MB of nodes
            interpreter.arrays["evidence"] = cla.zeros_like(interpreter.arrays["evidence"])
            return tables
        first, last, n_bins = interpreter.first_bin, interpreter.last_bin, interpreter.n_bins
        unblocked = np.zeros((n_bins, N_CLASSES, NODES), np.int64), np.zeros((n_bins, N_CLASSES, NODES), np.int64)
        if first <= last:
            with np.errstate(divide="ignore"):
                unblocked[0][first:last + 1] = logodds.to_fixed(np.log(m.miss[first:last + 1]))
            unblocked[1][first:last + 1] = np.rint(m.opportunity[first:last + 1] * logodds.KNOWLEDGE_SCALE)
            unblocked[0][unblocked[1] == 0] = 0                 # no look, no evidence (as the kernel's nodes)
        kept = interpreter.classes                              # the node array's classes (node_shape)
        tables.update(miss=cla.to_device(queue, m.miss.astype(np.float32)),
                      unblocked=cla.to_device(queue, pack_nodes(*(u[:, :kept] for u in unblocked))))
        return tables

    def after_kernel(self, interpreter, event, profiles, node_use=None):
        if interpreter.nodes is None:     # "detection" evidence: the beam's walk made the nodes
            return event
        t = interpreter._tables
        return interpreter.nodes.enqueue(profiles, interpreter.arrays["flags_out"], t["state"], t["ln_floors"],
                                         interpreter.arrays["evidence"], wait_for=[event], node_use=node_use)

    def oracle(self, profiles, noise, mask, config, bin_spacing_m, bin_model=None, flags=None):
        from radarcl import oracle

        return np.stack(oracle.interpret_detstats(profiles, noise, mask, config, bin_spacing_m, bin_model, flags)[:2])

    def comparable(self, evidence):
        # the oracle's form has both classes: a class the pipeline drops has all its nodes 0
        return np.stack([all_classes(v) for v in unpack_nodes(evidence)])

    def nodes(self, evidence):
        return tuple(all_classes(v) for v in unpack_nodes(evidence))

    def on_axis(self, evidence):
        return evidence[0, ..., 0, 0]         # the evidence (not the opportunity) of an upright target, rho2 = 0
