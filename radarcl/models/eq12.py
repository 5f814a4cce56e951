"""Eq. 12 of the paper (model "paper") and radarcl's occlusion-aware variant of it ("occlusion").

Both give one evidence value per bin: k_occ log10(r/n) on a pulse, E_h before the first wide pulse
(the occlusion model: before the first surface, E_h ramping in range to e_high_far), E_l after it
(``radarcl.config.stage_config.InterpretConfig``; the kernel's switch OCCLUSION).
"""

from radarcl.models.base import EvidenceModel, Number


class Eq12(EvidenceModel):
    """The paper's interpreter, eq. 12, with its constants k_occ, E_h, E_l."""

    name = "paper"
    summary = "eq. 12"
    axis_label = "eq. 12 evidence [nat]"
    label_keys = ("interpret.k_occ", "interpret.e_", "interpret.wide")
    per_bin = "paper"
    fitted = ("interpret.k_occ", "interpret.e_high", "interpret.e_low")

    def describe(self, interpret, params):
        return f"eq. 12 with k_occ {interpret.k_occ:g}, E_h {interpret.e_high:g}, E_l {interpret.e_low:g}"


class Occlusion(Eq12):
    """Eq. 12 with free evidence only up to the first surface (a wide pulse, or one whose peak
    reaches surface_db), E_h interpolated in range from e_high to e_high_far."""

    name = "occlusion"
    summary = "free evidence only up to the first surface"
    keys = {"interpret.surface_db": Number(-100, 100, "dB", "occlusion: a pulse whose peak r/n reaches this is a "
                                                            "surface"),
            "interpret.e_high_far": Number(-16, 0, "nat", "occlusion: E_h at the far end of the range (e_high at "
                                                          "the near end)")}
    occludes = True
    per_bin = "occlusion"
    fitted = ("interpret.k_occ", "interpret.e_high", "interpret.e_high_far", "interpret.e_low")
