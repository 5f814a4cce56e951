"""A spinning radar with truth: generated streets and a Navtech-like radar driving through them.

``generate(seed)`` builds a street along +x: the road, kerbs, building facades on both sides with
gaps between them (cross streets, drives), parked cars along the kerbs, posts and trees on the
pavements, seeded. The sensor's head is at the origin, ``sensor_height_m`` above the road, so a
spinning radar's one elevation maps the horizontal plane at z = 0 (the grid of its profile).

``observe(scene, radar, lattice, turns, seed)`` simulates ``turns`` full turns of the radar
(``scene.observe.observe_frame`` with one pose per azimuth: the vehicle drives at
``SPEED_M_S`` along the street while the antenna turns at ``TURN_HZ``, so each azimuth's beam has
its own origin, as the Oxford and RADIATE scans do), to raw samples with receiver noise and the
ADC. The whole pipeline runs from those samples; ``evaluation.evaluate.instrument`` gives the
truth as for the tilting stand. ``physics`` turns on the simulator's harder physics
(``scene.observe``), as for the stand.

``TRAIN_SEEDS`` are for choosing anything, ``HELD_OUT_SEEDS`` for reporting only.
"""

import numpy as np

from radarcl.errors import ConfigError
from radarcl.geometry import pose_from_xyz_rpy
from radarcl.scene.fmcw import simulate_beams
from radarcl.scene.generator import CONCRETE, _box
from radarcl.scene.observe import ADC, NOISE_RMS, Observations, observe_frame
from radarcl.scene.outdoor import BARK, FOLIAGE, GRASS, METAL, Material, Scene, SceneObject
from radarcl.scene.shapes import Cylinder, Ground, Sphere

TRAIN_SEEDS = (301, 302, 303, 304, 305, 306)
HELD_OUT_SEEDS = (401, 402, 403, 404)
SPEED_M_S = 5.0                   # the vehicle, along +x
TURN_HZ = 4.0                     # turns of the antenna per second (Navtech CTS350-X: 4 Hz)
RAYS_ACROSS = 24                  # a fan beam 8 deg tall needs finer ray cells than the paper's pencil beams
BRICK = Material("brick", -10.0)
KERB = Material("kerb stone", -8.0)


def generate(seed):
    """The street of ``seed``: (Scene, a dict that describes it)."""
    rng = np.random.default_rng(seed)
    height = float(rng.uniform(1.6, 2.4))          # the antenna on a vehicle's roof
    road = float(rng.uniform(3.0, 5.0))            # half the road's width
    pavement = float(rng.uniform(1.5, 3.0))
    g = -height                                     # the road's surface, the head at z = 0
    objects = [SceneObject("ground", Ground(g), GRASS)]

    def add(name, shape, material):
        objects.append(SceneObject(name, shape, material))

    for side in (-1.0, 1.0):
        kerb = side * road
        add(f"kerb {side:+.0f}", _box((-30.0, min(kerb, kerb + side * 0.2), g - 0.1),
                                      (90.0, max(kerb, kerb + side * 0.2), g + 0.15)), KERB)
        x = -30.0 + float(rng.uniform(0.0, 8.0))
        k = 0
        while x < 85.0:                             # facades with gaps
            length = float(rng.uniform(6.0, 22.0))
            front = side * (road + pavement + float(rng.uniform(0.0, 1.5)))
            depth, tall = float(rng.uniform(5.0, 10.0)), float(rng.uniform(3.0, 12.0))
            lo_y, hi_y = (front, front + depth) if side > 0 else (front - depth, front)
            add(f"building {side:+.0f}.{k}", _box((x, lo_y, g - 0.3), (x + length, hi_y, g + tall)),
                CONCRETE if rng.random() < 0.5 else BRICK)
            x += length + float(rng.uniform(2.0, 12.0))
            k += 1
        x = -25.0 + float(rng.uniform(0.0, 10.0))
        k = 0
        while x < 80.0:                             # parked cars along the kerb
            if rng.random() < 0.6:
                y0 = side * (road - 0.3) - (1.8 if side > 0 else 0.0)
                add(f"car {side:+.0f}.{k}", _box((x, y0, g + 0.2), (x + 4.5, y0 + 1.8, g + 1.6)), METAL)
                k += 1
            x += float(rng.uniform(5.5, 9.0))
        for j in range(int(rng.integers(3, 8))):    # posts and trees on the pavement
            px = float(rng.uniform(-20.0, 80.0))
            py = side * (road + 0.5 + float(rng.uniform(0.0, max(0.1, pavement - 1.0))))
            if rng.random() < 0.5:
                add(f"post {side:+.0f}.{j}", Cylinder((px, py), float(rng.uniform(0.05, 0.12)), g - 0.2,
                                                       g + float(rng.uniform(2.5, 5.0))), METAL)
            else:
                tall, crown = float(rng.uniform(3.0, 5.0)), float(rng.uniform(1.0, 2.0))
                add(f"tree {side:+.0f}.{j} trunk", Cylinder((px, py), float(rng.uniform(0.1, 0.25)), g - 0.3, g + tall),
                    BARK)
                add(f"tree {side:+.0f}.{j} crown", Sphere((px, py, g + tall + 0.6 * crown), crown), FOLIAGE)
    scene = Scene(tuple(objects), (), (0.0, 0.0, 0.0))
    return scene, dict(seed=int(seed), sensor_height_m=round(height, 2), road_half_width_m=round(road, 2),
                       objects=[o.name for o in objects[1:]])


def beam_poses(lattice, turns, speed_m_s=SPEED_M_S, turn_hz=TURN_HZ):
    """(turns, n_az, 4, 4) per-azimuth poses: the head at x = speed t, the azimuths of one turn
    taken one after another while it drives."""
    n = lattice.n_beams
    t = (np.arange(turns)[:, None] + np.arange(n)[None, :] / n) / turn_hz
    return np.stack([[pose_from_xyz_rpy(speed_m_s * tk, 0.0, 0.0) for tk in row] for row in t])


def observe(scene, radar, lattice, turns, seed=0, noise_rms=NOISE_RMS, adc=ADC, poses=None, physics=0):
    """Simulate ``turns`` turns of a spinning radar (``radar``: a ``RadarConfig`` with one
    elevation, ``lattice``: its spinning ``BeamLattice``) driving through ``scene``; returns
    ``Observations`` whose poses are (turns, n_az, 4, 4). ``poses`` replaces ``beam_poses``;
    ``physics``: the simulator's harder physics (``scene.observe``: SIDELOBES | MULTIPATH |
    SPREAD | CLUTTER), 0 for none."""
    if radar.n_elevation != 1 or lattice.n_el != 1 or not lattice.wraps:
        raise ConfigError("the street simulation is for a spinning radar with one elevation")
    P = beam_poses(lattice, turns) if poses is None else np.asarray(poses, float)
    rng = np.random.default_rng(seed)
    frames, clipped, rays = [], 0, 0
    for j, turn in enumerate(P):
        amp, r, phase = observe_frame(scene, turn, radar, RAYS_ACROSS, salt=seed, physics=physics, lattice=lattice,
                                      frame=j)
        sim = simulate_beams(radar, amp, r, phase, noise_rms=noise_rms, adc=adc, seed=rng.integers(2 ** 63))
        frames.append(sim.samples.reshape(radar.n_azimuth, 1, radar.n_samples))
        clipped += sim.n_clipped
        rays = amp.shape[1]
    return Observations(np.stack(frames), P, np.zeros(len(P)), int(seed), int(rays), clipped, int(physics))

