"""Generated scenes (radarcl/scene/generator.py): seeded, a training and a held-out split that do
not overlap, faces off the voxel lattices, sloped terrain with exact truth, and the scenes bench
end to end on one small scene."""

import numpy as np
import pytest

from radarcl.gridspec import GridSpec
from radarcl.scene import generator
from radarcl.scene.outdoor import GRASS, INTERIOR, OCCUPIED, Scene, SceneObject
from radarcl.scene.shapes import Box, Slope


def test_scenes_are_seeded_and_the_splits_are_fixed_and_disjoint():
    a, da = generator.generate(201)
    b, db = generator.generate(201)
    assert a == b and da == db
    assert not set(generator.TRAIN_SEEDS) & set(generator.HELD_OUT_SEEDS)
    kinds = {generator.generate(s)[1]["terrain"] for s in generator.TRAIN_SEEDS + generator.HELD_OUT_SEEDS}
    assert kinds == {"flat", "sloped", "uneven"}
    heights = [generator.generate(s)[1]["sensor_height_m"] for s in generator.HELD_OUT_SEEDS]
    assert all(1.0 <= h <= 3.0 for h in heights)


def test_box_faces_stay_off_the_voxel_lattices():
    for seed in generator.TRAIN_SEEDS + generator.HELD_OUT_SEEDS:
        scene, _ = generator.generate(seed)
        for obj in scene.objects:
            if isinstance(obj.shape, Box):
                faces = np.concatenate([obj.shape.lo_m, obj.shape.hi_m])
                off = np.abs(faces / generator.LATTICE_M - np.round(faces / generator.LATTICE_M)) * generator.LATTICE_M
                assert (off > 4e-4).all(), (seed, obj.name, faces)


def test_sloped_terrain_truth_is_exact():
    """Each voxel's label against the plane's height at its four top/bottom corners."""
    slope = Slope(0.1317, 0.0513, -0.0297)        # no corner exactly on a voxel face (FACE_EPS decides those)
    scene = Scene((SceneObject("ground", slope, GRASS),), (), (0.0, 0.0, 2.0))
    spec = GridSpec((-3.1, -2.7, -1.3), 0.2, (30, 25, 14))
    labels = scene.truth(spec)
    idx = np.argwhere(np.ones(spec.array_shape, bool))[:, ::-1]
    lo = np.asarray(spec.origin_m) + idx * spec.voxel_m
    corners = [slope.height(lo[:, 0] + dx, lo[:, 1] + dy) for dx in (0, 0.2) for dy in (0, 0.2)]
    top, bottom = np.max(corners, axis=0), np.min(corners, axis=0)
    want = np.where(lo[:, 2] + 0.2 <= bottom, INTERIOR, np.where(lo[:, 2] <= top, OCCUPIED, 0))
    assert np.array_equal(labels[idx[:, 2], idx[:, 1], idx[:, 0]], want)
    # a ray straight down from above meets the plane at its height
    t, _ = slope.intersect(np.array([[1.0, 1.0, 5.0]]), np.array([[0.0, 0.0, -1.0]]))
    assert t[0] == pytest.approx(5.0 - slope.height(1.0, 1.0))


def test_the_scenes_bench_scores_every_map_and_baseline(runtime):
    from radarcl.bench import scenes

    r = scenes.run(runtime, [201], voxel_m=0.8)
    names = set(r["mean"])
    assert {"tuned", "paper constants", "baseline: prior_only", "baseline: raw_intensity", "baseline: octomap"} <= names
    for m in r["mean"].values():
        assert {"auc_detectable", "auc_obstacles", "false_free", "ece", "objects_found", "ece_occupied",
                "occupied_calls"} <= set(m)
    assert r["scenes"][0]["classes"]["detectable"] > 0
    lines = scenes.format_table(r)
    assert any("scene 201" in line for line in lines) and "ECEocc" in lines[1] and "occ-n" in lines[1]
    # what the default map calls occupied: counted over the scene, its calibration in the table
    detstats = r["mean"]["detection statistics"]
    assert detstats["occupied_calls"] == r["scenes"][0]["maps"]["detection statistics"]["occupied_calls"] > 0
    row = next(line for line in lines if line.strip().startswith("detection statistics "))
    assert row.split()[-1] == str(detstats["occupied_calls"]) and row.split()[-2] == f"{detstats['ece_occupied']:.3f}"
    # an object with a DETECTABLE surface voxel is one a perfect detector finds: its bin's +1 nat
    # reaches the voxel; the others are seen only WEAK
    oracle = r["mean"]["oracle detections, free 0"]
    assert 0 < oracle["detectable_total"] <= oracle["objects_total"]
    assert oracle["detectable_found"] == oracle["detectable_total"]
