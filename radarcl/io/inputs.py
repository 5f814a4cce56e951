"""What a sensor's reader opens, as frames with their poses: ``open_input(sensor, path)``.

It opens whatever the sensor profile's reader reads (its [reader] ``format``): a radarcl
recording (``recording``), a directory of polar PNG scans with their odometry (``polar-png``),
a TI raw ADC capture (``ti-openradar``). It returns a ``FrameSource``: the sensor (with its bin
count filled from the data where the profile leaves it out), the frames, one pose (or one per
beam) and optional flags per frame, and a line saying what was read. Every size is checked
against the sensor before a frame reaches a device. No pyopencl imports here.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from radarcl.errors import FrameFormatError
from radarcl.io import polar_png, recording
from radarcl.io.ti_adc import load_capture
from radarcl.oracle import FLAG_SILENT


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
    sequence = polar_png.read_sequence(path, polar_png.PolarLayout.of(sensor), odometry)
    scans = sequence.scans
    if sensor.n_bins() is None:
        sensor = sensor.with_bins(scans[0].n_bins)
    for s in scans:
        _check_frame(sensor, s.levels.shape, np.float32, str(s.path))
    how = (f"poses from {sequence.odometry_path}" if sequence.odometry is not None
           else "no odometry: a still radar at the origin")
    per_beam = polar_png.beam_poses(scans, sequence.poses(), sensor.n_azimuth)
    return polar_source(sensor, scans, per_beam, f"{len(scans)} polar scans of {path} ({how})")


def polar_source(sensor, scans, per_beam, summary):
    """A ``FrameSource`` of polar scans (``polar_png.PolarScan``) at per-azimuth poses
    (n, n_az, 4, 4): their power converted one scan at a time, azimuths not measured flagged
    silent (no evidence)."""
    flags = [np.where(s.valid, 0, FLAG_SILENT).astype(np.uint8) for s in scans]
    return FrameSource(sensor, _LazyPower(scans), per_beam, flags, summary)


class _LazyPower:
    """Scans' power, converted one at a time (a scan's float32 power is 4x its levels)."""

    def __init__(self, scans):
        self.scans = scans

    def __len__(self):
        return len(self.scans)

    def __getitem__(self, i):
        return self.scans[i].power()
