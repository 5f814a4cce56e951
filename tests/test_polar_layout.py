"""Polar scans in every published layout, read as the files are (radarcl.io.polar_layout): RADIATE's
own scans with the built-in profile, files written in Boreas' and MulRan's documented layouts,
layouts that do not match refused with both shapes and the key to change, a range beyond the
last bin clipped with a note."""

import math

import numpy as np
import pytest
from PIL import Image

from radarcl.config import mapconfig, sensors
from radarcl.errors import ConfigError, FrameFormatError
from radarcl.io import polar_png
from radarcl.io.inputs import open_input
from radarcl.io.polar_layout import read_side_file, seconds_text_to_ns


def _layout(name):
    return polar_png.PolarLayout.of(sensors.load(name))


def test_radiate_scans_read_with_the_builtin_profile(shared_data):
    """576 range rows x 400 azimuth columns, no metadata: 400 azimuths of 576 bins, column k at
    (k + 0.5) x 0.9 deg clockwise from ahead, times from Navtech_Polar.txt (a time of arrival:
    the middle azimuth 0.25 s before it), the levels the PNG's own."""
    root = shared_data / "radiate_fog"
    seq = polar_png.read_sequence(root, _layout("radiate-cts350x"), odometry=False)
    assert seq.directory == root / "Navtech_Polar" and len(seq.scans) == 12 and seq.timed
    stamps = read_side_file(root / "Navtech_Polar.txt")
    for scan in seq.scans[:3]:
        png = np.asarray(Image.open(scan.path))
        assert png.shape == (576, 400) and scan.levels.shape == (400, 576) and scan.levels.dtype == np.uint8
        for row in (0, 1, 137, 399):
            k = scan.acquired[row]
            assert np.array_equal(scan.levels[row], png[:, k])
            assert math.isclose(scan.angles_rad[row], math.radians(-(k + 0.5) * 0.9) % (2 * math.pi), abs_tol=1e-9)
        middle = int(np.flatnonzero(scan.acquired == 199)[0])
        assert scan.timestamps_ns[middle] == stamps[scan.path.stem] - 250_000_000
        period = scan.timestamps_ns.max() - scan.timestamps_ns.min()
        assert 0.23e9 < period < 0.26e9                                  # a turn of ~0.25 s
    # the whole recording through open_input: the profile's 576 bins, poses found beside it
    source = open_input(sensors.load("radiate-cts350x"), root, clock_offset_s=65.8)
    assert source.posed and source.frames[0].shape == (400, 576) and source.poses.shape == (12, 400, 4, 4)


def test_side_file_decimals_are_left_padded(tmp_path):
    """RADIATE's SDK pads a fraction of fewer than 9 digits on the left: '12.5' is 12 s + 5 ns."""
    assert seconds_text_to_ns("12", "5") == 12 * 10 ** 9 + 5
    assert seconds_text_to_ns("1574859773", "185142137") == 1574859773185142137
    f = tmp_path / "Navtech_Polar.txt"
    f.write_text("Frame: 000001 Time: 12.5\nFrame: 000002 Time: 12.250000000\n")
    assert read_side_file(f) == {"000001": 12 * 10 ** 9 + 5, "000002": 12_250_000_000}
    f.write_text("Frame: 000001 Time: 12.5\nFrame 2 at noon\n")
    with pytest.raises(FrameFormatError, match=r"Navtech_Polar.txt:2: expected 'Frame: NNNNNN Time: <unix seconds>'"):
        read_side_file(f)


def _oxford_like_png(path, n_az, bins, start_us, turn_us, encoder0=13, valid=255):
    """A scan in Oxford's / Boreas' layout: per-azimuth int64 us, uint16 encoder, a byte, bins."""
    raw = np.zeros((n_az, 11 + bins.shape[1]), np.uint8)
    stamps = start_us + (np.arange(n_az) * turn_us) // n_az
    raw[:, 0:8] = stamps.astype("<i8").view(np.uint8).reshape(n_az, 8)
    enc = (encoder0 + np.arange(n_az) * 14).astype("<u2")
    raw[:, 8:10] = enc.view(np.uint8).reshape(n_az, 2)
    raw[:, 10] = valid
    raw[:, 11:] = bins
    Image.fromarray(raw).save(path)
    return stamps, enc


def test_a_boreas_scan_in_its_documented_layout(tmp_path):
    """Boreas: Oxford's 11 metadata columns with column 10 unused (here 0, which would read as
    'not measured' were it a valid flag), 19-digit names among 16-digit ones, and the -0.31 m
    range offset (5 of 0.0596 m bins dropped: bin j at j x 0.0596 m within 0.012 m)."""
    radar = tmp_path / "boreas-2021-08-05-13-34" / "radar"
    radar.mkdir(parents=True)
    rng = np.random.default_rng(1)
    bins = rng.integers(0, 60, (400, 600), dtype=np.uint8)
    bins[:, 100] = 200                                               # a target at bin 100: 100 x 0.0596 - 0.31 m
    stamps, enc = _oxford_like_png(radar / "1628184868123456.png", 400, bins, 1628184868000000, 250000, valid=0)
    _oxford_like_png(radar / "1628184868373456789.png", 400, bins, 1628184868250000, 250000, valid=0)
    sensor = sensors.load("boreas-cir204")
    seq = polar_png.read_sequence(radar.parent, polar_png.PolarLayout.of(sensor), odometry=False)
    first = seq.scans[0]
    assert len(seq.scans) == 2 and first.levels.shape == (400, 595) and first.valid.all()
    assert np.argmax(first.levels[0]) == 95
    assert abs(95 * 0.0596 - (100 * 0.0596 - 0.31)) < 0.0596 / 2
    assert first.timestamps_us[0] == stamps[0]                        # from the metadata, per azimuth
    assert math.isclose(first.angles_rad[0], (-2 * math.pi * enc[0] / 5600) % (2 * math.pi), abs_tol=1e-12)
    source = open_input(sensor, radar.parent)                       # no poses here
    assert not source.posed and source.sensor.n_bins() == 595 and source.frames[0].shape == (400, 595)


def test_a_mulran_scan_in_its_documented_layout(tmp_path):
    """MulRan: 3360 range rows x 400 azimuth columns, no metadata, nanosecond file names;
    column k at (k + 1) x 0.9 deg clockwise; the azimuths spread over the measured period."""
    polar = tmp_path / "KAIST01" / "sensor_data" / "radar" / "polar"
    polar.mkdir(parents=True)
    img = np.zeros((3360, 400), np.uint8)
    img[1000, 7] = 250                                               # column 7, bin 1000
    t0 = 1566279920_000_000_000
    for k in range(3):
        Image.fromarray(img).save(polar / f"{t0 + k * 250_000_000}.png")
    sensor = sensors.load("mulran")
    seq = polar_png.read_sequence(tmp_path / "KAIST01", polar_png.PolarLayout.of(sensor), odometry=False)
    scan = seq.scans[1]
    row = int(np.flatnonzero(scan.acquired == 7)[0])
    assert scan.levels.shape == (400, 3360) and scan.levels[row, 1000] == 250
    assert math.isclose(scan.angles_rad[row], math.radians(-(7 + 1) * 0.9) % (2 * math.pi), abs_tol=1e-9)
    assert scan.start_ns == t0 + 250_000_000
    assert scan.timestamps_ns[row] == t0 + 250_000_000 + (7 * 250_000_000) // 400


def test_a_layout_that_does_not_match_is_refused_with_both_shapes_and_the_key(shared_data, tmp_path):
    scan = shared_data / "radiate_fog" / "Navtech_Polar" / "000007.png"
    with pytest.raises(FrameFormatError, match=r"the image is 576 x 400 \(rows x columns\); the layout reads 400 "
                                               r"azimuth rows x \(11 metadata \+ bins\) columns \(576 azimuths where "
                                               r"the sensor has 400\); its columns look like the 400 azimuths: set "
                                               r"\[reader\] orientation = \"range-rows\" and meta_columns = 0"):
        polar_png.load_scan(scan, _layout("navtech-cts350x"))
    oxford = shared_data / "navtech_oxford" / "radar" / "1547131046353776.png"
    with pytest.raises(FrameFormatError, match=r"the image is 400 x 3779 .* its rows look like the 400 azimuths: set "
                                               r"\[reader\] orientation = \"azimuth-rows\""):
        polar_png.load_scan(oxford, _layout("radiate-cts350x"))
    # the right orientation, the wrong bin count: refused before anything is fused, naming the key
    with pytest.raises(FrameFormatError, match=r"frames are \(400, 576\) float32; sensor mulran expects \(400, 3360\) "
                                               r"float32 \(\[range\] n_bins = 3360"):
        open_input(sensors.load("mulran"), scan)


def test_reader_keys_none_and_their_checks(tmp_path):
    """timestamp_column = -1 (none) is accepted where documented; a layout whose keys contradict
    each other is refused when the profile is read, naming the key."""
    good = tmp_path / "mine.toml"
    good.write_text('name = "mine"\ninput = "profiles"\nextends = "polar-png"\n[reader]\nmeta_columns = 0\n'
                    'timestamp_column = -1\nencoder_column = -1\nvalid_column = -1\norientation = "range-rows"\n')
    layout = polar_png.PolarLayout.of(sensors.load(str(good)))
    assert layout.timestamp_column == -1 and layout.timestamps == "file-name"
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\ninput = "profiles"\nextends = "polar-png"\n[reader]\nmeta_columns = 0\n')
    with pytest.raises(ConfigError, match=r"bad.toml: \[reader\] timestamp_column = 0 needs 8 columns inside the 0 "
                                          r"metadata columns \(-1: none\)"):
        sensors.load(str(bad))
    side = tmp_path / "side.toml"
    side.write_text('name = "side"\ninput = "profiles"\nextends = "mine"\n[reader]\ntimestamps = "side-file"\n')
    (tmp_path / "mine.toml").rename(tmp_path / "mine2.toml")
    side.write_text(side.read_text().replace('extends = "mine"', f'extends = "{tmp_path / "mine2.toml"}"'))
    with pytest.raises(ConfigError, match=r"timestamps = 'side-file' needs timestamp_file"):
        sensors.load(str(side))


def test_a_range_beyond_the_last_bin_is_clipped_with_a_note(shared_data, tmp_path):
    """A generic profile's 100 m on 576 bins of 0.173611 m (last bin 99.83 m): clipped, with a
    note, in the profile and in the configuration made before the bins were known."""
    prof = tmp_path / "radiate-generic.toml"
    prof.write_text('name = "radiate-generic"\ninput = "profiles"\nextends = "radiate-cts350x"\n[range]\n'
                    'range_max_m = 100.0\n')
    with_bins = sensors.load(str(prof))
    assert math.isclose(with_bins.range_interval_m[1], 99.826325, abs_tol=1e-6)
    assert any("range_max_m = 100 m lies beyond the last of 576 bins" in n for n in with_bins.notes)
    generic = sensors.load("polar-png")
    config = mapconfig.resolve(generic)
    learnt = generic.with_bins(576)
    clipped = config.for_sensor(learnt)
    assert learnt.range_interval_m[1] == round(575 * 0.0432, 6)
    assert clipped["interpret.range_max_m"] == learnt.range_interval_m[1]
    assert any("clipped" in n for n in clipped.notes)


def test_power_from_a_table_is_the_formula():
    """Levels become power through a 256-entry table: exactly 10^(level x dB / 10) in float64,
    rounded to float32, for every level and both dB scales."""
    levels = np.arange(256, dtype=np.uint8).reshape(16, 16)
    for db in (1.0, 0.5):
        expected = (10.0 ** (levels.astype(np.float64) * (db / 10.0))).astype(np.float32)
        assert np.array_equal(polar_png.levels_to_power(levels, db), expected)
