"""`bench quality`'s sweep (radarcl/evaluation/quality.py): the Pareto fronts, reading a map of
another voxel size on the fixed voxel set against a float64 loop over world coordinates, and the
default model's configurations it sweeps."""

import itertools

import numpy as np
import pytest

from radarcl.config.presets import paper_config
from radarcl.errors import ConfigError
from radarcl.evaluation import quality
from radarcl.evaluation.tuning import TUNED
from radarcl.gridspec import GridSpec


def test_the_front_keeps_only_runs_no_other_beats_in_both_time_and_score():
    runs = [dict(ms_per_frame=10.0, auc=0.9), dict(ms_per_frame=20.0, auc=0.95), dict(ms_per_frame=30.0, auc=0.93),
            dict(ms_per_frame=5.0, auc=0.5), dict(ms_per_frame=20.0, auc=0.95), dict(ms_per_frame=20.0, auc=0.94),
            dict(ms_per_frame=1.0, auc=None)]
    # run 3 is slower and worse than run 2; run 5 is the same point as run 2 (no second point);
    # run 6 ties run 2 in time and is worse; run 7 has no score
    assert quality.pareto(runs, "auc") == [True, True, False, True, False, False, False]
    assert quality.pareto(runs, "auc", higher=False) == [False, False, False, True, False, False, False]


def _oracle_read(spec, target, log_odds, knowledge):
    """Each target voxel, in float64 world coordinates: a coarser-or-equal map's voxel holding its centre;
    for a finer map, along each axis the map voxels whose centres lie inside it (none: the nearest),
    and of those the first of the highest log-odds."""
    nz, ny, nx = target.shape[::-1]
    out, known = np.zeros((nz, ny, nx)), np.zeros((nz, ny, nx))
    o, t = np.asarray(spec.origin_m, float), np.asarray(target.origin_m, float)
    for z, y, x in itertools.product(range(nz), range(ny), range(nx)):
        low = t + np.array([x, y, z]) * target.voxel_m
        if spec.voxel_m >= target.voxel_m:
            i = np.clip(np.floor((low + target.voxel_m / 2 - o) / spec.voxel_m).astype(int), 0,
                        np.asarray(spec.shape) - 1)
            out[z, y, x], known[z, y, x] = log_odds[i[2], i[1], i[0]], knowledge[i[2], i[1], i[0]]
            continue
        axes = []
        for a in range(3):
            centres = o[a] + (np.arange(spec.shape[a]) + 0.5) * spec.voxel_m
            inside = np.flatnonzero((centres > low[a]) & (centres < low[a] + target.voxel_m))
            axes.append(inside if inside.size else [np.argmin(np.abs(centres - low[a] - target.voxel_m / 2))])
        best = None
        for i in itertools.product(*axes):
            v = log_odds[i[2], i[1], i[0]]
            if best is None or v > best[0]:
                best = (v, knowledge[i[2], i[1], i[0]])
        out[z, y, x], known[z, y, x] = best
    return out, known


@pytest.mark.parametrize("voxel_m, origin, shape", [(0.4, (-1.0, -0.6, -0.2), (4, 3, 2)),
                                                    (0.6, (-1.0, -0.6, -0.2), (3, 2, 2)),
                                                    (0.2, (-1.0, -0.6, -0.2), (6, 5, 3)),
                                                    (0.1, (-1.0, -0.6, -0.2), (12, 9, 5)),
                                                    (0.1, (-0.8, -0.6, -0.2), (10, 8, 5)),
                                                    (0.05, (-1.0, -0.6, -0.2), (24, 20, 12))])
def test_a_map_of_any_voxel_reads_on_the_voxel_set_as_the_float64_loop_says(voxel_m, origin, shape):
    target = GridSpec((-1.0, -0.6, -0.2), 0.2, (6, 5, 3))
    spec = GridSpec(origin, voxel_m, shape)
    rng = np.random.default_rng(7)
    log_odds = rng.normal(0, 2, shape[::-1]).astype(np.float32)
    knowledge = rng.integers(0, 4, shape[::-1]).astype(np.float32)
    got, known = quality.on_voxel_set(spec, target, log_odds, knowledge)
    want, want_known = _oracle_read(spec, target, log_odds, knowledge)
    assert got.shape == known.shape == (3, 5, 6) and got.dtype == np.float32
    np.testing.assert_array_equal(got, want)          # a choice of stored values: exact
    np.testing.assert_array_equal(known, want_known)
    alone, none = quality.on_voxel_set(spec, target, log_odds)
    assert none is None and np.array_equal(alone, got)


def test_a_finer_voxel_that_does_not_divide_the_set_s_is_refused_in_one_sentence():
    target = GridSpec((0.0, 0.0, 0.0), 0.2, (4, 4, 4))
    with pytest.raises(ConfigError, match="cannot be read on a set of 0.2 m voxels: expected a finer voxel that"):
        quality.on_voxel_set(GridSpec((0.0, 0.0, 0.0), 0.15, (6, 6, 6)), target, np.zeros((6, 6, 6), np.float32))
    with pytest.raises(ConfigError, match="on a lattice through its origin"):
        quality.on_voxel_set(GridSpec((0.05, 0.0, 0.0), 0.1, (8, 8, 8)), target, np.zeros((8, 8, 8), np.float32))
    assert quality.voxel_readable(0.4, 0.2) and quality.voxel_readable(0.1, 0.2) and quality.voxel_readable(0.3, 0.2)
    assert not quality.voxel_readable(0.15, 0.2)
    with pytest.raises(ConfigError, match="voxel 0.15 m cannot be scored on the 0.2 m voxel set: expected a voxel"):
        quality.check_voxels(0.2, (0.4, 0.15))


def test_the_sweep_runs_each_pipeline_once_and_reads_the_default_map_in_other_ways():
    reference, default = paper_config(0.2, TUNED), paper_config(0.2)
    runs = quality.variants(reference, (0.4, 0.2, 0.1), default)
    keys = [tuple(sorted(c.values.items())) for _, c in runs]
    assert len(keys) == len(set(keys))
    mine = [(d, c) for d, c in runs if d.startswith("default model")]
    assert mine[0] == ("default model", default)
    budget = {(c["sensor_model.evidence"], c["range_fft.n_fft"], c["grid.voxel_m"])
              for d, c in mine if d == "default model: budget"}
    assert budget == {("detection", 256, 0.2), ("detection", 512, 0.2), ("detection", 1024, 0.4)}
    # a look limit changes only the reading: never a pipeline run of its own
    assert all(c["sensor_model.look_limit"] == default["sensor_model.look_limit"] for _, c in mine)
    read = quality.readings(default)
    assert [c["sensor_model.look_limit"] for _, _, c, _ in read] == [1.0, 4.0, 16.0, 2.0]
    assert read[-1][1] == quality.KNOWLEDGE_OFF and read[-1][3] is False
