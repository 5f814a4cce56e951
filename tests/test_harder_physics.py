"""Harder physics in the simulator (radarcl/scene/observe.py, the paper's future work), each a
switch, off by default: sidelobes put a strong reflector outside the main lobe into a beam at
about -20 dB; multipath adds a ghost at the mirror image's range below the surface and makes a
smooth wall seen obliquely return (almost) nothing; with the switches off nothing changes.
The spinning radar on a vehicle (scene.streets) has them too: azimuth sidelobes of its fan beam
(range sidelobes come from the window, measured), traced mirror paths off the road and smooth
walls; and, for both radars, a heavy-tailed RCS spread and a K-distributed clutter floor."""

import math

import numpy as np
import pytest

from radarcl import oracle
from radarcl.config import mapconfig
from radarcl.config.stage_config import PAPER_RADAR, RadarConfig
from radarcl.geometry import BeamLattice
from radarcl.scene import generator, streets
from radarcl.scene import observe as ob
from radarcl.scene.fmcw import simulate_beams
from radarcl.scene.outdoor import GRASS, METAL, Material, Scene, SceneObject
from radarcl.scene.shapes import Box, Cylinder, Ground, Sphere

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


# -- the spinning radar (scene.streets: one pose per beam, a fan beam) ------------------------------------------
# Its echoes on hand-built scenes, the radar still at the origin (one identity pose per beam), so
# that beam i looks along azimuth i x 0.9 deg. The radar is the spinning-sim profile's.

SPINNING = mapconfig.resolve("spinning-sim").sensor
STILL = np.repeat(np.eye(4)[None], SPINNING.lattice().n_beams, axis=0)
HALF_AZ_DEG = SPINNING.radar.beamwidth_az_deg / 2

# A thin post spans 0.17 half-widths in azimuth: over it the two-way main lobe near the axis (0.25
# half-widths off) varies by 0.6 dB in power and the sidelobe ring near its peak by 0.3 dB, so a
# beam's power relative to another's holds the pattern's ratio at the post's centre to this.
SIDELOBE_LEVEL_DB = 0.5
# Ghost against the mirror image's echo: the reflected ray starts 1e-6 m off the mirror (so that it
# cannot meet the mirror again), which moves its hit on the object by ~1e-6 m, more at grazing
# incidence on a curved silhouette: relative amplitude and absolute range within these.
MIRROR_RTOL = 1e-5
MIRROR_ATOL_M = 1e-4
# Quantiles of the SPREAD draws over ~16,000 surface cells: the standard error of the 5 % and 95 %
# quantiles of a t3 of 6 dB scale is ~0.25 dB there (0.1 dB at the median); 4 standard errors.
SPREAD_QUANTILE_DB = 1.0


def spinning_echoes(scene, physics, salt=7):
    return ob.observe_frame(scene, STILL, SPINNING.radar, streets.RAYS_ACROSS, salt=salt, physics=physics,
                            lattice=SPINNING.lattice())


def beam_power_db(amp, beam, reference):
    p = (amp ** 2).sum(axis=1)
    return 10 * np.log10(p[beam] / p[reference])


def test_spinning_sidelobes_put_a_strong_post_into_the_beams_beside_it():
    """A post at azimuth 90.225 deg: 0.25 half-widths off beam 100, 2.25 off beam 98 (the ring's
    peak, azimuth only). Without sidelobes beam 98 sees nothing; with them it carries the
    pattern's ratio, -20 dB of the ring's peak over the main lobe at 0.25: -19.6 dB."""
    az = math.radians(90.0 + 0.25 * HALF_AZ_DEG)
    post = SceneObject("post", Cylinder((15 * math.cos(az), 15 * math.sin(az)), 0.02, -5.0, 5.0), METAL)
    scene = Scene((post,), (), (0.0, 0.0, 0.0))
    plain, _, _ = spinning_echoes(scene, 0)
    lobes, _, _ = spinning_echoes(scene, ob.SIDELOBES)
    assert not plain[98].any() and plain[100].any()
    want = 20 * np.log10(ob._ring(np.array(2.25)) / 2.0 ** -(0.25 ** 2))
    assert want == pytest.approx(-19.62, abs=0.01)
    assert beam_power_db(lobes, 98, 100) == pytest.approx(want, abs=SIDELOBE_LEVEL_DB)
    # the ring lies in azimuth only: 2.25 half-widths up or down, sidelobes add nothing to the main lobe
    assert ob.fan_pattern_amplitude(np.array([0.0, 2.25]), True) == ob.fan_pattern_amplitude(np.array([0.0, 2.25]))
    assert ob.fan_pattern_amplitude(np.array([2.25, 0.0]), True) == pytest.approx(0.1)


def test_spinning_range_sidelobes_come_from_the_window_with_or_without_the_switch():
    """Range sidelobes need no switch: the profiles are the Hann-windowed FFT of simulated beat
    samples (radarcl.oracle.range_profile, the range FFT kernel's oracle), so a point-like echo
    spreads into neighbouring bins at the window's first sidelobe, -31.5 dB, falling 18 dB per
    octave. Sampled every half bin (n_fft = 2 n) the strongest sample 2-4 bins off the peak lies
    within a quarter bin of the sidelobe's crest, and the peak sample within a quarter bin of
    the main lobe's: -34 to -30 dB."""
    az = math.radians(90.0)
    ball = SceneObject("ball", Sphere((15 * math.cos(az), 15 * math.sin(az), 0.0), 0.05), METAL)
    scene = Scene((ball,), (), (0.0, 0.0, 0.0))
    for physics in (0, ob.SIDELOBES):
        amp, r, phase = spinning_echoes(scene, physics)
        samples = simulate_beams(SPINNING.radar, amp[100:101], r[100:101], phase[100:101]).samples
        power = oracle.range_profile(samples, 2 * SPINNING.radar.n_samples, output="power")[0]
        peak = int(np.argmax(power))
        rel = 10 * np.log10(power / power[peak])
        first = max(rel[peak + 4:peak + 9].max(), rel[peak - 8:peak - 3].max())      # 2-4 bins off
        assert -34.0 <= first <= -30.0
        assert max(rel[peak + 9:peak + 41].max(), rel[peak - 40:peak - 8].max()) < -45.0   # 4.5 bins and beyond


WALL = SceneObject("smooth wall", Box((-20.03, 5.03, -3.0), (40.03, 5.33, 3.0)), SMOOTH)


def test_spinning_multipath_puts_a_posts_ghost_behind_a_smooth_wall():
    """A smooth wall along the street (y = 5.03 m) and a post across it at (13, -3): the beam at 45
    deg meets the wall, its reflection meets the post, and the ghost (radar -> wall -> post -> wall
    -> radar) is the echo of the post's mirror image at (13, 13.06), 18.4 m away, times
    WALL_BOUNCE^2: exactly the echoes of a post put there with no wall, ray by ray. The other
    order (radar -> post -> wall -> radar) would need the post within the 45 deg beam: none."""
    post = lambda y: SceneObject("post", Cylinder((13.0, y), 0.1, -5.0, 5.0), METAL)      # noqa: E731
    scene = Scene((WALL, post(-3.0)), (), (0.0, 0.0, 0.0))
    image = Scene((post(2 * 5.03 + 3.0),), (), (0.0, 0.0, 0.0))
    a0, r0, p0 = spinning_echoes(scene, 0)
    a1, r1, p1 = spinning_echoes(scene, ob.MULTIPATH)
    ai, ri, _ = spinning_echoes(image, 0)
    k = a0.shape[1]
    assert np.array_equal(r1[:, :k], r0)                     # the direct echoes stay where they were
    ghost, ghost_r = a1[:, k:], r1[:, k:]
    beams = np.flatnonzero((ghost > 0).any(axis=1))
    assert np.array_equal(beams, np.flatnonzero((ai > 0).any(axis=1))) and 50 in beams
    for b in beams:
        mine, theirs = ghost[b] > 0, ai[b] > 0
        assert mine.sum() == theirs.sum() > 20
        np.testing.assert_allclose(np.sort(ghost[b][mine]), np.sort(ai[b][theirs]) * ob.WALL_BOUNCE ** 2,
                                   rtol=MIRROR_RTOL)
        np.testing.assert_allclose(np.sort(ghost_r[b][mine]), np.sort(ri[b][theirs]), atol=MIRROR_ATOL_M)
    # in the range profile of the 45 deg beam: the ghost is the peak, at the image's range (the smooth
    # wall seen at 45 deg returns cos^41 = -62 dB of a matte one); without multipath, the wall is
    n_fft = 2 * SPINNING.radar.n_samples
    spacing = SPINNING.radar.bin_spacing_m(n_fft)
    for amp, r, phase, want in ((a1, r1, p1, np.median(ri[50][ai[50] > 0])), (a0, r0, p0, None)):
        samples = simulate_beams(SPINNING.radar, amp[50:51], r[50:51], phase[50:51]).samples
        power = oracle.range_profile(samples, n_fft, output="power")[0]
        peak_m = np.argmax(power[16:]) * spacing + 16 * spacing
        if want is None:
            assert abs(peak_m - 5.03 * math.sqrt(2)) < 0.25
        else:
            assert abs(peak_m - want) < 0.25 and want == pytest.approx(18.3, abs=0.1)


def test_spinning_multipath_bounces_off_the_ground():
    """A box 0.3-1.5 m above a flat road, 40 m ahead (the radar 2.03 m up). Rays that meet the road
    short of the box reflect into it: the four-leg ghost (radar -> road -> box -> road -> radar) is
    the echo of the box's mirror image below the road times GROUND_BOUNCE^2, ray by ray (the
    stand's ground bounce, with the pattern of the ray that points at the image). The three-leg
    paths (out via the road, back straight, and the reverse) lie between the box's range and
    its image's, each 2 / GROUND_BOUNCE = 4x the four-leg's amplitude times sqrt(g(p) / g(ray)):
    the box lies 0.2-0.6 half-widths below the axis, its image 0.8-1.25, so their power exceeds the
    four-leg ghosts' by 12 dB plus 0.9-4.6 dB."""
    g = -2.03
    box = lambda z0, z1: SceneObject("box", Box((40.03, -1.03, z0), (40.53, 1.03, z1)), METAL)  # noqa: E731
    scene = Scene((SceneObject("road", Ground(g), GRASS), box(g + 0.3, g + 1.5)), (), (0.0, 0.0, 0.0))
    image = Scene((box(g - 1.5, g - 0.3),), (), (0.0, 0.0, 0.0))
    a0, r0, _ = spinning_echoes(scene, 0)
    a1, r1, _ = spinning_echoes(scene, ob.MULTIPATH)
    ai, ri, _ = spinning_echoes(image, 0)
    k = a0.shape[1]
    assert np.array_equal(a1[:, :k], a0) and np.array_equal(r1[:, :k], r0)   # nothing here is specular
    ghost, ghost_r = a1[:, k:], r1[:, k:]
    beams = np.flatnonzero((ai > 0).any(axis=1))
    assert len(beams) >= 3 and np.array_equal(np.flatnonzero((ghost > 0).any(axis=1)), beams)
    for b in beams:
        mine, theirs = np.flatnonzero(ghost[b] > 0), np.flatnonzero(ai[b] > 0)
        same = ((np.abs(ghost_r[b][mine][:, None] - ri[b][theirs][None, :]) < MIRROR_ATOL_M)
                & (np.abs(ghost[b][mine][:, None] / (ai[b][theirs][None, :] * ob.GROUND_BOUNCE ** 2) - 1)
                   < MIRROR_RTOL))
        assert same.any(axis=0).all()                        # every image echo is a four-leg ghost
        four, three = mine[same.any(axis=1)], mine[~same.any(axis=1)]
        assert 0 < len(three) <= len(four)
        direct = r0[b][(a0[b] > 0) & (r0[b] > 39.0) & (r0[b] < 41.0)]   # the box's own echoes
        assert (ghost_r[b][three] > direct.min()).all() and (ghost_r[b][three] < ri[b][theirs].max()).all()
        ratio_db = 10 * np.log10((ghost[b][three] ** 2).sum() / (ghost[b][four] ** 2).sum())
        assert 12.0 < ratio_db < 17.0


def test_spread_draws_each_patchs_rcs_from_a_heavy_tailed_spread():
    """A road seen by the spinning radar: with SPREAD each echo's power is the plain one times
    10^(X / 10), X drawn per 0.5 m cell of the surface, so over the ~16,000 cells the rays meet
    X follows SPREAD_SCALE_DB x t(SPREAD_DOF) clipped at +-SPREAD_CLIP_DB: the quartiles of the
    7 dB log-normal prior of the spinning profile, 10x its mass beyond +-20 dB. Ranges and
    phases do not change."""
    from scipy import stats

    scene = Scene((SceneObject("road", Ground(-2.03), GRASS),), (), (0.0, 0.0, 0.0))
    a0, r0, p0 = spinning_echoes(scene, 0)
    a1, r1, p1 = spinning_echoes(scene, ob.SPREAD)
    assert np.array_equal(r0, r1) and np.array_equal(p0, p1) and np.array_equal(a0 > 0, a1 > 0)
    x = 20 * np.log10(a1[a0 > 0] / a0[a0 > 0])
    q = np.array([0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95])
    want = ob.SPREAD_SCALE_DB * stats.t.ppf(q, ob.SPREAD_DOF)
    np.testing.assert_allclose(np.quantile(x, q), want, atol=SPREAD_QUANTILE_DB)
    assert np.abs(x).max() <= ob.SPREAD_CLIP_DB + 1e-9
    prior_db = mapconfig.resolve("spinning-sim")["sensor_model.target_spread_db"]    # 7 dB
    beyond = np.mean(np.abs(x) > 20.0)
    assert beyond == pytest.approx(2 * stats.t.sf(20.0 / ob.SPREAD_SCALE_DB, ob.SPREAD_DOF), abs=0.01)
    assert beyond > 5 * 2 * stats.norm.sf(20.0 / prior_db)                       # the prior: 0.4 %
    iqr = np.subtract(*np.quantile(x, [0.75, 0.25]))
    assert iqr == pytest.approx(2 * stats.norm.ppf(0.75) * prior_db, abs=1.0)     # the prior's core: 9.4 dB


def test_spread_applies_to_the_stands_points_and_surfaces():
    """On the stand too: each point scatterer's echo scales by 10^(spread_db(its index) / 20) in
    every beam, surfaces by their cell's draw; the same seed draws the same, another seed not."""
    scene, _ = generator.generate(301)
    assert scene.points
    pose = scene.stand_pose(-9.2)
    a0, r0, p0 = ob.observe_frame(scene, pose, salt=301)
    a1, r1, p1 = ob.observe_frame(scene, pose, salt=301, physics=ob.SPREAD)
    n = len(scene.points)
    assert np.array_equal(r0, r1) and np.array_equal(p0, p1)
    factor = 10 ** (ob.spread_db(np.arange(n)[:, None], 301, 6) / 20)
    np.testing.assert_allclose(a1[:, -n:], a0[:, -n:] * factor, rtol=1e-12)
    surface = a0[:, :-n] > 0
    assert not np.allclose(a1[:, :-n][surface], a0[:, :-n][surface])
    assert np.array_equal(a1, ob.observe_frame(scene, pose, salt=301, physics=ob.SPREAD)[0])
    other = ob.observe_frame(scene, pose, salt=302, physics=ob.SPREAD)[0]
    assert not np.allclose(other[:, -n:], a0[:, -n:] * factor)


def test_clutter_is_a_floor_of_k_distributed_power_up_to_the_first_surface():
    """CLUTTER (rain): per beam, scatterers at CLUTTER_PER_M per metre from the minimum range to
    the first surface on the beam's axis, each of mean power CLUTTER_ETA Omega r^2 / CLUTTER_PER_M
    through the radar equation, K-distributed: normalised by that mean, P(I > x) =
    2 sqrt(x) K_1(2 sqrt(x)) for shape 1 (an exponential would give e^-x: 5e-5 at x = 10, where K
    gives 6e-3). A wall 20 m ahead stops it; the other echoes do not change."""
    from scipy import special

    scene = Scene((SceneObject("far ground", Ground(-1e4), GRASS),
                   SceneObject("wall", Box((20.03, -5.0, -3.0), (20.5, 5.0, 3.0)), METAL)), (), (0.0, 0.0, 0.0))
    a0, r0, p0 = spinning_echoes(scene, 0)
    a1, r1, p1 = ob.observe_frame(scene, STILL, SPINNING.radar, streets.RAYS_ACROSS, salt=7, physics=ob.CLUTTER,
                                  lattice=SPINNING.lattice(), frame=3)
    k = a0.shape[1]
    assert all(np.array_equal(x[:, :k], y) for x, y in ((a1, a0), (r1, r0), (p1, p0)))
    amp, r = a1[:, k:], r1[:, k:]
    there = amp > 0
    radar = SPINNING.radar
    half_az, half_el = math.radians(radar.beamwidth_az_deg) / 2, math.radians(radar.beamwidth_el_deg) / 2
    omega = math.pi * half_az * half_el / (2 * math.log(2))
    mean = ob.A_1M2_AT_10M ** 2 * ob.CLUTTER_ETA * omega * ob.R_REF_M ** 4 / (ob.CLUTTER_PER_M * r[there] ** 2)
    intensity = amp[there] ** 2 / mean
    assert intensity.size > 20000 and intensity.mean() == pytest.approx(1.0, abs=0.05)
    for x in (1.0, 3.0, 10.0):
        want = 2 * math.sqrt(x) * special.kv(1, 2 * math.sqrt(x))
        assert np.mean(intensity > x) == pytest.approx(want, abs=4 * math.sqrt(want / intensity.size) + 1e-4)
    for b in np.r_[0:8, 392:400]:                            # beams whose axis meets the wall's face x = 20.03
        assert r[b][there[b]].max() < 20.03 / math.cos(math.radians(0.9 * b)) + 1e-9
    assert r[100][there[100]].max() > 50.0
    assert (r[there] >= radar.range_min_m).all()
    counts = there.sum(axis=1)[100:300]                      # 58 m of open range: Poisson(58)
    assert counts.mean() == pytest.approx(ob.CLUTTER_PER_M * (radar.range_max_m - radar.range_min_m), abs=2.0)
    # the stand: the same floor after its echoes, the same per (seed, frame), another frame other drops
    stand, _ = generator.generate(301)
    pose = stand.stand_pose(-9.2)
    plain = ob.observe_frame(stand, pose, salt=301)
    rain = [ob.observe_frame(stand, pose, salt=301, physics=ob.CLUTTER, frame=f) for f in (2, 2, 3)]
    k = plain[0].shape[1]
    assert all(np.array_equal(x[:, :k], y) for x, y in zip(rain[0], plain)) and rain[0][0].shape[1] > k
    assert all(np.array_equal(x, y) for x, y in zip(rain[0], rain[1]))
    assert rain[2][0].shape != rain[0][0].shape or not np.array_equal(rain[2][0], rain[0][0])


def test_spinning_switches_are_deterministic_per_seed_and_off_changes_nothing():
    """Each switch: the same seed (and frame) gives the same echoes; another seed other ones
    (CLUTTER: another frame too, rain's drops move); physics=0 is the default; through
    streets.observe, samples and the recorded switches are reproducible."""
    scene = Scene((SceneObject("road", Ground(-2.03), GRASS), WALL,
                   SceneObject("post", Cylinder((13.0, -3.0), 0.1, -5.0, 5.0), METAL),
                   SceneObject("car", Box((20.03, -4.13, -1.8), (24.53, -2.33, -0.4)), METAL)), (), (0.0, 0.0, 0.0))
    for bit in (ob.SIDELOBES, ob.MULTIPATH, ob.SPREAD, ob.CLUTTER):
        a = spinning_echoes(scene, bit)
        assert all(np.array_equal(x, y) for x, y in zip(a, spinning_echoes(scene, bit)))
        b = spinning_echoes(scene, bit, salt=8)
        assert a[0].shape != b[0].shape or not np.array_equal(a[0], b[0])
    plain = spinning_echoes(scene, 0)
    default = ob.observe_frame(scene, STILL, SPINNING.radar, streets.RAYS_ACROSS, salt=7, lattice=SPINNING.lattice())
    assert all(np.array_equal(x, y) for x, y in zip(plain, default))
    f3 = ob.observe_frame(scene, STILL, SPINNING.radar, streets.RAYS_ACROSS, salt=7, physics=ob.CLUTTER,
                          lattice=SPINNING.lattice(), frame=3)[0]
    f4 = ob.observe_frame(scene, STILL, SPINNING.radar, streets.RAYS_ACROSS, salt=7, physics=ob.CLUTTER,
                          lattice=SPINNING.lattice(), frame=4)[0]
    assert f3.shape != f4.shape or not np.array_equal(f3, f4)
    small = RadarConfig(n_azimuth=40, n_elevation=1, azimuth_step_deg=9.0, beamwidth_az_deg=6.0, beamwidth_el_deg=8.0)
    lattice = BeamLattice.spinning(40)
    every = ob.SIDELOBES | ob.MULTIPATH | ob.SPREAD | ob.CLUTTER
    one = streets.observe(scene, small, lattice, 2, seed=301, physics=every)
    two = streets.observe(scene, small, lattice, 2, seed=301, physics=every)
    off = streets.observe(scene, small, lattice, 2, seed=301)
    assert one.physics == every and off.physics == 0
    assert np.array_equal(one.samples, two.samples) and not np.array_equal(one.samples, off.samples)


def test_bench_scenes_takes_every_switch_by_name():
    from radarcl.bench.scenes import parse_physics, physics_names
    from radarcl.errors import ConfigError

    every = parse_physics("sidelobes, multipath,spread,clutter")
    assert every == ob.SIDELOBES | ob.MULTIPATH | ob.SPREAD | ob.CLUTTER
    assert physics_names(every) == ["sidelobes", "multipath", "spread", "clutter"]
    assert parse_physics("") == 0 and physics_names(0) == ["none"] and parse_physics("spread,spread") == ob.SPREAD
    with pytest.raises(ConfigError, match="rain"):
        parse_physics("sidelobes,rain")
