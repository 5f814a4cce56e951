"""The three baselines (radarcl/evaluation/baseline.py): OctoMap read back exactly as
octomap-python holds it, on grids whose origin is not a multiple of the voxel; the ground prior;
raw intensity as evidence."""

import math

import numpy as np
import pytest

from radarcl import logodds
from radarcl.evaluation import baseline
from radarcl.gridspec import GridSpec

try:                                  # the OctoMap baseline is part of the suite: a broken install fails it
    import octomap  # noqa: F401 - radarcl.evaluation.baseline imports it where it is used
except ImportError as exc:
    pytest.fail(f"octomap-python does not import ({exc}): the OctoMap baseline's voxel-by-voxel check cannot run; "
                "install radarcl[export] (make test does)", pytrace=False)


def test_one_ray_as_octomap_defines_it():
    """One point at 2.03 m along x on a 0.1 m grid starting at -0.05 m (voxel 20): the hit takes
    logit(0.7), the 20 voxels before it logit(0.4), nothing else changes; scans clamp."""
    spec = GridSpec((-0.05, -0.15, -0.15), 0.1, (40, 3, 3))
    scan = [((0.0, 0.0, 0.0), np.array([[2.03, 0.0, 0.0]]))]
    L = baseline.octomap(spec, scan)
    row = L[1, 1]
    assert np.count_nonzero(L) == 21
    assert row[20] == pytest.approx(math.log(0.7 / 0.3), rel=1e-6)
    assert np.allclose(row[:20], math.log(0.4 / 0.6)) and (row[21:] == 0).all()
    L = baseline.octomap(spec, scan * 30)
    assert L[1, 1, 20] == pytest.approx(math.log(0.971 / 0.029), rel=1e-5)
    assert L[1, 1, 0] == pytest.approx(math.log(0.1192 / 0.8808), rel=1e-5)


def test_the_read_back_is_what_octomap_holds_voxel_by_voxel():
    rng = np.random.default_rng(2)
    spec = GridSpec((-2.3, -3.1, -1.7), 0.2, (40, 30, 20))          # origin off the multiples of 0.2
    scans = []
    for _ in range(3):
        origin = rng.uniform([-1, -1, 0], [0, 1, 1])
        scans.append((origin, origin + rng.normal(0, 1, (200, 3)) * [2.5, 2.0, 0.8]))
    tree = baseline.octree(spec, scans)
    L = baseline.read_back(tree, spec)
    idx = np.argwhere(np.ones(spec.array_shape, bool))[:, ::-1]
    centres = spec.index_to_world(idx) - np.asarray(spec.origin_m)
    want = np.zeros(len(idx), np.float32)
    for n, c in enumerate(centres):
        node = tree.search(c)
        if node is not None:
            try:
                want[n] = node.getValue()
            except Exception:                                   # octomap-python's empty node
                pass
    got = L[idx[:, 2], idx[:, 1], idx[:, 0]]
    assert np.count_nonzero(want) > 1000
    assert np.array_equal(got, want)


def test_the_ground_prior_uses_no_radar_data():
    spec = GridSpec((0.0, 0.0, -1.0), 0.2, (2, 2, 10))
    L = baseline.prior_only(spec)
    layers = L[:, 0, 0]
    z = -1.0 + (np.arange(10) + 0.5) * 0.2
    assert layers[np.abs(z) < 0.2].tolist() == [1.0, 1.0]                # the two layers at the plane
    assert layers[np.abs(np.abs(z) - 0.3) < 1e-9].tolist() == [-1.0, -1.0]
    assert (layers[np.abs(z) > 0.4] == -2.0).all()


def test_raw_evidence_is_one_nat_per_10_db_above_10_db():
    noise = np.full(100, 1.0)
    profile = noise * math.log(2.0)                  # median / ln 2 = 1: the noise estimate
    profile[10], profile[20], profile[30] = 10 ** 1.5, 10 ** 1.0, 10 ** 5
    ev = baseline.raw_evidence(profile[None])[0] / logodds.SCALE
    assert ev[10] == pytest.approx(0.5, abs=1e-3) and ev[20] == pytest.approx(0.0, abs=1e-3)
    assert ev[30] == 1.0 and ev[0] == pytest.approx(-1.0)        # clipped; noise alone is -1 nat


def test_raw_intensity_under_a_detection_statistics_configuration_is_the_same_map(runtime):
    """The raw-intensity baseline fuses its own evidence per bin: a configuration of the
    detection-statistics model (whose fusion reads node tables, not evidence) gives the same map
    as eq. 12's, bit for bit, instead of a shape error (pipeline.evidence_config)."""
    from radarcl.config.presets import paper_config
    from radarcl.scene import generator
    from radarcl.scene.observe import observe

    scene, _ = generator.generate(201)
    obs = observe(scene, [-5.2], seed=201)
    eq12 = baseline.raw_intensity(runtime, obs, paper_config(0.8))
    detstats = baseline.raw_intensity(runtime, obs, paper_config(0.8, {"interpret.model": "detstats"}))
    assert np.array_equal(eq12, detstats) and (eq12 > 0).any() and (eq12 < 0).any()
