"""Power range profiles of simple scenes through the paper's radar: flat ground lit by a tilted
beam (a distributed echo) and point echoes, via the eq. 5 simulator and the float64 range
processing of ``radarcl.oracle`` (Hann window, zero padding, |X|^2).

These feed the detection tests (the two cases of the paper's Fig. 10) and the CFAR bench. The
ground is a line of independent scatterers with random phases (Rayleigh speckle) whose power
falls as r^-3 (radar equation r^-4 times a footprint growing as r), so its echo has the
width that geometry predicts (``physics.ground_echo_extent``) seen through the radar's pulse.
"""

import math

import numpy as np

from radarcl import oracle
from radarcl.config.stage_config import PAPER_RADAR, PAPER_SENSOR_HEIGHT_M
from radarcl.errors import ConfigError
from radarcl.scene.fmcw import simulate_beams

NOISE_RMS = 1e-3           # receiver noise per sample [V]
SCATTERERS_PER_M = 40      # ground scatterers per metre of range: many per resolution cell


def ground_scatterers(elevation_deg, sensor_height_m=PAPER_SENSOR_HEIGHT_M, amplitude_at_10m=0.002,
                      radar=PAPER_RADAR, rng=None):
    """(amplitude, range_m, phase) of the ground lit by a beam at ``elevation_deg`` (< 0: down).

    The ground spans h / sin(-e + b/2) .. h / sin(-e - b/2) (cut at the radar's range_max_m);
    a beam that does not reach the ground gets no scatterers (empty arrays).
    """
    rng = np.random.default_rng(rng)
    half = math.radians(radar.beamwidth_el_deg) / 2
    down = -math.radians(elevation_deg)
    if sensor_height_m <= 0:
        raise ConfigError(f"sensor_height_m must be positive, got {sensor_height_m}")
    if down - half <= 0 and down + half <= 0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    near = sensor_height_m / math.sin(down + half)
    far = sensor_height_m / math.sin(down - half) if down - half > 0 else math.inf
    near, far = min(near, radar.range_max_m), min(far, radar.range_max_m)
    count = max(1, int((far - near) * SCATTERERS_PER_M))
    ranges = rng.uniform(near, far, count)
    power = rng.exponential(size=count) / SCATTERERS_PER_M * (10.0 / ranges) ** 3
    return amplitude_at_10m * np.sqrt(power), ranges, rng.uniform(0, 2 * np.pi, count)


def beam_profile(amplitude, range_m, phase, n_fft=1024, radar=PAPER_RADAR, noise_rms=NOISE_RMS, seed=None):
    """Power profile (n_fft/2,) float64 of one beam holding the given scatterers plus noise."""
    if len(amplitude) == 0:
        amplitude, range_m, phase = np.zeros(1), np.ones(1), np.zeros(1)
    samples = simulate_beams(radar, amplitude, range_m, phase, noise_rms=noise_rms, seed=seed).samples
    return oracle.range_profile(samples, n_fft, output="power")


def fig10_ground_beam(seed=0, n_fft=1024):
    """The paper's Fig. 10a case: a beam at -9 deg whose footprint on the ground makes a wide
    pulse, with two point echoes behind it. Returns (profile float64, ground (near, far) [m])."""
    rng = np.random.default_rng(seed)
    a, r, p = ground_scatterers(-9.0, rng=rng)
    a = np.concatenate([a, [0.0015, 0.001]])
    r = np.concatenate([r, [18.0, 31.0]])
    p = np.concatenate([p, rng.uniform(0, 2 * np.pi, 2)])
    return beam_profile(a, r, p, n_fft, seed=seed), (float(r[:-2].min()), float(r[:-2].max()))


def fig10_fence_and_tree(seed=0, n_fft=1024, fence_m=14.0, tree_m=23.0):
    """The paper's Fig. 10b case: a beam almost parallel to the ground (no ground return) with
    two narrow pulses, a fence and a tree. Returns the power profile, float64."""
    rng = np.random.default_rng(seed)
    return beam_profile(np.array([0.0015, 0.001]), np.array([fence_m, tree_m]), rng.uniform(0, 2 * np.pi, 2),
                        n_fft, seed=seed)


def paper_like_samples(seed=0, tilt_deg=-7.0, radar=PAPER_RADAR):
    """Raw samples (n_az, n_el, n_samples) float32 [V] of one frame of the paper's radar on its
    stand: ground in every beam that reaches it, and 0-3 point echoes per beam with amplitudes
    0.5-5.5 decades above the per-sample noise (up to ~100 dB in power). Stacked beam k points
    at tilt + (k - 1.5) x 2 deg."""
    rng = np.random.default_rng(seed)
    n_az, n_el = radar.n_azimuth, radar.n_elevation
    beams = []
    for el in range(n_el):
        elevation = tilt_deg + (el - (n_el - 1) / 2) * radar.elevation_step_deg
        for _ in range(n_az):
            a, r, p = ground_scatterers(elevation, rng=rng, radar=radar)
            k = int(rng.integers(0, 4))
            a = np.concatenate([a, NOISE_RMS * 10 ** rng.uniform(0.5, 5.5, k)])
            r = np.concatenate([r, rng.uniform(2, 60, k)])
            p = np.concatenate([p, rng.uniform(0, 2 * np.pi, k)])
            beams.append((a, r, p))
    width = max(len(b[0]) for b in beams)
    amp, rng_m, phase = (np.zeros((len(beams), width)) for _ in range(3))
    rng_m[:] = 1.0
    for j, (a, r, p) in enumerate(beams):
        amp[j, :len(a)], rng_m[j, :len(r)], phase[j, :len(p)] = a, r, p
    samples = simulate_beams(radar, amp, rng_m, phase, noise_rms=NOISE_RMS, seed=seed).samples
    return samples.reshape(n_el, n_az, -1).transpose(1, 0, 2).astype(np.float32)


def paper_like_frame(seed=0, tilt_deg=-7.0, n_fft=1024, radar=PAPER_RADAR):
    """Power profiles (n_az, n_el, n_fft/2) float32 of ``paper_like_samples``, by the oracle."""
    samples = paper_like_samples(seed, tilt_deg, radar).astype(np.float64)
    return oracle.range_profile(samples, n_fft, output="power").astype(np.float32)
