"""`radarcl bench heldout-scans`: real data without lidar. A map of some Navtech scans predicts
the CFAR detections of the scans it did not see (``evaluation.heldout`` scores it).

The Oxford sequence (``navtech_map.load``: polar scans with ground-truth odometry) is split by
interleaving: the even scans make the map, the odd ones are held out (they see the same street a
quarter of a second later). The baselines, from the same run and the same scans: the
raw-intensity map (``heldout.raw_map``); no map (log-odds 0 everywhere); the held-out
detection rate as a constant (an oracle of one number that uses no map: it sets the
log-likelihood a calibrated map must beat, AUC 0.5); and, as a reference for what these
detections allow at all, the even scans' own detection frequency per voxel
(``heldout.frequency_map``: the outcome itself counted, no sensor model).
"""

from pathlib import Path

import numpy as np

from radarcl import logodds, sensor_model
from radarcl.commands.options import add_config, default_data, resolve_config
from radarcl.config import mapconfig
from radarcl.errors import ConfigError
from radarcl.evaluation.evaluate import read_units
from radarcl.evaluation.heldout import (detection_probability, frequency_map, predictions, raw_map, score,
                                         score_probability)
from radarcl.io import scan_poses
from radarcl.jobs import navtech_map
from radarcl.pipeline import evidence_config


def run(runtime, config, data_dir, report=None):
    """Build both maps from the even scans and score them on the odd ones; returns the --json dict."""
    say = report or (lambda _: None)
    scans, poses, _, _ = navtech_map.load(config, data_dir)
    if config.sensor.n_bins() is None:
        config = config.for_sensor(config.sensor.with_bins(scans[0].n_bins))
    per_beam = scan_poses.beam_poses(scans, poses, config.sensor.n_azimuth)
    spec = navtech_map.grid_for(per_beam, config["interpret.range_max_m"], config["grid.voxel_m"])
    train, test = list(range(0, len(scans), 2)), list(range(1, len(scans), 2))
    say(f"{len(scans)} scans: map of scans {train}, held out {test}")
    # the configuration's map, and beside it eq. 12's or the detection-statistics model's
    if config.evidence_model().knowledge:
        detstats, models = config, {"map": config, "eq. 12": evidence_config(config)}
    else:
        detstats = config.replaced(interpret__model="detstats")
        models = {"map": config, "detection statistics": detstats}
    maps, known = {}, {}
    for name, c in models.items():
        maps[name], known[name] = read_units(navtech_map.build_map(runtime, c, spec, [scans[k] for k in train],
                                                                   per_beam[train]), c)
    maps["baseline: raw_intensity"] = raw_map(runtime, config, spec, [scans[k] for k in train], per_beam[train])
    # the outcomes: the sensor profile's own detector, whatever the compared map's CFAR is
    outcome = mapconfig.resolve(config.sensor, program={"grid.voxel_m": config["grid.voxel_m"]})
    maps["reference: detection frequency"] = logodds.to_fixed(frequency_map(
        runtime, outcome, spec, [scans[k] for k in train], per_beam[train]))
    knowing = [name for name, k in known.items() if k is not None]
    columns = list(maps.values()) + [known[name].astype(np.int32) * logodds.SCALE for name in knowing]
    stacked, y, ranges = predictions(runtime, outcome, spec, np.stack(columns, axis=-1),
                                     [scans[k] for k in test], per_beam[test], with_ranges=True)
    out = {name: score(stacked[:, m], y) for m, name in enumerate(maps)}
    for i, name in enumerate(knowing):            # a map with knowledge covers the bins whose voxel it knows
        out[name]["coverage"] = float(np.mean(stacked[:, len(maps) + i] > 0))
    column = list(maps).index(next(n for n, c in models.items() if c is detstats))   # the detection-statistics map
    # the model's own prediction of a detection from the map, and the same with no map (the
    # detection opportunity's fall with range alone, the controls it must beat): at p 1/2
    # everywhere, and at the reading's prior everywhere
    prior = float(sensor_model.read_log_odds(0, 0, 0, detstats.model_params().reading))
    out["detection statistics, predictive"] = score_probability(
        detection_probability(detstats, stacked[:, column], ranges), y)
    out["control: P_d by range, p 1/2"] = score_probability(detection_probability(detstats, np.zeros(len(y)), ranges), y)
    out["control: P_d by range, the prior"] = score_probability(
        detection_probability(detstats, np.full(len(y), prior), ranges), y)
    out["baseline: no map"] = score(np.zeros(len(y)), y)
    # no radar data beyond one number: the held-out detection rate itself, as a constant log-odds
    rate = float(y.mean())
    out["baseline: detection rate"] = score(np.full(len(y), np.log(rate / (1 - rate))), y)
    return dict(benchmark="heldout-scans", device=runtime.name, sensor=config.sensor.name, scans=len(scans),
                train=train, held_out=test, voxel_m=config["grid.voxel_m"], config=config.label(),
                outcome_detector=outcome.label(), results=out)


def format_table(r):
    lines = [f"{r['sensor']}: map of scans {r['train']} predicts the CFAR detections of scans {r['held_out']} "
             f"({r['voxel_m']} m; map: {r['config']}; outcomes: {r['outcome_detector']})",
             f"  {'predictor':34s} {'AUC':>6s} {'log-lik [nat/bin]':>18s} {'coverage':>9s} {'bins':>10s} {'detected':>9s}"]
    for name, s in r["results"].items():
        lines.append(f"  {name:34s} {s['auc']:6.3f} {s['log_likelihood']:18.4f} {s['coverage']:9.3f} {s['bins']:10d} "
                     f"{s['detected']:9d}")
    return lines


def add_arguments(parser):
    """`radarcl bench heldout-scans` options."""
    parser.add_argument("data", nargs="?", default=None, help="a directory of radar/*.png and gt/radar_odometry.csv "
                                                               "(default: the shared Oxford sequence)")
    add_config(parser, "navtech-cts350x")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    data = args.data or default_data("navtech_oxford")
    if not Path(data).is_dir():
        raise ConfigError(f"no data directory {data}; give DATA (radar/*.png and gt/radar_odometry.csv)")
    result = run(runtime(), resolve_config(args), data, report=say)
    return result, format_table(result)
