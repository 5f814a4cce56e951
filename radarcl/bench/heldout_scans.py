"""`radarcl bench heldout-scans`: real data without lidar. A map of some Navtech scans predicts
the CFAR detections of the scans it did not see.

The Oxford sequence (``navtech_map.load``: polar scans with ground-truth odometry) is split by
interleaving: the even scans make the map, the odd ones are held out (they see the same street a
quarter of a second later). For every held-out range bin inside the interpreter's range window,
its CFAR detection by the sensor profile's own detector (the same outcomes for every map
compared) is the outcome and the map's log-odds at
the bin's world position (the azimuth's own pose, as the map was fused) the prediction:

- ``auc``: ROC area of the log-odds at detected against not-detected bins (ties one half, an
  unknown voxel 0);
- ``log_likelihood``: mean log p(outcome) per bin [nat] with p = sigmoid(L) clipped to
  [1e-4, 1 - 1e-4]; a map that knows nothing scores log(1/2) = -0.693;
- ``coverage``: the share of held-out bins whose voxel the map holds any evidence for.

The baselines, from the same run and the same scans: the raw-intensity map
(``baseline.raw_evidence`` of each bin's power, fused with the same beams and poses); no map
(log-odds 0 everywhere); and the held-out detection rate as a constant (an oracle of one number
that uses no map: it sets the log-likelihood a calibrated map must beat, AUC 0.5).
"""

import numpy as np

from radarcl import logodds

P_CLIP = 1e-4


def _raw_map(runtime, config, spec, scans, per_beam):
    from radarcl.evaluation.baseline import raw_evidence
    from radarcl.grid import EvidenceGrid
    from radarcl.pipeline import Mapping

    mapping = Mapping.from_config(runtime, config=config, grid=EvidenceGrid(runtime, spec), per_beam_poses=True)
    fusion = mapping.fusion
    for scan, poses in zip(scans, per_beam):
        evidence = raw_evidence(scan.power().reshape(fusion.evidence_shape))
        evidence[~np.asarray(scan.valid).reshape(-1)] = 0
        fusion.upload(evidence).wait()
        fusion.enqueue(plan=fusion.plan(poses))
    runtime.queue.finish()
    return mapping.grid.snapshot()


def predictions(runtime, config, spec, grid_int, scans, per_beam):
    """(log-odds [nat] at each held-out bin, its CFAR detection) over the range window.
    ``config`` is the outcome detector's configuration (the sensor profile's own, the same for
    every map compared: the outcomes must not change with the map's CFAR). ``grid_int`` may
    carry trailing axes (several maps of one grid stacked): the log-odds then have them too, and
    the scans are detected once for all."""
    from radarcl.pipeline import Mapping

    mapping = Mapping.from_config(runtime, config=config, per_beam_poses=True)
    i = config.interpret_config()
    ranges = np.arange(scans[0].n_bins) * config.sensor.bin_spacing_m()
    window = (ranges >= i.range_min_m) & (ranges <= i.range_max_m)
    axes = config.sensor.lattice().beam_rotations()[:, :, 0]              # (n_az, 3) in the head frame
    L, y = [], []
    for scan, poses in zip(scans, per_beam):
        detected = mapping.detection.cfar(scan.power()).mask.reshape(len(axes), -1)
        valid = np.asarray(scan.valid).reshape(-1)
        dirs = np.einsum("aij,aj->ai", poses[:, :3, :3], axes)
        points = poses[:, None, :3, 3] + ranges[None, window, None] * dirs[:, None, :]
        idx = spec.world_to_index(points.reshape(-1, 3))
        inside = spec.contains(idx)
        values = np.zeros((len(idx),) + np.shape(grid_int)[3:], np.float64)
        values[inside] = grid_int[idx[inside, 2], idx[inside, 1], idx[inside, 0]] / logodds.SCALE
        keep = np.repeat(valid, window.sum())
        L.append(values[keep])
        y.append(detected[:, window].reshape(-1)[keep])
    return np.concatenate(L), np.concatenate(y).astype(bool)


def score(L, y):
    """``auc``, ``log_likelihood`` [nat per bin] and ``coverage`` of predictions ``L`` of ``y``."""
    from radarcl.evaluation.metrics import roc_auc

    p = np.clip(1.0 / (1.0 + np.exp(-L)), P_CLIP, 1 - P_CLIP)
    return dict(auc=roc_auc(L, y), log_likelihood=float(np.mean(np.where(y, np.log(p), np.log1p(-p)))),
                coverage=float(np.mean(L != 0)), bins=int(len(y)), detected=int(y.sum()))


def run(runtime, config, data_dir, report=None):
    """Build both maps from the even scans and score them on the odd ones; returns the --json dict."""
    from radarcl.io import polar_png
    from radarcl.jobs import navtech_map

    say = report or (lambda _: None)
    scans, poses, _, _ = navtech_map.load(config, data_dir)
    if config.sensor.n_bins() is None:
        config = config.for_sensor(config.sensor.with_bins(scans[0].n_bins))
    per_beam = polar_png.beam_poses(scans, poses, config.sensor.n_azimuth)
    spec = navtech_map.grid_for(per_beam, config["interpret.range_max_m"], config["grid.voxel_m"])
    train, test = list(range(0, len(scans), 2)), list(range(1, len(scans), 2))
    say(f"{len(scans)} scans: map of scans {train}, held out {test}")
    maps = {"map": navtech_map.build_map(runtime, config, spec, [scans[k] for k in train], per_beam[train]).snapshot(),
            "baseline: raw_intensity": _raw_map(runtime, config, spec, [scans[k] for k in train], per_beam[train])}
    from radarcl import mapconfig

    # the outcomes: the sensor profile's own detector, whatever the compared map's CFAR is
    outcome = mapconfig.resolve(config.sensor, program={"grid.voxel_m": config["grid.voxel_m"]})
    stacked, y = predictions(runtime, outcome, spec, np.stack(list(maps.values()), axis=-1),
                             [scans[k] for k in test], per_beam[test])
    out = {name: score(stacked[:, m], y) for m, name in enumerate(maps)}
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
             f"  {'predictor':26s} {'AUC':>6s} {'log-lik [nat/bin]':>18s} {'coverage':>9s} {'bins':>10s} {'detected':>9s}"]
    for name, s in r["results"].items():
        lines.append(f"  {name:26s} {s['auc']:6.3f} {s['log_likelihood']:18.4f} {s['coverage']:9.3f} {s['bins']:10d} "
                     f"{s['detected']:9d}")
    return lines


def add_arguments(parser):
    """`radarcl bench heldout-scans` options."""
    from radarcl.cli import add_config

    parser.add_argument("data", nargs="?", default=None, help="a directory of radar/*.png and gt/radar_odometry.csv "
                                                               "(default: the shared Oxford sequence)")
    add_config(parser, "navtech-cts350x")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    from radarcl.commands import default_data, resolve_config
    from radarcl.errors import ConfigError

    data = args.data or default_data("navtech_oxford")
    if not __import__("pathlib").Path(data).is_dir():
        raise ConfigError(f"no data directory {data}; give DATA (radar/*.png and gt/radar_odometry.csv)")
    result = run(runtime(), resolve_config(args), data, report=say)
    return result, format_table(result)
