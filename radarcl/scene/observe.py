"""Radar observations of a ``Scene``: raw beat-signal samples of every beam, seeded.

Each beam is sampled by rays spread over its pattern: a stratified, jittered set of offsets
(s, t) in units of the half-power half-widths (azimuth, elevation) with s^2 + t^2 <= ``SPAN``^2,
so the one-way pattern 2^-(s^2 + t^2) (the square root of ``geometry.two_way_weight``) falls to
0.21 at the edge of what is sampled. Per ray:

- the first surface it meets (occlusion: nothing behind it is seen);
- a patch of that surface of area r^2 dOmega / cos(theta_i) with sigma0 = gamma cos(theta_i)
  (the constant-gamma model, ``outdoor.Material``), so the patch's RCS is gamma r^2 dOmega;
- the radar equation in amplitude: a = A_1M2_AT_10M sqrt(sigma / 1 m^2) (10 m / r)^2 times the
  two-way pattern in amplitude, 2^-(s^2 + t^2);
- a uniformly random phase (a rough surface: speckle).

A grazing ground return spreads over the ranges its rays reach, and its power per range cell
falls with range: both come from the geometry, nothing is imposed. Point scatterers (RCS) add
one echo to each beam whose sampled pattern holds them, unless a surface occludes them.
The echoes become samples through the eq. 5 simulator (``fmcw.simulate_beams``) with receiver
noise and the ADC's rounding and clipping, so the whole pipeline runs from raw samples.
"""

import math
from dataclasses import dataclass

import numpy as np

from radarcl.config import PAPER_RADAR
from radarcl.errors import ConfigError
from radarcl.geometry import BeamLattice
from radarcl.scene.fmcw import Adc, simulate_beams

SPAN = 1.5                   # sampled pattern radius, in half-power half-widths
RAYS_ACROSS = 12             # stratified grid of RAYS_ACROSS^2 cells over the span's square
A_1M2_AT_10M = 0.05          # tone amplitude [V] of a 1 m^2 target at 10 m on the beam axis
R_REF_M = 10.0
NOISE_RMS = 1e-3             # receiver noise per sample [V]
ADC = Adc(bits=12)           # full scale 1 V


@dataclass(frozen=True)
class Observations:
    """Raw frames of a scene: ``samples`` (n_frames, n_az, n_el, n_samples) int16 ADC codes,
    ``poses`` (n_frames, 4, 4) of the head, ``tilts_deg`` and how they were made."""

    samples: np.ndarray
    poses: np.ndarray
    tilts_deg: np.ndarray
    seed: int
    rays_per_beam: int
    n_clipped: int


def ray_offsets(rays_across=RAYS_ACROSS, span=SPAN):
    """(k, 2) offsets (s, t) in half-power half-widths: the centres of the stratified cells
    that lie in the disc of radius ``span``; and a cell's area in those units."""
    cell = 2 * span / rays_across                       # edge of a cell
    centres = (np.arange(rays_across) + 0.5) * cell - span
    s, t = np.meshgrid(centres, centres, indexing="ij")
    keep = s ** 2 + t ** 2 <= span ** 2
    return np.column_stack([s[keep], t[keep]]), cell * cell


def _beam_frames(pose, lattice):
    """(n_beams, 3, 3) world rotations of the beams: columns u (axis), v, w."""
    return pose[:3, :3] @ lattice.beam_rotations()


def observe_frame(scene, pose, radar=PAPER_RADAR, rays_across=RAYS_ACROSS, rng=None):
    """Echoes of every beam of one frame: (amplitude, range_m, phase) arrays (n_beams, k)."""
    rng = np.random.default_rng(rng)
    lattice = BeamLattice.from_radar(radar)
    frames = _beam_frames(pose, lattice)
    n_beams = len(frames)
    half_az, half_el = math.radians(radar.beamwidth_az_deg) / 2, math.radians(radar.beamwidth_el_deg) / 2
    origin = np.asarray(scene.sensor_m, float)

    st, cell = ray_offsets(rays_across)
    k = len(st)
    st = st[None] + rng.uniform(-0.5, 0.5, (n_beams, k, 2)) * math.sqrt(cell)    # jitter in its cell
    d_omega = cell * half_az * half_el                                  # solid angle per ray [sr]
    dirs = (frames[:, None, :, 0] + np.tan(st[..., :1] * half_az) * frames[:, None, :, 1]
            + np.tan(st[..., 1:] * half_el) * frames[:, None, :, 2])
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    flat = dirs.reshape(-1, 3)
    t, owner, normal = scene.first_hit(np.broadcast_to(origin, flat.shape), flat)
    hit = np.isfinite(t) & (t <= radar.range_max_m * 1.05)
    gamma = np.array([10 ** (o.material.gamma_db / 10) for o in scene.objects])
    cos_i = np.abs(np.einsum("ij,ij->i", normal, flat))
    r = np.where(hit, t, R_REF_M)
    area = r ** 2 * d_omega / np.maximum(cos_i, 1e-6)                   # patch of surface [m^2]
    sigma = np.where(hit, gamma[owner] * cos_i * area, 0.0)            # sigma0(theta_i) x area
    pattern = 2.0 ** -(st[..., 0] ** 2 + st[..., 1] ** 2).reshape(-1)  # two-way, in amplitude
    amp = A_1M2_AT_10M * np.sqrt(sigma) * (R_REF_M / r) ** 2 * pattern
    amp, rng_m = amp.reshape(n_beams, k), r.reshape(n_beams, k)
    phase = rng.uniform(0, 2 * np.pi, (n_beams, k))

    if scene.points:
        p_amp, p_r = _point_echoes(scene, frames, origin, half_az, half_el)
        amp = np.concatenate([amp, p_amp], axis=1)
        rng_m = np.concatenate([rng_m, p_r], axis=1)
        phase = np.concatenate([phase, rng.uniform(0, 2 * np.pi, p_amp.shape)], axis=1)
    return amp, rng_m, phase


def _point_echoes(scene, frames, origin, half_az, half_el):
    """(amplitude, range) (n_beams, n_points) of the scene's point scatterers (0 where unseen)."""
    pos = np.array([p.position_m for p in scene.points], float) - origin
    dist = np.linalg.norm(pos, axis=1)
    to = pos / dist[:, None]
    t, owner, _ = scene.first_hit(np.broadcast_to(origin, to.shape), to)
    own = np.array([p.owner for p in scene.points])
    visible = (owner == own) | (t >= dist - 1e-6)
    local = np.einsum("bij,pi->bpj", frames, pos)                       # (beam, point, (d, y, z))
    d = local[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        rho2 = (np.arctan2(local[..., 1], d) / half_az) ** 2 + (np.arctan2(local[..., 2], d) / half_el) ** 2
    seen = visible[None] & (d > 0) & (rho2 <= SPAN ** 2)
    rcs = np.array([p.rcs_m2 for p in scene.points])
    amp = np.where(seen, A_1M2_AT_10M * np.sqrt(rcs) * (R_REF_M / dist) ** 2 * 2.0 ** -np.where(seen, rho2, 0), 0.0)
    return amp, np.broadcast_to(dist, amp.shape).copy()


def observe(scene, tilts_deg, radar=PAPER_RADAR, seed=0, rays_across=RAYS_ACROSS, noise_rms=NOISE_RMS, adc=ADC,
            progress=None):
    """Simulate one frame per tilt (``outdoor.PAPER_TILTS_DEG``); returns ``Observations``.
    ``progress(done_frames, n_frames)`` is called after each frame."""
    tilts = np.asarray(tilts_deg, float).reshape(-1)
    if not len(tilts):
        raise ConfigError("observe needs at least one tilt")
    if radar.complex_samples:
        raise ConfigError("the reference scene simulates a real-sampling radar like the paper's")
    rng = np.random.default_rng(seed)
    frames, poses, clipped = [], [], 0
    for j, tilt in enumerate(tilts):
        pose = scene.stand_pose(float(tilt))
        amp, r, phase = observe_frame(scene, pose, radar, rays_across, rng)
        sim = simulate_beams(radar, amp, r, phase, noise_rms=noise_rms, adc=adc, seed=rng.integers(2 ** 63))
        frames.append(sim.samples.reshape(radar.n_azimuth, radar.n_elevation, radar.n_samples))
        poses.append(pose)
        clipped += sim.n_clipped
        if progress is not None:
            progress(j + 1, len(tilts))
    return Observations(np.stack(frames), np.stack(poses), tilts, int(seed), int(amp.shape[1]), clipped)
