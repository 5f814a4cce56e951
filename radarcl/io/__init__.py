"""Frame formats, recordings and readers of other radars' files. No pyopencl imports here.

``open_input(sensor, path)`` opens whatever the sensor profile's reader reads (its [reader]
``format``): a radarcl recording (``recording``), a directory of polar PNG scans with their
odometry (``polar-png``), a TI raw ADC capture (``ti-openradar``). It returns a
``FrameSource``: the sensor (with its bin count filled from the data where the profile leaves
it out), the frames, one pose (or one per beam) and optional flags per frame, and a line saying
what was read. Every size is checked against the sensor before a frame reaches a device.

``safe_npz`` opens an ``.npz`` without pickles and checks every array's declared size against
``memory_budget()`` before reading it.
"""

import os
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError, FrameFormatError


def memory_budget():
    """Bytes one loaded file may take: RADARCL_MEMORY_BUDGET (bytes), else half the RAM."""
    env = os.environ.get("RADARCL_MEMORY_BUDGET")
    if env:
        try:
            return int(float(env))
        except ValueError:
            raise ConfigError(f"RADARCL_MEMORY_BUDGET must be a number of bytes, got {env!r}") from None
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (ValueError, OSError, AttributeError):
        return 4 << 30


def read_npy_header(f):
    """(shape, dtype) from an open .npy stream positioned at its start."""
    version = np.lib.format.read_magic(f)
    read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
    shape, _, dtype = read(f)
    return shape, dtype


def declared_bytes(shape, dtype):
    """Bytes an array of ``shape`` and ``dtype`` takes (float64 arithmetic: never overflows)."""
    return float(np.prod(shape, dtype=np.float64)) * np.dtype(dtype).itemsize


# What zipfile and numpy raise on a damaged archive member (a flipped compression method field
# gives NotImplementedError, a damaged deflate stream zlib.error).
_DAMAGED = (KeyError, OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError)


class SafeNpz:
    """An ``.npz`` read member by member: no pickles, and each array's header (shape, dtype) is
    read and checked against the budget before its data is. Use as a context manager."""

    def __init__(self, path, budget=None, what="readable .npz file"):
        self.path = Path(path)
        self.budget = memory_budget() if budget is None else budget
        try:
            self._zip = zipfile.ZipFile(self.path)
        except (OSError, zipfile.BadZipFile, ValueError, NotImplementedError) as exc:
            raise FrameFormatError(f"{self.path} is not a {what} ({exc})") from exc
        names = self._zip.namelist()
        if len(set(names)) != len(names):
            raise FrameFormatError(f"{self.path}: an archive member appears twice")
        self.files = [n[:-4] for n in names if n.endswith(".npy")]
        self.used = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._zip.close()

    def header(self, key):
        """(shape, dtype) that member ``key`` declares."""
        try:
            with self._zip.open(f"{key}.npy") as f:
                shape, dtype = read_npy_header(f)
        except _DAMAGED as exc:
            raise FrameFormatError(f"{self.path}: member {key!r} is not a readable array ({exc})") from exc
        if dtype.hasobject:
            raise FrameFormatError(f"{self.path}: member {key!r} holds Python objects; radarcl never unpickles")
        return shape, dtype

    def __getitem__(self, key):
        shape, dtype = self.header(key)
        nbytes = declared_bytes(shape, dtype)
        if self.used + nbytes > self.budget:
            raise FrameFormatError(f"{self.path}: member {key!r} declares {shape} {dtype} = {nbytes / 2**20:.0f} MiB; "
                                   f"with the rest that exceeds the memory budget of {self.budget / 2**20:.0f} MiB "
                                   "(RADARCL_MEMORY_BUDGET)")
        try:
            with self._zip.open(f"{key}.npy") as f:
                array = np.lib.format.read_array(f, allow_pickle=False)
        except _DAMAGED as exc:
            raise FrameFormatError(f"{self.path}: member {key!r} is truncated or corrupt ({exc})") from exc
        self.used += nbytes
        return array


def safe_npz(path, budget=None, what="readable .npz file"):
    """A ``SafeNpz`` over ``path``; ``what`` names the expected kind of file in errors."""
    return SafeNpz(path, budget, what)


@dataclass
class FrameSource:
    """What ``open_input`` read: ``frames[i]`` with ``poses[i]`` ((4, 4) or (n_beams, 4, 4))
    and ``flags[i]`` (or None), for ``sensor``; ``summary`` says what was read."""

    sensor: object
    frames: object
    poses: object
    flags: object
    summary: str

    def __len__(self):
        return len(self.frames)


def open_input(sensor, path, odometry=None):
    """A ``FrameSource`` for ``path`` read as ``sensor``'s [reader] format says."""
    fmt = sensor.get("reader", "format", "recording")
    path = Path(path)
    if not path.exists():
        raise FrameFormatError(f"{path} does not exist")
    if fmt == "recording" or (path.is_file() and path.suffix == ".npz"):
        return _recording(sensor, path)
    if fmt == "ti-openradar":
        return _ti_capture(sensor, path)
    return _polar(sensor, path, odometry)


def _check_frame(sensor, shape, dtype, what):
    expected = sensor.frame_shape()
    if tuple(shape) != tuple(expected) or np.dtype(dtype) != sensor.sample_dtype:
        raise FrameFormatError(f"{what}: frames are {tuple(shape)} {np.dtype(dtype)}; sensor {sensor.name} "
                               f"expects {tuple(expected)} {sensor.sample_dtype}")


def _recording(sensor, path):
    from radarcl.io import recording

    rec = recording.load(path)
    if not sensor.raw and sensor.n_bins() is None:
        sensor = sensor.with_bins(rec.frames.shape[-1])
    _check_frame(sensor, rec.frames.shape[1:], rec.frames.dtype, str(path))
    n_beams = sensor.lattice().n_beams
    if rec.poses.ndim == 4 and rec.poses.shape[1] != n_beams:
        raise FrameFormatError(f"{path}: per-beam poses for {rec.poses.shape[1]} beams; sensor {sensor.name} has {n_beams}")
    note = "" if rec.sensor == sensor.name else f" (recorded as sensor {rec.sensor})"
    flags = rec.flags if rec.flags is not None else [None] * len(rec)
    return FrameSource(sensor, rec.frames, rec.poses, flags, f"{len(rec)} frames of {path}{note}")


def _ti_capture(sensor, path):
    from radarcl.io.ti_adc import load_capture

    iq = load_capture(path)
    n = sensor.radar.n_samples
    if iq.shape[-1] != n:
        raise FrameFormatError(f"{path}: chirps of {iq.shape[-1]} samples; sensor {sensor.name} has {n}")
    chirps = iq.reshape(-1, n)
    frames = chirps.reshape(len(chirps), 1, 1, n)
    _check_frame(sensor, frames.shape[1:], frames.dtype, str(path))
    poses = np.broadcast_to(np.eye(4), (len(frames), 4, 4))
    return FrameSource(sensor, frames, poses, [None] * len(frames),
                       f"{len(frames)} chirps of {path} (one per frame, the sensor still at the origin)")


def _polar(sensor, path, odometry):
    from radarcl.io import polar_png

    layout = polar_png.PolarLayout.of(sensor)
    paths = [path] if path.is_file() else polar_png.scan_paths(path)
    scans = [polar_png.load_scan(p, layout) for p in paths]
    n_bins = scans[0].n_bins
    if sensor.n_bins() is None:
        sensor = sensor.with_bins(n_bins)
    for s in scans:
        _check_frame(sensor, s.levels.shape, np.float32, str(s.path))
    if odometry is None:
        for candidate in (path / "radar_odometry.csv", path.parent / "gt" / "radar_odometry.csv"):
            if path.is_dir() and candidate.is_file():
                odometry = candidate
                break
    if odometry is not None:
        try:
            stamps = [int(s.path.stem) for s in scans]
        except ValueError:
            raise FrameFormatError("odometry needs scans named by their UNIX time in us (<stamp>.png)") from None
        poses = polar_png.scan_poses(stamps, polar_png.load_odometry(odometry))
        how = f"poses from {odometry}"
    else:
        poses = np.broadcast_to(np.eye(4), (len(scans), 4, 4))
        how = "no odometry: a still radar at the origin"
    per_beam = polar_png.beam_poses(scans, poses, sensor.n_azimuth)
    flags = [np.where(s.valid, 0, 8).astype(np.uint8) for s in scans]     # oracle.FLAG_SILENT: no evidence
    frames = _LazyPower(scans)
    return FrameSource(sensor, frames, per_beam, flags, f"{len(scans)} polar scans of {path} ({how})")


class _LazyPower:
    """Scans' power, converted one at a time (a scan's float32 power is 4x its levels)."""

    def __init__(self, scans):
        self.scans = scans

    def __len__(self):
        return len(self.scans)

    def __getitem__(self, i):
        return self.scans[i].power()
