"""Every example of the hostile corpus that was an "unexpected error" (exit 70), a raw exception from the
API, a hang, a silent wrong answer, an overwrite or a leftover: each now a sentence (exit 2),
a right answer, or nothing left behind."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from radarcl.cli import main
from radarcl.errors import RadarclError


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    from radarcl.io import recording
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    path = tmp_path_factory.mktemp("rec") / "rec.npz"
    recording.save(path, observe(paper_scene(), (-9.2,), seed=1))
    return path


@pytest.fixture(scope="module")
def small_map(tmp_path_factory):
    from radarcl.gridspec import GridSpec
    from radarcl.maps import npz

    path = tmp_path_factory.mktemp("map") / "m.npz"
    keys = np.array([[0, 0, 0], [1, 0, 0]], np.int32)
    npz.write(path, GridSpec((0.0, 0.0, 0.0), 0.5, (16, 8, 8)), keys, np.full((2, 8, 8, 8), 3000, np.int32))
    return path


def sentence(capsys, argv, status=2):
    """Run the CLI; assert its status and one error line, never a bug's exit 70 or a traceback."""
    got = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert got == status, (argv, got, err)
    assert "unexpected error" not in err and "Traceback" not in err
    return err


@pytest.mark.parametrize("key,value", [("tilts_deg", "abc"), ("seed", [1, 2, 3]), ("rays_per_beam", "x"),
                                       ("n_clipped", [1.5, 2.0]), ("physics", "p"), ("sensor", ["paper", "x"]),
                                       ("version", [2, 2]), ("seed", 1.5)])
def test_recording_metadata_of_the_wrong_kind(rec, tmp_path, capsys, key, value):
    bad = tmp_path / "bad.npz"
    z = dict(np.load(rec))
    z[key] = np.asarray(value)
    np.savez(bad, **z)
    err = sentence(capsys, ["fuse", bad, "--out", tmp_path / "m.npz", "--voxel", "0.4", "--no-report",
                            "--no-progress"])
    assert key in err and not (tmp_path / "m.npz").exists()


def test_a_complex_pose_is_refused_not_truncated(rec, tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    z = dict(np.load(rec))
    z["poses"] = z["poses"] + 1j
    np.savez(bad, **z)
    assert "real numbers" in sentence(capsys, ["fuse", bad, "--out", tmp_path / "m.npz", "--no-report"])


@pytest.mark.parametrize("text,says", [
    ("[grid]\nvoxel_m = " + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply"),
    ("[defaults]\nfoo = 1\n", "unknown entry"),
])
def test_configurations_that_used_to_be_bugs(tmp_path, capsys, text, says):
    path = tmp_path / "c.toml"
    path.write_text(text)
    assert says in sentence(capsys, ["config", "show", "--config", path])


@pytest.mark.parametrize("text,says", [
    ('name = "x"\nextends = "paper"\n[defaults]\nfoo = 1\n', "holds tables [defaults.<section>]"),
    ('name = "x"\nextends = "paper"\n[waveform]\nbandwidth_hz = 1e-300\n', "bandwidth_hz must lie in"),
    ('name = "x"\nextends = "paper"\n[beams]\nn_azimuth = ' + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply"),
])
def test_profiles_that_used_to_be_bugs(tmp_path, capsys, text, says):
    path = tmp_path / "p.toml"
    path.write_text(text)
    assert says in sentence(capsys, ["sensors", path])


def test_an_extends_chain_of_1500(tmp_path, capsys):
    for i in range(1500):
        nxt = f'extends = "{tmp_path}/p{i + 1}.toml"\n' if i < 1499 else 'extends = "paper"\n'
        (tmp_path / f"p{i}.toml").write_text(f'name = "p{i}"\n' + nxt)
    assert "more than 16 deep" in sentence(capsys, ["sensors", tmp_path / "p0.toml"])


def test_a_configuration_that_is_a_pipe_is_refused_at_once(tmp_path, capsys):
    fifo = tmp_path / "c.toml"
    os.mkfifo(fifo)
    start = time.monotonic()
    assert "a pipe or socket" in sentence(capsys, ["config", "show", "--config", fifo])
    os.mkfifo(tmp_path / "s.rcs")
    assert "is a pipe" in sentence(capsys, ["replay", tmp_path / "s.rcs", "--out", tmp_path / "m.npz"])
    assert time.monotonic() - start < 10


@pytest.mark.parametrize("to", ["ply", "mesh", "octomap", "costmap"])
def test_a_nan_threshold_is_refused_not_an_empty_file(small_map, tmp_path, capsys, to):
    out = tmp_path / ("x.bt" if to == "octomap" else "x.pgm" if to == "costmap" else "x.ply")
    assert "must be finite numbers [nat]" in sentence(capsys, ["export", small_map, "--to", to, "--out", out,
                                                                "--threshold", "nan"])
    assert not out.exists()


def test_a_costmap_yaml_out_is_refused_before_anything_is_written(small_map, tmp_path, capsys):
    err = sentence(capsys, ["export", small_map, "--to", "costmap", "--out", tmp_path / "cm.yaml"])
    assert "give --out" in err and "cm.pgm" in err and not list(tmp_path.iterdir())


def test_emulate_frame_period_fuse_many_scheduler_calibrate_seeds(rec, tmp_path, capsys):
    sentence(capsys, ["emulate", rec, "--pty", "--frame-period", "1e300"])
    assert "cannot reach the Dask scheduler" in sentence(capsys, ["fuse-many", rec, "--out", tmp_path / "m.npz",
                                                                  "--scheduler", "not an address"])
    with pytest.raises(SystemExit):                    # argparse: a usage line and the reason, exit 2
        main(["calibrate", "--seeds", "-1"])
    assert "must lie in [0, 4294967295]" in capsys.readouterr().err
    assert "appears twice" in sentence(capsys, ["calibrate", "--seeds", "1", "1", "1"])


def test_a_grid_origin_of_1e300_is_refused(rec, tmp_path, capsys):
    assert "local frame" in sentence(capsys, ["fuse", rec, "--out", tmp_path / "m.npz", "--no-report",
                                              "--set", "grid.origin_m=[1e300, 0, 0]"])


def api(fn):
    """The outcome of a Python API call: 'ok', or 'error' for a RadarclError (anything else fails)."""
    try:
        fn()
    except RadarclError as exc:
        assert str(exc)
        return "error"
    return "ok"


def test_absurd_api_arguments_get_a_sentence(runtime, small_map):
    from radarcl.config import mapconfig
    from radarcl.gridspec import GridSpec
    from radarcl.maps.map import Map
    from radarcl.pipeline import Mapping
    from radarcl.stages.range_fft import RangeFFT

    m = Map.open(small_map)
    for fn in (lambda: RangeFFT(runtime, (1,), 256, 2 ** 40), lambda: GridSpec((0, 0, 0), 0.5, None),
               lambda: GridSpec("abc", 0.5, (8, 8, 8)), lambda: GridSpec((1e300, 0, 0), 0.5, (8, 8, 8)),
               lambda: m.slice(float("nan")), lambda: m.slice(None), lambda: m.occupied(float("nan")),
               lambda: m.units_at(np.array([[1j, 0, 0]])), lambda: Map.open(None),
               lambda: Mapping.from_config(runtime, None, 5), lambda: mapconfig.resolve("paper", None, [1, 2]),
               lambda: RangeFFT(runtime, (1,), 256, 1024, dtype="nonsense")):
        assert api(fn) == "error"


def test_numpy_scalars_are_numbers(runtime):
    from radarcl.config import mapconfig
    from radarcl.config.stage_config import CfarConfig, InterpretConfig, RadarConfig

    assert CfarConfig(pfa=np.float32(0.01)).pfa == np.float32(0.01)
    assert InterpretConfig(k_occ=np.float32(1.0)) and RadarConfig(bandwidth_hz=np.float32(3e8), n_samples=np.int64(256))
    spec = mapconfig.resolve("paper", program={"grid.voxel_m": np.float32(0.5), "cfar.pfa": np.float64(1e-3)}).grid_spec()
    assert spec.voxel_m == 0.5


def test_fuse_many_leaves_no_dask_scratch_space(rec, tmp_path, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    import dask

    before = dask.config.get("temporary-directory", None)
    assert main(["fuse-many", str(rec), "--out", "m.npz", "--voxel", "0.4", "--workers", "1"]) == 0
    assert sorted(p.name for p in work.iterdir()) == ["m.npz"]
    # the run's scratch setting does not outlive it: a later cluster, from another directory, would
    # recreate the removed (relative) scratch there
    assert dask.config.get("temporary-directory", None) == before


def test_a_report_killed_mid_way_is_cleaned_by_the_next_run(rec, tmp_path):
    """kill -9 while the report's figures are written: the next run of the same page removes
    what the killed one left (a private directory beside the page, never a tmpXXXX in /tmp)."""
    env = dict(os.environ, TMPDIR=str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    out = tmp_path / "m.npz"
    proc = subprocess.Popen([sys.executable, "-m", "radarcl", "fuse", str(rec), "--out", str(out), "--voxel", "0.4",
                             "--no-progress"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    work = []
    while proc.poll() is None and time.monotonic() < deadline and not work:
        work = list(tmp_path.glob(".m.html.work.*.tmp/top.png")) + list((tmp_path / "tmp").rglob("top.png"))
        time.sleep(0.002)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert work, "the report's figure never appeared while the report was written"
    assert main(["fuse", str(rec), "--out", str(out), "--voxel", "0.4", "--no-progress", "--force"]) == 0
    assert not list(tmp_path.glob(".*.tmp")) and not list((tmp_path / "tmp").iterdir())


def test_force_replaces_a_bag_only_when_it_holds_nothing_else(small_map, tmp_path, capsys):
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bag / "NOTES.txt").write_text("keep me")
    sentence(capsys, ["export", small_map, "--to", "rosbag", "--out", bag, "--force"])
    assert (bag / "NOTES.txt").read_text() == "keep me"


@pytest.mark.parametrize("to", ["costmap", "rosbag"])
def test_a_threshold_beyond_any_value_is_not_a_bug(small_map, tmp_path, capsys, to):
    out = tmp_path / ("cm.pgm" if to == "costmap" else "bag")
    sentence(capsys, ["export", small_map, "--to", to, "--out", out, "--threshold", "1e308"], status=0)


# -- public constructors: a sentence, never a raw exception ---------------------------------------------
def test_constructors_answer_bad_numbers_with_a_sentence():
    import math

    from radarcl.cl import Runtime
    from radarcl.errors import ConfigError
    from radarcl.geometry import BeamModel
    from radarcl.grid import EvidenceGrid
    from radarcl.gridspec import GridSpec
    from radarcl.stages.range_fft import RangeFFT

    runtime = Runtime()
    for clip in ("abc", "0.5", True, [1.0]):
        with pytest.raises(ConfigError, match="clip_level must be a positive number"):
            RangeFFT(runtime, (2, 1), 8, 16, dtype=np.float32, clip_level=clip)
    assert RangeFFT(runtime, (2, 1), 8, 16, dtype=np.float32, clip_level=np.float32(5.0)).clip_level == 5.0
    with pytest.raises(ConfigError, match=r"beamwidth_az_rad must be a number, got '0.1' \(str\)"):
        BeamModel(beamwidth_az_rad="0.1", beamwidth_el_rad=0.1, half_aperture_az_m=0.0, half_aperture_el_m=0.0)
    with pytest.raises(ConfigError, match="half_aperture_el_m must be a number"):
        BeamModel(0.1, 0.1, 0.0, [0.0])
    with pytest.raises(ConfigError, match="near_field must be True or False"):
        BeamModel(0.1, 0.1, 0.0, 0.0, near_field="no")
    assert BeamModel(np.float64(0.1), math.radians(2.0), 0, np.float32(0.1)).beamwidth_az_rad == 0.1
    grid = EvidenceGrid(runtime, GridSpec((0.0, 0.0, 0.0), 0.5, (16, 16, 16)))
    for bricks in ([[np.nan, 0, 0]], [[0.5, 0, 0]], [["a", 0, 0]], [[0, 0]], [[np.inf, 0, 0]]):
        with pytest.raises(ConfigError, match="bricks must be"):
            grid.allocate(bricks)
    assert grid.memory()["bricks"] == 0                      # nothing allocated by a refused call
    assert list(grid.allocate([[1.0, 0, 0], [0, 1, 1]])) == [0, 1]


# -- a file whose version and members disagree: refused naming both ------------------------------------
def knowledge_map(path):
    """A small map of the detection-statistics model written as radarcl writes it (version 3)."""
    from radarcl.gridspec import GridSpec
    from radarcl.maps import npz
    from radarcl.sensor_model import READING

    keys = np.array([[0, 0, 0]], np.int32)
    data = np.full((1, 8, 8, 8), 3000, np.int32)
    reading = dict(look_limit=2.0, prior_nats=-3.0, prior_looks=1.0, known_looks=0.5)
    assert set(reading) == set(READING)
    channels = npz.Channels(np.full_like(data, 4096), np.full_like(data, 2), reading)
    npz.write(path, GridSpec((0.0, 0.0, 0.0), 0.5, (16, 8, 8)), keys, data, channels=channels)
    return path


@pytest.mark.parametrize("version,drop,says", [
    (3, ("knowledge", "looks", "reading"), "version 3 map .* lacks its knowledge, looks, reading"),
    (3, ("reading",), "version 3 map .* lacks its reading"),
    (2, ("knowledge", "looks", "reading"), "version 2 map, which is planar .* holds neither"),
    (2, ("looks",), "version 2 map with knowledge, reading lacks its looks"),
    (1, (), "version 1 map but holds knowledge-channel members"),
])
def test_an_npz_whose_version_and_members_disagree_is_refused(tmp_path, capsys, version, drop, says):
    from radarcl.errors import FrameFormatError
    from radarcl.maps.map import Map

    good = knowledge_map(tmp_path / "good.npz")
    z = dict(np.load(good))
    assert int(z["version"]) == 3 and Map.open(good).has_knowledge
    z["version"] = np.asarray(version)
    for name in drop:
        del z[name]
    bad = tmp_path / "bad.npz"
    np.savez(bad, **z)
    with pytest.raises(FrameFormatError, match=says):
        Map.open(bad)
    err = sentence(capsys, ["export", bad, "--to", "ply", "--out", tmp_path / "x.ply"])
    assert "version" in err and not (tmp_path / "x.ply").exists()


def test_a_legacy_version_2_knowledge_map_still_reads(tmp_path):
    from radarcl.maps.map import Map

    z = dict(np.load(knowledge_map(tmp_path / "k.npz")))
    z["version"] = np.asarray(2)                                 # as radarcl wrote knowledge maps before
    np.savez(tmp_path / "v2.npz", **z)
    assert Map.open(tmp_path / "v2.npz").counts() == Map.open(tmp_path / "k.npz").counts()


@pytest.mark.parametrize("edit", ["reading", "reading and its checksums", "everything"])
def test_a_store_that_lost_its_reading_is_refused(tmp_path, edit):
    import json
    import shutil

    from radarcl.errors import FrameFormatError
    from radarcl.maps import store
    from radarcl.maps.map import Map

    Map.open(knowledge_map(tmp_path / "k.npz")).save(tmp_path / "k.rcmap")
    manifest = json.loads((tmp_path / "k.rcmap" / store.MANIFEST).read_text())
    del manifest["reading"]
    if edit != "reading":
        del manifest["checksums"]["knowledge"], manifest["checksums"]["looks"]
    if edit == "everything":
        for name in ("knowledge_0", "looks_0"):
            shutil.rmtree(tmp_path / "k.rcmap" / name)
    manifest["crc32"] = store.seal(manifest)                     # edited with care: the seal matches
    (tmp_path / "k.rcmap" / store.MANIFEST).write_text(json.dumps(manifest))
    says = {"reading": "gives no reading, yet the store lists checksums of knowledge, looks and holds knowledge_0",
            "reading and its checksums": "gives no reading, yet the store holds knowledge_0, looks_0",
            "everything": "store format 3 is written for planar bricks or the knowledge channel, but this store is cubic"}
    with pytest.raises(FrameFormatError, match=says[edit]):
        Map.open(tmp_path / "k.rcmap")


def test_an_npz_write_killed_leaves_a_temp_file_the_next_run_removes_and_names(tmp_path, caplog):
    """kill -9 while the map's temporary file is open: it may survive the kill (nothing can
    remove it then), and the next write of the same map removes it and says so."""
    import logging

    from radarcl.gridspec import GridSpec
    from radarcl.maps import npz

    out = tmp_path / "map.npz"
    script = ("import sys, time\nfrom radarcl.io.files import atomic\n"
              "with atomic(sys.argv[1]) as tmp:\n    tmp.write_bytes(b'half a map')\n    print(tmp, flush=True)\n"
              "    time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", script, str(out)], stdout=subprocess.PIPE, text=True)
    tmp = proc.stdout.readline().strip()
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert tmp.endswith(f".map.npz.{proc.pid}.tmp") and os.path.exists(tmp)        # what the kill left
    with caplog.at_level(logging.WARNING, logger="radarcl.io.files"):
        npz.write(out, GridSpec((0.0, 0.0, 0.0), 0.5, (8, 8, 8)), np.zeros((0, 3), np.int32),
                  np.zeros((0, 8, 8, 8), np.int32))
    assert not os.path.exists(tmp) and sorted(p.name for p in tmp_path.iterdir()) == ["map.npz"]
    assert f"removed {tmp}, left by a run that was killed while writing map.npz" in caplog.text
