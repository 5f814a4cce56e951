"""A real-data map: polar scans of a spinning radar (the Navtech scans of the Oxford set by
default) fused with their ground-truth odometry, and numbers that say whether the geometry is
right.

Frames: x forward, y left, z up (REP-103); the reader (``io.polar_png``) converts the Oxford
frame. The world is the first scan's frame. Scan k's pose chains the odometry rows: pose_k =
pose_(k-1) @ T(k-1 <- k). The radar turns while the car moves 2 m per scan: each azimuth gets
its own pose, interpolated between scan poses at its time (``scan_poses.beam_poses``), and its
own encoder angle, folded into that pose (so one lattice of azimuths serves every scan).

Consistency: the map of scans 1-5 and the map of scans 6-11 see the same street; with the
right geometry they agree best. ``consistency`` gives the correlation of their log-odds over
the voxels both observed and the overlap (Jaccard) of their occupied voxels; ``run`` compares
the true poses with the second half moved by 1 m or turned by 2 deg, and with the azimuth
direction or the odometry reversed.
"""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from radarcl import logodds
from radarcl.config import sensors
from radarcl.errors import FrameFormatError
from radarcl.evaluation.evaluate import read_map, read_units
from radarcl.geometry import se2_pose
from radarcl.gridspec import GridSpec, lattice_box
from radarcl.io import polar_png, scan_poses
from radarcl.io import poses as pose_files
from radarcl.io.inputs import polar_source
from radarcl.io.trajectory import DEFAULT_MAX_SPEED_M_S
from radarcl.maps.map import KNOWN_LOOKS
from radarcl.pipeline import Detection, Mapping, new_grid
from radarcl.report import figures

OCCUPIED_NATS = 1.0                 # occupied in the consistency overlap: log-odds above this


def grid_for(poses, range_m, voxel_m, brick_z=1):
    """A one-voxel-thick grid in the radar's plane covering every pose plus ``range_m``, in
    planar bricks (8 x 8 x 1) unless ``brick_z`` says 8."""
    xy = poses[..., :2, 3].reshape(-1, 2)
    (x0, y0), size = lattice_box(xy.min(axis=0) - range_m, xy.max(axis=0) + range_m, voxel_m)
    nx, ny = (max(1, round(s / voxel_m)) for s in size)
    return GridSpec((x0, y0, -0.5 * voxel_m), voxel_m, (nx, ny, 1), brick_z)


def build_map(runtime, config, spec, scans, per_beam, progress=None):
    """Fuse ``scans`` taken at ``per_beam`` poses (n, n_az, 4, 4) into a new grid of ``spec``
    with ``config`` (a ``mapconfig.Resolved``); returns the grid."""
    grid = new_grid(runtime, config, spec)
    mapping = Mapping.from_config(runtime, config=config, grid=grid, per_beam_poses=True)
    source = polar_source(config.sensor, scans, per_beam, f"{len(scans)} polar scans")
    mapping.fuse_source(source, None if progress is None else lambda j, _: progress(j + 1, len(scans)))
    mapping.runtime.queue.finish()
    return mapping.grid


def consistency(a, b):
    """Agreement of two maps over the voxels both observed: Pearson correlation of their
    log-odds, Jaccard overlap of their occupied voxels, voxel count. ``a``, ``b``: int grids
    (logodds units; observed: not 0), or (grid, observed mask) pairs (a map with the knowledge
    channel reads its prior where it never looked: its knowledge says what it observed)."""
    (a, seen_a), (b, seen_b) = ((m if isinstance(m, tuple) else (m, m != 0)) for m in (a, b))
    both = seen_a & seen_b
    x, y = a[both].astype(np.float64), b[both].astype(np.float64)
    occ_a, occ_b = x > OCCUPIED_NATS * logodds.SCALE, y > OCCUPIED_NATS * logodds.SCALE
    union = np.count_nonzero(occ_a | occ_b)
    return {"correlation": float(np.corrcoef(x, y)[0, 1]) if len(x) > 1 else float("nan"),
            "occupied_jaccard": float(np.count_nonzero(occ_a & occ_b) / union) if union else float("nan"),
            "common_voxels": int(both.sum())}


def _moved(poses, dx=0.0, dy=0.0, dyaw=0.0):
    """Poses moved rigidly about the first one: translated by (dx, dy), turned by dyaw."""
    pivot = poses.reshape(-1, 4, 4)[0]
    delta = pivot @ se2_pose(dx, dy, dyaw) @ np.linalg.inv(pivot)
    return delta @ poses


def load(config, data_dir, poses=None, poses_format=None, clock_offset_s=None, report=None,
         max_speed_m_s=DEFAULT_MAX_SPEED_M_S):
    """(scans, scan poses, timestamps, odometry) of ``data_dir`` read as ``config``'s sensor: the
    scans of its layout (``radar/*.png`` for Oxford), the trajectory from ``poses`` or found
    beside them (``io.poses``); scan poses at each scan's first azimuth in the first scan's
    frame; odometry: the Oxford rows when that is what the poses are, else None."""
    data_dir = Path(data_dir)
    layout = polar_png.PolarLayout.of(config.sensor)
    if layout.scan_directory is None and (data_dir / "radar").is_dir() and not any(data_dir.glob("*.png")):
        data_dir = data_dir / "radar"                  # Oxford's recording layout, whatever the profile
    sequence = polar_png.read_sequence(data_dir, layout, odometry=False)
    found = (Path(poses), poses_format) if poses else pose_files.find_beside(sequence.directory)
    if found is None:
        raise FrameFormatError(f"{data_dir}: no poses beside the scans; give --poses FILE")
    if len(sequence.scans) < 4:
        raise FrameFormatError(f"{sequence.directory}: the half-map check needs at least 4 scans, found "
                               f"{len(sequence.scans)}")
    odometry = polar_png.load_odometry(found[0]) if (found[1] or pose_files.detect_format(found[0])) == "oxford" \
        else None
    track = pose_files.read_trajectory(found[0], found[1], clock_offset_s, report=report)
    track.check_motion(max_speed_m_s)
    starts = [s.start_ns for s in sequence.scans]
    track = track.relative_to(starts[0])
    stamps = sequence.stamps if odometry is not None else starts
    return sequence.scans, track.at(starts), stamps, odometry


def _inverted(poses):
    """Scan poses whose every step between scans is inverted (the odometry read backwards)."""
    out = [poses[0]]
    for a, b in zip(poses[:-1], poses[1:]):
        out.append(out[-1] @ np.linalg.inv(np.linalg.inv(a) @ b))
    return np.stack(out)


def run(runtime, config, data_dir, report=print, progress=None, poses=None, poses_format=None, clock_offset_s=None,
        max_speed_m_s=DEFAULT_MAX_SPEED_M_S):
    """Build the half maps under the true and the altered geometries; returns a dict of
    ``consistency`` results by case, the full-map grid (true poses, all scans), the scan
    poses and the pulse statistics of the detector."""
    scans, poses, stamps, odometry = load(config, data_dir, poses, poses_format, clock_offset_s, report, max_speed_m_s)
    if config.sensor.n_bins() is None:                      # a generic profile: bins from the data
        config = config.for_sensor(config.sensor.with_bins(scans[0].n_bins))
    n_az = config.sensor.n_azimuth
    split = len(scans) // 2
    range_max_m = config["interpret.range_max_m"]
    report(f"{len(scans)} scans, {n_az} azimuths x {scans[0].n_bins} bins; the car moves "
           f"{np.linalg.norm(poses[-1, :2, 3]):.1f} m and turns {math.degrees(math.atan2(poses[-1, 1, 0], poses[-1, 0, 0])):.1f} deg")
    true_beams = scan_poses.beam_poses(scans, poses, n_az)
    spec = grid_for(true_beams, range_max_m, config["grid.voxel_m"], sensors.brick_depth(config.sensor))

    def build(sc, pb):
        units, known = read_units(build_map(runtime, config, spec, sc, pb), config)
        return units if known is None else (units, known)

    half_a = build(scans[:split], true_beams[:split])
    # case -> (per-azimuth poses, whether the first half is rebuilt with them too)
    cases = {
        "true poses": (true_beams, False),
        "second half +1 m along x": (_moved(true_beams, dx=1.0), False),
        "second half +1 m along y": (_moved(true_beams, dy=1.0), False),
        "second half turned +2 deg": (_moved(true_beams, dyaw=math.radians(2)), False),
        "second half turned -2 deg": (_moved(true_beams, dyaw=math.radians(-2)), False),
        "one pose per scan (no motion within a scan)": (scan_poses.beam_poses(scans, poses, n_az, motion=False), False),
        "azimuths reversed": (scan_poses.beam_poses(scans, poses, n_az, azimuth_sign=-1.0), True),
        "odometry inverted": (scan_poses.beam_poses(scans, _inverted(poses), n_az), True),
    }
    results = {}
    for k, (name, (per_beam, both_halves)) in enumerate(cases.items()):
        a = build(scans[:split], per_beam[:split]) if both_halves else half_a
        b = build(scans[split:], per_beam[split:])
        r = results[name] = consistency(a, b)
        report(f"{name:45s} correlation {r['correlation']:.4f}  occupied overlap {r['occupied_jaccard']:.4f}  "
               f"({r['common_voxels']} voxels seen by both halves)")
        if progress is not None:
            progress(k + 1, len(cases) + 1, "geometries checked")
    full = build_map(runtime, config, spec, scans, true_beams)
    if progress is not None:
        progress(len(cases) + 1, len(cases) + 1, "geometries checked")
    return results, full, poses, pulse_statistics(runtime, config, scans)


def pulse_statistics(runtime, config, scans):
    """What the detector makes of the scans: detections and pulses per scan, pulse widths [m]
    (median, 90th percentile), the share of wide pulses; over the evidence interval."""
    spacing = config.sensor.bin_spacing_m()
    # the pulses are the CFAR's runs whatever the interpreter: counted with eq. 12's, which needs no tables
    det = Detection(runtime, (len(scans[0].timestamps_ns),), scans[0].n_bins, spacing, config.cfar_config(),
                    replace(config.interpret_config(), model="paper"))
    first, last = det.interpreter.first_bin, det.interpreter.last_bin
    detections, pulses, widths, wide = [], [], [], []
    for scan in scans:
        r = det(scan.power())
        detections.append(int(r.cfar.mask[:, first:last + 1].sum()))
        pulses.append(int(r.interpret.n_pulses.sum()))
        p = r.interpret.pulses
        kept = p[..., 0] >= 0
        widths.append(((p[..., 1] - p[..., 0] + 1) * spacing)[kept])
        wide.append(p[..., 3][kept])
    w, wd = np.concatenate(widths), np.concatenate(wide)
    return dict(detections_per_scan=float(np.mean(detections)), pulses_per_scan=float(np.mean(pulses)),
                pulse_width_median_m=float(np.median(w)) if len(w) else float("nan"),
                pulse_width_p90_m=float(np.percentile(w, 90)) if len(w) else float("nan"),
                wide_fraction=float(np.mean(wd)) if len(wd) else float("nan"),
                cfar=dict(kind=det.cfar.config.kind, guard_bins=det.cfar.config.guard,
                          train_bins=det.cfar.config.train, pfa=det.cfar.config.pfa),
                wide_bins=det.interpreter.wide_bins)


def plot_map(grid, poses, path, results=None, title="Navtech", config=None):
    """Top-down PNG of a one-layer map (``jobs.figures.plane_map_figure``) with the half-map
    check's result in the title; a map of the detection-statistics model as its reading says
    (``config``), grey where it knows nothing."""
    detstats = grid.has_knowledge
    text = f"{title}, {len(poses)} scans fused at {grid.spec.voxel_m} m " + \
        ("(detection statistics; grey: unknown)" if detstats else "(eq. 9)")
    if results:
        r = results["true poses"]["correlation"]
        worst = max(v["correlation"] for k, v in results.items() if k != "true poses")
        text += f"\nhalf-map correlation {r:.3f} with the true poses, at most {worst:.3f} altered"
    log_odds, knowledge = read_map(grid, config) if detstats else (grid.log_odds(), None)
    unknown = None if knowledge is None else knowledge[0] < KNOWN_LOOKS
    figures.save(figures.plane_map_figure(log_odds[0], grid.spec, poses, text, unknown=unknown), path, dpi=120)
