"""What the renderer draws, prepared with numpy alone: the map as texture values, its coarse
max-mip for empty-space skipping, downsampling to the GL limit, and the bricks that changed.

A ``Volume`` holds a grid snapshot as float16 log-odds [nat] in the (nz, ny, nx) layout of
``radarcl.grid`` (x fastest), which is byte for byte a GL 3D texture of size (nx, ny, nz): the
numpy (z, y, x) -> GL (x, y, z) swap is that sentence and nothing else. Texel i's centre,
texture coordinate (i + 0.5) / n, is voxel i's centre ``origin + (i + 0.5) * voxel`` in world
coordinates, so the box [origin, origin + n * voxel] carries the texture exactly.

The coarse max-mip has one cell per 8^3 brick of the grid holding the largest log-odds any
trilinear sample inside that brick can read: the brick's voxels and a one-voxel apron around
it (a sample at voxel coordinate u reads voxels floor(u - 1/2) and floor(u - 1/2) + 1). A ray
may jump over a cell whose maximum its mode cannot see, and the picture does not change.
"""

from dataclasses import dataclass, field

import numpy as np

from radarcl import logodds
from radarcl.errors import ConfigError, ShapeError
from radarcl.gridspec import BRICK, GridSpec, assemble, rebrick
from radarcl.maps.disk import read_channels, read_poses
from radarcl.maps.map import Map

TEXTURE_LIMIT_NATS = 1000.0        # texture values are clamped here: float16 holds them to 0.5 nat


@dataclass
class Volume:
    """A map ready to render: ``spec`` (the grid, possibly downsampled), ``values`` float16
    (nz, ny, nx) log-odds [nat], ``coarse`` float16 (nbz, nby, nbx) max-mip, ``note`` what was
    done to fit (empty when nothing), ``keys``/``bricks`` the sparse source when it has one."""

    spec: GridSpec
    values: np.ndarray
    coarse: np.ndarray
    note: str = ""
    keys: np.ndarray = field(default=None, repr=False)
    bricks: np.ndarray = field(default=None, repr=False)
    poses: np.ndarray = field(default=None, repr=False)     # the sensor's (n, 4, 4), when the map keeps them
    _percentiles: dict = field(default_factory=dict, repr=False)
    _boxes: dict = field(default_factory=dict, repr=False)

    @property
    def positive(self):
        """Number of cells with positive log-odds (the Fig. 11 spheres)."""
        return int(np.count_nonzero(self.values > 0))

    def percentile_above(self, lo, q=99.9):
        """The ``q``-th percentile [nat] of the values above ``lo``, or None when there are
        none; remembered until the next ``update`` (a full pass costs about 0.25 s on the paper grid)."""
        key = (float(lo), float(q))
        if key not in self._percentiles:
            bricks = self.coarse > lo                   # only bricks that hold such values are read
            above = []
            for bz, by, bx in np.argwhere(bricks):
                block = self.values[bz * BRICK:(bz + 1) * BRICK, by * BRICK:(by + 1) * BRICK,
                                    bx * BRICK:(bx + 1) * BRICK]
                above.append(block[block > lo])
            above = np.concatenate(above).astype(np.float32) if above else np.empty(0, np.float32)
            self._percentiles[key] = float(np.percentile(above, q)) if above.size else None
        return self._percentiles[key]

    def percentile_below(self, hi, q=99.9):
        """The ``q``-th percentile, counted from the most negative, of the values below ``hi``
        (a negative log-odds [nat]), or None when there are none; remembered like
        ``percentile_above``."""
        key = ("below", float(hi), float(q))
        if key not in self._percentiles:
            below = self.values[self.values < hi].astype(np.float32)
            self._percentiles[key] = float(np.percentile(below, 100 - q)) if below.size else None
        return self._percentiles[key]

    def content_box(self, lo, keep=0.98):
        """World box (lo, hi) [m] around the voxels holding values above ``lo`` (what a view at
        that clamp shows), leaving out the ``1 - keep`` most outlying of them along each axis
        (isolated false alarms would otherwise frame the whole grid); None when there are none.
        Voxels, not bricks: a brick's apron would frame a one-brick object three bricks wide.
        Remembered until the next ``update`` (the window's guides ask every frame)."""
        key = (float(lo), float(keep))
        if key not in self._boxes:
            self._boxes[key] = self._content_box(lo, keep)
        return self._boxes[key]

    def _content_box(self, lo, keep):
        mask = above(self.values, lo)
        columns = mask.view(np.uint8).sum(axis=0, dtype=np.uint16)      # (ny, nx); nz <= 2048 (the GL limit)
        total = int(columns.sum(dtype=np.int64))
        if total == 0:
            return None
        counts = (columns.sum(axis=0, dtype=np.int64), columns.sum(axis=1, dtype=np.int64),
                  np.count_nonzero(mask.reshape(len(mask), -1), axis=1))
        first, last = [], []
        for count in counts:                                       # along x, y, z
            cum = np.cumsum(count)
            first.append(int(np.searchsorted(cum, total * (1 - keep) / 2, side="right")))
            last.append(int(np.searchsorted(cum, total * (1 + keep) / 2, side="left")) + 1)
        v, o = self.spec.voxel_m, np.asarray(self.spec.origin_m)
        return o + np.asarray(first) * v, o + np.asarray(last) * v

    def view_box(self, lo):
        """The box a default view frames: the content above ``lo`` grown to hold the sensor's
        positions, or the whole grid when there is no content."""
        found = self.content_box(lo)
        if found is None:
            o = np.asarray(self.spec.origin_m, float)
            found = (o, o + np.asarray(self.spec.shape) * self.spec.voxel_m)
        lo_w, hi_w = (np.asarray(v, float) for v in found)
        if self.poses is not None and len(self.poses):
            p = self.poses[:, :3, 3]
            lo_w, hi_w = np.minimum(lo_w, p.min(axis=0)), np.maximum(hi_w, p.max(axis=0))
        return lo_w, hi_w

    def value_range(self):
        """(min, max) of the log-odds [nat]."""
        return float(self.values.min()), float(self.values.max())


def above(values, lo, inclusive=False):
    """``values > lo`` (``>=`` when ``inclusive``) for float16 ``values`` (no NaN), ``lo`` taken
    as float16 as numpy does. For lo > 0 it compares the bit patterns, which order like the
    non-negative values: numpy emulates float16 arithmetic, 0.47 s on the paper's grid against
    0.08 s here, and the window's guides need it after every live update."""
    lo16 = np.float16(lo)
    if not lo16 > 0:                                # -0.0 >= 0, but its bits say otherwise
        return values >= lo16 if inclusive else values > lo16
    bits, b = values.view(np.uint16), lo16.view(np.uint16)
    return ((bits >= b) if inclusive else (bits > b)) & (bits <= np.uint16(0x7C00))     # 0x7C00 = +inf


def to_texture(units):
    """int32 logodds units -> float16 nats, clamped to +-TEXTURE_LIMIT_NATS."""
    nats = np.multiply(units, np.float32(1.0 / logodds.SCALE), dtype=np.float32)
    np.clip(nats, -TEXTURE_LIMIT_NATS, TEXTURE_LIMIT_NATS, out=nats)
    return nats.astype(np.float16)


def _apron_max(a, axis, first, count, start, n):
    """Bricks ``first`` .. ``first + count - 1`` along ``axis`` of ``a``, a slice of an axis of
    length ``n`` that begins at ``start``: each the max over its BRICK voxels and one either
    side, indices clamped to [0, n) as clamp-to-edge sampling clamps them."""
    idx = np.clip(np.arange(first * BRICK - 1, (first + count) * BRICK + 1), 0, n - 1) - start
    taken = np.take(a, idx, axis=axis)                  # element j is voxel first*8 - 1 + j
    body = np.take(taken, np.arange(1, count * BRICK + 1), axis=axis)
    m = body.reshape(a.shape[:axis] + (count, BRICK) + a.shape[axis + 1:]).max(axis=axis + 1)
    left = np.take(taken, np.arange(count) * BRICK, axis=axis)              # voxel 8b - 1
    right = np.take(taken, np.arange(count) * BRICK + BRICK + 1, axis=axis)  # voxel 8b + 8
    return np.maximum(m, np.maximum(left, right))


def coarse_max(values, lo=(0, 0, 0), hi=None):
    """The max-mip of ``values`` (nz, ny, nx): one cell per 8^3 brick with its one-voxel apron,
    for the bricks [lo, hi) (bx, by, bz), all of them by default; returns (nbz, nby, nbx)."""
    shape = values.shape
    hi = hi if hi is not None else tuple(-(-n // BRICK) for n in shape[::-1])
    cut = tuple(slice(max(lo[2 - a] * BRICK - 1, 0), min(hi[2 - a] * BRICK + 1, shape[a])) for a in range(3))
    out = values[cut]                                   # the region and its apron, a view
    for axis in (2, 1, 0):                              # x first: the largest reduction on the big array
        out = _apron_max(out, axis, lo[2 - axis], hi[2 - axis] - lo[2 - axis], cut[axis].start, shape[axis])
    return np.ascontiguousarray(out)


def coarser_max(coarse, factor=4):
    """The next level of the max-mip: the max of ``factor``^3 coarse cells (32^3 voxels)."""
    nz, ny, nx = coarse.shape
    cz, cy, cx = (-(-n // factor) for n in (nz, ny, nx))
    padded = np.pad(coarse, ((0, cz * factor - nz), (0, cy * factor - ny), (0, cx * factor - nx)), mode="edge")
    return np.ascontiguousarray(padded.reshape(cz, factor, cy, factor, cx, factor).max(axis=(1, 3, 5)))


def active_box(coarse, visible):
    """The voxel box ((x0, y0, z0), (x1, y1, z1)) holding every brick whose coarse maximum
    passes ``visible`` (a vectorised predicate), or None when none does."""
    z, y, x = np.nonzero(visible(coarse))
    if len(z) == 0:
        return None
    return (np.array([x.min(), y.min(), z.min()]) * BRICK, (np.array([x.max(), y.max(), z.max()]) + 1) * BRICK)


def downsample(units, spec, max_size):
    """Max-pool ``units`` (nz, ny, nx) by the smallest integer factor that brings every axis to
    ``max_size`` or below (cubic voxels kept). Max keeps occupied evidence visible. Returns
    (units, spec, factor)."""
    factor = max(1, -(-max(spec.shape) // max_size))
    if factor == 1:
        return units, spec, 1
    nz, ny, nx = units.shape
    cz, cy, cx = (-(-n // factor) for n in (nz, ny, nx))
    padded = np.pad(units, ((0, cz * factor - nz), (0, cy * factor - ny), (0, cx * factor - nx)), mode="edge")
    pooled = padded.reshape(cz, factor, cy, factor, cx, factor).max(axis=(1, 3, 5))
    return np.ascontiguousarray(pooled), GridSpec(spec.origin_m, spec.voxel_m * factor, (cx, cy, cz)), factor


def from_units(spec, units, max_size=2048):
    """A ``Volume`` from a dense int32 snapshot (nz, ny, nx) in logodds units. A grid with an
    axis over ``max_size`` (the GL 3D-texture limit) is max-pooled to fit and says so in ``note``."""
    units = np.asarray(units)
    if units.shape != spec.array_shape:
        raise ShapeError(f"expected a snapshot of shape {spec.array_shape} (nz, ny, nx), got {units.shape}")
    if units.dtype.kind not in "iu":
        raise ShapeError(f"expected integer logodds units (a grid snapshot), got {units.dtype}")
    note = ""
    small, small_spec, factor = downsample(units, spec, max_size)
    if factor > 1:
        note = (f"grid {spec.shape} exceeds this GL's 3D texture limit of {max_size} per axis: shown max-pooled "
                f"by {factor} to {small_spec.shape} at {small_spec.voxel_m:g} m voxels")
    values = to_texture(small)
    return Volume(small_spec, values, coarse_max(values), note)


def from_nats(spec, nats, max_size=2048):
    """A ``Volume`` from dense log-odds [nat] (nz, ny, nx); NaN is refused, infinities clamp."""
    nats = np.asarray(nats, dtype=np.float64)
    if nats.shape != spec.array_shape:
        raise ShapeError(f"expected log-odds of shape {spec.array_shape} (nz, ny, nx), got {nats.shape}")
    if np.isnan(nats).any():
        raise ConfigError("log-odds must not be NaN")
    units = np.rint(np.clip(nats, -TEXTURE_LIMIT_NATS, TEXTURE_LIMIT_NATS) * logodds.SCALE).astype(np.int32)
    return from_units(spec, units, max_size)


def load_map(path, max_size=2048, budget=None):
    """Read a map file (an npz or map store, e.g. ``radarcl demo``'s map.npz) into a
    ``Volume`` (a map with the knowledge channel: its reading, unknown voxels 0); anything else raises ``FrameFormatError`` with the reason. A grid over the GL
    3D-texture limit ``max_size`` or whose volume would not fit the memory ``budget`` (bytes;
    default ``radarcl.io.files.memory_budget()``) is max-pooled by the smallest factor that fits,
    assembled a slab at a time from its bricks (a small file declaring 1000^3 voxels never
    becomes a 4 GB array), and the note says so."""
    spec, keys, bricks, channels = read_channels(path)
    if channels is not None:
        # a map of the detection-statistics model is drawn as it reads (correlated looks counted
        # once, not its raw sums), and what the radar never observed as 0, which no mode draws:
        # unknown is not free
        bricks = Map(spec, keys, bricks, channels.knowledge, channels.looks, channels.reading).shown_units()
    volume = from_bricks(spec, keys, bricks, max_size, budget)
    volume.poses = read_poses(path)
    return volume


def from_bricks(spec, keys, bricks, max_size=2048, budget=None):
    """A ``Volume`` from a sparse snapshot (``maps.disk.read``'s keys and bricks), pooled as
    ``load_map`` says. A planar map's 8 x 8 x 1 bricks are read as the 8^3 bricks the texture
    code walks (``grid.rebrick``: the same voxels)."""
    from radarcl.io.files import memory_budget

    spec, keys, bricks = rebrick(spec, keys, bricks, BRICK)
    budget = memory_budget() if budget is None else budget
    factor = pool_factor(spec, max_size, budget)
    if factor == 1:
        volume = from_units(spec, assemble(spec, keys, bricks), max_size)
        volume.keys, volume.bricks = keys, bricks
        return volume
    units, small = pooled_units(spec, keys, bricks, factor)
    values = to_texture(units)
    note = (f"grid {spec.shape} exceeds this GL's 3D texture limit of {max_size} per axis or the memory budget "
            f"of {budget / 2**30:.1f} GiB: shown max-pooled by {factor} to {small.shape} at {small.voxel_m:g} m voxels")
    return Volume(small, values, coarse_max(values), note)


BYTES_PER_CELL = 8      # int32 units + float16 values + the pooling's slab, per cell shown


def pool_factor(spec, max_size, budget):
    """Smallest integer factor that brings every axis to ``max_size`` or below and the shown
    volume to ``budget`` bytes or below; above 8, a multiple of 8 (whole bricks per cell)."""
    factor = max(1, -(-max(spec.shape) // max_size))
    while True:
        if factor > BRICK:
            factor = -(-factor // BRICK) * BRICK
        if np.prod([-(-n // factor) for n in spec.shape], dtype=np.float64) * BYTES_PER_CELL <= budget:
            return factor
        factor += 1


def pooled_units(spec, keys, bricks, factor):
    """(units (cz, cy, cx) int32, GridSpec): the grid max-pooled by ``factor``; voxels without a
    brick count as 0, as in a snapshot. Memory beyond the result stays small: with a factor that
    is a multiple of 8 each cell is whole bricks (reduced brick by brick); below, the grid is
    assembled one tile of lcm(factor, 8)^3 voxels at a time, empty tiles skipped."""
    import math

    nx, ny, nz = spec.shape
    shape = tuple(-(-n // factor) for n in (nz, ny, nx))
    out = np.zeros(shape, np.int32)
    small = GridSpec(spec.origin_m, spec.voxel_m * factor, shape[::-1])
    if not len(keys):
        return out, small
    kzyx = keys[:, ::-1].astype(np.int64)
    if factor % BRICK == 0:
        per = factor // BRICK                                   # bricks per cell edge
        inside = np.minimum(BRICK, np.asarray([nz, ny, nx]) - kzyx * BRICK)     # in-grid part of each brick
        peak = np.empty(len(keys), np.int32)
        edge = (inside < BRICK).any(axis=1)
        peak[~edge] = bricks[~edge].reshape(int((~edge).sum()), -1).max(axis=1)
        for i in np.flatnonzero(edge):                          # partial bricks at the high ends
            z, y, x = inside[i]
            peak[i] = bricks[i, :z, :y, :x].max()
        cells, inverse = np.unique(kzyx // per, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        best = np.full(len(cells), np.iinfo(np.int32).min, np.int32)
        np.maximum.at(best, inverse, peak)
        seen = np.bincount(inverse, minlength=len(cells))
        # a cell wholly covered by bricks takes their maximum; an uncovered voxel adds a 0
        n_bricks = np.asarray(spec.brick_shape[::-1])
        full = np.prod(np.minimum((cells + 1) * per, n_bricks) - cells * per, axis=1)
        out[tuple(cells.T)] = np.where(seen == full, best, np.maximum(best, 0))
        return out, small
    tile = factor * BRICK // math.gcd(factor, BRICK)          # voxels, a multiple of both
    tb = tile // BRICK
    tiles = kzyx // tb
    code = (tiles[:, 0] << 42) | (tiles[:, 1] << 21) | tiles[:, 2]
    order = np.argsort(code, kind="stable")
    sorted_code = code[order]
    starts = np.flatnonzero(np.r_[True, sorted_code[1:] != sorted_code[:-1]])
    for a, b in zip(starts, np.r_[starts[1:], len(order)]):
        sel = order[a:b]
        t = tiles[sel[0]] * tile                                # tile origin [voxels] (z, y, x)
        dense = np.zeros((tb, tb, tb, BRICK, BRICK, BRICK), np.int32)
        local = kzyx[sel] - tiles[sel[0]] * tb
        dense[local[:, 0], local[:, 1], local[:, 2]] = bricks[sel]
        dense = dense.transpose(0, 3, 1, 4, 2, 5).reshape(tile, tile, tile)
        dense = dense[:min(tile, nz - t[0]), :min(tile, ny - t[1]), :min(tile, nx - t[2])]
        dense = np.pad(dense, [(0, -(-n // factor) * factor - n) for n in dense.shape], mode="edge")
        d = [n // factor for n in dense.shape]
        c = t // factor
        out[c[0]:c[0] + d[0], c[1]:c[1] + d[1], c[2]:c[2] + d[2]] = \
            dense.reshape(d[0], factor, d[1], factor, d[2], factor).max(axis=(1, 3, 5))
    return out, small


def changed_bricks(old_keys, old_bricks, new_keys, new_bricks):
    """Brick keys (n, 3) (bx, by, bz) whose contents differ between two sparse snapshots: new
    bricks, dropped bricks and bricks with any changed voxel."""
    def ids(keys):
        k = keys.astype(np.int64)
        return (k[:, 2] << 42) | (k[:, 1] << 21) | k[:, 0]

    old_ids, new_ids = ids(old_keys), ids(new_keys)
    common, i_old, i_new = np.intersect1d(old_ids, new_ids, assume_unique=True, return_indices=True)
    differs = (old_bricks[i_old] != new_bricks[i_new]).reshape(len(common), -1).any(axis=1)
    added = np.setdiff1d(new_ids, old_ids, assume_unique=True)
    dropped = np.setdiff1d(old_ids, new_ids, assume_unique=True)
    out = np.concatenate([common[differs], added, dropped])
    mask = (1 << 21) - 1
    return np.stack([out & mask, (out >> 21) & mask, out >> 42], axis=1).astype(np.int32)


def update(volume, keys, bricks, changed):
    """Write the ``changed`` bricks of a new sparse snapshot (``keys``, ``bricks``) into
    ``volume.values`` and recompute the coarse cells they touch; returns the voxel boxes
    ((z0, z1), (y0, y1), (x0, x1)) written, for the texture upload, and the coarse box."""
    if volume.keys is None:
        raise ConfigError("this volume was downsampled or built from a dense array; reload it instead")
    lookup = {tuple(k): i for i, k in enumerate(keys.tolist())}
    blocks = np.zeros((len(changed), BRICK, BRICK, BRICK), np.int32)
    for j, key in enumerate(np.asarray(changed).tolist()):
        i = lookup.get(tuple(key))
        if i is not None:
            blocks[j] = bricks[i]
    out = write_bricks(volume, changed, blocks)
    volume.keys, volume.bricks = keys, bricks
    return out


def write_bricks(volume, keys, blocks):
    """Write bricks (``keys`` (n, 3) (bx, by, bz), ``blocks`` (n, 8, 8, 8) int32 units) into
    ``volume.values`` and recompute the coarse cells they touch (a live engine's changed bricks,
    ``radarcl view --follow``); returns the voxel boxes written and the coarse box, as ``update``."""
    spec = volume.spec
    if volume.note:
        raise ConfigError("this volume is max-pooled to fit the GL: bricks cannot be written into it; reload it")
    nz, ny, nx = spec.array_shape
    boxes = []
    for (bx, by, bz), block in zip(np.asarray(keys).tolist(), blocks):
        z0, y0, x0 = bz * BRICK, by * BRICK, bx * BRICK
        z1, y1, x1 = min(z0 + BRICK, nz), min(y0 + BRICK, ny), min(x0 + BRICK, nx)
        volume.values[z0:z1, y0:y1, x0:x1] = to_texture(block[:z1 - z0, :y1 - y0, :x1 - x0])
        boxes.append(((z0, z1), (y0, y1), (x0, x1)))
    volume._percentiles.clear()
    volume._boxes.clear()
    if not boxes:
        return boxes, None
    c = np.asarray(keys)
    lo = np.maximum(c.min(axis=0) - 1, 0)              # a neighbour's apron may reach a changed voxel
    hi = np.minimum(c.max(axis=0) + 2, np.asarray(spec.brick_shape))
    volume.coarse[lo[2]:hi[2], lo[1]:hi[1], lo[0]:hi[0]] = coarse_max(volume.values, lo, hi)
    return boxes, (tuple(lo), tuple(hi))
