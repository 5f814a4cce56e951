"""radarcl.grid: the voxel-centre convention, sparse bricks, memory, save/load."""

import numpy as np
import pytest

from radarcl.errors import ConfigError, DeviceCapabilityError, FrameFormatError
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import BRICK, BRICK_BYTES, GridSpec, assemble
from radarcl.maps.disk import load_grid, save_grid

SPEC = GridSpec((-2.0, -1.0, 0.5), 0.25, (20, 12, 9))


def test_index_convention_is_floor_with_centres():
    assert np.array_equal(SPEC.world_to_index([-2.0, -1.0, 0.5]), [0, 0, 0])
    assert np.array_equal(SPEC.world_to_index([-1.7501, -0.75, 0.7499]), [0, 1, 0])
    assert np.allclose(SPEC.index_to_world([0, 0, 0]), [-1.875, -0.875, 0.625])
    i = np.array([[3, 4, 5], [19, 11, 8]])
    assert np.array_equal(SPEC.world_to_index(SPEC.index_to_world(i)), i)
    assert np.array_equal(SPEC.world_to_index([-2.01, 0, 0]), [-1, 4, -2])
    assert SPEC.array_shape == (9, 12, 20)


def test_checked_index_names_the_point_outside():
    assert np.array_equal(SPEC.world_to_index_checked([[0.0, 0.0, 1.0]]), [[8, 4, 2]])
    with pytest.raises(ConfigError, match=r"\[3\.0, 0\.0, 1\.0\] lies outside the grid"):
        SPEC.world_to_index_checked([[0.0, 0.0, 1.0], [3.0, 0.0, 1.0]])
    with pytest.raises(ConfigError, match="finite"):
        SPEC.world_to_index_checked([np.nan, 0, 0])


@pytest.mark.parametrize("kwargs, words", [
    (dict(origin_m=(0, 0), voxel_m=0.1, shape=(1, 1, 1)), "origin_m"),
    (dict(origin_m=(0, 0, np.inf), voxel_m=0.1, shape=(1, 1, 1)), "origin_m"),
    (dict(origin_m=(0, 0, 0), voxel_m=0.0, shape=(1, 1, 1)), "voxel_m"),
    (dict(origin_m=(0, 0, 0), voxel_m=0.1, shape=(1, 0, 1)), "shape"),
])
def test_spec_refuses_impossible_grids(kwargs, words):
    with pytest.raises(ConfigError, match=words):
        GridSpec(**kwargs)


def test_bricks_are_allocated_once_in_sorted_order(runtime):
    grid = EvidenceGrid(runtime, SPEC)
    assert grid.n_bricks == 0 and grid.spec.brick_shape == (3, 2, 2)
    slots = grid.allocate([[2, 1, 1], [0, 0, 0], [2, 1, 1]])
    assert slots.tolist() == [1, 0, 1]
    assert grid.allocate([[0, 0, 0], [1, 0, 0]]).tolist() == [0, 2]
    mem = grid.memory()
    assert mem["bricks"] == 3 and mem["sparse_bytes"] == 3 * BRICK_BYTES + grid.table.nbytes
    assert mem["dense_bytes"] == 4 * 20 * 12 * 9
    with pytest.raises(ConfigError, match="brick indices"):
        grid.allocate([[3, 0, 0]])
    # the flat form: the same slots, out-of-table and non-integer indices refused
    assert grid.allocate_index(np.array([0, 1, 1 * 3 * 2 + 1 * 3 + 2])).tolist() == [0, 2, 1]
    for bad in (np.array([-1]), np.array([12]), np.array([0.5])):
        with pytest.raises(ConfigError, match="brick indices"):
            grid.allocate_index(bad)
    assert grid.n_bricks == 3


def test_growth_keeps_data_and_save_load_round_trip(runtime, tmp_path):
    import pyopencl as cl

    grid = EvidenceGrid(runtime, SPEC)
    grid.allocate([[1, 1, 1]])
    values = np.arange(BRICK ** 3, dtype=np.int32).reshape(BRICK, BRICK, BRICK) - 100
    cl.enqueue_copy(runtime.queue, grid.pool, values, is_blocking=True)
    bz, by, bx = np.indices((2, 2, 3)).reshape(3, -1)
    grid.allocate(np.stack([bx, by, bz], 1))            # grows the pool past its first capacity
    keys, data = grid.bricks()
    assert np.array_equal(data[0], values) and not data[1:].any()
    dense = grid.snapshot()
    assert np.array_equal(dense, assemble(SPEC, keys, data))
    assert np.array_equal(dense[8:9, 8:12, 8:16], values[:1, :4, :])   # clipped at the grid's edge
    save_grid(grid, tmp_path / "map.npz")
    loaded = load_grid(runtime, tmp_path / "map.npz")
    assert loaded.spec == SPEC and np.array_equal(loaded.snapshot(), dense)
    assert np.allclose(loaded.probability()[8, 8, 8], 1 / (1 + np.exp(100 / 1024)))


def test_bad_files_are_refused(runtime, tmp_path):
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(FrameFormatError, match="not a radarcl grid"):
        load_grid(runtime, tmp_path / "junk.npz")
    np.savez(tmp_path / "v9.npz", version=9, origin_m=[0, 0, 0], voxel_m=1.0, shape=[8, 8, 8],
             keys=np.zeros((0, 3), np.int32), data=np.zeros((0, 8, 8, 8), np.int32))
    with pytest.raises(FrameFormatError, match="version 9"):
        load_grid(runtime, tmp_path / "v9.npz")


def test_a_grid_too_big_for_the_device_says_what_to_do(runtime):
    huge = GridSpec((0, 0, 0), 0.05, (4096, 4096, 512))          # 32 GiB dense
    with pytest.raises(DeviceCapabilityError, match=r"needs \d+ bricks = [\d.]+ [KMG]iB.*use voxels of at least"):
        EvidenceGrid(runtime, huge, dense=True)
    assert EvidenceGrid(runtime, huge).n_bricks == 0               # sparse: nothing allocated yet
    with pytest.raises(ConfigError, match="brick table"):
        EvidenceGrid(runtime, GridSpec((0, 0, 0), 0.01, (2 ** 14, 2 ** 14, 2 ** 12)))


def test_clear_forgets_evidence_and_fusion_replans(runtime):
    from radarcl.config.stage_config import RadarConfig
    from radarcl.geometry import BeamLattice, BeamModel
    from radarcl.stages.fusion import Fusion

    radar = RadarConfig()
    spec = GridSpec.around((4.0, 0.0, 0.0), (8.0, 8.0, 2.0), 0.25)
    grid = EvidenceGrid(runtime, spec)
    lat = BeamLattice.from_radar(radar)
    f = Fusion(runtime, grid, lat, BeamModel.from_radar(radar), 64, 0.125, 8, 60)
    ev = np.full((lat.n_beams, 64), 500, np.int32)
    f(ev, np.eye(4))
    first = grid.snapshot()
    grid.clear()
    assert grid.n_bricks == 0 and not grid.snapshot().any()
    f(ev, np.eye(4))                       # same pose: the cached plan's slots are stale
    assert np.array_equal(grid.snapshot(), first) and first.max() >= 500
