"""What a map says, at a glance: the blocks that open every page (``html``) about a map."""

import math

from radarcl.maps.map import FREE_NATS, OCCUPIED_NATS
from radarcl.report.html import Pairs, Text


def probability(nats):
    """The occupancy probability of a log-odds [nat]."""
    return 1.0 / (1.0 + math.exp(-nats))


def threshold_text(occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS):
    """The thresholds in nats with their probabilities."""
    return (f"occupied above {occupied_nats:g} nat (p {probability(occupied_nats):.2f}), free below {free_nats:g} nat "
            f"(p {probability(free_nats):.2f}), undecided between")


def map_summary(m, path, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS, band_hint=None):
    """Blocks: the voxels by class with their volumes (a planar map: cells with their areas), the area seen from above by class, the
    thresholds, and the commands to run next on the map at ``path`` (``band_hint``: a height
    band for the costmap command, (z_min, z_max) [m])."""
    v = m.spec.voxel_m
    counts = m.counts(occupied_nats, free_nats)
    top = m.projection(None, occupied_nats, free_nats)
    cell = v * v
    if m.spec.shape[2] == 1:            # one voxel thick: a planar map's cells cover an area, not a volume
        rows = {f"{name} cells": f"{n:,} ({n * v * v:,.0f} m²)" for name, n in counts.items() if name != "unobserved"}
    else:
        rows = {f"{name} voxels": f"{n:,} ({n * v ** 3:,.1f} m³)" for name, n in counts.items() if name != "unobserved"}
    rows[f"{'cells' if m.spec.shape[2] == 1 else 'voxels'} never observed"] = f"{counts['unobserved']:,}"
    rows["seen from above [m²]"] = (f"occupied {(top == 100).sum() * cell:,.0f}, free {(top == 0).sum() * cell:,.0f}, "
                                    f"unknown {(top == -1).sum() * cell:,.0f}")
    rows["what the classes mean"] = threshold_text(occupied_nats, free_nats)
    band = "" if band_hint is None else f" --band {band_hint[0]:g} {band_hint[1]:g}"
    stem = str(path).rsplit(".", 1)[0] if str(path).endswith((".npz", ".rcmap")) else str(path)
    nxt = (f"Next: radarcl view {path} (look at it); radarcl export {path} --to costmap --out {stem}.pgm{band} "
           f"(a Nav2 costmap); --to octomap --out {stem}.bt (OctoMap, octovis); --to ply --out {stem}.ply "
           "(CloudCompare, MeshLab); --to rosbag --out {stem}_bag (ROS 2).").replace("{stem}", stem)
    return [Pairs(rows), Text(nxt)]
