"""A map as data: open an ``.npz`` map or a map store and query it with numpy (no device).

What users ask mapping libraries for (OctoMap's Python bindings, nvblox's queries): log-odds
and probability at world points, the occupied voxels as an (N, 3) array, a horizontal slice, a
2D occupancy projection over a height band (the costmap of a ground robot).

Values are the grid's exact int32 sums in ``radarcl.logodds`` units; the views convert to
nats or probabilities. A voxel no beam reached holds 0 (unknown: probability 0.5; with the
knowledge channel, below, it reads the reading's prior instead).

What a map says, in every view and export alike (``classes``): a voxel is OCCUPIED above the
occupancy threshold (``OCCUPIED_NATS``), FREE below the free threshold (``FREE_NATS``) and
UNDECIDED between them; a voxel no beam reached is UNOBSERVED. A 2D cell of a projection is
occupied when some voxel of its column in the band is occupied, free when none is and some is
free, and unknown otherwise (octomap_server's projected map does the same).

A map of the detection-statistics model (``radarcl.sensor_model``) also holds the knowledge
channel: per voxel the summed detection opportunity of its looks (``knowledge_at``, in looks)
and their number, and is read through its reading (``sensor_model.read_log_odds``: correlated
looks counted once, the prior: the world's base rate, so a voxel never observed reads a
calibrated probability). Every query, dense copy, class and projection uses that reading, and a
voxel is UNOBSERVED when its knowledge is below ``KNOWN_LOOKS`` ("never observed" apart from
"observed, undecided"), which its value cannot say once the prior is not 0. A map without
knowledge (eq. 12) reads its sums as they are, and a voxel no beam reached is its UNOBSERVED.
"""

from dataclasses import dataclass

import numpy as np

from radarcl import logodds, sensor_model
from radarcl.errors import ConfigError, ShapeError
from radarcl.gridspec import BRICK, GridSpec
from radarcl.io.files import memory_budget
from radarcl.maps import disk, npz
from radarcl.maps.disk import read_map, reading_of
from radarcl.sensor_model import KNOWN_LOOKS

UNKNOWN = -1          # a 2D cell that is neither occupied nor free (the ROS OccupancyGrid convention)
OCCUPIED_NATS = 1.0   # occupied above this log-odds (p 0.73)
FREE_NATS = -1.0      # free below this (p 0.27)
UNOBSERVED, FREE, UNDECIDED, OCCUPIED = -1, 0, 1, 2       # voxel classes (``classes``)


def check_thresholds(occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS):
    """(occupied, free) as floats, or ConfigError unless both are finite and free <= 0 <= occupied
    (a voxel no beam reached holds 0: neither)."""
    try:
        occ, free = float(occupied_nats), float(free_nats)
    except (TypeError, ValueError):
        raise ConfigError(f"thresholds must be numbers [nat], got {occupied_nats!r} and {free_nats!r}") from None
    if not (np.isfinite(occ) and np.isfinite(free) and free <= 0 <= occ):
        raise ConfigError(f"the occupied threshold ({occupied_nats}) and the free threshold ({free_nats}) must be "
                          "finite numbers [nat] with free <= 0 <= occupied")
    return occ, free


def classes(units, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS, known=None):
    """int8 classes of int32 ``units`` (logodds units, as the map reads them): OCCUPIED, FREE,
    UNDECIDED, or UNOBSERVED where ``known`` is False (default: where no beam reached, 0)."""
    occ, free = check_thresholds(occupied_nats, free_nats)
    u = np.asarray(units)
    out = np.full(u.shape, UNDECIDED, np.int8)
    out[u > occ * logodds.SCALE] = OCCUPIED
    out[u < free * logodds.SCALE] = FREE
    out[(u == 0) if known is None else ~np.asarray(known, bool)] = UNOBSERVED
    return out


@dataclass
class Map:
    """A sparse map: ``spec`` (GridSpec), ``keys`` (n, 3) int32 bricks (bx, by, bz) and ``data``
    (n, *brick) int32 [z, y, x] in logodds units (brick (8, 8, 8), or (1, 8, 8) for planar bricks);
    a map of the detection-statistics model also ``knowledge`` and ``looks`` (the same bricks) and
    its ``reading`` (``maps.npz.Channels``)."""

    spec: GridSpec
    keys: np.ndarray
    data: np.ndarray
    knowledge: np.ndarray = None
    looks: np.ndarray = None
    reading: dict = None
    lost: list = None          # bricks a salvaged store could not give (``maps.disk.read_map``)

    @classmethod
    def open(cls, path, salvage=False):
        """Read a map file or store (``maps.disk.read_map``; with ``salvage``, a damaged store's
        intact bricks, the lost ones listed in ``lost``)."""
        spec, keys, data, lost, channels = read_map(path, salvage)
        if channels is None:
            return cls(spec, keys, data, lost=lost)
        return cls(spec, keys, data, channels.knowledge, channels.looks, channels.reading, lost)

    @classmethod
    def of_grid(cls, grid, reading=None):
        """The map held by an ``EvidenceGrid`` (copied from the device); a grid with the knowledge
        channel is read with its own reading (a pipeline's grid knows it) or ``reading``: a dict
        (``maps.disk.reading_of``) or the ``mapconfig.Resolved`` it was made with."""
        keys, data = grid.bricks()
        if not grid.has_knowledge:
            return cls(grid.spec, keys, data)
        reading = reading if reading is not None else grid.reading     # a pipeline's grid knows it
        if reading is None:
            raise ConfigError("a grid with the knowledge channel is read with its reading: Map.of_grid(grid, reading)")
        if not isinstance(reading, dict):
            reading = reading_of(reading)
        return cls(grid.spec, keys, data, grid.knowledge_bricks(), grid.knowledge_bricks("looks"), reading)

    def save(self, path, poses=None, overwrite=False, meta=None):
        """Write the map to ``path``: an ``.npz`` file, or a map store for any other name
        (``maps.disk.output_format``), with its knowledge channel and reading when it has them,
        the sensor ``poses`` (n, 4, 4) and ``meta`` (a JSON-able dict, ``maps.disk.read_meta``)
        when given. An existing ``path`` is refused unless ``overwrite``. Returns the path."""
        path = disk.check_output(path, force=overwrite)
        channels = None if not self.has_knowledge else npz.Channels(self.knowledge, self.looks, self.reading)
        writer = disk.FORMATS[disk.output_format(path)].writer(path, self.spec, reading=self.reading)
        writer(self.keys.astype(np.int32), self.data, poses=poses, channels=channels, meta=meta)
        return path

    def costmap(self, band, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS):
        """A ground robot's 2D occupancy grid over the height ``band`` (z_min, z_max) [m]:
        ``Costmap`` (``projection``'s int8 cells, 100 occupied, 0 free, -1 unknown, with the
        world position of cell (0, 0)'s corner and the cell size, as ROS's OccupancyGrid
        carries them)."""
        cells = self.projection(band, occupied_nats, free_nats)
        return Costmap(cells, tuple(float(v) for v in self.spec.origin_m[:2]), float(self.spec.voxel_m))

    def __post_init__(self):
        if not isinstance(self.spec, GridSpec):
            raise ShapeError(f"spec must be a GridSpec, got {type(self.spec).__name__}")
        self.keys, self.data = np.asarray(self.keys), np.asarray(self.data)
        if self.keys.ndim != 2 or self.keys.shape[1:] != (3,) or self.keys.dtype.kind not in "iu":
            raise ShapeError(f"expected brick keys (n, 3) integers, got {self.keys.shape} {self.keys.dtype}")
        if self.data.shape != (len(self.keys), *self.spec.brick_data_shape) or self.data.dtype != np.int32:
            raise ShapeError(f"expected bricks ({len(self.keys)}, {', '.join(map(str, self.spec.brick_data_shape))}) "
                             f"int32, got {self.data.shape} {self.data.dtype}")
        self._brick = np.asarray(self.spec.brick, np.int64)         # voxels per brick along x, y, z
        if not ((self.knowledge is None) == (self.looks is None) == (self.reading is None)):
            raise ConfigError("a map's knowledge comes with its looks and its reading, and only with them")
        for name in ("knowledge", "looks"):
            if getattr(self, name) is not None and np.shape(getattr(self, name)) != self.data.shape:
                raise ShapeError(f"expected {name} bricks {self.data.shape}, got {np.shape(getattr(self, name))}")
        k = self.keys.astype(np.int64)
        self._ids = (k[:, 2] << 42) | (k[:, 1] << 21) | k[:, 0]
        self._order = np.argsort(self._ids)
        self._nats = self._units = None

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

    def read_units(self):
        """(n, 8, 8, 8) int32 log-odds units as the map reads them: the stored sums, or for a map
        with knowledge its reading rounded to logodds units (computed once: every view and export
        reads it)."""
        if not self.has_knowledge:
            return self.data
        if self._units is None:
            self._units = logodds.to_fixed(self.nats())
        return self._units

    def shown_units(self):
        """(n, 8, 8, 8) int32 log-odds units as a viewer draws them: for a map with knowledge the
        reading where it knows and 0 (which no view mode draws) where it does not, since its
        prior reads an unknown voxel as probably free; without knowledge the stored sums."""
        if not self.has_knowledge:
            return self.data
        return np.where(self.known(), self.read_units(), 0).astype(np.int32)

    def known(self):
        """(n, 8, 8, 8) bool: voxels the map observed (knowledge of ``KNOWN_LOOKS`` looks or
        more; without knowledge: any evidence at all)."""
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
        p = _points(points)
        if not np.isfinite(p).all():
            raise ConfigError("points must be finite")
        idx = self.spec.world_to_index(p.reshape(-1, 3))
        out = np.zeros(len(idx), np.int32)
        ok = self.spec.contains(idx)
        if ok.any() and len(self.keys):
            i = idx[ok]
            b = i // self._brick
            ids = (b[:, 2] << 42) | (b[:, 1] << 21) | b[:, 0]
            pos = np.minimum(np.searchsorted(self._ids[self._order], ids), len(self._order) - 1)
            row = self._order[pos]
            hit = self._ids[row] == ids
            local = i[hit] % self._brick
            vals = np.zeros(len(i), np.int32)
            vals[hit] = source[row[hit], local[:, 2], local[:, 1], local[:, 0]]
            out[ok] = vals
        return out.reshape(p.shape[:-1])

    def inside(self, points):
        """(...,) bool: points inside the grid."""
        return self.spec.contains(self.spec.world_to_index(_points(points)))

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

    def state_at(self, points, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS):
        """int8 class (``classes``) at world points (..., 3): UNOBSERVED where never observed (or
        outside the grid), else OCCUPIED, FREE or UNDECIDED by the map's reading."""
        nats = self.log_odds_at(points)
        if self.has_knowledge:
            known = self.units_at(points, "knowledge") >= KNOWN_LOOKS * logodds.KNOWLEDGE_SCALE
        else:
            known = self.units_at(points) != 0
        units = logodds.to_fixed(np.nan_to_num(nats))
        return classes(units, occupied_nats, free_nats, known=known & self.inside(points))

    def probability_at(self, points):
        """Occupancy probability at world points (..., 3); NaN outside the grid."""
        return 1.0 / (1.0 + np.exp(-self.log_odds_at(points)))

    # -- voxel sets --------------------------------------------------------------------------------------
    def voxels(self, lo_nats=None, hi_nats=None, with_knowledge=False):
        """(indices (N, 3) int64 (x, y, z), units (N,) int32) of the observed voxels (``known``)
        whose log-odds as read lie in [lo_nats, hi_nats] (None: unbounded), inside the grid;
        ``units`` are the read log-odds in logodds units (``read_units``). ``with_knowledge``
        adds their knowledge [looks] (NaN for a map without the channel) as a third array."""
        lo_nats = None if lo_nats is None else _number(lo_nats, "lo_nats", infinite=True)
        hi_nats = None if hi_nats is None else _number(hi_nats, "hi_nats", infinite=True)
        if not len(self.keys):
            empty = (np.zeros((0, 3), np.int64), np.zeros(0, np.int32))
            return empty + ((np.zeros(0),) if with_knowledge else ())
        units = self.read_units()
        keep = self.known()
        if lo_nats is not None:
            keep &= units >= lo_nats * logodds.SCALE
        if hi_nats is not None:
            keep &= units <= hi_nats * logodds.SCALE
        b, z, y, x = np.nonzero(keep)
        idx = self.keys[b].astype(np.int64) * self._brick + np.stack([x, y, z], axis=1)
        inside = self.spec.contains(idx)
        out = (idx[inside], units[b, z, y, x][inside])
        if with_knowledge:
            looks = (self.knowledge[b, z, y, x] / float(logodds.KNOWLEDGE_SCALE) if self.has_knowledge
                     else np.full(len(b), np.nan))
            out += (looks[inside],)
        return out

    def decided(self, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS):
        """(indices (N, 3) int64 (x, y, z), units (N,) int32) of the occupied and the free voxels
        (``classes``, as read), found brick by brick without listing the undecided ones."""
        occ, free = check_thresholds(occupied_nats, free_nats)
        if not len(self.keys):
            return np.zeros((0, 3), np.int64), np.zeros(0, np.int32)
        units = self.read_units()
        b, z, y, x = np.nonzero(((units > occ * logodds.SCALE) | (units < free * logodds.SCALE)) & self.known())
        idx = self.keys[b].astype(np.int64) * self._brick + np.stack([x, y, z], axis=1)
        inside = self.spec.contains(idx)
        return idx[inside], units[b, z, y, x][inside]

    def occupied(self, threshold_nats=OCCUPIED_NATS):
        """(centres (N, 3) [m], log-odds (N,) [nat]) of the occupied voxels: strictly above
        ``threshold_nats``, as ``classes`` counts them."""
        threshold_nats = _number(threshold_nats, "threshold_nats")
        idx, units = self.voxels(lo_nats=threshold_nats)
        above = units > threshold_nats * logodds.SCALE
        return self.spec.index_to_world(idx[above]), logodds.to_nats(units[above])

    def dense(self, band=None):
        """Dense int32 (nz, ny, nx) log-odds units as the map reads them (``read_units``; a voxel
        of no brick: 0, or with knowledge the reading of a voxel never observed); ``band``
        (z_min, z_max) [m] keeps only those layers. Refused beyond the memory budget."""
        fill = 0
        if self.has_knowledge:
            fill = int(logodds.to_fixed(sensor_model.read_log_odds(0, 0, 0, self.reading)))
        return self._dense(self.read_units(), band, fill)

    def dense_knowledge(self, band=None):
        """Dense float64 (nz, ny, nx) knowledge [looks] (0: never observed), or None for a map
        without the knowledge channel; ``band`` as ``dense``."""
        if not self.has_knowledge:
            return None
        return self._dense(self.knowledge, band) / float(logodds.KNOWLEDGE_SCALE)

    def _dense(self, bricks, band, fill=0):
        z0, z1 = self._band(band)
        nx, ny, _ = self.spec.shape
        nbx, nby, _ = self.spec.brick_shape
        bz = self.spec.brick_z
        b0, b1 = z0 // bz, (z1 - 1) // bz + 1                       # the brick layers the band touches
        if 4.0 * nbx * nby * (b1 - b0) * bz * BRICK ** 2 > memory_budget():
            raise ConfigError(f"a dense copy of {nx} x {ny} x {z1 - z0} voxels exceeds the memory budget; "
                              "narrow the band")
        slab = np.full(((b1 - b0) * bz, nby * BRICK, nbx * BRICK), fill, np.int32)
        view = slab.reshape(b1 - b0, bz, nby, BRICK, nbx, BRICK).transpose(0, 2, 4, 1, 3, 5)
        sel = (self.keys[:, 2] >= b0) & (self.keys[:, 2] < b1)      # whole bricks, no voxel lists
        k = self.keys[sel]
        view[k[:, 2] - b0, k[:, 1], k[:, 0]] = bricks[sel]
        return np.ascontiguousarray(slab[z0 - b0 * bz:z1 - b0 * bz, :ny, :nx])

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

    def _column_hi_lo(self):
        """int64 (ny, nx) largest and smallest value as read of each column's voxels (0 for
        unobserved ones), brick by brick: never the dense volume."""
        ny, nx = self.spec.shape[1], self.spec.shape[0]
        nby, nbx = -(-ny // BRICK), -(-nx // BRICK)
        hi = np.zeros((nby, nbx, BRICK, BRICK), np.int64)
        lo = np.zeros((nby, nbx, BRICK, BRICK), np.int64)
        if len(self.keys):
            bz = self.spec.brick_z
            inside = self.keys[:, 2, None] * bz + np.arange(bz) < self.spec.shape[2]     # a top brick's overhang
            d = np.where(inside[:, :, None, None] & self.known(), self.read_units(), 0).astype(np.int64)
            np.maximum.at(hi, (self.keys[:, 1], self.keys[:, 0]), d.max(axis=1))
            np.minimum.at(lo, (self.keys[:, 1], self.keys[:, 0]), d.min(axis=1))
        flat = [a.transpose(0, 2, 1, 3).reshape(nby * BRICK, nbx * BRICK)[:ny, :nx] for a in (hi, lo)]
        return flat[0], flat[1]

    def column_extremes(self):
        """Log-odds [nat] (ny, nx) of each column's most telling observed voxel, seen from
        above: its largest value when that is positive (something occupied somewhere above the
        cell), else its smallest (how free the column is); 0 where no voxel of the column was
        observed. Brick by brick: never the dense volume."""
        hi, lo = self._column_hi_lo()
        return logodds.to_nats(np.where(hi > 0, hi, lo))

    def known_columns(self):
        """bool (ny, nx): the columns holding a voxel the map knows (``known``), brick by brick;
        for the top-down pictures, which draw the others as unknown, apart from free."""
        ny, nx = self.spec.shape[1], self.spec.shape[0]
        nby, nbx = -(-ny // BRICK), -(-nx // BRICK)
        out = np.zeros((nby, nbx, BRICK, BRICK), bool)
        if len(self.keys):
            bz = self.spec.brick_z
            inside = self.keys[:, 2, None] * bz + np.arange(bz) < self.spec.shape[2]     # a top brick's overhang
            np.logical_or.at(out, (self.keys[:, 1], self.keys[:, 0]), (inside[:, :, None, None] & self.known()).any(axis=1))
        return out.transpose(0, 2, 1, 3).reshape(nby * BRICK, nbx * BRICK)[:ny, :nx]

    def classes_from_above(self, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS):
        """int8 (ny, nx) class of each column seen from above (``classes``' values): OCCUPIED
        when some voxel of it is occupied, else FREE when some is free, else UNDECIDED when the
        map observed one, else UNOBSERVED; for a planar map, its one layer's classes. Brick by
        brick: never the dense volume."""
        occ, free = check_thresholds(occupied_nats, free_nats)
        hi, lo = self._column_hi_lo()
        out = np.full(hi.shape, UNOBSERVED, np.int8)
        out[self.known_columns()] = UNDECIDED
        out[lo < free * logodds.SCALE] = FREE
        out[hi > occ * logodds.SCALE] = OCCUPIED
        return out

    def counts(self, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS):
        """Voxels of the grid by class: {"occupied", "free", "undecided", "unobserved"}."""
        _, units = self.voxels()
        c = classes(units, occupied_nats, free_nats, known=np.ones(len(units), bool))
        seen = {"occupied": int((c == OCCUPIED).sum()), "free": int((c == FREE).sum()),
                "undecided": int((c == UNDECIDED).sum())}
        return dict(seen, unobserved=self.spec.n_voxels - sum(seen.values()))

    def projection(self, band=None, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS):
        """A 2D occupancy grid over a height band, int8 (ny, nx) in the ROS OccupancyGrid
        convention: 100 occupied (some voxel of the column in the band above ``occupied_nats``),
        0 free (none occupied, some below ``free_nats``), -1 unknown (neither)."""
        occ, free = check_thresholds(occupied_nats, free_nats)
        if band is None:                                # the whole height: brick by brick
            hi, lo = self._column_hi_lo()
        else:
            d = self.dense(band)
            if self.has_knowledge:
                d = np.where(self.dense_knowledge(band) >= KNOWN_LOOKS, d, 0)
            hi, lo = d.max(axis=0), d.min(axis=0)
        out = np.full(hi.shape, UNKNOWN, np.int8)
        out[lo < free * logodds.SCALE] = 0
        out[hi > occ * logodds.SCALE] = 100
        return out


@dataclass(frozen=True)
class Costmap:
    """A 2D occupancy grid: ``cells`` int8 (ny, nx), 100 occupied, 0 free, -1 unknown (ROS's
    OccupancyGrid convention); ``origin_m`` (x, y) [m] the corner of cell (0, 0) in the map's
    frame; ``resolution_m`` the cell size [m]. Row j, column i covers x from
    origin_m[0] + i * resolution_m and y from origin_m[1] + j * resolution_m."""

    cells: np.ndarray
    origin_m: tuple
    resolution_m: float

    def cell_of(self, xy):
        """(..., 2) int64 (column i, row j) of world points (..., 2) [m]; cells outside the grid
        come out of range (compare with ``cells.shape``)."""
        p = np.asarray(xy, np.float64)
        if p.shape[-1:] != (2,):
            raise ShapeError(f"points must be (..., 2) x, y [m], got {p.shape}")
        return np.floor((p - np.asarray(self.origin_m)) / self.resolution_m).astype(np.int64)


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
