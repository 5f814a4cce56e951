"""Real data without lidar (radarcl/bench/heldout_scans.py): the map of the even Oxford scans
predicts the CFAR detections of the odd ones; scores by hand; the baselines from the same run."""

import math

import numpy as np
import pytest

from radarcl.bench import heldout_scans as hs


def test_scores_by_hand():
    L = np.array([2.0, -1.0, 0.0, 0.0])
    y = np.array([True, False, True, False])
    s = hs.score(L, y)
    # pairs (detected, not): (2, -1) win, (2, 0) win, (0, -1) win, (0, 0) tie -> 3.5 / 4
    assert s["auc"] == pytest.approx(3.5 / 4)
    p = 1 / (1 + np.exp(-L))
    want = np.mean([math.log(p[0]), math.log(1 - p[1]), math.log(0.5), math.log(0.5)])
    assert s["log_likelihood"] == pytest.approx(want) and s["coverage"] == 0.5 and s["detected"] == 2


def test_the_map_of_some_scans_predicts_the_detections_of_the_others(runtime, shared_data):
    from radarcl.config import mapconfig

    r = hs.run(runtime, mapconfig.resolve("navtech-cts350x"), shared_data / "navtech_oxford")
    res = r["results"]
    assert set(r["train"]).isdisjoint(r["held_out"]) and len(r["held_out"]) >= 4
    assert res["baseline: no map"]["log_likelihood"] == pytest.approx(math.log(0.5))
    assert res["baseline: no map"]["auc"] == 0.5 and res["baseline: detection rate"]["auc"] == 0.5
    bins = {s["bins"] for s in res.values()}
    assert len(bins) == 1 and bins.pop() > 10 ** 6                     # every predictor on the same bins
    assert res["eq. 12"]["auc"] > 0.55 and res["eq. 12"]["coverage"] > 0.9
    assert res["map"]["auc"] > 0.55 and 0.1 < res["map"]["coverage"] < 0.5    # the default model knows a part
    assert any("predicts the CFAR detections" in line for line in hs.format_table(r))
    # the outcomes come from the profile's own detector: a map with another CFAR is judged on them too
    other = hs.run(runtime, mapconfig.resolve("navtech-cts350x", flags={"cfar.kind": "so", "cfar.pfa": 0.01}), shared_data / "navtech_oxford")
    assert other["results"]["map"]["detected"] == res["map"]["detected"]
    assert other["outcome_detector"] == r["outcome_detector"]
