"""Map quality against ground truth: the instrument every claim about a map is measured with.

Two sets of metrics. ``radar_scores`` (below) is the instrument: it scores a map against the
visibility truth (``evaluation.visibility``: what the line of sight reaches and what echoes
above the noise) on one fixed voxel set, beside three baselines (``evaluation.baseline``).
``evaluate`` is the older set over "observed" voxels (inside some beam's volume, whether or
not anything blocks the line of sight). It is kept because tuning (``evaluation.tuning``)
still optimises it: a score that uses no radar data (closeness to the ground plane) reaches
AUC 0.93 on it, higher than any map, so do not read it as the radar's quality.

``evaluate``'s inputs are dense (nz, ny, nx) arrays of one grid: the map's log-odds (any unit: only signs
and order matter, except for the Brier score, which needs nats), the truth labels of
``radarcl.scene.outdoor`` (FREE / OCCUPIED / INTERIOR) and the mask of observed voxels (some
beam's volume reached the voxel, whatever its evidence). Every metric is taken over the
voxels that are observed and not INTERIOR (a radar sees surfaces, not the inside of the earth):

- ``auc``: ROC area, occupied vs free, scored by the log-odds; ties count one half
  (Mann-Whitney), so an unknown voxel (0) is a coin toss, not a free pass.
- ``iou``: |P and T| / |P or T| with P the voxels with p > 0.5 and T the truly occupied ones.
- ``iou_tol1``: the same with a one-voxel tolerance (26-neighbourhood): a P voxel next to a T
  voxel is a hit; a T voxel with no P voxel within one voxel is a miss.
- ``brier``: mean (p - y)^2 with y = 1 for occupied (0.25 for a map that says 0.5 everywhere).
- ``false_free``: fraction of truly occupied voxels the map calls free (p < 0.5): the dangerous
  error for navigation. ``false_occupied``: free voxels called occupied (p > 0.5).
- ``coverage``: observed fraction of the truly occupied voxels of the whole grid.
"""

import numpy as np

from radarcl.errors import ShapeError
from radarcl.evaluation import visibility as vis
from radarcl.evaluation.visibility import dilate
from radarcl.maps.map import KNOWN_LOOKS
from radarcl.scene.outdoor import INTERIOR, OCCUPIED


def roc_auc(scores, positive):
    """Exact ROC area of ``scores`` for the boolean labels ``positive``, ties counted one half.
    NaN when either class is empty."""
    scores, positive = np.asarray(scores).reshape(-1), np.asarray(positive, bool).reshape(-1)
    n_pos = int(np.count_nonzero(positive))
    n_neg = positive.size - n_pos
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    _, inverse = np.unique(scores, return_inverse=True)
    pos = np.bincount(inverse[positive], minlength=inverse.max() + 1).astype(np.float64)
    neg = np.bincount(inverse[~positive], minlength=inverse.max() + 1).astype(np.float64)
    neg_below = np.cumsum(neg) - neg
    return float((pos * (neg_below + 0.5 * neg)).sum() / (n_pos * float(n_neg)))


def evaluate(log_odds_nats, truth, observed):
    """The metrics above as a dict of floats (and voxel counts as ints)."""
    log_odds_nats = np.asarray(log_odds_nats)
    if not (log_odds_nats.shape == np.shape(truth) == np.shape(observed)):
        raise ShapeError(f"map {log_odds_nats.shape}, truth {np.shape(truth)} and observed {np.shape(observed)} "
                         f"must be the same (nz, ny, nx) grid")
    occupied_all = truth == OCCUPIED
    scored = np.asarray(observed, bool) & (truth != INTERIOR)
    occupied = occupied_all & scored
    called_occupied = scored & (log_odds_nats > 0)
    s, y = log_odds_nats[scored], occupied[scored]
    n_pos = int(np.count_nonzero(y))
    n_neg = y.size - n_pos
    p = 1.0 / (1.0 + np.exp(-s.astype(np.float64)))
    inter = int(np.count_nonzero(called_occupied & occupied))
    union = int(np.count_nonzero(called_occupied | occupied))
    near_truth, near_called = dilate(occupied), dilate(called_occupied)
    hits = int(np.count_nonzero(called_occupied & near_truth))
    false_p = int(np.count_nonzero(called_occupied & ~near_truth))
    missed = int(np.count_nonzero(occupied & ~near_called))
    return dict(
        auc=roc_auc(s, y),
        iou=inter / union if union else float("nan"),
        iou_tol1=hits / (hits + false_p + missed) if hits + false_p + missed else float("nan"),
        brier=float(np.mean((p - y) ** 2)) if y.size else float("nan"),
        false_free=float(np.count_nonzero(s[y] < 0) / n_pos) if n_pos else float("nan"),
        false_occupied=float(np.count_nonzero(s[~y] > 0) / n_neg) if n_neg else float("nan"),
        coverage=n_pos / max(1, int(np.count_nonzero(occupied_all))),
        observed_voxels=int(y.size), observed_occupied=n_pos)


# -- metrics on the visibility truth (``evaluation.visibility``): what users of a radar map need ----------
FREE_BELOW_P = 0.35             # false-free: an occupied voxel the map calls free (p below this)
UNKNOWN_NATS = 0.2              # unknown where unknowable: a shadowed voxel within +-this of 0 (no knowledge channel)
ECE_BINS = 10


def probability(log_odds_nats):
    """p = 1 / (1 + e^-L), in float64 (L below -709 nat gives 0, without a warning)."""
    with np.errstate(over="ignore"):
        return 1.0 / (1.0 + np.exp(-np.asarray(log_odds_nats, np.float64)))


def auc_iou(log_odds_nats, positive, negative):
    """(AUC, IoU) of ``positive`` against ``negative`` voxels (boolean masks of one grid): the
    ROC area of the log-odds, and |called and positive| / |called or positive| over the two
    sets with called = p > 0.5. NaN when a set is empty."""
    pos, neg = np.asarray(positive, bool), np.asarray(negative, bool)
    s = np.concatenate([log_odds_nats[pos], log_odds_nats[neg]])
    y = np.zeros(len(s), bool)
    y[:int(np.count_nonzero(pos))] = True
    called = s > 0
    union = int(np.count_nonzero(called | y))
    return roc_auc(s, y), (int(np.count_nonzero(called & y)) / union if union else float("nan"))


def calibration(p, y, bins=ECE_BINS):
    """(ECE, per-bin rows (lo, hi, count, mean p, frequency)) of probabilities ``p`` against
    outcomes ``y`` in ``bins`` equal-width bins; ECE = sum over bins of count / n x |frequency -
    mean p|. Bins are (lo, hi], the first [0, hi]: an unknown voxel (p = 0.5) falls in (0.4, 0.5]."""
    p, y = np.asarray(p, np.float64).reshape(-1), np.asarray(y, bool).reshape(-1)
    edges = np.linspace(0.0, 1.0, bins + 1)
    which = np.searchsorted(edges[1:-1], p, side="left")           # (lo, hi], as scikit-learn's calibration_curve
    count = np.bincount(which, minlength=bins)
    mean_p = np.bincount(which, weights=p, minlength=bins) / np.maximum(count, 1)
    freq = np.bincount(which, weights=y, minlength=bins) / np.maximum(count, 1)
    ece = float((count * np.abs(freq - mean_p)).sum() / max(1, len(p)))
    rows = [(float(edges[b]), float(edges[b + 1]), int(count[b]), float(mean_p[b]), float(freq[b])) for b in range(bins)]
    return ece, rows


def radar_scores(log_odds_nats, truth, objects=(), knowledge=None):
    """The radar's metrics on one fixed voxel set (``truth``, a ``VisibilityTruth``):

    - ``auc_detectable``, ``iou_detectable``: DETECTABLE vs FREE-visible (where the radar has signal);
    - ``auc_weak``, ``iou_weak``: WEAK vs FREE-visible;
    - ``auc_obstacles``, ``iou_obstacles``: DETECTABLE voxels of every solid but the ground vs
      FREE-visible (the ground is predictable without a radar, obstacles are not);
    - ``false_free``: the share of OCCUPIED voxels of any visibility the map calls free (p < 0.35
      where it claims to know: every voxel of a map without the knowledge channel, the voxels it
      knows of one with it); ``false_free_obstacles`` the same on the surface voxels of every
      solid but the ground (most OCCUPIED voxels are ground at grazing incidence, whose echo is WEAK);
    - ``shadow_unknown``: the share of SHADOWED voxels the map leaves unknown: |L| <= 0.2 nat, or
      for a map with the knowledge channel, knowledge below ``KNOWN_LOOKS`` (such a map reads an
      unknown voxel as its prior, the world's base rate, and says "unknown" with its knowledge:
      the state its views and exports show);
    - ``brier``, ``ece`` (10 bins) and ``reliability`` rows on the visible voxels (FREE-visible,
      DETECTABLE, WEAK), occupied = surface voxel, every voxel at the probability the map reads;
    - ``ece_occupied`` and ``occupied_calls``: the calibration of what the map calls occupied, the
      ECE over the visible voxels it knows and reads at p >= 0.5, and their number: of the voxels
      a robot would avoid, is the share truly occupied the probability the map gives them? A map
      without the knowledge channel knows every voxel holding evidence: one at exactly 0 (no
      evidence; UNOBSERVED in ``maps.map.classes``, unknown in the costmap) is no call;
    - ``objects_found`` / ``objects_total`` and per object its range, peak log-odds and whether it
      is detectable (``objects``: ``visibility.object_surfaces``); an object is found when one of
      its voxels reads p > 0.5 where the map knows it (a map without the knowledge channel: any
      of them); ``detectable_found`` / ``detectable_total`` the same over the objects with a
      DETECTABLE surface voxel (the others echo below every CFAR threshold: a map that finds them
      calls weak echoes occupied).
    With ``knowledge`` (dense [looks], a map of the detection-statistics model) also:
    ``known_visible``, the share of visible voxels it knows; ``ece_known`` and ``brier_known``,
    calibration on the visible voxels it knows.
    Voxel counts of each class come with them."""
    L = np.asarray(log_odds_nats, np.float32)
    c = truth.classes
    if L.shape != c.shape:
        raise ShapeError(f"map {L.shape} and truth {c.shape} must be the same (nz, ny, nx) grid")
    free, det, weak, shadow = (c == vis.FREE_VISIBLE), (c == vis.DETECTABLE), (c == vis.WEAK), (c == vis.SHADOWED)
    out = {}
    for key, pos in (("detectable", det), ("weak", weak), ("obstacles", det & truth.obstacle)):
        out[f"auc_{key}"], out[f"iou_{key}"] = auc_iou(L, pos, free)
    claimed = np.ones(L.shape, bool) if knowledge is None else np.asarray(knowledge, np.float32) >= KNOWN_LOOKS
    called_free = claimed & (probability(L) < FREE_BELOW_P)
    occupied = truth.observed & (truth.labels == OCCUPIED)
    n_occ = int(np.count_nonzero(occupied))
    out["false_free"] = float(np.count_nonzero(called_free[occupied]) / n_occ) if n_occ else float("nan")
    obst = occupied & truth.obstacle
    n_obst = int(np.count_nonzero(obst))
    out["false_free_obstacles"] = float(np.count_nonzero(called_free[obst]) / n_obst) if n_obst else float("nan")
    n_sh = int(np.count_nonzero(shadow))
    unknown = (np.abs(L[shadow]) <= UNKNOWN_NATS) if knowledge is None else ~claimed[shadow]
    out["shadow_unknown"] = float(np.count_nonzero(unknown) / n_sh) if n_sh else float("nan")
    visible = free | det | weak
    p, y = probability(L[visible]), (det | weak)[visible]
    out["brier"] = float(np.mean((p - y) ** 2)) if len(p) else float("nan")
    out["ece"], out["reliability"] = calibration(p, y)
    # a voxel with no evidence (0) is no call: maps.map.classes' UNOBSERVED, unknown in the costmap
    knows = claimed if knowledge is not None else L != 0
    called = knows[visible] & (p >= 0.5)
    out["ece_occupied"] = calibration(p[called], y[called])[0] if called.any() else float("nan")
    out["occupied_calls"] = int(np.count_nonzero(called))
    if knowledge is not None:
        kv = claimed[visible]
        out["known_visible"] = float(np.count_nonzero(kv) / max(1, len(kv)))
        out["ece_known"] = calibration(p[kv], y[kv])[0] if kv.any() else float("nan")
        out["brier_known"] = float(np.mean((p[kv] - y[kv]) ** 2)) if kv.any() else float("nan")
    found = []
    for obj in objects:
        at = (obj["near"][:, 2], obj["near"][:, 1], obj["near"][:, 0])
        near = L[at]
        found.append(dict(name=obj["name"], range_m=obj["range_m"], peak_nats=float(near.max()),
                          found=bool(((near > 0) & claimed[at]).any()), detectable=bool(obj.get("detectable", True))))
    out["objects"] = found
    out["objects_found"] = sum(o["found"] for o in found)
    out["objects_total"] = len(found)
    out["detectable_found"] = sum(o["found"] for o in found if o["detectable"])
    out["detectable_total"] = sum(o["detectable"] for o in found)
    out["voxels"] = dict(free_visible=int(free.sum()), detectable=int(det.sum()), weak=int(weak.sum()),
                         obstacles=int((det & truth.obstacle).sum()), shadowed=n_sh, occupied=n_occ)
    return out
