"""Recordings: frames of any sensor with their poses, in one ``.npz`` file the CLI replays.

Version 2 (written here): ``frames`` (n_frames, *frame) in the sensor's frame shape and dtype
(raw samples (n_az, n_el, n_samples), or power profiles (*batch, n_bins) float32), ``poses``
(n_frames, 4, 4) or (n_frames, n_beams, 4, 4), optional ``flags`` (n_frames, *batch) uint8,
``sensor`` (the profile's name) and ``version``. Simulations add ``tilts_deg``, ``seed``,
``rays_per_beam`` (-1 for a real recording) and ``n_clipped``. Version 1 (the paper radar's int16
``samples`` with the same metadata) is still read.

A file that does not follow this is refused with what was wrong; nothing is written over an
existing file unless asked.
"""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from radarcl.errors import FrameFormatError
from radarcl.geometry import check_poses
from radarcl.io.files import atomic, safe_npz

VERSION = 2
SIMULATION_META = ("tilts_deg", "seed", "rays_per_beam", "n_clipped")       # a simulation's metadata
_OPTIONAL_META = ("physics",)          # simulator switches (scene.observe.SIDELOBES | MULTIPATH); 0 when absent


@dataclass(frozen=True)
class Recording:
    """Frames of one sensor: ``frames`` (n, *frame), ``poses`` (n, 4, 4) or (n, n_beams, 4, 4),
    ``flags`` (n, *batch) uint8 or None, the sensor's name, and simulation metadata."""

    frames: np.ndarray
    poses: np.ndarray
    sensor: str = "paper"
    flags: np.ndarray = None
    meta: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.frames)


def save(path, recording, overwrite=True):
    """Write a ``Recording`` or a simulation's ``Observations`` to ``path`` (.npz, compressed)."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FrameFormatError(f"{path} exists; pass overwrite=True to replace it")
    if not isinstance(recording, Recording):            # scene.observe.Observations
        obs = recording
        recording = Recording(obs.samples, obs.poses, "paper", None,
                              dict(tilts_deg=obs.tilts_deg, seed=obs.seed, rays_per_beam=obs.rays_per_beam,
                                   n_clipped=obs.n_clipped, physics=obs.physics))
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = dict(version=VERSION, sensor=np.str_(recording.sensor), frames=recording.frames, poses=recording.poses,
                  **{k: np.asarray(v) for k, v in recording.meta.items()})
    if recording.flags is not None:
        arrays["flags"] = recording.flags
    with atomic(path) as tmp, open(tmp, "wb") as f:   # a file object: numpy would append .npz
        np.savez_compressed(f, **arrays)


def load(path):
    """Read a recording (version 1 or 2); checks keys, version, dtypes, shapes and poses.
    Returns a ``Recording``."""
    try:
        with safe_npz(path) as z:
            if "version" not in z.files:
                raise FrameFormatError(f"{path} is not a radarcl recording: it has no version")
            version = _scalar(path, "version", z["version"], "i")
            if version not in (1, VERSION):
                raise FrameFormatError(f"{path} has recording version {version}; this radarcl reads 1 and {VERSION}")
            frames_key = "samples" if version == 1 else "frames"
            missing = [k for k in (frames_key, "poses") + (SIMULATION_META if version == 1 else ("sensor",)) if k not in z.files]
            if missing:
                raise FrameFormatError(f"{path} is not a radarcl recording: missing {', '.join(missing)}")
            frames, poses = z[frames_key], z["poses"]
            flags = z["flags"] if "flags" in z.files else None
            sensor = "paper" if version == 1 else _scalar(path, "sensor", z["sensor"], "U")
            if not sensor:
                raise FrameFormatError(f"{path}: its sensor name is empty")
            meta = {k: z[k] for k in SIMULATION_META + _OPTIONAL_META if k in z.files}
    except (OSError, ValueError, EOFError) as exc:
        if isinstance(exc, FrameFormatError):
            raise
        raise FrameFormatError(f"{path} is not a readable .npz recording ({exc})") from exc
    n = len(frames) if frames.ndim else 0
    if frames.ndim < 3 or n < 1:
        raise FrameFormatError(f"{path}: frames must be (n_frames >= 1, ...) with a frame of at least 2 axes, "
                               f"got {frames.shape} {frames.dtype}")
    if frames.dtype not in (np.int16, np.float32, np.complex64):
        raise FrameFormatError(f"{path}: frames must be int16, float32 or complex64, got {frames.dtype}")
    if poses.shape not in ((n, 4, 4),) and not (poses.ndim == 4 and poses.shape[0] == n and poses.shape[2:] == (4, 4)):
        raise FrameFormatError(f"{path}: {n} frames need poses ({n}, 4, 4) or ({n}, n_beams, 4, 4), got {poses.shape}")
    try:
        check_poses(poses.reshape(-1, 4, 4), len(poses.reshape(-1, 4, 4)))
    except ValueError as exc:
        raise FrameFormatError(f"{path}: {exc}") from exc
    if flags is not None and (flags.dtype != np.uint8 or len(flags) != n):
        raise FrameFormatError(f"{path}: flags must be (n_frames, *batch) uint8, got {flags.shape} {flags.dtype}")
    meta = {k: _tilts(path, v, n) if k == "tilts_deg" else _scalar(path, k, v, "i") for k, v in meta.items()}
    return Recording(frames, poses.astype(np.float64), sensor, flags, meta)


def _scalar(path, name, value, kind):
    """A recording's metadata entry as one integer (kind "i") or string ("U"); FrameFormatError
    names the entry and what it holds instead (a vector, a string, a float where an integer belongs)."""
    value = np.asarray(value)
    ok = value.ndim == 0 and (value.dtype.kind in "iu" if kind == "i" else value.dtype.kind == "U")
    if not ok:
        want = "an integer" if kind == "i" else "a string"
        raise FrameFormatError(f"{path}: its {name} must be {want}, got {value.dtype} of shape {value.shape}")
    return int(value) if kind == "i" else str(value)


def _tilts(path, value, n):
    """A simulation's tilt per frame (n,) finite degrees."""
    value = np.asarray(value)
    if value.dtype.kind not in "iuf" or value.shape != (n,) or not np.isfinite(value).all():
        raise FrameFormatError(f"{path}: tilts_deg must be {n} finite angles [deg], got {value.dtype} {value.shape}")
    return value.astype(np.float64)
