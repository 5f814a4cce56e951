"""The paper's outdoor scene (§4.3, Fig. 8b, Fig. 11) as analytic geometry with exact ground truth.

"A variety of objects, some on the fairly flat surface covered with grass; trees, a metal fence,
a 55-gallon drum, steel bars and rocks." The paper gives no layout, so this one is ours: every
object lies inside the radar's 64 deg x 64 m field of view from the stand at the origin, at
ranges of 9-55 m (the fence at 14 m and a tree at 23 m, as in Fig. 10b).

World frame: x forward from the stand, y left, z up, the grass at z = 0. The sensor head sits
``SENSOR_HEIGHT_M`` above the grass on a stand that tilts it about y. The grid is the paper's:
80 x 70 x 20 m at 0.1 m with the ground at mid-height (``paper_grid``).

Backscatter (our assumptions; the paper measured none). Surfaces follow the constant-gamma
clutter model, sigma0(theta_i) = gamma cos(theta_i) with theta_i the incidence angle from the
surface normal: a patch of projected solid angle returns less the more grazing the beam.
Objects much smaller than the beam footprint or specular (the drum, the bars) are point
scatterers with a radar cross-section (RCS) at their centre, visible where nothing occludes it.

Ground truth per voxel, exact at any voxel size (``truth``): FREE when the voxel holds only
air, OCCUPIED when it touches a solid without lying entirely inside one (a surface voxel),
INTERIOR when it lies entirely inside a solid (below the grass, inside a rock). A radar sees
surfaces, not the inside of the earth, so metrics leave INTERIOR voxels out (radarcl.evaluation.metrics).
"""

import math
from dataclasses import dataclass

import numpy as np

from radarcl.config.stage_config import PAPER_SENSOR_HEIGHT_M
from radarcl.errors import ConfigError
from radarcl.geometry import pose_from_xyz_rpy
from radarcl.gridspec import GridSpec
from radarcl.scene.shapes import Box, Cylinder, Ground, Sphere

FREE, OCCUPIED, INTERIOR = 0, 1, 2
# A voxel is the half-open box [lo, hi) (radarcl.grid): it touches a closed solid when they
# share a point, so the grass at z = 0 on a face between layers belongs to the layer above it
# and the layer below is INTERIOR. The tests shift both faces down by this fraction of the edge
# (touch) or shrink the box by it (inside), so that the rounding of origin + i * voxel cannot
# put a surface lying on a face into two layers or none.
FACE_EPS = 1e-6
SENSOR_HEIGHT_M = PAPER_SENSOR_HEIGHT_M
# §4.3: "15 elevations between -0.2 and -14.2 deg at intervals of one degree". We read each as
# the elevation of the LOWEST stacked beam, which makes -14.2 deg the radar's lowest elevation
# as §3.3 says ("the lowest elevation of the radar (-14 deg)"); the four beams then span
# t .. t + 6 deg, and the stand pitches the head's centre to t + 3 deg.
PAPER_TILTS_DEG = tuple(-14.2 + k for k in range(15))
FENCE_HEIGHT_M = 1.2


@dataclass(frozen=True)
class Material:
    """Backscatter of a surface: gamma [dB] of the constant-gamma model; ``specular`` for a
    smooth surface (``scene.observe.MULTIPATH``)."""

    name: str
    gamma_db: float
    specular: bool = False       # smooth: with MULTIPATH it returns only near normal incidence


GRASS = Material("grass", -15.0)
BARK = Material("bark", -10.0)
FOLIAGE = Material("foliage", -12.0)
ROCK = Material("rock", -10.0)
METAL = Material("metal", -3.0)          # diffuse part of the fence mesh and of the drum's surface


@dataclass(frozen=True)
class SceneObject:
    """One solid of the scene with its surface material."""

    name: str
    shape: object
    material: Material


@dataclass(frozen=True)
class PointScatterer:
    """A point echo of ``rcs_m2`` at ``position_m``, belonging to scene object ``owner`` (so
    that the object's own surface does not occlude it)."""

    name: str
    position_m: tuple
    rcs_m2: float
    owner: int


@dataclass(frozen=True)
class Scene:
    """Solids, point scatterers and where the sensor stands."""

    objects: tuple
    points: tuple
    sensor_m: tuple

    def first_hit(self, origins, dirs):
        """First surface each ray meets: (t [m], object index (-1 for none), outward normal)."""
        t = np.full(len(origins), np.inf)
        owner = np.full(len(origins), -1)
        normal = np.zeros_like(origins)
        for j, obj in enumerate(self.objects):
            tj, nj = obj.shape.intersect(origins, dirs)
            closer = tj < t
            t[closer], owner[closer], normal[closer] = tj[closer], j, nj[closer]
        return t, owner, normal

    def truth(self, spec: GridSpec):
        """uint8 (nz, ny, nx) labels FREE / OCCUPIED / INTERIOR of every voxel of ``spec``."""
        labels = np.zeros(spec.array_shape, np.uint8)
        origin, v = np.asarray(spec.origin_m), spec.voxel_m
        eps = FACE_EPS * v
        shape = np.asarray(spec.shape)
        for obj in self.objects:
            box = obj.shape.bounds()
            if box is None and isinstance(obj.shape, Ground):   # flat ground: layer by layer in z
                lo = np.zeros((spec.shape[2], 3))
                lo[:, 2] = origin[2] + np.arange(spec.shape[2]) * v
                touch, inside = _classify(obj.shape, lo, v, eps)
                labels[touch] = np.maximum(labels[touch], OCCUPIED)
                labels[inside] = INTERIOR
                continue
            if box is None:                                   # other terrain: every voxel, a layer at a time
                y, x = np.meshgrid(np.arange(spec.shape[1]), np.arange(spec.shape[0]), indexing="ij")
                lo = np.zeros((x.size, 3))
                lo[:, 0], lo[:, 1] = origin[0] + x.ravel() * v, origin[1] + y.ravel() * v
                for k in range(spec.shape[2]):
                    lo[:, 2] = origin[2] + k * v
                    touch, inside = _classify(obj.shape, lo, v, eps)
                    layer = labels[k].reshape(-1)
                    layer[touch] = np.maximum(layer[touch], OCCUPIED)
                    layer[inside] = INTERIOR
                continue
            i0 = np.clip(np.floor((box[0] - origin) / v).astype(int), 0, shape)
            i1 = np.clip(np.floor((box[1] - origin) / v).astype(int) + 1, 0, shape)
            if (i1 <= i0).any():
                continue                                      # outside the grid
            idx = np.stack(np.meshgrid(*[np.arange(a, b) for a, b in zip(i0, i1)], indexing="ij"), -1).reshape(-1, 3)
            touch, inside = _classify(obj.shape, origin + idx * v, v, eps)
            label = np.where(inside, INTERIOR, np.where(touch, OCCUPIED, FREE)).astype(np.uint8)
            view = labels[i0[2]:i1[2], i0[1]:i1[1], i0[0]:i1[0]]
            np.maximum(view, label.reshape(tuple(i1 - i0)).transpose(2, 1, 0), out=view)
        return labels

    def stand_pose(self, tilt_deg):
        """4x4 pose of the radar head for a lowest-beam elevation ``tilt_deg`` (see
        PAPER_TILTS_DEG): at the sensor position, pitched so the frame's centre points at
        tilt + 3 deg. Use with ``BeamLattice.from_radar(radar, tilt_deg=0)``."""
        if not -90.0 <= tilt_deg <= 84.0:
            raise ConfigError(f"tilt_deg must lie in [-90, 84] so that every beam points within "
                              f"+-90 deg of the horizon, got {tilt_deg}")
        centre = math.radians(tilt_deg + 3.0)
        return pose_from_xyz_rpy(*self.sensor_m, pitch=-centre)   # Ry(pitch): positive pitch is nose down


def _classify(shape, lo, v, eps):
    """(touches, inside) of the half-open voxels [lo, lo + v), robust to rounding (FACE_EPS)."""
    touch, _ = shape.classify(lo - eps, lo + v - eps)
    _, inside = shape.classify(lo + eps, lo + v - eps)
    return touch, inside


def paper_grid(voxel_m=0.1):
    """The paper's grid: 80 m along x (from 8 m behind the stand), 70 m across, 20 m high with
    the grass at mid-height; ``voxel_m`` cubes (the paper: 0.1 m)."""
    size = np.array([80.0, 70.0, 20.0])
    shape = tuple(int(n) for n in np.ceil(size / voxel_m - 1e-9))
    return GridSpec((-8.0, -35.0, -10.0), voxel_m, shape)


def paper_scene():
    """The reference scene: grass, four trees, a fence, a drum, three steel bars, four rocks."""
    objects = [SceneObject("grass", Ground(0.0), GRASS)]
    points = []

    def add(name, shape, material, rcs=None, at=None):
        objects.append(SceneObject(name, shape, material))
        if rcs is not None:
            points.append(PointScatterer(name, tuple(at), rcs, len(objects) - 1))

    # A metal fence across the view at 14 m (Fig. 10b: "a fence and a tree"), 1.2 m high. It was
    # 1.8 m, a solid wall above the 1.5 m stand that shadowed 43 deg of the 64 deg view; a real
    # mesh fence is partly transparent at 3.9 mm. The simulator's surfaces are opaque, so the
    # fence is lowered below the sensor instead: the radar sees over it, as it would see through
    # a mesh.
    add("fence", Box((14.0, -6.0, 0.0), (14.05, 5.0, FENCE_HEIGHT_M)), METAL)
    for k, (x, y, trunk_r, crown_r, height) in enumerate(((23.0, 2.0, 0.25, 2.2, 4.5), (35.0, -12.0, 0.3, 2.8, 5.5),
                                                          (47.0, 11.0, 0.2, 2.0, 4.0), (55.0, -24.0, 0.35, 3.0, 6.0))):
        add(f"tree {k} trunk", Cylinder((x, y), trunk_r, 0.0, height), BARK)
        add(f"tree {k} crown", Sphere((x, y, height + 0.6 * crown_r), crown_r), FOLIAGE)
    # A 55-gallon drum (0.572 m across, 0.851 m tall). Broadside it would be a 350 m^2 specular
    # cylinder, a few degrees off it far less; 10 m^2 is our aspect-averaged guess.
    add("drum", Cylinder((11.0, -4.0), 0.286, 0.0, 0.851), METAL, rcs=10.0, at=(11.0 - 0.286, -4.0, 0.43))
    # Steel bars lying in the grass (2 m long, 5 cm square), 1 m^2 each.
    for k, (x, y, along_x) in enumerate(((18.0, 7.0, False), (27.0, -7.0, True), (31.0, 3.0, False))):
        half = np.array([1.0, 0.025, 0.05]) if along_x else np.array([0.025, 1.0, 0.05])
        c = np.array([x, y, 0.025])
        add(f"bar {k}", Box(tuple(c - half * [1, 1, 0.5]), tuple(c + half * [1, 1, 0.5])), METAL, rcs=1.0,
            at=(x - 0.025, y, 0.05))
    # Rocks: balls half-buried in the grass.
    for k, (x, y, r) in enumerate(((9.0, 3.0, 0.5), (20.0, -10.0, 0.8), (40.0, -4.0, 1.0), (33.0, 15.0, 0.7))):
        add(f"rock {k}", Sphere((x, y, -0.3 * r), r), ROCK)
    return Scene(tuple(objects), tuple(points), (0.0, 0.0, SENSOR_HEIGHT_M))
