"""The node pairs of the detection-statistics model: what the interpreter writes and the fusion
reads (kernels/fusion_common.h has the kernels' side).

Per (beam, bin) the update and delta at rho2 = 0, 1/4, ..., 1 (``NODES``), packed as SEGMENTS
int2 pairs of 16-bit halves per class of target (``pack_nodes``); the fusion interpolates them in
integers (kernels/fusion.cl, DETSTATS; ``node_lerp`` here) at rho2 quantised to 2^14 steps
(``quantised_rho2``). A scene without a terrain class (no ground plane) keeps only the upright
class (``node_shape``): half the bytes for the fusion to read, and the same map.
"""

import numpy as np

from radarcl import logodds
from radarcl.errors import ConfigError, ShapeError

NODES = 5                        # node values over rho2 = 0, 1/4, ..., 1
SEGMENTS = NODES - 1
CLASSES = ("upright", "terrain")  # the typical target of a voxel: chosen per voxel by its height (kernels/fusion.cl)
N_CLASSES = len(CLASSES)
Q_ONE = 1 << 14                  # rho2 = 1 in the fusion's quantisation steps (2^12 per segment)
Q_MAX = Q_ONE - 1                # the last step: rho2 = 1 quantises into the last segment


def pack_nodes(evidence, opportunity):
    """(..., NODES) int evidence [logodds units] and detection opportunity [KNOWLEDGE_SCALE
    units] -> (..., SEGMENTS, 2) int32: per segment s, (e_s | e_{s+1} << 16, d_s | d_{s+1} << 16)
    (the low half as 16 bits, the high half signed)."""
    e = np.asarray(evidence, np.int64)
    d = np.asarray(opportunity, np.int64)
    if e.shape[-1:] != (NODES,) or d.shape != e.shape:
        raise ShapeError(f"expected evidence and opportunity nodes (..., {NODES}), got {e.shape} and {d.shape}")
    if np.abs(e).max(initial=0) > logodds.EVIDENCE_LIMIT or d.min(initial=0) < 0 \
            or d.max(initial=0) > logodds.KNOWLEDGE_SCALE:
        raise ConfigError(f"node values out of range: evidence within +-{logodds.EVIDENCE_LIMIT}, opportunity within "
                          f"[0, {logodds.KNOWLEDGE_SCALE}] units")
    out = np.empty(e.shape[:-1] + (SEGMENTS, 2), np.int32)
    for c, v in enumerate((e, d)):
        word = (v[..., :-1] & 0xFFFF) | (v[..., 1:] << 16)
        out[..., c] = ((word + (1 << 31)) % (1 << 32) - (1 << 31)).astype(np.int32)
    return out


def node_shape(classes=N_CLASSES):
    """The shape of one (beam, bin)'s node pairs for a pipeline that keeps the first ``classes``
    classes (1: upright targets only, a scene without a terrain class; 2: ``CLASSES``):
    (classes, SEGMENTS, 2) int32, an int2 (evidence pair, opportunity pair) per class and segment
    as ``pack_nodes`` lays them out."""
    if classes not in (1, N_CLASSES):
        raise ConfigError(f"classes must be 1 or {N_CLASSES}, got {classes!r}")
    return (classes, SEGMENTS, 2)


def live_segments(opportunity, classes=N_CLASSES):
    """Which segments of each bin and class can ever carry an update: (n_bins, classes) uint8, bit s
    set where node s or s + 1 of a bin model's ``opportunity`` (n_bins, N_CLASSES, NODES, the delta
    at tau = 1, the most a look ever has) is above half a knowledge unit, in float32 as the kernels
    round it or in float64 as the host's exact nodes do. A node at most half a unit has knowledge
    0 in every frame, and so no evidence (a look that is not one): a voxel's entry in a segment of
    two such nodes adds nothing to any channel, ever, and a still table leaves it out."""
    node_shape(classes)                         # ConfigError for a count no node array has
    opp = np.asarray(opportunity)
    if opp.ndim != 3 or opp.shape[1:] != (N_CLASSES, NODES):
        raise ShapeError(f"expected opportunity (n_bins, {N_CLASSES}, {NODES}), got {opp.shape}")
    units32 = np.asarray(opp, np.float32) * np.float32(logodds.KNOWLEDGE_SCALE)
    live = (units32 > np.float32(0.5)) | (np.asarray(opp, np.float64) * logodds.KNOWLEDGE_SCALE > 0.5)
    either = live[..., :-1] | live[..., 1:]                      # (n_bins, N_CLASSES, SEGMENTS)
    bits = (either << np.arange(SEGMENTS)).sum(-1).astype(np.uint8)
    return np.ascontiguousarray(bits[:, :classes])


def all_classes(nodes):
    """Unpacked nodes (..., classes, NODES) of the first ``classes`` classes as all ``N_CLASSES``
    (..., N_CLASSES, NODES): a class a pipeline drops has no opportunity, so its nodes are 0."""
    nodes = np.asarray(nodes)
    pad = [(0, 0)] * nodes.ndim
    pad[-2] = (0, N_CLASSES - nodes.shape[-2])
    return np.pad(nodes, pad)


def kept_classes(nodes, classes):
    """The float64 oracle's nodes (..., N_CLASSES, NODES) of the classes a pipeline keeps (the
    first ``classes``), checking the premise of dropping the others: their nodes are all 0
    (ValueError where one is not)."""
    nodes = np.asarray(nodes)
    dropped = nodes[..., classes:, :]
    if dropped.any():
        raise ValueError(f"a dropped class has {np.count_nonzero(dropped)} nonzero nodes (up to "
                         f"{np.abs(dropped).max()}): the pipeline keeps {classes} class(es) where the scene has more")
    return nodes[..., :classes, :]


def unpack_nodes(packed):
    """The inverse of ``pack_nodes``: (evidence, opportunity), each (..., NODES) int64."""
    p = np.asarray(packed).astype(np.int64)
    if p.shape[-2:] != (SEGMENTS, 2):
        raise ShapeError(f"expected packed nodes (..., {SEGMENTS}, 2), got {p.shape}")
    out = []
    for c in range(2):
        w = p[..., c]
        lo = ((w & 0xFFFF) ^ 0x8000) - 0x8000
        hi = w >> 16
        out.append(np.concatenate([lo, hi[..., -1:]], axis=-1))
    return tuple(out)


def quantised_rho2(rho2):
    """rho2 in the fusion's steps: floor(min(rho2 x 2^14, 2^14 - 1)), int64 (float64 here, float32
    in the kernel: they agree except where rho2 x 2^14 lies within float32 rounding of an integer).
    The cap keeps q in the last segment (no clamp of the segment in the kernel): rho2 = 1 reads
    within 1 unit of the last node."""
    return np.floor(np.minimum(np.asarray(rho2, np.float64) * Q_ONE, Q_MAX)).astype(np.int64)


def node_lerp(nodes, q):
    """The fusion's interpolation of node values (..., NODES) int at quantised rho2 ``q``
    (``quantised_rho2``), in integers: e_s + ((e_{s+1} - e_s) f + 2048) >> 12, s = q >> 12."""
    nodes = np.asarray(nodes, np.int64)
    q = np.asarray(q, np.int64)
    seg = np.minimum(q >> 12, SEGMENTS - 1)
    f = q - (seg << 12)
    lo = np.take_along_axis(nodes, seg[..., None], axis=-1)[..., 0]
    hi = np.take_along_axis(nodes, seg[..., None] + 1, axis=-1)[..., 0]
    return lo + (((hi - lo) * f + 2048) >> 12)
