"""Radar maps scored against lidar (``radarcl evaluate-lidar``): truth ray-cast from the lidar
with the poses, scores per range band where the lidar knows, with controls that use no radar
data beside every row, and annotated objects checked.

Truth (``lidar_truth``), in the radar's plane (one cell per map column):
- points within ``EGO_RADIUS_M`` of the lidar are its own vehicle and are dropped;
- a frame's points go into the world with the lidar's pose at its time; its ground is the 10th
  percentile of its heights within ``GROUND_RANGE_M`` (the lower rings hit the road);
- a cell holds a hit when a point lies in it between ``CLEARANCE_M`` and ``TOP_M`` above that
  ground (an obstacle a vehicle's radar plane can meet); a ray passes a cell when the segment
  from the lidar to any point (ground hits too) crosses it before the point's own cell, between
  ``CLEARANCE_M`` and ``FREE_TOP_M`` above the ground: lower than any vehicle, so that rays over
  a parked car's roof do not make its cells free;
- the frame reaches only as far as its points do: ``REACH_PERCENTILE`` % of its points lie
  within its reach, and nothing beyond it counts (in fog: 10-15 m; no point does not mean free);
- over frames a cell is OCCUPIED when at least as many frames saw a hit in it as saw rays pass
  it without a hit, FREE when more frames saw rays pass than hit, UNKNOWN when none saw it.

Scores (``band_scores``), per band of range from the radar's path (a cell's distance to the
nearest position of the radar), over the cells the lidar knows: the ROC area of each predictor
(occupied against free), and for maps the IoU at the occupancy threshold (log-odds > 0 against
OCCUPIED) and what a robot acting on the map's costmap meets (``costmap_scores``: the phantom
and miss rates at the export thresholds, the cells left unknown, the calibration against the
lidar, and the raw intensity's phantom rate at the same recall, ``phantom_at_recall``). Bands
with fewer than ``MIN_CELLS`` occupied or free cells are not scored. Two
predictors use no radar data: the number of radar samples a cell holds, negated ("-1 per
sample": occupied cells lie farther out, so counting wins against summed evidence when range is
not held fixed), and the range itself; the raw intensity fused with the same beams is the
no-model baseline (``heldout.raw_map``). A map must beat all three in every band.

Objects (``box_scores``): each annotated box, placed in the world with the radar's pose at the
azimuth that looks at it, is occupied in a map when a cell whose centre lies inside it has
log-odds above 0. Beside it, the chance of that for the same box turned about the radar to
``CHANCE_TURNS`` other bearings at the same range (a map occupied everywhere passes every box),
and the box's rank among those copies by mean log-odds (0.5: no better than a box anywhere at
its range).
"""

import math
from dataclasses import dataclass

import numpy as np

from radarcl import logodds
from radarcl.errors import ConfigError
from radarcl.evaluation.metrics import calibration, probability, roc_auc
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import GridSpec
from radarcl.maps.map import FREE, OCCUPIED, UNOBSERVED, classes
from radarcl.pipeline import Mapping, evidence_config

EGO_RADIUS_M = 3.0           # nearer the lidar: the vehicle that carries it (a car reaches ~2.5 m from its roof)
CLEARANCE_M = 0.3            # above the ground: kerbs and the road's own roughness are not obstacles
TOP_M = 3.0                  # a vehicle's radar plane meets nothing higher (eaves, tree crowns)
FREE_TOP_M = 1.0             # rays mark cells free only this low: under a car's roof, a person's waist
GROUND_RANGE_M = 20.0
REACH_PERCENTILE = 99.0
STEPS_PER_CELL = 4           # ray samples per cell edge
BANDS_M = (2.0, 5.0, 10.0, 15.0, 20.0, 30.0, 50.0)
MIN_CELLS = 20
CHANCE_TURNS = 72


def plane_spec(positions, range_m, voxel_m):
    """A one-cell-thick grid in the radar's plane (z = 0) holding every position (n, 2 or 3)
    plus ``range_m``."""
    xy = np.asarray(positions, np.float64).reshape(-1, np.shape(positions)[-1])[:, :2]
    lo, hi = xy.min(axis=0) - range_m, xy.max(axis=0) + range_m
    nx, ny = (int(math.ceil(v)) for v in (hi - lo) / voxel_m)
    return GridSpec((float(lo[0]), float(lo[1]), -0.5 * voxel_m), voxel_m, (nx, ny, 1))


@dataclass
class LidarTruth:
    """Per cell (ny, nx): frames that saw a hit in it, frames whose rays passed it without one;
    the reach of each frame [m]."""

    spec: GridSpec
    hits: np.ndarray
    passes: np.ndarray
    reach_m: list

    @property
    def occupied(self):
        """Cells at least as many frames saw a hit in as saw rays pass."""
        return (self.hits > 0) & (self.hits >= self.passes)

    @property
    def free(self):
        """Cells more frames saw rays pass than hit."""
        return self.passes > self.hits

    @property
    def known(self):
        """Cells some frame saw."""
        return (self.hits > 0) | (self.passes > 0)


def _cells(spec, xy):
    """(ix, iy, inside) of world points (n, 2) in a plane grid."""
    i = np.floor((xy - np.asarray(spec.origin_m[:2])) / spec.voxel_m).astype(np.int64)
    inside = (i[:, 0] >= 0) & (i[:, 0] < spec.shape[0]) & (i[:, 1] >= 0) & (i[:, 1] < spec.shape[1])
    return i[:, 0], i[:, 1], inside


def frame_cells(spec, pose, points):
    """(hit (ny, nx) bool, passed (ny, nx) bool, reach [m]) of one lidar frame: ``points`` (n, 3)
    in the lidar's REP-103 frame, ``pose`` its 4x4 pose in the world (see the module)."""
    p = np.asarray(points, np.float64)
    ny, nx = spec.shape[1], spec.shape[0]
    hit, passed = np.zeros((ny, nx), bool), np.zeros((ny, nx), bool)
    if len(p) == 0:
        return hit, passed, 0.0
    r = np.hypot(p[:, 0], p[:, 1])
    p, r = p[r >= EGO_RADIUS_M], r[r >= EGO_RADIUS_M]
    if len(p) == 0:
        return hit, passed, 0.0
    near = r < GROUND_RANGE_M
    ground = float(np.percentile(p[near if near.any() else slice(None), 2], 10))
    reach = float(np.percentile(r, REACH_PERCENTILE))
    p = p[r <= reach]
    world = p @ pose[:3, :3].T + pose[:3, 3]
    height = p[:, 2] - ground
    obstacle = (height >= CLEARANCE_M) & (height <= TOP_M)
    ix, iy, inside = _cells(spec, world[obstacle, :2])
    hit[iy[inside], ix[inside]] = True
    # rays: one per end cell (rays ending in one cell cross the same cells but the last few),
    # sampled STEPS_PER_CELL times per cell edge up to the end point's own cell
    ex, ey, _ = _cells(spec, world[:, :2])
    _, first = np.unique(np.stack([ex, ey], 1), axis=0, return_index=True)
    origin = pose[:3, 3]
    ends = world[first]
    length = np.linalg.norm(ends[:, :2] - origin[:2], axis=1)
    step = spec.voxel_m / STEPS_PER_CELL
    n = np.maximum(1, np.ceil(length / step).astype(np.int64))
    ray = np.repeat(np.arange(len(ends)), n)
    frac = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
    samples = origin + frac[:, None] * (ends[ray] - origin)
    sx, sy, s_in = _cells(spec, samples[:, :2])
    before = (sx != ex[first][ray]) | (sy != ey[first][ray])
    h = _sample_height(samples, pose, ground)
    keep = s_in & before & (h >= CLEARANCE_M) & (h <= FREE_TOP_M)
    passed[sy[keep], sx[keep]] = True
    return hit, passed & ~hit, reach


def _sample_height(samples, pose, ground):
    """Height above the frame's ground of world samples (the ground is level in the lidar's frame)."""
    local = (samples - pose[:3, 3]) @ pose[:3, :3]
    return local[:, 2] - ground


def lidar_truth(spec, frames):
    """``LidarTruth`` on the plane grid ``spec`` from ``frames`` [(pose (4, 4), points (n, 3) in the
    lidar's REP-103 frame)]."""
    ny, nx = spec.shape[1], spec.shape[0]
    hits, passes, reach = np.zeros((ny, nx), np.int32), np.zeros((ny, nx), np.int32), []
    for pose, points in frames:
        h, p, r = frame_cells(spec, np.asarray(pose, np.float64), points)
        hits += h
        passes += p
        reach.append(r)
    return LidarTruth(spec, hits, passes, reach)


def count_map(runtime, config, spec, scans, per_beam):
    """The no-radar control: -1 nat for every valid range bin inside the interpreter's window,
    fused with the map's own beams and poses (it counts samples and uses nothing they hold); a
    dense int32 snapshot of ``spec``."""
    mapping = Mapping.from_config(runtime, config=evidence_config(config), grid=EvidenceGrid(runtime, spec),
                                  per_beam_poses=True)
    fusion = mapping.fusion
    for scan, poses in zip(scans, per_beam):
        evidence = np.full(fusion.evidence_shape, -logodds.SCALE, np.int32)
        evidence[~np.asarray(scan.valid).reshape(-1)] = 0
        fusion.upload(evidence).wait()
        fusion.enqueue(plan=fusion.plan(poses))
    runtime.queue.finish()
    return mapping.grid.snapshot()


def radar_visible(truth, per_beam, range_min_m, range_max_m):
    """(ny, nx) bool: cells some radar beam reaches no later than the first cell the lidar calls
    occupied along it (the beam's axis from each azimuth's pose, sampled ``STEPS_PER_CELL`` times
    per cell): what the radar could see if the lidar's truth were the world. Occupied cells in
    every beam's shadow and the free cells behind them are left out."""
    spec, occ = truth.spec, truth.occupied
    ny, nx = occ.shape
    seen = np.zeros_like(occ)
    r = np.arange(range_min_m, range_max_m, spec.voxel_m / STEPS_PER_CELL)
    origin = np.asarray(spec.origin_m[:2])
    for poses in per_beam:
        n_az = len(poses)
        az = np.arange(n_az) * (2 * math.pi / n_az)      # the spinning lattice's azimuth i, turned by its pose
        dirs = np.einsum("aij,aj->ai", poses[:, :2, :2], np.stack([np.cos(az), np.sin(az)], axis=1))
        pts = poses[:, None, :2, 3] + r[None, :, None] * dirs[:, None, :]
        ij = np.floor((pts - origin) / spec.voxel_m).astype(np.int64)
        inside = (ij[..., 0] >= 0) & (ij[..., 0] < nx) & (ij[..., 1] >= 0) & (ij[..., 1] < ny)
        ij = np.where(inside[..., None], ij, 0)
        hit = occ[ij[..., 1], ij[..., 0]] & inside
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), len(r) - 1)
        keep = (np.arange(len(r))[None, :] <= first[:, None]) & inside
        seen[ij[..., 1][keep], ij[..., 0][keep]] = True
    return seen


def bin_cells(spec, poses, ranges_m):
    """(iy, ix, inside), each (n_az, n_bins), of the plane grid's cell under every bin of one
    scan: its azimuths' ``poses`` (n_az, 4, 4), bins at ``ranges_m`` along each beam's axis (the
    spinning lattice's azimuth i turned by its pose, as ``radar_visible``)."""
    n_az = len(poses)
    az = np.arange(n_az) * (2 * math.pi / n_az)
    dirs = np.einsum("aij,aj->ai", poses[:, :2, :2], np.stack([np.cos(az), np.sin(az)], axis=1))
    pts = poses[:, None, :2, 3] + np.asarray(ranges_m)[None, :, None] * dirs[:, None, :]
    ij = np.floor((pts - np.asarray(spec.origin_m[:2])) / spec.voxel_m).astype(np.int64)
    inside = (ij[..., 0] >= 0) & (ij[..., 0] < spec.shape[0]) & (ij[..., 1] >= 0) & (ij[..., 1] < spec.shape[1])
    ij = np.where(inside[..., None], ij, 0)
    return ij[..., 1], ij[..., 0], inside


# -- scores --------------------------------------------------------------------------------------------------
def range_from_path(spec, positions):
    """(ny, nx) distance [m] of each cell centre to the nearest of ``positions`` (n, >= 2)."""
    from scipy.spatial import cKDTree

    nx, ny = spec.shape[0], spec.shape[1]
    x = spec.origin_m[0] + (np.arange(nx) + 0.5) * spec.voxel_m
    y = spec.origin_m[1] + (np.arange(ny) + 0.5) * spec.voxel_m
    gx, gy = np.meshgrid(x, y)
    d, _ = cKDTree(np.asarray(positions, np.float64)[:, :2]).query(np.stack([gx.ravel(), gy.ravel()], 1))
    return d.reshape(ny, nx)


def costmap_scores(nats, pos, neg, known=None):
    """What a robot acting on a map meets where the lidar knows: ``nats`` (ny, nx) log-odds as the
    map reads them, ``pos`` / ``neg`` the lidar's occupied / free cells (bool masks), ``known``
    the cells the map knows (bool, a map with the knowledge channel: knowledge of ``KNOWN_LOOKS``
    looks or more; None: the cells holding any evidence, as for a map without it). The map's
    classes are the costmap export's (``maps.map.classes``): occupied above ``OCCUPIED_NATS``,
    free below ``FREE_NATS``, unknown between them and wherever the map does not know the cell,
    whatever it reads. A dict of

    - ``phantom``: the share of ``neg`` called occupied (a robot stops for nothing there);
    - ``miss``: the share of ``pos`` called free (a robot drives into it);
    - ``unknown``: the share of ``pos`` and ``neg`` called neither;
    - ``recall``: the share of ``pos`` called occupied;
    - ``ece`` (``metrics.calibration``, 10 bins) of the probability the map reads against the
      lidar's occupied / free, over the cells of ``pos`` and ``neg`` the map knows, and their
      number ``ece_cells`` (the cells it does not know are left out: they count in ``unknown``).

    Shares are NaN over an empty set."""
    nats, pos, neg = np.asarray(nats, np.float64), np.asarray(pos, bool), np.asarray(neg, bool)
    c = classes(logodds.to_fixed(nats), known=known)
    known = c != UNOBSERVED if known is None else np.asarray(known, bool)

    def share(hit, of):
        n = int(np.count_nonzero(of))
        return int(np.count_nonzero(hit & of)) / n if n else float("nan")

    lidar = pos | neg
    scored = lidar & known
    out = dict(phantom=share(c == OCCUPIED, neg), miss=share(c == FREE, pos),
               unknown=share((c != OCCUPIED) & (c != FREE), lidar), recall=share(c == OCCUPIED, pos),
               ece_cells=int(np.count_nonzero(scored)))
    out["ece"] = calibration(probability(nats[scored]), pos[scored])[0] if out["ece_cells"] else float("nan")
    return out


def phantom_at_recall(score, pos, neg, recall):
    """(threshold, phantom rate) of ``score`` (ny, nx, higher = more occupied) called occupied
    above a threshold chosen so that it calls exactly ``recall`` of the ``pos`` cells occupied:
    above the threshold every cell, at it the share of the tied cells that makes the recall exact
    (the ROC curve's straight segment across a tie, as the AUC's ties count one half); the
    phantom rate is the share of ``neg`` called occupied that way. Recall 0: threshold +inf,
    phantom 0. NaN for an empty ``pos`` or ``neg`` or a NaN recall."""
    s = np.asarray(score, np.float64)
    s_pos, s_neg = s[np.asarray(pos, bool)], s[np.asarray(neg, bool)]
    if not len(s_pos) or not len(s_neg) or not np.isfinite(recall):
        return float("nan"), float("nan")
    wanted = float(recall) * len(s_pos)                          # positive cells to call occupied
    if wanted <= 0:
        return float("inf"), 0.0
    t = np.sort(s_pos)[::-1][min(len(s_pos), int(math.ceil(wanted - 1e-9))) - 1]
    above, tied = np.count_nonzero(s_pos > t), np.count_nonzero(s_pos == t)
    share = (wanted - above) / tied                              # of the tied cells, in (0, 1]
    phantom = (np.count_nonzero(s_neg > t) + share * np.count_nonzero(s_neg == t)) / len(s_neg)
    return float(t), float(phantom)


def band_scores(truth, distance, maps, baselines, bands=BANDS_M, mask=None, known=None, equal_recall=None):
    """Rows per band [{band, occupied, free, auc: {name: AUC}, iou: {name: IoU}, costmap: {name:
    costmap_scores}}]: ``maps`` and ``baselines`` are {name: (ny, nx) score, higher = more
    occupied}; maps (log-odds [nat] as they read) also get an IoU at log-odds 0 and their
    ``costmap_scores`` (``known``: {name: (ny, nx) bool} for the maps with the knowledge channel),
    and with ``equal_recall`` (the name of a baseline) that baseline's threshold and phantom rate
    at each map's recall (``phantom_at_recall``) in their ``costmap`` entry as
    ``equal_recall_threshold`` and ``equal_recall_phantom``. Only cells of ``mask`` count
    (default all). Bands where the lidar knows fewer than ``MIN_CELLS`` of either class are left
    out."""
    occ, free = truth.occupied, truth.free
    if mask is not None:
        occ, free = occ & mask, free & mask
    known = known or {}
    rows = []
    for lo, hi in zip(bands[:-1], bands[1:]):
        band = (distance >= lo) & (distance < hi)
        pos, neg = occ & band, free & band
        n_pos, n_neg = int(pos.sum()), int(neg.sum())
        if n_pos < MIN_CELLS or n_neg < MIN_CELLS:
            continue
        y = np.r_[np.ones(n_pos, bool), np.zeros(n_neg, bool)]
        row = dict(band=(lo, hi), occupied=n_pos, free=n_neg, auc={}, iou={}, costmap={})
        for name, score in {**maps, **baselines}.items():
            s = np.r_[score[pos], score[neg]]
            row["auc"][name] = roc_auc(s, y)
        for name, score in maps.items():
            called = np.r_[score[pos], score[neg]] > 0
            union = int(np.count_nonzero(called | y))
            row["iou"][name] = int(np.count_nonzero(called & y)) / union if union else float("nan")
            row["costmap"][name] = costmap_scores(score, pos, neg, known.get(name))
            if equal_recall is not None:
                t, phantom = phantom_at_recall(baselines[equal_recall], pos, neg, row["costmap"][name]["recall"])
                row["costmap"][name].update(equal_recall_threshold=t, equal_recall_phantom=phantom)
        rows.append(row)
    return rows


# -- objects -------------------------------------------------------------------------------------------------
def inside_polygon(points, corners):
    """(n,) bool: points (n, 2) inside the convex polygon ``corners`` (k, 2) (either winding)."""
    p = np.asarray(points, np.float64)
    c = np.asarray(corners, np.float64)
    edge = np.roll(c, -1, axis=0) - c
    cross = edge[None, :, 0] * (p[:, None, 1] - c[None, :, 1]) - edge[None, :, 1] * (p[:, None, 0] - c[None, :, 0])
    return (cross >= 0).all(axis=1) | (cross <= 0).all(axis=1)


def _box_cells(spec, corners):
    """(ix, iy) of the plane grid's cells whose centres lie inside the polygon (world metres)."""
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    i0 = np.floor((lo - np.asarray(spec.origin_m[:2])) / spec.voxel_m).astype(int)
    i1 = np.ceil((hi - np.asarray(spec.origin_m[:2])) / spec.voxel_m).astype(int)
    i0, i1 = np.maximum(i0, 0), np.minimum(i1, spec.shape[:2])
    if (i1 <= i0).any():
        return np.zeros(0, int), np.zeros(0, int)
    gx, gy = np.meshgrid(np.arange(i0[0], i1[0]), np.arange(i0[1], i1[1]))
    gx, gy = gx.ravel(), gy.ravel()
    centres = np.asarray(spec.origin_m[:2]) + (np.stack([gx, gy], 1) + 0.5) * spec.voxel_m
    keep = inside_polygon(centres, corners)
    return gx[keep], gy[keep]


def box_scores(spec, boxes, maps, truth=None):
    """Per box [{object, class, frame, range_m, cells, lidar_hits, maps: {name: (occupied,
    peak log-odds, chance, rank)}}]. ``boxes`` are [(object id, class, frame, world corners (4, 2),
    radar position (2,))]; ``maps`` {name: (ny, nx) log-odds}; the chance is the share of
    ``CHANCE_TURNS`` copies of the box turned about the radar that the map calls occupied, the
    rank the share of those copies (inside the grid) whose mean log-odds lies below the box's
    (ties one half): 0.5 when the map does not tell the box from anywhere else at its range, 1
    when the box stands out from all of them (a map occupied everywhere passes every box, but
    ranks them at 0.5). The mean, not the peak: a map whose evidence reaches its cap in many
    places ties most copies at the peak."""
    out = []
    turns = np.linspace(0, 2 * math.pi, CHANCE_TURNS, endpoint=False)[1:]
    for obj, cls, frame, corners, radar in boxes:
        corners, radar = np.asarray(corners, float), np.asarray(radar, float)[:2]
        gx, gy = _box_cells(spec, corners)
        copies = []
        for a in turns:
            c, s = math.cos(a), math.sin(a)
            copies.append(_box_cells(spec, (corners - radar) @ np.array([[c, s], [-s, c]]) + radar))
        row = dict(object=obj, cls=cls, frame=frame, range_m=float(np.linalg.norm(corners.mean(0) - radar)),
                   cells=int(len(gx)), lidar_hits=int(truth.hits[gy, gx].sum()) if truth is not None else None,
                   maps={})
        for name, nats in maps.items():
            values = nats[gy, gx]
            peak = float(values.max()) if len(values) else float("nan")
            chance = [bool(len(tx)) and bool((nats[ty, tx] > 0).any()) for tx, ty in copies]
            means = np.array([nats[ty, tx].mean() for tx, ty in copies if len(tx)])
            mean = values.mean() if len(values) else float("nan")
            rank = float(np.mean((means < mean) + 0.5 * (means == mean))) if len(means) and len(values) else float("nan")
            row["maps"][name] = (bool((values > 0).any()), peak, float(np.mean(chance)), rank)
        out.append(row)
    return out


def nats_of(snapshot):
    """(ny, nx) float64 log-odds [nat] of a one-layer int32 snapshot (nz = 1, ny, nx)."""
    snap = np.asarray(snapshot)
    if snap.ndim != 3 or snap.shape[0] != 1:
        raise ConfigError(f"lidar scores need a one-layer map (the radar's plane), got a snapshot of {snap.shape}")
    return snap[0].astype(np.float64) / logodds.SCALE
