"""Seeded outdoor scenes beyond the reference one, with a fixed training set and a held-out set.

A configuration tuned and judged on one scene learns that scene. ``generate(seed)`` composes the
reference scene's solids into a different layout for every seed:

- the sensor 1-3 m above the terrain at the origin (a stand, a mast, a vehicle roof);
- terrain: flat, sloped (up to 4 deg, ``shapes.Slope``) or uneven (flat with low mounds: balls
  buried to 0.2-0.6 m of their radius, named "mound", counted as terrain, not as obstacles);
- walls (some in pairs: a corridor 2.5-4 m wide), posts, vehicles (4.5 x 1.8 x 1.5 m metal boxes),
  trees (trunk and crown), rocks, drums (with their point echo), all within the radar's
  64 deg x 64 m fan at 6-58 m, with gaps between them;
- every axis-aligned face kept off the voxel lattices the benches use (multiples of 0.05 m), so
  the truth never depends on how a face on a voxel boundary is rounded.

``TRAIN_SEEDS`` are for choosing anything (constants, models); ``HELD_OUT_SEEDS`` only for
reporting. Materials are those of ``outdoor`` (grass, bark, foliage, rock, metal).
"""

import math

import numpy as np

from radarcl.scene.outdoor import BARK, FOLIAGE, GRASS, METAL, ROCK, Material, PointScatterer, Scene, SceneObject
from radarcl.scene.shapes import Box, Cylinder, Ground, Slope, Sphere

TRAIN_SEEDS = (101, 102, 103, 104, 105, 106)
HELD_OUT_SEEDS = (201, 202, 203, 204)
CONCRETE = Material("smooth concrete", -8.0, specular=True)    # specular only with observe.MULTIPATH
TERRAIN_NAMES = ("ground", "mound")
LATTICE_M = 0.05
HALF_FAN_DEG = 30.0                  # inside the paper radar's +-32 deg, so objects are seen whole


def _off_lattice(value):
    """``value`` nudged 13 mm when it lies within 0.5 mm of a multiple of LATTICE_M."""
    k = round(value / LATTICE_M)
    return value + 0.013 if abs(value - k * LATTICE_M) < 5e-4 else value


def _box(lo, hi):
    return Box(tuple(_off_lattice(float(v)) for v in lo), tuple(_off_lattice(float(v)) for v in hi))


def is_terrain(name):
    """True for the terrain's solids (the ground and its mounds): not obstacles."""
    return name.split(" ")[0] in TERRAIN_NAMES


def generate(seed):
    """The scene of ``seed``: (Scene, a dict that describes it)."""
    rng = np.random.default_rng(seed)
    height = float(rng.uniform(1.0, 3.0))
    kind = ("flat", "sloped", "uneven")[int(rng.integers(3))]
    objects, points, placed = [], [], []
    if kind == "sloped":
        slope = math.tan(math.radians(rng.uniform(1.0, 4.0)))
        heading = rng.uniform(0, 2 * math.pi)
        terrain = Slope(0.0, slope * math.cos(heading), slope * math.sin(heading))
    else:
        terrain = Ground(0.0)
    objects.append(SceneObject("ground", terrain, GRASS))

    def ground_z(x, y):
        return float(terrain.height(x, y)) if isinstance(terrain, Slope) else 0.0

    def spot(radius, r_min=6.0, r_max=58.0, tries=200):
        """A free place (x, y) in the fan, ``radius`` clear of everything placed."""
        for _ in range(tries):
            r, az = rng.uniform(r_min, r_max), math.radians(rng.uniform(-HALF_FAN_DEG, HALF_FAN_DEG))
            x, y = r * math.cos(az), r * math.sin(az)
            if all(math.hypot(x - px, y - py) > radius + pr + 1.0 for px, py, pr in placed):
                placed.append((x, y, radius))
                return x, y
        return None

    def add(name, shape, material, point=None, rcs=None):
        objects.append(SceneObject(name, shape, material))
        if point is not None:
            points.append(PointScatterer(name, tuple(point), rcs, len(objects) - 1))

    if kind == "uneven":
        for k in range(int(rng.integers(3, 7))):
            where = spot(4.0, 8.0, 60.0)
            if where:
                radius = rng.uniform(2.5, 5.0)
                add(f"mound {k}", Sphere((*where, -radius + rng.uniform(0.2, 0.6)), radius), GRASS)
    for k in range(int(rng.integers(1, 3))):                       # walls, some as a corridor
        length, along_x = rng.uniform(4.0, 10.0), bool(rng.integers(2))
        where = spot(length / 2)
        if not where:
            continue
        x, y = where
        thick, top = rng.uniform(0.2, 0.3), rng.uniform(1.0, 3.0)
        z = ground_z(x, y) - 0.3
        half = np.array([length / 2, thick / 2]) if along_x else np.array([thick / 2, length / 2])
        add(f"wall {k}", _box((x - half[0], y - half[1], z), (x + half[0], y + half[1], z + 0.3 + top)), CONCRETE)
        if along_x and rng.random() < 0.5:                         # its twin across a corridor
            gap = rng.uniform(2.5, 4.0) + thick
            add(f"wall {k} twin", _box((x - half[0], y + gap - half[1], z), (x + half[0], y + gap + half[1], z + 0.3 + top)),
                CONCRETE)
            placed.append((x, y + gap, length / 2))
    for k in range(int(rng.integers(2, 6))):                       # posts
        where = spot(0.3)
        if where:
            z = ground_z(*where) - 0.2
            add(f"post {k}", Cylinder(where, rng.uniform(0.05, 0.15), z, z + 0.2 + rng.uniform(1.0, 3.0)), METAL)
    for k in range(int(rng.integers(0, 3))):                       # vehicles
        where = spot(2.6)
        if where:
            x, y = where
            z = ground_z(x, y) - 0.2
            half = (2.25, 0.9) if rng.random() < 0.5 else (0.9, 2.25)
            add(f"vehicle {k}", _box((x - half[0], y - half[1], z + 0.2), (x + half[0], y + half[1], z + 1.7)), METAL)
    for k in range(int(rng.integers(1, 5))):                       # trees
        crown = rng.uniform(1.5, 3.0)
        where = spot(crown)
        if where:
            z, tall = ground_z(*where), rng.uniform(3.5, 6.0)
            add(f"tree {k} trunk", Cylinder(where, rng.uniform(0.15, 0.35), z - 0.3, z + tall), BARK)
            add(f"tree {k} crown", Sphere((*where, z + tall + 0.6 * crown), crown), FOLIAGE)
    for k in range(int(rng.integers(1, 5))):                       # rocks
        radius = rng.uniform(0.4, 1.0)
        where = spot(radius)
        if where:
            add(f"rock {k}", Sphere((*where, ground_z(*where) - 0.3 * radius), radius), ROCK)
    for k in range(int(rng.integers(0, 3))):                       # drums, with their point echo
        where = spot(0.4)
        if where:
            x, y = where
            z = ground_z(x, y)
            add(f"drum {k}", Cylinder(where, 0.286, z - 0.1, z + 0.851), METAL, point=(x - 0.286, y, z + 0.43), rcs=10.0)
    scene = Scene(tuple(objects), tuple(points), (0.0, 0.0, ground_z(0.0, 0.0) + height))
    described = dict(seed=int(seed), sensor_height_m=round(height, 2), terrain=kind,
                     objects=[o.name for o in objects[1:] if not is_terrain(o.name)])
    return scene, described
