"""Solid primitives of the reference scene: ray intersection and exact voxel classification.

Every primitive is a closed solid in world coordinates (x, y, z [m], z up) with two
vectorised questions:

- ``intersect(origins, dirs)``: the first entry of each ray (unit ``dirs``) into the solid,
  as ``(t, normal)``: distance [m] (``inf`` for a miss) and the outward unit normal there. A
  ray starting inside a solid is not considered (the radar stands in free air).
- ``classify(lo, hi)``: for axis-aligned boxes [lo, hi) (voxels), whether the box touches the
  solid and whether it lies entirely inside it. Both tests are exact (closest / farthest point
  of the box), so ground truth holds at any voxel size.

``bounds()`` gives the solid's axis-aligned bounding box, or None for the unbounded ground,
so that truth is computed only where a solid can be.
"""

from dataclasses import dataclass

import numpy as np

from radarcl.errors import ConfigError

_NO_HIT = np.inf


def _positive(name, value):
    if not (np.isfinite(value) and value > 0):
        raise ConfigError(f"{name} must be a positive finite length, got {value!r}")


def _box_distance(centre, lo, hi):
    """Per-axis distance from ``centre`` (3,) to the nearest point of boxes (n, 3), and to the
    farthest corner."""
    near = np.maximum(np.maximum(lo - centre, centre - hi), 0.0)
    far = np.maximum(np.abs(lo - centre), np.abs(hi - centre))
    return near, far


@dataclass(frozen=True)
class Ground:
    """The half-space z <= ``height_m`` (the terrain, solid below its surface)."""

    height_m: float = 0.0

    def bounds(self):
        """None: the ground is unbounded."""
        return None

    def height(self, x, y):
        """Terrain height [m] at (x, y)."""
        return np.full(np.broadcast(np.asarray(x), np.asarray(y)).shape, float(self.height_m))

    def intersect(self, origins, dirs):
        """(t, normal) of the first entry of each ray; see the module docstring."""
        dz = dirs[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.height_m - origins[:, 2]) / dz
        t = np.where((dz < 0) & (origins[:, 2] > self.height_m) & (t > 0), t, _NO_HIT)
        normal = np.broadcast_to(np.array([0.0, 0.0, 1.0]), origins.shape)
        return t, normal

    def classify(self, lo, hi):
        """(touches, inside) for boxes [lo, hi)."""
        return lo[:, 2] <= self.height_m, hi[:, 2] <= self.height_m


@dataclass(frozen=True)
class Sphere:
    """A ball of ``radius_m`` around ``centre_m`` (rocks, crowns)."""

    centre_m: tuple
    radius_m: float

    def __post_init__(self):
        _positive("Sphere radius", self.radius_m)

    def bounds(self):
        """(lo, hi) bounding box [m]."""
        c = np.asarray(self.centre_m, float)
        return c - self.radius_m, c + self.radius_m

    def intersect(self, origins, dirs):
        """(t, normal) of the first entry of each ray; see the module docstring."""
        c = np.asarray(self.centre_m, float)
        oc = origins - c
        b = np.einsum("ij,ij->i", oc, dirs)
        disc = b * b - (np.einsum("ij,ij->i", oc, oc) - self.radius_m ** 2)
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(disc)
        t = np.where((disc >= 0) & (t > 0), t, _NO_HIT)
        hit = origins + np.where(np.isfinite(t), t, 0.0)[:, None] * dirs
        return t, (hit - c) / self.radius_m

    def classify(self, lo, hi):
        """(touches, inside) for boxes [lo, hi)."""
        near, far = _box_distance(np.asarray(self.centre_m, float), lo, hi)
        r2 = self.radius_m ** 2
        return (near ** 2).sum(axis=1) <= r2, (far ** 2).sum(axis=1) <= r2


@dataclass(frozen=True)
class Cylinder:
    """A vertical capped cylinder: axis at (x, y) = ``centre_xy_m``, ``radius_m``, from
    ``z0_m`` to ``z1_m`` (trunks, the drum)."""

    centre_xy_m: tuple
    radius_m: float
    z0_m: float
    z1_m: float

    def __post_init__(self):
        _positive("Cylinder radius", self.radius_m)
        if not self.z1_m > self.z0_m:
            raise ConfigError(f"Cylinder needs z1_m > z0_m, got {self.z0_m} and {self.z1_m}")

    def bounds(self):
        """(lo, hi) bounding box [m]."""
        cx, cy = self.centre_xy_m
        r = self.radius_m
        return np.array([cx - r, cy - r, self.z0_m]), np.array([cx + r, cy + r, self.z1_m])

    def intersect(self, origins, dirs):
        """(t, normal) of the first entry of each ray; see the module docstring."""
        c = np.asarray(self.centre_xy_m, float)
        o2, d2 = origins[:, :2] - c, dirs[:, :2]
        a = np.einsum("ij,ij->i", d2, d2)
        b = np.einsum("ij,ij->i", o2, d2)
        disc = b * b - a * (np.einsum("ij,ij->i", o2, o2) - self.radius_m ** 2)
        with np.errstate(invalid="ignore", divide="ignore"):
            t_side = (-b - np.sqrt(disc)) / a
        z_side = origins[:, 2] + t_side * dirs[:, 2]
        t_side = np.where((disc >= 0) & (a > 0) & (t_side > 0) & (z_side >= self.z0_m) & (z_side <= self.z1_m),
                          t_side, _NO_HIT)
        t = t_side
        normal = np.zeros_like(origins)
        side_xy = o2 + np.where(np.isfinite(t_side), t_side, 0.0)[:, None] * d2
        normal[:, :2] = side_xy / self.radius_m
        for z, sign in ((self.z1_m, 1.0), (self.z0_m, -1.0)):     # the caps, entered from outside
            with np.errstate(divide="ignore", invalid="ignore"):
                t_cap = (z - origins[:, 2]) / dirs[:, 2]
            p = o2 + np.where(np.isfinite(t_cap), t_cap, 0.0)[:, None] * d2
            ok = (sign * dirs[:, 2] < 0) & (t_cap > 0) & ((p ** 2).sum(axis=1) <= self.radius_m ** 2) & (t_cap < t)
            t = np.where(ok, t_cap, t)
            normal[ok] = (0.0, 0.0, sign)
        return t, normal

    def classify(self, lo, hi):
        """(touches, inside) for boxes [lo, hi)."""
        c = np.array([*self.centre_xy_m, 0.0])
        near, far = _box_distance(c, lo, hi)
        r2 = self.radius_m ** 2
        z_touch = (lo[:, 2] <= self.z1_m) & (hi[:, 2] > self.z0_m)
        z_inside = (lo[:, 2] >= self.z0_m) & (hi[:, 2] <= self.z1_m)
        return (z_touch & ((near[:, :2] ** 2).sum(axis=1) <= r2),
                z_inside & ((far[:, :2] ** 2).sum(axis=1) <= r2))


@dataclass(frozen=True)
class Box:
    """An axis-aligned box [lo_m, hi_m] (the fence, steel bars)."""

    lo_m: tuple
    hi_m: tuple

    def __post_init__(self):
        if not (np.asarray(self.hi_m, float) > np.asarray(self.lo_m, float)).all():
            raise ConfigError(f"Box needs hi_m > lo_m on every axis, got {self.lo_m} and {self.hi_m}")

    def bounds(self):
        """(lo, hi) bounding box [m]."""
        return np.asarray(self.lo_m, float), np.asarray(self.hi_m, float)

    def intersect(self, origins, dirs):
        """(t, normal) of the first entry of each ray (slab method); see the module docstring."""
        lo, hi = self.bounds()
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / dirs
            t0, t1 = (lo - origins) * inv, (hi - origins) * inv
        t0 = np.where(np.isnan(t0), -np.inf, t0)       # a ray in a slab's plane, parallel to it
        t1 = np.where(np.isnan(t1), np.inf, t1)
        t_near, t_far = np.minimum(t0, t1), np.maximum(t0, t1)
        axis = np.argmax(t_near, axis=1)
        enter, leave = t_near.max(axis=1), t_far.min(axis=1)
        t = np.where((enter <= leave) & (enter > 0), enter, _NO_HIT)
        normal = np.zeros_like(origins)
        rows = np.arange(len(origins))
        normal[rows, axis] = -np.sign(dirs[rows, axis])
        return t, normal

    def classify(self, lo, hi):
        """(touches, inside) for boxes [lo, hi)."""
        blo, bhi = self.bounds()
        return (lo <= bhi).all(axis=1) & (hi > blo).all(axis=1), (lo >= blo).all(axis=1) & (hi <= bhi).all(axis=1)


@dataclass(frozen=True)
class Slope:
    """Sloped terrain: the half-space z <= z0_m + gx x + gy y (gradients gx, gy, rise per metre)."""

    z0_m: float = 0.0
    gx: float = 0.0
    gy: float = 0.0

    def bounds(self):
        """None: the terrain is unbounded."""
        return None

    def height(self, x, y):
        """Terrain height [m] at (x, y)."""
        return self.z0_m + self.gx * np.asarray(x) + self.gy * np.asarray(y)

    def intersect(self, origins, dirs):
        """(t, normal) of the first entry of each ray; see the module docstring."""
        above = origins[:, 2] - self.height(origins[:, 0], origins[:, 1])
        rate = dirs[:, 2] - self.gx * dirs[:, 0] - self.gy * dirs[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -above / rate
        t = np.where((above > 0) & (rate < 0) & (t > 0), t, _NO_HIT)
        n = np.array([-self.gx, -self.gy, 1.0])
        return t, np.broadcast_to(n / np.linalg.norm(n), origins.shape)

    def classify(self, lo, hi):
        """(touches, inside) for boxes [lo, hi): the plane is linear, so its extremes over a box
        lie at corners."""
        top_lo = self.z0_m + np.maximum(self.gx * lo[:, 0], self.gx * hi[:, 0]) + np.maximum(self.gy * lo[:, 1],
                                                                                           self.gy * hi[:, 1])
        top_hi = self.z0_m + np.minimum(self.gx * lo[:, 0], self.gx * hi[:, 0]) + np.minimum(self.gy * lo[:, 1],
                                                                                           self.gy * hi[:, 1])
        return lo[:, 2] <= top_lo, hi[:, 2] <= top_hi
