"""The paper's §4.1 experiment: two point targets in line, resolved or not, with zero padding.

Whether two equal echoes one resolution cell apart show two peaks depends on their relative
phase (unknown: the reflection adds phi, eq. 4) and on where they fall between FFT bins
(paper Fig. 4 b-c). So the experiment is a sweep: a grid of relative phases x a common range
offset across one resolution cell, and the result is the fraction of cases resolved.
"""

from dataclasses import dataclass

import numpy as np

from radarcl import oracle
from radarcl.config.stage_config import RadarConfig
from radarcl.scene.fmcw import simulate_beams


def count_peaks(profile, ranges_m, lo_m, hi_m, min_dip_db=0.0):
    """Peaks of ``profile`` between lo_m and hi_m: local maxima within 6 dB of the strongest,
    merged when the dip between neighbours is shallower than ``min_dip_db`` (0: any dip counts,
    the paper's "double change in the slope", Fig. 4)."""
    idx = np.flatnonzero((ranges_m >= lo_m) & (ranges_m <= hi_m))
    v = np.asarray(profile, dtype=np.float64)[idx]
    maxima = [i for i in range(1, len(v) - 1) if v[i] > v[i - 1] and v[i] >= v[i + 1] and v[i] >= v.max() / 2]
    kept = []
    for i in maxima:
        if kept and 20 * np.log10(min(v[kept[-1]], v[i]) / max(v[kept[-1]:i + 1].min(), 1e-300)) < min_dip_db:
            if v[i] > v[kept[-1]]:
                kept[-1] = i
            continue
        kept.append(i)
    return [float(ranges_m[idx[i]]) for i in kept]


@dataclass(frozen=True)
class ResolutionResult:
    """Fraction of (phase, offset) cases with two peaks per FFT length, the peaks found, the truth."""

    separation_m: float
    n_ffts: tuple
    resolved_fraction: dict      # n_fft -> fraction in [0, 1]
    peak_ranges: dict            # n_fft -> list of peak-range lists, one per case
    target_ranges: np.ndarray    # (n_cases, 2) true ranges of the pair in each case

    @property
    def n_cases(self):
        """Number of simulated (phase, offset) cases."""
        return len(self.target_ranges)

    def peak_error_m(self, n_fft):
        """Largest distance [m] between a target and its peak over the cases resolved at n_fft."""
        errors = [max(abs(p[0] - t[0]), abs(p[-1] - t[1]))
                  for p, t in zip(self.peak_ranges[n_fft], self.target_ranges) if len(p) >= 2]
        return max(errors, default=float("nan"))


def two_target_experiment(config: RadarConfig, near_m=7.0, separation_m=1.0, n_ffts=(256, 512, 1024),
                          n_phases=12, n_offsets=10, window="hann", min_dip_db=0.0, transform=None):
    """Simulate two equal point targets at near_m + offset and near_m + offset + separation_m for
    every relative phase (n_phases over 2 pi) and offset (n_offsets over one resolution cell);
    count the cases with two peaks for each padded FFT length.

    transform(samples (n_cases, n), n_fft) -> profiles; default the float64 oracle
    ``oracle.range_profile`` with this window (pass a kernel plan's call to test the kernel)."""
    if transform is None:
        def transform(samples, n_fft):
            return oracle.range_profile(samples, n_fft, window=window)
    phases = np.linspace(0, 2 * np.pi, n_phases, endpoint=False)
    offsets = np.linspace(0, config.range_resolution_m, n_offsets, endpoint=False)
    shape = (n_offsets, n_phases, 2)
    ranges = np.empty(shape)
    ranges[..., 0] = near_m + offsets[:, None]
    ranges[..., 1] = ranges[..., 0] + separation_m
    phase = np.zeros(shape)
    phase[..., 1] = phases[None, :]
    samples = simulate_beams(config, np.ones(shape), ranges, phase).samples.reshape(-1, config.n_samples)
    lo, hi = near_m - 1.5, near_m + config.range_resolution_m + separation_m + 1.5
    fractions, peaks = {}, {}
    for n_fft in n_ffts:
        profiles = transform(samples, n_fft)
        axis = config.bin_ranges_m(n_fft)
        peaks[n_fft] = [count_peaks(p, axis, lo, hi, min_dip_db) for p in profiles]
        fractions[n_fft] = float(np.mean([len(p) >= 2 for p in peaks[n_fft]]))
    return ResolutionResult(separation_m, tuple(n_ffts), fractions, peaks, ranges.reshape(-1, 2))
