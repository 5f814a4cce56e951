"""`radarcl navtech`: detection on a real Navtech scan, summarised and plotted (paper Fig. 10)."""

import time
from pathlib import Path

import numpy as np

from radarcl.jobs import plots
from radarcl.config import CfarConfig, InterpretConfig
from radarcl.errors import ConfigError
from radarcl.io import navtech
from radarcl.pipeline import Detection

MAX_PULSES = 128      # pulse rows kept per azimuth: a 163 m profile holds dozens


def report(runtime, args, say):
    """Run CFAR + eq. 12 over every azimuth of ``args.scan`` and plot ``args.azimuth``."""
    scan = navtech.load_scan(args.scan)
    n_az = scan.levels.shape[0]
    if not 0 <= args.azimuth < n_az:
        raise ConfigError(f"--azimuth must be in [0, {n_az - 1}] for this scan, got {args.azimuth}")
    spacing = scan.bin_spacing_m
    range_max = args.range_max if args.range_max is not None else (scan.n_bins - 1) * spacing
    cfar_config = CfarConfig(kind=args.kind, guard=args.guard, train=args.train, pfa=args.pfa)
    options = dict(range_min_m=args.range_min, range_max_m=range_max, max_pulses=MAX_PULSES)
    if args.wide_m is not None:
        options["wide_pulse_m"] = args.wide_m
    interpret_config = InterpretConfig(**options)
    power = scan.power()
    detection = Detection(runtime, (n_az,), scan.n_bins, spacing, cfar_config, interpret_config)
    detection(power)                                     # build and warm up
    start = time.perf_counter()
    result = detection(power)
    elapsed = time.perf_counter() - start
    cfar, interp = result.cfar, result.interpret
    wide = interp.pulses[..., 3] == 1
    say(f"{Path(args.scan).name}: {n_az} azimuths x {scan.n_bins} bins of {spacing} m on {runtime.name}")
    say(f"  CFAR {cfar_config.kind.upper()} guard {cfar_config.guard} train {cfar_config.train} "
        f"pfa {cfar_config.pfa:g} (alpha {detection.cfar.alpha:.3f}); wide pulse >= "
        f"{interpret_config.wide_pulse_m:.2f} m ({detection.interpreter.wide_bins} bins)")
    say(f"  detections per azimuth {cfar.mask.sum(axis=1).mean():.1f}, pulses per azimuth "
        f"{interp.n_pulses.mean():.1f}, wide pulses {int(wide.sum())}, invalid azimuths "
        f"{int((~interp.valid).sum())}; {elapsed * 1e3:.1f} ms for the scan (upload, kernels, download)")
    a = args.azimuth
    rows = interp.pulses[a, :min(interp.n_pulses[a], interpret_config.max_pulses)]
    threshold = detection.cfar.alpha * cfar.noise[a]
    title = (f"Navtech {Path(args.scan).stem}, azimuth {a} ({np.degrees(scan.angles_rad[a]):.1f} deg): "
             f"{interp.n_pulses[a]} pulses, {cfar_config.kind.upper()}-CFAR Pfa {cfar_config.pfa:g}, eq. 12 with k_occ "
             f"{interpret_config.k_occ:g}, E_h {interpret_config.e_high:g}, E_l {interpret_config.e_low:g}")
    fig = plots.interpretation_figure(np.arange(scan.n_bins) * spacing, power[a], threshold, rows,
                                      interp.evidence[a], title,
                                      (detection.interpreter.first_bin, detection.interpreter.last_bin))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    say(f"  azimuth {a}: {len(rows)} pulses "
        + ", ".join(f"{r[0] * spacing:.1f}-{r[1] * spacing:.1f} m{' (wide)' if r[3] else ''}" for r in rows[:8])
        + (" ..." if len(rows) > 8 else ""))
    say(f"  wrote {out}")
    return result
