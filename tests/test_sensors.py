"""Sensor profiles: built-ins load, round-trip through TOML, derive their defaults from their own
resolution, and bad profiles are refused with file, line, key, value and what is allowed."""

import math

import numpy as np
import pytest

from radarcl.cli import main
from radarcl.config import mapconfig, sensors
from radarcl.errors import ConfigError


def test_builtins_load_and_round_trip(tmp_path):
    assert set(sensors.builtin_names()) >= {"paper", "navtech-cts350x", "polar-png", "ti-xwr-openradar"}
    for name in sensors.builtin_names():
        s = sensors.load(name)
        path = tmp_path / f"{name}.toml"
        path.write_text(s.toml())
        back = sensors.load(path)
        assert back.name == s.name and back.input == s.input and back.defaults == s.defaults
        assert {k: v for k, v in back.tables.items() if not k.startswith("defaults")} == \
               {k: v for k, v in s.tables.items() if not k.startswith("defaults") and k != ""} | {"": back.tables[""]}
        assert back.lattice() == s.lattice() and back.frame_shape() == s.frame_shape()


def test_the_paper_radar_derives_the_papers_choices():
    """From its own geometry alone: 1024-point FFT, CFAR guard and training 16 bins (2 m: the Hann
    mainlobe of 4 cells of 0.5 m; half the -9 deg ground echo is 1.57 m), wide pulse 1.87 m."""
    c = mapconfig.resolve("paper")
    cfar = c.cfar_config()
    assert c.n_fft == 1024 and (cfar.guard, cfar.train, cfar.kind) == (16, 16, "ca")
    assert abs(c["interpret.wide_pulse_m"] - 1.8719) < 1e-3 and c.interpret_config().wide_bins(c.bin_spacing_m) == 15
    assert sensors.ground_pulse_m(c.sensor, -9.0) / 2 < c["cfar.guard_m"]
    assert c.sensor.lattice().n_beams == 256 and c.sensor.frame_shape() == (64, 4, 256)


def test_windows_are_physical_whatever_the_bin_spacing(tmp_path):
    """A polar-PNG unit with 0.1736 m bins (another Navtech) gets the same guard in metres as the
    Oxford unit's 0.0432 m bins: 4 bins instead of 14, not 14 bins = 2.4 m."""
    other = tmp_path / "ciro.toml"
    other.write_text('name = "ciro"\ninput = "profiles"\nextends = "navtech-cts350x"\n'
                     '[range]\nbin_spacing_m = 0.1736\nn_bins = 2856\nrange_max_m = 300.0\n')
    oxford, wide = mapconfig.resolve("navtech-cts350x"), mapconfig.resolve(other)
    assert oxford["cfar.guard_m"] == wide["cfar.guard_m"] == pytest.approx(0.6)
    assert oxford.cfar_config().guard == 14 and wide.cfar_config().guard == 4
    assert wide.sensor.n_azimuth == 400 and wide.sensor.spinning          # inherited
    assert "4 resolution cells of 0.15 m" in wide.origins["cfar.guard_m"]


@pytest.mark.parametrize("body,words", [
    ('name = "x"\ninput = "profiles"\n[range]\nbin_spacing_m = 0\n', r"x.toml:4: \[range\] bin_spacing_m must lie in \(0"),
    ('name = "x"\ninput = "profiles"\n[beams]\nn_azimuth = "400"\n', r"x.toml:4: \[beams\] n_azimuth must be an integer"),
    ('name = "x"\ninput = "profiles"\n[beams]\nn_azimuth = 64.7\n', "must be an integer, got 64.7"),
    ('name = "x"\ninput = "profiles"\n[beams]\nn_azimuth = true\n', "must be an integer, got True"),
    ('name = "x"\ninput = "profiles"\n[range]\nbin_spacing = 0.1\n', r"x.toml:4: \[range\] bin_spacing: unknown key"),
    ('name = "x"\ninput = "radio"\n', r"x.toml:2: top level input must be one of 'samples', 'profiles'"),
    ('name = "x"\ninput = "profiles"\n[antenna]\ngain = 1\n', r"\[antenna\]: unknown table"),
    ('name = "x"\ninput = "profiles"\n', "needs a \\[beams\\] table"),
    ('name = "x"\ninput = "samples"\nextends = "polar-png"\n', "needs a \\[waveform\\] table"),
    ('name = "x"\ninput = "profiles"\nextends = "x.toml"\n', "extend each other in a circle"),
    # a range beyond the last bin is clipped with a note, not refused (tests/test_polar_layout.py)
    ('name = "x"\ninput = "profiles"\nextends = "polar-png"\n[reader]\nmeta_columns = 0\n',
     r"\[reader\] timestamp_column = 0 needs 8 columns inside the 0 metadata columns"),
    ('name = "x"\ninput = "profiles"\nextends = "polar-png"\n[range]\nrange_max_m = inf\n', "must be a finite number"),
    ('name = "x"\ninput = "profiles"\nextends = "polar-png"\n[defaults.cfar]\nguard = 16\n',
     r"x.toml:5: \[defaults.cfar\] guard unknown configuration key 'cfar.guard'"),
    ('name = "x"\ninput = "profiles"\nextends = "polar-png"\n[defaults.cfar]\nguard_m = -1.0\n',
     r"cfar.guard_m must lie in \[0, 10000.0\] \[m\], got -1.0"),
    ('name = "x"\ninput = "profiles"\n[range\n', "not valid TOML"),
])
def test_bad_profiles_name_file_line_key_and_what_is_allowed(tmp_path, monkeypatch, body, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.toml").write_text(body)
    with pytest.raises(ConfigError, match=words):
        sensors.load(tmp_path / "x.toml")


def test_unknown_sensor_lists_the_builtins():
    with pytest.raises(ConfigError, match="no sensor profile 'radar9000': not a built-in \\(boreas-cir204, mulran, navtech-cts350x"):
        sensors.load("radar9000")
    with pytest.raises(ConfigError, match="and no such file; did you mean radiate-cts350x\\?"):
        sensors.load("radiate-cts305x")                       # a typo gets the name it is closest to
    with pytest.raises(ConfigError, match="and no such file$"):
        sensors.load("radar9000")                             # nothing close: no guess


def test_cli_lists_and_prints_profiles(capsys):
    assert main(["sensors"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in sensors.builtin_names())
    assert main(["sensors", "ti-xwr-openradar"]) == 0
    assert 'sample_type = "complex64"' in capsys.readouterr().out


def test_field_of_view_boxes():
    """A spinning radar with one elevation maps its plane, one voxel thick, centred on it; the TI
    board's 60 x 30 deg beam to 6 m fits its box; every box starts on the voxel lattice that
    starts at 0 (OctoMap's), widened to the next voxel; the paper's profile gives its own grid."""
    origin, size = sensors.field_of_view_box(sensors.load("navtech-cts350x"), 0.3, 80.0)
    assert origin == (-80.1, -80.1, -0.15) and size == (160.2, 160.2, 0.3)       # 267 voxels each side of 0
    origin, size = sensors.field_of_view_box(sensors.load("ti-xwr-openradar"), 0.05, 6.0)
    assert origin[0] == 0.0 and size[0] == pytest.approx(6.0) and size[1] == pytest.approx(6.0)
    half = 6.0 * math.sin(math.radians(15))                                         # 1.553 m
    assert origin[2] == pytest.approx(-1.6) and size[2] == pytest.approx(3.2) and 3.2 - 2 * half < 0.1
    spec = mapconfig.resolve("paper").grid_spec()
    assert spec.shape == (800, 700, 200) and spec.origin_m == (-8.0, -35.0, -10.0)
    assert np.isclose(mapconfig.resolve("paper", flags={"grid.voxel_m": 0.4}).grid_spec().voxel_m, 0.4)
