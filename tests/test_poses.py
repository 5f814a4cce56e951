"""One trajectory reader for every format (radarcl.io.poses): TUM (a round trip), KITTI, Oxford
odometry, radarcl's xyzrpy, RADIATE's GPS/IMU (its traps), Boreas' applanix CSV; trajectories that
run backwards, jump or do not cover the scans refused with the times named; per-azimuth poses of a
moving spinning radar; `fuse` without poses refused unless --still; `radarcl poses`."""

import math

import numpy as np
import pytest

from radarcl.cli import main
from radarcl.config import sensors
from radarcl.errors import FrameFormatError
from radarcl.geometry import pose_from_xyz_rpy
from radarcl.io import polar_png, radiate, scan_poses
from radarcl.io import poses as pose_files
from radarcl.io.trajectory import Trajectory, quaternions, rotations

T0 = 1_600_000_000_000_000_000


def _track(n=20, dt=0.1, speed=5.0, yaw_rate=0.2):
    """A car turning left at constant speed: (times_ns, poses)."""
    t = T0 + (np.arange(n) * dt * 1e9).astype(np.int64)
    yaw = yaw_rate * np.arange(n) * dt
    x = np.cumsum(np.r_[0, speed * dt * np.cos(yaw[:-1])])
    y = np.cumsum(np.r_[0, speed * dt * np.sin(yaw[:-1])])
    return t, np.stack([pose_from_xyz_rpy(a, b, 0.3 * k / n, 0.01 * k, -0.02 * k, c)
                        for k, (a, b, c) in enumerate(zip(x, y, yaw))])


def test_tum_round_trip(tmp_path):
    t, p = _track()
    path = tmp_path / "traj.tum"
    path.write_text(Trajectory(t, p, "test").tum_text())
    assert pose_files.detect_format(path) == "tum"
    back = pose_files.read_trajectory(path)
    assert np.array_equal(back.times_ns, t)
    assert np.abs(back.poses - p).max() < 1e-6                 # 6 decimals of metres, 9 of the quaternion
    q = quaternions(p[:, :3, :3])
    assert np.abs(rotations(q) - p[:, :3, :3]).max() < 1e-12 and np.allclose(np.linalg.norm(q, axis=1), 1)


def test_kitti_with_its_times(tmp_path):
    t, p = _track()
    path = tmp_path / "00.txt"
    np.savetxt(path, p[:, :3, :].reshape(len(p), 12))
    with pytest.raises(FrameFormatError, match="KITTI poses carry no times; put times.txt"):
        pose_files.read_trajectory(path)
    (tmp_path / "times.txt").write_text("".join(f"{v // 10**9}.{v % 10**9:09d}\n" for v in t))
    back = pose_files.read_trajectory(path)
    assert pose_files.detect_format(path) == "kitti" and np.abs(back.poses - p).max() < 1e-9
    assert np.array_equal(back.times_ns, t)                     # decimal seconds read exactly
    bad = p.copy()
    bad[3, :3, :3] *= 1.1
    np.savetxt(path, bad[:, :3, :].reshape(len(p), 12))
    with pytest.raises(FrameFormatError, match=r"00.txt:4: not a rotation"):
        pose_files.read_trajectory(path)


def test_xyzrpy_and_its_errors(tmp_path):
    path = tmp_path / "poses.csv"
    path.write_text("# t x y z roll pitch yaw\n1.0,0,0,0,0,0,0\n2.0,1,0,0,0,0,0.5\n")
    track = pose_files.read_trajectory(path)
    assert pose_files.detect_format(path) == "xyzrpy" and track.times_ns[1] == 2_000_000_000
    assert np.allclose(track.poses[1], pose_from_xyz_rpy(1, 0, 0, yaw=0.5))
    path.write_text("1.0,0,0,0,0,0,0\n0.5,1,0,0,0,0,0.5\n")
    with pytest.raises(FrameFormatError, match=r"poses.csv:2: the trajectory runs backwards: t = 0.500000 s follows "
                                               r"t = 1.000000 s on line 1"):
        pose_files.read_trajectory(path)
    path.write_text("1.0,0,0,0,0,0,0\n2.0,1,0,x,0,0,0.5\n")
    with pytest.raises(FrameFormatError, match=r"poses.csv:2: expected 7 finite numbers"):
        pose_files.read_trajectory(path, "xyzrpy")


def test_oxford_odometry_is_the_chain_of_its_rows(shared_data):
    """The trajectory of radar_odometry.csv at the scans' stamps is scan_poses' chain."""
    path = shared_data / "navtech_oxford" / "gt" / "radar_odometry.csv"
    track = pose_files.read_trajectory(path)
    stamps = [int(p.stem) for p in polar_png.scan_paths(shared_data / "navtech_oxford" / "radar")]
    chain = polar_png.scan_poses(stamps, polar_png.load_odometry(path))
    at = track.relative_to(stamps[0] * 1000).at(np.array(stamps) * 1000)
    assert np.abs(at - chain).max() < 1e-9


def test_trajectory_checks_name_the_times():
    t, p = _track(n=10)
    track = Trajectory(t, p, "car")
    with pytest.raises(FrameFormatError, match=r"car: the trajectory covers t = 1600000000.000 \.\. 1600000000.900 s "
                                               r"but the scans run 1600000001.200 \.\. 1600000001.200 s \(0.150 s "
                                               r"after its end\)"):
        track.at([T0 + 1_200_000_000])
    track.at([T0 + 1_000_000_000])                               # within 1.5 sample intervals: extended
    jumped = p.copy()
    jumped[6:, 0, 3] += 30.0
    with pytest.raises(FrameFormatError, match=r"car: the trajectory jumps 30.\d\d m in 0.100 s between t = "
                                               r"1600000000.500 and 1600000000.600 s \(30\d.\d m/s, over the bound of "
                                               r"70 m/s; --max-speed sets it\)"):
        Trajectory(t, jumped, "car").check_motion()
    Trajectory(t, jumped, "car").check_motion(max_speed_m_s=400.0)
    with pytest.raises(FrameFormatError, match=r"runs backwards: pose 3 at t = 1600000000.100 s follows pose 2"):
        Trajectory(t[[0, 1, 2, 1]], p[:4], "car")


def test_interpolation_per_azimuth_moves_the_radar_during_its_turn(tmp_path):
    """A radar driving straight at 10 m/s: each azimuth's pose sits where the car was at that
    azimuth's time (motion compensation), and slerp keeps rotations exact between samples."""
    t = T0 + np.arange(5, dtype=np.int64) * 500_000_000
    p = np.stack([pose_from_xyz_rpy(10.0 * k * 0.5, 0, 0, yaw=0.1 * k) for k in range(5)])
    track = Trajectory(t, p, "straight")
    mid = track.at([T0 + 250_000_000])[0]
    assert math.isclose(mid[0, 3], 2.5) and math.isclose(math.atan2(mid[1, 0], mid[0, 0]), 0.05, abs_tol=1e-12)
    img = np.zeros((40, 400), np.uint8)                             # RADIATE-like: 40 bins x 400 azimuths
    (tmp_path / "Navtech_Polar").mkdir()
    from PIL import Image

    Image.fromarray(img).save(tmp_path / "Navtech_Polar" / "000001.png")
    stamp = T0 + 1_000_000_000
    (tmp_path / "Navtech_Polar.txt").write_text(f"Frame: 000001 Time: {stamp // 10**9}.{stamp % 10**9:09d}\n")
    layout = polar_png.PolarLayout.of(sensors.load("radiate-cts350x"))
    scan = polar_png.read_sequence(tmp_path, layout, odometry=False).scans[0]
    per = scan_poses.beam_poses([scan], track, 400)[0]
    times = scan_poses.azimuth_times(scan)
    assert np.allclose(per[:, 0, 3], 10.0 * (times - T0) / 1e9, atol=1e-6)   # x = speed x time
    assert per[:, 0, 3].max() - per[:, 0, 3].min() > 2.4                      # 0.25 s of 10 m/s within one turn


def test_beam_poses_a_scan_at_a_time_are_the_stacked_ones(tmp_path):
    """BeamPoses (what a fuse holds: a scan's poses computed when its turn comes) gives, item by
    item, slice by slice, the float64 array beam_poses stacks, for a trajectory, a still radar,
    per-scan poses and no motion; the scans are read with progress reported to the last one."""
    from PIL import Image

    n = 7
    (tmp_path / "Navtech_Polar").mkdir()
    rng = np.random.default_rng(2)
    lines = []
    for k in range(n):
        Image.fromarray(rng.integers(0, 255, (40, 400), np.uint8)).save(tmp_path / "Navtech_Polar" / f"{k + 1:06d}.png")
        stamp = T0 + 250_000_000 * (k + 1)
        lines.append(f"Frame: {k + 1:06d} Time: {stamp // 10**9}.{stamp % 10**9:09d}")
    (tmp_path / "Navtech_Polar.txt").write_text("\n".join(lines) + "\n")
    heard = []
    layout = polar_png.PolarLayout.of(sensors.load("radiate-cts350x"))
    scans = polar_png.read_sequence(tmp_path, layout, odometry=False,
                                    progress=lambda done, total, what: heard.append((done, total))).scans
    assert heard[-1] == (n, n) and [d for d, _ in heard] == sorted({d for d, _ in heard})
    t, p = _track(n=12, dt=0.25)
    for track, motion in ((Trajectory(t, p, "car"), True), (Trajectory(t, p, "car"), False), (None, True),
                          (p[:n], True)):
        lazy = scan_poses.BeamPoses(scans, track, 400, motion=motion)
        whole = scan_poses.beam_poses(scans, track, 400, motion=motion)
        assert whole.shape == lazy.shape == (n, 400, 4, 4) and whole.dtype == np.float64
        assert all(np.array_equal(lazy[k], whole[k]) for k in range(-n, n))
        assert np.array_equal(np.asarray(lazy), whole) and np.array_equal(np.stack(list(lazy)), whole)
        part = lazy[2:6][1:]
        assert len(part) == 3 and np.array_equal(np.asarray(part), whole[3:6])
        for i in (0, 200, 399):                      # one azimuth's positions alone: the same floats
            assert np.array_equal(lazy.positions(i), whole[:, i, :3, 3])
        assert np.array_equal(part.positions(200), whole[3:6, 200, :3, 3])
    assert not np.array_equal(scan_poses.beam_poses(scans, Trajectory(t, p, "car"), 400)[:, 0],
                              scan_poses.beam_poses(scans, None, 400)[:, 0])     # the cases differ
    with pytest.raises(FrameFormatError, match="expected 401 azimuths, got 400"):
        scan_poses.BeamPoses(scans, None, 401)
    # refused when made, not when a scan's turn comes: a trajectory that ends before the last
    # scan, too few scan poses
    with pytest.raises(FrameFormatError, match=r"the trajectory covers .* after its end"):
        scan_poses.BeamPoses(scans, Trajectory(t[:4], p[:4], "short"), 400)
    with pytest.raises(FrameFormatError, match="7 scans need a pose each, got 6 poses"):
        scan_poses.BeamPoses(scans, p[:6], 400)


def test_radiate_gps_imu_traps(shared_data, tmp_path):
    """Duplicated frames dropped, frames 29-49 restamped +0.41 s, a corrupt line named by file and
    line, the heading along the track (not the quaternion), the clock offset given or found."""
    gps = radiate.read_gps_imu(shared_data / "radiate_fog")
    assert len(gps.frames) == 125 and np.all(np.diff(gps.times_ns) > 0)
    assert any("frames 000029-000049 are stamped 0.410 s early" in n for n in gps.notes)
    assert np.abs(np.diff(gps.times_ns) / 1e9 - 0.05).max() < 0.002
    track = radiate.gps_trajectory(gps, 65.8)
    heading = np.arctan2(track.poses[:, 1, 0], track.poses[:, 0, 0])
    course = np.arctan2(gps.velocity[:, 0], gps.velocity[:, 1])     # twist: x north, y east
    assert np.degrees(np.abs(np.angle(np.exp(1j * (heading - course))))).max() < 8
    assert track.times_ns[0] == gps.times_ns[0] - 65_800_000_000
    # a damaged copy: one line of one frame
    import shutil

    root = tmp_path / "seq"
    shutil.copytree(shared_data / "radiate_fog" / "GPS_IMU_Twist", root / "GPS_IMU_Twist")
    shutil.copy(shared_data / "radiate_fog" / "GPS_IMU_Twist.txt", root / "GPS_IMU_Twist.txt")
    frame = root / "GPS_IMU_Twist" / "000031.txt"
    lines = frame.read_text().splitlines()
    lines[16] = "-7.3,abc,-0.29"
    frame.write_text("\n".join(lines) + "\n")
    with pytest.raises(FrameFormatError, match=r"GPS_IMU_Twist/000031.txt:17: expected 3 comma-separated numbers"):
        pose_files.read_trajectory(root, clock_offset_s=65.8)
    assert pose_files.detect_format(root) == "radiate"


def test_radiate_clock_offset_is_found_from_the_lidar(shared_data):
    """The GPS/IMU clock runs ~65.7 s ahead of the radar's (not 64): found by matching the GPS
    speed to the lidar's own motion."""
    gps = radiate.read_gps_imu(shared_data / "radiate_fog")
    offset, (lo, hi), rms = radiate.estimate_clock_offset(gps, shared_data / "radiate_fog")
    assert 65.3 < offset < 66.2 and lo <= offset <= hi and not lo <= 64.0 <= hi and rms < 0.3


def test_boreas_applanix_poses(tmp_path):
    """pyboreas' rotation (roll(r) @ pitch(p) @ yaw(y)); the radar's frame (z down) turned into
    REP-103, so its x axis runs along the velocity and z points up; 16- and 19-digit times."""
    rows = ["GPSTime,easting,northing,altitude,vel_east,vel_north,vel_up,roll,pitch,heading,angvel_z,angvel_y,angvel_x"]
    heading = 0.174
    for k, stamp in enumerate(("1630597346061361", "1630597346311356000", "1630597346561361")):
        e, n = 623452.6 + 0.25 * k * 3.9, 4848823.37 + 0.25 * k * 0.68
        rows.append(f"{stamp},{e},{n},154.6,3.9,0.68,0.1,3.131,0.030,{heading},0,0,0")
    path = tmp_path / "radar_poses.csv"
    path.write_text("\n".join(rows) + "\n")
    assert pose_files.detect_format(path) == "boreas"
    track = pose_files.read_trajectory(path)
    assert list(track.times_ns) == [1630597346061361000, 1630597346311356000, 1630597346561361000]
    r = track.poses[1, :3, :3]
    velocity = np.array([3.9, 0.68, 0.0]) / np.hypot(3.9, 0.68)
    assert r[:, 0] @ velocity > 0.99 and r[2, 2] > 0.99 and np.isclose(np.linalg.det(r), 1)
    rows[2] = rows[2].replace("154.6", "high")
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(FrameFormatError, match=r"radar_poses.csv:3: expected 13 numbers"):
        pose_files.read_trajectory(path)


def test_fuse_without_poses_needs_still(tmp_path, capsys, shared_data):
    """A directory of scans with no poses is refused with the options named; --still fuses it."""
    one = tmp_path / "scans"
    one.mkdir()
    import shutil

    shutil.copy(shared_data / "navtech_oxford" / "radar" / "1547131046353776.png", one)
    out = tmp_path / "map.npz"
    args = ["fuse", str(one), "--sensor", "navtech-cts350x", "--voxel", "2.0", "--no-progress", "--no-report"]
    assert main(args + ["--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "no poses for these frames" in err and "--poses FILE" in err and "--still" in err and not out.exists()
    assert main(args + ["--out", str(out), "--still"]) == 0 and out.exists()


def test_the_poses_command_summarises_and_writes_tum(tmp_path, capsys, shared_data):
    src = shared_data / "navtech_oxford" / "gt" / "radar_odometry.csv"
    out = tmp_path / "odo.tum"
    assert main(["poses", str(src), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "2250 poses" in said and "length 3078.9 m" in said and f"wrote {out}" in said
    again = pose_files.read_trajectory(out)
    first = pose_files.read_trajectory(src)
    assert np.array_equal(again.times_ns, first.times_ns) and np.abs(again.poses - first.poses).max() < 1e-5
    assert main(["poses", str(src), "--out", str(out)]) == 2       # exists: kept
    assert "exists" in capsys.readouterr().err


def test_live_reads_every_pose_format(tmp_path):
    """`radarcl live --poses` goes through the same reader: a TUM file becomes the PoseSource's
    track, interpolated at a beam's time."""
    import argparse

    from radarcl.commands import live

    t, p = _track(n=5)
    path = tmp_path / "traj.tum"
    path.write_text(Trajectory(t, p, "test").tum_text())
    parser = argparse.ArgumentParser()
    live.add_pose_options(parser)
    source = live.pose_source(parser.parse_args(["--poses", str(path)]))
    times, poses = source.track
    assert np.array_equal(times, t) and np.abs(poses - p).max() < 1e-6


def test_evaluate_lidar_takes_any_configuration_file(tmp_path):
    """A model is a name or any configuration file (a new sensor model needs no code change)."""
    from radarcl.config import mapconfig
    from radarcl.errors import ConfigError
    from radarcl.jobs import evaluate_lidar as job

    path = tmp_path / "my-model.toml"
    mapconfig.resolve("radiate-cts350x", flags={"interpret.k_occ": 0.3}).save(path)
    (label, config), = job.resolve_models("radiate-cts350x", [str(path)])
    assert label == "my-model" and config["interpret.k_occ"] == 0.3
    with pytest.raises(ConfigError, match="neither a model"):
        job.resolve_models("radiate-cts350x", ["nosuch"])


def test_poses_between_samples_are_the_quaternions_of_their_two_poses_bit_for_bit():
    """``Trajectory.at`` takes each pose's quaternion once for the whole trajectory: the same
    floats as converting the two poses around each time, call by call."""
    from radarcl.io.trajectory import slerp

    rng = np.random.default_rng(4)
    n = 200
    yaw, pitch = np.cumsum(rng.normal(0, 0.2, n)), rng.normal(0, 0.05, n)
    poses = np.tile(np.eye(4), (n, 1, 1))
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 0, 2] = cy * cp, -sy, cy * sp
    poses[:, 1, 0], poses[:, 1, 1], poses[:, 1, 2] = sy * cp, cy, sy * sp
    poses[:, 2, 0], poses[:, 2, 2] = -sp, cp
    poses[:, :3, 3] = np.cumsum(rng.normal(0, 0.5, (n, 3)), axis=0)
    times = T0 + np.arange(n, dtype=np.int64) * 250_000_000
    track = Trajectory(times, poses)
    t = np.sort(rng.integers(times[0], times[-1], 4000))
    i = np.clip(np.searchsorted(times, t, side="right"), 1, n - 1)
    a = (t - times[i - 1]).astype(np.float64) / (times[i] - times[i - 1]).astype(np.float64)
    want = rotations(slerp(quaternions(poses[i - 1, :3, :3]), quaternions(poses[i, :3, :3]), a))
    got = track.at(t)
    assert np.array_equal(got[:, :3, :3], want) and not np.array_equal(got[0], got[-1])
