"""Map configuration: layers and their origins, files with file:line errors, flags, save/read
round trips, and the CLI's `config show` / `config save`."""

import pytest

from radarcl.cli import main
from radarcl.config import mapconfig
from radarcl.errors import ConfigError


def test_every_value_says_where_it_came_from(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('sensor = "navtech-cts350x"\n[cfar]\nkind = "os"\n\n[grid]\nvoxel_m = 0.5\n')
    c = mapconfig.resolve(None, path, flags={"cfar.pfa": 1e-4})
    assert c.sensor.name == "navtech-cts350x"
    assert c.origins["cfar.kind"] == f"file {path}:3" and c["cfar.kind"] == "os"
    assert c.origins["grid.voxel_m"] == f"file {path}:6" and c["grid.voxel_m"] == 0.5
    assert c.origins["cfar.pfa"] == "flag" and c["cfar.pfa"] == 1e-4
    assert c.origins["interpret.k_occ"] == "radarcl default"
    assert c.origins["cfar.guard_m"].startswith("sensor navtech-cts350x: a point target's pulse")
    assert c.origins["interpret.range_max_m"] == "sensor navtech-cts350x (built-in navtech-cts350x)"
    assert c.cfar_config().rank == round(0.75 * 2 * 14)
    lines = mapconfig.show(c)
    assert any(line.strip().startswith("cfar.kind") and f"file {path}:3" in line for line in lines)
    assert any("CFAR guard 0.6 m -> 14 bins of 0.0432 m" in line for line in lines)


def test_saved_configuration_reads_back_identically(tmp_path):
    c = mapconfig.resolve("paper", flags={"cfar.kind": "so", "interpret.e_low": 0.0, "grid.voxel_m": 0.25})
    path = tmp_path / "c.toml"
    c.save(path)
    back = mapconfig.resolve(None, path)
    assert back.sensor.name == "paper" and back.values == c.values
    with pytest.raises(ConfigError, match="exists; choose another name or pass --force"):
        c.save(path)


@pytest.mark.parametrize("body,words", [
    ("[cfar]\nguard = 16\n", r"c.toml:2: \[cfar\] guard: unknown key; allowed: guard_m, kind"),
    ("[cfar]\nguard_m = -0.5\n", r"c.toml:2: \[cfar\] guard_m = -0.5: must lie in \[0, 10000.0\] \[m\]"),
    ("[cfar]\npfa = 1.5\n", r"c.toml:2: \[cfar\] pfa = 1.5: must lie in \(0, 0.5\]"),
    ("[cfar]\nkind = \"median\"\n", r"must be one of 'ca', 'go', 'so', 'os', got 'median'"),
    ("[grid]\nvoxel_m = \"fine\"\n", r"c.toml:2: \[grid\] voxel_m = 'fine': must be a finite number"),
    ("[grid]\nvoxel_m = 0\n", r"c.toml:2: \[grid\] voxel_m = 0: must lie in \[0.0001, 1000.0\]"),
    ("[grid]\nsize_m = [1, 2]\n", "must be a list of 3 numbers"),
    ("[range_fft]\nn_fft = 1000\n", "must be a power of two"),
    ("[range_fft]\nn_fft = true\n", "must be an integer, got True"),
    ("[interpret]\ne_high = 0.5\n", r"e_high = 0.5: must lie in \[-16, 0\]"),
    ("[interpretation]\nk_occ = 1\n", r"c.toml:1: top level interpretation: unknown entry"),
    ("[cfar]\nguard_m = 40.0\n", r"cfar.guard_m = 40 \(from file .*c.toml:2\).*the CFAR window needs 675 bins of 0.1249 m; the sensor's profiles have 512"),
    ("[interpret]\nrange_max_m = 100.0\n", r"outside the range sensor paper measures, \[1, 64\] m"),
    ("[interpret]\nrange_min_m = 30.0\nrange_max_m = 20.0\n", "need range_min_m < range_max_m"),
    ("[range_fft]\nn_fft = 128\n", "shorter than the 256 samples per ramp"),
    ("[grid]\nvoxel_m = 0.0001\n", r"grid.voxel_m = 0.0001 .*more than the 268435456 a brick table holds; use voxels "
                                   r"of at least 0.00934 m"),
])
def test_bad_files_name_file_line_key_value_and_what_is_allowed(tmp_path, body, words):
    path = tmp_path / "c.toml"
    path.write_text(body)
    with pytest.raises(ConfigError, match=words):
        mapconfig.resolve("paper", path)


def test_flags(tmp_path):
    assert mapconfig.parse_flag("cfar.kind=so") == ("cfar.kind", "so")
    assert mapconfig.parse_flag("grid.size_m=[10, 20, 5]") == ("grid.size_m", (10.0, 20.0, 5.0))
    for text, words in (("cfar.kind", "takes section.key=value"), ("cfar.guard=3", "unknown configuration key"),
                        ("cfar.guard_m=nan", "must be a finite number"), ("grid.voxel_m=inf", "finite")):
        with pytest.raises(ConfigError, match=words):
            mapconfig.parse_flag(text)


def test_cli_config_show_and_save(tmp_path, capsys):
    assert main(["config", "show", "--sensor", "ti-xwr-openradar", "--set", "cfar.kind=go"]) == 0
    out = capsys.readouterr().out
    assert "sensor ti-xwr-openradar" in out and "cfar.kind" in out and "flag" in out and "range_fft.n_fft" in out
    path = tmp_path / "ti.toml"
    assert main(["config", "save", str(path), "--sensor", "ti-xwr-openradar", "--voxel", "0.1"]) == 0
    assert mapconfig.resolve(None, path)["grid.voxel_m"] == 0.1
    assert main(["config", "save", str(path)]) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert main(["config", "show", "--set", "cfar.guard=3"]) == 2
    assert "unknown configuration key 'cfar.guard'" in capsys.readouterr().err
