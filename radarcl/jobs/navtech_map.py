"""A real-data map: the Navtech scans fused with their ground-truth odometry, and numbers that
say whether the geometry is right.

Frames: the Oxford radar frame (x forward, y right, z down); azimuths and yaw both turn about z
from x towards y, so both are rotations about the lattice's z axis. The world is the first
scan's frame. Scan k's pose chains the odometry rows: pose_k = pose_(k-1) @ T(k-1 <- k).
The radar turns while the car moves 2 m per scan: each azimuth gets its own pose, interpolated
between scan poses at its time (``beam_poses``), and its own encoder angle, folded into that
pose (so one lattice of 400 azimuths serves every scan).

Consistency: the map of scans 1-5 and the map of scans 6-11 see the same street; with the
right geometry they agree best. ``consistency`` gives the correlation of their log-odds over
the voxels both observed and the overlap (Jaccard) of their occupied voxels; ``run`` compares
the true poses with the second half moved by 1 m or turned by 2 deg, and with the azimuth
direction or the odometry reversed.
"""

import math
from pathlib import Path

import numpy as np

from radarcl.config import CfarConfig, InterpretConfig
from radarcl.errors import ConfigError
from radarcl.geometry import BeamLattice, BeamModel, half_aperture, interpolate_se2, se2_pose
from radarcl.grid import EvidenceGrid, GridSpec
from radarcl.io import navtech
from radarcl.pipeline import Mapping

N_AZ = 400
CARRIER_HZ = 76.5e9                 # CTS350-X, 76-77 GHz
BEAM_AZ_DEG = 1.8                   # about 1.8 deg in azimuth (data README)
# The elevation fan is wide; the map is one voxel thick in the radar's plane, where any fan
# width lets the beam through, so this value only has to be wide.
BEAM_EL_DEG = 40.0
OCCUPIED_NATS = 1.0                 # occupied in the consistency overlap: log-odds above this


def beam_model():
    """The Navtech beam: 1.8 deg in azimuth, a wide fan in elevation, near-field cylinder and
    Gaussian weight on."""
    lam = 299_792_458.0 / CARRIER_HZ
    az, el = math.radians(BEAM_AZ_DEG), math.radians(BEAM_EL_DEG)
    return BeamModel(az, el, float(half_aperture(lam, az)), float(half_aperture(lam, el)))


def scan_poses(stamps, odometry, invert=False):
    """(n_scans, 4, 4) poses of scans with radar timestamps ``stamps`` in the first one's frame.
    invert=True reads each odometry row the other way round (a convention check)."""
    poses = [np.eye(4)]
    for prev, cur in zip(stamps[:-1], stamps[1:]):
        try:
            x, y, yaw = odometry[(cur, prev)]
        except KeyError:
            raise ConfigError(f"no odometry row from scan {cur} to scan {prev}") from None
        step = se2_pose(x, y, yaw)
        poses.append(poses[-1] @ (np.linalg.inv(step) if invert else step))
    return np.stack(poses)


def beam_poses(scans, poses, azimuth_sign=1.0, motion=True):
    """(n_scans, N_AZ, 4, 4) per-azimuth poses: the scan poses interpolated at each azimuth's
    time (a line fitted to its bursty timestamps), times the rotation of its encoder angle
    (times ``azimuth_sign``) less the lattice's i x 2 pi / N_AZ. motion=False puts every
    azimuth at its scan's pose (no motion within a scan; a consistency check)."""
    stamps = np.array([s.timestamps_us[0] for s in scans], np.float64)
    out = []
    for k, scan in enumerate(scans):
        i = np.arange(len(scan.timestamps_us))
        t = np.polyval(np.polyfit(i, scan.timestamps_us.astype(np.float64), 1), i)
        if not motion:
            a = b = poses[k]
            frac = np.zeros(len(i))
        elif k + 1 < len(scans):
            a, b, t0, t1 = poses[k], poses[k + 1], stamps[k], stamps[k + 1]
            frac = (t - t0) / (t1 - t0)
        else:                                   # the last scan: extend the motion into it
            a, b, t0, t1 = poses[k - 1], poses[k], stamps[k - 1], stamps[k]
            frac = 1 + (t - stamps[k]) / (t1 - t0)
        moved = interpolate_se2(a, b, frac)
        turn = azimuth_sign * scan.angles_rad - i * (2 * math.pi / N_AZ)
        out.append(moved @ np.stack([se2_pose(0.0, 0.0, float(r)) for r in turn]))
    return np.stack(out)


def grid_for(poses, range_m, voxel_m):
    """A one-voxel-thick grid in the radar's plane covering every pose plus ``range_m``."""
    xy = poses[..., :2, 3].reshape(-1, 2)
    lo, hi = xy.min(axis=0) - range_m, xy.max(axis=0) + range_m
    nx, ny = (int(math.ceil(v)) for v in (hi - lo) / voxel_m)
    return GridSpec((lo[0], lo[1], -0.5 * voxel_m), voxel_m, (nx, ny, 1))


def build_map(runtime, spec, scans, per_beam, range_max_m):
    """Fuse ``scans`` taken at ``per_beam`` poses (n, N_AZ, 4, 4) into a new grid; returns it."""
    grid = EvidenceGrid(runtime, spec)
    first = scans[0]
    mapping = Mapping(runtime, grid, BeamLattice.spinning(N_AZ), beam_model(), n_bins=first.n_bins,
                      bin_spacing_m=first.bin_spacing_m, cfar_config=CfarConfig(),
                      interpret_config=InterpretConfig(range_min_m=2.0, range_max_m=range_max_m),
                      per_beam_poses=True)
    for scan, poses in zip(scans, per_beam):
        if scan.levels.shape[0] != N_AZ:
            raise ConfigError(f"{scan.path}: expected {N_AZ} azimuths, got {scan.levels.shape[0]}")
        flags = np.where(scan.valid, 0, 8).astype(np.uint8)     # FLAG_SILENT: no evidence
        mapping.fuse(scan.power(), poses, flags=flags)
    mapping.runtime.queue.finish()
    return grid


def consistency(a, b):
    """Agreement of two int grids (logodds units) over the voxels both observed: Pearson
    correlation of their log-odds, Jaccard overlap of their occupied voxels, voxel count."""
    both = (a != 0) & (b != 0)
    x, y = a[both].astype(np.float64), b[both].astype(np.float64)
    occ_a, occ_b = x > OCCUPIED_NATS * 1024, y > OCCUPIED_NATS * 1024
    union = np.count_nonzero(occ_a | occ_b)
    return {"correlation": float(np.corrcoef(x, y)[0, 1]) if len(x) > 1 else float("nan"),
            "occupied_jaccard": float(np.count_nonzero(occ_a & occ_b) / union) if union else float("nan"),
            "common_voxels": int(both.sum())}


def _moved(poses, dx=0.0, dy=0.0, dyaw=0.0):
    """Poses moved rigidly about the first one: translated by (dx, dy), turned by dyaw."""
    pivot = poses.reshape(-1, 4, 4)[0]
    delta = pivot @ se2_pose(dx, dy, dyaw) @ np.linalg.inv(pivot)
    return delta @ poses


def run(runtime, data_dir, voxel_m=0.3, range_max_m=80.0, split=5, report=print):
    """Build the half maps under the true and the altered geometries; returns a dict of
    ``consistency`` results by case, the full-map grid (true poses, all scans) and the scan poses."""
    data_dir = Path(data_dir)
    scans = [navtech.load_scan(p) for p in navtech.scan_paths(data_dir / "radar")]
    odometry = navtech.load_odometry(data_dir / "gt" / "radar_odometry.csv")
    stamps = [int(s.path.stem) for s in scans]
    poses = scan_poses(stamps, odometry)
    report(f"{len(scans)} scans, {N_AZ} azimuths x {scans[0].n_bins} bins; the car moves "
           f"{np.linalg.norm(poses[-1, :2, 3]):.1f} m and turns {math.degrees(math.atan2(poses[-1, 1, 0], poses[-1, 0, 0])):.1f} deg")
    true_beams = beam_poses(scans, poses)
    spec = grid_for(true_beams, range_max_m, voxel_m)
    half_a = build_map(runtime, spec, scans[:split], true_beams[:split], range_max_m).snapshot()
    # case -> (per-azimuth poses, whether the first half is rebuilt with them too)
    cases = {
        "true poses": (true_beams, False),
        "second half +1 m along x": (_moved(true_beams, dx=1.0), False),
        "second half +1 m along y": (_moved(true_beams, dy=1.0), False),
        "second half turned +2 deg": (_moved(true_beams, dyaw=math.radians(2)), False),
        "second half turned -2 deg": (_moved(true_beams, dyaw=math.radians(-2)), False),
        "one pose per scan (no motion within a scan)": (beam_poses(scans, poses, motion=False), False),
        "azimuths counter-clockwise": (beam_poses(scans, poses, azimuth_sign=-1.0), True),
        "odometry inverted": (beam_poses(scans, scan_poses(stamps, odometry, invert=True)), True),
    }
    results = {}
    for name, (per_beam, both_halves) in cases.items():
        a = build_map(runtime, spec, scans[:split], per_beam[:split], range_max_m).snapshot() if both_halves else half_a
        b = build_map(runtime, spec, scans[split:], per_beam[split:], range_max_m).snapshot()
        r = results[name] = consistency(a, b)
        report(f"{name:45s} correlation {r['correlation']:.4f}  occupied overlap {r['occupied_jaccard']:.4f}  "
               f"({r['common_voxels']} voxels seen by both halves)")
    full = build_map(runtime, spec, scans, true_beams, range_max_m)
    return results, full, poses


def plot_map(grid, poses, path, results=None):
    """Top-down PNG of a one-layer map: log-odds from -3 (empty, blue) to +3 nat (occupied,
    red), unseen white, x (forward) up and y (right) to the right, the scan poses in black."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spec = grid.spec
    nats = grid.log_odds()[0]                                  # (ny, nx)
    shown = np.ma.masked_equal(nats, 0.0).T                     # rows = x, columns = y
    x0, y0, _ = spec.origin_m
    nx, ny, _ = spec.shape
    extent = (y0, y0 + ny * spec.voxel_m, x0, x0 + nx * spec.voxel_m)
    fig, ax = plt.subplots(figsize=(8, 8 * nx / ny), dpi=120)
    image = ax.imshow(shown, origin="lower", extent=extent, cmap="coolwarm", vmin=-3, vmax=3,
                      interpolation="nearest")
    ax.plot(poses[:, 1, 3], poses[:, 0, 3], "k.-", ms=4, label="scan poses")
    ax.set_xlabel("y, right [m]")
    ax.set_ylabel("x, forward [m]")
    title = f"Navtech, {len(poses)} scans fused at {spec.voxel_m} m (eq. 9)"
    if results:
        r = results["true poses"]["correlation"]
        worst = max(v["correlation"] for k, v in results.items() if k != "true poses")
        title += f"\nhalf-map correlation {r:.3f} with the true poses, at most {worst:.3f} altered"
    ax.set_title(title, fontsize=10)
    fig.colorbar(image, ax=ax, label="log-odds [nat]", shrink=0.8)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
