"""Real Navtech scans (../shared/data/navtech_oxford): the reader, and CFAR + eq. 12 on them
with the kernels against the float64 oracle; the `radarcl navtech` command."""

import numpy as np
import pytest
from test_cfar import check_against_oracle
from tolerances import EVIDENCE_UNITS_TOL

from radarcl import oracle
from radarcl.cli import main
from radarcl.config.sensors import load as load_sensor
from radarcl.config.stage_config import CfarConfig, InterpretConfig
from radarcl.errors import FrameFormatError
from radarcl.io import png
from radarcl.io import polar_png as navtech
from radarcl.pipeline import Detection


@pytest.fixture(scope="module")
def scans(shared_data):
    return navtech.scan_paths(shared_data / "navtech_oxford" / "radar")


def test_reader_decodes_every_scan(scans):
    assert len(scans) == 11
    for path in scans:
        scan = navtech.load_scan(path)
        assert scan.levels.shape == (400, 3768) and scan.levels.dtype == np.uint8
        assert scan.valid.all()
        # one revolution: 400 azimuths 0.9 deg apart, counter-clockwise (REP-103: the sensor turns
        # clockwise, so the rows come in reverse order after the first); the first row is the
        # first in time (the file's name), the turn takes ~1/4 s
        assert np.allclose(np.diff(np.unwrap(scan.angles_rad)), 2 * np.pi / 400, atol=1e-9)
        assert 0 <= scan.angles_rad.min() and scan.angles_rad.max() < 2 * np.pi
        assert scan.timestamps_us[0] == int(path.stem) and np.all(np.diff(scan.timestamps_us[1:]) <= 0)
        assert np.array_equal(scan.acquired, (-np.arange(400)) % 400)
        assert 0.2e6 < scan.timestamps_us.max() - scan.timestamps_us.min() < 0.3e6


def test_levels_are_decibels_of_integer_amplitudes(scans):
    """The evidence for 1 dB per level: the lowest levels present are 20 log10(k), k = 1..8."""
    levels = np.unique(navtech.load_scan(scans[0]).levels)
    assert list(levels[:8]) == [0, 6, 9, 12, 14, 15, 17, 18]
    assert np.all(np.abs(levels[:8] - 20 * np.log10(np.arange(1, 9))) < 1.0)
    assert navtech.levels_to_power(np.array([0, 10, 255]))[1] == np.float32(10.0)


def _png(pixels, filters, compressed=None):
    """A greyscale 8-bit PNG of ``pixels`` (h, w) uint8 with each row's filter byte taken from
    ``filters`` (0 None, 1 Sub, 2 Up: the rows are filtered to match), its image data
    ``compressed`` when given (a damaged stream), with valid chunk CRCs."""
    import struct
    import zlib

    h, w = pixels.shape
    rows = []
    for i, f in enumerate(filters):
        row = pixels[i].astype(np.int16)
        before = {0: 0, 1: np.concatenate([[0], row[:-1]]), 2: pixels[i - 1].astype(np.int16) if i else 0}[f]
        rows.append(bytes([f]) + ((row - before) % 256).astype(np.uint8).tobytes())
    data = zlib.compress(b"".join(rows)) if compressed is None else compressed

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    return (png.PNG_SIGNATURE + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", data[: len(data) // 2]) + chunk(b"IDAT", data[len(data) // 2:]) + chunk(b"IEND", b""))


def test_scans_decoded_by_hand_are_pil_s_pixels(scans, tmp_path, monkeypatch):
    """The reader's own inflate and unfiltering (rows all "Sub", as Navtech writes them, or all
    "None"; unfiltered a block of rows at a time, a block smaller than the image here too) gives
    PIL's pixels exactly; other filters are left to PIL, and a stream that inflates short, long
    or not at all is refused with a sentence."""
    import io

    from PIL import Image

    for path in scans:
        raw = path.read_bytes()
        w, h = png.verify_png(path, raw)
        pixels = png.greyscale_pixels(path, raw, w, h)
        assert pixels is not None and np.array_equal(pixels, np.asarray(Image.open(io.BytesIO(raw))))
    rng = np.random.default_rng(5)
    pixels = rng.integers(0, 256, (6, 300), dtype=np.uint8)
    for filters, by_hand in (([1] * 6, True), ([0] * 6, True), ([1, 2, 1, 2, 1, 2], False), ([0, 1] * 3, False)):
        raw = _png(pixels, filters)
        got = png.greyscale_pixels("x.png", raw, 300, 6)
        assert (got is not None) == by_hand and np.array_equal(np.asarray(Image.open(io.BytesIO(raw))), pixels)
        if by_hand:
            assert np.array_equal(got, pixels)
            with monkeypatch.context() as m:
                m.setattr(png, "UNFILTER_BLOCK_BYTES", 4 * 300)        # blocks of 4 rows and of 2
                assert np.array_equal(png.greyscale_pixels("x.png", raw, 300, 6), pixels)
        (tmp_path / "s.png").write_bytes(raw)
        layout = navtech.PolarLayout(meta_columns=0, timestamp_column=-1, encoder_column=-1, valid_column=-1)
        scan = navtech.load_scan(tmp_path / "s.png", layout)
        assert np.array_equal(scan.levels, pixels[scan.acquired])
    import zlib

    stream = zlib.compress(b"".join(bytes([1]) + r.tobytes() for r in pixels))
    short = zlib.compress(b"".join(bytes([1]) + r.tobytes() for r in pixels[:5]))
    peeked = zlib.compress(b"".join(bytes([1]) + r.tobytes() for r in pixels[:png.PEEK_ROWS]))
    long_ = zlib.compress(b"".join(bytes([1]) + r.tobytes() for r in np.vstack([pixels, pixels])))
    for damaged, said in ((stream[:-30], r"stop after 17\d\d bytes, before their stream's end; expected the 1806 "),
                          (stream[:-4], "stop after 1806 bytes, before their stream's end"),
                          (short, r"inflate to 1505 bytes, expected the 1806 bytes of 6 x 300 pixels\)$"),
                          (peeked, f"inflate to {png.PEEK_ROWS * 301} bytes, expected the 1806"),
                          (long_, "inflate to more than the 1806 bytes"), (b"\x00" * 40, "do not inflate")):
        with pytest.raises(FrameFormatError, match=said):
            png.greyscale_pixels("x.png", _png(pixels, [1] * 6, damaged), 300, 6)


@pytest.mark.parametrize("range_offset_m", [0.0, 0.2, -0.2])      # 5 bins padded, 5 dropped (0.0438 m bins)
@pytest.mark.parametrize("clockwise", [True, False])
def test_scans_kept_as_differences_read_as_the_pixels_do(scans, range_offset_m, clockwise):
    """A "Sub" scan keeps its rows' differences (``PolarScan.differenced``): its metadata, its
    levels (their running sums) and its power are those of the same scan decoded from PIL's
    pixels, whatever bins the layout drops or pads and whichever way it turns."""
    import dataclasses
    import io

    from PIL import Image

    layout = dataclasses.replace(navtech.PolarLayout(), range_offset_m=range_offset_m, clockwise=clockwise,
                                 **({"bin_spacing_m": 0.0438} if range_offset_m else {}))
    for path in scans[:2]:
        scan = navtech.load_scan(path, layout)
        pixels = np.asarray(Image.open(io.BytesIO(path.read_bytes())))
        expected = navtech.decode_scan(pixels, layout, path)
        assert scan.differenced and not expected.differenced
        for name in ("timestamps_ns", "angles_rad", "valid", "acquired"):
            assert np.array_equal(getattr(scan, name), getattr(expected, name)), name
        assert scan.levels.shape == expected.levels.shape == (400, 3768 + int(round(range_offset_m / 0.0438)))
        assert np.array_equal(scan.levels, expected.levels)
        assert np.array_equal(png.running_sums(scan.coded_levels), expected.levels)
        assert np.array_equal(scan.power(), expected.power())


def test_bad_files_are_refused(tmp_path):
    bad = tmp_path / "1.png"
    bad.write_bytes(b"not a png")
    with pytest.raises(FrameFormatError, match="not a PNG file"):
        navtech.load_scan(bad)
    from PIL import Image

    Image.fromarray(np.zeros((4, 8), np.uint8)).save(tmp_path / "2.png")
    with pytest.raises(FrameFormatError, match=r"the image is 4 x 8 \(rows x columns\); the layout reads n azimuth rows x "
                                                 r"\(11 metadata \+ bins\) columns: no range bins"):
        navtech.load_scan(tmp_path / "2.png")
    with pytest.raises(FrameFormatError, match="not a directory of polar PNG scans"):
        navtech.scan_paths(tmp_path / "empty")


def test_detection_on_a_real_scan_matches_the_oracle(runtime, scans):
    scan = navtech.load_scan(scans[3])
    power = scan.power()
    cfar_config = CfarConfig()
    interpret_config = InterpretConfig(range_min_m=2.0, range_max_m=160.0, max_pulses=128)
    spacing = load_sensor("navtech-cts350x").bin_spacing_m()
    result = Detection(runtime, (400,), scan.n_bins, spacing, cfar_config, interpret_config)(power)
    assert np.isfinite(result.cfar.noise).all() and np.isfinite(result.cfar.ratio).all()
    mask = check_against_oracle(result.cfar, power, cfar_config)
    per_azimuth = mask.sum(axis=1)
    # plausible: every azimuth sees something, none is mostly detections
    assert per_azimuth.min() >= 1 and per_azimuth.max() < 0.3 * scan.n_bins
    # the interpreter on 40 azimuths (the plain oracle walks bins in Python)
    rows = slice(0, 400, 10)
    evidence, pulses, n_pulses, flags = oracle.interpret(
        power[rows], result.cfar.noise[rows], result.cfar.mask[rows], interpret_config, spacing)
    got = result.interpret
    assert np.array_equal(got.n_pulses[rows], n_pulses) and np.array_equal(got.pulses[rows], pulses)
    assert np.array_equal(got.flags[rows], flags) and got.valid.all()
    diff = np.abs(got.evidence[rows].astype(np.int64) - evidence)
    assert diff.max() <= EVIDENCE_UNITS_TOL and np.array_equal(diff[~result.cfar.mask[rows]], 0 * diff[~result.cfar.mask[rows]])
    assert 5 <= got.n_pulses.mean() <= 200


def test_cli_plots_one_azimuth(scans, tmp_path, capsys):
    out = tmp_path / "fig.png"
    assert main(["navtech", str(scans[0]), "--azimuth", "100", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert out.stat().st_size > 10_000 and "pulses per azimuth" in text and "azimuth 100:" in text
    assert main(["navtech", str(scans[0]), "--azimuth", "100", "--out", str(out)]) == 2
    assert "exists; pass --force to replace it" in capsys.readouterr().err
    assert main(["navtech", str(scans[0]), "--azimuth", "400", "--out", str(out), "--force"]) == 2
    assert "--azimuth must be in [0, 399]" in capsys.readouterr().err


def test_a_recording_read_for_fusion_leaves_its_levels_in_the_files(scans, tmp_path):
    """``read_sequence(keep_levels=False)`` (what ``radarcl fuse`` reads a folder with) keeps each
    scan's times and angles, not its levels: they are read again when asked for, the same
    levels; a scan whose file changed since is refused with a sentence naming it."""
    import shutil

    for path in scans[:3]:
        shutil.copy(path, tmp_path / path.name)
    kept = navtech.read_sequence(tmp_path, navtech.PolarLayout(), odometry=False)
    left = navtech.read_sequence(tmp_path, navtech.PolarLayout(), odometry=False, keep_levels=False)
    for a, b in zip(kept.scans, left.scans):
        assert isinstance(b.stored_levels, navtech.StoredLevels) and b.shape == a.shape == (400, 3768)
        assert np.array_equal(a.timestamps_ns, b.timestamps_ns) and np.array_equal(a.angles_rad, b.angles_rad)
        assert b.differenced == a.differenced and np.array_equal(b.coded_levels, a.coded_levels)
        assert np.array_equal(b.levels, a.levels)
    shutil.copy(scans[5], tmp_path / scans[1].name)           # the same size: read as it is now
    assert not np.array_equal(left.scans[1].levels, kept.scans[1].levels)
    from PIL import Image

    Image.fromarray(np.zeros((400, 3000), np.uint8)).save(tmp_path / scans[2].name)
    with pytest.raises(FrameFormatError, match=rf"{scans[2].name}: the scan changed since it was first read \(now 400 x "
                                               r"2989 levels, first 400 x 3768\); read the recording again$"):
        left.scans[2].coded_levels


def test_differences_decoded_from_the_caller_s_array_leave_it_as_it_was():
    """``decode_scan(..., differenced=True)`` of an array in memory (no metadata, nothing dropped,
    counter-clockwise: no step copies it on the way) writes its first levels into a copy, not
    into the caller's differences; a layout that drops every bin is refused with a sentence."""
    import dataclasses

    layout = navtech.PolarLayout(meta_columns=0, timestamp_column=-1, encoder_column=-1, valid_column=-1,
                                 clockwise=False)
    levels = np.arange(10, 60, 10, dtype=np.uint8)[None].repeat(3, axis=0)
    coded = levels.copy()
    coded[:, 1:] -= levels[:, :-1]
    before = coded.copy()
    scan = navtech.decode_scan(coded, layout, "mem", differenced=True)
    assert np.array_equal(coded, before) and not np.shares_memory(scan.coded_levels, coded)
    assert np.array_equal(scan.levels, levels)
    dropped = dataclasses.replace(layout, range_offset_m=-6.0, bin_spacing_m=1.0)
    for differenced, frame in ((True, coded), (False, levels)):
        with pytest.raises(FrameFormatError, match=r"^mem: \[reader\] range_offset_m = -6 m drops 6 bins, every one of "
                                                   r"the scan's 5; check range_offset_m and \[range\] bin_spacing_m$"):
            navtech.decode_scan(frame, dropped, "mem", differenced=differenced)
