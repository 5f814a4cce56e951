"""A saved configuration knows its sensor: used with another it is refused with both names, or with
--force-sensor used with a warning, its constants kept and its sensor-derived metres derived again."""

import math
import re

import pytest

from radarcl.cli import main
from radarcl.config import mapconfig
from radarcl.errors import ConfigError


@pytest.fixture
def oxford_config(tmp_path):
    path = tmp_path / "oxford.toml"
    mapconfig.resolve("navtech-cts350x", flags={"cfar.kind": "so", "interpret.k_occ": 0.5}).save(path)
    assert 'sensor = "navtech-cts350x"' in path.read_text()
    return path


def test_a_configuration_for_another_sensor_is_refused(oxford_config):
    with pytest.raises(ConfigError, match=r"oxford.toml is a configuration for sensor 'navtech-cts350x', not "
                                          r"'radiate-cts350x'.*--force-sensor"):
        mapconfig.resolve("radiate-cts350x", oxford_config)
    same = mapconfig.resolve("navtech-cts350x", oxford_config)            # its own sensor: fine
    assert same["cfar.guard_m"] == 0.6 and not same.notes


def test_force_sensor_keeps_constants_and_rederives_the_metres(oxford_config):
    forced = mapconfig.resolve("radiate-cts350x", oxford_config, force_sensor=True)
    native = mapconfig.resolve("radiate-cts350x")
    assert forced["cfar.kind"] == "so" and forced["interpret.k_occ"] == 0.5          # the file's constants
    for key in mapconfig.SENSOR_KEYS:                                                # the new sensor's own
        assert forced[key] == native[key], key
    assert math.isclose(forced["cfar.guard_m"], 4 * 0.173611) and forced["interpret.range_max_m"] == 99.826
    said = " ".join(forced.notes)
    assert "made for sensor 'navtech-cts350x'; used with 'radiate-cts350x' (--force-sensor)" in said
    assert "cfar.guard_m 0.6 -> 0.694444" in said and "interpret.range_max_m 80 -> 99.826" in said


def test_the_cli_refuses_or_warns(oxford_config, capsys):
    assert main(["config", "show", "--sensor", "radiate-cts350x", "--config", str(oxford_config)]) == 2
    assert "is a configuration for sensor 'navtech-cts350x'" in capsys.readouterr().err
    assert main(["config", "show", "--sensor", "radiate-cts350x", "--config", str(oxford_config),
                 "--force-sensor"]) == 0
    captured = capsys.readouterr()
    assert "radarcl: note:" in captured.err and "derived again" in captured.err
    assert re.search(r"cfar\.guard_m +=  *0\.694444 ", captured.out)
