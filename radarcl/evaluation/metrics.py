"""Map quality against ground truth: the instrument every claim about a map is measured with.

Inputs are dense (nz, ny, nx) arrays of one grid: the map's log-odds (any unit: only signs
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


def dilate(mask):
    """Boolean dilation by the 3 x 3 x 3 cube (one voxel, 26-neighbourhood), as three 1-D passes."""
    out = np.asarray(mask, bool).copy()
    for axis in range(out.ndim):
        grown = out.copy()
        lo = [slice(None)] * out.ndim
        hi = [slice(None)] * out.ndim
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        grown[tuple(lo)] |= out[tuple(hi)]
        grown[tuple(hi)] |= out[tuple(lo)]
        out = grown
    return out


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
