"""Visibility truth (radarcl/evaluation/visibility.py) on small hand-made scenes: a box in front
of a wall shadows the wall's part behind it; a plate whose echo stays below the noise + 10 dB
is WEAK, a bright one DETECTABLE; the CFAR level of 10 dB is derived, not assumed."""

import math

import numpy as np
import pytest

from radarcl.config.stage_config import PAPER_RADAR
from radarcl.evaluation import visibility as vis
from radarcl.geometry import BeamLattice
from radarcl.gridspec import GridSpec
from radarcl.scene.outdoor import INTERIOR, OCCUPIED, Material, Scene, SceneObject
from radarcl.scene.shapes import Box

SENSOR = (0.0, 0.0, 1.0)
SPEC = GridSpec((0.0, -4.0, -1.0), 0.2, (60, 40, 25))          # x 0..12, y -4..4, z -1..4
MATTE = Material("matte", -10.0)


def voxel_at(x, y, z):
    i = SPEC.world_to_index(np.array([[x, y, z]]))[0]
    return int(i[2]), int(i[1]), int(i[0])


def box_and_wall():
    # faces kept off the 0.2 m lattice (5.03, 10.07, ...): a face on a voxel boundary is
    # decided by FACE_EPS, which is not what this test is about
    box = SceneObject("box", Box((5.03, -0.61, 0.43), (5.87, 0.59, 1.61)), MATTE)
    wall = SceneObject("wall", Box((10.07, -3.03, -0.5), (10.53, 3.03, 3.03)), MATTE)
    return Scene((box, wall), (), SENSOR)


def test_a_box_in_front_of_a_wall_shadows_the_wall_behind_it():
    scene = box_and_wall()
    pose = np.eye(4)
    pose[:3, 3] = SENSOR
    t = vis.visibility_truth(scene, SPEC, np.ones(SPEC.array_shape, bool), pose[None])
    c = t.classes
    assert c[voxel_at(10.1, 0.0, 1.0)] == vis.SHADOWED              # the wall's face straight behind the box
    assert c[voxel_at(10.1, 2.5, 1.0)] == vis.DETECTABLE            # the wall's face beside it
    assert c[voxel_at(5.1, 0.0, 1.0)] == vis.DETECTABLE             # the box's front face
    assert c[voxel_at(5.9, 0.0, 1.1)] == vis.SHADOWED               # the box's back face
    assert c[voxel_at(5.5, 0.0, 1.0)] == vis.INSIDE_SOLID               # inside the box
    assert c[voxel_at(8.1, 0.0, 1.1)] == vis.SHADOWED               # air behind the box
    assert c[voxel_at(8.1, 2.5, 1.1)] == vis.FREE_VISIBLE           # air beside that
    assert c[voxel_at(3.1, 0.0, 1.1)] == vis.FREE_VISIBLE           # air in front of the box
    assert c[voxel_at(11.5, 0.1, 1.1)] == vis.SHADOWED              # air behind the wall
    # the classes partition the labels: every surface voxel is DETECTABLE or SHADOWED here (no
    # noise model given), every INTERIOR label is INTERIOR
    occ = t.labels == OCCUPIED
    assert set(np.unique(c[occ])) == {vis.DETECTABLE, vis.SHADOWED}
    assert (c[t.labels == INTERIOR] == vis.INSIDE_SOLID).all()
    # the shadow of the box on the wall's front face (the layer x 10.0-10.2): the rays from the
    # sensor through the box's outline, scaled by 10.07 / 5.03, within a voxel or two
    front = np.argwhere((c[:, :, 50] == vis.SHADOWED) & occ[:, :, 50])       # (z, y)
    y = SPEC.origin_m[1] + (front[:, 1] + 0.5) * SPEC.voxel_m
    z = SPEC.origin_m[2] + (front[:, 0] + 0.5) * SPEC.voxel_m
    scale = 10.07 / 5.03
    assert len(front) and y.min() > -0.61 * scale - 0.4 and y.max() < 0.59 * scale + 0.4
    assert z.min() > 1 + (0.43 - 1) * scale - 0.4 and z.max() < 1 + (1.61 - 1) * scale + 0.4


def test_a_voxel_seen_from_any_sensor_position_is_visible():
    scene = box_and_wall()
    poses = np.stack([np.eye(4)] * 2)
    poses[0, :3, 3] = SENSOR
    poses[1, :3, 3] = (0.0, 3.0, 1.0)                              # a second stand, off to the side
    t = vis.visibility_truth(scene, SPEC, np.ones(SPEC.array_shape, bool), poses)
    assert t.classes[voxel_at(10.1, 0.0, 1.0)] == vis.DETECTABLE   # seen past the box from the second


def test_ten_db_is_where_the_papers_cfar_detects_half_the_time():
    from radarcl.cfar_theory import detection_probability_swerling1, threshold_factor

    snr_db = vis.detectable_snr_db(1e-3, 32, 0.5)
    assert snr_db == pytest.approx(10.0, abs=0.05)
    factor = threshold_factor("ca", 1e-3, 32)
    assert detection_probability_swerling1("ca", factor, 32, 10 ** (snr_db / 10)) == pytest.approx(0.5, abs=1e-9)


def test_noise_power_per_bin_matches_the_oracles_profiles():
    from radarcl import oracle

    x = np.random.default_rng(1).standard_normal((4000, 256)) * 1e-3
    measured = oracle.range_profile(x, 1024, output="power")[:, 8:-8].mean()
    assert measured == pytest.approx(vis.noise_power_per_bin(1e-3, 256), rel=0.02)


def test_a_plate_below_the_noise_is_weak_a_bright_one_detectable():
    from radarcl import oracle
    from radarcl.scene.observe import NOISE_RMS, observe

    dim, bright = Material("absorber", -60.0), Material("metal", 0.0)
    plates = (SceneObject("dim plate", Box((20.03, -3.01, 0.57), (20.13, -1.41, 1.43)), dim),
              SceneObject("bright plate", Box((20.03, 1.41, 0.57), (20.13, 3.01, 1.43)), bright))
    scene = Scene(plates, (), SENSOR)
    spec = GridSpec((14.0, -4.0, -1.0), 0.2, (40, 40, 20))
    quiet = observe(scene, [-3.0], seed=3, noise_rms=0.0, adc=None)
    power = oracle.range_profile(quiet.samples.reshape(1, -1, PAPER_RADAR.n_samples), 1024, output="power")
    lattice = BeamLattice.from_radar(PAPER_RADAR)
    half = (math.radians(PAPER_RADAR.beamwidth_az_deg) / 2, math.radians(PAPER_RADAR.beamwidth_el_deg) / 2)
    t = vis.visibility_truth(scene, spec, np.ones(spec.array_shape, bool), quiet.poses, power,
                             vis.noise_power_per_bin(NOISE_RMS, PAPER_RADAR.n_samples), lattice, half,
                             PAPER_RADAR.bin_spacing_m(1024))

    def face(y0, y1):
        idx = np.argwhere(t.labels == OCCUPIED)[:, ::-1]
        world = spec.index_to_world(idx)
        keep = (world[:, 0] < 20.2) & (world[:, 1] > y0) & (world[:, 1] < y1) & (np.abs(world[:, 2] - 1.0) < 0.3)
        return t.classes[idx[keep, 2], idx[keep, 1], idx[keep, 0]]

    assert len(face(-2.9, -1.5)) and (face(-2.9, -1.5) == vis.WEAK).all()
    # speckle: a bin of the bright plate may still fade below 10 dB (a fixed phase per scatterer)
    assert len(face(1.5, 2.9)) and (face(1.5, 2.9) == vis.DETECTABLE).mean() > 0.8
