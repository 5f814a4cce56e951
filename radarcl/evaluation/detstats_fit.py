"""Calibration of the detection-statistics model (`radarcl calibrate --model detstats`): its few
physical parameters and its reading by maximum likelihood on the training scenes.

Two likelihoods, each for what it can identify:

- The physical parameters (``LOOK_GRIDS``: the typical target's reflectivity, spread and extent,
  the terrain's reflectivity) are the sensor model: they say how likely a look at an occupied
  voxel detects. They are fitted on the looks themselves (``looks``: every beam of every frame
  whose volume holds a visible occupied voxel, its bin's CFAR outcome, the voxel's rho2, range
  and class, and the blocking of the pulses in front of it): the Bernoulli likelihood of the
  outcomes under P(det) = P_fa + (1 - P_fa) delta(params) (``look_log_likelihood``). Free
  voxels do not inform the target's RCS (a free voxel's bin detects with P_fa whatever it is),
  so 97 % free air cannot drag the fit. (Fitted instead on the map's visible voxels, with every
  candidate a map, a coordinate search chose the brightest targets and the weakest terrain its
  grid allowed: free evidence everywhere, as an earlier calibration did; docs/guide/sensor-models.md
  gives its scores.)
- The reading (``sensor_model.READING``) is how a map's sums become probabilities: fitted on the
  maps of the fitted model, by the Bernoulli log-likelihood of the visible voxels (DETECTABLE or
  WEAK: 1, FREE-visible: 0; the set ECE is measured on), unknown voxels included at the value the
  reading gives them (``prior_looks`` 0: the prior, the base rate; > 0: p = 1/2), among the
  readings whose maps meet the ECE and false-free goals (``READING_GOALS``): the unconstrained
  best, made by the 97 % free air, calls a quarter of the streets' obstacle voxels free.

The reading needs no new map: it is a grid search over ``READING_GRID`` on the stored sums. The
physical parameters' standard errors come from the scene jackknife (each scene left out in turn
and the looks refitted: scenes, not looks, are the independent units).
"""

import itertools

import numpy as np

from radarcl import logodds, sensor_model, snr_evidence
from radarcl.evaluation import visibility as vis

READING_GOALS = dict(ece=0.05, false_free_obstacles=0.05)     # what a chosen reading's maps must meet
READING_GRID = dict(look_limit=(1.0, 2.0, 3.0, 4.0, 8.0, 16.0, 64.0, 1e4),
                    prior_nats=tuple(-0.5 * k for k in range(13)),
                    prior_looks=(0.0, 0.25, 0.5, 1.0, 2.0))
P_CLIP = 1e-6


def visible_sums(res, truth):
    """(E [nat], K [looks], n [looks counted], y) of the visible voxels of a detstats
    ``MapResult``: the stored sums, not yet read."""
    c = truth.classes
    keep = (c == vis.FREE_VISIBLE) | (c == vis.DETECTABLE) | (c == vis.WEAK)
    e = res.grid.snapshot()[keep] / float(logodds.SCALE)
    k = res.grid.knowledge_snapshot()[keep] / float(logodds.KNOWLEDGE_SCALE)
    n = res.grid.knowledge_snapshot("looks")[keep]
    return e, k, n, c[keep] != vis.FREE_VISIBLE


def log_likelihood(e, k, n, y, reading):
    """Mean log p(y) per voxel under ``reading``."""
    L = sensor_model.read_log_odds(e * logodds.SCALE, k * logodds.KNOWLEDGE_SCALE, n, reading)
    with np.errstate(over="ignore"):
        p = np.clip(1.0 / (1.0 + np.exp(-L)), P_CLIP, 1.0 - P_CLIP)
    return float(np.mean(np.where(y, np.log(p), np.log1p(-p))))


def fit_reading(per_scene, meets=None):
    """The ``READING_GRID`` point of the best pooled log-likelihood over scenes' (e, k, n, y):
    (reading, pooled log-lik, per-scene log-liks). With ``meets`` (reading -> bool), the best of
    those that meet it, tried in order of likelihood (the unconstrained best of the visible voxels'
    likelihood, made by the free air, calls obstacles free: docs/guide/sensor-models.md)."""
    ranked = []
    for limit, prior, looks in itertools.product(*READING_GRID.values()):
        if prior == 0.0 and looks != READING_GRID["prior_looks"][0]:
            continue                                   # prior_looks means nothing without a prior
        reading = dict(look_limit=limit, prior_nats=prior, prior_looks=looks, known_looks=sensor_model.KNOWN_LOOKS)
        scenes = [log_likelihood(e, k, n, y, reading) for e, k, n, y in per_scene]
        n = [len(y) for *_, y in per_scene]
        ranked.append((float(np.average(scenes, weights=n)), reading, scenes))
    ranked.sort(key=lambda r: -r[0])
    for pooled, reading, scenes in ranked:
        if meets is None or meets(reading):
            return reading, pooled, scenes
    return None


# -- the sensor model's own likelihood: looks at occupied voxels ------------------------------------------------------
LOOK_GRIDS = {                   # 1-D scans of the coordinate search over the looks (cheap: no map is made)
    "sensor_model.target_gamma_db": np.arange(-25.0, 5.01, 1.0),
    "sensor_model.target_spread_db": np.arange(0.0, 15.01, 1.0),
    "sensor_model.target_extent_m": np.array([0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0]),
    "sensor_model.terrain_gamma_db": np.arange(-40.0, 0.01, 1.0),
}


def looks(runtime, obs, inst, config):
    """The looks at the visible occupied voxels (DETECTABLE or WEAK) of one scene: a dict of
    arrays, one entry per (frame, beam, voxel) with the voxel's centre inside the beam's volume
    and its bin in the range window: ``rho2``, ``range_m`` (of its bin), ``terrain`` (its class,
    ``sensor_model.terrain_dz``), ``detected`` (its bin's CFAR outcome) and ``blocked`` (the
    blocking in front of the bin, ``oracle.interpret_detstats``'s X with ``config``'s evidence,
    in units of its block_gamma_db)."""
    from radarcl.pipeline import Mapping, bin_model

    mapping = Mapping.from_config(runtime, config=config)
    fusion, detection = mapping.fusion, mapping.detection
    lattice, model = fusion.lattice, fusion.model
    icfg = config.interpret_config()
    params = config.model_params()
    bm = bin_model(config, inst.spec.voxel_m)
    c = inst.truth.classes
    idx = np.argwhere((c == vis.DETECTABLE) | (c == vis.WEAK))[:, ::-1]
    centres = inst.spec.index_to_world(idx)
    rotations = lattice.beam_rotations()
    dz = sensor_model.terrain_dz(params)
    out = {k: [] for k in ("rho2", "range_m", "terrain", "detected", "blocked")}
    for frame, poses in zip(obs.samples, obs.poses):
        profiles = mapping.range_fft(frame).profiles
        cfar = detection.cfar(profiles)
        mask = cfar.mask.reshape(lattice.n_beams, -1).astype(bool)
        power = profiles.reshape(mask.shape)
        noise = cfar.noise.reshape(mask.shape)
        if bm.graded:                  # "snr" evidence: a pulse's energy over the beam's noise floor
            first, last = icfg.bin_interval(fusion.bin_spacing_m, power.shape[1])
            noise = np.broadcast_to(snr_evidence.noise_floor(power, first, last, bm.noise_floor)[:, None], power.shape)
        blocked = blocking(power, noise, mask, icfg, fusion.bin_spacing_m, bm)
        P = np.asarray(poses)
        for b in range(lattice.n_beams):
            T = P[b] if P.ndim == 3 else P
            x = centres - T[:3, 3]
            d, y, z = (x @ (T[:3, :3] @ rotations[b])).T
            j = np.rint(np.linalg.norm(x, axis=1) / fusion.bin_spacing_m).astype(np.int64)
            rho2 = model.rho2(d, y, z)
            inside = np.flatnonzero((d > 0) & (rho2 <= 1) & (j >= fusion.first_bin) & (j <= fusion.last_bin))
            if not len(inside):
                continue
            out["rho2"].append(rho2[inside])
            out["range_m"].append(j[inside] * fusion.bin_spacing_m)
            out["terrain"].append(x[inside, 2] < dz)
            out["detected"].append(mask[b, j[inside]])
            out["blocked"].append(blocked[b, j[inside]])
    return {k: np.concatenate(v) if v else np.zeros(0) for k, v in out.items()}


def blocking(profiles, noise, mask, config, bin_spacing_m, bm):
    """(n_beams, n_bins) X: the summed blocking of the pulses that ended before each bin (as
    ``oracle.interpret_detstats`` walks it), vectorised over beams."""
    r, n = np.asarray(profiles, np.float64), np.asarray(noise, np.float64)
    n_bins = r.shape[1]
    first, last = config.bin_interval(bin_spacing_m, n_bins)
    j = np.arange(n_bins)
    det = mask & ((j >= first) & (j <= last))[None, :]
    begins = det & ~np.concatenate([np.zeros((len(det), 1), bool), det[:, :-1]], axis=1)
    ends = det & ~np.concatenate([det[:, 1:], np.zeros((len(det), 1), bool)], axis=1)
    key = np.arange(len(det))[:, None] * (n_bins + 1) + np.cumsum(begins, axis=1) * det
    with np.errstate(divide="ignore", invalid="ignore"):
        excess = np.where(det, np.maximum(r / n - 1.0, 0.0), 0.0)
    energy = np.bincount(key[det], weights=excess[det], minlength=key.max() + 1)
    peak_power = np.zeros(key.max() + 1)
    np.maximum.at(peak_power, key[det], r[det])
    is_peak = det & (r == peak_power[key])
    peak_bin = np.full(key.max() + 1, n_bins - 1)
    np.minimum.at(peak_bin, key[is_peak], np.broadcast_to(j, r.shape)[is_peak])
    step = np.where(ends, energy[key] * bm.blocking[peak_bin[key]], 0.0)
    return np.cumsum(step, axis=1) - step


def look_probability(values, scene_looks, config, half_az_rad, half_el_rad, voxel_m):
    """P(detected) of each look under the parameters ``values`` {key: value} (the rest from
    ``config``), with the CFAR's achieved P_fa: P_fa + (1 - P_fa) delta."""
    params = sensor_model.ModelParams.of({**config.values, **values})
    cfar = config.cfar_config()
    oversampling = config.n_fft / config.sensor.radar.n_samples
    table = sensor_model.DetectionTable.build(cfar.kind, cfar.alpha, cfar.n_train, cfar.rank, oversampling,
                                              params.target_spread_db)
    r = scene_looks["range_m"]
    ln_up, kappa = sensor_model.upright_snr(params, r, half_az_rad, half_el_rad)
    ln_ter = sensor_model.terrain_snr(params, r, voxel_m)
    t = scene_looks["rho2"] * np.log(4.0)
    ln_s = np.where(scene_looks["terrain"], ln_ter - t, ln_up - kappa * t)
    scale = 10.0 ** ((config["sensor_model.block_gamma_db"] - params.block_gamma_db) / 10.0)
    delta = np.exp(-scene_looks["blocked"] * scale) * table(ln_s)
    return table.pfa + (1.0 - table.pfa) * delta


def look_log_likelihood(values, per_scene, config, half_az_rad, half_el_rad, voxel_m):
    """(pooled mean log-likelihood per look, per-scene means) of the looks' outcomes."""
    lls, n = [], []
    for scene_looks in per_scene:
        p = np.clip(look_probability(values, scene_looks, config, half_az_rad, half_el_rad, voxel_m), P_CLIP, 1 - P_CLIP)
        y = scene_looks["detected"].astype(bool)
        lls.append(float(np.mean(np.where(y, np.log(p), np.log1p(-p)))))
        n.append(len(y))
    return float(np.average(lls, weights=n)), lls


def fit_looks(per_scene, config, half_az_rad, half_el_rad, voxel_m, rounds=3):
    """Coordinate search of ``LOOK_GRIDS`` from ``config``'s values: (values, pooled log-lik)."""
    best = {k: float(config[k]) for k in LOOK_GRIDS}
    score = look_log_likelihood(best, per_scene, config, half_az_rad, half_el_rad, voxel_m)[0]
    for _ in range(rounds):
        moved = False
        for key, grid in LOOK_GRIDS.items():
            for v in grid:
                trial = {**best, key: float(v)}
                ll = look_log_likelihood(trial, per_scene, config, half_az_rad, half_el_rad, voxel_m)[0]
                if ll > score + 1e-9:
                    best, score, moved = trial, ll, True
        if not moved:
            break
    return best, score
