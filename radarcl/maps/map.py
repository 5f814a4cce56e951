"""A map as data: open an ``.npz`` map or a map store and query it with numpy (no device).

What users ask mapping libraries for (OctoMap's Python bindings, nvblox's queries): log-odds
and probability at world points, the occupied voxels as an (N, 3) array, a horizontal slice, a
2D occupancy projection over a height band (the costmap of a ground robot).

Values are the grid's exact int32 sums in ``radarcl.logodds`` units; the views convert to
nats or probabilities. A voxel no beam reached holds 0 (unknown: probability 0.5).

A map of the detection-statistics model (``radarcl.sensor_model``) also holds the knowledge
channel: per voxel the summed detection opportunity of its looks (``knowledge_at``, in looks),
and is read through its reading (``sensor_model.read_log_odds``: correlated looks counted once,
the prior where the radar looked). Every log-odds query returns that reading; ``state_at`` tells
"never observed" (UNKNOWN: knowledge below ``KNOWN_LOOKS``) from "observed, undecided"
(UNDECIDED: known, within the threshold of 0). A map without knowledge (eq. 12) reads its sums
as they are, and a voxel no beam reached is its UNKNOWN.
"""

from dataclasses import dataclass

import numpy as np

from radarcl import logodds, sensor_model
from radarcl.errors import ConfigError, ShapeError
from radarcl.grid import BRICK, GridSpec
from radarcl.io.files import memory_budget
from radarcl.maps.disk import read_channels

UNKNOWN = -1          # a 2D cell no beam reached in the band (the ROS map_server convention)
# Voxel states (``state_at``), in the codes of ``projection`` (ROS OccupancyGrid's, 50 between)
FREE, UNDECIDED, OCCUPIED = 0, 50, 100
KNOWN_LOOKS = 0.5     # a voxel whose knowledge reaches this many looks is known


@dataclass
class Map:
    """A sparse map: ``spec`` (GridSpec), ``keys`` (n, 3) int32 bricks (bx, by, bz) and ``data``
    (n, 8, 8, 8) int32 [z, y, x] in logodds units; for the detection-statistics model also
    ``knowledge`` (n, 8, 8, 8) int32 [``logodds.KNOWLEDGE_SCALE`` units], ``looks`` (n, 8, 8, 8)
    int32 counts and its ``reading`` (a dict, ``sensor_model.READING``)."""

    spec: GridSpec
    keys: np.ndarray
    data: np.ndarray
    knowledge: np.ndarray = None
    looks: np.ndarray = None
    reading: dict = None

    @classmethod
    def open(cls, path):
        """Read a map file or store (``maps.disk.read_channels``)."""
        spec, keys, data, channels = read_channels(path)
        if channels is None:
            return cls(spec, keys, data)
        return cls(spec, keys, data, channels.knowledge, channels.looks, channels.reading)

    @classmethod
    def of_grid(cls, grid, reading=None):
        """The map held by an ``EvidenceGrid`` (copied from the device); a grid with the knowledge
        channel needs its ``reading`` (``maps.disk.reading_of``)."""
        keys, data = grid.bricks()
        if not grid.has_knowledge:
            return cls(grid.spec, keys, data)
        if reading is None:
            raise ConfigError("a grid with the knowledge channel is read with its reading: Map.of_grid(grid, reading)")
        return cls(grid.spec, keys, data, grid.knowledge_bricks(), grid.knowledge_bricks("looks"), reading)

    def __post_init__(self):
        if self.data.shape != (len(self.keys), BRICK, BRICK, BRICK):
            raise ShapeError(f"expected bricks ({len(self.keys)}, 8, 8, 8), got {self.data.shape}")
        if not ((self.knowledge is None) == (self.looks is None) == (self.reading is None)):
            raise ConfigError("a map's knowledge comes with its looks and its reading, and only with them")
        for name in ("knowledge", "looks"):
            if getattr(self, name) is not None and np.shape(getattr(self, name)) != self.data.shape:
                raise ShapeError(f"expected {name} bricks {self.data.shape}, got {np.shape(getattr(self, name))}")
        k = self.keys.astype(np.int64)
        self._ids = (k[:, 2] << 42) | (k[:, 1] << 21) | k[:, 0]
        self._order = np.argsort(self._ids)
        self._nats = None

    @property
    def has_knowledge(self):
        """True for a map of the detection-statistics model (knowledge channel and reading)."""
        return self.knowledge is not None

    def nats(self):
        """(n, 8, 8, 8) float64 log-odds of the bricks as the map reads them (computed once)."""
        if self._nats is None:
            self._nats = (sensor_model.read_log_odds(self.data, self.knowledge, self.looks, self.reading)
                          if self.has_knowledge
                          else logodds.to_nats(self.data))
        return self._nats

    def known(self):
        """(n, 8, 8, 8) bool: voxels the map knows (knowledge of ``KNOWN_LOOKS`` looks or more;
        without knowledge: any evidence at all)."""
        if self.has_knowledge:
            return self.knowledge >= KNOWN_LOOKS * logodds.KNOWLEDGE_SCALE
        return self.data != 0

    # -- point queries --------------------------------------------------------------------------------
    def units_at(self, points, channel="data"):
        """int32 stored sums at world points (..., 3) [m] (logodds units; ``channel="knowledge"`` or
        ``"looks"``: those channels'): 0 where no beam reached, and for points outside the grid
        (``inside`` tells them apart)."""
        source = {"data": self.data, "knowledge": self.knowledge, "looks": self.looks}[channel]
        if source is None:
            raise ConfigError("this map has no knowledge channel (made with eq. 12, not the detection-statistics model)")
        return self._at(points, source)

    def _at(self, points, source):
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ShapeError(f"points must be (..., 3) [m], got {p.shape}")
        if not np.isfinite(p).all():
            raise ConfigError("points must be finite")
        idx = self.spec.world_to_index(p.reshape(-1, 3))
        out = np.zeros(len(idx), source.dtype)
        ok = self.spec.contains(idx)
        if ok.any() and len(self.keys):
            i = idx[ok]
            b = i // BRICK
            ids = (b[:, 2] << 42) | (b[:, 1] << 21) | b[:, 0]
            pos = np.minimum(np.searchsorted(self._ids[self._order], ids), len(self._order) - 1)
            row = self._order[pos]
            hit = self._ids[row] == ids
            local = i[hit] % BRICK
            vals = np.zeros(len(i), source.dtype)
            vals[hit] = source[row[hit], local[:, 2], local[:, 1], local[:, 0]]
            out[ok] = vals
        return out.reshape(p.shape[:-1])

    def inside(self, points):
        """(...,) bool: points inside the grid."""
        return self.spec.contains(self.spec.world_to_index(np.asarray(points, dtype=np.float64)))

    def log_odds_at(self, points):
        """Log-odds [nat] at world points (..., 3), as the map reads them; NaN outside the grid."""
        if self.has_knowledge:
            nats = sensor_model.read_log_odds(self.units_at(points), self.units_at(points, "knowledge"),
                                              self.units_at(points, "looks"), self.reading)
        else:
            nats = logodds.to_nats(self.units_at(points))
        return np.where(self.inside(points), nats, np.nan)

    def knowledge_at(self, points):
        """Knowledge [looks] at world points (..., 3): the summed detection opportunity of the
        looks at the voxel (0: never observed); NaN outside the grid. A map without the knowledge
        channel refuses (ConfigError)."""
        looks = self.units_at(points, "knowledge") / float(logodds.KNOWLEDGE_SCALE)
        return np.where(self.inside(points), looks, np.nan)

    def state_at(self, points, threshold_nats=1.0):
        """int8 state at world points (..., 3): ``UNKNOWN`` (never observed, or outside the grid),
        else ``OCCUPIED`` above ``threshold_nats``, ``FREE`` below its negative, ``UNDECIDED``
        between."""
        nats = self.log_odds_at(points)
        if self.has_knowledge:
            known = self.units_at(points, "knowledge") >= KNOWN_LOOKS * logodds.KNOWLEDGE_SCALE
        else:
            known = self.units_at(points) != 0
        out = np.full(nats.shape, UNDECIDED, np.int8)
        out[nats > threshold_nats] = OCCUPIED
        out[nats < -threshold_nats] = FREE
        out[~(known & self.inside(points))] = UNKNOWN
        return out

    def probability_at(self, points):
        """Occupancy probability at world points (..., 3); NaN outside the grid."""
        return 1.0 / (1.0 + np.exp(-self.log_odds_at(points)))

    # -- voxel sets --------------------------------------------------------------------------------------
    def voxels(self, lo_nats=None, hi_nats=None, with_knowledge=False):
        """(indices (N, 3) int64 (x, y, z), units (N,) int32) of the observed voxels (non-zero
        sums; with the knowledge channel: known ones) whose log-odds as read lie in
        [lo_nats, hi_nats] (None: unbounded), inside the grid. ``units`` are the read log-odds in
        logodds units (the stored sums for a map without knowledge); ``with_knowledge`` adds
        their knowledge [looks] as a third array."""
        if not len(self.keys):
            empty = (np.zeros((0, 3), np.int64), np.zeros(0, np.int32))
            return empty + ((np.zeros(0),) if with_knowledge else ())
        keep = self.known() if self.has_knowledge else self.data != 0
        nats = self.nats()
        if lo_nats is not None:
            keep &= nats >= lo_nats
        if hi_nats is not None:
            keep &= nats <= hi_nats
        b, z, y, x = np.nonzero(keep)
        idx = self.keys[b].astype(np.int64) * BRICK + np.stack([x, y, z], axis=1)
        inside = self.spec.contains(idx)
        units = self.data[b, z, y, x] if not self.has_knowledge else logodds.to_fixed(nats[b, z, y, x])
        out = (idx[inside], units[inside])
        if with_knowledge:
            looks = (self.knowledge[b, z, y, x] / float(logodds.KNOWLEDGE_SCALE) if self.has_knowledge
                     else np.full(len(b), np.nan))
            out += (looks[inside],)
        return out

    def occupied(self, threshold_nats=1.0):
        """(centres (N, 3) [m], log-odds (N,) [nat]) of the voxels above ``threshold_nats``."""
        idx, units = self.voxels(lo_nats=threshold_nats)
        return self.spec.index_to_world(idx), logodds.to_nats(units)

    def read_units(self):
        """(n, 8, 8, 8) int32 log-odds units as the map reads them: the stored sums, or for a map
        with knowledge its reading rounded to logodds units."""
        return logodds.to_fixed(self.nats()) if self.has_knowledge else self.data

    def dense(self, band=None):
        """Dense int32 (nz, ny, nx) log-odds units as the map reads them (``read_units``); ``band``
        (z_min, z_max) [m] keeps only those layers. Refused beyond the memory budget."""
        return self._dense(self.read_units(), band)

    def dense_knowledge(self, band=None):
        """Dense float64 (nz, ny, nx) knowledge [looks] (0: never observed), or None for a map
        without the knowledge channel; ``band`` as ``dense``."""
        if not self.has_knowledge:
            return None
        return self._dense(self.knowledge, band) / float(logodds.KNOWLEDGE_SCALE)

    def _dense(self, bricks, band):
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
        view[k[:, 2] - b0, k[:, 1], k[:, 0]] = bricks[sel]
        return np.ascontiguousarray(slab[z0 - b0 * BRICK:z1 - b0 * BRICK, :ny, :nx])

    def _band(self, band):
        nz = self.spec.shape[2]
        if band is None:
            return 0, nz
        lo, hi = (float(v) for v in band)
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
        k = int(np.floor((float(z_m) - self.spec.origin_m[2]) / self.spec.voxel_m))
        if not 0 <= k < self.spec.shape[2]:
            raise ConfigError(f"z = {z_m} m lies outside the grid")
        top = self.spec.origin_m[2] + (k + 0.5) * self.spec.voxel_m
        return logodds.to_nats(self.dense((top - 0.25 * self.spec.voxel_m, top + 0.25 * self.spec.voxel_m))[0])

    def column_extremes(self):
        """Log-odds [nat] (ny, nx) of each column's most telling observed voxel, seen from
        above: its largest value when that is positive (something occupied somewhere above the
        cell), else its smallest (how free the column is); 0 where no voxel of the column was
        observed (for a map with knowledge: none is known). Brick by brick: never the dense volume."""
        ny, nx = self.spec.shape[1], self.spec.shape[0]
        nby, nbx = -(-ny // BRICK), -(-nx // BRICK)
        hi = np.zeros((nby, nbx, BRICK, BRICK), np.int64)
        lo = np.zeros((nby, nbx, BRICK, BRICK), np.int64)
        if len(self.keys):
            inside = self.keys[:, 2, None] * BRICK + np.arange(BRICK) < self.spec.shape[2]     # a top brick's overhang
            d = np.where(inside[:, :, None, None] & self.known(), self.read_units(), 0).astype(np.int64)
            np.maximum.at(hi, (self.keys[:, 1], self.keys[:, 0]), d.max(axis=1))
            np.minimum.at(lo, (self.keys[:, 1], self.keys[:, 0]), d.min(axis=1))
        best = np.where(hi > 0, hi, lo).transpose(0, 2, 1, 3).reshape(nby * BRICK, nbx * BRICK)[:ny, :nx]
        return logodds.to_nats(best)

    def known_columns(self):
        """bool (ny, nx): the columns holding a voxel the map knows (``known``), brick by brick;
        for the top-down pictures, which draw the others as unknown, apart from free."""
        ny, nx = self.spec.shape[1], self.spec.shape[0]
        nby, nbx = -(-ny // BRICK), -(-nx // BRICK)
        out = np.zeros((nby, nbx, BRICK, BRICK), bool)
        if len(self.keys):
            inside = self.keys[:, 2, None] * BRICK + np.arange(BRICK) < self.spec.shape[2]
            np.logical_or.at(out, (self.keys[:, 1], self.keys[:, 0]), (inside[:, :, None, None] & self.known()).any(axis=1))
        return out.transpose(0, 2, 1, 3).reshape(nby * BRICK, nbx * BRICK)[:ny, :nx]

    def projection(self, band=None, threshold_nats=1.0):
        """A 2D occupancy grid over a height band, int8 (ny, nx) in the ROS map_server
        convention: 100 occupied (some observed voxel of the column above ``threshold_nats``), 0
        free (every observed voxel of the column below -``threshold_nats``), 50 between, -1
        unknown (no voxel of the column observed; for a map with knowledge: none known)."""
        d = self.dense(band)
        known = d != 0 if not self.has_knowledge else self.dense_knowledge(band) >= KNOWN_LOOKS
        seen = known.any(axis=0)
        top = np.where(known, d, np.iinfo(np.int32).min).max(axis=0)      # over observed voxels only
        t = int(round(threshold_nats * logodds.SCALE))
        out = np.full(top.shape, 50, np.int8)
        out[top > t] = 100
        out[seen & (top < -t)] = 0
        out[~seen] = UNKNOWN
        return out
