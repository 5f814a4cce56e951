"""Harder physics in the simulator (radarcl/scene/observe.py, the paper's future work), each a
switch, off by default: sidelobes put a strong reflector outside the main lobe into a beam at
about -20 dB; multipath adds a ghost at the mirror image's range below the surface and makes a
smooth wall seen obliquely return (almost) nothing; with the switches off nothing changes."""

import math

import numpy as np
import pytest

from radarcl.config.stage_config import PAPER_RADAR
from radarcl.scene import observe as ob
from radarcl.scene.outdoor import GRASS, Material, Scene, SceneObject
from radarcl.scene.shapes import Box, Ground

SENSOR = (0.0, 0.0, 1.5)
MATTE = Material("matte", -5.0)
SMOOTH = Material("smooth", -5.0, specular=True)


def head_pose(scene, elevation_deg=0.0):
    """The head pitched so its lowest beam points at ``elevation_deg`` - 3 deg (stand_pose)."""
    return scene.stand_pose(elevation_deg - 3.0)


def echoes(scene, physics, elevation_deg=0.0):
    amp, r, _ = ob.observe_frame(scene, head_pose(scene, elevation_deg), salt=1, physics=physics)
    return amp, r


def test_switches_off_change_nothing():
    scene = Scene((SceneObject("ground", Ground(0.0), GRASS), SceneObject("box", Box((20.03, -1.01, 0.0), (20.53, 1.01, 2.0)), MATTE)),
                  (), SENSOR)
    a = ob.observe_frame(scene, head_pose(scene), salt=3)
    b = ob.observe_frame(scene, head_pose(scene), salt=3, physics=0)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    # multipath on a scene with nothing above the terrain and nothing smooth: the same echoes,
    # the ghost columns all zero
    flat = Scene((SceneObject("ground", Ground(0.0), GRASS),), (), SENSOR)
    plain = ob.observe_frame(flat, head_pose(flat, -5.0), salt=3)
    multi = ob.observe_frame(flat, head_pose(flat, -5.0), salt=3, physics=ob.MULTIPATH)
    k = plain[0].shape[1]
    assert np.array_equal(multi[0][:, :k], plain[0]) and np.array_equal(multi[1][:, :k], plain[1])
    assert not multi[0][:, k:].any()


def test_multipath_puts_a_ghost_at_the_mirror_images_range():
    box = SceneObject("box", Box((20.03, -1.01, 1.0), (20.53, 1.01, 2.0)), MATTE)       # a box 1-2 m up
    scene = Scene((SceneObject("ground", Ground(0.0), GRASS), box), (), SENSOR)
    amp0, r0 = echoes(scene, 0)
    amp1, r1 = echoes(scene, ob.MULTIPATH)
    k = amp0.shape[1]
    ghost_amp, ghost_r = amp1[:, k:], r1[:, k:]
    on_box = amp0 > 0
    assert ghost_amp.any()
    # Every ghost: a quarter of its direct echo's amplitude, at the distance of the hit's image
    # below z = 0. The hit p lies on the box, 1 to 2 m up; the sensor at height h = 1.5 m; the
    # image (x, y, -z) is at r_g^2 = r_d^2 + 4 z h from it: sqrt(r_d^2 + 6) <= r_g <= sqrt(r_d^2 + 12),
    # a window 0.15 m wide at 20 m (the range resolution is 0.5 m).
    hit = np.flatnonzero((ghost_amp > 0).ravel())
    direct_r = r0.ravel()[hit]
    assert len(hit) > 20 and on_box.ravel()[hit].all() and (np.abs(direct_r - 20.3) < 0.4).all()
    assert np.allclose(ghost_amp.ravel()[hit], amp0.ravel()[hit] * ob.GROUND_BOUNCE ** 2)
    h = SENSOR[2]
    lo, hi = np.sqrt(direct_r ** 2 + 4 * 1.0 * h), np.sqrt(direct_r ** 2 + 4 * 2.0 * h)
    assert np.all(ghost_r.ravel()[hit] >= lo - 1e-9) and np.all(ghost_r.ravel()[hit] <= hi + 1e-9)
    # and a ghost only where there is a direct echo
    assert not ghost_amp.ravel()[~on_box.ravel()].any()


def test_multipath_makes_a_smooth_wall_seen_obliquely_vanish():
    wall = Box((15.03, -20.0, -0.5), (15.33, 20.0, 4.0))
    for material, kept in ((MATTE, True), (SMOOTH, False)):
        scene = Scene((SceneObject("wall", wall, material),), (), SENSOR)
        a0, _ = echoes(scene, 0)
        a1, _ = echoes(scene, ob.MULTIPATH)
        az = np.repeat(np.arange(PAPER_RADAR.n_azimuth), PAPER_RADAR.n_elevation)
        oblique = np.abs(az - 31.5) > 25                      # beams more than 25 deg off the wall's normal
        p0, p1 = (a0[oblique] ** 2).sum(), (a1[oblique, :a0.shape[1]] ** 2).sum()
        if kept:
            assert p1 == pytest.approx(p0)                   # a matte wall is not specular
        else:
            assert p1 < 0.02 * p0                            # smooth: the beam goes away (cos^40 of 25 deg: 0.02)
            square = ~oblique & (np.abs(az - 31.5) < 2)
            assert (a1[square, :a0.shape[1]] ** 2).sum() > 0.5 * (a0[square] ** 2).sum()


def test_sidelobes_see_a_reflector_outside_the_main_lobe():
    # a wall off to the side, at azimuths beyond the main lobe of beam 0 but within its sidelobe ring
    half = math.radians(PAPER_RADAR.beamwidth_az_deg) / 2
    az0 = math.radians(-31.5)                                 # beam 0's azimuth
    y_mid = 20.0 * math.tan(az0 - 2.4 * half)               # 2.4 half-widths off, +-0.3 wide: 2.1-2.7
    wall = SceneObject("wall", Box((20.03, y_mid - 0.05, -1.0), (20.13, y_mid + 0.05, 4.0)), MATTE)
    scene = Scene((wall,), (), SENSOR)
    a0, _ = echoes(scene, 0)
    a1, _ = echoes(scene, ob.SIDELOBES)
    beam0 = [i * PAPER_RADAR.n_elevation + 1 for i in (0,)]
    assert not a0[beam0].any()                                # outside the main lobe: nothing
    assert a1[beam0].any()                                    # the sidelobe sees it
    rho = np.linspace(0, 3, 301)
    pattern = ob.pattern_amplitude(rho, sidelobes=True)
    assert pattern[rho > 2.0].max() == pytest.approx(10 ** (ob.SIDELOBE_DB / 20), rel=0.02)   # the ring peaks at 2.25
    assert np.array_equal(ob.pattern_amplitude(rho[rho <= 1.5]), pattern[rho <= 1.5])
