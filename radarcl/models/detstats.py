"""The detection-statistics model ("detstats", radarcl's default): evidence from the CFAR's own
detection statistics per target class and rho2 node, a knowledge channel, correlated looks
counted once (``radarcl.sensor_model`` says the physics; ``radarcl.snr_evidence`` the "snr"
evidence's table). On the device: kernels/interpret.cl with DETSTATS (and GRADED for "snr").
"""

import numpy as np

from radarcl import logodds, sensor_model
from radarcl.models.base import Choice, EvidenceModel, Number, placeholder_tables
from radarcl.sensor_model import N_CLASSES, NODES, pack_nodes
from radarcl.snr_evidence import GAP_CAP, SNR_U, SNR_V, detection_cap

# Work-items per work-group of interpret_nodes ("snr" evidence's nodes, eight bins a work-item):
# any size is correct; within any device's work-group limit.
NODES_LOCAL_SIZE = 64


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
        graded = bin_model.graded
        grid = dict(SNR_NU=SNR_U[2], SNR_NV=SNR_V[2], SNR_U0=float(SNR_U[0]), SNR_V0=float(SNR_V[0]),
                    SNR_U_SCALE=(SNR_U[2] - 1) / (SNR_U[1] - SNR_U[0]),
                    SNR_V_SCALE=(SNR_V[2] - 1) / (SNR_V[1] - SNR_V[0]), GAP_CAP=GAP_CAP) if graded else {}
        return dict(OCCLUSION=0, DETSTATS=1, GRADED=int(graded), **grid)

    def device_tables(self, queue, interpreter):
        import pyopencl.array as cla

        tables = placeholder_tables(queue)
        m = interpreter.bin_model
        tables.update(opportunity=cla.to_device(queue, m.opportunity.astype(np.float32)),
                      blocking=cla.to_device(queue, m.blocking.astype(np.float32)), c_det=(1.0 - m.pfa) / m.pfa)
        if m.graded:                     # the table replaces the misses and the exact unblocked nodes
            n_beams, n_bins = interpreter.n_beams, interpreter.n_bins
            snr_cap = detection_cap(m.opportunity, m.snr_table.q, m.bounded).astype(np.float32)
            tables.update(ln_snr=cla.to_device(queue, m.ln_snr.astype(np.float32)),
                          snr_table=cla.to_device(queue, m.snr_table.values.astype(np.float32)),
                          snr_cap=cla.to_device(queue, snr_cap),
                          noise_floor=float(m.noise_floor), blocker_gap=float(m.blocker_gap),
                          snr_q=float(m.snr_table.q),
                          state=cla.zeros(queue, (n_beams, 2, n_bins), np.float32),    # per bin: blocked, tau
                          ln_floors=cla.zeros(queue, (n_beams,), np.float32))
            # the beam's walk leaves each bin's blocking; interpret_nodes makes the nodes, eight bins a
            # work-item, reading its tables with the bins last (one vector load a node) and writing
            # the window's bins only: the others are 0 from here on
            interpreter.arrays["evidence"].fill(0)
            kernel = interpreter.kernels["interpret_nodes"]
            interpreter.model_state = dict(
                kernel=kernel, local_size=min(NODES_LOCAL_SIZE, interpreter.runtime.max_local_size(kernel)),
                tables={name: cla.to_device(queue, np.ascontiguousarray(
                    np.asarray(table, np.float32).reshape(n_bins, N_CLASSES * NODES).T))
                    for name, table in (("opportunity", m.opportunity), ("ln_snr", m.ln_snr), ("snr_cap", snr_cap))})
            return tables
        first, last, n_bins = interpreter.first_bin, interpreter.last_bin, interpreter.n_bins
        unblocked = np.zeros((n_bins, N_CLASSES, NODES), np.int64), np.zeros((n_bins, N_CLASSES, NODES), np.int64)
        if first <= last:
            with np.errstate(divide="ignore"):
                unblocked[0][first:last + 1] = logodds.to_fixed(np.log(m.miss[first:last + 1]))
            unblocked[1][first:last + 1] = np.rint(m.opportunity[first:last + 1] * logodds.KNOWLEDGE_SCALE)
            unblocked[0][unblocked[1] == 0] = 0                 # no look, no evidence (as the kernel's nodes)
        tables.update(miss=cla.to_device(queue, m.miss.astype(np.float32)),
                      unblocked=cla.to_device(queue, pack_nodes(*unblocked)))
        return tables

    def after_kernel(self, interpreter, event, profiles):
        state = interpreter.model_state
        if state is None:                 # "detection" evidence: the beam's walk made the nodes
            return event
        chunks = max(0, (interpreter.last_bin >> 3) - (interpreter.first_bin >> 3) + 1)   # eight bins meeting the window
        n, ls, t = interpreter.n_beams * chunks, state["local_size"], interpreter._tables
        if not n:
            return event
        return state["kernel"](interpreter.runtime.queue, (-(-n // ls) * ls,), (ls,), wait_for=[event],
                               profiles=profiles, flags_out=interpreter.arrays["flags_out"], state=t["state"],
                               ln_floors=t["ln_floors"], snr_table=t["snr_table"], **state["tables"],
                               first_bin=interpreter.first_bin, last_bin=interpreter.last_bin,
                               blocker_gap=t["blocker_gap"], snr_q=t["snr_q"], n_chunks=chunks,
                               n_beams=interpreter.n_beams, evidence=interpreter.arrays["evidence"])

    def oracle(self, profiles, noise, mask, config, bin_spacing_m, bin_model=None, flags=None):
        from radarcl import oracle

        return np.stack(oracle.interpret_detstats(profiles, noise, mask, config, bin_spacing_m, bin_model, flags)[:2])

    def comparable(self, evidence):
        return np.stack(sensor_model.unpack_nodes(evidence))

    def nodes(self, evidence):
        return sensor_model.unpack_nodes(evidence)

    def on_axis(self, evidence):
        return evidence[0, ..., 0, 0]         # the evidence (not the opportunity) of an upright target, rho2 = 0
