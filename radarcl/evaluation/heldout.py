"""Real data without lidar: how well a map of some scans predicts the CFAR detections of scans it
did not see (`radarcl bench heldout-scans`, `radarcl calibrate-scans`).

For every held-out range bin inside the interpreter's range window, its CFAR detection by the
sensor profile's own detector (the same outcomes for every map compared) is the outcome and the
map's log-odds at the bin's world position (the azimuth's own pose, as the map was fused) the
prediction:

- ``auc``: ROC area of the log-odds at detected against not-detected bins (ties one half, an
  unknown voxel 0);
- ``log_likelihood``: mean log p(outcome) per bin [nat] with p = sigmoid(L) clipped to
  [1e-4, 1 - 1e-4]; a map that knows nothing scores log(1/2) = -0.693;
- ``coverage``: the share of held-out bins whose voxel the map holds any evidence for (for a map
  with the knowledge channel, `radarcl bench heldout-scans` gives the share whose voxel it knows).

``raw_map`` is the raw-intensity baseline fused with the same beams and poses.
"""

import numpy as np

from radarcl import logodds
from radarcl.evaluation.baseline import raw_evidence
from radarcl.evaluation.metrics import roc_auc
from radarcl.errors import ConfigError
from radarcl.grid import EvidenceGrid
from radarcl.pipeline import Mapping, bin_model, evidence_config

P_CLIP = 1e-4
FREQUENCY_SIGMA_VOXELS = 1.0       # ``frequency_map``: one voxel, one look (docs/guide/sensor-models.md: the best of a
                                   # sweep over 0.5-3 voxels and 1 and 5 looks on the held-out scans themselves scores
                                   # 0.001 AUC more)
FREQUENCY_PRIOR_LOOKS = 1.0


def raw_map(runtime, config, spec, scans, per_beam):
    """The raw-intensity baseline: each bin's power as evidence (``baseline.raw_evidence``),
    fused with the map's own beams and poses; a dense int32 snapshot of ``spec``."""
    mapping = Mapping.from_config(runtime, config=evidence_config(config), grid=EvidenceGrid(runtime, spec),
                                  per_beam_poses=True)
    fusion = mapping.fusion
    for scan, poses in zip(scans, per_beam):
        evidence = raw_evidence(scan.power().reshape(fusion.evidence_shape))
        evidence[~np.asarray(scan.valid).reshape(-1)] = 0
        fusion.upload(evidence).wait()
        fusion.enqueue(plan=fusion.plan(poses))
    runtime.queue.finish()
    return mapping.grid.snapshot()


def looked_bins(runtime, config, spec, scans, per_beam):
    """Per scan: (voxel index (n, 3) of each valid bin in the range window, inside ``spec`` or
    not, its CFAR detection by ``config``'s detector, its range [m]): the bins at their world
    positions on the beam's axis (the azimuth's own pose, as the maps are fused)."""
    mapping = Mapping.from_config(runtime, config=config, per_beam_poses=True)
    i = config.interpret_config()
    ranges = np.arange(scans[0].n_bins) * config.sensor.bin_spacing_m()
    window = (ranges >= i.range_min_m) & (ranges <= i.range_max_m)
    axes = config.sensor.lattice().beam_rotations()[:, :, 0]              # (n_az, 3) in the head frame
    for scan, poses in zip(scans, per_beam):
        detected = mapping.detection.cfar(scan.power()).mask.reshape(len(axes), -1)
        keep = np.repeat(np.asarray(scan.valid).reshape(-1), window.sum())
        dirs = np.einsum("aij,aj->ai", poses[:, :3, :3], axes)
        points = poses[:, None, :3, 3] + ranges[None, window, None] * dirs[:, None, :]
        idx = spec.world_to_index(points.reshape(-1, 3))
        yield idx[keep], detected[:, window].reshape(-1)[keep], np.tile(ranges[window], len(axes))[keep]


def predictions(runtime, config, spec, grid_int, scans, per_beam, with_ranges=False):
    """(log-odds [nat] at each held-out bin, its CFAR detection) over the range window.
    ``config`` is the outcome detector's configuration (the sensor profile's own, the same for
    every map compared: the outcomes must not change with the map's CFAR). ``grid_int`` may
    carry trailing axes (several maps of one grid stacked): the log-odds then have them too, and
    the scans are detected once for all. ``with_ranges``: also each bin's range [m] (a third array)."""
    L, y, r = [], [], []
    for idx, detected, ranges in looked_bins(runtime, config, spec, scans, per_beam):
        inside = spec.contains(idx)
        values = np.zeros((len(idx),) + np.shape(grid_int)[3:], np.float64)
        values[inside] = grid_int[idx[inside, 2], idx[inside, 1], idx[inside, 0]] / logodds.SCALE
        L.append(values)
        y.append(detected)
        r.append(ranges)
    out = np.concatenate(L), np.concatenate(y).astype(bool)
    return out + (np.concatenate(r),) if with_ranges else out


def frequency_map(runtime, config, spec, scans, per_beam, sigma_voxels=FREQUENCY_SIGMA_VOXELS,
                  prior_looks=FREQUENCY_PRIOR_LOOKS):
    """The reference predictor of held-out detections that needs no sensor model: how often the
    map scans' own CFAR (``config``: the outcome detector) detected at each voxel, hits and looks
    (bins on the beam's axis) each smoothed by a Gaussian of ``sigma_voxels`` in the grid's plane,
    shrunk towards the map scans' detection rate by ``prior_looks``:
    p = (H + a rate) / (K + a), ``prior_looks`` a > 0. Returns its log-odds [nat], a float64 grid
    of ``spec``: +-inf where the map scans detected nothing or everything (``logodds.to_fixed``
    clamps them)."""
    from scipy.ndimage import gaussian_filter

    if not prior_looks > 0:
        raise ConfigError(f"the reference's prior_looks must be > 0 (a voxel never looked at reads the rate), "
                          f"got {prior_looks!r}")
    hits = np.zeros(spec.shape[::-1], np.float64)
    looks = np.zeros_like(hits)
    for idx, detected, _ in looked_bins(runtime, config, spec, scans, per_beam):
        inside = spec.contains(idx)
        at = tuple(idx[inside][:, ::-1].T)
        np.add.at(hits, at, detected[inside])
        np.add.at(looks, at, 1.0)
    rate = hits.sum() / max(looks.sum(), 1.0)
    plane = (0.0, sigma_voxels, sigma_voxels)                      # z, y, x: no smoothing across the radar's plane
    p = (gaussian_filter(hits, plane) + prior_looks * rate) / (gaussian_filter(looks, plane) + prior_looks)
    return np.log(p / (1.0 - p))


def detection_probability(config, log_odds, ranges_m):
    """What the detection-statistics model predicts a look at a bin detects, from a map: P_fa +
    (1 - P_fa) delta(r) p, p the map's occupancy probability there and delta(r) the typical
    target's detection opportunity on the beam's axis at the bin's range (``sensor_model``), with
    the CFAR's achieved P_fa: a map says how likely a voxel is occupied, the model how likely an
    occupied one is seen."""
    bm = bin_model(config, config["grid.voxel_m"])
    j = np.clip(np.rint(np.asarray(ranges_m) / config.bin_spacing_m).astype(np.int64), 0, len(bm.opportunity) - 1)
    delta = bm.opportunity[j, 0, 0]
    p = 1.0 / (1.0 + np.exp(-np.asarray(log_odds, np.float64)))
    return bm.pfa + (1.0 - bm.pfa) * delta * p


def score_probability(p, y):
    """``score`` of predicted probabilities ``p`` (not log-odds)."""
    p = np.clip(np.asarray(p, np.float64), P_CLIP, 1 - P_CLIP)
    return dict(auc=roc_auc(p, y), log_likelihood=float(np.mean(np.where(y, np.log(p), np.log1p(-p)))),
                coverage=1.0, bins=int(len(y)), detected=int(np.sum(y)))


def log_likelihood(L, y):
    """Mean log p(outcome) [nat] of log-odds ``L`` [nat] against bool outcomes ``y``, p = sigmoid(L)
    clipped to [P_CLIP, 1 - P_CLIP]."""
    p = np.clip(1.0 / (1.0 + np.exp(-np.asarray(L, np.float64))), P_CLIP, 1 - P_CLIP)
    return float(np.mean(np.where(y, np.log(p), np.log1p(-p))))


def score(L, y):
    """``auc``, ``log_likelihood`` [nat per bin] and ``coverage`` of predictions ``L`` of ``y``."""
    return dict(auc=roc_auc(L, y), log_likelihood=log_likelihood(L, y), coverage=float(np.mean(L != 0)),
                bins=int(len(y)), detected=int(y.sum()))
