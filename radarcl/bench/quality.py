"""`radarcl bench quality`: map error against run time on the reference scene.

One recording of the paper's 3,840 observations (``tuning.EVALUATION_SEED``) is mapped with the
tuned configuration (``tuning.TUNED``) and with one setting changed at a time: zero padding
(n_fft 256 = none, 512 = x2, 1024 = x4), the beam model (``geometry.BEAM_MODELS``), the voxel
size (0.4, 0.2, 0.1 m) and the CFAR kind. For each run, measured in this process:
``ms_per_frame`` (the device pipeline, planning included), AUC, IoU, false-free rate, Brier, and
``max_dev_nats``: the largest |kernel - float64 oracle| over the voxels that ``ORACLE_BEAMS`` of
the middle frame reach, the oracle being ``radarcl.oracle`` end to end (range profile, CFAR, eq. 12,
``fusion_at_points``), voxels whose decisions lie within ``FUSION_DECISION_MARGIN`` of a boundary left
out. The baseline entry is the OctoMap-style map (``evaluation.baseline``) of the reference run's
detections, timed in numpy. Runs on the Pareto front (no other run both faster and better in
AUC) are marked; ``chart`` draws AUC against ms per frame.
"""

import numpy as np

from radarcl import logodds, oracle
from radarcl.evaluation.evaluate import baseline_map, map_observations, score
from radarcl.geometry import BEAM_MODELS
from radarcl.grid import EvidenceGrid
from radarcl.pipeline import Mapping
from radarcl.stages.fusion import Fusion

ORACLE_BEAMS = (0, 85, 170, 255)
DECISION_MARGIN = 1e-3           # as tests/tolerances.FUSION_DECISION_MARGIN
VOXELS = (0.4, 0.2, 0.1)
N_FFTS = (256, 512, 1024)
CFAR_KINDS = ("ca", "go", "so", "os")


def variants(reference_config, voxels=VOXELS):
    """(dimension, Resolved) for the reference and each one-setting change of it."""
    out = [("reference", reference_config)]
    for n in N_FFTS:
        out.append(("zero padding", reference_config.replaced(range_fft__n_fft=n)))
    for b in BEAM_MODELS:
        out.append(("beam model", reference_config.replaced(beam__model=b)))
    for v in voxels:
        out.append(("voxel", reference_config.replaced(grid__voxel_m=v)))
    for k in CFAR_KINDS:
        out.append(("cfar", reference_config.replaced(cfar__kind=k)))
    seen, unique = set(), []
    for dim, c in out:                   # the reference reappears in each dimension: run it once
        key = tuple(sorted(c.values.items()))
        if key not in seen:
            seen.add(key)
            unique.append((dim, c))
    return unique


def oracle_deviation(runtime, obs, config, beams=ORACLE_BEAMS):
    """Max |kernel map - float64 oracle map| [nat] of ``beams`` of the middle frame, the
    fraction of compared voxels that agree exactly, and how many were compared."""
    j = len(obs.samples) // 2
    mapping = Mapping.from_config(runtime, config=config)
    spec, lattice, model = mapping.grid.spec, mapping.fusion.lattice, mapping.fusion.model
    mapping.fuse(obs.samples[j], obs.poses[j])
    runtime.queue.finish()
    it, fusion = mapping.detection.interpreter, mapping.fusion
    evidence = it.arrays["evidence"].get(runtime.queue).reshape(lattice.n_beams, it.n_bins)
    only = np.zeros_like(evidence)
    only[list(beams)] = evidence[list(beams)]
    check = EvidenceGrid(runtime, spec)
    Fusion(runtime, check, lattice, model, it.n_bins, fusion.bin_spacing_m, fusion.first_bin, fusion.last_bin)(
        only, obs.poses[j])
    keys, data = check.bricks()
    index = spec.brick_voxels(keys[(data != 0).reshape(len(keys), -1).any(axis=1)])

    profiles = oracle.range_profile(obs.samples[j].astype(np.float64), config.n_fft, output="power")
    noise, _, mask = oracle.cfar(profiles, config.cfar_config())
    ev64 = oracle.interpret(profiles, noise, mask, config.interpret_config(), fusion.bin_spacing_m)[0]
    sums, _, ambiguous = oracle.fusion_at_points(spec.index_to_world(index), ev64.reshape(lattice.n_beams, -1), lattice,
                                                 model, obs.poses[j], fusion.bin_spacing_m, fusion.first_bin,
                                                 fusion.last_bin, margin=DECISION_MARGIN, beams=beams)
    got = check.snapshot()[index[:, 2], index[:, 1], index[:, 0]].astype(np.int64)
    err = np.abs(got - sums)[~ambiguous]
    if not err.size:
        return 0.0, 1.0, 0
    return float(err.max()) / logodds.SCALE, float((err == 0).mean()), int(err.size)


def pareto(runs):
    """Flags: run i is on the front when no run is at least as fast and as good, one strictly."""
    flags = []
    for r in runs:
        dominated = any(o["ms_per_frame"] <= r["ms_per_frame"] and o["auc"] >= r["auc"]
                        and (o["ms_per_frame"] < r["ms_per_frame"] or o["auc"] > r["auc"]) for o in runs)
        flags.append(not dominated)
    return flags


def run(runtime, obs, truth_for, reference_config, voxels=VOXELS, report=None):
    """Measure every variant; ``truth_for(voxel_m)`` gives the truth labels of that grid.
    Returns the --json dict."""
    say = report or (lambda _: None)
    runs, baseline = [], None
    for dim, config in variants(reference_config, voxels):
        say(f"{dim}: {config.label(reference_config)} ...")
        res = map_observations(runtime, obs, config)
        truth = truth_for(config["grid.voxel_m"])
        m = score(res.log_odds, res.observed, truth)
        dev, exact, compared = oracle_deviation(runtime, obs, config)
        label = ("reference: " + config.label()) if config is reference_config else config.label(reference_config)
        runs.append(dict(dimension=dim, label=label, config=config.as_dict(), ms_per_frame=res.ms_per_frame,
                         auc=m["auc"], iou=m["iou"], iou_tol1=m["iou_tol1"], false_free=m["false_free"],
                         brier=m["brier"], coverage=m["coverage"], max_dev_nats=dev, exact_fraction=exact,
                         oracle_voxels=compared, memory_mib=res.memory["sparse_bytes"] / 2 ** 20))
        if config == reference_config:
            log_odds, _, ms = baseline_map(obs, res.detections, config)
            b = score(log_odds, res.observed, truth)
            baseline = dict(label="CFAR points, OctoMap-style (numpy)", config=config.as_dict(), ms_per_frame=ms,
                            auc=b["auc"], iou=b["iou"], iou_tol1=b["iou_tol1"], false_free=b["false_free"],
                            brier=b["brier"], coverage=b["coverage"])
        del res
    for r, front in zip(runs, pareto(runs)):
        r["pareto"] = front
    return dict(benchmark="quality", device=runtime.name, frames=len(obs.samples),
                observations=int(np.prod(obs.samples.shape[:3])), seed=obs.seed, runs=runs, baseline=baseline)


def format_table(r):
    """Human-readable lines for a ``run`` result."""
    lines = [f"reference scene, {r['observations']} observations (seed {r['seed']}) on {r['device']}; "
             f"* = Pareto front (no run both faster and higher in AUC)",
             f"  {'dimension':13s} {'configuration':64s} {'ms/frame':>9s} {'AUC':>6s} {'IoU':>6s} {'IoU1':>6s} "
             f"{'f-free':>6s} {'Brier':>6s} {'dev[nat]':>8s}"]
    for x in r["runs"]:
        lines.append(f"{'*' if x['pareto'] else ' '} {x['dimension']:13s} {x['label'][:64]:64s} {x['ms_per_frame']:9.1f} "
                     f"{x['auc']:6.3f} {x['iou']:6.3f} {x['iou_tol1']:6.3f} {x['false_free']:6.3f} {x['brier']:6.3f} "
                     f"{x['max_dev_nats']:8.3f}")
    b = r["baseline"]
    if b:
        lines.append(f"  {'baseline':13s} {b['label'][:64]:64s} {b['ms_per_frame']:9.1f} {b['auc']:6.3f} "
                     f"{b['iou']:6.3f} {b['iou_tol1']:6.3f} {b['false_free']:6.3f} {b['brier']:6.3f}")
    return lines


def sweep_table(r):
    """The sweep as a report table (``jobs.report``): one row per run and the baseline."""
    from radarcl.jobs import report

    rows = [[k, x["dimension"], x["label"], x["ms_per_frame"], x["auc"], x["iou"], x["false_free"],
             "yes" if x["pareto"] else ""] for k, x in enumerate(r["runs"], 1)]
    b = r.get("baseline")
    if b:
        rows.append(["", "baseline", b["label"], b["ms_per_frame"], b["auc"], b["iou"], b["false_free"], ""])
    return report.Table(["run", "changed", "configuration", "ms/frame", "AUC", "IoU", "false-free", "Pareto"], rows)


def write_report(r, chart_path, page):
    """``bench quality``'s page: the device, the sweep table and the chart."""
    from radarcl.jobs import report

    report.write(page, "radarcl bench quality: error against run time", [
        ("Run", [report.Pairs({"device": r["device"], "observations": r["observations"], "seed": r["seed"],
                               "frames": r["frames"]})]),
        ("Runs", [sweep_table(r), report.Text("ms/frame: the whole device pipeline per frame; AUC, IoU and "
                                              "false-free over the observed voxels of the reference scene.")]),
        ("Chart", [report.Figure(chart_path, "AUC against ms per frame; the Pareto front dashed")])],
        "Each run changes one setting of the reference configuration.")


def chart(r, path):
    """AUC against ms per frame (``jobs.plots.quality_figure``) written to ``path``."""
    from radarcl.jobs import plots

    plots.save(plots.quality_figure(r), path)


def add_arguments(parser):
    """`radarcl bench quality` options."""
    from radarcl.cli import add_output, positive_float

    parser.add_argument("--voxel", type=positive_float, default=0.2,
                        help="voxel of the reference run [m] (default: %(default)s)")
    parser.add_argument("--voxels", type=positive_float, nargs="+", default=list(VOXELS),
                        help="voxel sizes swept [m] (default: 0.4 0.2 0.1)")
    parser.add_argument("--paper", action="store_true", help="sweep around the paper's constants, not the tuned")
    parser.add_argument("--seed", type=int, default=None, help="simulation seed (default: the evaluation seed, 0)")
    parser.add_argument("--replay", default=None, help="a recording of the reference scene instead of simulating")
    add_output(parser, "--chart", "quality.png", "PNG chart to write")
    parser.add_argument("--report", default=None, metavar="FILE",
                        help="the HTML page (table and chart; default: the chart's name with .html)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    from radarcl import outputs
    from radarcl.evaluation.evaluate import paper_config
    from radarcl.evaluation.tuning import EVALUATION_SEED, TUNED
    from radarcl.io import recording
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import PAPER_TILTS_DEG, paper_grid, paper_scene

    chart_path = outputs.check(args.chart, args.force, inputs=[args.replay], what="chart")
    page = outputs.check(args.report or chart_path.with_suffix(".html"), args.force, inputs=[args.replay, chart_path],
                         what="report")
    scene = paper_scene()
    if args.replay:
        obs = recording.load_observations(args.replay)
    else:
        seed = EVALUATION_SEED if args.seed is None else args.seed
        say(f"simulating the reference scene, seed {seed} ...")
        obs = observe(scene, PAPER_TILTS_DEG, seed=seed)
    reference = paper_config(args.voxel, None if args.paper else TUNED)
    result = run(runtime(), obs, lambda v: scene.truth(paper_grid(v)), reference, voxels=tuple(args.voxels),
                 report=say)
    chart(result, chart_path)
    write_report(result, chart_path, page)
    say(f"wrote {chart_path} and {page}")
    return result, format_table(result)
