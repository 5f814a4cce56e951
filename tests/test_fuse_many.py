"""Fleets: recordings fused on Dask workers and merged there brick by brick (partitioned by key)
give the map of one process, bit for bit, with 1, 2 and 3 workers and in any order; mismatched inputs are refused
before any work."""

import numpy as np
import pytest

from radarcl.config import mapconfig
from radarcl.errors import ConfigError, FrameFormatError
from radarcl.gridspec import assemble
from radarcl.jobs import fuse_many
from radarcl.maps.disk import read
from radarcl.pipeline import Mapping


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    from radarcl.io import recording
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    root = tmp_path_factory.mktemp("fleet")
    scene, paths = paper_scene(), []
    for i, tilts in enumerate([(-11.2,), (-7.2, -5.2), (-3.2,)]):
        paths.append(root / f"run{i}.npz")
        recording.save(paths[-1], observe(scene, tilts, seed=10 + i))
    return paths


def test_merged_map_equals_one_process(runtime, recordings, tmp_path):
    config = mapconfig.resolve("paper", flags={"grid.voxel_m": 0.5})
    single = Mapping.from_config(runtime, config=config)
    from radarcl.io import recording

    for path in recordings:
        rec = recording.load(path)
        for frame, pose in zip(rec.frames, rec.poses):
            single.fuse(frame, pose)
    want = single.snapshot()
    assert (want > 0).any() and (want < 0).any()
    for workers, order in ((1, [0, 1, 2]), (2, [2, 0, 1]), (3, [1, 2, 0])):
        out = tmp_path / f"map{workers}.npz"
        result = fuse_many.run(config, [recordings[i] for i in order], out, workers=workers, report=lambda _: None)
        spec, keys, data = read(out)
        assert spec == config.grid_spec() and result["inputs"] == 3
        assert result["partitions"] == min(3 * workers, -(-result["bricks"] // 256))    # merged on the workers
        assert np.array_equal(assemble(spec, keys, data), want), f"{workers} workers differ from one process"


def test_a_detection_statistics_fleet_merges_its_knowledge_as_one_process(runtime, recordings, tmp_path):
    """With the detection-statistics model each worker's map carries the knowledge channel and
    the merge sums it too: the merged map's sums, knowledge and looks are one process's, bit for
    bit, and it reads with the configuration's reading."""
    from radarcl.io import recording
    from radarcl.maps.map import Map

    config = mapconfig.resolve("paper", flags={"grid.voxel_m": 0.5, "interpret.model": "detstats"})
    single = Mapping.from_config(runtime, config=config)
    for path in recordings:
        rec = recording.load(path)
        for frame, pose in zip(rec.frames, rec.poses):
            single.fuse(frame, pose)
    grid = single.grid
    out = tmp_path / "fleet.rcmap"
    fuse_many.run(config, recordings[::-1], out, workers=2, report=lambda _: None)
    m = Map.open(out)
    spec = config.grid_spec()
    assert m.has_knowledge and m.reading == config.model_params().reading
    for mine, theirs in ((m.data, grid.snapshot()), (m.knowledge, grid.knowledge_snapshot()),
                         (m.looks, grid.knowledge_snapshot("looks"))):
        assert np.array_equal(assemble(spec, m.keys, mine), theirs) and theirs.any()


def test_mismatched_inputs_are_refused_before_any_work(recordings, tmp_path):
    config = mapconfig.resolve("ti-xwr-openradar")
    with pytest.raises(FrameFormatError, match="frames are \\(64, 4, 256\\) int16; sensor ti-xwr-openradar expects"):
        fuse_many.run(config, recordings[:1], tmp_path / "m.npz", report=lambda _: None)
    with pytest.raises(ConfigError, match="an input appears twice"):
        fuse_many.run(mapconfig.resolve("paper"), [recordings[0], recordings[0]], tmp_path / "m.npz",
                      report=lambda _: None)
    assert not (tmp_path / "m.npz").exists()


def test_cli_fuse_many_writes_a_store(recordings, tmp_path, capsys):
    from radarcl.cli import main

    out = tmp_path / "fleet.rcmap"
    assert main(["fuse-many", *map(str, recordings[:2]), "--voxel", "0.8", "--workers", "1", "--out", str(out)]) == 0
    assert "merged in" in capsys.readouterr().out
    from radarcl.maps import store

    manifest = store.read_manifest(out)
    assert [i["path"] for i in manifest["provenance"]["inputs"]] == [str(p) for p in recordings[:2]]
    assert all(len(i["sha256"]) == 64 for i in manifest["provenance"]["inputs"])
