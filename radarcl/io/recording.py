"""Recordings of raw radar frames with their poses: one ``.npz`` file the CLI can replay.

Contents: ``samples`` (n_frames, n_az, n_el, n_samples) int16 ADC codes, ``poses``
(n_frames, 4, 4) float64, ``tilts_deg`` (n_frames,), the simulation ``seed`` and
``rays_per_beam`` (-1 for a real recording), ``n_clipped`` and ``version``. A file that does not
follow this is refused with what was wrong; nothing is written over an existing file unless
asked.
"""

from pathlib import Path

import numpy as np

from radarcl.errors import FrameFormatError
from radarcl.geometry import check_poses
from radarcl.scene.observe import Observations

VERSION = 1
_KEYS = ("samples", "poses", "tilts_deg", "seed", "rays_per_beam", "n_clipped", "version")


def save(path, obs: Observations, overwrite=True):
    """Write ``obs`` to ``path`` (.npz, compressed)."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FrameFormatError(f"{path} exists; pass overwrite=True to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:        # a file object: numpy would append .npz to other names
        np.savez_compressed(f, samples=obs.samples, poses=obs.poses, tilts_deg=obs.tilts_deg, seed=obs.seed,
                            rays_per_beam=obs.rays_per_beam, n_clipped=obs.n_clipped, version=VERSION)


def load(path, n_az=None, n_el=None, n_samples=None):
    """Read a recording; checks its keys, version, dtypes and shapes (and the frame shape
    against n_az, n_el, n_samples when given). Returns ``Observations``."""
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in _KEYS if k not in z.files]
            if missing:
                raise FrameFormatError(f"{path} is not a radarcl recording: missing {', '.join(missing)}")
            data = {k: z[k] for k in _KEYS}
    except (OSError, ValueError) as exc:
        raise FrameFormatError(f"{path} is not a readable .npz recording ({exc})") from exc
    if int(data["version"]) != VERSION:
        raise FrameFormatError(f"{path} has recording version {int(data['version'])}; this radarcl reads {VERSION}")
    s = data["samples"]
    if s.dtype != np.int16 or s.ndim != 4:
        raise FrameFormatError(f"{path}: samples must be (n_frames, n_az, n_el, n_samples) int16, got {s.shape} {s.dtype}")
    expected = (n_az, n_el, n_samples)
    if any(e is not None and e != g for e, g in zip(expected, s.shape[1:])):
        raise FrameFormatError(f"{path}: frames are {s.shape[1:]}, the radar expects {expected}")
    poses, tilts = data["poses"], data["tilts_deg"]
    if poses.shape != (len(s), 4, 4) or tilts.shape != (len(s),):
        raise FrameFormatError(f"{path}: {len(s)} frames need poses ({len(s)}, 4, 4) and tilts ({len(s)},), "
                               f"got {poses.shape} and {tilts.shape}")
    try:
        check_poses(poses, len(poses))
    except ValueError as exc:
        raise FrameFormatError(f"{path}: {exc}") from exc
    return Observations(s, poses.astype(np.float64), tilts.astype(np.float64), int(data["seed"]),
                        int(data["rays_per_beam"]), int(data["n_clipped"]))
