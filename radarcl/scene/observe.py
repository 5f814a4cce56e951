"""Radar observations of a ``Scene``: raw beat-signal samples of every beam, seeded.

Each beam is sampled by rays spread over its pattern: the directions of one lattice fixed in the
world (``lattice_rays``; cells of 2 SPAN / RAYS_ACROSS half-power half-widths, a jitter fixed per
cell) whose offsets (s, t) from the beam's axis, in half-widths, satisfy s^2 + t^2 <= ``SPAN``^2,
so the one-way pattern 2^-(s^2 + t^2) (the square root of ``geometry.two_way_weight``) falls to
0.21 at the edge of what is sampled. Beams and tilts that overlap share rays. Per ray:

- the first surface it meets (occlusion: nothing behind it is seen);
- a patch of that surface of area r^2 dOmega / cos(theta_i) with sigma0 = gamma cos(theta_i)
  (the constant-gamma model, ``outdoor.Material``), so the patch's RCS is gamma r^2 dOmega;
- the radar equation in amplitude: a = A_1M2_AT_10M sqrt(sigma / 1 m^2) (10 m / r)^2 times the
  two-way pattern in amplitude, 2^-(s^2 + t^2);
- the phase of the scatterer it hits, fixed per ``SPECKLE_CELL_M`` cell of the surface and per
  recording (``hash_uniform`` of the cell and the seed): a still radar sees the same speckle
  from the same scatterer at every tilt, as a real one does (before, every tilt drew new
  phases, and fusing tilts averaged speckle more than a real radar could).

A grazing ground return spreads over the ranges its rays reach, and its power per range cell
falls with range: both come from the geometry, nothing is imposed. Point scatterers (RCS) add
one echo to each beam whose sampled pattern holds them, unless a surface occludes them.
The echoes become samples through the eq. 5 simulator (``fmcw.simulate_beams``) with receiver
noise and the ADC's rounding and clipping, so the whole pipeline runs from raw samples.

Harder physics, each a bit of ``physics``, off by default (nothing above changes when off):
SIDELOBES (a sidelobe ring; the spinning radar's fan beam has it in azimuth only), MULTIPATH
(specular surfaces; the stand's ground bounce, the spinning radar's mirror paths off the
terrain and smooth walls, traced), SPREAD (a heavy-tailed RCS per surface patch and point),
CLUTTER (rain: volume scatterers of K-distributed power, new each frame). Range sidelobes need
no switch: the range FFT's window makes them from the samples.
"""

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.special import stdtrit

from radarcl.config.stage_config import PAPER_RADAR
from radarcl.errors import ConfigError, FrameFormatError
from radarcl.geometry import BeamLattice
from radarcl.io import recording
from radarcl.scene.fmcw import Adc, simulate_beams

SPAN = 1.5                   # sampled pattern radius, in half-power half-widths
RAYS_ACROSS = 12             # stratified grid of RAYS_ACROSS^2 cells over the span's square
A_1M2_AT_10M = 0.05          # tone amplitude [V] of a 1 m^2 target at 10 m on the beam axis
R_REF_M = 10.0
NOISE_RMS = 1e-3             # receiver noise per sample [V]
SPECKLE_CELL_M = 0.05        # a scatterer's phase is fixed per cell of this edge on the surface
# Harder physics (the paper's future work), each a switch, off by default (docs/guide/evaluation.md):
SIDELOBES = 1                # the pattern beyond the main lobe: a sidelobe ring at -20 dB out to SIDELOBE_SPAN
MULTIPATH = 2                # ghosts of mirror paths (ground, smooth walls) and specular surfaces
SPREAD = 4                   # each surface patch's and point's RCS drawn from a heavy-tailed spread
CLUTTER = 8                  # a diffuse clutter floor: volume scatterers of K-distributed power
PHYSICS_NAMES = {"sidelobes": SIDELOBES, "multipath": MULTIPATH, "spread": SPREAD, "clutter": CLUTTER}
SIDELOBE_SPAN = 3.0          # sampled radius with sidelobes, in half-power half-widths
SIDELOBE_DB = -20.0          # the ring's peak: two-way pattern amplitude, so echo power (one-way power: -10 dB)
GROUND_BOUNCE = 0.5          # amplitude reflection coefficient of the terrain (-6 dB), twice on the image path
WALL_BOUNCE = 0.4            # of a smooth wall: Fresnel's (n - 1) / (n + 1) for concrete, eps_r ~ 5-6 at 77 GHz
SPECULAR_EXPONENT = 40       # a specular surface returns gamma cos^41(incidence): at 30 deg, 0.3 % of diffuse
SPREAD_CELL_M = 0.5          # one RCS draw per cell of this edge on a surface (the size of a facade's feature)
SPREAD_SCALE_DB = 6.0        # the draw in dB: SPREAD_SCALE_DB x Student's t with SPREAD_DOF degrees of freedom:
SPREAD_DOF = 3               # median 0 dB (the material's gamma), the quartiles of a 7 dB log-normal, tails heavier
SPREAD_CLIP_DB = 30.0        # ... clipped at +-30 dB (a 10 cm corner reflector over a 0.5 m patch of brick)
CLUTTER_ETA = 1e-3           # volume reflectivity [m^2 / m^3]: rain-like, 17 dB over noise at 10 m (docs/guide/evaluation.md)
CLUTTER_PER_M = 1.0          # scatterers per metre of range in each beam (a bin of 0.25 m holds 0 or 1)
CLUTTER_SHAPE = 1.0          # K-distribution shape nu: texture Gamma(nu, 1 / nu) x exponential speckle
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
    physics: int = 0             # SIDELOBES | MULTIPATH | SPREAD | CLUTTER: the switches it was simulated with
    offsets_m: np.ndarray = None  # (n_frames, 3) the sensor's offset from the scene's sensor_m per frame (moving), or None

    def first(self, n):
        """The first ``n`` frames, as the recording they would have been alone (the same seed,
        so the same scatterers; the receiver noise of those frames)."""
        offsets = None if self.offsets_m is None else self.offsets_m[:n]
        return Observations(self.samples[:n], self.poses[:n], self.tilts_deg[:n], self.seed, self.rays_per_beam,
                            self.n_clipped, self.physics, offsets)


def _beam_frames(pose, lattice):
    """(n_beams, 3, 3) world rotations of the beams: columns u (axis), v, w."""
    return pose[:3, :3] @ lattice.beam_rotations()


def hash_uniform(keys, salt, stream=0):
    """Floats in [0, 1) from integer ``keys`` (..., m) and ``salt``: splitmix64 over the key's
    entries, so the same key always draws the same number (the same scatterer, the same ray)."""
    k = np.asarray(keys, np.int64).astype(np.uint64)
    with np.errstate(over="ignore"):
        h = np.uint64((int(salt) * 0x9E3779B97F4A7C15 + int(stream) * 0xD1B54A32D192ED03) & 0xFFFFFFFFFFFFFFFF)
        h = np.broadcast_to(h, k.shape[:-1]).copy()
        for j in range(k.shape[-1]):
            h = (h ^ k[..., j]) * np.uint64(0xBF58476D1CE4E5B9)
            h ^= h >> np.uint64(31)
        h = (h ^ (h >> np.uint64(30))) * np.uint64(0x94D049BB133111EB)
        h ^= h >> np.uint64(31)
    return (h >> np.uint64(11)).astype(np.float64) / 2.0 ** 53


def lattice_rays(frames, half_az, half_el, rays_across=RAYS_ACROSS, salt=0, span=SPAN, span_az=None):
    """The rays that sample each beam, drawn from one lattice of directions fixed in the world:
    cells ``2 SPAN / rays_across`` half-power half-widths wide in world azimuth and elevation,
    one ray per cell at a jitter fixed per cell (``hash_uniform``). A beam takes the lattice's
    rays within ``span`` of its axis, so beams and tilts that overlap share rays, and a still
    radar sees the same scatterers, with the same speckle, at every tilt. ``span_az``: also the
    rays within ``span_az`` in azimuth and ``span`` in elevation (a fan beam's azimuth sidelobes).

    Returns (dirs (n_beams, k, 3), offsets (n_beams, k, 2) in half-widths, solid angle per ray
    (n_beams, k) [sr], used (n_beams, k) bool); k is the most rays a beam holds."""
    cell = 2 * SPAN / rays_across                 # the lattice does not change with the span
    d_az, d_el = cell * half_az, cell * half_el
    u = frames[:, :, 0]
    a_b, e_b = np.arctan2(u[:, 1], u[:, 0]), np.arcsin(np.clip(u[:, 2], -1, 1))
    worst = np.cos(np.minimum(np.abs(e_b).max() + span * half_el, 1.4))
    reach = span if span_az is None else max(span, span_az)
    n_i, n_k = int(math.ceil(reach * half_az / (d_az * worst))) + 1, int(math.ceil(span / cell)) + 1
    di, dk = np.meshgrid(np.arange(-n_i, n_i + 1), np.arange(-n_k, n_k + 1), indexing="ij")
    I = np.rint(a_b / d_az).astype(np.int64)[:, None] + di.reshape(1, -1)
    K = np.rint(e_b / d_el).astype(np.int64)[:, None] + dk.reshape(1, -1)
    keys = np.stack([I, K], axis=-1)
    az = (I + hash_uniform(keys, salt, 1) - 0.5) * d_az
    el = (K + hash_uniform(keys, salt, 2) - 0.5) * d_el
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)
    du, dv, dw = (np.einsum("bkj,bj->bk", dirs, frames[:, :, c]) for c in range(3))
    st = np.stack([np.arctan2(dv, du) / half_az, np.arctan2(dw, du) / half_el], axis=-1)
    inside = (du > 0) & ((st ** 2).sum(axis=-1) <= span ** 2)
    if span_az is not None:
        inside |= (du > 0) & (np.abs(st[..., 0]) <= span_az) & (np.abs(st[..., 1]) <= span)
    order = np.argsort(~inside, axis=1, kind="stable")[:, :int(inside.sum(axis=1).max())]
    take = lambda a: np.take_along_axis(a, order.reshape(order.shape + (1,) * (a.ndim - 2)), axis=1)  # noqa: E731
    used = take(inside)
    return take(dirs), take(st), np.where(used, d_az * d_el * np.cos(take(el)), 0.0), used


def _ring(rho):
    """The sidelobe ring in the two-way pattern's amplitude: peaking at SIDELOBE_DB halfway
    between SPAN and SIDELOBE_SPAN half-widths off the axis, 0 elsewhere."""
    ring = 10 ** (SIDELOBE_DB / 20) * np.sin(np.pi * np.clip((rho - SPAN) / (SIDELOBE_SPAN - SPAN), 0, 1)) ** 2
    return ring * (rho > SPAN)


def pattern_amplitude(rho, sidelobes=False):
    """Two-way pattern in amplitude at ``rho`` half-power half-widths off the axis: the main lobe
    2^-rho^2 (the square root of ``geometry.two_way_weight``); with sidelobes, beyond it a ring
    peaking at SIDELOBE_DB between 1.5 and SIDELOBE_SPAN (a stylised first sidelobe)."""
    main = 2.0 ** -(rho ** 2)
    if not sidelobes:
        return main
    return np.maximum(main, _ring(rho))


def fan_pattern_amplitude(st, sidelobes=False):
    """A fan beam's two-way pattern in amplitude at offsets ``st`` (..., 2) (azimuth, elevation)
    in half-widths: the main lobe 2^-(s^2 + t^2); with sidelobes, the ring of
    ``pattern_amplitude`` in azimuth only, times the main lobe's elevation profile 2^-t^2. A
    long horizontal aperture (a narrow azimuth beam) puts its sidelobes in the horizontal plane;
    a short vertical one (a tall beam) puts them far up and down."""
    s, t = st[..., 0], st[..., 1]
    main = 2.0 ** -(s ** 2 + t ** 2)
    if not sidelobes:
        return main
    return np.maximum(main, _ring(np.abs(s)) * 2.0 ** -(t ** 2))


def observe_frame(scene, pose, radar=PAPER_RADAR, rays_across=RAYS_ACROSS, salt=0, physics=0, lattice=None, frame=0):
    """Echoes of every beam of one frame: (amplitude, range_m, phase) arrays (n_beams, k).

    ``salt`` fixes the recording's scatterers: ray jitter and speckle phases are functions of
    the world direction and of the scatterer, not random draws (``lattice_rays``,
    ``hash_uniform``), so the same salt gives the same echoes at the same pose. ``physics``:
    SIDELOBES | MULTIPATH | SPREAD | CLUTTER (module constants), 0 for none. ``pose`` (4, 4) puts
    the head at the scene's sensor position; (n_beams, 4, 4) gives each beam its own pose and
    origin (a spinning radar on a moving vehicle: ``scene.streets``; no point scatterers; its
    fan beam's sidelobes lie in azimuth only, ``fan_pattern_amplitude``, and its multipath is
    traced, ``_mirror_paths``). ``lattice``: the frame's ``BeamLattice`` (default: the radar's
    stacked lattice). ``frame``: the frame's index in its recording (CLUTTER's scatterers are
    drawn anew each frame, as rain's drops move)."""
    lattice = BeamLattice.from_radar(radar) if lattice is None else lattice
    P = np.asarray(pose, float)
    per_beam = P.ndim == 3
    if per_beam and scene.points:
        raise ConfigError("one pose per beam simulates surfaces only: no point scatterers")
    frames = P[:, :3, :3] @ lattice.beam_rotations() if per_beam else _beam_frames(P, lattice)
    n_beams = len(frames)
    half_az, half_el = math.radians(radar.beamwidth_az_deg) / 2, math.radians(radar.beamwidth_el_deg) / 2
    origin = np.asarray(scene.sensor_m, float)

    sidelobes, fan = bool(physics & SIDELOBES), per_beam and bool(physics & SIDELOBES)
    if fan:                              # the spinning radar's fan beam: sidelobes in azimuth only
        dirs, st, d_omega, used = lattice_rays(frames, half_az, half_el, rays_across, salt, SPAN, SIDELOBE_SPAN)
    else:
        span = SIDELOBE_SPAN if sidelobes else SPAN
        dirs, st, d_omega, used = lattice_rays(frames, half_az, half_el, rays_across, salt, span)
    k = dirs.shape[1]
    flat = dirs.reshape(-1, 3)
    starts = np.repeat(P[:, :3, 3], k, axis=0) if per_beam else np.broadcast_to(origin, flat.shape)
    t, owner, normal = scene.first_hit(starts, flat)
    hit = np.isfinite(t) & (t <= radar.range_max_m * 1.05) & used.reshape(-1)
    gamma = np.array([10 ** (o.material.gamma_db / 10) for o in scene.objects])
    specular = np.array([getattr(o.material, "specular", False) for o in scene.objects])
    cos_i = np.abs(np.einsum("ij,ij->i", normal, flat))
    r = np.where(hit, t, R_REF_M)
    area = r ** 2 * d_omega.reshape(-1) / np.maximum(cos_i, 1e-6)      # patch of surface [m^2]
    sigma = np.where(hit, gamma[owner] * cos_i * area, 0.0)            # sigma0(theta_i) x area
    if physics & MULTIPATH:              # a specular surface sends the beam away unless it meets it square on
        sigma = np.where(hit & specular[owner], sigma * cos_i ** SPECULAR_EXPONENT, sigma)
    p_hit = starts + np.where(hit, t, 0.0)[:, None] * flat
    if physics & SPREAD:
        sigma = sigma * 10 ** (spread_db(np.floor(p_hit / SPREAD_CELL_M), salt) / 10)
    pattern = (fan_pattern_amplitude(st, True) if fan else
               pattern_amplitude(np.sqrt((st ** 2).sum(axis=-1)), sidelobes)).reshape(-1)
    amp = A_1M2_AT_10M * np.sqrt(sigma) * (R_REF_M / r) ** 2 * pattern
    amp, rng_m = amp.reshape(n_beams, k), r.reshape(n_beams, k)
    # the scatterer's own phase: fixed per SPECKLE_CELL_M cell of the surface it sits on
    cells = np.floor(p_hit / SPECKLE_CELL_M).astype(np.int64)
    phase = 2 * np.pi * hash_uniform(cells, salt, 3).reshape(n_beams, k)
    extra = []
    if physics & MULTIPATH and per_beam:     # paths off the terrain and smooth walls, traced
        extra.append(_mirror_paths(scene, frames, starts, flat, t, hit, owner, normal, d_omega.reshape(-1), pattern,
                                   salt, physics, (half_az, half_el), radar.range_max_m * 1.05))
    elif physics & MULTIPATH:            # the ground bounce: the echo of the object's mirror image below the terrain
        ghost_amp, ghost_r = _ground_bounce(scene, origin, flat, t, hit, owner, amp.reshape(-1))
        amp = np.concatenate([amp, ghost_amp.reshape(n_beams, k)], axis=1)
        rng_m = np.concatenate([rng_m, ghost_r.reshape(n_beams, k)], axis=1)
        phase = np.concatenate([phase, (phase + np.pi) % (2 * np.pi)], axis=1)    # two reflections: pi each

    if scene.points:
        p_amp, p_r = _point_echoes(scene, frames, origin, half_az, half_el)
        if physics & SPREAD:
            p_amp = p_amp * 10 ** (spread_db(np.arange(len(scene.points))[:, None], salt, 6) / 20)
        amp = np.concatenate([amp, p_amp], axis=1)
        rng_m = np.concatenate([rng_m, p_r], axis=1)
        fixed = 2 * np.pi * hash_uniform(np.arange(len(scene.points))[:, None], salt, 4)
        phase = np.concatenate([phase, np.broadcast_to(fixed, p_amp.shape)], axis=1)
    if physics & CLUTTER:
        beam_origins = P[:, :3, 3] if per_beam else np.broadcast_to(origin, (n_beams, 3))
        extra.append(_clutter(scene, frames, beam_origins, radar, half_az, half_el, salt, frame))
    for columns in extra:
        amp, rng_m, phase = (np.concatenate([a, c], axis=1) for a, c in zip((amp, rng_m, phase), columns))
    return amp, rng_m, phase


def spread_db(keys, salt, stream=5):
    """SPREAD's RCS draw [dB] per key (..., m) (a surface cell, a point): SPREAD_SCALE_DB times
    Student's t with SPREAD_DOF degrees of freedom at the key's ``hash_uniform``, clipped to
    +-SPREAD_CLIP_DB; median 0 dB. The same key and salt draw the same value."""
    u = hash_uniform(np.asarray(keys).astype(np.int64), salt, stream)
    return np.clip(SPREAD_SCALE_DB * stdtrit(SPREAD_DOF, u), -SPREAD_CLIP_DB, SPREAD_CLIP_DB)


def _beam_offsets(frames, vec, half_az, half_el):
    """(along the axis, offsets (m, 2) in half-widths) of unit vectors ``vec`` (m, 3) in the
    beams ``frames`` (m, 3, 3), as ``lattice_rays`` measures its rays."""
    du, dv, dw = (np.einsum("mj,mj->m", vec, frames[:, :, c]) for c in range(3))
    return du, np.stack([np.arctan2(dv, du) / half_az, np.arctan2(dw, du) / half_el], axis=-1)


def _by_beam(beam, n_beams, *columns):
    """Echoes listed with their ``beam`` as (n_beams, m) arrays, each beam's first (zeros pad),
    m the most any beam has (at least 1)."""
    order = np.argsort(beam, kind="stable")
    beam = beam[order]
    counts = np.bincount(beam, minlength=n_beams)
    slot = np.arange(len(beam)) - np.repeat(np.cumsum(counts) - counts, counts)
    out = []
    for c in columns:
        a = np.zeros((n_beams, max(1, int(counts.max(initial=0)))))
        a[beam, slot] = c[order]
        out.append(a)
    return out


def _mirror_paths(scene, frames, starts, dirs, t, hit, owner, normal, d_omega, pattern, salt, physics, half, r_max):
    """Echoes (amplitude, range, phase) (n_beams, m) of the paths that bounce off a mirror: the
    terrain (a ``Ground`` or ``Slope``, amplitude coefficient GROUND_BOUNCE) or a specular
    surface (WALL_BOUNCE). A ray whose first hit q is a mirror goes on along its reflection and
    meets a surface at p; the patch it lights there (constant gamma, as a direct hit's) gives

    - radar -> q -> p -> q -> radar: a ghost at the mirror image of p, range L = |q - o| + |p - q|,
      coefficient^2 of what that patch would give at L on the ray's own pattern weight (the
      stand's ground bounce, with the pattern taken where the image lies);
    - radar -> q -> p -> radar and its reverse (one length, so twice the amplitude): range
      (L + |p - o|) / 2, coefficient once, the radar equation over L and |p - o|, the pattern
      the geometric mean of the ray's and p's direction's (0 outside the sampled beam), p seen
      from the radar unoccluded.

    Both lie beyond p's own range; the beam's main lobe must hold the ray (and, for the second,
    p's direction too), so a wall that turns the beam sideways gives mostly the first."""
    n_beams = len(frames)
    k = len(t) // n_beams
    specular = np.array([getattr(o.material, "specular", False) for o in scene.objects])
    terrain = np.array([hasattr(o.shape, "height") for o in scene.objects])      # Ground, Slope
    idx = np.flatnonzero(hit & (terrain[owner] | specular[owner]))
    coeff = np.where(terrain[owner[idx]], GROUND_BOUNCE, WALL_BOUNCE)
    d, n, o = dirs[idx], normal[idx], starts[idx]
    q = o + t[idx, None] * d
    d2 = d - 2 * np.einsum("ij,ij->i", d, n)[:, None] * n
    start2 = q - 1e-6 * d                       # a step back along the ray: off the mirror, on its lit side
    t2, owner2, normal2 = scene.first_hit(start2, d2)
    ok = np.isfinite(t2)
    p = start2 + np.where(ok, t2, 0.0)[:, None] * d2
    length = t[idx] + np.linalg.norm(p - q, axis=1)
    ok &= length <= r_max
    idx, coeff, o, d2, p, length, owner2, normal2 = (a[ok] for a in (idx, coeff, o, d2, p, length, owner2, normal2))
    gamma = np.array([10 ** (obj.material.gamma_db / 10) for obj in scene.objects])
    cos2 = np.abs(np.einsum("ij,ij->i", normal2, d2))
    sigma = gamma[owner2] * length ** 2 * d_omega[idx]          # gamma cos_i x the patch L^2 dOmega / cos_i
    sigma = np.where(specular[owner2], sigma * cos2 ** SPECULAR_EXPONENT, sigma)
    if physics & SPREAD:
        sigma = sigma * 10 ** (spread_db(np.floor(p / SPREAD_CELL_M), salt) / 10)
    phase = 2 * np.pi * hash_uniform(np.floor(p / SPECKLE_CELL_M).astype(np.int64), salt, 3)
    beam = idx // k
    image_amp = A_1M2_AT_10M * np.sqrt(sigma) * (R_REF_M / length) ** 2 * pattern[idx] * coeff ** 2

    to_p = p - o
    r_p = np.linalg.norm(to_p, axis=1)
    along, st = _beam_offsets(frames[beam], to_p / r_p[:, None], *half)
    fan = bool(physics & SIDELOBES)
    inside = (along > 0) & (((st ** 2).sum(axis=-1) <= SPAN ** 2) |
                            (fan & (np.abs(st[:, 0]) <= SIDELOBE_SPAN) & (np.abs(st[:, 1]) <= SPAN)))
    back = np.where(inside, fan_pattern_amplitude(st, fan), 0.0)
    look = np.flatnonzero(back > 0)
    t3, _, _ = scene.first_hit(o[look], to_p[look] / r_p[look, None])
    back[look[t3 < r_p[look] - 1e-3]] = 0.0                     # something stands between the radar and p
    mixed_amp = (2 * coeff * A_1M2_AT_10M * np.sqrt(sigma) * R_REF_M ** 2 / (length * r_p)
                 * np.sqrt(pattern[idx] * back))
    mixed = back > 0
    return _by_beam(np.concatenate([beam, beam[mixed]]), n_beams,
                    np.concatenate([image_amp, mixed_amp[mixed]]),
                    np.concatenate([length, (length[mixed] + r_p[mixed]) / 2]),
                    np.concatenate([phase, phase[mixed]]))


def _clutter(scene, frames, origins, radar, half_az, half_el, salt, frame):
    """Echoes (amplitude, range, phase) (n_beams, m) of a volume of clutter (rain): per beam,
    scatterers at CLUTTER_PER_M per metre (Poisson) from the radar's minimum range to the first
    surface on the beam's axis, each of mean RCS CLUTTER_ETA x its share of the beam's volume,
    CLUTTER_ETA Omega r^2 / CLUTTER_PER_M (Omega = pi half_az half_el / (2 ln 2), the two-way
    pattern's solid angle), times a Gamma(CLUTTER_SHAPE) texture and an exponential speckle:
    K-distributed power. Drawn from (salt, frame): the same recording draws the same drops."""
    rng = np.random.default_rng([int(salt) % 2 ** 63, int(frame), CLUTTER])
    n_beams = len(frames)
    t_axis, _, _ = scene.first_hit(np.ascontiguousarray(origins, float), frames[:, :, 0])
    near, far = radar.range_min_m, np.minimum(t_axis, radar.range_max_m)
    count = rng.poisson(CLUTTER_PER_M * np.maximum(far - near, 0.0))
    beam = np.repeat(np.arange(n_beams), count)
    r = near + rng.random(len(beam)) * (far - near)[beam]
    omega = math.pi * half_az * half_el / (2 * math.log(2))
    texture = rng.gamma(CLUTTER_SHAPE, 1 / CLUTTER_SHAPE, len(beam))
    sigma = CLUTTER_ETA * omega * r ** 2 / CLUTTER_PER_M * texture * rng.exponential(1.0, len(beam))
    amp = A_1M2_AT_10M * np.sqrt(sigma) * (R_REF_M / r) ** 2
    return _by_beam(beam, n_beams, amp, r, 2 * np.pi * rng.random(len(beam)))


def _ground_bounce(scene, origin, dirs, t, hit, owner, amp):
    """(amplitude, range) of the double-bounce echo of every ray that hit a solid above the
    terrain: sensor -> terrain -> object -> terrain -> sensor, whose length is the distance to the
    object's mirror image in the terrain (flat ground at z = 0, or the terrain's height below the
    hit), with GROUND_BOUNCE^2 of the direct amplitude. A ghost in the map below the surface."""
    terrain = scene.objects[0].shape
    p = origin + np.where(hit, t, 0.0)[:, None] * dirs
    ground = terrain.height(p[:, 0], p[:, 1]) if hasattr(terrain, "height") else np.zeros(len(p))
    above = hit & (owner > 0) & (p[:, 2] > ground + 0.05)
    image = p.copy()
    image[:, 2] = 2 * ground - p[:, 2]
    r = np.where(above, np.linalg.norm(image - origin, axis=1), R_REF_M)
    return np.where(above, amp * GROUND_BOUNCE ** 2, 0.0), r


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
            progress=None, physics=0, offsets_m=None):
    """Simulate one frame per tilt (``outdoor.PAPER_TILTS_DEG``); returns ``Observations``.
    ``progress(done_frames, n_frames)`` is called after each frame. ``offsets_m`` (n_frames, 3):
    a moving sensor, frame j taken at scene.sensor_m + offsets_m[j] (the same scatterers: speckle
    changes only as the viewpoint does)."""
    tilts = np.asarray(tilts_deg, float).reshape(-1)
    if not len(tilts):
        raise ConfigError("observe needs at least one tilt")
    if offsets_m is not None:
        offsets_m = np.asarray(offsets_m, float)
        if offsets_m.shape != (len(tilts), 3) or not np.isfinite(offsets_m).all():
            raise ConfigError(f"offsets_m must be finite ({len(tilts)}, 3), one per tilt, got {offsets_m.shape}")
    if radar.complex_samples:
        raise ConfigError("the reference scene simulates a real-sampling radar like the paper's")
    rng = np.random.default_rng(seed)
    frames, poses, clipped = [], [], 0
    for j, tilt in enumerate(tilts):
        here = scene if offsets_m is None else replace(scene, sensor_m=tuple(np.add(scene.sensor_m, offsets_m[j])))
        pose = here.stand_pose(float(tilt))
        amp, r, phase = observe_frame(here, pose, radar, rays_across, salt=seed, physics=physics, frame=j)
        sim = simulate_beams(radar, amp, r, phase, noise_rms=noise_rms, adc=adc, seed=rng.integers(2 ** 63))
        frames.append(sim.samples.reshape(radar.n_azimuth, radar.n_elevation, radar.n_samples))
        poses.append(pose)
        clipped += sim.n_clipped
        if progress is not None:
            progress(j + 1, len(tilts))
    return Observations(np.stack(frames), np.stack(poses), tilts, int(seed), int(amp.shape[1]), clipped, int(physics),
                        offsets_m)


def load_observations(path):
    """A simulation of the paper's reference scene (``scene.observe.Observations``) from its
    recording; refuses recordings of other sensors or without the simulation's metadata."""
    rec = recording.load(path)
    if rec.frames.shape[1:] != PAPER_RADAR.frame_shape or rec.frames.dtype != np.int16:
        raise FrameFormatError(f"{path}: frames are {rec.frames.shape[1:]} {rec.frames.dtype}; the paper radar's "
                               f"are {PAPER_RADAR.frame_shape} int16")
    missing = [k for k in recording.SIMULATION_META if k not in rec.meta]
    if missing or rec.poses.ndim != 3:
        raise FrameFormatError(f"{path} is not a recording of the reference scene: it lacks {', '.join(missing)}"
                               if missing else f"{path}: the reference scene has one pose per frame")
    if rec.meta["tilts_deg"].shape != (len(rec),):
        raise FrameFormatError(f"{path}: {len(rec)} frames need tilts ({len(rec)},), got {rec.meta['tilts_deg'].shape}")
    m = rec.meta
    return Observations(rec.frames, rec.poses, m["tilts_deg"], m["seed"], m["rays_per_beam"], m["n_clipped"],
                        m.get("physics", 0))
