"""The main job: the paper's reference scene simulated, fused, scored, plotted.

1. Fig. 9: the paper's radar looking at point targets, without and with zero padding
   (``demo_fig9``).
2. The outdoor scene of §4.3 (``scene.outdoor``): 15 tilts x 64 azimuths x 4 stacked beams =
   3,840 observations simulated to raw samples (``scene.observe``, seed ``EVALUATION_SEED``), or
   replayed from a recording, and saved as ``reference_scene.npz`` (replay it with --replay).
3. The maps with radarcl's default, the detection-statistics model (``sensor_model``: the one
   written and shown unless ``shown`` names another), the paper's eq. 12 constants, the tuned
   ones (``tuning.TUNED``) and the calibrated occlusion-aware interpreter
   (``calibration.CALIBRATED``) at ``DEFAULT_VOXEL_M`` (0.2 m: a laptop's memory; --full: the
   paper's 0.1 m, --quick: 0.4 m), the OctoMap-style baseline on the same detections, and their metrics
   against the exact ground truth (``metrics``), with timings.
4. Plots: ``fig10_scene.png`` (two beams of the scene like the paper's Fig. 10),
   ``topdown.png`` (the map seen from above beside the truth), ``quality.png`` (error against
   run time, ``evaluation.quality`` at 0.4 m), ``view.png`` (the tuned map's isosurface rendered
   headless by the viewer, ``radarcl render``); the map itself as ``map.npz``
   (``maps.disk.load_grid``, ``radarcl view``); everything in ``summary.json``, and one page
   with the configuration, the tables and every figure in ``report.html``.
"""

import json
import time
from pathlib import Path

import numpy as np

from radarcl import oracle
from radarcl.config.presets import EQ12, EVALUATION_SEED, paper_config
from radarcl.config.stage_config import PAPER_RADAR
from radarcl.errors import ConfigError
from radarcl.evaluation import quality
from radarcl.evaluation.evaluate import baselines, instrument, map_observations, radar_score
from radarcl.evaluation.tuning import TUNED
from radarcl.geometry import BeamLattice
from radarcl.io import recording
from radarcl.jobs import demo_fig9
from radarcl.maps.disk import save_grid
from radarcl.maps.map import Map
from radarcl.pipeline import bin_model
from radarcl.report import figures
from radarcl.report import html as page
from radarcl.report.quality import METRICS_TEXT, chart, format_table, sweep_table
from radarcl.report.summary import map_summary
from radarcl.scene.observe import load_observations, observe
from radarcl.scene.outdoor import OCCUPIED, PAPER_TILTS_DEG, paper_scene

QUICK_VOXEL_M = 0.4                   # --quick (CI-sized)
DEFAULT_VOXEL_M = 0.2                 # the default: the same figures within a laptop's memory
FULL_VOXEL_M = 0.1                    # --full: the paper's voxel (eight times the voxels and the memory)
DEMO_TIMING_PASSES = 3                # bench quality's sweep, each run timed fewer times than the bench's
QUICK_TIMING_PASSES = 1               # --quick: each run of the sweep timed with its map alone
VIEW_CAMERA = "-160,30"               # behind and left of the stand, looking down the field
METRIC_KEYS = ("auc_detectable", "iou_detectable", "auc_obstacles", "auc_weak", "false_free", "shadow_unknown", "ece",
               "brier")
METRIC_NAMES = ("AUC detectable", "IoU detectable", "AUC obstacles", "AUC weak", "false-free", "shadow unknown",
                "ECE", "Brier")


def _metrics_line(name, m, ms):
    cells = " ".join(f"{m[k]:7.3f}" if m[k] is not None else f"{'-':>7s}" for k in METRIC_KEYS)
    return f"  {name:34s} {cells} {m['objects_found']:>3d}/{m['objects_total']:<3d} {ms:9.1f}"


SHOWN = "detection statistics"        # radarcl's default model: the map written, rendered and plotted


def run(runtime, out_dir, seed=EVALUATION_SEED, voxel_m=DEFAULT_VOXEL_M, replay=None, report=print, progress=None,
        shown=SHOWN):
    """Run the main job into ``out_dir`` with the maps at ``voxel_m`` [m] (``QUICK_VOXEL_M``,
    ``DEFAULT_VOXEL_M`` or ``FULL_VOXEL_M``); ``report`` gets lines, ``progress(done, total,
    what)`` counts simulated frames and fused observations. Returns the summary dict."""
    out = Path(out_dir)
    replayed = load_observations(replay) if replay else None     # a bad file stops here
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out} is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    tick = (lambda what: (lambda d, t: progress(d, t, what))) if progress else (lambda what: None)
    voxel = float(voxel_m)
    if not 0.05 <= voxel <= 1.0:
        raise ConfigError(f"the demo's voxel must lie in [0.05, 1] m, got {voxel_m!r}")
    summary = dict(device=runtime.name, voxel_m=voxel, quick=voxel >= QUICK_VOXEL_M)
    summary["fig9"] = demo_fig9.run(runtime, out, report=report)

    scene = paper_scene()
    start = time.perf_counter()
    if replay:
        obs = replayed
        report(f"replaying {replay}: {len(obs.samples)} frames")
    else:
        report(f"simulating the reference scene: {len(PAPER_TILTS_DEG)} tilts x 64 x 4 beams, seed {seed} ...")
        obs = observe(scene, PAPER_TILTS_DEG, seed=seed, progress=tick("frames simulated"))
        recording.save(out / "reference_scene.npz", obs)
    n_obs = int(np.prod(obs.samples.shape[:3]))
    summary.update(observations=n_obs, seed=obs.seed, simulate_s=time.perf_counter() - start,
                   clipped_samples=obs.n_clipped, recording=str(replay) if replay else "reference_scene.npz (simulated)")
    report(f"{n_obs} observations ({obs.rays_per_beam} rays per beam, {obs.n_clipped} clipped samples) in "
           f"{summary['simulate_s']:.1f} s")

    tuned = paper_config(voxel, TUNED)
    from radarcl.evaluation.calibration import CALIBRATED

    configs = {"detection statistics": paper_config(voxel), "paper constants": paper_config(voxel, EQ12),
               "tuned": tuned, "calibrated": paper_config(voxel, CALIBRATED)}
    if shown not in configs:
        raise ConfigError(f"the demo shows one of {', '.join(configs)}, not {shown!r}")
    report("truth: the line of sight and the noiseless echo of every voxel the tuned map's beams reach ...")
    inst = instrument(runtime, scene, obs, tuned, progress=tick("observations fused"))
    report(inst.describe())
    maps = {}
    for name, config in configs.items():
        report(f"fusing with the {name} ({config.label()}) ...")
        res = inst.reference_map if config is tuned else map_observations(runtime, obs, config,
                                                                         progress=tick("observations fused"))
        maps[name] = (config, res, radar_score(inst, res.log_odds, res.knowledge))
    config, res, _ = maps[shown]
    report(f"the map written, rendered and plotted is the {shown} one ({config.label()})")
    summary["shown"] = shown
    report("baselines on the same voxel set: prior_only, raw_intensity, octomap ...")
    base = baselines(runtime, inst, obs)
    report(f"  {'map':34s} " + " ".join(f"{k.replace('_', ' ')[:7]:>7s}" for k in METRIC_KEYS) + " objects  ms/frame")
    for name, (config_n, res_n, m) in maps.items():
        report(_metrics_line(name, m, res_n.ms_per_frame))
    for name, b in base.items():
        report(_metrics_line(f"baseline: {name}", b, b["ms_per_frame"]) if "error" not in b else f"  {name}: {b['error']}")
    summary["voxel_set"] = inst.describe()
    summary["maps"] = {name: dict(config=c.as_dict(), ms_per_frame=r.ms_per_frame, metrics=m,
                                  memory_mib=r.memory["sparse_bytes"] / 2 ** 20) for name, (c, r, m) in maps.items()}
    summary["baselines"] = base

    save_grid(res.grid, out / "map.npz", poses=obs.poses, reading=config)
    summary["view"] = _render_view(out, report)
    _plot_profiles(obs, config, out / "fig10_scene.png", shown)
    _plot_topdown(res.log_odds, inst.truth.labels, res.spec, out / "topdown.png")
    report("error against run time at 0.4 m (bench quality) ...")
    quick = summary["quick"]                    # a smoke run: one voxel, each run timed with its map alone
    reference = paper_config(QUICK_VOXEL_M, TUNED)
    q = quality.run(runtime, scene, obs, reference, voxels=(QUICK_VOXEL_M,) if quick else (2 * QUICK_VOXEL_M, QUICK_VOXEL_M),
                    default_config=paper_config(QUICK_VOXEL_M), passes=QUICK_TIMING_PASSES if quick else DEMO_TIMING_PASSES,
                    prepared=(inst, base) if reference.as_dict() == tuned.as_dict() else None)   # the truth made above
    chart(q, out / "quality.png", out / "reliability.png")
    for line in format_table(q):
        report(line)
    summary["quality"] = q
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    _write_report(out, summary, maps, base, q, Map.of_grid(res.grid, config))
    report(f"wrote {', '.join(p.name for p in sorted(out.iterdir()))} in {out}")
    return summary


def _write_report(out, summary, maps, base, q, shown_map):
    """report.html: what the map says and which map is best, then the run's configuration, its
    metrics, every figure and the viewer's render."""
    headers = ["map"] + list(METRIC_NAMES) + ["objects", "ms/frame"]
    rows = [[name] + [m[k] for k in METRIC_KEYS] + [f"{m['objects_found']}/{m['objects_total']}", r.ms_per_frame]
            for name, (_, r, m) in maps.items()]
    rows += [[f"baseline: {name}"] + [b[k] for k in METRIC_KEYS] + [f"{b['objects_found']}/{b['objects_total']}",
                                                                    b["ms_per_frame"]]
             for name, b in base.items() if "error" not in b]
    shown = summary["shown"]
    pictures = [("fig9.png", "Fig. 9: two point targets 1.0 m apart, without and with zero padding"),
               ("frame.png", "One frame of the paper's radar, range x azimuth, per stacked beam"),
               ("fig10_scene.png", "Two beams of the reference scene as in Fig. 10, with CFAR and eq. 12"),
               ("topdown.png", f"The {shown} map from above beside the ground truth"),
               ("quality.png", "Error against run time (bench quality at 0.4 m)"),
               ("reliability.png", "Reliability of the 0.4 m reference map and the baselines"),
               ("view.png", f"The {shown} map's isosurface at 1 nat, rendered by the viewer")]
    best = max(maps, key=lambda name: maps[name][2]["auc_detectable"])
    raw = base.get("raw_intensity", {})
    verdict = (f"Best on this scene by AUC detectable (detectable surfaces ranked above free air, on the fixed voxel "
               f"set): the {best} map, {maps[best][2]['auc_detectable']:.3f}"
               + (f" (raw intensity {raw['auc_detectable']:.3f})" if "auc_detectable" in raw else "")
               + f"; its ECE is {maps[best][2]['ece']:.3f}. The map written, drawn and summed up below is the {shown} "
               "one (radarcl demo --show chooses).")
    sections = [
        ("Summary", [page.Text(verdict)] + map_summary(shown_map, out / "map.npz", band_hint=(-0.5, 2.0))),
        ("Run", [page.Pairs({"device": summary["device"], "recording": summary["recording"],
                             "observations": summary["observations"], "seed": summary["seed"],
                             "voxel [m]": summary["voxel_m"],
                             "simulation [s]": round(summary["simulate_s"], 1)})]),
        ("Metrics on the fixed voxel set", [page.Text(summary["voxel_set"]), page.Table(headers, rows),
                                            page.Text(METRICS_TEXT)]),
        ("Error against run time", [sweep_table(q)]),
        ("Figures", [page.Figure(out / name, caption) for name, caption in pictures if (out / name).is_file()]),
        (f"Configuration of the {shown} map", [page.configuration(maps[shown][0])]),
    ]
    page.write(out / "report.html", "radarcl demo: the paper's reference scene", sections,
               f"Foessel-Bunting's sensor model on the reference scene (§4.3), {summary['observations']} observations.")


def _render_view(out, report):
    """The viewer's picture of the map (EGL, no display); without EGL the demo goes on and says why."""
    from radarcl.viewer.headless import render_map
    from radarcl.viewer.renderer import ViewerError

    try:
        return render_map(out / "map.npz", out / "view.png", "iso", camera=VIEW_CAMERA, size=(800, 500),
                          report=report)
    except ViewerError as exc:
        report(f"no view.png: {exc}")
        return dict(error=str(exc))


def _plot_profiles(obs, config, path, name, beams=((2, 32, 0), (14, 20, 3))):
    """Two beams of the recording like the paper's Fig. 10: a steep one on the grass and a
    near-horizontal one, each with its CFAR threshold and its evidence (float64 oracle): eq. 12's,
    or the detection-statistics model's for a voxel on the beam's axis (an upright target)."""
    spacing = config.bin_spacing_m
    interpret, cfar = config.interpret_config(), config.cfar_config()
    evidence_model, model = config.evidence_model(), bin_model(config, config["grid.voxel_m"])
    panels = []
    for frame, az, el in beams:
        prof = oracle.range_profile(obs.samples[frame, az, el].astype(np.float64), config.n_fft, output="power")
        noise, _, mask = oracle.cfar(prof[None], cfar)
        evidence = evidence_model.on_axis(evidence_model.oracle(prof[None], noise, mask, interpret, spacing, model))[0]
        elevation = obs.tilts_deg[frame] + PAPER_RADAR.elevation_step_deg * el
        azimuth = np.degrees(BeamLattice.from_radar(PAPER_RADAR).azimuths[az])
        panels.append((np.arange(len(prof)) * spacing, prof, cfar.alpha * noise[0], mask[0], evidence,
                       f"beam at {elevation:.1f} deg elevation, {azimuth:+.1f} deg azimuth"))
    label = evidence_model.axis_label
    figures.save(figures.beams_figure(panels, f"Two beams of the reference scene (as the paper's Fig. 10), {name}",
                                      label), path, dpi=100)


def _plot_topdown(log_odds, truth, spec, path):
    """Largest log-odds over z per (x, y) (Fig. 11 seen from above) beside the truth."""
    figures.save(figures.topdown_figure(log_odds, truth == OCCUPIED, spec, above_z_m=0.0), path, dpi=100)
