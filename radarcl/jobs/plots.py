"""Figures in the paper's style (matplotlib, Agg backend: no display needed)."""

import numpy as np

from radarcl import logodds


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def interpretation_figure(ranges_m, power, threshold, pulses, evidence_units, title, interval=None):
    """Fig. 10 of the paper for one beam: (a) the profile with the CFAR threshold and its
    pulses (wide ones shaded darker), (b) the eq. 12 evidence in log-odds [nat].

    ranges_m, power, threshold, evidence_units: (n_bins,); pulses: rows [start, end, peak, wide];
    interval: (first, last) bins that may give evidence, marked as dotted lines. Returns the figure.
    """
    plt = _pyplot()
    floor = np.finfo(np.float32).tiny
    fig, (ax_a, ax_b) = plt.subplots(2, 1, figsize=(10, 6.4), sharex=True, constrained_layout=True)
    spacing = ranges_m[1] - ranges_m[0]
    for start, end, peak, wide in pulses:
        ax_a.axvspan(ranges_m[start] - spacing / 2, ranges_m[end] + spacing / 2, zorder=0,
                     color="tab:orange" if wide else "tab:green", alpha=0.45 if wide else 0.3, lw=0)
    ax_a.plot(ranges_m, 10 * np.log10(np.maximum(threshold, floor)), lw=0.8, color="tab:red",
              label="CFAR threshold")
    ax_a.plot(ranges_m, 10 * np.log10(np.maximum(power, floor)), lw=0.6, color="0.1", label="profile")
    ax_a.plot([], [], color="tab:green", alpha=0.5, lw=6, label="narrow pulse")
    ax_a.plot([], [], color="tab:orange", alpha=0.6, lw=6, label="wide pulse")
    ax_a.set_ylabel("power [dB]")
    ax_a.set_title(title, fontsize=10)
    ax_a.legend(loc="upper right", fontsize=8)
    ax_b.plot(ranges_m, logodds.to_nats(evidence_units), lw=0.8, color="tab:blue", drawstyle="steps-mid")
    ax_b.axhline(0, color="0.5", lw=0.5)
    ax_b.set_ylabel("evidence, log-odds [nat]")
    ax_b.set_xlabel("range [m]")
    if interval is not None:
        for ax in (ax_a, ax_b):
            for j in interval:
                ax.axvline(ranges_m[j], color="0.4", ls=":", lw=0.8)
    return fig
