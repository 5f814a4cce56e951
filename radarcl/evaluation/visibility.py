"""Truth that says what a radar can know: every observed voxel's visibility class.

The scene's labels (``scene.outdoor``: FREE / OCCUPIED / INTERIOR) say what is there. A radar
can only know what its line of sight reaches and what echoes above its noise, so the metrics
score a map against these classes (``visibility_truth``):

- ``UNOBSERVED``: outside every beam's volume (the fixed voxel set leaves it out);
- ``FREE_VISIBLE``: air the line of sight from a sensor position reaches;
- ``DETECTABLE``: a surface voxel on the line of sight whose range bin, in some beam holding
  it, carries a noiseless echo at least ``DETECTABLE_DB`` above the noise;
- ``WEAK``: a surface voxel on the line of sight, below that;
- ``SHADOWED``: behind the first surface along the ray from every sensor position (air or
  surface: a radar cannot tell);
- ``INSIDE_SOLID``: inside a solid (the scene's INTERIOR label).

Line of sight: one ray from each sensor position to the voxel's centre; the voxel is visible
when the first surface on that ray lies no nearer than the voxel's own near boundary (its
distance less half the voxel's diagonal): a surface voxel's own face does not hide it, a face
one voxel in front of it does. Rays are cast against the scene's exact solids
(``Scene.first_hit``), as the simulator casts them.

Why 10 dB: the paper's CA-CFAR (16 training cells a side, P_fa 1e-3) detects a Swerling-1
target of signal-to-noise ratio S with P_d = (1 + a / (N (1 + S)))^-N, N = 32,
a = N (P_fa^(-1/N) - 1) = 7.71; P_d = 1/2 at S = 10.0 (10.0 dB): the level at which a
fluctuating surface is found about half the time (``detectable_snr_db`` computes it).
"""

import math
from dataclasses import dataclass

import numpy as np

from radarcl.errors import ShapeError
from radarcl.gridspec import GridSpec
from radarcl.scene.outdoor import INTERIOR, OCCUPIED

UNOBSERVED, FREE_VISIBLE, DETECTABLE, WEAK, SHADOWED, INSIDE_SOLID = range(6)
CLASS_NAMES = ("unobserved", "free-visible", "detectable", "weak", "shadowed", "interior")
DETECTABLE_DB = 10.0
CHUNK = 1 << 20                  # rays cast at once (memory: about 200 bytes per ray)


def dilate(mask):
    """Boolean dilation by the 3 x 3 x 3 cube (one voxel, 26-neighbourhood), as three 1-D passes."""
    out = np.asarray(mask, bool).copy()
    for axis in range(out.ndim):
        grown = out.copy()
        lo = [slice(None)] * out.ndim
        hi = [slice(None)] * out.ndim
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        grown[tuple(lo)] |= out[tuple(hi)]
        grown[tuple(hi)] |= out[tuple(lo)]
        out = grown
    return out


def detectable_snr_db(pfa=1e-3, n_train=32, pd=0.5):
    """The Swerling-1 SNR [dB] at which CA-CFAR with ``n_train`` cells at ``pfa`` detects with
    probability ``pd`` (closed form; see the module docstring)."""
    a = n_train * (pfa ** (-1.0 / n_train) - 1.0)
    snr = a / (n_train * (pd ** (-1.0 / n_train) - 1.0)) - 1.0
    return 10.0 * math.log10(snr)


@dataclass
class VisibilityTruth:
    """Classes of one grid (``classes``, uint8 (nz, ny, nx)) with what they were made from:
    ``labels`` the scene's FREE / OCCUPIED / INTERIOR, ``obstacle`` the surface voxels of every
    solid but the ground, ``observed`` the fixed voxel set's mask."""

    classes: np.ndarray
    labels: np.ndarray
    obstacle: np.ndarray
    observed: np.ndarray
    detectable_db: float = DETECTABLE_DB

    def counts(self):
        """{class name: voxels} over the grid."""
        found = np.bincount(self.classes.reshape(-1), minlength=len(CLASS_NAMES))
        return {name: int(n) for name, n in zip(CLASS_NAMES, found)}


def line_of_sight(scene, spec, voxels, origins):
    """Boolean per voxel index (n, 3) (x, y, z): some sensor position in ``origins`` (m, 3)
    sees the voxel (see the module docstring)."""
    voxels = np.asarray(voxels)
    seen = np.zeros(len(voxels), bool)
    slack = 0.5 * math.sqrt(3.0) * spec.voxel_m
    for start in range(0, len(voxels), CHUNK):
        centres = spec.index_to_world(voxels[start:start + CHUNK])
        for origin in np.asarray(origins, float).reshape(-1, 3):
            todo = ~seen[start:start + len(centres)]
            if not todo.any():
                break
            d = centres[todo] - origin
            dist = np.linalg.norm(d, axis=1)
            dist = np.maximum(dist, 1e-9)
            t, _, _ = scene.first_hit(np.broadcast_to(origin, d.shape), d / dist[:, None])
            idx = np.flatnonzero(todo) + start
            seen[idx] = t >= dist - slack
    return seen


def noise_power_per_bin(noise_rms, n_samples, window="hann"):
    """Mean power of real white noise of ``noise_rms`` [V] in one bin of ``oracle.range_profile``
    (``output="power"``), calibrated as that function calibrates: E|sum w x e^-i..|^2 / (sum w)^2
    = noise_rms^2 sum w^2 / (sum w)^2 (any zero padding)."""
    n = np.arange(n_samples)
    w = 0.5 - 0.5 * np.cos(2 * np.pi * n / n_samples) if window == "hann" else np.ones(n_samples)
    return float(noise_rms ** 2 * (w ** 2).sum() / w.sum() ** 2)


def beam_bins(spec, voxels, poses, lattice, half_az_rad, half_el_rad, bin_spacing_m, n_bins):
    """For each pose: (beam index, range bin) of every voxel, -1 where no beam holds it (the
    nearest beam of the lattice, when the voxel lies within its half-power half-widths)."""
    centres = spec.index_to_world(np.asarray(voxels))
    az, el = lattice.azimuths, lattice.elevations
    out = []
    for pose in np.asarray(poses, float):
        beams = pose if pose.ndim == 3 else None     # one pose per beam (a spinning radar on a vehicle)
        pose = pose if beams is None else pose[len(pose) // 2]
        local = (centres - pose[:3, 3]) @ pose[:3, :3] @ lattice.head_rotation()
        a = np.arctan2(local[:, 1], local[:, 0])
        e = np.arctan2(local[:, 2], np.hypot(local[:, 0], local[:, 1]))
        if lattice.wraps:                           # a full turn: the nearest azimuth, across the seam too
            i = np.rint((a - az[0]) / lattice.az_step_rad).astype(np.int64) % len(az)
            off = np.angle(np.exp(1j * (a - az[i])))
        else:
            i = np.clip(np.rint((a - az[0]) / (lattice.az_step_rad or 1.0)).astype(np.int64), 0, len(az) - 1)
            off = a - az[i]
        k = np.clip(np.rint((e - el[0]) / (lattice.el_step_rad or 1.0)).astype(np.int64), 0, len(el) - 1)
        inside = (np.abs(off) <= half_az_rad) & (np.abs(e - el[k]) <= half_el_rad)
        if beams is None:
            r = np.linalg.norm(local, axis=1)
        else:                                       # the range from the beam's own origin
            r = np.linalg.norm(centres - beams[i * lattice.n_el + k, :3, 3], axis=1)
        b = np.rint(r / bin_spacing_m).astype(np.int64)
        inside &= b < n_bins
        out.append((np.where(inside, i * lattice.n_el + k, -1), np.where(inside, b, -1)))
    return out


def visibility_truth(scene, spec, observed, poses, noiseless_power=None, noise_power=None, lattice=None,
                     half_widths_rad=None, bin_spacing_m=None, detectable_db=DETECTABLE_DB):
    """``VisibilityTruth`` of ``spec`` for a sensor at ``poses`` (n, 4, 4).

    ``observed`` (nz, ny, nx) bool: the fixed voxel set (what the reference configuration's
    beams reach). With ``noiseless_power`` (n_frames, n_beams, n_bins) (the frames' range
    profiles without receiver noise, ``oracle.range_profile(..., output="power")``) and
    ``noise_power`` (its noise level per bin), visible surface voxels split into DETECTABLE and
    WEAK; without it every visible surface voxel is DETECTABLE."""
    labels = scene.truth(spec)
    observed = np.asarray(observed, bool)
    if observed.shape != labels.shape:
        raise ShapeError(f"observed {observed.shape} must be the grid's {labels.shape}")
    obstacles = type(scene)(tuple(o for o in scene.objects if o.shape.bounds() is not None and not is_terrain(o.name)),
                            (), scene.sensor_m)
    obstacle = obstacles.truth(spec) == OCCUPIED
    classes = np.full(labels.shape, UNOBSERVED, np.uint8)
    classes[observed & (labels == INTERIOR)] = INSIDE_SOLID
    cast = observed & (labels != INTERIOR)
    idx = np.argwhere(cast)[:, ::-1]                                   # (x, y, z)
    P = np.asarray(poses, float)
    # one pose per beam: each turn's middle beam's origin (the others lie within one turn's drive)
    heads = P[:, P.shape[1] // 2] if P.ndim == 4 else P
    origins = np.unique(heads[:, :3, 3].round(9), axis=0)
    seen = line_of_sight(scene, spec, idx, origins)
    occ = labels[idx[:, 2], idx[:, 1], idx[:, 0]] == OCCUPIED
    cls = np.where(~seen, SHADOWED, np.where(occ, DETECTABLE, FREE_VISIBLE)).astype(np.uint8)
    if noiseless_power is not None:
        surface = np.flatnonzero(seen & occ)
        loud = np.zeros(len(surface), bool)
        level = noise_power * 10 ** (detectable_db / 10)
        n_bins = noiseless_power.shape[-1]
        for j, (beam, b) in enumerate(beam_bins(spec, idx[surface], poses, lattice, *half_widths_rad, bin_spacing_m,
                                                 n_bins)):
            ok = beam >= 0
            loud[ok] |= noiseless_power[j][beam[ok], b[ok]] >= level
        cls[surface[~loud]] = WEAK
    classes[idx[:, 2], idx[:, 1], idx[:, 0]] = cls
    return VisibilityTruth(classes, labels, obstacle, observed, detectable_db)


def is_terrain(name):
    """The ground and the generator's mounds: terrain, predictable without a radar, not obstacles."""
    return name.split(" ")[0] in ("ground", "grass", "mound")


def object_group(name):
    """The object a solid belongs to: a tree's trunk and crown are one tree."""
    for part in (" trunk", " crown"):
        if name.endswith(part):
            return name[:-len(part)]
    return name


def object_surfaces(scene, truth, spec, sensor_m=None):
    """Per object of ``scene`` (every solid but the ground, a tree's trunk and crown together)
    with a visible surface voxel (DETECTABLE or WEAK) in ``truth``: {"name", "range_m" (sensor
    to its nearest visible surface voxel), "near" (n, 3) voxel indices (x, y, z) within one
    voxel of its visible surface (26-neighbourhood), "detectable" (a surface voxel is DETECTABLE:
    an echo a perfect detector would see; an object seen only WEAK is below every CFAR)}; and
    the names of objects with none."""
    sensor = np.asarray(scene.sensor_m if sensor_m is None else sensor_m, float)
    groups = {}
    for obj in scene.objects:
        if obj.shape.bounds() is not None and not is_terrain(obj.name):
            groups.setdefault(object_group(obj.name), []).append(obj)
    origin, v, shape = np.asarray(spec.origin_m), spec.voxel_m, np.asarray(spec.shape)
    found, hidden = [], []
    for name, objs in groups.items():
        lo = np.min([o.shape.bounds()[0] for o in objs], axis=0)
        hi = np.max([o.shape.bounds()[1] for o in objs], axis=0)
        i0 = np.clip(np.floor((lo - origin) / v).astype(int) - 2, 0, shape)
        i1 = np.clip(np.floor((hi - origin) / v).astype(int) + 3, 0, shape)
        if (i1 <= i0).any():
            hidden.append(name)
            continue
        sub = GridSpec(tuple(origin + i0 * v), v, tuple(int(n) for n in i1 - i0))
        mine = type(scene)(tuple(objs), (), scene.sensor_m).truth(sub) == OCCUPIED
        cls = truth.classes[i0[2]:i1[2], i0[1]:i1[1], i0[0]:i1[0]]
        seen = mine & ((cls == DETECTABLE) | (cls == WEAK))
        if not seen.any():
            hidden.append(name)
            continue
        near = np.argwhere(dilate(seen))[:, ::-1] + i0
        surface = np.argwhere(seen)[:, ::-1] + i0
        rng = float(np.linalg.norm(spec.index_to_world(surface) - sensor, axis=1).min())
        found.append(dict(name=name, range_m=rng, near=near, detectable=bool((mine & (cls == DETECTABLE)).any())))
    return found, hidden
