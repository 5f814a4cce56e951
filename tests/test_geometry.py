"""radarcl.geometry: the cylindrical-conical beam (Fig. 7c), its weight (Fig. 7b), lattices, poses."""

import math

import numpy as np
import pytest

from radarcl.config.stage_config import RadarConfig
from radarcl.errors import ConfigError
from radarcl.geometry import (
    BeamLattice,
    BeamModel,
    beam_half_width,
    check_pose,
    cone_start_range,
    interpolate_se2,
    pose_from_xyz_rpy,
    se2_pose,
    two_way_weight,
)

RADAR = RadarConfig()


def test_paper_beam_cylinder_gives_way_to_the_cone_near_the_far_field():
    m = BeamModel.from_radar(RADAR)
    assert m.half_aperture_az_m == pytest.approx(0.1135, abs=5e-4)        # eq. 1, 1 deg at 77 GHz
    start = float(cone_start_range(m.half_aperture_az_m, m.beamwidth_az_rad))
    assert start == pytest.approx(13.0, abs=0.1)                          # eq. 2 gives 13.3 m
    assert beam_half_width(1.0, m.half_aperture_az_m, m.beamwidth_az_rad) == pytest.approx(m.half_aperture_az_m)
    assert beam_half_width(60.0, m.half_aperture_az_m, m.beamwidth_az_rad) == pytest.approx(60 * math.tan(math.radians(0.5)))


def test_two_way_weight_is_one_on_axis_and_a_quarter_on_the_edge():
    assert two_way_weight(0.0) == 1.0 and two_way_weight(1.0) == 0.25
    m = BeamModel.from_radar(RADAR)
    edge = 30 * math.tan(m.beamwidth_az_rad / 2)
    assert m.rho2(30.0, edge, 0.0) == pytest.approx(1.0)
    assert m.rho2(-1.0, 0.0, 0.0) == np.inf
    assert BeamModel.from_radar(RADAR, gaussian=False).weight(0.7) == 1.0
    assert BeamModel.from_radar(RADAR, near_field=False).apertures == (0.0, 0.0)


def test_lattice_directions_azimuth_elevation_and_tilt():
    lat = BeamLattice.from_radar(RADAR, tilt_deg=-14.0)
    assert lat.n_beams == 256 and lat.batch == (64, 4)
    assert np.degrees(lat.azimuths[[0, -1]]).tolist() == pytest.approx([-31.5, 31.5])
    assert np.degrees(lat.elevations).tolist() == pytest.approx([-3, -1, 1, 3])
    R = lat.beam_rotations()
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3)) and np.allclose(np.linalg.det(R), 1)
    u = R[:, :, 0]
    el = np.degrees(np.arcsin(u[:, 2]))
    # beam (i, k) = index i * 4 + k: the lowest stacked beam of the centre column looks 17 deg down
    assert el[32 * 4 + 0] == pytest.approx(-17.0, abs=0.05) and el[32 * 4 + 3] == pytest.approx(-11.0, abs=0.05)
    # azimuth positive towards +y (left)
    assert u[63 * 4 + 1, 1] > 0 and u[0 * 4 + 1, 1] < 0
    flat = BeamLattice.from_radar(RADAR).beam_rotations()[:, :, 0]
    assert flat[32 * 4 + 2, 2] == pytest.approx(math.sin(math.radians(1)))


def test_spinning_lattice_wraps():
    lat = BeamLattice.spinning(400)
    assert lat.wraps and lat.batch == (400,)
    assert not BeamLattice.from_radar(RADAR).wraps
    with pytest.raises(ConfigError, match="more than a turn"):
        BeamLattice(401, 1, 0.0, 2 * math.pi / 400)
    with pytest.raises(ConfigError, match="elevations"):
        BeamLattice(4, 2, 0.0, 0.1, el0_rad=1.5, el_step_rad=0.1)


def test_poses_are_validated():
    T = pose_from_xyz_rpy(1, 2, 3, 0.1, 0.2, 0.3)
    assert np.allclose(check_pose(T)[:3, :3] @ T[:3, :3].T, np.eye(3))
    bad = T.copy()
    bad[:3, :3] *= 1.01
    with pytest.raises(ConfigError, match="not a proper rotation"):
        check_pose(bad)
    bad = T.copy()
    bad[3, 0] = 1
    with pytest.raises(ConfigError, match="last row"):
        check_pose(bad)


def test_se2_interpolation_reaches_both_ends():
    a, b = se2_pose(1.0, 2.0, 0.1), se2_pose(3.0, 2.5, 0.3)
    mid = interpolate_se2(a, b, [0.0, 1.0])
    assert np.allclose(mid[0], a) and np.allclose(mid[1], b)
