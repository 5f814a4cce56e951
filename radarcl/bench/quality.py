"""`radarcl bench quality`: map error against run time on the reference scene.

One recording of the paper's 3,840 observations (``tuning.EVALUATION_SEED``) is mapped with the
tuned configuration (``tuning.TUNED``) and with one setting changed at a time: zero padding
(n_fft 256 = none, 512 = x2, 1024 = x4), the beam model (``geometry.BEAM_MODELS``), the voxel
size (0.4, 0.2, 0.1 m) and the CFAR kind. Every run is scored on one fixed voxel set per voxel
size: what the reference configuration's beams reach at that size (``evaluate.instrument``),
with the visibility truth (``evaluation.visibility``) and ``metrics.radar_scores``; beside the
three baselines of ``evaluation.baseline`` (prior_only, raw_intensity, octomap) on the same set.
For each run, measured in this process: ``ms_per_frame`` (the device pipeline, planning
included), the scores, and ``max_dev_nats``: the largest |kernel - float64 oracle| over the
voxels that ``ORACLE_BEAMS`` of the middle frame reach, the oracle being ``radarcl.oracle`` end
to end (range profile, CFAR, eq. 12, ``fusion_at_points``), voxels whose decisions lie within
``FUSION_DECISION_MARGIN`` of a boundary left out. Runs on the Pareto front within their voxel
size (no other run both faster and higher in ``auc_detectable``) are marked; ``chart`` draws
that AUC against ms per frame, and a reliability diagram.
"""

import numpy as np

from radarcl import logodds, oracle
from radarcl.evaluation.evaluate import map_observations
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


SCORE_KEYS = ("auc_detectable", "iou_detectable", "auc_obstacles", "iou_obstacles", "auc_weak", "false_free",
              "shadow_unknown", "ece", "brier", "objects_found", "objects_total")
BASELINES = ("prior_only", "raw_intensity", "octomap")
TABLE_KEYS = ("auc_detectable", "iou_detectable", "auc_obstacles", "auc_weak", "false_free", "shadow_unknown", "ece",
              "brier")                  # the page's columns (iou_obstacles is in the JSON)


def pareto(runs, key="auc_detectable"):
    """Flags: run i is on the front when no run is at least as fast and as good, one strictly."""
    flags = []
    for r in runs:
        dominated = any(o["ms_per_frame"] <= r["ms_per_frame"] and o[key] >= r[key]
                        and (o["ms_per_frame"] < r["ms_per_frame"] or o[key] > r[key]) for o in runs)
        flags.append(not dominated)
    return flags


def run(runtime, scene, obs, reference_config, voxels=VOXELS, report=None):
    """Measure every variant of ``reference_config`` on ``obs`` (simulated from ``scene``), each
    scored on the fixed voxel set of its voxel size (``evaluate.instrument``: what the reference
    configuration reaches at that size), beside the three baselines. Returns the --json dict."""
    from radarcl.evaluation.evaluate import baselines, instrument, radar_score

    say = report or (lambda _: None)
    instruments, runs, by_voxel = {}, [], {}
    for dim, config in variants(reference_config, voxels):
        v = config["grid.voxel_m"]
        if v not in instruments:
            say(f"truth and baselines at {v} m ...")
            inst = instruments[v] = instrument(runtime, scene, obs, reference_config.replaced(grid__voxel_m=v))
            by_voxel[str(v)] = dict(voxel_set=inst.describe(), classes=inst.truth.counts(), hidden_objects=inst.hidden,
                                    baselines=baselines(runtime, inst, obs))
        inst = instruments[v]
        say(f"{dim}: {config.label(reference_config)} ...")
        res = map_observations(runtime, obs, config)
        m = radar_score(inst, res.log_odds)
        dev, exact, compared = oracle_deviation(runtime, obs, config)
        label = ("reference: " + config.label()) if config is reference_config else config.label(reference_config)
        runs.append(dict(dimension=dim, label=label, voxel_m=v, config=config.as_dict(), ms_per_frame=res.ms_per_frame,
                         **{k: m[k] for k in SCORE_KEYS}, objects=m["objects"], reliability=m["reliability"],
                         max_dev_nats=dev, exact_fraction=exact, oracle_voxels=compared,
                         memory_mib=res.memory["sparse_bytes"] / 2 ** 20))
        del res
    for v in {r["voxel_m"] for r in runs}:                 # the front within one voxel set
        same = [r for r in runs if r["voxel_m"] == v]
        for r, front in zip(same, pareto(same)):
            r["pareto"] = front
    ref_v = str(reference_config["grid.voxel_m"])
    return dict(benchmark="quality", device=runtime.name, frames=len(obs.samples),
                observations=int(np.prod(obs.samples.shape[:3])), seed=obs.seed, reference_voxel_m=float(ref_v),
                voxel_set=by_voxel[ref_v]["voxel_set"], runs=runs, baselines=by_voxel[ref_v]["baselines"],
                by_voxel=by_voxel)


def _cells(x):
    def f(k, fmt="6.3f"):
        v = x.get(k)
        return f"{v:{fmt}}" if isinstance(v, float) else f"{'-' if v is None else v!s:>6s}"
    return (f"{f('auc_detectable')} {f('iou_detectable')} {f('auc_obstacles')} {f('auc_weak')} {f('false_free')} "
            f"{f('shadow_unknown')} {f('ece')} {f('brier')} {x.get('objects_found', '-')!s:>3s}/{x.get('objects_total', '-')!s:<3s}")


def format_table(r):
    """Human-readable lines for a ``run`` result."""
    head = (f"{'AUCdet':>6s} {'IoUdet':>6s} {'AUCobs':>6s} {'AUCwk':>6s} {'f-free':>6s} {'shd-unk':>6s} {'ECE':>6s} "
            f"{'Brier':>6s} {'objects':>7s}")
    lines = [f"reference scene, {r['observations']} observations (seed {r['seed']}) on {r['device']}",
             "* = Pareto front within a voxel size (no run both faster and higher in AUC detectable)"]
    for v, b in r["by_voxel"].items():
        lines += [f"{b['voxel_set']}", f"  {'':13s} {'configuration':52s} {'ms/frame':>9s} {head} {'dev[nat]':>8s}"]
        for x in (x for x in r["runs"] if str(x["voxel_m"]) == v):
            lines.append(f"{'*' if x['pareto'] else ' '} {x['dimension']:13s} {x['label'][:52]:52s} "
                         f"{x['ms_per_frame']:9.1f} {_cells(x)} {x['max_dev_nats']:8.3f}")
        for name in BASELINES:
            x = b["baselines"][name]
            if "error" in x:
                lines.append(f"  {'baseline':13s} {name:52s} {x['error']}")
            else:
                lines.append(f"  {'baseline':13s} {name:52s} {x['ms_per_frame']:9.1f} {_cells(x)}")
    return lines


def sweep_table(r):
    """The sweep as a report table (``jobs.report``): one row per run and per baseline."""
    from radarcl.jobs import report

    rows = []
    for k, x in enumerate(r["runs"], 1):
        rows.append([k, x["voxel_m"], x["dimension"], x["label"], x["ms_per_frame"]] + [x[key] for key in TABLE_KEYS]
                    + [f"{x['objects_found']}/{x['objects_total']}", "yes" if x["pareto"] else ""])
    for v, b in r["by_voxel"].items():
        for name in BASELINES:
            x = b["baselines"][name]
            if "error" not in x:
                rows.append(["", float(v), "baseline", name, x["ms_per_frame"]] + [x[key] for key in TABLE_KEYS]
                            + [f"{x['objects_found']}/{x['objects_total']}", ""])
    return report.Table(["run", "voxel [m]", "changed", "configuration", "ms/frame", "AUC det", "IoU det", "AUC obst",
                         "AUC weak", "false-free", "shadow unknown", "ECE", "Brier", "objects", "Pareto"], rows)


def write_report(r, chart_path, page, reliability_path=None):
    """``bench quality``'s page: the device, the voxel sets, the sweep table and the charts."""
    from radarcl.jobs import report

    figures = [report.Figure(chart_path, "AUC (detectable vs free-visible) against ms per frame; the Pareto front "
                                         "dashed; the baselines as large markers")]
    if reliability_path:
        figures.append(report.Figure(reliability_path, "Reliability of the reference map and the baselines on the "
                                                       "visible voxels"))
    report.write(page, "radarcl bench quality: error against run time", [
        ("Run", [report.Pairs({"device": r["device"], "observations": r["observations"], "seed": r["seed"],
                               "frames": r["frames"]})]),
        ("Voxel sets", [report.Text(b["voxel_set"]) for b in r["by_voxel"].values()]),
        ("Runs", [sweep_table(r), report.Text(METRICS_TEXT)]),
        ("Charts", figures)],
        "Each run changes one setting of the reference configuration; each is scored on the fixed voxel set of "
        "its voxel size.")


METRICS_TEXT = ("AUC/IoU det: detectable surface voxels (noiseless echo >= 10 dB over the noise) vs free-visible air; "
                "obst: the same for every solid but the ground; weak: surface voxels below that; false-free: occupied "
                "voxels of any visibility with p < 0.35; shadow unknown: shadowed voxels within 0.2 nat of 0; ECE "
                "(10 bins) and Brier on the visible voxels; objects: found within one voxel of their visible surface.")


def chart(r, path, reliability_path=None):
    """AUC against ms per frame (``jobs.plots.quality_figure``) written to ``path``; with
    ``reliability_path`` the reliability diagram of the reference map and the baselines."""
    from radarcl.jobs import plots

    plots.save(plots.quality_figure(r), path)
    if reliability_path:
        ref = r["runs"][0]
        curves = {"map: " + ref["label"][:40]: ref["reliability"]}
        curves.update({name: b["reliability"] for name, b in r["baselines"].items() if "reliability" in b})
        plots.save(plots.reliability_figure(curves, r["voxel_set"]), reliability_path)


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
    add_output(parser, "--chart", "quality.png", "PNG chart to write (and its reliability diagram beside it, "
                                                   "*_reliability.png)")
    parser.add_argument("--report", default=None, metavar="FILE",
                        help="the HTML page (table and chart; default: the chart's name with .html)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    from radarcl import outputs
    from radarcl.evaluation.evaluate import paper_config
    from radarcl.evaluation.tuning import EVALUATION_SEED, TUNED
    from radarcl.io import recording
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import PAPER_TILTS_DEG, paper_scene

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
    result = run(runtime(), scene, obs, reference, voxels=tuple(args.voxels), report=say)
    reliability = outputs.check(chart_path.with_name(chart_path.stem + "_reliability.png"), args.force,
                                inputs=[args.replay], what="reliability chart")
    chart(result, chart_path, reliability)
    write_report(result, chart_path, page, reliability)
    say(f"wrote {chart_path}, {reliability} and {page}")
    return result, format_table(result)
