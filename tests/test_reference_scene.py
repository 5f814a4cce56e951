"""The reference scene: solids (ray hits, exact voxel classes), truth, simulation, recordings,
metrics and the OctoMap-style baseline, each against a brute-force or closed-form answer."""

import math

import numpy as np
import pytest

from radarcl.errors import ConfigError, FrameFormatError
from radarcl.evaluation import metrics
from radarcl.gridspec import GridSpec
from radarcl.io import recording
from radarcl.scene import outdoor
from radarcl.scene.observe import load_observations, observe
from radarcl.scene.shapes import Box, Cylinder, Ground, Sphere

SHAPES = [Sphere((3.0, 0.2, 0.1), 0.7), Cylinder((4.0, -0.3), 0.4, -0.5, 1.2), Box((2.5, -1.0, -0.2), (3.1, 0.4, 0.9))]


def _inside(shape, p):
    """Brute-force membership of points p (n, 3) in the closed solid."""
    if isinstance(shape, Sphere):
        return np.linalg.norm(p - shape.centre_m, axis=1) <= shape.radius_m
    if isinstance(shape, Cylinder):
        return ((np.linalg.norm(p[:, :2] - shape.centre_xy_m, axis=1) <= shape.radius_m)
                & (p[:, 2] >= shape.z0_m) & (p[:, 2] <= shape.z1_m))
    lo, hi = shape.bounds()
    return ((p >= lo) & (p <= hi)).all(axis=1)


@pytest.mark.parametrize("shape", SHAPES, ids=["sphere", "cylinder", "box"])
def test_ray_hits_agree_with_marching(shape):
    """The analytic first hit equals the first of 1 mm steps inside the solid, to 1 mm."""
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(300, 3)) * [0.2, 0.3, 0.3] + [1, 0, 0]
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = np.zeros_like(dirs)
    t, normal = shape.intersect(origins, dirs)
    steps = np.arange(0, 6, 1e-3)
    for o, d, ti, n in zip(origins, dirs, t, normal):
        inside = _inside(shape, o + steps[:, None] * d)
        if not inside.any():
            assert ti == np.inf
            continue
        assert abs(ti - steps[np.argmax(inside)]) <= 1.5e-3
        assert abs(np.linalg.norm(n) - 1) < 1e-9 and n @ d <= 1e-9      # outward, facing the ray


@pytest.mark.parametrize("shape", SHAPES, ids=["sphere", "cylinder", "box"])
def test_voxel_classes_agree_with_dense_sampling(shape):
    """touches / inside against 9^3 sample points per voxel: sampled-inside implies touches,
    inside implies all samples inside, and the exact test never contradicts the samples."""
    spec = GridSpec((1.5, -1.5, -1.0), 0.25, (14, 12, 10))
    idx = np.indices(spec.shape).reshape(3, -1).T
    lo = np.asarray(spec.origin_m) + idx * spec.voxel_m
    touch, inside = shape.classify(lo, lo + spec.voxel_m)
    u = (np.arange(9) + 0.5) / 9
    sub = np.stack(np.meshgrid(u, u, u, indexing="ij"), -1).reshape(-1, 3) * spec.voxel_m
    for i in range(len(lo)):
        s = _inside(shape, lo[i] + sub)
        assert not (s.any() and not touch[i])
        assert not (inside[i] and not s.all())
    assert inside.sum() > 0 and (touch & ~inside).sum() > 0


def test_ground_is_one_occupied_layer_at_any_voxel_size():
    """The grass at z = 0 lies on a face for every voxel that divides 10 m: it belongs to the
    layer above (the grid's half-open convention), the layers below are INTERIOR."""
    scene = outdoor.Scene((outdoor.SceneObject("grass", Ground(0.0), outdoor.GRASS),), (), (0, 0, 1.5))
    for v in (0.1, 0.2, 0.4, 0.3):
        spec = outdoor.paper_grid(v)
        labels = scene.truth(spec)[:, 0, 0]
        z_lo = spec.origin_m[2] + np.arange(spec.shape[2]) * v
        layer = int(np.floor(-spec.origin_m[2] / v + 1e-9))
        assert labels[layer] == outdoor.OCCUPIED and z_lo[layer] <= 1e-9 < z_lo[layer] + v
        assert (labels[:layer] == outdoor.INTERIOR).all() and (labels[layer + 1:] == outdoor.FREE).all()


def test_paper_scene_truth_holds_every_object():
    scene = outdoor.paper_scene()
    spec = outdoor.paper_grid(0.4)
    truth = scene.truth(spec)
    for obj in scene.objects[1:]:
        lo, hi = obj.shape.bounds()
        centre = spec.world_to_index((lo + hi) / 2)
        assert truth[centre[2], centre[1], centre[0]] != outdoor.FREE, obj.name
    assert scene.stand_pose(-14.2)[:3, 3].tolist() == [0.0, 0.0, outdoor.SENSOR_HEIGHT_M]
    with pytest.raises(ConfigError, match="tilt_deg"):
        scene.stand_pose(88.0)


def test_observation_of_one_plate_puts_its_echo_at_its_range():
    """A metal plate 20 m ahead of a level beam (no ground): the strongest bin of the centre
    beam's profile lies within one bin of 20 m, and the same seed gives the same samples."""
    from radarcl import oracle
    from radarcl.config.stage_config import PAPER_RADAR

    plate = outdoor.SceneObject("plate", Box((20.0, -2.0, -1.0), (20.1, 2.0, 4.0)), outdoor.METAL)
    scene = outdoor.Scene((plate,), (), (0.0, 0.0, 1.5))
    a = observe(scene, [-3.0], seed=5)
    b = observe(scene, [-3.0], seed=5)
    assert np.array_equal(a.samples, b.samples) and a.samples.dtype == np.int16
    profile = oracle.range_profile(a.samples[0, 32, 1].astype(float), 1024, output="power")
    spacing = PAPER_RADAR.bin_spacing_m(1024)
    assert abs(np.argmax(profile) * spacing - 20.0) <= spacing


def test_recording_round_trip_and_refusals(tmp_path):
    obs = observe(outdoor.paper_scene(), [-7.2], seed=3)
    path = tmp_path / "rec.npz"
    recording.save(path, obs)
    back = load_observations(path)
    assert np.array_equal(back.samples, obs.samples) and np.array_equal(back.poses, obs.poses)
    assert back.seed == 3 and np.array_equal(back.tilts_deg, obs.tilts_deg)
    assert recording.load(path).sensor == "paper"
    with pytest.raises(FrameFormatError, match="exists"):
        recording.save(path, obs, overwrite=False)
    other = tmp_path / "other.npz"
    recording.save(other, recording.Recording(obs.samples[:, :32], obs.poses, "half-paper"))
    with pytest.raises(FrameFormatError, match=r"frames are \(32, 4, 256\) int16; the paper radar's are"):
        load_observations(other)
    bad = tmp_path / "bad.npz"
    np.savez(bad, version=2, samples=obs.samples)
    with pytest.raises(FrameFormatError, match="missing"):
        recording.load(bad)
    bad.write_bytes(b"\x00" * 10)
    with pytest.raises(FrameFormatError, match="not a readable"):
        recording.load(bad)
    assert not list(tmp_path.glob(".*.tmp")), "a temporary file was left behind"


def test_roc_auc_equals_the_pairwise_definition():
    rng = np.random.default_rng(0)
    scores = rng.integers(-5, 6, 400)          # many ties
    labels = rng.random(400) < 0.3
    pos, neg = scores[labels], scores[~labels]
    pairs = (pos[:, None] > neg[None]).mean() + 0.5 * (pos[:, None] == neg[None]).mean()
    assert metrics.roc_auc(scores, labels) == pytest.approx(pairs, abs=1e-12)
    assert metrics.roc_auc(np.zeros(10), np.arange(10) < 4) == 0.5
    assert math.isnan(metrics.roc_auc([1, 2], [True, True]))


def test_metrics_on_a_hand_made_map():
    """A 1-D row of voxels: every count checked by hand."""
    truth = np.array([0, 0, 1, 0, 0, 2, 1, 0], np.uint8).reshape(1, 1, 8)
    observed = np.array([1, 1, 1, 1, 1, 1, 1, 0], bool).reshape(1, 1, 8)
    log_odds = np.array([-2, -1, 3, 2, -1, 5, -1, 9], float).reshape(1, 1, 8)
    m = metrics.evaluate(log_odds, truth, observed)
    # scored: voxels 0-4 and 6 (5 is INTERIOR, 7 unobserved); occupied 2 and 6; called occupied 2, 3
    assert m["observed_voxels"] == 6 and m["observed_occupied"] == 2
    assert m["iou"] == pytest.approx(1 / 3)                 # {2} of {2, 3, 6}
    assert m["iou_tol1"] == pytest.approx(2 / 3)             # 3 is next to 2: a hit; 6 has no called voxel near
    assert m["false_free"] == pytest.approx(1 / 2) and m["false_occupied"] == pytest.approx(1 / 4)
    assert m["coverage"] == 1.0
    p = 1 / (1 + np.exp(-np.array([-2, -1, 3, 2, -1, -1.0])))
    y = np.array([0, 0, 1, 0, 0, 1])
    assert m["brier"] == pytest.approx(np.mean((p - y) ** 2))
    assert m["auc"] == pytest.approx(metrics.roc_auc([-2, -1, 3, 2, -1, -1], y.astype(bool)))




def test_a_still_radar_sees_the_same_speckle_at_every_tilt():
    """Rays come from one lattice fixed in the world, and a scatterer's phase is fixed per
    surface cell: two tilts whose beams overlap share rays, echo ranges and phases; another
    recording (another salt) has other scatterers."""
    from radarcl.config.stage_config import PAPER_RADAR
    from radarcl.scene import observe as ob

    scene = outdoor.paper_scene()
    a = ob.observe_frame(scene, scene.stand_pose(-9.2), salt=5)
    b = ob.observe_frame(scene, scene.stand_pose(-8.2), salt=5)      # one degree up: beams overlap
    c = ob.observe_frame(scene, scene.stand_pose(-9.2), salt=6)
    assert all(np.array_equal(x, y) for x, y in zip(a, ob.observe_frame(scene, scene.stand_pose(-9.2), salt=5)))
    # elevation beam 1 at tilt -9.2 points where beam 0 at -8.2 points... within 1 deg: shared echoes
    shared = [set(zip(a[1][i * 4 + 1].round(9), a[2][i * 4 + 1].round(9))) &
              set(zip(b[1][i * 4 + 0].round(9), b[2][i * 4 + 0].round(9))) for i in range(0, 64, 8)]
    assert min(len(s) for s in shared) > 20
    other = set(zip(c[1][1].round(9), c[2][1].round(9))) & set(zip(a[1][1].round(9), a[2][1].round(9)))
    assert len(other) <= 1                                           # (a miss's filler range, phase 0)
    u = ob.hash_uniform(np.arange(30000)[:, None], 1)
    assert 0 <= u.min() and u.max() < 1 and abs(u.mean() - 0.5) < 0.01
    assert PAPER_RADAR.n_elevation == 4
