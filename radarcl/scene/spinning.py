"""Spinning sensors in a scene of exact solids: a multi-beam lidar's points and a spinning radar's
polar scans, cast against ``outdoor.Scene.first_hit``, so that an evaluation against lidar can
be checked where the truth is known exactly (``evaluation.lidar``, ``tests/test_evaluate_lidar.py``).

Lidar (``lidar_points``): rings at the given elevations, ``n_azimuth`` rays per ring, each
returning the first surface it meets within ``max_range_m`` (fog: nothing beyond; no noise), as
points in the lidar's REP-103 frame.

Radar (``polar_scan``): a Navtech-like scan of ``n_azimuth`` azimuths (counter-clockwise, REP-103)
and ``n_bins`` bins of ``bin_spacing_m``, as 8-bit levels of 1 dB of power: receiver noise
(exponential power, ``noise_db`` mean) everywhere, and an echo ``echo_db`` above it at the first
surface of a few rays across the beam (``rays`` in azimuth x elevation), spread over the bins of
a point target's pulse (two bins each side, -6 and -20 dB). No speckle on the echo, no
multipath: enough to tell a sensor model from counting samples, not a radar simulator.
"""

import math

import numpy as np

from radarcl.errors import ConfigError
from radarcl.scene.outdoor import METAL, ROCK, Scene, SceneObject
from radarcl.scene.shapes import Box, Ground

PULSE_DB = {0: 0.0, 1: -6.0, 2: -20.0}      # a Hann-windowed point target's pulse, bins off its peak


def _directions(azimuths, elevations):
    az, el = np.meshgrid(azimuths, elevations, indexing="ij")
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1).reshape(-1, 3)


def lidar_points(scene, pose, elevations_deg, n_azimuth, max_range_m, min_range_m=0.5):
    """(n, 3) points in the lidar's REP-103 frame of one turn from ``pose`` (4x4 in the scene)."""
    if not (max_range_m > min_range_m > 0) or n_azimuth < 1:
        raise ConfigError(f"a lidar needs 0 < min_range_m < max_range_m and azimuths, got {min_range_m}, "
                          f"{max_range_m}, {n_azimuth}")
    pose = np.asarray(pose, np.float64)
    local = _directions(np.arange(n_azimuth) * (2 * math.pi / n_azimuth), np.radians(elevations_deg))
    dirs = local @ pose[:3, :3].T
    t, _, _ = scene.first_hit(np.broadcast_to(pose[:3, 3], dirs.shape).copy(), dirs)
    keep = (t >= min_range_m) & (t <= max_range_m)
    return local[keep] * t[keep, None]


def polar_scan(scene, poses, n_bins, bin_spacing_m, rng, noise_db=20.0, echo_db=40.0, beam_deg=(1.8, 4.0),
               rays=(3, 3)):
    """(n_az, n_bins) uint8 levels of one turn, azimuth i of the scan looking along
    ``poses[i]``'s x axis (``poses`` (n_az, 4, 4): the radar's pose per azimuth, the turn folded
    in); ``rng`` a numpy Generator for the noise."""
    poses = np.asarray(poses, np.float64)
    n_az = len(poses)
    half_az, half_el = (math.radians(b) / 2 for b in beam_deg)
    local = _directions(np.linspace(-half_az, half_az, rays[0]), np.linspace(-half_el, half_el, rays[1]))
    per = len(local)
    dirs = np.einsum("aij,rj->ari", poses[:, :3, :3], local).reshape(-1, 3)
    origins = np.repeat(poses[:, :3, 3], per, axis=0)
    t, _, _ = scene.first_hit(origins, dirs)
    power = rng.exponential(10 ** (noise_db / 10), (n_az, n_bins))
    echo = 10 ** ((noise_db + echo_db) / 10) / per
    first = np.rint(t.reshape(n_az, per) / bin_spacing_m)
    for k in range(per):
        b = first[:, k]
        for off, db in PULSE_DB.items():
            for sign in ((0,) if off == 0 else (-1, 1)):
                j = b + sign * off
                ok = np.isfinite(j) & (j >= 0) & (j < n_bins)
                power[np.flatnonzero(ok), j[ok].astype(int)] += echo * 10 ** (db / 10)
    return np.clip(np.rint(10 * np.log10(power)), 0, 255).astype(np.uint8)


def street(height_m=1.8):
    """A street to drive along +x with the sensor ``height_m`` above the road (z = 0 the road):
    a long wall on the left (y 6-6.5 m, 3.5 m high), a building on the right (y -12 to -9 m,
    x 4-16 m), a parked car (y -4.1 to -2.3 m, x 20-24.5 m, 1.6 m high), two posts. Faces lie off
    the 0.1 m lattices, so no truth depends on how a face on a cell boundary rounds."""
    objects = [SceneObject("road", Ground(0.0), ROCK),
               SceneObject("wall", Box((-30.03, 6.03, 0.0), (40.03, 6.53, 3.5)), ROCK),
               SceneObject("building", Box((4.03, -12.03, 0.0), (16.03, -9.03, 8.0)), ROCK),
               SceneObject("car", Box((20.03, -4.13, 0.0), (24.53, -2.33, 1.6)), METAL),
               SceneObject("post 1", Box((-5.03, -5.03, 0.0), (-4.73, -4.73, 3.2)), METAL),
               SceneObject("post 2", Box((30.03, -6.03, 0.0), (30.33, -5.73, 3.2)), METAL)]
    return Scene(tuple(objects), (), (0.0, 0.0, height_m))
