"""`radarcl calibrate-scans`: the interpreter's constants fitted on a real radar's own scans.

Real data comes without a voxel truth. What it does have is more scans: a map of some scans
should predict what the radar detects in the scans it did not see (`radarcl bench
heldout-scans`). That prediction is a logistic model too, linear in the interpreter's constants
(``evaluation.calibration``), so the same fit applies with the held-out detections as the
outcome:

1. The sequence is split in time. The first part fits: a map of its even scans (each feature
   fused as its own channel, with the sensor's per-beam poses) predicts the CFAR detections of
   its odd scans, at each held-out bin's world position. The last part is for reporting only.
2. The outcome detector is the sensor profile's own, the same for every candidate (the outcome
   must not move with the map's CFAR). Candidates (the map's CFAR kind and P_fa, the surface
   test) are compared by the fit's log-likelihood per bin: millions of bins against four
   constants, so the in-sample likelihood hardly flatters.
3. Standard errors: Wald, and a jackknife over the predicted scans (bins of one scan are not
   independent).
4. On the last part: the profile's constants and the calibrated ones as real maps (the fusion
   kernel, not the linear model), beside the raw-intensity map, no map and the detection rate as
   a constant, all on the same held-out bins: AUC, log-likelihood and the reliability diagram.
"""

import numpy as np

from radarcl import logodds, models
from radarcl.config import mapconfig
from radarcl.errors import ConfigError
from radarcl.evaluation import calibration as cal
from radarcl.evaluation import heldout
from radarcl.evaluation.metrics import calibration
from radarcl.grid import EvidenceGrid
from radarcl.io import scan_poses
from radarcl.jobs import navtech_map
from radarcl.jobs.calibrate import with_fit
from radarcl.pipeline import Mapping, evidence_config
from radarcl.report import figures
from radarcl.stages.fusion import Fusion

CFAR_CANDIDATES = (("ca", 1e-3), ("ca", 1e-2), ("os", 1e-2))
SURFACE_CANDIDATES_DB = (10.0, 15.0, 20.0)


def scan_features(runtime, config, spec, scans, per_beam):
    """(nz, ny, nx, 4) float64: the features of ``scans`` (``calibration.bin_features`` with
    ``config``'s CFAR and interpreter) each fused as its own channel with per-beam poses.
    Beams a scan marks invalid give nothing."""
    mapping = Mapping.from_config(runtime, config=config, grid=EvidenceGrid(runtime, spec), per_beam_poses=True)
    f = mapping.fusion
    icfg = config.interpret_config()
    channels = [Fusion(runtime, EvidenceGrid(runtime, spec), f.lattice, f.model, f.n_bins, f.bin_spacing_m, f.first_bin,
                       f.last_bin, per_beam_poses=True) for _ in cal.CHANNELS]
    for scan, poses in zip(scans, per_beam):
        power = scan.power().reshape(f.evidence_shape)
        det = mapping.detection.cfar(power)
        feats = cal.bin_features(power, det.noise, det.mask, icfg, f.bin_spacing_m)
        feats[~np.asarray(scan.valid).reshape(-1)] = 0.0
        for c, fusion in enumerate(channels):
            fusion.upload(np.rint(feats[..., c] * logodds.SCALE).astype(np.int32)).wait()
            fusion.enqueue(plan=fusion.plan(poses))
    runtime.queue.finish()
    return np.stack([c.grid.snapshot() for c in channels], axis=-1)


def design(runtime, config, outcome, spec, scans, per_beam, map_idx, test_idx, model):
    """(X, y, scan of each row): the fused features of the ``map_idx`` scans at every held-out
    bin of the ``test_idx`` scans, and each bin's detection by ``outcome``."""

    grids = scan_features(runtime, config, spec, [scans[k] for k in map_idx], per_beam[map_idx])
    X, y, which = [], [], []
    for k in test_idx:                     # every channel at once: each scan detected once
        values, detected = heldout.predictions(runtime, outcome, spec, grids, [scans[k]], per_beam[[k]])
        X.append(values)
        y.append(detected)
        which.append(np.full(len(values), k))
    X, y = np.concatenate(X), np.concatenate(y)
    return cal.merged(X, model).astype(np.float32), y, np.concatenate(which)


def run(runtime, config, data_dir, model="occlusion", report=None):
    """Calibrate ``config`` (a ``Resolved`` for a polar-scan sensor) on ``data_dir``; returns
    (the calibrated ``Resolved``, the result dict)."""
    say = report or (lambda _: None)
    config = evidence_config(config)       # this fits eq. 12's constants: "profile constants" are eq. 12's
    scans, poses, _, _ = navtech_map.load(config, data_dir)
    if len(scans) < 8:
        raise ConfigError(f"calibrating on scans needs at least 8 (4 to fit, 4 to report on), found {len(scans)}")
    if config.sensor.n_bins() is None:
        config = config.for_sensor(config.sensor.with_bins(scans[0].n_bins))
    per_beam = scan_poses.beam_poses(scans, poses, config.sensor.n_azimuth)
    spec = navtech_map.grid_for(per_beam, config["interpret.range_max_m"], config["grid.voxel_m"])
    n_fit = 2 * ((len(scans) + 1) // 4)           # an even count, about half: 6 of 11
    fit_part, report_part = list(range(n_fit)), list(range(n_fit, len(scans)))
    fit_map, fit_test = fit_part[0::2], fit_part[1::2]
    rep_map, rep_test = report_part[0::2], report_part[1::2]
    outcome = mapconfig.resolve(config.sensor, program={"grid.voxel_m": config["grid.voxel_m"]})
    say(f"{len(scans)} scans: fit on {fit_part} (map {fit_map} predicts {fit_test}); report on {report_part} "
        f"(map {rep_map} predicts {rep_test})")
    surfaces = SURFACE_CANDIDATES_DB if models.get(model).occludes else (config["interpret.surface_db"],)
    rows, best = [], None
    for kind, pfa in CFAR_CANDIDATES:
        for surface in surfaces:
            cfg = config.replaced(cfar__kind=kind, cfar__pfa=pfa, interpret__model=model, interpret__surface_db=surface)
            X, y, which = design(runtime, cfg, outcome, spec, scans, per_beam, fit_map, fit_test, model)
            f = cal.fit(X, y, model)
            rows.append(dict(candidate=cfg.label(config), fit=f.values, held=f.held, log_likelihood=f.log_likelihood))
            say(f"  {rows[-1]['candidate']}: log-likelihood {f.log_likelihood:.5f} nat/bin")
            if best is None or f.log_likelihood > best[0].log_likelihood:
                best = (f, cfg, X, y, which)
    final, cfg, X, y, which = best
    jack = [list(cal.fit(X[which != k], y[which != k], model).values.values()) for k in fit_test]
    calibrated = with_fit(cfg, final.values)
    constants = cal.with_intervals(final, jack)

    say(f"reporting on scans {report_part} ...")
    test_scans = [scans[k] for k in rep_test]
    results, reliability = {}, {}
    maps = {"profile constants": navtech_map.build_map(runtime, config, spec, [scans[k] for k in rep_map],
                                                       per_beam[rep_map]).snapshot(),
            "calibrated": navtech_map.build_map(runtime, calibrated, spec, [scans[k] for k in rep_map],
                                                per_beam[rep_map]).snapshot(),
            "baseline: raw_intensity": heldout.raw_map(runtime, config, spec, [scans[k] for k in rep_map], per_beam[rep_map])}
    stacked, yt = heldout.predictions(runtime, outcome, spec, np.stack(list(maps.values()), axis=-1), test_scans,
                                 per_beam[rep_test])
    for m, name in enumerate(maps):
        L = stacked[:, m]
        results[name] = heldout.score(L, yt)
        results[name]["ece"], reliability[name] = calibration(1.0 / (1.0 + np.exp(-L)), yt)
    results["baseline: no map"] = dict(heldout.score(np.zeros(len(yt)), yt), ece=calibration(np.full(len(yt), 0.5), yt)[0])
    rate = float(y.mean())                  # the fit part's detection rate: no peeking at the report part
    const = np.full(len(yt), np.log(rate / (1 - rate)))
    results["baseline: detection rate"] = dict(heldout.score(const, yt), ece=calibration(1 / (1 + np.exp(-const)), yt)[0])
    result = dict(benchmark="calibrate-scans", sensor=config.sensor.name, model=model, scans=len(scans),
                  fit_scans=fit_part, report_scans=report_part, voxel_m=config["grid.voxel_m"],
                  outcome_detector=outcome.label(), candidates=rows, chosen=cfg.label(config), constants=constants,
                  held=final.held, bins=final.n, log_likelihood=final.log_likelihood, results=results,
                  reliability=reliability, config=calibrated.as_dict())
    return calibrated, result


def format_lines(r):
    """What `radarcl calibrate-scans` prints."""
    lines = [f"{r['sensor']}, {r['model']} interpreter, {r['voxel_m']} m: fitted on scans {r['fit_scans']} "
             f"({r['bins']:,} held-out bins), reported on scans {r['report_scans']}; outcomes: {r['outcome_detector']}"]
    lines += cal.candidate_lines(r["candidates"], r["chosen"], "candidate (map CFAR, surface)                               "
                                 "fit log-lik [nat/bin]", "log_likelihood")
    lines += cal.constant_lines(r["constants"], r["held"], "predicted scans")
    lines.append(f"  on the report scans {r['report_scans']} (the same held-out bins for every row):")
    lines.append(f"  {'predictor':26s} {'AUC':>6s} {'log-lik [nat/bin]':>18s} {'ECE':>6s} {'coverage':>9s}")
    for name, s in r["results"].items():
        lines.append(f"  {name:26s} {s['auc']:6.3f} {s['log_likelihood']:18.4f} {s['ece']:6.3f} {s['coverage']:9.3f}")
    return lines


def reliability_figure(r):
    """Reliability of the held-out detections on the report scans, before and after."""
    return figures.reliability_figure(r["reliability"], f"{r['sensor']}: maps of scans predict the CFAR detections of "
                                                      f"held-out scans {r['report_scans']}; calibrated: {r['chosen']}",
                                    what="held-out bins", outcome="detected")
