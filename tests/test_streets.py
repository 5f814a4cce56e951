"""The spinning radar with truth (radarcl/scene/streets.py): seeded streets with facades and gaps,
per-azimuth poses on a moving vehicle, echoes at the right range from each beam's own origin, and
the visibility truth's beam and bin of a voxel from that origin."""

import math

import numpy as np

from radarcl.config.stage_config import RadarConfig
from radarcl.evaluation import visibility as vis
from radarcl.geometry import BeamLattice
from radarcl.gridspec import GridSpec
from radarcl.scene import streets
from radarcl.scene.outdoor import METAL, Scene, SceneObject
from radarcl.scene.shapes import Box, Ground

SMALL = RadarConfig(n_azimuth=40, n_elevation=1, azimuth_step_deg=9.0, beamwidth_az_deg=6.0, beamwidth_el_deg=8.0)
LATTICE = BeamLattice.spinning(40)


def test_streets_are_seeded_with_facades_gaps_cars_and_a_disjoint_split():
    a, da = streets.generate(401)
    b, db = streets.generate(401)
    assert a == b and da == db and not set(streets.TRAIN_SEEDS) & set(streets.HELD_OUT_SEEDS)
    kinds = {name.split(" ")[0] for name in da["objects"]}
    assert {"building", "car", "kerb"} <= kinds and kinds & {"post", "tree"}
    left = sorted((o.shape.lo_m[0], o.shape.hi_m[0]) for o in a.objects if o.name.startswith("building +1"))
    assert len(left) >= 3 and all(nxt[0] - cur[1] >= 2.0 for cur, nxt in zip(left, left[1:]))   # gaps
    assert abs(a.objects[0].shape.height_m + da["sensor_height_m"]) < 0.01 and a.sensor_m == (0.0, 0.0, 0.0)


def test_each_azimuth_has_its_own_pose_and_sees_a_wall_at_its_range():
    """A wall 10 m to the left of a vehicle driving along x: the beam pointing at it (azimuth 90
    deg) puts its strongest echo at the wall's range from that beam's own origin."""
    scene = Scene((SceneObject("ground", Ground(-2.0), METAL),
                   SceneObject("wall", Box((-20.0, 10.013, -2.5), (40.0, 10.3, 3.0)), METAL)), (), (0.0, 0.0, 0.0))
    poses = streets.beam_poses(LATTICE, 2)
    assert poses.shape == (2, 40, 4, 4)
    step = streets.SPEED_M_S / streets.TURN_HZ
    assert np.allclose(poses[1, 0, :3, 3], [step, 0, 0]) and np.allclose(poses[0, 20, :3, 3], [step / 2, 0, 0])
    obs = streets.observe(scene, SMALL, LATTICE, 1, seed=3, noise_rms=0.0, adc=None)
    assert obs.samples.shape == (1, 40, 1, SMALL.n_samples) and obs.poses.shape == (1, 40, 4, 4)
    from radarcl import oracle

    power = oracle.range_profile(obs.samples[0, :, 0], 1024, output="power")
    beam = 10                                            # azimuth 90 deg: +y
    peak = int(np.argmax(power[beam, 8:])) + 8
    assert abs(peak * SMALL.bin_spacing_m(1024) - 10.013) < 0.3


def test_the_truth_takes_each_voxels_range_from_its_beams_own_origin():
    spec = GridSpec((-1.0, -1.0, -0.1), 0.2, (100, 100, 1))
    voxel = spec.world_to_index(np.array([[4.1, 10.0, 0.0]]))   # at +y from the turn's middle
    poses = np.stack([np.eye(4)] * 40)
    poses[:, 0, 3] = np.linspace(0.0, 8.0, 40)            # the vehicle moved 8 m during the turn
    (beam, b), = vis.beam_bins(spec, voxel, poses[None], LATTICE, math.radians(3.0), math.radians(4.0), 0.1, 200)
    assert beam[0] == 10                                   # +y
    want = np.linalg.norm(spec.index_to_world(voxel[0]) - poses[10, :3, 3]) / 0.1
    assert b[0] == int(np.rint(want))
    assert abs(want - np.linalg.norm(spec.index_to_world(voxel[0]) - poses[20, :3, 3]) / 0.1) > 1   # it matters
