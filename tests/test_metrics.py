"""The metrics on the visibility truth (radarcl/evaluation/metrics.py: radar_scores and its
parts) against hand-computed values and against scikit-learn as an oracle."""

import math

import numpy as np
import pytest
from sklearn import metrics as skm

from radarcl.evaluation import metrics
from radarcl.evaluation import visibility as vis
from radarcl.scene.outdoor import FREE, INTERIOR, OCCUPIED


def test_auc_iou_brier_and_ece_match_scikit_learn():
    rng = np.random.default_rng(5)
    L = np.round(rng.normal(0, 2, 4000), 1).astype(np.float32)      # ties on purpose
    y = rng.random(4000) < 1 / (1 + np.exp(-L))                      # roughly calibrated
    pos, neg = y.copy(), ~y
    auc, iou = metrics.auc_iou(L, pos, neg)
    assert auc == pytest.approx(skm.roc_auc_score(y, L), abs=1e-12)
    assert iou == pytest.approx(skm.jaccard_score(y, L > 0), abs=1e-12)
    p = metrics.probability(L)
    ece, rows = metrics.calibration(p, y)
    # scikit-learn's calibration_curve with uniform bins gives each non-empty bin's frequency
    # and mean p: the ECE from them, weighted by the bin counts
    from sklearn.calibration import calibration_curve

    freq, mean_p = calibration_curve(y, p, n_bins=10, strategy="uniform")
    counts = [r[2] for r in rows if r[2]]
    assert [r[4] for r in rows if r[2]] == pytest.approx(freq, abs=1e-12)
    assert [r[3] for r in rows if r[2]] == pytest.approx(mean_p, abs=1e-12)
    assert ece == pytest.approx(float(np.dot(counts, np.abs(freq - mean_p)) / len(p)), abs=1e-12)
    assert float(np.mean((p - y) ** 2)) == pytest.approx(skm.brier_score_loss(y, p), abs=1e-12)


def small_truth():
    """A 1 x 2 x 6 grid by hand: classes and labels chosen so every metric has a known value."""
    classes = np.array([[[vis.FREE_VISIBLE, vis.FREE_VISIBLE, vis.DETECTABLE, vis.WEAK, vis.SHADOWED, vis.SHADOWED],
                         [vis.FREE_VISIBLE, vis.DETECTABLE, vis.UNOBSERVED, vis.INSIDE_SOLID, vis.SHADOWED, vis.WEAK]]],
                       np.uint8)
    labels = np.array([[[FREE, FREE, OCCUPIED, OCCUPIED, OCCUPIED, FREE],
                        [FREE, OCCUPIED, OCCUPIED, INTERIOR, FREE, OCCUPIED]]], np.uint8)
    obstacle = np.zeros_like(classes, bool)
    obstacle[0, 1, 1] = True                                            # the second DETECTABLE voxel
    return vis.VisibilityTruth(classes, labels, obstacle, classes != vis.UNOBSERVED)


def test_radar_scores_by_hand():
    t = small_truth()
    L = np.array([[[-1.0, 0.5, 2.0, -0.1, 0.1, -3.0],
                   [-2.0, 1.0, 9.0, 5.0, 0.0, -0.7]]], np.float32)
    s = metrics.radar_scores(L, t)
    # DETECTABLE {2.0, 1.0} vs FREE-visible {-1.0, 0.5, -2.0}: every pair ranked right
    assert s["auc_detectable"] == 1.0
    assert s["iou_detectable"] == pytest.approx(2 / 3)                  # called: 2.0, 1.0, 0.5
    # WEAK {-0.1, -0.7} vs FREE {-1.0, 0.5, -2.0}: pairs won: -0.1 beats 2, -0.7 beats 2 -> 4 / 6
    assert s["auc_weak"] == pytest.approx(4 / 6)
    assert s["iou_weak"] == 0.0                                          # called 0.5 (free), no weak one
    assert s["auc_obstacles"] == 1.0 and s["iou_obstacles"] == pytest.approx(1 / 2)
    # OCCUPIED within the observed set: 2.0, -0.1, 0.1, 1.0, -0.7 (the unobserved 9.0 is not in
    # it); p < 0.35 means L < -0.619: only -0.7
    assert s["false_free"] == pytest.approx(1 / 5)
    assert s["false_free_obstacles"] == 0.0                             # the obstacle voxel holds 1.0
    L2 = L.copy()
    L2[0, 1, 1] = -0.7
    assert metrics.radar_scores(L2, t)["false_free_obstacles"] == 1.0
    # SHADOWED {0.1, -3.0, 0.0}: two within 0.2 nat
    assert s["shadow_unknown"] == pytest.approx(2 / 3)
    visible = np.array([-1.0, 0.5, 2.0, -0.1, -2.0, 1.0, -0.7])
    y = np.array([0, 0, 1, 1, 0, 1, 1], bool)
    p = 1 / (1 + np.exp(-visible))
    assert s["brier"] == pytest.approx(np.mean((p - y) ** 2), abs=1e-7)
    assert s["voxels"] == dict(free_visible=3, detectable=2, weak=2, obstacles=1, shadowed=3, occupied=5)


def test_a_map_with_knowledge_is_scored_by_what_it_claims():
    """A map with the knowledge channel reads an unknown voxel as its prior (the base rate), so
    its value says nothing of "unknown": false-free counts only voxels it knows and calls free,
    and a shadowed voxel is left unknown when the map does not know it, whatever it reads."""
    t = small_truth()
    L = np.full((1, 2, 6), -3.5, np.float32)          # the prior everywhere
    k = np.zeros((1, 2, 6), np.float32)
    L[0, 0, 2], k[0, 0, 2] = 4.0, 3.0                # a known DETECTABLE voxel called occupied
    L[0, 1, 1], k[0, 1, 1] = -2.0, 2.0               # the known obstacle voxel called free
    k[0, 0, 4] = 1.0                                 # one SHADOWED voxel the map knows
    s = metrics.radar_scores(L, t, knowledge=k)
    # OCCUPIED and observed: (0,0,2) 4.0 known, (0,0,3) unknown, (0,0,4) known at -3.5, (0,1,1)
    # known at -2.0, (0,1,5) unknown: two of five called free
    assert s["false_free"] == pytest.approx(2 / 5)
    assert s["false_free_obstacles"] == 1.0
    assert s["shadow_unknown"] == pytest.approx(2 / 3)                   # (0,0,4) is known
    assert s["known_visible"] == pytest.approx(2 / 7)
    without = metrics.radar_scores(L, t)                                  # the same values read without knowledge
    assert without["false_free"] == pytest.approx(4 / 5) and without["shadow_unknown"] == 0.0
    # ECE is over every visible voxel at the probability it reads: unknown ones at the prior
    visible = np.array([-3.5, -3.5, 4.0, -3.5, -3.5, -2.0, -3.5])
    y = np.array([0, 0, 1, 1, 0, 1, 1], bool)
    assert s["ece"] == pytest.approx(metrics.calibration(metrics.probability(visible), y)[0])


def test_a_map_of_zeros_and_the_empty_cases():
    t = small_truth()
    s = metrics.radar_scores(np.zeros((1, 2, 6), np.float32), t)
    assert s["auc_detectable"] == 0.5 and s["iou_detectable"] == 0.0
    assert s["false_free"] == 0.0 and s["shadow_unknown"] == 1.0 and s["brier"] == 0.25
    t.classes[t.classes == vis.SHADOWED] = vis.FREE_VISIBLE
    assert math.isnan(metrics.radar_scores(np.zeros((1, 2, 6), np.float32), t)["shadow_unknown"])
    with pytest.raises(Exception, match="same"):
        metrics.radar_scores(np.zeros((2, 2, 6), np.float32), t)


def test_objects_are_found_within_one_voxel_of_their_visible_surface():
    t = small_truth()
    objects = [dict(name="near", range_m=3.0, near=np.array([[2, 0, 0], [1, 1, 0]]), detectable=True),
               dict(name="far", range_m=9.0, near=np.array([[5, 0, 0]]), detectable=False),
               dict(name="post", range_m=5.0, near=np.array([[4, 0, 0]]), detectable=True)]
    L = np.zeros((1, 2, 6), np.float32)
    L[0, 1, 1] = 0.3
    L[0, 0, 5] = -1.0
    s = metrics.radar_scores(L, t, objects)
    assert s["objects_found"] == 1 and s["objects_total"] == 3
    assert s["objects"][0] == dict(name="near", range_m=3.0, peak_nats=pytest.approx(0.3), found=True, detectable=True)
    assert s["objects"][1]["found"] is False and s["objects"][1]["peak_nats"] == -1.0
    # the objects with a detectable surface: the far one echoes below every CFAR and is not counted
    assert s["detectable_found"] == 1 and s["detectable_total"] == 2
    L[0, 0, 4] = 0.1
    assert metrics.radar_scores(L, t, objects)["detectable_found"] == 2


def _p(nats):
    return 1.0 / (1.0 + math.exp(-nats))


def test_the_occupied_call_ece_by_hand():
    """ECE of what the map calls occupied: over the visible voxels (FREE-visible, DETECTABLE,
    WEAK) read at p >= 0.5; a map with knowledge: only those it knows, whatever the others read;
    one without: those holding evidence (a voxel at exactly 0 is unknown, no call)."""
    t = small_truth()
    L = np.array([[[-1.0, 0.5, 2.0, -0.1, 0.1, -3.0],
                   [-2.0, 1.0, 9.0, 5.0, 0.0, -0.7]]], np.float32)
    s = metrics.radar_scores(L, t)
    # visible at p >= 0.5: 0.5 (free), 2.0 and 1.0 (detectable), each alone in its bin
    assert s["occupied_calls"] == 3
    assert s["ece_occupied"] == pytest.approx((_p(0.5) + (1 - _p(2.0)) + (1 - _p(1.0))) / 3, abs=1e-12)
    # a weak echo at the slightest positive evidence is a call; at exactly 0 it is none
    L2 = L.copy()
    L2[0, 0, 3] = 1e-3
    s2 = metrics.radar_scores(L2, t)
    assert s2["occupied_calls"] == 4
    assert s2["ece_occupied"] == pytest.approx((_p(0.5) + (1 - _p(2.0)) + (1 - _p(1.0)) + (1 - _p(1e-3))) / 4,
                                               abs=1e-7)
    L2[0, 0, 3] = 0.0
    assert metrics.radar_scores(L2, t)["occupied_calls"] == 3
    zeros = metrics.radar_scores(np.zeros((1, 2, 6), np.float32), t)
    assert zeros["occupied_calls"] == 0 and math.isnan(zeros["ece_occupied"])
    k = np.zeros((1, 2, 6), np.float32)
    k[0, 0, 1], k[0, 0, 2] = 1.0, 0.5                 # it knows the free 0.5 and the detectable 2.0 (0.5 look: known)
    k[0, 1, 1] = 0.49                                 # and not quite the detectable 1.0
    s = metrics.radar_scores(L, t, knowledge=k)
    assert s["occupied_calls"] == 2
    assert s["ece_occupied"] == pytest.approx((_p(0.5) + (1 - _p(2.0))) / 2, abs=1e-12)
    assert math.isnan(metrics.radar_scores(L, t, knowledge=np.zeros_like(k))["ece_occupied"])


def test_an_object_is_found_only_where_the_map_knows_it():
    """A map with the knowledge channel finds an object only at a voxel it knows that reads p >
    0.5; what it reads where it does not know (its prior, or evidence too thin) finds nothing."""
    t = small_truth()
    objects = [dict(name="near", range_m=3.0, near=np.array([[2, 0, 0], [1, 1, 0]]), detectable=True),
               dict(name="post", range_m=5.0, near=np.array([[4, 0, 0]]), detectable=True)]
    L = np.zeros((1, 2, 6), np.float32)
    L[0, 0, 2], L[0, 1, 1], L[0, 0, 4] = -1.0, 0.3, 2.0   # "near": p > 0.5 at (x 1, y 1); "post" at x 4
    k = np.zeros((1, 2, 6), np.float32)
    k[0, 0, 2] = 3.0                                  # "near" known only where it reads free
    k[0, 0, 4] = 1.0                                  # "post" known where it reads occupied
    s = metrics.radar_scores(L, t, objects, knowledge=k)
    assert [o["found"] for o in s["objects"]] == [False, True]
    assert s["objects_found"] == 1 and s["detectable_found"] == 1
    assert s["objects"][0]["peak_nats"] == pytest.approx(0.3)           # the peak is what it reads, known or not
    k[0, 1, 1] = 0.5
    assert metrics.radar_scores(L, t, objects, knowledge=k)["objects_found"] == 2
    assert metrics.radar_scores(L, t, objects)["objects_found"] == 2     # without knowledge: as before
