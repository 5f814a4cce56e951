"""The Python API at the top (``import radarcl``), used as a notebook user writes it: a map
fused from three scans, saved, loaded, queried and projected to a costmap, in at most three
imports; and that ``import radarcl`` itself stays light."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
OXFORD = ROOT.parent / "shared" / "data" / "navtech_oxford"

NOTEBOOK = """
import numpy as np
import radarcl

m = radarcl.fuse({data!r}, sensor="navtech-cts350x", scans=3, out={out!r})
again = radarcl.Map.open({out!r})
assert again.has_knowledge and again.reading == m.reading
assert again.counts() == m.counts()
occupied, nats = again.occupied()
assert len(occupied) == m.counts()["occupied"] > 0 and (nats > 1.0).all()
states = again.state_at(occupied)
assert (states == radarcl.OCCUPIED).all()
assert again.state_at([[1e6, 0.0, 0.0]])[0] == radarcl.UNOBSERVED
p = again.probability_at(occupied)
assert np.allclose(p, 1 / (1 + np.exp(-again.log_odds_at(occupied))), rtol=0, atol=1e-12) and (p > 0.73).all()
cost = again.costmap(band=(-0.1, 0.1))
i, j = cost.cell_of(occupied[:, :2]).T
assert (cost.cells[j, i] == 100).all()
assert int((cost.cells == 100).sum()) == m.counts()["occupied"]   # a planar map: one voxel per cell
print("occupied", m.counts()["occupied"], "frames", len(open({out!r} + ".tum").read().splitlines()) - 1)
"""


@pytest.mark.skipif(not OXFORD.is_dir(), reason="the shared Oxford scans are not here")
def test_a_notebook_fuses_three_scans_and_queries_the_map_in_three_imports(tmp_path):
    code = NOTEBOOK.format(data=str(OXFORD), out=str(tmp_path / "oxford.npz"))
    assert sum(line.startswith(("import ", "from ")) for line in code.splitlines()) <= 3
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    words = out.stdout.split()
    assert words[0] == "occupied" and int(words[1]) > 0 and words[2:] == ["frames", "3"]


def test_import_radarcl_loads_nothing_heavy():
    code = "import sys, radarcl; print(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'pyopencl', 'radarcl')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}).stdout
    assert out.strip() == "['radarcl']"


def test_every_api_name_resolves_and_an_unknown_one_is_refused():
    import radarcl

    for name in radarcl.API:
        assert getattr(radarcl, name) is not None, name
    assert (radarcl.OCCUPIED, radarcl.FREE, radarcl.UNDECIDED, radarcl.UNOBSERVED) == (2, 0, 1, -1)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        radarcl.nope


def test_a_sensor_name_is_taken_where_a_profile_is(tmp_path):
    import radarcl
    from radarcl.errors import ConfigError
    from radarcl.io import inputs

    source = radarcl.open_input("navtech-cts350x", OXFORD)
    assert len(source) == 11 and source.sensor.name == "navtech-cts350x" and len(source.times_ns) == 11
    assert len(source.head(3)) == 3 and source.head(3).frames[2].shape == source.frames[2].shape
    with pytest.raises(ConfigError, match="takes a sensor profile, got the name 'navtech-cts350x'"):
        inputs.open_input("navtech-cts350x", OXFORD)


def test_a_directory_is_recognised_or_answered_with_the_profiles(tmp_path):
    import radarcl
    from radarcl.io.polar_layout import recognise

    assert recognise(OXFORD)[0] == "navtech-cts350x" and recognise(OXFORD / "radar")[0] == "navtech-cts350x"
    radiate = ROOT.parent / "shared" / "data" / "radiate_fog"
    if radiate.is_dir():
        assert recognise(radiate)[0] == "radiate-cts350x"
    (tmp_path / "Navtech_Polar").mkdir()
    assert recognise(tmp_path)[0] == "radiate-cts350x"
    boreas = tmp_path / "boreas"
    (boreas / "radar").mkdir(parents=True)
    (boreas / "applanix").mkdir()
    assert recognise(boreas)[0] == recognise(boreas / "radar")[0] == "boreas-cir204"
    mulran = tmp_path / "mulran"
    (mulran / "sensor_data" / "radar" / "polar").mkdir(parents=True)
    assert recognise(mulran)[0] == "mulran"
    empty = tmp_path / "empty"
    empty.mkdir()
    assert recognise(empty) is None
    with pytest.raises(radarcl.ConfigError, match="no recording layout.*give sensor=: one of .*navtech-cts350x"):
        radarcl.fuse(empty)


def test_the_fuse_command_answers_an_unknown_directory_with_the_profiles(tmp_path, capsys):
    from radarcl import cli

    empty = tmp_path / "scans"
    empty.mkdir()
    assert cli.main(["fuse", str(empty), "--out", str(tmp_path / "m.npz")]) != 0
    err = capsys.readouterr().err
    assert "no recording layout radarcl knows" in err and "--sensor: one of" in err and "radiate-cts350x" in err
    assert not (tmp_path / "m.npz").exists()


@pytest.mark.skipif(not OXFORD.is_dir(), reason="the shared Oxford scans are not here")
def test_a_loop_of_ones_own_saves_its_reading_untold(tmp_path):
    """The guide's own loop: a pipeline from a sensor name, three frames, ``save_grid`` with no
    ``reading=``, and ``Map.save`` to a store and back: every copy reads as the grid."""
    import radarcl

    source = radarcl.open_input("navtech-cts350x", OXFORD)
    mapping = radarcl.Mapping.from_config(radarcl.Runtime(), config=radarcl.resolve_config(source.sensor))
    for j in range(3):
        mapping.fuse(source.frames[j], source.poses[j], flags=source.flags[j])
    radarcl.save_grid(mapping.grid, tmp_path / "three.npz")
    m = radarcl.Map.of_grid(mapping.grid)
    assert m.has_knowledge and m.counts()["occupied"] > 0
    saved = radarcl.Map.open(tmp_path / "three.npz")
    assert saved.reading == m.reading and saved.counts() == m.counts()
    m.save(tmp_path / "three.rcmap")
    stored = radarcl.Map.open(tmp_path / "three.rcmap")
    assert stored.reading == m.reading and stored.counts() == m.counts()
    with pytest.raises(radarcl.ConfigError, match="exists"):
        m.save(tmp_path / "three.npz")


@pytest.mark.skipif(not OXFORD.is_dir(), reason="the shared Oxford scans are not here")
def test_a_planar_map_renders_its_classes_from_above_by_default(tmp_path, capsys):
    """radarcl render of a planar map draws occupied, free, undecided and unknown apart, seen
    from above with metre axes (matplotlib); a mode or camera asked for gets the 3D render."""
    from PIL import Image

    import radarcl
    from radarcl.cli import main
    from radarcl.report import figures

    m = radarcl.fuse(OXFORD, scans=3, out=tmp_path / "m.npz")
    top = m.classes_from_above()
    counts = m.counts()
    assert int((top == radarcl.OCCUPIED).sum()) == counts["occupied"]       # one layer: a cell is its voxel
    assert int((top == radarcl.FREE).sum()) == counts["free"] and int((top == radarcl.UNDECIDED).sum()) == counts["undecided"]
    assert main(["render", str(tmp_path / "m.npz"), "--out", str(tmp_path / "top.png")]) == 0
    assert "classes seen from above" in capsys.readouterr().out
    rgb = np.asarray(Image.open(tmp_path / "top.png").convert("RGB")).reshape(-1, 3)
    for _, _, colour in figures.CLASS_COLOURS:                              # all four classes drawn, apart
        want = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])
        assert (np.abs(rgb.astype(int) - want).max(axis=1) <= 2).sum() > 200, colour
    assert main(["render", str(tmp_path / "m.npz"), "--mode", "classes", "--threshold", "nan",
                 "--out", str(tmp_path / "bad.png")]) == 2
    assert not (tmp_path / "bad.png").exists()


def test_a_geo_anchor_composes_with_poses():
    """A frame 100 m east and 50 m north of an anchor, turned 90 deg: its origin moves by those
    metres on the Earth and its heading by the turn; the identity keeps the anchor."""
    import math

    from radarcl.io.trajectory import EARTH_RADIUS_M, geo_anchor

    a = dict(latitude_deg=55.0, longitude_deg=-3.0, altitude_m=200.0, heading_deg=0.0)
    assert geo_anchor(a, np.eye(4)) == a
    pose = np.eye(4)
    pose[:3, 3] = (100.0, 50.0, 2.0)
    pose[:2, :2] = [[0.0, -1.0], [1.0, 0.0]]
    b = geo_anchor(a, pose)
    assert math.isclose(math.radians(b["latitude_deg"] - 55.0) * EARTH_RADIUS_M, 50.0, abs_tol=1e-6)
    assert math.isclose(math.radians(b["longitude_deg"] + 3.0) * EARTH_RADIUS_M * math.cos(math.radians(55.0)), 100.0,
                        abs_tol=1e-6)
    assert b["altitude_m"] == 202.0 and math.isclose(b["heading_deg"], 90.0)
    c = geo_anchor(dict(a, heading_deg=90.0), pose)               # x north: 100 m along x is north
    assert math.isclose(math.radians(c["latitude_deg"] - 55.0) * EARTH_RADIUS_M, 100.0, abs_tol=1e-6)
    assert math.isclose(c["heading_deg"], 180.0) or math.isclose(c["heading_deg"], -180.0)


RADIATE = ROOT.parent / "shared" / "data" / "radiate_fog"


@pytest.mark.skipif(not RADIATE.is_dir(), reason="the shared RADIATE sequence is not here")
def test_a_map_placed_by_gps_carries_its_geo_anchor(tmp_path):
    import math

    import radarcl
    from radarcl.io import radiate
    from radarcl.io.trajectory import EARTH_RADIUS_M
    from radarcl.maps.disk import read_meta

    radarcl.fuse(RADIATE, scans=3, out=tmp_path / "r.npz")
    anchor = read_meta(tmp_path / "r.npz", "geo_anchor")
    gps = radiate.read_gps_imu(RADIATE)
    north = math.radians(anchor["latitude_deg"] - gps.lat[0]) * EARTH_RADIUS_M
    east = math.radians(anchor["longitude_deg"] - gps.lon[0]) * EARTH_RADIUS_M * math.cos(math.radians(gps.lat[0]))
    assert 0 < math.hypot(north, east) < 200 and -180 <= anchor["heading_deg"] < 180     # near the first fix
    header = (tmp_path / "r.npz.tum").read_text().splitlines()[1].split()
    assert header[:3] == ["#", "geo_anchor", "latitude_deg"] and float(header[3]) == anchor["latitude_deg"]
    oxford = radarcl.fuse(OXFORD, scans=2, out=tmp_path / "o.npz")
    assert oxford.counts()["occupied"] > 0 and read_meta(tmp_path / "o.npz", "geo_anchor") is None   # odometry only


@pytest.mark.skipif(not OXFORD.is_dir(), reason="the shared Oxford scans are not here")
def test_a_sensor_name_is_taken_where_a_configuration_is(tmp_path):
    """Every function that takes a configuration takes a sensor's name for its defaults: the
    pipeline, the fuse job, the live mapper, the configuration itself."""
    import radarcl
    from radarcl.config import mapconfig
    from radarcl.jobs import fuse
    from radarcl.livemap import LiveMapper

    runtime = radarcl.Runtime()
    assert mapconfig.as_resolved("navtech-cts350x").sensor.name == "navtech-cts350x"
    config = mapconfig.resolve("navtech-cts350x")
    assert mapconfig.as_resolved(config) is config
    assert LiveMapper(runtime, "navtech-cts350x").config.sensor.name == "navtech-cts350x"
    source = radarcl.open_input("navtech-cts350x", OXFORD).head(2)
    result = fuse.run(runtime, source, "navtech-cts350x", tmp_path / "m.npz", report=lambda line: None)
    assert result["frames"] == 2 and radarcl.Map.open(tmp_path / "m.npz").counts()["occupied"] > 0
    with pytest.raises(radarcl.ConfigError, match="nosuch"):
        mapconfig.as_resolved("nosuch")
