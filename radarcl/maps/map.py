"""A map as data: open an ``.npz`` map or a map store and query it with numpy (no device).

What users ask mapping libraries for (OctoMap's Python bindings, nvblox's queries): log-odds
and probability at world points, the occupied voxels as an (N, 3) array, a horizontal slice, a
2D occupancy projection over a height band (the costmap of a ground robot).

Values are the grid's exact int32 sums in ``radarcl.logodds`` units; the views convert to
nats or probabilities. A voxel no beam reached holds 0 (unknown: probability 0.5).
"""

from dataclasses import dataclass

import numpy as np

from radarcl import logodds
from radarcl.errors import ConfigError, ShapeError
from radarcl.grid import BRICK, GRID_LIMIT, GridSpec
from radarcl.io.files import memory_budget
from radarcl.maps.disk import read_salvaged

UNKNOWN = -1          # a 2D cell no beam reached in the band (the ROS map_server convention)


@dataclass
class Map:
    """A sparse map: ``spec`` (GridSpec), ``keys`` (n, 3) int32 bricks (bx, by, bz) and ``data``
    (n, 8, 8, 8) int32 [z, y, x] in logodds units."""

    spec: GridSpec
    keys: np.ndarray
    data: np.ndarray

    lost: list = None          # bricks a salvaged store could not give (``maps.disk.read_salvaged``)

    @classmethod
    def open(cls, path, salvage=False):
        """Read a map file or store (``maps.disk.read``; with ``salvage``, a damaged store's
        intact bricks, the lost ones listed in ``lost``)."""
        spec, keys, data, lost = read_salvaged(path, salvage)
        return cls(spec, keys, data, lost)

    @classmethod
    def of_grid(cls, grid):
        """The map held by an ``EvidenceGrid`` (copied from the device)."""
        keys, data = grid.bricks()
        return cls(grid.spec, keys, data)

    def __post_init__(self):
        if not isinstance(self.spec, GridSpec):
            raise ShapeError(f"spec must be a GridSpec, got {type(self.spec).__name__}")
        self.keys, self.data = np.asarray(self.keys), np.asarray(self.data)
        if self.keys.ndim != 2 or self.keys.shape[1:] != (3,) or self.keys.dtype.kind not in "iu":
            raise ShapeError(f"expected brick keys (n, 3) integers, got {self.keys.shape} {self.keys.dtype}")
        if self.data.shape != (len(self.keys), BRICK, BRICK, BRICK) or self.data.dtype != np.int32:
            raise ShapeError(f"expected bricks ({len(self.keys)}, 8, 8, 8) int32, got {self.data.shape} "
                             f"{self.data.dtype}")
        k = self.keys.astype(np.int64)
        self._ids = (k[:, 2] << 42) | (k[:, 1] << 21) | k[:, 0]
        self._order = np.argsort(self._ids)

    # -- point queries --------------------------------------------------------------------------------
    def units_at(self, points):
        """int32 logodds units at world points (..., 3) [m]: 0 where no beam reached, and for
        points outside the grid (``inside`` tells them apart)."""
        p = _points(points)
        if not np.isfinite(p).all():
            raise ConfigError("points must be finite")
        idx = self.spec.world_to_index(p.reshape(-1, 3))
        out = np.zeros(len(idx), np.int32)
        ok = self.spec.contains(idx)
        if ok.any() and len(self.keys):
            i = idx[ok]
            b = i // BRICK
            ids = (b[:, 2] << 42) | (b[:, 1] << 21) | b[:, 0]
            pos = np.minimum(np.searchsorted(self._ids[self._order], ids), len(self._order) - 1)
            row = self._order[pos]
            hit = self._ids[row] == ids
            local = i[hit] % BRICK
            vals = np.zeros(len(i), np.int32)
            vals[hit] = self.data[row[hit], local[:, 2], local[:, 1], local[:, 0]]
            out[ok] = vals
        return out.reshape(p.shape[:-1])

    def inside(self, points):
        """(...,) bool: points inside the grid."""
        return self.spec.contains(self.spec.world_to_index(_points(points)))

    def log_odds_at(self, points):
        """Log-odds [nat] at world points (..., 3); NaN outside the grid."""
        nats = logodds.to_nats(self.units_at(points))
        return np.where(self.inside(points), nats, np.nan)

    def probability_at(self, points):
        """Occupancy probability at world points (..., 3); NaN outside the grid."""
        return 1.0 / (1.0 + np.exp(-self.log_odds_at(points)))

    # -- voxel sets --------------------------------------------------------------------------------------
    def voxels(self, lo_nats=None, hi_nats=None):
        """(indices (N, 3) int64 (x, y, z), units (N,) int32) of the observed voxels (non-zero)
        whose log-odds lie in [lo_nats, hi_nats] (None: unbounded), inside the grid."""
        lo_nats = None if lo_nats is None else _number(lo_nats, "lo_nats", infinite=True)
        hi_nats = None if hi_nats is None else _number(hi_nats, "hi_nats", infinite=True)
        if not len(self.keys):
            return np.zeros((0, 3), np.int64), np.zeros(0, np.int32)
        keep = self.data != 0
        if lo_nats is not None:
            keep &= self.data >= lo_nats * logodds.SCALE
        if hi_nats is not None:
            keep &= self.data <= hi_nats * logodds.SCALE
        b, z, y, x = np.nonzero(keep)
        idx = self.keys[b].astype(np.int64) * BRICK + np.stack([x, y, z], axis=1)
        inside = self.spec.contains(idx)
        return idx[inside], self.data[b, z, y, x][inside]

    def occupied(self, threshold_nats=1.0):
        """(centres (N, 3) [m], log-odds (N,) [nat]) of the voxels above ``threshold_nats``."""
        idx, units = self.voxels(lo_nats=_number(threshold_nats, "threshold_nats"))
        return self.spec.index_to_world(idx), logodds.to_nats(units)

    def dense(self, band=None):
        """Dense int32 (nz, ny, nx) units; ``band`` (z_min, z_max) [m] keeps only those layers.
        Refused beyond the memory budget."""
        z0, z1 = self._band(band)
        nx, ny, _ = self.spec.shape
        nbx, nby, _ = self.spec.brick_shape
        b0, b1 = z0 // BRICK, (z1 - 1) // BRICK + 1                 # the brick layers the band touches
        if 4.0 * nbx * nby * (b1 - b0) * BRICK ** 3 > memory_budget():
            raise ConfigError(f"a dense copy of {nx} x {ny} x {z1 - z0} voxels exceeds the memory budget; "
                              "narrow the band")
        slab = np.zeros(((b1 - b0) * BRICK, nby * BRICK, nbx * BRICK), np.int32)
        view = slab.reshape(b1 - b0, BRICK, nby, BRICK, nbx, BRICK).transpose(0, 2, 4, 1, 3, 5)
        sel = (self.keys[:, 2] >= b0) & (self.keys[:, 2] < b1)      # whole bricks, no voxel lists
        k = self.keys[sel]
        view[k[:, 2] - b0, k[:, 1], k[:, 0]] = self.data[sel]
        return np.ascontiguousarray(slab[z0 - b0 * BRICK:z1 - b0 * BRICK, :ny, :nx])

    def _band(self, band):
        nz = self.spec.shape[2]
        if band is None:
            return 0, nz
        try:
            lo, hi = (float(v) for v in band)
        except (TypeError, ValueError):
            raise ConfigError(f"the height band must be two numbers z_min < z_max [m], got {band!r}") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise ConfigError(f"the height band must be two finite numbers z_min < z_max [m], got {band!r}")
        oz, v = self.spec.origin_m[2], self.spec.voxel_m
        z0 = int(np.clip(np.floor((lo - oz) / v + 0.5), 0, nz))     # layers whose centre lies in the band
        z1 = int(np.clip(np.floor((hi - oz) / v + 0.5), 0, nz))
        if z1 <= z0:
            raise ConfigError(f"the band [{lo}, {hi}] m holds no voxel centre of the grid "
                              f"(z from {oz} to {oz + nz * v} m)")
        return z0, z1

    def slice(self, z_m):
        """Log-odds [nat] (ny, nx) of the layer whose voxels contain height ``z_m``."""
        z = _number(z_m, "z_m")
        k = np.floor((z - self.spec.origin_m[2]) / self.spec.voxel_m)
        if not 0 <= k < self.spec.shape[2]:
            raise ConfigError(f"z = {z_m} m lies outside the grid")
        top = self.spec.origin_m[2] + (int(k) + 0.5) * self.spec.voxel_m
        return logodds.to_nats(self.dense((top - 0.25 * self.spec.voxel_m, top + 0.25 * self.spec.voxel_m))[0])

    def column_extremes(self):
        """Log-odds [nat] (ny, nx) of each column's most telling observed voxel, seen from
        above: its largest value when that is positive (something occupied somewhere above the
        cell), else its smallest (how free the column is); 0 where no voxel of the column was
        observed. Brick by brick: never the dense volume."""
        ny, nx = self.spec.shape[1], self.spec.shape[0]
        nby, nbx = -(-ny // BRICK), -(-nx // BRICK)
        hi = np.zeros((nby, nbx, BRICK, BRICK), np.int64)
        lo = np.zeros((nby, nbx, BRICK, BRICK), np.int64)
        if len(self.keys):
            inside = self.keys[:, 2, None] * BRICK + np.arange(BRICK) < self.spec.shape[2]     # a top brick's overhang
            d = np.where(inside[:, :, None, None], self.data, 0).astype(np.int64)
            np.maximum.at(hi, (self.keys[:, 1], self.keys[:, 0]), d.max(axis=1))
            np.minimum.at(lo, (self.keys[:, 1], self.keys[:, 0]), d.min(axis=1))
        best = np.where(hi > 0, hi, lo).transpose(0, 2, 1, 3).reshape(nby * BRICK, nbx * BRICK)[:ny, :nx]
        return logodds.to_nats(best)

    def projection(self, band=None, threshold_nats=1.0):
        """A 2D occupancy grid over a height band, int8 (ny, nx) in the ROS map_server
        convention: 100 occupied (some observed voxel of the column above ``threshold_nats``), 0
        free (every observed voxel of the column below -``threshold_nats``), 50 between, -1
        unknown (no voxel of the column observed)."""
        threshold_nats = _number(threshold_nats, "threshold_nats")
        d = self.dense(band)
        seen = (d != 0).any(axis=0)
        top = np.where(d != 0, d, np.iinfo(np.int32).min).max(axis=0)     # over observed voxels only
        t = int(np.rint(np.clip(threshold_nats * logodds.SCALE, -GRID_LIMIT, GRID_LIMIT)))   # beyond: all or nothing
        out = np.full(top.shape, 50, np.int8)
        out[top > t] = 100
        out[seen & (top < -t)] = 0
        out[~seen] = UNKNOWN
        return out


def _points(points):
    """World points (..., 3) [m] as float64; ShapeError for anything but real numbers of that shape."""
    p = np.asarray(points)
    if p.dtype.kind not in "iuf" or p.shape[-1:] != (3,):
        raise ShapeError(f"points must be real numbers (..., 3) [m], got {p.shape} {p.dtype}")
    return p.astype(np.float64)


def _number(value, name, infinite=False):
    """``value`` as a float: a real number (numpy scalars too), finite unless ``infinite``; never NaN."""
    try:
        if isinstance(value, (bool, np.bool_, complex, np.complexfloating, str, bytes)):
            raise TypeError
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a number, got {value!r}") from None
    if np.isnan(x) or (not infinite and not np.isfinite(x)):
        raise ConfigError(f"{name} must be a {'' if infinite else 'finite '}number, got {value!r}")
    return x
