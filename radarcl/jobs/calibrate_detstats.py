"""`radarcl calibrate --model detstats`: the detection-statistics model's physical parameters and
reading by maximum likelihood on the training scenes (``evaluation.detstats_fit``).

1. Scenes: the training seeds of the radar's generator (``scene.generator`` for the tilting stand,
   ``scene.streets`` for the spinning radar); the first two thirds fit, the last third validates.
   The held-out scenes are never seen here.
2. Truth per scene: ``evaluate.instrument`` with the tuned configuration as the reference (the
   same fixed voxel sets as `radarcl bench scenes`); the model gets each scene's mounting.
3. The physical parameters by the looks' likelihood at the fitting scenes' occupied voxels
   (``detstats_fit.looks``, ``fit_looks``), with the scene jackknife (each scene left out in turn,
   refitted) for standard errors and 95 % intervals.
4. The reading by the visible voxels' likelihood on maps of the fitted model (``fit_reading``),
   the best of those whose maps meet the ECE and false-free goals (``READING_GOALS``).
5. Reliability, ECE and the ranking scores on the validation scenes: the paper's constants, the
   model's defaults, the fitted model read without a prior (a voxel never observed reads 1/2, as
   the last release read it) and read with its fitted reading.
"""

import math

import numpy as np

from radarcl import logodds, sensor_model
from radarcl.config import mapconfig
from radarcl.config.presets import EQ12
from radarcl.errors import ConfigError
from radarcl.evaluation import calibration as cal
from radarcl.evaluation import detstats_fit as fit
from radarcl.evaluation.evaluate import for_scene, instrument, map_observations, radar_score
from radarcl.evaluation.tuning import TUNED
from radarcl.report import figures
from radarcl.scene import generator, streets
from radarcl.scene.observe import observe
from radarcl.scene.outdoor import PAPER_TILTS_DEG

SENSORS = {"paper": "paper", "spinning": "spinning-sim"}
STREET_TURNS = 8
SCORES = ("ece", "ece_known", "brier", "auc_detectable", "auc_obstacles", "false_free_obstacles", "shadow_unknown")


def simulate(runtime, radar, seed, voxel_m):
    """(described, Observations, Instrument) of a training scene of ``radar``."""
    reference = mapconfig.resolve(SENSORS[radar], program={"grid.voxel_m": voxel_m, **TUNED})
    if radar == "spinning":
        scene, described = streets.generate(seed)
        obs = streets.observe(scene, reference.sensor.radar, reference.sensor.lattice(), STREET_TURNS, seed=seed)
    else:
        scene, described = generator.generate(seed)
        obs = observe(scene, PAPER_TILTS_DEG, seed=seed)
    return described, obs, instrument(runtime, scene, obs, reference)


def run(runtime, voxel_m=0.4, seeds=None, report=None, radar="paper"):
    """Calibrate; returns (the calibrated ``Resolved``, the result dict)."""
    say = report or (lambda _: None)
    seeds = list(seeds or (streets.TRAIN_SEEDS if radar == "spinning" else generator.TRAIN_SEEDS))
    if len(seeds) < 3:
        raise ConfigError("calibration needs at least 3 training scenes (2 to fit, 1 to validate)")
    n_val = max(1, len(seeds) // 3)
    fit_seeds, val_seeds = seeds[:-n_val], seeds[-n_val:]
    base = mapconfig.resolve(SENSORS[radar], program={"grid.voxel_m": voxel_m, "interpret.model": "detstats"})
    scenes = []
    for seed in seeds:
        say(f"scene {seed}: simulating, truth ...")
        scenes.append((seed, *simulate(runtime, radar, seed, voxel_m)))
    fitting = [s for s in scenes if s[0] in fit_seeds]
    say("looks at the occupied voxels of the fitting scenes ...")
    per_looks = [fit.looks(runtime, obs, inst, for_scene(base, described)) for _, described, obs, inst in fitting]
    half = tuple(math.radians(base.sensor.get("beams", k)) / 2 for k in ("beamwidth_az_deg", "beamwidth_el_deg"))
    geometry = (*half, voxel_m)
    best, loglik = fit.fit_looks(per_looks, base, *geometry)
    say(f"  fitted {best}: {loglik:.5f} nat per look")
    jack = []
    for leave in range(len(per_looks)):
        values, _ = fit.fit_looks(per_looks[:leave] + per_looks[leave + 1:], base, *geometry)
        jack.append([values[k] for k in fit.LOOK_GRIDS])
    jack = np.asarray(jack)
    n = len(jack)
    se = np.sqrt((n - 1) / n * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0))
    fitted = base.replaced(**_kw(best))
    say("the reading, on maps of the fitted model ...")
    sums, grids = [], []
    for _, described, obs, inst in fitting:
        res = map_observations(runtime, obs, for_scene(fitted, described))
        sums.append(fit.visible_sums(res, inst.truth))
        grids.append((res.grid.snapshot(), res.grid.knowledge_snapshot(), res.grid.knowledge_snapshot("looks"), inst))
        del res

    def meets(reading):
        """The fitting scenes' maps read with ``reading`` meet ``READING_GOALS`` (means over scenes)."""
        rows = [radar_score(inst, sensor_model.read_log_odds(e, k, n, reading).astype(np.float32),
                            (k / logodds.KNOWLEDGE_SCALE).astype(np.float32)) for e, k, n, inst in grids]
        return all(_mean([r[key] for r in rows]) <= limit for key, limit in fit.READING_GOALS.items())

    chosen = fit.fit_reading(sums, meets)
    if chosen is None:
        raise ConfigError(f"no reading of {fit.READING_GRID} meets {fit.READING_GOALS} on scenes {fit_seeds}")
    reading, reading_loglik, _ = chosen
    calibrated = fitted.replaced(**_kw({f"sensor_model.{k}": v for k, v in reading.items()}))
    no_prior = fitted.replaced(sensor_model__prior_nats=0.0)
    say("validation scenes ...")
    validation = {}
    paper = mapconfig.resolve(SENSORS[radar], program={"grid.voxel_m": voxel_m, **EQ12})
    for name, config in (("paper constants", paper), ("detection statistics, defaults", base),
                         ("detection statistics, fitted, no prior", no_prior),
                         ("detection statistics, fitted, fitted reading", calibrated)):
        rows = []
        for seed, described, obs, inst in scenes:
            if seed in val_seeds:
                res = map_observations(runtime, obs, for_scene(config, described))
                rows.append(radar_score(inst, res.log_odds, res.knowledge))
        validation[name] = dict(rows=cal.pool_reliability([r["reliability"] for r in rows]),
                                **{k: _mean([r.get(k) for r in rows]) for k in SCORES})
    constants = {key: dict(value=best[key], jackknife_se=float(s), ci95=[best[key] - 1.96 * float(s),
                                                                          best[key] + 1.96 * float(s)],
                           leave_one_out=jack[:, i].tolist())
                 for i, (key, s) in enumerate(zip(fit.LOOK_GRIDS, se))}
    result = dict(model="detstats", radar=radar, voxel_m=voxel_m, fit_seeds=fit_seeds, validation_seeds=val_seeds,
                  constants=constants, look_log_likelihood=loglik, looks=int(sum(len(x["detected"]) for x in per_looks)),
                  reading=reading, reading_log_likelihood=reading_loglik, validation=validation,
                  config=calibrated.as_dict())
    return calibrated, result


def _mean(values):
    values = [v for v in values if v is not None and np.isfinite(v)]
    return float(np.mean(values)) if values else float("nan")


def _kw(values):
    return {k.replace(".", "__"): v for k, v in values.items()}


def format_lines(r):
    """What `radarcl calibrate --model detstats` prints."""
    lines = [f"detection-statistics model, {r['radar']} radar, {r['voxel_m']} m; fitted on scenes {r['fit_seeds']} "
             f"({r['looks']:,} looks at occupied voxels, {r['look_log_likelihood']:.5f} nat per look), validated on "
             f"{r['validation_seeds']}",
             "  physical parameters (value, scene-jackknife SE, 95 % interval, leave-one-scene-out fits):"]
    for key, c in r["constants"].items():
        lines.append(f"    {key:32s} {c['value']:8.3f}  {c['jackknife_se']:.3f}  [{c['ci95'][0]:.3f}, {c['ci95'][1]:.3f}]"
                     f"  {[round(v, 3) for v in c['leave_one_out']]}")
    lines.append("  reading: " + ", ".join(f"{k} {v:g}" for k, v in r["reading"].items())
                 + f" ({r['reading_log_likelihood']:.5f} nat per visible voxel)")
    lines.append(f"  validation scenes:{'':36s} AUCdet AUCobs ff-obs shd-unk  ECE   ECEknown Brier")
    for name, v in r["validation"].items():
        lines.append(f"    {name:50s} {v['auc_detectable']:.3f}  {v['auc_obstacles']:.3f}  {v['false_free_obstacles']:.3f}"
                     f"  {v['shadow_unknown']:.3f}  {v['ece']:.3f}  {v['ece_known']:.3f}  {v['brier']:.3f}")
    return lines


def reliability_figure(r):
    """Before / after reliability on the validation scenes."""
    return figures.reliability_figure({name: v["rows"] for name, v in r["validation"].items()},
                                      f"validation scenes {r['validation_seeds']}, {r['voxel_m']} m, {r['radar']} "
                                      "radar: the detection-statistics model before and after calibration")
