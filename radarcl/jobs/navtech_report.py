"""`radarcl navtech`: detection on a real Navtech scan, summarised and plotted (paper Fig. 10)."""

import time
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError
from radarcl.io import polar_png
from radarcl.pipeline import Detection, bin_model
from radarcl.report import figures


def report(runtime, config, scan_path, azimuth, out, say):
    """Run CFAR and the interpreter (``config``, a ``mapconfig.Resolved`` of a polar-PNG sensor:
    eq. 12, or the detection-statistics model, whose evidence is plotted for a voxel on the beam's
    axis) over every azimuth of the scan at ``scan_path``, and plot ``azimuth`` to ``out``."""
    sensor = config.sensor
    scan = polar_png.load_scan(scan_path, polar_png.PolarLayout.of(sensor))
    n_az = scan.shape[0]
    if n_az != sensor.n_azimuth or (sensor.n_bins() is not None and scan.n_bins != sensor.n_bins()):
        raise ConfigError(f"{scan_path}: {n_az} azimuths x {scan.n_bins} bins; sensor {sensor.name} has "
                          f"{sensor.n_azimuth} x {sensor.n_bins()}")
    if not 0 <= azimuth < n_az:
        raise ConfigError(f"--azimuth must be in [0, {n_az - 1}] for this scan, got {azimuth}")
    spacing = sensor.bin_spacing_m()
    cfar_config, interpret_config = config.cfar_config(), config.interpret_config()
    power = scan.power()
    if interpret_config.evidence_model.knowledge and sensor.n_bins() is None:     # its tables are per bin
        config = config.for_sensor(sensor.with_bins(scan.n_bins))
    model = bin_model(config, config["grid.voxel_m"])
    detection = Detection(runtime, (n_az,), scan.n_bins, spacing, cfar_config, interpret_config, bin_model=model)
    detection(power)                                     # build and warm up
    start = time.perf_counter()
    result = detection(power)
    elapsed = time.perf_counter() - start
    cfar, interp = result.cfar, result.interpret
    wide = interp.pulses[..., 3] == 1
    say(f"{Path(scan_path).name}: {n_az} azimuths x {scan.n_bins} bins of {spacing} m on {runtime.name}")
    say(f"  CFAR {cfar_config.kind.upper()} guard {cfar_config.guard} train {cfar_config.train} "
        f"pfa {cfar_config.pfa:g} (alpha {detection.cfar.alpha:.3f}); wide pulse >= "
        f"{interpret_config.wide_pulse_m:.2f} m ({detection.interpreter.wide_bins} bins)")
    say(f"  detections per azimuth {cfar.mask.sum(axis=1).mean():.1f}, pulses per azimuth "
        f"{interp.n_pulses.mean():.1f}, wide pulses {int(wide.sum())}, invalid azimuths "
        f"{int((~interp.valid).sum())}; {elapsed * 1e3:.1f} ms for the scan (upload, kernels, download)")
    a = azimuth
    rows = interp.pulses[a, :min(interp.n_pulses[a], interpret_config.max_pulses)]
    threshold = detection.cfar.alpha * cfar.noise[a]
    evidence_model = interpret_config.evidence_model
    evidence = evidence_model.on_axis(evidence_model.comparable(interp.evidence[a]))
    model_text = evidence_model.describe(interpret_config, config.model_params())
    title = (f"{sensor.name} {Path(scan_path).stem}, azimuth {a} ({np.degrees(scan.angles_rad[a]):.1f} deg): "
             f"{interp.n_pulses[a]} pulses, {cfar_config.kind.upper()}-CFAR Pfa {cfar_config.pfa:g}, {model_text}")
    fig = figures.interpretation_figure(np.arange(scan.n_bins) * spacing, power[a], threshold, rows,
                                      evidence, title,
                                      (detection.interpreter.first_bin, detection.interpreter.last_bin))
    out = Path(out)
    figures.save(fig, out, dpi=110)
    say(f"  azimuth {a}: {len(rows)} pulses "
        + ", ".join(f"{r[0] * spacing:.1f}-{r[1] * spacing:.1f} m{' (wide)' if r[3] else ''}" for r in rows[:8])
        + (" ..." if len(rows) > 8 else ""))
    say(f"  wrote {out}")
    return result
