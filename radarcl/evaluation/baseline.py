"""The three baselines every map is scored beside, on the same fixed voxel set.

- ``prior_only``: no radar data at all. The log-odds fall with the distance from the flat
  ground plane: +1 nat in the voxel layers that touch it, -1 nat one voxel further, -2 nat
  beyond (``GROUND_PRIOR_NATS`` per voxel). It knows the ground, which is predictable without a
  radar, and nothing else: a metric it wins does not measure the radar.
- ``raw_intensity``: the dense signal without a sensor model. Each range bin's power becomes
  evidence, one nat per ``RAW_DB_PER_NAT`` dB above ``RAW_LEVEL_DB`` over the beam's noise
  (estimated as its median power / ln 2, the mean of exponential noise), clipped to
  +-``RAW_LIMIT_NATS``, fused with the same beams and beam model as the map (no CFAR, no eq. 12).
- ``octomap``: what most radar mapping does today. The CFAR detections of each frame become
  points on their beams' axes and go into OctoMap itself (octomap-python's ``OcTree``, the C++
  library) with ``insertPointCloud`` from the sensor's origin, at the map's resolution, with
  its default sensor model (hit 0.7, miss 0.4, clamping 0.12 / 0.97); read back per voxel.
  The numpy imitation of OctoMap it replaces is gone: the real one installs from PyPI as a
  manylinux wheel (the ``export`` extra).
"""

import math

import numpy as np

from radarcl import logodds
from radarcl.errors import ConfigError
from radarcl.pipeline import Mapping, evidence_config

GROUND_PRIOR_NATS = 2.0
RAW_LEVEL_DB, RAW_DB_PER_NAT, RAW_LIMIT_NATS = 10.0, 10.0, 1.0


def prior_only(spec, ground_z_m=0.0):
    """(nz, ny, nx) float32 log-odds [nat] from the distance to the plane z = ``ground_z_m``."""
    nz = spec.shape[2]
    centres = spec.origin_m[2] + (np.arange(nz) + 0.5) * spec.voxel_m
    layer = np.clip(GROUND_PRIOR_NATS * (1.0 - np.abs(centres - ground_z_m) / spec.voxel_m), -GROUND_PRIOR_NATS,
                    GROUND_PRIOR_NATS)
    return np.broadcast_to(layer.astype(np.float32)[:, None, None], spec.array_shape)


def raw_evidence(power):
    """(n_beams, n_bins) power profiles -> int32 evidence in log-odds units (see the module)."""
    power = np.asarray(power, np.float64)
    noise = np.median(power, axis=-1, keepdims=True) / math.log(2.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        snr_db = 10.0 * np.log10(power / noise)
    nats = np.clip((np.nan_to_num(snr_db, nan=-np.inf) - RAW_LEVEL_DB) / RAW_DB_PER_NAT, -RAW_LIMIT_NATS,
                   RAW_LIMIT_NATS)
    return np.rint(nats * logodds.SCALE).astype(np.int32)


def raw_intensity(runtime, obs, config):
    """The raw-intensity map of ``obs`` with ``config``'s beams and beam model: (nz, ny, nx)
    float32 log-odds [nat]."""
    mapping = Mapping.from_config(runtime, config=evidence_config(config))
    fusion = mapping.fusion
    for frame, pose in zip(obs.samples, obs.poses):
        profiles = mapping.range_fft(frame).profiles.reshape(fusion.evidence_shape)
        fusion.upload(raw_evidence(profiles)).wait()
        fusion.enqueue(plan=fusion.plan(pose))
    runtime.queue.finish()
    return (mapping.grid.snapshot() / np.float32(logodds.SCALE)).astype(np.float32)


def detection_points(pose, axes, ranges, mask, min_range, max_range):
    """World points (n, 3) of one frame's CFAR detections: each detected bin in [min_range,
    max_range] on its beam's axis (``axes`` (n_beams, 3) in the head frame) at its range."""
    mask = np.asarray(mask, bool) & ((ranges >= min_range) & (ranges <= max_range))[None]
    beam, b = np.nonzero(mask)
    pose = np.asarray(pose)
    if pose.ndim == 3:                               # one pose per beam (a spinning radar on a vehicle)
        return pose[beam, :3, 3] + ranges[b, None] * np.einsum("nij,nj->ni", pose[beam, :3, :3], axes[beam])
    return pose[:3, 3] + ranges[b, None] * (axes[beam] @ pose[:3, :3].T)


def octree(spec, scans):
    """An ``octomap.OcTree`` at ``spec``'s resolution holding ``scans`` [(origin (3,), points
    (n, 3))], each inserted with ``insertPointCloud``, in grid coordinates (world - origin_m):
    OctoMap's cells are [k v, (k + 1) v), ours start at ``spec.origin_m``, which need not be a
    multiple of v (the paper grid's -35 m at 0.4 m)."""
    try:
        import octomap as om
    except ImportError as exc:
        raise ConfigError("the octomap baseline needs octomap-python: pip install 'radarcl[export]'") from exc
    shift = np.asarray(spec.origin_m, np.float64)
    tree = om.OcTree(spec.voxel_m)
    for origin, points in scans:
        if len(points):
            tree.insertPointCloud(np.ascontiguousarray(np.asarray(points, np.float64) - shift),
                                  np.asarray(origin, np.float64) - shift)
    return tree


def read_back(tree, spec):
    """(nz, ny, nx) float32 log-odds [nat] of an ``octree`` on ``spec``: each leaf's value over
    the voxels it covers (a pruned leaf covers several), 0 where OctoMap knows nothing."""
    out = np.zeros(spec.array_shape, np.float32)
    v, shape = spec.voxel_m, np.asarray(spec.shape)
    for leaf in tree.begin_leafs():
        centre, half = np.asarray(leaf.getCoordinate(), float), 0.5 * leaf.getSize()
        lo = np.clip(np.rint((centre - half) / v).astype(int), 0, shape)
        hi = np.clip(np.rint((centre + half) / v).astype(int), 0, shape)
        if (hi > lo).all():
            out[lo[2]:hi[2], lo[1]:hi[1], lo[0]:hi[0]] = leaf.getValue()
    return out


def octomap(spec, scans):
    """OctoMap's map of ``scans`` read back on ``spec`` (``octree``, ``read_back``)."""
    return read_back(octree(spec, scans), spec)


def detection_scans(obs, detections, config):
    """[(origin, points)] per frame of ``obs``: its CFAR detections (one mask (n_beams, n_bins)
    per frame) as ``detection_points`` within the interpreter's range window."""
    axes = config.sensor.lattice().beam_rotations()[:, :, 0]
    ranges = config.sensor.radar.bin_ranges_m(config.n_fft)
    i = config.interpret_config()
    return [((pose if pose.ndim == 2 else pose[len(pose) // 2])[:3, 3],
             detection_points(pose, axes, ranges, mask, i.range_min_m, i.range_max_m))
            for pose, mask in zip(np.asarray(obs.poses), detections)]
