"""`radarcl bench quality`'s sweep (``evaluation.quality``) as people read it: the table, the
report page's table and text, the charts."""

from radarcl.evaluation.quality import BASELINES
from radarcl.report import figures, html

# the page's columns, as many as a laptop's window holds (the IoUs and the rest are in the JSON)
TABLE_KEYS = ("auc_detectable", "auc_obstacles", "auc_weak", "false_free", "shadow_unknown", "ece", "brier",
              "ece_occupied")


def _cells(x):
    def f(k, fmt="6.3f"):
        v = x.get(k)
        return f"{v:{fmt}}" if isinstance(v, float) else f"{'-' if v is None else v!s:>6s}"
    return (f"{f('auc_detectable')} {f('iou_detectable')} {f('auc_obstacles')} {f('auc_weak')} {f('false_free')} "
            f"{f('shadow_unknown')} {f('ece')} {f('brier')} {f('ece_occupied')} "
            f"{x.get('objects_found', '-')!s:>3s}/{x.get('objects_total', '-')!s:<3s}")


def format_table(r):
    """Human-readable lines for a ``run`` result."""
    head = (f"{'AUCdet':>6s} {'IoUdet':>6s} {'AUCobs':>6s} {'AUCwk':>6s} {'f-free':>6s} {'shd-unk':>6s} {'ECE':>6s} "
            f"{'Brier':>6s} {'ECEocc':>6s} {'objects':>7s}")
    lines = [f"reference scene, {r['observations']} observations (seed {r['seed']}) on {r['device']}",
             r["voxel_set"], "every run is scored on it; a run at another voxel size is read on its voxels",
             f"ms/frame: the median of {r.get('timing_passes', 1)} timings of each pipeline, the later ones "
             "interleaved over all; a reading of the default map shares its run time",
             "* / + = on the Pareto front: no run both faster and higher in AUC detectable (*), "
             "or lower in the occupied calls' ECE (+)",
             "passes: of the timing passes alone, how many put the run on each front it is on",
             f"   {'':22s} {'configuration':52s} {'voxel':>5s} {'ms/frame':>9s} {head} {'dev[nat]':>8s} passes"]
    for x in r["runs"]:
        lines.append(f"{_marks(x)} {x['dimension'][:22]:22s} {x['label'][:52]:52s} {x['voxel_m']:5.2f} "
                     f"{x['ms_per_frame']:9.1f} {_cells(x)} {x['max_dev_nats']:8.3f} {_held(x, r.get('timing_passes'))}")
    for name in BASELINES:
        x = r["baselines"][name]
        if "error" in x:
            lines.append(f"   {'baseline':22s} {name:52s} {x['error']}")
        else:
            lines.append(f"   {'baseline':22s} {name:52s} {r['reference_voxel_m']:5.2f} {x['ms_per_frame']:9.1f} "
                         f"{_cells(x)}")
    if "default_model_on_front" in r:
        lines.append(f"the default model's configurations on a Pareto front: {r['default_model_on_front']}")
    if "default_model_on_front_by_pass" in r:
        lines.append("the same from each timing pass alone: "
                     + ", ".join(str(n) for n in r["default_model_on_front_by_pass"]))
    return lines


def _marks(x):
    return ("*" if x["pareto"] else " ") + ("+" if x.get("pareto_ece") else " ")


def _held(x, passes):
    """"5/5, 3/5": of the timing passes alone, how many put the run on each front it is on (AUC, ECE)."""
    if not passes or "pareto_passes" not in x:
        return ""
    return ", ".join(f"{x[k]}/{passes}" for k, on in (("pareto_passes", x["pareto"]),
                                                     ("pareto_ece_passes", x["pareto_ece"])) if on)


def sweep_table(r):
    """The sweep as a report table (``report.html``): one row per run and per baseline."""
    rows = []
    for k, x in enumerate(r["runs"], 1):
        rows.append([k, x["voxel_m"], x["label"], x["ms_per_frame"]] + [x.get(key) for key in TABLE_KEYS]
                    + [f"{x['objects_found']}/{x['objects_total']}", _front_names(x, r.get("timing_passes"))])
    for name in BASELINES:
        x = r["baselines"][name]
        if "error" not in x:
            rows.append(["", r["reference_voxel_m"], f"baseline: {name}", x["ms_per_frame"]]
                        + [x.get(key) for key in TABLE_KEYS] + [f"{x['objects_found']}/{x['objects_total']}", ""])
    return html.Table(["run", "voxel [m]", "configuration (what differs from its model's reference)", "ms/frame",
                       "AUC det", "AUC obst", "AUC weak", "false-free", "shadow unknown", "ECE", "Brier",
                       "ECE occ.", "objects", "Pareto"], rows)


def _front_names(x, passes=None):
    names = ", ".join(name for name, on in (("AUC", x["pareto"]), ("ECE occ.", x.get("pareto_ece"))) if on)
    held = _held(x, passes)
    return f"{names} ({held} passes)" if held else names


def write_report(r, chart_path, page, reliability_path=None):
    """``bench quality``'s page: the device, the voxel sets, the sweep table and the charts."""
    figures = [html.Figure(chart_path, "AUC (detectable vs free-visible) and the occupied calls' ECE against ms per "
                                         "frame, eq. 12 and the default model; each Pareto front dashed; the "
                                         "baselines as large markers")]
    if reliability_path:
        figures.append(html.Figure(reliability_path, "Reliability of the reference map and the baselines on the "
                                                       "visible voxels"))
    html.write(page, "radarcl bench quality: error against run time", [
        ("Run", [html.Pairs({"device": r["device"], "observations": r["observations"], "seed": r["seed"],
                               "frames": r["frames"]})]),
        ("Voxel set", [html.Text(r["voxel_set"])]),
        ("Runs", [sweep_table(r), html.Text(METRICS_TEXT)]),
        ("Charts", figures)],
        "Each run changes a setting of its model's reference configuration (eq. 12's tuned one, or the default "
        "model's); all are scored on one fixed voxel set, the same for both models (a map of another voxel size "
        "read on its voxels).")


METRICS_TEXT = ("AUC/IoU det: detectable surface voxels (noiseless echo >= 10 dB over the noise) vs free-visible air; "
                "obst: the same for every solid but the ground; weak: surface voxels below that; false-free: occupied "
                "voxels of any visibility with p < 0.35; shadow unknown: shadowed voxels within 0.2 nat of 0; ECE "
                "(10 bins) and Brier on the visible voxels; ECE occupied: the same over the visible voxels the map knows "
                "and calls occupied (p >= 0.5); objects: found within one voxel of their visible surface. "
                "Knowledge channel off: the default map read without its unknown class; a look limit: the default "
                "map read with it (both at the default's run time). A coarser map is read at each voxel's centre, a "
                "finer one by its most occupied voxel inside.")


def chart(r, path, reliability_path=None):
    """AUC against ms per frame (``jobs.figures.quality_figure``) written to ``path``; with
    ``reliability_path`` the reliability diagram of the reference map and the baselines."""
    figures.save(figures.quality_figure(r), path)
    if reliability_path:
        ref = r["runs"][0]
        curves = {"map: " + ref["label"][:40]: ref["reliability"]}
        curves.update({name: b["reliability"] for name, b in r["baselines"].items() if "reliability" in b})
        figures.save(figures.reliability_figure(curves, r["voxel_set"]), reliability_path)
