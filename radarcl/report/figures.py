"""Every figure radarcl draws (matplotlib, Agg backend: no display needed), one function each,
returning the figure; ``save`` writes it whole or not at all.

House rules, checked by ``problems`` in the tests: every image-like panel has a colour bar with
its unit; every axis is labelled with its unit (metres, degrees, dB, nat); text is at least 10 pt
and inside the canvas; maps seen from above have x forward up and y left to the left (REP-103).
"""

import numpy as np

from radarcl import logodds
from radarcl.io.files import atomic

RC = {"font.size": 10, "axes.titlesize": 11, "axes.labelsize": 10, "xtick.labelsize": 10,
      "ytick.labelsize": 10, "legend.fontsize": 10, "figure.titlesize": 12}
MIN_POINTS = 10


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update(RC)
    return plt


def save(fig, path, dpi=110):
    """Write ``fig`` as a PNG through a temporary file, then close it; cropped to what is
    drawn (square map panels otherwise leave wide empty margins)."""
    plt = _pyplot()
    with atomic(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png", bbox_inches="tight", pad_inches=0.15)
    plt.close(fig)


def problems(fig):
    """What breaks the house rules in ``fig`` (an empty list when nothing does)."""
    from matplotlib.image import AxesImage
    from matplotlib.text import Text

    fig.canvas.draw()
    out = []
    renderer = fig.canvas.get_renderer()
    canvas = fig.bbox
    colorbar_axes = {id(ax) for ax in fig.axes if hasattr(ax, "_colorbar")}
    images = [ax for ax in fig.axes if id(ax) not in colorbar_axes and any(isinstance(a, AxesImage) for a in ax.get_children())]
    mappables = [getattr(ax, "_colorbar").mappable for ax in fig.axes if hasattr(ax, "_colorbar")]
    for ax in images:
        if not any(m.axes is ax for m in mappables) and not getattr(ax, "_radarcl_shared_colorbar", False):
            out.append(f"image panel {ax.get_title()!r} has no colour bar")
    for ax in fig.axes:
        if id(ax) in colorbar_axes:
            if not getattr(ax, "_colorbar").ax.get_ylabel() and not getattr(ax, "_colorbar").ax.get_xlabel():
                out.append("a colour bar without a label")
            continue
        if not ax.axison:
            continue
        if not ax.get_xlabel() and not getattr(ax, "_radarcl_shared_x", False):
            out.append(f"panel {ax.get_title()!r} has no x label")
        if not ax.get_ylabel() and not getattr(ax, "_radarcl_shared_y", False):
            out.append(f"panel {ax.get_title()!r} has no y label")
    def outside(box):
        return box.x0 < canvas.x0 - 1 or box.y0 < canvas.y0 - 1 or box.x1 > canvas.x1 + 1 or box.y1 > canvas.y1 + 1

    # Matplotlib keeps tick labels beyond the view limits that it never draws: tick labels are
    # placed through their axes' tight box (what is drawn), every other text on its own.
    tick_labels = {id(t) for ax in fig.axes for axis in (ax.xaxis, ax.yaxis) for t in axis.get_ticklabels(which="both")}
    for ax in fig.axes:
        if ax.get_visible() and outside(ax.get_tightbbox(renderer)):
            out.append(f"panel {ax.get_title()!r} reaches outside the canvas (tick labels or axis labels)")
    for text in fig.findobj(Text):
        if not text.get_visible() or not text.get_text().strip():
            continue
        if text.get_fontsize() < MIN_POINTS:
            out.append(f"text {text.get_text()!r} at {text.get_fontsize():.1f} pt")
        if id(text) not in tick_labels and outside(text.get_window_extent(renderer)):
            out.append(f"text {text.get_text()!r} outside the canvas")
    return out


def _colorbar(fig, image, ax, label):
    bar = fig.colorbar(image, ax=ax, shrink=0.85)
    bar.set_label(label)
    bar.ax._colorbar = bar
    return bar


# -- the range profile and detection (paper §3.2, §3.3) -------------------------------------------
def fig9_figure(ranges, profiles, pair_m, labels):
    """Fig. 9: one beam's profile at several zero paddings. ``ranges`` and ``profiles`` are
    lists (one per FFT length), ``labels`` their panel titles."""
    plt = _pyplot()
    fig, axes = plt.subplots(len(profiles), 1, figsize=(7.5, 8), sharex=True)
    for k, (ax, r, p, label) in enumerate(zip(axes, ranges, profiles, labels)):
        ax.plot(r, p, ".-", ms=3)
        for m in pair_m:
            ax.axvline(m, color="grey", lw=0.8, ls="--")
        ax.set_title(f"({'abcdef'[k]}) {label}")
        ax.set_ylabel("amplitude [ADC codes]")
        if k < len(profiles) - 1:
            ax._radarcl_shared_x = True
    axes[-1].set_xlim(4, 11)
    axes[-1].set_xlabel("range [m]")
    fig.suptitle(f"Two point targets 1.0 m apart at {pair_m[0]} and {pair_m[1]} m (paper Fig. 9)")
    fig.tight_layout()
    return fig


def frame_figure(db, azimuths_deg, range_max_m, n_fft):
    """One frame as range x azimuth images, one per stacked beam, in dB of the strongest bin,
    azimuth in degrees (positive to the left, so left is on the left)."""
    plt = _pyplot()
    n_el = db.shape[1]
    fig, axes = plt.subplots(1, n_el, figsize=(3.2 * n_el + 1.2, 4.4), sharey=True)
    axes = np.atleast_1d(axes)
    top = float(db.max())
    half = 0.5 * (azimuths_deg[1] - azimuths_deg[0]) if len(azimuths_deg) > 1 else 0.5
    image = None
    for el, ax in enumerate(axes):
        image = ax.imshow(db[:, el, :].T - top, origin="lower", aspect="auto", vmin=-70, vmax=0, cmap="viridis",
                          extent=(azimuths_deg[0] - half, azimuths_deg[-1] + half, 0, range_max_m))
        ax.invert_xaxis()                                    # azimuth positive to the left
        ax.set_title(f"stacked beam {el}")
        ax.set_xlabel("azimuth [deg], left +")
        if el:
            ax._radarcl_shared_y = True
        ax._radarcl_shared_colorbar = True
    axes[0].set_ylabel("range [m]")
    bar = fig.colorbar(image, ax=list(axes), shrink=0.9)
    bar.set_label("power [dB re strongest bin]")
    bar.ax._colorbar = bar
    fig.suptitle(f"One frame of the paper's radar, range x azimuth, n_fft = {n_fft}")
    return fig


def interpretation_figure(ranges_m, power, threshold, pulses, evidence_units, title, interval=None):
    """Fig. 10 of the paper for one beam: (a) the profile with the CFAR threshold and its
    pulses (wide ones shaded darker), (b) the eq. 12 evidence in log-odds [nat].

    ranges_m, power, threshold, evidence_units: (n_bins,); pulses: rows [start, end, peak, wide];
    interval: (first, last) bins that may give evidence, marked as dotted lines. Returns the figure.
    """
    plt = _pyplot()
    floor = np.finfo(np.float32).tiny
    fig, (ax_a, ax_b) = plt.subplots(2, 1, figsize=(10, 6.6), sharex=True, constrained_layout=True)
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
    ax_a.set_title(title, fontsize=10, wrap=True)
    ax_a.legend(loc="upper right")
    ax_a._radarcl_shared_x = True
    ax_b.plot(ranges_m, logodds.to_nats(evidence_units), lw=0.8, color="tab:blue", drawstyle="steps-mid")
    ax_b.axhline(0, color="0.5", lw=0.5)
    ax_b.set_ylabel("evidence, log-odds [nat]")
    ax_b.set_xlabel("range [m]")
    if interval is not None:
        for ax in (ax_a, ax_b):
            for j in interval:
                ax.axvline(ranges_m[j], color="0.4", ls=":", lw=0.8)
    return fig


def beams_figure(panels, title, evidence_label="eq. 12 evidence [nat]"):
    """Several beams like Fig. 10, side by side: ``panels`` of (ranges, power, threshold, mask,
    evidence_units, subtitle); ``evidence_label`` names the evidence axis."""
    plt = _pyplot()
    fig, axes = plt.subplots(2, len(panels), figsize=(5.6 * len(panels), 6.6), sharex=True, squeeze=False)
    floor = np.finfo(np.float32).tiny
    for col, (r, power, threshold, mask, evidence, subtitle) in enumerate(panels):
        top, bottom = axes[0, col], axes[1, col]
        top.plot(r, 10 * np.log10(np.maximum(power, floor)), lw=0.7, label="power")
        top.plot(r, 10 * np.log10(np.maximum(threshold, floor)), lw=0.8, label="CFAR threshold")
        top.plot(r[mask], 10 * np.log10(np.maximum(power[mask], floor)), ".", ms=2, label="detections")
        top.set_title(subtitle, fontsize=10)
        top.set_ylabel("power [dB]")
        top._radarcl_shared_x = True
        bottom.plot(r, logodds.to_nats(evidence), lw=0.8)
        bottom.set_xlabel("range [m]")
        bottom.set_ylabel(evidence_label)
    axes[0, 0].legend(loc="upper right")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


# -- maps seen from above ------------------------------------------------------------------------------
def topdown_figure(log_odds, occupied_truth, spec, above_z_m=0.0):
    """The map's largest positive log-odds above ``above_z_m`` seen from above beside the truth
    (occupied voxels above it), x forward up, y left to the left."""
    plt = _pyplot()
    x0, y0, z0 = spec.origin_m
    nx, ny, nz = spec.shape
    extent = (y0, y0 + ny * spec.voxel_m, x0, x0 + nx * spec.voxel_m)
    above = z0 + np.arange(nz) * spec.voxel_m >= above_z_m - 1e-9     # from the layer holding above_z_m up
    top = np.max(np.where(log_odds[above] > 0, log_odds[above], 0), axis=0)
    fig, axes = plt.subplots(1, 2, figsize=(12.5, 6.2), sharey=True)
    vmax = float(np.percentile(top[top > 0], 99)) if (top > 0).any() else 1.0
    image = axes[0].imshow(top.T, origin="lower", extent=extent, cmap="magma", vmin=0, vmax=vmax, aspect="equal")
    _colorbar(fig, image, axes[0], "largest log-odds above the grass [nat]")
    axes[0].set_title("map")
    truth = occupied_truth[above][1:].any(axis=0)                     # the layers above the grass itself
    image = axes[1].imshow(truth.T, origin="lower", extent=extent, cmap="Greys", vmin=0, vmax=1, aspect="equal")
    bar = _colorbar(fig, image, axes[1], "truth: occupied above the grass")
    bar.set_ticks([0, 1], labels=["free", "occupied"])
    axes[1].set_title("ground truth")
    for ax in axes:
        ax.set_xlabel("y, left [m]")
        ax.invert_xaxis()
    axes[0].set_ylabel("x, forward [m]")
    axes[1]._radarcl_shared_y = True
    fig.tight_layout()
    return fig


def plane_map_figure(nats, spec, poses, title, pose_label="scan poses", label="log-odds [nat]", unknown=None):
    """A one-layer map (ny, nx) seen from above: log-odds from -L (free, blue) to +L (occupied,
    red), L the 99th percentile of |log-odds|, unseen white; the poses (n, 4, 4) in black.
    ``unknown`` (ny, nx) bool (a map with the knowledge channel): those cells grey, whatever
    their log-odds (never observed is not "observed, undecided")."""
    plt = _pyplot()
    seen = nats[nats != 0]
    limit = float(np.percentile(np.abs(seen), 99)) if seen.size else 1.0
    shown = np.ma.masked_equal(nats, 0.0).T                     # rows = x, columns = y
    if unknown is not None:
        shown = np.ma.masked_where(np.asarray(unknown).T, shown)
    x0, y0, _ = spec.origin_m
    nx, ny, _ = spec.shape
    extent = (y0, y0 + ny * spec.voxel_m, x0, x0 + nx * spec.voxel_m)
    fig, ax = plt.subplots(figsize=(8.4, float(np.clip(8.4 * nx / ny, 4.0, 12.0))), dpi=120)
    if unknown is not None:
        ax.imshow(np.ma.masked_where(~np.asarray(unknown).T, np.ones(shown.shape)), origin="lower", extent=extent,
                  cmap="Greys", vmin=0.0, vmax=2.5, interpolation="nearest")
    image = ax.imshow(shown, origin="lower", extent=extent, cmap="coolwarm", vmin=-limit, vmax=limit,
                      interpolation="nearest")
    if len(poses):
        ax.plot(poses[:, 1, 3], poses[:, 0, 3], "k.-", ms=4, label=pose_label)
        ax.legend(loc="upper right")
    ax.invert_xaxis()                                           # y points left
    ax.set_xlabel("y, left [m]")
    ax.set_ylabel("x, forward [m]")
    ax.set_title(title)
    _colorbar(fig, image, ax, f"{label}; white: unseen" + ("; grey: unknown" if unknown is not None else ""))
    fig.tight_layout()
    return fig


CLASS_COLOURS = ((-1, "unknown (never observed)", "#c8c8c8"), (0, "free", "#ffffff"),
                 (1, "observed, undecided", "#f2d49b"), (2, "occupied", "#b2182b"))   # the values of maps.map.classes


def classes_figure(classes, spec, poses, title, pose_label="sensor path", what="seen from above"):
    """A map's classes (ny, nx) (``Map.classes_from_above``: occupied, free, undecided, unknown)
    seen from above in four flat colours with a legend, x forward up and y left, metre axes, and
    the sensor's poses (n, 4, 4) as its path."""
    plt = _pyplot()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    x0, y0, _ = spec.origin_m
    nx, ny, _ = spec.shape
    extent = (y0, y0 + ny * spec.voxel_m, x0, x0 + nx * spec.voxel_m)
    fig, ax = plt.subplots(figsize=(8.4, float(np.clip(8.4 * nx / ny, 4.0, 12.0))), dpi=120)
    index = np.asarray(classes, np.int64).T + 1                     # rows = x, columns = y; -1..2 -> 0..3
    ax.imshow(index, origin="lower", extent=extent, cmap=ListedColormap([c for _, _, c in CLASS_COLOURS]),
              vmin=-0.5, vmax=3.5, interpolation="nearest")
    handles = [Patch(facecolor=c, edgecolor="0.4", label=f"{name}: {int((np.asarray(classes) == v).sum()):,}")
               for v, name, c in CLASS_COLOURS]
    if len(poses):
        handles += ax.plot(poses[:, 1, 3], poses[:, 0, 3], "k.-", ms=3, lw=1, label=pose_label)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), title=f"cells of {spec.voxel_m:g} m")
    ax.invert_xaxis()                                           # y points left
    ax.set_xlabel("y, left [m]")
    ax.set_ylabel("x, forward [m]")
    ax.set_aspect("equal")
    ax.set_title(f"{title}, {what}")
    fig.tight_layout()
    return fig


# -- error against run time ------------------------------------------------------------------------------
DIMENSION_MARKERS = {"reference": "*", "zero padding": "o", "beam model": "s", "voxel": "D", "cfar": "^",
                     "evidence": "v", "blocker gap": "<", "look limit": ">", "knowledge": "p", "budget": "H"}


BASELINE_MARKERS = {"prior_only": ("P", "tab:gray"), "raw_intensity": ("h", "tab:olive"), "octomap": ("X", "crimson")}


MODEL_COLOURS = {"paper": "tab:blue", "detstats": "tab:orange"}       # eq. 12, the default model
MODEL_NAMES = {"paper": "eq. 12", "detstats": "default model"}


def quality_figure(r):
    """``bench quality``'s result, two panels against ms per frame: AUC (detectable vs
    free-visible) and the ECE of the occupied calls, on the reference voxel size's fixed set.
    Each run is a numbered marker, its colour the model (eq. 12, the default model), its shape
    the setting changed; the names are in the table beside, each panel's Pareto front a dashed
    line, the baselines large markers. Every run is scored on the same fixed voxel set (a run at
    another voxel size read on its voxels)."""
    plt = _pyplot()
    runs = r["runs"]
    import textwrap

    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    rows = []
    for k, x in enumerate(runs, 1):
        name = x["label"] if x["dimension"] in ("reference", "default model") or x["label"].startswith(
            ("reference", "default model")) else f"{MODEL_NAMES.get(x.get('model'), '')}: {x['label']}"
        lines = textwrap.wrap(name, 46) or [""]
        rows += [f"{k:>2}  {lines[0]}"] + [f"    {line}" for line in lines[1:]]
    # the run table above the legend (two columns, about 10 lines), at MIN_POINTS: 0.17 inch a line
    fig = plt.figure(figsize=(15, max(8.5, 0.17 * (len(rows) + 12) / 0.82)))
    ref_v = r.get("reference_voxel_m")
    panels = (("auc_detectable", "pareto", "ROC-AUC, detectable vs free-visible (higher: better)"),
              ("ece_occupied", "pareto_ece", "ECE of the occupied calls (lower: better)"))
    for i, (key, front_key, ylabel) in enumerate(panels):
        ax = fig.add_axes([0.05 + i * 0.3, 0.09, 0.25, 0.82])
        shown = [(k, x) for k, x in enumerate(runs, 1) if x.get(key) is not None]
        for k, x in shown:
            dim = x["dimension"].removeprefix("default model: ").removeprefix("default model")
            colour = MODEL_COLOURS.get(x.get("model"), "k")
            ax.scatter(x["ms_per_frame"], x[key], marker=DIMENSION_MARKERS.get(dim or "reference", "o"),
                       s=160 if dim in ("reference", "") else 60, color=colour, edgecolor="k",
                       linewidth=1.6 if x.get(front_key) else 0.4, zorder=3)
        front = sorted((x["ms_per_frame"], x[key]) for _, x in shown if x.get(front_key))
        if front:
            ax.plot(*zip(*front), "k--", lw=1.2, label="Pareto front (thick edge)", zorder=2)
        for name, b in (r.get("baselines") or {}).items():
            if b.get(key) is not None:
                marker, colour = BASELINE_MARKERS.get(name, ("X", "k"))
                ax.scatter(max(b["ms_per_frame"], 0.1), b[key], marker=marker, color=colour, edgecolor="k",
                           s=220, zorder=4, label=f"baseline: {name}")
        ax.set_xscale("log")
        ax.set_xlabel("ms per frame, whole pipeline (prior_only at 0.1)")
        ax.set_ylabel(ylabel)
        ax.xaxis.set_major_locator(LogLocator(subs=(1, 2, 5)))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.grid(alpha=0.3, which="both")
        _number_points(ax, [(x["ms_per_frame"], x[key]) for _, x in shown], [k for k, _ in shown])
        if i == 0:
            handles, labels = ax.get_legend_handles_labels()
    fig.suptitle(f"Error against run time: reference scene, {r['observations']} observations, fixed voxel set at "
                 f"{ref_v} m, on {r['device'].split('/')[-1].strip()[:40]}", fontsize=12)
    for model, colour in MODEL_COLOURS.items():
        if any(x.get("model") == model for x in runs):
            handles.append(plt.Line2D([], [], marker="o", ls="", color=colour, markeredgecolor="k"))
            labels.append(MODEL_NAMES[model])
    for dim, marker in DIMENSION_MARKERS.items():
        if any(x["dimension"].endswith(dim) or (dim == "reference" and x["dimension"] == "default model")
               for x in runs):
            handles.append(plt.Line2D([], [], marker=marker, ls="", color="w", markeredgecolor="k"))
            labels.append(dim)
    table = fig.add_axes([0.64, 0.09, 0.35, 0.82])
    table.axis("off")
    text = table.text(0, 1, "run  setting changed from its model's reference\n" + "\n".join(rows), va="top",
                      family="monospace", fontsize=MIN_POINTS, transform=table.transAxes)
    # the legend right below the run table, wherever its lines end
    below = table.transAxes.inverted().transform(text.get_window_extent(fig.canvas.get_renderer()))[0, 1]
    table.legend(handles, labels, loc="upper left", bbox_to_anchor=(0.0, below - 0.01), frameon=False,
                 fontsize=MIN_POINTS, ncol=2)
    return fig


def _number_points(ax, points, numbers=None, near_px=12):
    """Number the points 1..n (or ``numbers``) beside their markers; points closer than ``near_px`` on screen
    share one label ("1, 5"), and each label takes the first of four places beside its marker
    that overlaps no other label or marker, so numbers never print over each other."""
    ax.autoscale_view()
    screen = ax.transData.transform(np.asarray(points, float))
    groups = []
    for k, p in enumerate(screen):
        for g in groups:
            if np.hypot(*(screen[g[0]] - p)) < near_px:
                g.append(k)
                break
        else:
            groups.append([k])
    scale = ax.figure.dpi / 72.0                        # offsets are in points, the screen in pixels
    placed = [(p[0] - 7, p[1] - 7, p[0] + 7, p[1] + 7) for p in screen]          # the markers
    for g in groups:
        text = _runs_text([k + 1 if numbers is None else numbers[k] for k in g])
        w, h = 7.0 * len(text) * scale, 11.0 * scale
        x, y = screen[g[0]]
        for dx, dy in ((6, 4), (6, -14), (-8 - 7 * len(text), 4), (-8 - 7 * len(text), -14)):
            box = (x + dx * scale, y + dy * scale, x + dx * scale + w, y + dy * scale + h)
            if not any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in placed):
                break
        else:
            dx, dy = 6, 4
        placed.append(box)
        ax.annotate(text, points[g[0]], xytext=(dx, dy), textcoords="offset points", fontsize=10, zorder=5)


def _runs_text(numbers):
    """"1, 5" or, for three or more in a row, "12-16": a group's label kept short."""
    spans = []
    for n in numbers:
        if spans and n == spans[-1][1] + 1:
            spans[-1][1] = n
        else:
            spans.append([n, n])
    return ", ".join(f"{a}-{b}" if b - a >= 2 else ", ".join(map(str, range(a, b + 1))) for a, b in spans)


def reliability_figure(curves, subtitle="", what="visible voxels", outcome="occupied"):
    """Reliability diagram: per map ({name: rows (lo, hi, count, mean p, frequency)} from
    ``metrics.calibration``) the observed frequency of ``outcome`` against the mean predicted p
    in each bin, the diagonal being perfect calibration; beneath, how many ``what`` each bin
    holds."""
    import textwrap

    plt = _pyplot()
    fig, (ax, hist) = plt.subplots(2, 1, figsize=(7.5, 8.0), gridspec_kw=dict(height_ratios=(3, 1.2)), sharex=True)
    ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls=":", label="perfectly calibrated")
    width = 0.1 / (len(curves) + 1)
    for n, (name, rows) in enumerate(curves.items()):
        rows = [row for row in rows if row[2]]
        mean_p, freq, count = [x[3] for x in rows], [x[4] for x in rows], [x[2] for x in rows]
        ax.plot(mean_p, freq, "o-", label=name, lw=1.5)
        hist.bar([x[0] + (n + 0.5) * width for x in rows], count, width=width, label=name)
    ax.set_ylabel(f"observed frequency of {outcome}")
    ax.set_xlim(0, 1)
    ax.set_ylim(-0.02, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    ax.set_title(f"Reliability on the {what}\n" + "\n".join(textwrap.wrap(subtitle, 70)), fontsize=10)
    ax._radarcl_shared_x = True                         # the x label sits under the panel below
    hist.set_yscale("log")
    hist.set_xlabel(f"predicted p (bin: mean p of its {what})")
    hist.set_ylabel(f"{what} per bin")
    hist.grid(alpha=0.3)
    fig.tight_layout()
    return fig
