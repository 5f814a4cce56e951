"""Part of the main job: the paper's radar looking at point targets (§4.1, Fig. 9).

Simulates one frame (64 x 4 beams) with a §4.1 pair 1.0 m apart in one beam and a few other
targets, runs the range-FFT kernel at n_fft = 256, 512, 1024, and writes:
  fig9.png       the pair's range profile without and with zero padding (paper Fig. 9)
  frame.png      range x azimuth image of each stacked beam (n_fft = 1024), dB of the strongest bin
  fig9.json      device, timings, detected peak ranges, the §4.1 sweep fractions
"""

import json
import logging
import time
from pathlib import Path

import numpy as np

from radarcl.config.stage_config import PAPER_RADAR
from radarcl.geometry import BeamLattice
from radarcl.report import figures
from radarcl.scene.fmcw import Adc, PointTarget, simulate_frame
from radarcl.scene.resolution import count_peaks, two_target_experiment
from radarcl.stages.range_fft import RangeFFT

log = logging.getLogger(__name__)

PAIR_BEAM = (32, 1)
# Whether a pair 1.0 m apart shows one peak without padding depends on its phase and sub-bin
# position (tests/test_paper_4_1.py: 24 % of cases). This pair, 0.2 m beyond the paper's 7 and
# 8 m with opposite phases, is one of them: one peak unpadded, two with padding, as in Fig. 9.
PAIR_M = (7.2, 8.2)
TARGETS = ([PointTarget(*PAIR_BEAM, PAIR_M[0], 0.25, 0.0), PointTarget(*PAIR_BEAM, PAIR_M[1], 0.25, np.pi)]
           + [PointTarget(az, 2, 20.0, 0.05) for az in range(8, 20)]          # a fence
           + [PointTarget(45, 1, 12.0, 0.4), PointTarget(50, 0, 35.0, 0.15),   # a drum, a tree
              PointTarget(50, 1, 35.3, 0.1), PointTarget(5, 3, 55.0, 0.3)])    # a far rock
N_FFTS = (256, 512, 1024)


def run(runtime, out_dir, seed=0, report=log.info):
    """Make the Fig. 9 plots; ``report`` receives progress lines. Returns the summary dict."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cfg = PAPER_RADAR
    report(f"device: {runtime.name}")
    report(f"radar: {cfg.carrier_hz / 1e9:g} GHz, {cfg.bandwidth_hz / 1e6:g} MHz in {cfg.sweep_time_s * 1e6:g} us, "
           f"{cfg.n_samples} samples at {cfg.sample_rate_hz / 1e6:g} MHz; resolution {cfg.range_resolution_m:.3f} m "
           f"(eq. 7), far field {cfg.far_field_m:.1f} m (eq. 2), beat {cfg.max_beat_frequency_hz / 1e3:.1f} kHz "
           f"at {cfg.range_max_m:g} m (eq. 10)")
    frame = simulate_frame(cfg, TARGETS, noise_rms=2e-3, adc=Adc(bits=12), seed=seed)
    report(f"frame: {frame.samples.shape} {frame.samples.dtype}, {len(TARGETS)} point targets, "
           f"{frame.n_clipped} clipped samples")

    profiles, timings = {}, {}
    for n_fft in N_FFTS:
        plan = RangeFFT(runtime, frame.samples.shape[:2], cfg.n_samples, n_fft)
        plan(frame.samples)                                   # warm-up: first launch builds caches
        start = time.perf_counter()
        result = plan(frame.samples)
        timings[n_fft] = (time.perf_counter() - start) * 1e3
        profiles[n_fft] = result.profiles
        report(f"range FFT n_fft={n_fft:5d}: {timings[n_fft]:.2f} ms for the frame, "
               f"{result.n_invalid} invalid / {result.n_clipped} clipped beams")

    peaks = {n: count_peaks(profiles[n][PAIR_BEAM], cfg.bin_ranges_m(n), 5.5, 9.5) for n in N_FFTS}
    for n in N_FFTS:
        report(f"pair at {PAIR_M[0]} and {PAIR_M[1]} m, n_fft={n:5d}: peaks at {', '.join(f'{p:.2f}' for p in peaks[n])} m")
    sweep = {sep: two_target_experiment(cfg, 7.0, sep).resolved_fraction for sep in (1.0, 0.5)}
    for sep, fractions in sweep.items():
        report(f"§4.1 sweep, {sep} m apart, fraction of 120 phase/offset cases resolved: "
               + ", ".join(f"n_fft {n}: {f:.2f}" for n, f in fractions.items()))

    labels = [f"n_fft = {n}: " + ("no padding" if n == cfg.n_samples else f"{n - cfg.n_samples} zeros") for n in N_FFTS]
    figures.save(figures.fig9_figure([cfg.bin_ranges_m(n) for n in N_FFTS], [profiles[n][PAIR_BEAM] for n in N_FFTS],
                                 PAIR_M, labels), out_dir / "fig9.png")
    db = 20 * np.log10(np.maximum(profiles[1024], 1e-3))
    azimuths = np.degrees(BeamLattice.from_radar(cfg).azimuths)
    figures.save(figures.frame_figure(db, azimuths, cfg.bin_ranges_m(1024)[-1], 1024), out_dir / "frame.png", dpi=90)

    summary = dict(device=runtime.name, frame_shape=list(frame.samples.shape),
                   range_fft_ms={str(n): t for n, t in timings.items()},
                   pair_peaks_m={str(n): v for n, v in peaks.items()},
                   resolved_fraction={str(s): {str(n): f for n, f in fr.items()} for s, fr in sweep.items()})
    (out_dir / "fig9.json").write_text(json.dumps(summary, indent=2))
    report(f"wrote {out_dir / 'fig9.png'}, {out_dir / 'frame.png'}, {out_dir / 'fig9.json'}")
    return summary
