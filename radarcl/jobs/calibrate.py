"""`radarcl calibrate`: the interpreter's constants fitted by maximum likelihood on the training
scenes (``evaluation.calibration``), the CFAR settings and the surface test chosen by the
log-likelihood on validation scenes, and a configuration file every command reads.

1. Scenes: ``generator.TRAIN_SEEDS``; the first four fit, the last two validate. The held-out
   scenes are never seen here.
2. Truth per scene: ``evaluate.instrument`` with the tuned configuration as the reference (the
   same fixed voxel sets as `radarcl bench scenes`).
3. Per candidate (CFAR kind and P_fa; for the occlusion model also surface_db): fused features,
   a fit on the fitting scenes, its mean log-likelihood per voxel on the validation scenes.
4. The best candidate is refitted on all six scenes; leaving one scene out at a time gives a
   jackknife standard error beside the Wald one (voxels of one scene are not independent: the
   Wald intervals are too narrow, the jackknife's say by how much).
5. Reliability on the validation scenes, before (the paper's constants) and after (the fit),
   from real maps (``map_observations``), not from the linear model.
"""

import numpy as np

from radarcl import models
from radarcl.config.presets import EQ12, paper_config
from radarcl.errors import ConfigError
from radarcl.evaluation import calibration as cal
from radarcl.evaluation.evaluate import instrument, map_observations, radar_score
from radarcl.evaluation.tuning import TUNED
from radarcl.report import figures
from radarcl.scene.generator import TRAIN_SEEDS, generate
from radarcl.scene.observe import observe
from radarcl.scene.outdoor import PAPER_TILTS_DEG

CFAR_CANDIDATES = (("ca", 1e-3), ("ca", 1e-2), ("so", 1e-2))
SURFACE_CANDIDATES_DB = (6.0, 10.0, 15.0, 20.0)


def candidates(base, model):
    """The configurations compared by validation likelihood (constants still the base's)."""
    surfaces = SURFACE_CANDIDATES_DB if models.get(model).occludes else (base["interpret.surface_db"],)
    return [base.replaced(cfar__kind=k, cfar__pfa=p, interpret__model=model, interpret__surface_db=s)
            for k, p in CFAR_CANDIDATES for s in surfaces]


def with_fit(config, values):
    """``config`` with the fitted constants (rounded to 1e-4 nat; E's kept within [-16, 0])."""
    changes = {}
    for key, v in values.items():
        v = round(float(v), 4)
        changes[key.replace(".", "__")] = max(0.0, min(v, 1e3)) if key.endswith("k_occ") else max(-16.0, min(v, 0.0))
    return config.replaced(**changes)


def run(runtime, model="occlusion", voxel_m=0.2, seeds=None, report=None, unknown_behind=False):
    """Calibrate; returns (the calibrated ``Resolved``, the result dict). ``unknown_behind``
    holds E_l at 0: behind the first surface the map stays unknown (the fit sees only visible
    voxels, so left free it sets E_l by the visible air behind surfaces, and the shadowed
    voxels behind them get it too)."""
    say = report or (lambda _: None)
    seeds = list(seeds or TRAIN_SEEDS)
    if len(seeds) < 3:
        raise ConfigError("calibration needs at least 3 training scenes (2 to fit, 1 to validate)")
    n_val = max(1, len(seeds) // 3)
    fit_seeds, val_seeds = seeds[:-n_val], seeds[-n_val:]
    base = paper_config(voxel_m, EQ12)
    zero = ("interpret.e_low",) if unknown_behind else ()
    scenes = []
    for seed in seeds:
        scene, described = generate(seed)
        say(f"scene {seed}: {described['terrain']} terrain, sensor at {described['sensor_height_m']} m: truth ...")
        obs = observe(scene, PAPER_TILTS_DEG, seed=seed)
        scenes.append((seed, obs, instrument(runtime, scene, obs, paper_config(voxel_m, TUNED))))
    rows, best_design = [], None            # only the best candidate's features are kept (memory)
    for cfg in candidates(base, model):
        label = cfg.label(base)
        say(f"candidate {label} ...")
        per = {seed: cal.design(cal.fused_features(runtime, obs, cfg, inst.spec), inst.truth, model)
               for seed, obs, inst in scenes}
        X = np.concatenate([per[s][0] for s in fit_seeds])
        y = np.concatenate([per[s][1] for s in fit_seeds])
        f = cal.fit(X, y, model, zero=zero)
        beta = np.array(list(f.values.values()))
        Xv = np.concatenate([per[s][0] for s in val_seeds])
        yv = np.concatenate([per[s][1] for s in val_seeds])
        rows.append(dict(candidate=label, config=cfg.as_dict(), fit=f.values, held=f.held,
                         fit_log_likelihood=f.log_likelihood, validation_log_likelihood=cal.log_likelihood(Xv, yv, beta)))
        if best_design is None or rows[-1]["validation_log_likelihood"] > best_design[0]:
            best_design = (rows[-1]["validation_log_likelihood"], label, cfg, per)
        del per, X, y, Xv, yv
        say(f"  validation log-likelihood {rows[-1]['validation_log_likelihood']:.5f} nat/voxel")
    _, chosen, cfg, per = best_design
    best = next(r for r in rows if r["candidate"] == chosen)
    X = np.concatenate([per[s][0] for s, _, _ in scenes])
    y = np.concatenate([per[s][1] for s, _, _ in scenes])
    final = cal.fit(X, y, model, zero=zero)
    jack = []
    for leave in per:
        Xj = np.concatenate([per[s][0] for s in per if s != leave])
        yj = np.concatenate([per[s][1] for s in per if s != leave])
        jack.append(list(cal.fit(Xj, yj, model, zero=zero).values.values()))
    calibrated = with_fit(cfg, final.values)
    say("reliability on the validation scenes, before and after ...")
    reliability = {}
    for name, c in (("paper constants", base), ("tuned", paper_config(voxel_m, TUNED)), ("calibrated", calibrated)):
        scores = [radar_score(inst, map_observations(runtime, obs, c).log_odds)
                  for seed, obs, inst in scenes if seed in val_seeds]
        reliability[name] = dict(rows=cal.pool_reliability([s["reliability"] for s in scores]),
                                 ece=float(np.mean([s["ece"] for s in scores])),
                                 brier=float(np.mean([s["brier"] for s in scores])))
    constants = cal.with_intervals(final, jack)
    result = dict(model=model, voxel_m=voxel_m, unknown_behind=bool(unknown_behind), fit_seeds=fit_seeds, validation_seeds=val_seeds,
                  candidates=rows, chosen=best["candidate"], constants=constants, held=final.held,
                  voxels=final.n, log_likelihood=final.log_likelihood, reliability=reliability,
                  config=calibrated.as_dict())
    return calibrated, result


def format_lines(r):
    """What `radarcl calibrate` prints."""
    lines = [f"model {r['model']}, {r['voxel_m']} m; fitted on scenes {r['fit_seeds']}, validated on "
             f"{r['validation_seeds']}; {r['voxels']:,} visible voxels in the final fit"]
    lines += cal.candidate_lines(r["candidates"], r["chosen"], "candidate (CFAR, surface)                                   "
                                 "validation log-lik [nat/voxel]", "validation_log_likelihood")
    lines += cal.constant_lines(r["constants"], r["held"], "scenes",
                                "unknown behind the first surface" if r.get("unknown_behind") else "")
    for name, rel in r["reliability"].items():
        lines.append(f"  validation scenes, {name:16s} ECE {rel['ece']:.4f}  Brier {rel['brier']:.4f}")
    return lines


def reliability_figure(r):
    """Before / after reliability on the validation scenes."""
    return figures.reliability_figure({name: rel["rows"] for name, rel in r["reliability"].items()},
                                    f"validation scenes {r['validation_seeds']}, {r['voxel_m']} m, "
                                    f"calibrated: {r['model']} interpreter, {r['chosen']}")
