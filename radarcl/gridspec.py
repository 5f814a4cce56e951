"""Where a grid lies and how its bricks are cut: ``GridSpec`` (numpy only, no device).

Convention (one place, used everywhere): index (ix, iy, iz) covers world points p with
``origin + i * voxel <= p < origin + (i + 1) * voxel``; its coordinates are those of its CENTRE,
``origin + (i + 0.5) * voxel``. Index tuples and ``shape`` are (x, y, z). Dense numpy
snapshots are (nz, ny, nx), x fastest: the layout of a GL 3D texture of size (nx, ny, nz).

Values are int32 in ``radarcl.logodds`` units (1/1024 nat). The grid stores exact integer sums
of eq. 9 updates (each update already clamped to +-16 nat), so a map does not depend on the
order of frames or beams. Sums saturate at +-``GRID_LIMIT`` (2^30 units, about 1e6 nat, where
p = 1 in float64 anyway); only there would the order matter. Views (``log_odds``,
``probability``) are computed from the sums on read.

Bricks are 8 x 8 x ``brick_z`` voxels (``BRICK_DEPTHS``): 8^3 in general, 8 x 8 x 1 for a planar
sensor. ``assemble`` and ``rebrick`` turn sparse bricks into dense arrays or other brick depths.
The grid on the device is ``radarcl.grid``; files are ``radarcl.maps``.
"""

import math
from dataclasses import dataclass

import numpy as np

from radarcl.errors import ConfigError, ShapeError

BRICK = 8                           # voxels per brick edge along x and y (and z for cubic bricks)
BRICK_DEPTHS = (8, 1)               # voxels per brick along z: 8^3 bricks, or 8 x 8 x 1 (planar)
BRICK_VOXELS = BRICK ** 3           # of a cubic brick (the default)
BRICK_BYTES = 4 * BRICK_VOXELS
GRID_LIMIT = 2 ** 30                # stored sums saturate here [units]
MAX_TABLE_BRICKS = 2 ** 28          # the host brick table (int32) stays below 1 GiB
MAX_EXTENT_M = 1e7                  # as far as a pose may lie (geometry.MAX_TRANSLATION_M)
MIN_VOXEL_M, MAX_VOXEL_M = 1e-4, 1e4


@dataclass(frozen=True)
class GridSpec:
    """Where the grid lies: ``origin_m`` (x, y, z) of its low corner [m], cubic voxels of
    ``voxel_m`` [m], ``shape`` (nx, ny, nz) voxels; ``brick_z``: voxels per brick along z (8, or
    1 for a planar sensor's 8 x 8 x 1 bricks), which gives brick keys their meaning."""

    origin_m: tuple
    voxel_m: float
    shape: tuple
    brick_z: int = BRICK

    def __post_init__(self):
        try:
            raw = np.asarray(self.origin_m)
            origin = tuple(float(v) for v in raw.reshape(-1)) if raw.dtype.kind in "iuf" else ()
        except (TypeError, ValueError):
            origin = ()
        if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
            raise ConfigError(f"origin_m must be 3 finite numbers, got {self.origin_m!r}")
        if isinstance(self.voxel_m, (bool, np.bool_)) or not (
                isinstance(self.voxel_m, (int, float, np.integer, np.floating)) and math.isfinite(self.voxel_m)
                and MIN_VOXEL_M <= self.voxel_m <= MAX_VOXEL_M):
            raise ConfigError(f"voxel_m must be a number in [{MIN_VOXEL_M:g}, {MAX_VOXEL_M:g}] m, got {self.voxel_m!r}")
        try:
            shape = tuple(self.shape)
        except TypeError:
            shape = ()
        if len(shape) != 3 or not all(isinstance(n, (int, np.integer)) and not isinstance(n, (bool, np.bool_))
                                      and n >= 1 for n in shape):
            raise ConfigError(f"shape must be 3 positive integers (nx, ny, nz), got {self.shape!r}")
        if isinstance(self.brick_z, (bool, np.bool_)) or self.brick_z not in BRICK_DEPTHS:
            raise ConfigError(f"brick_z must be one of {BRICK_DEPTHS} voxels, got {self.brick_z!r}")
        if max(shape) > 2 ** 20:
            raise ConfigError(f"shape {shape} exceeds 2^20 voxels along an axis")
        far = np.abs(np.asarray(origin)) + np.asarray(shape, np.float64) * float(self.voxel_m)
        if (far > MAX_EXTENT_M).any():
            raise ConfigError(f"the grid from {list(origin)} m, {shape} voxels of {float(self.voxel_m):g} m, reaches "
                              f"beyond +-{MAX_EXTENT_M:g} m; express it in a local frame near the sensor (as poses)")
        object.__setattr__(self, "origin_m", origin)
        object.__setattr__(self, "voxel_m", float(self.voxel_m))
        object.__setattr__(self, "shape", tuple(int(n) for n in shape))
        object.__setattr__(self, "brick_z", int(self.brick_z))

    @classmethod
    def around(cls, centre_m, size_m, voxel_m, brick_z=BRICK):
        """A grid of at least ``size_m`` (x, y, z) [m] centred on ``centre_m``."""
        try:
            size, centre, voxel = np.asarray(size_m, dtype=float), np.asarray(centre_m, dtype=float), float(voxel_m)
        except (TypeError, ValueError):
            raise ConfigError(f"GridSpec.around takes numbers: centre_m {centre_m!r}, size_m {size_m!r}, "
                              f"voxel_m {voxel_m!r}") from None
        if size.shape != (3,) or centre.shape != (3,) or not (np.isfinite(size).all() and np.isfinite(centre).all()
                                                              and math.isfinite(voxel) and voxel > 0):
            raise ConfigError(f"GridSpec.around needs finite (x, y, z) centre_m and size_m and a positive voxel_m, got "
                              f"{centre_m!r}, {size_m!r}, {voxel_m!r}")
        shape = tuple(int(n) for n in np.clip(np.ceil(size / voxel - 1e-9), 1, 2 ** 21))
        origin = centre - 0.5 * np.asarray(shape) * voxel
        return cls(tuple(origin), voxel, shape, brick_z)

    @property
    def brick(self):
        """Voxels per brick along (x, y, z)."""
        return BRICK, BRICK, self.brick_z

    @property
    def brick_data_shape(self):
        """Shape of one brick's data: (brick_z, 8, 8) [z, y, x]."""
        return self.brick_z, BRICK, BRICK

    @property
    def brick_bytes(self):
        """Bytes of one brick (int32)."""
        return 4 * BRICK * BRICK * self.brick_z

    @property
    def array_shape(self):
        """Shape of a dense snapshot: (nz, ny, nx)."""
        nx, ny, nz = self.shape
        return nz, ny, nx

    @property
    def n_voxels(self):
        """Voxels in the grid."""
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def brick_shape(self):
        """Bricks along (x, y, z); partial bricks at the high ends hold voxels outside the grid."""
        return tuple(-(-n // b) for n, b in zip(self.shape, self.brick))

    def check_brick_table(self):
        """The number of bricks, or ConfigError when the host's brick table cannot hold them."""
        n_total = int(np.prod(self.brick_shape, dtype=np.int64))
        if n_total > MAX_TABLE_BRICKS:
            raise ConfigError(f"a grid of {self.shape} voxels of {self.voxel_m:g} m has {n_total} bricks, more "
                              f"than the {MAX_TABLE_BRICKS} a brick table holds; use voxels of at least "
                              f"{self.voxel_m * (n_total / MAX_TABLE_BRICKS) ** (1 / 3):.3g} m or a smaller grid")
        return n_total

    @property
    def dense_bytes(self):
        """Bytes of the grid stored densely as int32."""
        return 4 * self.n_voxels

    def world_to_index(self, points):
        """(..., 3) world points [m] -> (..., 3) int64 voxel indices floor((p - origin) / voxel),
        possibly outside the grid (see ``contains``, ``world_to_index_checked``)."""
        p = np.asarray(points, dtype=np.float64)
        return np.floor((p - np.asarray(self.origin_m)) / self.voxel_m).astype(np.int64)

    def index_to_world(self, index):
        """(..., 3) voxel indices -> (..., 3) world coordinates [m] of the voxel centres."""
        return np.asarray(self.origin_m) + (np.asarray(index, dtype=np.float64) + 0.5) * self.voxel_m

    def brick_voxels(self, bricks):
        """(n, 3) int64 indices (x, y, z) of the voxels of ``bricks`` (m, >= 3) (bx, by, bz, ...)
        that lie inside the grid (partial bricks at the high ends hold voxels outside it)."""
        b = np.asarray(bricks)[:, :3].astype(np.int64)
        offsets = np.stack(np.meshgrid(*[np.arange(n) for n in self.brick], indexing="ij"), -1).reshape(-1, 3)
        index = (b[:, None, :] * np.asarray(self.brick) + offsets[None]).reshape(-1, 3)
        return index[self.contains(index)]

    def contains(self, index):
        """(...,) bool: index inside the grid."""
        i = np.asarray(index)
        return ((i >= 0) & (i < np.asarray(self.shape))).all(axis=-1)

    def world_to_index_checked(self, points):
        """As ``world_to_index``, but ConfigError names the first point outside the grid."""
        p = np.asarray(points, dtype=np.float64)
        if not np.isfinite(p).all():
            raise ConfigError("points must be finite")
        index = self.world_to_index(p)
        inside = self.contains(index)
        if not inside.all():
            bad = p.reshape(-1, 3)[np.flatnonzero(~inside.reshape(-1))[0]]
            upper = np.asarray(self.origin_m) + np.asarray(self.shape) * self.voxel_m
            raise ConfigError(f"point {bad.tolist()} lies outside the grid [{list(self.origin_m)}, "
                              f"{upper.tolist()}) m")
        return index


def assemble(spec, keys, data):
    """Dense int32 (nz, ny, nx) array from bricks (keys (n, 3) (bx, by, bz), data (n, *brick))."""
    check_bricks(spec, keys, data)
    nbx, nby, nbz = spec.brick_shape
    bz = spec.brick_z
    full = np.zeros((nbz * bz, nby * BRICK, nbx * BRICK), np.int32)
    view = full.reshape(nbz, bz, nby, BRICK, nbx, BRICK).transpose(0, 2, 4, 1, 3, 5)
    if len(keys):
        view[keys[:, 2], keys[:, 1], keys[:, 0]] = data
    nz, ny, nx = spec.array_shape
    return np.ascontiguousarray(full[:nz, :ny, :nx])


def check_bricks(spec, keys, data):
    """ShapeError unless ``data`` holds one brick of ``spec``'s shape per key."""
    if np.shape(data) != (len(keys), *spec.brick_data_shape):
        raise ShapeError(f"expected bricks of shape ({len(keys)}, {', '.join(map(str, spec.brick_data_shape))}), "
                         f"got {np.shape(data)}")


def rebrick(spec, keys, data, brick_z):
    """The same map in bricks of depth ``brick_z``: (spec', keys', data') holding the same
    voxels (a planar map read as 8^3 bricks, or back). Voxels beyond the grid stay 0."""
    check_bricks(spec, keys, data)
    target = GridSpec(spec.origin_m, spec.voxel_m, spec.shape, brick_z)
    if brick_z == spec.brick_z:
        return target, keys, data
    keys = np.asarray(keys, np.int64)
    z0 = keys[:, 2] * spec.brick_z                              # first voxel layer of each brick
    if brick_z > spec.brick_z:                                  # many thin bricks into one deep one
        new_keys, inverse = np.unique(np.column_stack([keys[:, :2], z0 // brick_z]), axis=0, return_inverse=True)
        out = np.zeros((len(new_keys), brick_z, BRICK, BRICK), np.int32)
        for layer in range(spec.brick_z):
            out[inverse.reshape(-1), (z0 + layer) % brick_z] = data[:, layer]
        return target, new_keys.astype(np.int32), out
    parts = spec.brick_z // brick_z                             # one deep brick into thin ones
    new_keys = np.repeat(keys, parts, axis=0)
    new_keys[:, 2] = (z0[:, None] // brick_z + np.arange(parts)[None]).reshape(-1)
    out = np.ascontiguousarray(data).reshape(len(keys) * parts, brick_z, BRICK, BRICK)
    inside = new_keys[:, 2] * brick_z < spec.shape[2]
    keep = inside & (out.reshape(len(out), -1) != 0).any(axis=1)
    return target, new_keys[keep].astype(np.int32), out[keep]


def lattice_box(lo, hi, voxel_m, axes=3):
    """(origin_m, size_m) of the smallest box holding [lo, hi] (per axis, metres) whose origin is
    a whole number of voxels on its first ``axes`` axes: on the lattice that starts at 0, as
    OctoMap's does, so a map of a default grid exports to OctoMap voxel for voxel. Axes beyond
    ``axes`` keep ``lo`` and their size ``hi - lo``."""
    v = float(voxel_m)
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    snapped_lo = np.where(np.arange(len(lo)) < axes, np.floor(lo / v + 1e-9) * v, lo)
    snapped_hi = np.where(np.arange(len(hi)) < axes, np.ceil(hi / v - 1e-9) * v, hi)
    origin = tuple(round(float(x), 9) + 0.0 for x in snapped_lo)
    return origin, tuple(round(float(x), 9) for x in snapped_hi - snapped_lo)
