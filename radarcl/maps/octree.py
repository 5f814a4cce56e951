"""OctoMap's files (``.bt`` occupancy, ``.ot`` log-odds) written directly from voxel keys, a tree
built bottom-up in numpy, never a node at a time.

OctoMap (Hornung et al., Autonomous Robots 2013) keys a voxel of resolution r by
``floor(p / r) + 32768`` per axis: 16 levels below the root, the child index at depth d taken
from bit 15 - d of the keys (x + 2y + 4z). Both files start with OctoMap's text header (the
first line names the kind, then ``id OcTree``, ``size`` = nodes in the stream, ``res`` and
``data``) and hold the nodes depth first, a node before its children:
- ``.bt``: each inner node is two bytes (children 0-3, then 4-7), bits 2i and 2i + 1 for child i
  read as a number: 0 unknown, 1 free, 2 occupied, 3 has children; leaves are not written
  (OctoMap reads occupied leaves at its clamping maximum and free ones at its minimum).
- ``.ot``: every node is its log-odds (float32) and a byte whose bit i says child i exists; an
  inner node holds the largest log-odds of its children (``OcTreeNode::getMaxChildLogOdds``).
The byte layout was read off files OctoMap itself wrote; ``tests/test_exports.py`` reads every
file back with octomap-python and compares it voxel by voxel.
"""

import numpy as np

DEPTH = 16
CENTRE_KEY = 1 << (DEPTH - 1)                    # OctoMap's tree_max_val: the key of p = 0
_HEADERS = {"bt": b"# Octomap OcTree binary file\n", "ot": b"# Octomap OcTree file\n"}


def keys_of(points, resolution):
    """OctoMap keys (n, 3) int64 of points (n, 3) [m]; ValueError beyond the 2^16 keys per axis."""
    keys = np.floor(np.asarray(points, np.float64) / resolution).astype(np.int64) + CENTRE_KEY
    if len(keys) and (keys.min() < 0 or keys.max() >= 2 * CENTRE_KEY):
        raise ValueError(f"points beyond OctoMap's {2 * CENTRE_KEY} keys per axis at {resolution} m")
    return keys


def _spread(v):
    """The bits of 16-bit ``v`` (uint64) moved to every third position (bit i -> bit 3i)."""
    v = v & np.uint64(0xFFFF)
    for shift, mask in ((16, 0x0000FF0000FF), (8, 0x00F00F00F00F), (4, 0x0C30C30C30C3), (2, 0x249249249249)):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def _morton(keys):
    """(n,) uint64: the keys' bits interleaved, child index of depth 0 in the top three bits."""
    k = np.asarray(keys, np.uint64)
    return _spread(k[:, 0]) | (_spread(k[:, 1]) << np.uint64(1)) | (_spread(k[:, 2]) << np.uint64(2))


def _levels(keys, values):
    """The tree, bottom-up: per depth d (0..16) the nodes' codes (sorted prefixes), their
    child-exists masks and log-odds (max of the children's for inner nodes)."""
    code = _morton(keys)
    order = np.argsort(code, kind="stable")
    code, values = code[order], np.asarray(values, np.float32)[order]
    if len(code) > 1 and (np.diff(code) == 0).any():
        raise ValueError("a key appears twice")
    levels = [None] * (DEPTH + 1)
    levels[DEPTH] = (code, np.zeros(len(code), np.uint8), values)
    for d in range(DEPTH - 1, -1, -1):
        child_code, _, child_value = levels[d + 1]
        parent = child_code >> np.uint64(3)
        starts = np.flatnonzero(np.r_[True, parent[1:] != parent[:-1]])     # children are sorted: groups
        bit = np.left_shift(np.uint8(1), (child_code & np.uint64(7)).astype(np.uint8))
        mask = np.bitwise_or.reduceat(bit, starts)
        value = np.maximum.reduceat(child_value, starts)
        levels[d] = (parent[starts], mask, value)
    return levels


def _preorder(levels):
    """(depth, index within its level) of every node, depth first with a node before its
    children and children in index order: sorted by the node's code padded to full depth."""
    padded = np.concatenate([c << np.uint64(3 * (DEPTH - d)) for d, (c, _, _) in enumerate(levels)])
    depth = np.concatenate([np.full(len(c), d, np.int8) for d, (c, _, _) in enumerate(levels)])
    index = np.concatenate([np.arange(len(c)) for c, _, _ in levels])
    order = np.lexsort((depth, padded))
    return depth[order], index[order]


def write(path, keys, values, resolution, binary):
    """Write an OctoMap file of the leaves ``keys`` (n, 3) (``keys_of``) with log-odds ``values``
    (n,): ``binary`` a ``.bt`` (occupied where the value is above 0), else a ``.ot``. ``path``
    is an open binary file object. Returns the number of nodes written."""
    levels = _levels(keys, values) if len(keys) else None
    kind = "bt" if binary else "ot"
    if levels is None:                                  # an empty tree: no root at all
        path.write(_HEADERS[kind] + f"id OcTree\nsize 0\nres {resolution!r}\ndata\n".encode())
        return 0
    n_nodes = sum(len(c) for c, _, _ in levels)
    path.write(_HEADERS[kind] + f"id OcTree\nsize {n_nodes}\nres {resolution!r}\ndata\n".encode())
    depth, index = _preorder(levels)
    if binary:
        path.write(_binary_stream(levels, depth, index))
    else:
        rec = np.empty(len(depth), dtype=[("value", "<f4"), ("mask", "u1")])
        for d, (_, mask, value) in enumerate(levels):
            at = depth == d
            rec["value"][at] = value[index[at]]
            rec["mask"][at] = mask[index[at]]
        path.write(rec.tobytes())
    return n_nodes


def _binary_stream(levels, depth, index):
    """The ``.bt`` bytes: two per inner node, in pre-order."""
    inner = depth < DEPTH
    out = np.zeros((int(inner.sum()), 2), np.uint8)
    for d in range(DEPTH):
        child_code, child_mask, child_value = levels[d + 1]
        # each child's pair of bits: 3 inner, 2 occupied (> 0), 1 free
        state = np.where(child_mask > 0, 3, np.where(child_value > 0, 2, 1)).astype(np.uint16)
        slot = (child_code & np.uint64(7)).astype(np.uint16)
        parent = child_code >> np.uint64(3)
        starts = np.flatnonzero(np.r_[True, parent[1:] != parent[:-1]])     # one group per node of depth d
        word = np.bitwise_or.reduceat(state << (2 * slot), starts)
        rows = np.flatnonzero(depth[inner] == d)
        out[rows, 0] = (word[index[inner][rows]] & 0xFF).astype(np.uint8)
        out[rows, 1] = (word[index[inner][rows]] >> 8).astype(np.uint8)
    return out.tobytes()
