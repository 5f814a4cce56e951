"""Hostile input: property-based generation (hypothesis) of configurations, profiles, frames and
poses, and a seeded corpus of malformed files (truncated, bit-flipped, wrong and repeated keys,
bombs). Every case must end in success or a radarcl error (a sentence), never another
exception; a refused frame leaves the map bit-identical; a file that loads after damage must
hold exactly what was written (npz and PNG carry checksums); bombs stay within memory.

CI runs a short pass (well under a minute). RADARCL_FUZZ=long runs 20x more examples and a
larger corpus; RADARCL_FUZZ_REPORT=FILE writes the counts (cases, clear errors, crashes, other
exceptions, silent wrong answers, peak memory on the bombs) as JSON.
"""

import json
import os
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from peak_memory import peak_growth

from radarcl.config import mapconfig, sensors
from radarcl.errors import RadarclError
from radarcl.io.beam_protocol import MAX_HEADER_SIZE

LONG = os.environ.get("RADARCL_FUZZ", "") == "long"
EXAMPLES = 400 if LONG else 25
FLIPS = 200 if LONG else 25
RUN = settings(max_examples=EXAMPLES, deadline=None, derandomize=not LONG,
               suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
COUNTS = {"cases": 0, "ok": 0, "clear_errors": 0, "other_exceptions": 0, "silent_wrong": 0}


def outcome(fn, *args, **kwargs):
    """Run one case: 'ok' with its value, or 'error' for a RadarclError; anything else fails."""
    COUNTS["cases"] += 1
    try:
        value = fn(*args, **kwargs)
    except RadarclError as exc:
        COUNTS["clear_errors"] += 1
        assert str(exc), "a radarcl error must say what was wrong"
        return "error", exc
    except Exception as exc:                   # noqa: BLE001 - the point of the test
        COUNTS["other_exceptions"] += 1
        raise AssertionError(f"{type(exc).__name__} instead of a radarcl error: {exc}") from exc
    COUNTS["ok"] += 1
    return "ok", value


@pytest.fixture(scope="module", autouse=True)
def report():
    yield
    path = os.environ.get("RADARCL_FUZZ_REPORT")
    if path:
        with open(path, "w") as f:
            json.dump(COUNTS, f, indent=1)


# -- configurations and profiles ---------------------------------------------------------------------
SCALARS = st.one_of(st.integers(-10 ** 12, 10 ** 12), st.floats(allow_nan=True, allow_infinity=True),
                    st.booleans(), st.text(max_size=8), st.lists(st.floats(-1e3, 1e3), max_size=4))
CONFIG_KEYS = st.sampled_from(sorted(mapconfig.KEYS) + ["cfar.guard", "grid.voxel", "beam.kind", "sensor.name"])


@RUN
@given(st.dictionaries(CONFIG_KEYS, SCALARS, max_size=6), st.sampled_from(sensors.builtin_names()))
def test_configuration_flags(values, sensor):
    kind, resolved = outcome(lambda: mapconfig.resolve(sensor, flags={k: v for k, v in values.items()}))
    if kind == "ok":
        resolved.cfar_config(), resolved.interpret_config(), resolved.grid_spec()


@RUN
@given(st.dictionaries(st.sampled_from(["range_fft", "cfar", "interpret", "beam", "grid", "extra"]),
                       st.dictionaries(st.sampled_from(["n_fft", "kind", "pfa", "guard_m", "train_m", "k_occ",
                                                        "e_high", "voxel_m", "size_m", "model", "x"]),
                                       SCALARS, max_size=4), max_size=4))
def test_configuration_files(tmp_path_factory, tables):
    from radarcl.config import tomlfile

    path = tmp_path_factory.mktemp("cfg") / "c.toml"
    try:
        path.write_text(tomlfile.dumps(tables))
    except RadarclError:
        return                                  # a value TOML cannot hold (NaN): nothing to read
    outcome(mapconfig.resolve, "paper", path)


@RUN
@given(st.sampled_from(["range", "beams", "mounting", "reader", "waveform"]),
       st.sampled_from(["bin_spacing_m", "n_bins", "range_max_m", "n_azimuth", "beamwidth_az_deg", "height_m",
                        "meta_columns", "encoder_counts", "n_samples", "sample_rate_hz", "spinning", "nope"]),
       SCALARS, st.sampled_from(["polar-png", "navtech-cts350x", "paper", "ti-xwr-openradar"]))
def test_profiles(tmp_path_factory, section, key, value, base):
    from radarcl.config import tomlfile

    path = tmp_path_factory.mktemp("prof") / "p.toml"
    parent = sensors.load(base)
    try:
        path.write_text(tomlfile.dumps({section: {key: value}}, top={"name": "fuzz", "input": parent.input,
                                                                      "extends": base}))
    except RadarclError:
        return
    kind, s = outcome(sensors.load, path)
    if kind == "ok":
        outcome(mapconfig.resolve, s)


# -- frames and poses through the pipeline --------------------------------------------------------------
@pytest.fixture(scope="module")
def ti_mapping(runtime):
    from radarcl.pipeline import Mapping

    return Mapping.from_config(runtime, "ti-xwr-openradar", mapconfig.resolve("ti-xwr-openradar",
                                                                              flags={"grid.voxel_m": 0.2}))


SPECIALS = st.sampled_from([0.0, np.nan, np.inf, -np.inf, 1e10, 1e30, 3e38, -32768.0, 1e-45])


@RUN
@given(st.sampled_from([(1, 1, 128), (1, 1, 127), (1, 128), (2, 1, 128)]),
       st.sampled_from([np.complex64, np.complex128, np.float32, np.int16]),
       st.lists(st.tuples(st.integers(0, 127), SPECIALS), max_size=4), st.integers(0, 2 ** 31))
def test_frames(ti_mapping, shape, dtype, specials, seed):
    rng = np.random.default_rng(seed)
    frame = (rng.standard_normal(shape) * 100).astype(dtype) if dtype != np.int16 else \
        rng.integers(-2000, 2000, shape).astype(np.int16)
    with np.errstate(invalid="ignore", over="ignore"):
        for j, v in specials:
            if frame.size:
                frame.reshape(-1)[j % frame.size] = v if np.dtype(dtype).kind in "fc" else np.int16(-32768)
    before = ti_mapping.snapshot()
    kind, _ = outcome(ti_mapping.fuse, frame, np.eye(4))
    after = ti_mapping.snapshot()
    if kind == "error":
        assert np.array_equal(before, after), "a refused frame changed the map"
    assert np.abs(after.astype(np.int64)).max() <= 2 ** 30


@RUN
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=16, max_size=16),
       st.booleans())
def test_poses(ti_mapping, numbers, rigid):
    pose = np.array(numbers).reshape(4, 4)
    if rigid:                                     # mostly-valid poses: a rotation and a translation
        from radarcl.geometry import pose_from_xyz_rpy

        t = np.nan_to_num(pose[0, :3], posinf=1e3, neginf=-1e3)
        angles = np.nan_to_num(pose[1, :3], nan=0.0, posinf=3.0, neginf=-3.0) % 6.3
        pose = pose_from_xyz_rpy(*t, *angles)
    frame = np.zeros((1, 1, 128), np.complex64)
    frame[0, 0, ::7] = 50 + 20j
    before = ti_mapping.snapshot()
    kind, _ = outcome(ti_mapping.fuse, frame, pose)
    if kind == "error":
        assert np.array_equal(before, ti_mapping.snapshot())


# -- a seeded corpus of damaged files ---------------------------------------------------------------------
def _damaged(raw, rng, n):
    """Truncations at awkward places and single bit flips of ``raw``."""
    cuts = sorted({0, 1, 4, 22, 30, 64, len(raw) // 2, len(raw) - 1} | set(rng.integers(0, len(raw), n // 4)))
    for c in cuts:
        yield f"truncated at {c}", raw[:c]
    for _ in range(n):
        b = bytearray(raw)
        i = int(rng.integers(0, len(b)))
        b[i] ^= 1 << int(rng.integers(0, 8))
        yield f"bit flip at {i}", bytes(b)


def _npz_bytes(**arrays):
    import io

    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def _bomb_npz(declared_shape=(1 << 40,), dtype="<i4"):
    """An npz whose only member declares a huge array in a few bytes."""
    import io

    header = {"descr": dtype, "fortran_order": False, "shape": declared_shape}
    npy = io.BytesIO()
    np.lib.format.write_array_header_1_0(npy, header)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("data.npy", npy.getvalue() + b"\0" * 64)
        for key in ("version", "origin_m", "voxel_m", "shape", "keys"):
            z.writestr(f"{key}.npy", _member(key))
    return buf.getvalue()


def _member(key):
    import io

    values = dict(version=np.int64(1), origin_m=np.zeros(3), voxel_m=np.float64(0.5), shape=np.array([16, 16, 16]),
                  keys=np.zeros((1, 3), np.int32))
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asarray(values[key]))
    return buf.getvalue()


def test_damaged_files(tmp_path, shared_data):
    """Every loader on truncated and bit-flipped copies of a valid file: a radarcl error, or (npz,
    PNG: checksummed) exactly the original content."""
    from radarcl.io import polar_png, recording
    from radarcl.maps.disk import read

    rng = np.random.default_rng(0)
    spec_arrays = dict(version=1, origin_m=np.zeros(3), voxel_m=0.5, shape=np.array([24, 16, 8]),
                       keys=np.array([[0, 0, 0], [2, 1, 0]], np.int32),
                       data=rng.integers(-999, 999, (2, 8, 8, 8)).astype(np.int32))
    rec_arrays = dict(version=2, sensor=np.str_("ti-xwr-openradar"),
                      frames=(rng.standard_normal((3, 1, 1, 128)) * 50).astype(np.complex64),
                      poses=np.broadcast_to(np.eye(4), (3, 4, 4)).copy())
    png = (shared_data / "navtech_oxford" / "radar" / "1547131046353776.png").read_bytes()
    layout = polar_png.PolarLayout()
    cases = [("map", _npz_bytes(**spec_arrays), lambda p: read(p)[2]),
             ("recording", _npz_bytes(**rec_arrays), lambda p: recording.load(p).frames),
             ("polar scan", png, lambda p: polar_png.load_scan(p, layout).levels)]
    for name, raw, load in cases:
        path = tmp_path / ("x.png" if name == "polar scan" else "x.npz")
        path.write_bytes(raw)
        original = load(path)
        for what, damaged in _damaged(raw, rng, FLIPS):
            path.write_bytes(damaged)
            kind, value = outcome(load, path)
            if kind == "ok" and not np.array_equal(value, original):
                COUNTS["silent_wrong"] += 1
                raise AssertionError(f"{name} {what}: loaded different content without a word")


def test_crafted_files(tmp_path):
    """Wrong keys, repeated keys, keys outside the grid, declared sizes far beyond the data and a
    1 GiB deflate bomb: refused, within memory."""
    from radarcl.maps.disk import read

    good = dict(version=1, origin_m=np.zeros(3), voxel_m=0.5, shape=np.array([16, 16, 16]),
                keys=np.zeros((1, 3), np.int32), data=np.zeros((1, 8, 8, 8), np.int32))
    variants = {
        "repeated key": dict(good, keys=np.zeros((2, 3), np.int32), data=np.zeros((2, 8, 8, 8), np.int32)),
        "key outside": dict(good, keys=np.array([[5, 0, 0]], np.int32)),
        "negative key": dict(good, keys=np.array([[-1, 0, 0]], np.int32)),
        "float data": dict(good, data=np.zeros((1, 8, 8, 8))),
        "beyond saturation": dict(good, data=np.full((1, 8, 8, 8), 2 ** 31 - 1, np.int32)),
        "shape 0": dict(good, shape=np.array([0, 16, 16])),
        "voxel nan": dict(good, voxel_m=np.nan),
        "missing data": {k: v for k, v in good.items() if k != "data"},
        "object array": dict(good, version=np.array([None], dtype=object)),
    }
    for name, arrays in variants.items():
        path = tmp_path / f"{name}.npz"
        with open(path, "wb") as f:
            np.savez(f, **arrays, allow_pickle=True) if name == "object array" else np.savez(f, **arrays)
        kind, _ = outcome(read, path)
        assert kind == "error", name
    huge = tmp_path / "huge.npz"                  # 2^60 voxels declared, one brick stored
    with open(huge, "wb") as f:
        np.savez(f, **dict(good, shape=np.array([1 << 20, 1 << 20, 1 << 20])))
    bomb = tmp_path / "bomb.npz"
    bomb.write_bytes(_bomb_npz())
    # a deflate bomb: 1 GiB of zeros in ~1 MB, its header honest about the size
    import io

    size = 1 << 30
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<i4", "fortran_order": False, "shape": (size // 4,)})
    with zipfile.ZipFile(tmp_path / "deflate.npz", "w", zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        with z.open("data.npy", "w", force_zip64=True) as f:
            f.write(header.getvalue())
            zero = b"\0" * (1 << 24)
            for _ in range(size >> 24):
                f.write(zero)
        for key in ("version", "origin_m", "voxel_m", "shape", "keys"):
            z.writestr(f"{key}.npy", _member(key))
    assert (tmp_path / "deflate.npz").stat().st_size < 8 << 20
    # the three loaded in a fresh process, whose peak memory is theirs alone (peak_memory.py)
    grew, got = peak_growth(BOMB_IMPORTS, BOMB_BODY.format(huge=str(huge), bomb=str(bomb),
                                                           deflate=str(tmp_path / "deflate.npz")),
                            env={"RADARCL_MEMORY_BUDGET": str(256 << 20)})
    COUNTS["cases"] += 3
    COUNTS["clear_errors"] += sum(kind == "error" for kind, _ in got.values())
    COUNTS["ok"] += sum(kind == "ok" for kind, _ in got.values())
    assert got["huge"][0] == "ok" and "max-pooled" in got["huge"][1] and got["pooled_bytes"][1] < 64 << 20, got
    assert got["bomb"][0] == got["deflate"][0] == "error", got
    COUNTS["bomb_peak_growth_mib"] = round(grew, 1)
    assert grew < 512, f"the bombs took {grew:.0f} MiB"


BOMB_IMPORTS = """
from radarcl.errors import RadarclError
from radarcl.maps.disk import read
from radarcl.viewer.volume import load_map
"""
BOMB_BODY = """
result = {{}}
for name, load in (("huge", lambda: load_map({huge!r}, budget=256 << 20)), ("bomb", lambda: read({bomb!r})),
                   ("deflate", lambda: read({deflate!r}))):
    try:
        value = load()
        result[name] = ("ok", getattr(value, "note", ""))
        if name == "huge":
            result["pooled_bytes"] = ("ok", int(value.values.nbytes))
    except RadarclError as exc:
        result[name] = ("error", str(exc))
"""


def test_png_declaring_a_huge_image(tmp_path):
    """A small PNG that declares 20000 x 6000 pixels is refused before it is decoded."""
    from PIL import Image

    from radarcl.io import polar_png

    path = tmp_path / "huge.png"
    Image.new("L", (20000, 6000)).save(path, optimize=True)
    assert path.stat().st_size < 1 << 20
    kind, exc = outcome(polar_png.load_scan, path)
    assert kind == "error" and "refused before decoding" in str(exc)
    # decoded, it would take 114 MiB: in a fresh process (peak_memory.py), the refusal takes < 64
    grew, said = peak_growth("from radarcl.errors import RadarclError\nfrom radarcl.io import polar_png",
                             f"""
try:
    polar_png.load_scan({str(path)!r})
except RadarclError as exc:
    result = str(exc)
""")
    assert "refused before decoding" in said and grew < 64, (grew, said)


def _png(chunks):
    """A PNG file's bytes of (kind, body) chunks, each with its right CRC."""
    import struct
    import zlib

    from radarcl.io.png import PNG_SIGNATURE

    return PNG_SIGNATURE + b"".join(struct.pack(">I", len(body)) + kind + body
                                    + struct.pack(">I", zlib.crc32(kind + body)) for kind, body in chunks)


def test_pngs_with_no_pixels_or_a_malformed_header_are_refused_with_a_sentence(tmp_path):
    """An empty image (which would hand a scan of no azimuths on, or inflate without a bound) and
    a header chunk that is short, late or repeated: each a one-sentence refusal before decoding.
    Their CRCs are right, so the check of the chunks alone would pass them."""
    import struct
    import zlib

    from radarcl.io import polar_png

    def header(width, height, size=13):
        return b"IHDR", (struct.pack(">II", width, height) + bytes([8, 0, 0, 0, 0]))[:size]

    data = b"IDAT", zlib.compress(b"\0" * (8 * 1000 + 1) * 4)
    cases = {"no rows": ([header(8, 0), data], "0 pixels"), "no columns": ([header(0, 4), data], "x 4 pixels"),
             "short header": ([header(8, 4, size=8), data], "13 bytes"),
             "late header": ([data, header(8, 4)], "must come first"),
             "two headers": ([header(8, 4), header(8, 4), data], "once")}
    for name, (chunks, said) in cases.items():
        path = tmp_path / f"{name.replace(' ', '_')}.png"
        path.write_bytes(_png(chunks + [(b"IEND", b"")]))
        kind, exc = outcome(polar_png.load_scan, path)
        assert kind == "error" and "not a valid PNG" in str(exc) and said in str(exc), (name, kind, exc)


def test_the_cli_answers_hostile_arguments_with_a_sentence(tmp_path, capsys):
    """Bad files and bad arguments through the CLI: exit 2 and one line, never a traceback or
    the "unexpected error" of a bug (exit 70)."""
    from radarcl.cli import main

    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"PK\x03\x04" + bytes(range(200)))
    zero = tmp_path / "zero.npz"
    with open(zero, "wb") as f:
        np.savez(f, version=2, sensor=np.str_("paper"), frames=np.zeros((0, 64, 4, 256), np.int16),
                 poses=np.zeros((0, 4, 4)))
    notes = tmp_path / "notes.txt"
    notes.write_text("not a radar file")
    bad_toml = tmp_path / "bad.toml"
    bad_toml.write_text("[cfar\nkind = 'so'\n")
    good = tmp_path / "good.npz"                 # a valid map, so that the settings are what is refused
    with open(good, "wb") as f:
        np.savez(f, version=1, origin_m=np.zeros(3), voxel_m=0.5, shape=np.array([16, 16, 16]),
                 keys=np.zeros((1, 3), np.int32), data=np.full((1, 8, 8, 8), 3000, np.int32))
    out = tmp_path / "out.npz"
    argvs = [
        ["fuse", str(empty), "--out", str(out)], ["fuse", str(junk), "--out", str(out)],
        ["fuse", str(zero), "--out", str(out)], ["fuse", str(notes), "--out", str(out)],
        ["fuse", str(tmp_path), "--out", str(out), "--sensor", "polar-png"],
        ["fuse", str(junk), "--out", str(out), "--every", "0"], ["fuse", str(junk), "--voxel", "0"],
        ["fuse", str(junk), "--voxel", "nan"], ["fuse", str(junk), "--voxel", "-1"],
        ["fuse", str(junk), "--set", "cfar.guard_m=-3"], ["fuse", str(junk), "--set", "cfar"],
        ["fuse", str(junk), "--config", str(bad_toml)], ["fuse", str(junk), "--sensor", "nosuch"],
        ["fuse", str(junk), "--out", str(tmp_path)], ["fuse", str(junk), "--out", "/dev/null"],
        ["render", str(junk), "--out", str(tmp_path / "v.png")], ["render", str(empty)],
        ["render", str(tmp_path / "missing.npz")], ["render", str(junk), "--size", "0", "0"],
        ["render", str(good), "--threshold", "nan"], ["render", str(good), "--gamma", "inf"],
        ["render", str(good), "--camera", "nan,0"], ["render", str(good), "--camera", "1e400,0"],
        ["render", str(good), "--lo", "2", "--hi", "1"], ["render", str(good), "--out", str(good), "--force"],
        ["view", str(tmp_path / "missing.npz"), "--window", "headless", "--frames", "1"],
        ["navtech", str(notes)], ["navtech", str(tmp_path / "missing.png")],
        ["navtech-map", str(tmp_path)], ["config", "show", "--config", str(bad_toml)],
        ["config", "save"], ["sensors", str(notes)], ["tune", "--replay", str(junk)],
        ["demo", "--replay", str(zero), "--out", str(tmp_path / "d")],
        ["bench", "quality", "--replay", str(junk), "--chart", str(tmp_path / "q.png")],
        ["bench", "quality", "--voxels", "0.15", "--chart", str(tmp_path / "q.png")],
        ["bench", "fusion", "--repeat", "0"], ["bench", "range-fft", "--n-fft", "100"],
    ]
    for argv in argvs:
        COUNTS["cases"] += 1
        try:
            status = main(argv)
        except SystemExit as exc:                 # argparse: a usage line and the reason
            status = exc.code
        err = capsys.readouterr().err
        assert status == 2, (argv, status, err)
        assert "Traceback" not in err and err.strip(), argv
        COUNTS["clear_errors"] += 1
    assert not out.exists()


# -- serial streams: 10^6 mutated byte streams in the long run ---------------------------------------
STREAMS = 1_000_000 if LONG else 20_000
STREAM_COUNTS = {"streams": 0, "packets_delivered": 0, "exceptions": 0, "over_work": 0, "bad_deliveries": 0,
                 "intact_lost": 0, "counter_mismatches": 0, "extra_looks": 0, "max_work_per_byte": 0.0}
# The parsers' work on a stream, counted, not timed (one preemption of a loaded runner is not a
# bug): every byte the searches for a magic word scan, every byte a CRC reads or a TI frame's
# inner search copies, and every byte of a delivered packet (decoded once). A linear parser does
# at most WORK_PER_BYTE per byte fed, beside at most a header's bytes per look at a header (a
# packet still incomplete is looked at again when more bytes arrive; a look reads at most
# MAX_HEADER_SIZE bytes of it). Measured: at most 3.1 per byte on the 20,000 streams of the CI
# run (docs/guide/bad-input.md); a search that restarts at a frame's start on every chunk goes
# quadratic (test_parsers_work_linearly_on_a_packet_that_arrives_byte_by_byte).
WORK_PER_BYTE = 4
WORK_PER_LOOK = MAX_HEADER_SIZE


def _occurrences(magic, data):
    """Positions where ``magic`` starts in ``data`` (overlapping ones too)."""
    count, i = 0, data.find(magic)
    while i >= 0:
        count, i = count + 1, data.find(magic, i + 1)
    return count


class _CountingBuffer(bytearray):
    """A parser's buffer that counts the bytes its ``find`` scans."""

    scanned = 0

    def find(self, sub, start=0, *end):
        i = super().find(sub, start, *end)
        stop = (end[0] if end else len(self)) if i < 0 else i + len(sub)
        self.scanned += max(0, stop - start)
        return i


class _WorkCounter:
    """Counts a parser's work (see WORK_PER_BYTE): its buffer's searches, the CRCs the beam
    protocol computes, the frame bytes the TI parser copies to search them, its looks at
    headers. ``monkeypatch`` swaps the modules' zlib and bytes for counting ones."""

    def __init__(self, monkeypatch):
        import zlib

        from radarcl.io import beam_protocol, ti_uart

        self.crc = self.copied = self.looks = 0
        counter = self

        def crc32(data, *value):
            counter.crc += len(data)
            return zlib.crc32(data, *value)

        def copy(data=b"", *args):
            out = bytes(data, *args)
            counter.copied += len(out)
            return out

        monkeypatch.setattr(beam_protocol, "zlib", type("CountingZlib", (), {"crc32": staticmethod(crc32)}))
        monkeypatch.setattr(ti_uart, "bytes", copy, raising=False)
        self.parsers = []

    def watch(self, parser):
        """``parser`` with a counting buffer and examinations; returns it."""
        parser._buf = _CountingBuffer(parser._buf)
        examine = parser._examine

        def counted(view):
            self.looks += 1
            return examine(view)

        parser._examine = counted
        self.parsers.append(parser)
        return parser

    def take(self):
        """(bytes worked on, looks at a header) since the last call."""
        work = self.crc + self.copied + sum(p._buf.scanned + p.counters.bytes_in_packets for p in self.parsers)
        looks = self.looks
        self.crc = self.copied = self.looks = 0
        self.parsers = []
        return work, looks


def _capture(protocol, rng):
    """A valid stream of 1-5 packets: (list of packets, a way to tell a delivered one was sent)."""
    from radarcl.io import beam_protocol, emulator

    n = int(rng.integers(1, 6))
    if protocol == "beams":
        packets = [beam_protocol.encode(int(rng.integers(0, 1 << 32)), j, j % 3, j % 2, j,
                                        rng.integers(-999, 999, int(rng.integers(1, 64))).astype(np.int16),
                                        np.eye(4) if j % 2 else None) for j in range(n)]
    else:
        packets = emulator.ti_packets(rng.integers(0, 65535, (n, int(rng.integers(1, 40)))).astype(np.uint16),
                                      first_frame=int(rng.integers(0, 1000)),
                                      version=[0x01020000, 0x02010004, 0x03050004][int(rng.integers(0, 3))])
    return packets


def _mutate(packets, rng):
    """Damage at original positions (from the end, so positions stay valid): returns (bytes,
    indices of the packets no damage touched)."""
    from radarcl.io import beam_protocol, ti_uart

    data = bytearray(b"".join(packets))
    if rng.random() < 0.05:                                # pure noise, now and then with magic words
        junk = rng.integers(0, 256, int(rng.integers(0, 3000)), np.uint8).tobytes()
        return junk + (beam_protocol.MAGIC + ti_uart.MAGIC) * int(rng.integers(0, 3)), set()
    bounds = np.cumsum([0] + [len(p) for p in packets])
    touched = set()
    positions = np.sort(rng.integers(0, len(data), int(rng.integers(0, 5))))[::-1]
    grown = {}                                             # bytes a packet gained (or lost) so far
    for pos in positions.tolist():                         # from the end: earlier positions stay put
        if pos >= len(data):                               # a truncation at or before it came first
            continue
        op = rng.integers(0, 7)
        hit = int(np.searchsorted(bounds, pos, side="right") - 1)
        end = int(bounds[hit + 1]) + grown.get(hit, 0)     # where the packet ends now
        touched.add(hit)
        before = len(data)
        if op == 0:
            data[pos] ^= 1 << int(rng.integers(0, 8))
        elif op == 1:
            del data[pos:min(pos + int(rng.integers(1, 40)), end)]
        elif op == 2:
            data[pos:pos] = rng.integers(0, 256, int(rng.integers(1, 80)), np.uint8).tobytes()
        elif op == 3:
            data[pos:pos] = (beam_protocol.MAGIC if rng.random() < 0.5 else ti_uart.MAGIC) + \
                rng.integers(0, 256, int(rng.integers(0, 60)), np.uint8).tobytes()
        elif op == 4:
            data[pos:pos] = data[pos:min(pos + int(rng.integers(1, 100)), end)]
        elif op == 5:
            del data[pos:]
            touched.update(range(hit, len(packets)))
        else:
            data[pos] = int(rng.integers(0, 256))
        grown[hit] = grown.get(hit, 0) + len(data) - before
    return bytes(data), set(range(len(packets))) - touched


def test_parsers_work_linearly_on_a_packet_that_arrives_byte_by_byte(monkeypatch):
    """A 16 KiB TI frame and a long beam packet fed one byte at a time (a slow line): each look
    at the pending packet searches only the bytes that are new, so the work stays linear
    (WORK_PER_BYTE per byte beside WORK_PER_LOOK per look); a search from the frame's start on
    every chunk would be quadratic, 8,000 bytes per byte here."""
    from radarcl.io import beam_protocol, emulator, ti_uart

    work = _WorkCounter(monkeypatch)
    profiles = (np.arange(2 * 8192, dtype=np.uint16).reshape(2, 8192) % 4000 + 1000).astype(np.uint16)
    streams = {"ti": emulator.ti_packets(profiles),
               "beams": [beam_protocol.encode(7 + j, 0, j, 2, 3, np.arange(4000, dtype=np.int16), np.eye(4))
                         for j in range(2)]}
    for protocol, packets in streams.items():
        data = b"".join(packets)
        work.take()
        parser = work.watch(beam_protocol.BeamParser() if protocol == "beams" else ti_uart.TiParser())
        for k in range(len(data)):
            parser.data_received(data[k:k + 1])
        spent, looks = work.take()
        assert len(parser.take()) == 2 and parser.counters.bytes_dropped == 0, protocol
        assert looks <= _occurrences(parser.MAGIC, data) + len(data), (protocol, looks)
        assert spent <= WORK_PER_BYTE * len(data) + WORK_PER_LOOK * looks, (protocol, spent / len(data))


def test_stream_parsers_survive_mutated_streams(monkeypatch):
    """Both protocols' parsers on STREAMS seeded mutated captures (bit flips, deletions,
    insertions, fake magic words, repeats, truncation, pure noise) fed in random chunks, then a
    packet's length of zeros (what follows on a live line): no exception, work linear in the
    bytes fed (counted: WORK_PER_BYTE), every delivered beam packet one that was sent (its CRC
    checked), every untouched beam packet delivered (a TI frame: when the one before it is
    untouched too; that protocol has no CRC, a damaged frame may claim the next one's bytes),
    the counters adding up."""
    from radarcl.io import beam_protocol, ti_uart

    work = _WorkCounter(monkeypatch)
    rng = np.random.default_rng(20261123)
    for i in range(STREAMS):
        protocol = "beams" if i % 2 else "ti"
        packets = _capture(protocol, rng)
        data, intact = _mutate(packets, rng)
        work.take()                                # not the CRCs of encoding the capture
        parser = work.watch(beam_protocol.BeamParser() if protocol == "beams" else ti_uart.TiParser())
        cuts = np.sort(rng.integers(0, len(data) + 1, int(rng.integers(0, 6))))
        STREAM_COUNTS["streams"] += 1
        tail = bytes(max(len(p) for p in packets))
        try:
            prev = 0
            for c in list(cuts) + [len(data)]:
                parser.data_received(data[prev:c])
                prev = c
            # the radar goes on sending: a packet cut short waits for at most its own length in
            # bytes, then fails its check, and what it held back is searched again
            parser.data_received(tail)
        except Exception:                          # noqa: BLE001 - counted, then the test fails
            STREAM_COUNTS["exceptions"] += 1
            raise
        fed, chunks = len(data) + len(tail), len(cuts) + 2
        spent, looks = work.take()
        magics = _occurrences(parser.MAGIC, data + tail)
        STREAM_COUNTS["over_work"] += spent > WORK_PER_BYTE * fed + WORK_PER_LOOK * looks
        STREAM_COUNTS["extra_looks"] += looks > magics + chunks
        STREAM_COUNTS["max_work_per_byte"] = max(STREAM_COUNTS["max_work_per_byte"], spent / fed)
        got = parser.take()
        STREAM_COUNTS["packets_delivered"] += len(got)
        c = parser.counters
        STREAM_COUNTS["counter_mismatches"] += c.bytes_in != c.bytes_in_packets + c.bytes_dropped + c.bytes_pending
        if protocol == "beams":
            sent = {beam_protocol.encode(p.sequence, p.frame, p.azimuth, p.elevation, p.timestamp_ns, p.samples,
                                         p.pose) for p in got}
            STREAM_COUNTS["bad_deliveries"] += len(sent - set(packets))
            STREAM_COUNTS["intact_lost"] += len({packets[j] for j in intact} - sent)
        else:                    # no CRC: a frame arrives when it and the one before it are whole
            numbers = {f.frame_number for f in got}
            first = int.from_bytes(packets[0][20:24], "little")
            STREAM_COUNTS["intact_lost"] += sum(first + j not in numbers for j in intact if j == 0 or j - 1 in intact)
    COUNTS.update({f"stream_{k}": v for k, v in STREAM_COUNTS.items()})
    assert STREAM_COUNTS["exceptions"] == STREAM_COUNTS["over_work"] == STREAM_COUNTS["bad_deliveries"] == 0, \
        STREAM_COUNTS
    assert STREAM_COUNTS["intact_lost"] == STREAM_COUNTS["counter_mismatches"] == STREAM_COUNTS["extra_looks"] == 0
    assert STREAM_COUNTS["packets_delivered"] > STREAMS
