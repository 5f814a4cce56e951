"""`radarcl evaluate-lidar`: radar maps of a recording scored against the lidar that came with
it (``evaluation.lidar``), per range band, beside the controls that use no radar data and the
raw intensity, and the annotated vehicles checked (RADIATE).

Every map is fused on one plane grid (the radar's plane around its path) from the same scans
and poses: the configurations named (``MODELS``: the sensor's own defaults, i.e. the paper's
constants; the tuned ones; the calibrated occlusion-aware ones; the detection-statistics model,
scored as its reading reads it) or given as files (any
configuration ``--config`` takes, e.g. of a new sensor model), so that any model can be scored
with no code change.
"""

import json
import math
from pathlib import Path

import numpy as np

from radarcl.config import mapconfig
from radarcl.config.presets import EQ12
from radarcl.errors import ConfigError, FrameFormatError
from radarcl.evaluation import calibration, heldout, tuning
from radarcl.evaluation import lidar as L
from radarcl.evaluation.evaluate import read_units
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import GridSpec
from radarcl.io import radiate
from radarcl.io.inputs import open_input
from radarcl.pipeline import Mapping
from radarcl.report import figures

MODELS = {"paper": ("paper constants", EQ12), "tuned": ("tuned", tuning.TUNED),
          "calibrated": ("calibrated (occlusion-aware)", calibration.CALIBRATED),
          "detstats": ("detection statistics", {"interpret.model": "detstats"})}
RAW, COUNT, RANGE = "raw intensity", "no radar: -1 per sample", "no radar: range (better sign)"


def resolve_models(sensor, names, flags=None, force_sensor=False):
    """[(label, mapconfig.Resolved)] of ``names``: keys of ``MODELS`` or configuration files."""
    out = []
    for name in names:
        if name in MODELS:
            label, values = MODELS[name]
            out.append((label, mapconfig.resolve(sensor, program=values, flags=flags)))
        elif Path(name).is_file():
            out.append((Path(name).stem, mapconfig.resolve(sensor, name, flags, force_sensor=force_sensor)))
        else:
            raise ConfigError(f"--model {name!r}: neither a model ({', '.join(MODELS)}) nor a configuration file")
    if len({c.sensor.name for _, c in out}) > 1:
        raise ConfigError("every --model must be for one sensor")
    return out


def lidar_frames(root, track, report=print, mount=None):
    """[(time_ns, pose, REP-103 points)] of the recording's lidar frames that the trajectory
    covers (the others named in one line); the lidar's pose is the radar's times ``mount``
    (default: RADIATE's lidar-to-radar calibration, ``radiate.lidar_mount``)."""
    mount = radiate.lidar_mount() if mount is None else np.asarray(mount, float)
    out, left = [], []
    for name, t, path in radiate.lidar_frames(root):
        try:
            pose = track.at([t])[0] @ mount
        except FrameFormatError:
            left.append(name)
            continue
        out.append((t, pose, radiate.lidar_to_rep103(radiate.read_lidar_frame(path))))
    if left:
        report(f"lidar frames {left[0]}..{left[-1]} ({len(left)}) lie outside the trajectory: left out")
    if not out:
        raise FrameFormatError(f"{root}: no lidar frame lies within the trajectory")
    return out


def object_boxes(root, source, track):
    """[(object, class, frame, world corners (4, 2), radar position (2,))] of the annotations of
    the scans fused: each box placed with the radar's pose at the time of the azimuth that
    looks at its centre."""
    scans = {int(s.path.stem): s for s in source.frames.scans if s.path.stem.isdigit()}
    out = []
    for box in radiate.read_annotations(root):
        scan = scans.get(box.frame)
        if scan is None:
            continue
        centre = box.corners.mean(axis=0)
        bearing = math.atan2(centre[1], centre[0]) % (2 * math.pi)
        row = int(np.argmin(np.abs(np.angle(np.exp(1j * (scan.angles_rad - bearing))))))
        pose = track.at([scan.timestamps_ns[row]])[0]
        world = box.corners @ pose[:2, :2].T + pose[:2, 3]
        out.append((box.object_id, box.class_name, box.frame, world, pose[:2, 3]))
    return out


def run(runtime, models, data, voxel_m=0.3, bands=L.BANDS_M, poses=None, poses_format=None, clock_offset_s=None,
        report=print, progress=None):
    """Score ``models`` [(label, Resolved)] on the recording ``data``; returns the result dict
    (rows per band, boxes, the truth's summary) and the arrays to draw ({name: (ny, nx)})."""
    sensor = models[0][1].sensor
    source = open_input(sensor, data, poses=poses, poses_format=poses_format, clock_offset_s=clock_offset_s,
                        report=report)
    if not source.posed:
        raise ConfigError(f"{data}: evaluate-lidar needs the radar's poses (none given or found); give --poses FILE")
    models = [(label, c.for_sensor(source.sensor)) for label, c in models]
    scans, per_beam, track = source.frames.scans, source.poses, source.trajectory
    root = Path(data)
    frames = lidar_frames(root, track, report)
    spec = L.plane_spec(per_beam[..., :3, 3], bands[-1], voxel_m)
    truth = L.lidar_truth(spec, [(pose, points) for _, pose, points in frames])
    report(f"lidar truth from {len(frames)} frames on a {spec.shape[0]} x {spec.shape[1]} grid of {voxel_m:g} m: "
           f"{int(truth.occupied.sum())} occupied, {int(truth.free.sum())} free cells; each frame reaches "
           f"{np.min(truth.reach_m):.1f}-{np.max(truth.reach_m):.1f} m ({L.REACH_PERCENTILE:g} % of its points)")
    maps = {}
    for k, (label, config) in enumerate(models):
        if config["grid.voxel_m"] != spec.voxel_m:        # the plane grid's cells: a default prior follows them
            config = config.replaced(grid__voxel_m=spec.voxel_m)
        detstats = config["interpret.model"] == "detstats"
        mapping = Mapping.from_config(runtime, config=config, grid=EvidenceGrid(runtime, spec, knowledge=detstats),
                                      per_beam_poses=True)
        mapping.fuse_source(source)
        # a map of the detection-statistics model is scored as it reads (its reading), not its sums
        maps[label] = L.nats_of(read_units(mapping.grid, config)[0] if detstats else mapping.snapshot())
        if progress is not None:
            progress(k + 1, len(models) + 2, "maps fused")
    base = models[0][1]
    raw = L.nats_of(heldout.raw_map(runtime, base, spec, scans, per_beam))
    count = L.nats_of(L.count_map(runtime, base, spec, scans, per_beam))
    if progress is not None:
        progress(len(models) + 2, len(models) + 2, "maps fused")
    distance = L.range_from_path(spec, per_beam[..., :3, 3].reshape(-1, 3))
    window = (base["interpret.range_min_m"], min(base["interpret.range_max_m"], bands[-1]))
    visible = L.radar_visible(truth, per_beam, *window)
    scored = maps, {RAW: raw, COUNT: count, RANGE: distance}
    rows = L.band_scores(truth, distance, *scored, bands)
    rows_visible = L.band_scores(truth, distance, *scored, bands, mask=visible)
    for row in rows + rows_visible:                  # the range control with whichever sign ranks better
        row["auc"][RANGE] = max(row["auc"][RANGE], 1 - row["auc"][RANGE])
    placed, boxes = [], []
    if (root / "annotations" / "annotations.json").is_file():
        placed = object_boxes(root, source, track)
        boxes = L.box_scores(spec, placed, {**maps, RAW: raw}, truth)
    result = dict(data=str(data), sensor=sensor.name, scans=len(scans), lidar_frames=len(frames), voxel_m=voxel_m,
                  models={label: c.as_dict() for label, c in models}, notes=list(source.notes),
                  reach_m=[float(r) for r in truth.reach_m], occupied=int(truth.occupied.sum()),
                  free=int(truth.free.sum()), visible_occupied=int((truth.occupied & visible).sum()),
                  visible_free=int((truth.free & visible).sum()), bands=rows, bands_visible=rows_visible,
                  boxes=boxes, goal=goal(rows))
    arrays = dict(truth=truth, maps=maps, raw=raw, count=count, spec=spec, per_beam=per_beam,
                  boxes=placed, trajectory=track)
    return result, arrays


def goal(rows, margin=0.10):
    """Per band, the best map and whether it beats both no-radar controls by ``margin`` and the
    raw intensity: {band: (best map, its AUC, met)}."""
    out = {}
    for row in rows:
        best = max((m for m in row["iou"]), key=lambda m: row["auc"][m])
        a = row["auc"][best]
        met = a >= max(row["auc"][COUNT], row["auc"][RANGE]) + margin and a > row["auc"][RAW]
        out[f"{row['band'][0]:g}-{row['band'][1]:g} m"] = (best, a, bool(met))
    return out


def _band_table(rows):
    names, maps = list(rows[0]["auc"]), list(rows[0]["iou"])
    lines = ["| band | occupied / free | " + " | ".join(f"AUC {n}" for n in names) + " | "
             + " | ".join(f"IoU {n}" for n in maps) + " |", "|" + "---|" * (2 + len(names) + len(maps))]
    for row in rows:
        lines.append(f"| {row['band'][0]:g}-{row['band'][1]:g} m | {row['occupied']} / {row['free']} | "
                     + " | ".join(f"{row['auc'][n]:.3f}" for n in names) + " | "
                     + " | ".join(f"{row['iou'][n]:.3f}" for n in maps) + " |")
    return lines


def table(result):
    """Lines: the per-band tables (AUC of every map and baseline, IoU of every map; over all the
    cells the lidar knows, then over those the radar could see) and the boxes."""
    rows = result["bands"]
    if not rows:
        return ["no range band holds enough cells the lidar knows"]
    lines = [f"every cell the lidar knows ({result['occupied']} occupied, {result['free']} free):"] + _band_table(rows)
    for band, (best, a, met) in result["goal"].items():
        lines.append(f"goal {band}: best map {best} AUC {a:.3f}: {'met' if met else 'not met'} (>= controls + 0.10 "
                     "and > raw intensity)")
    if result.get("bands_visible"):
        lines += ["", f"cells the radar could see, the lidar's truth taken as the world ({result['visible_occupied']} "
                      f"occupied, {result['visible_free']} free):"] + _band_table(result["bands_visible"])
    if result["boxes"]:
        lines.append("")
        lines.append("| object | class | frame | range [m] | cells | lidar hits | " +
                     " | ".join(f"{n}: occupied (peak nat, chance, rank)" for n in result["boxes"][0]["maps"]) + " |")
        lines.append("|" + "---|" * (6 + len(result["boxes"][0]["maps"])))
        for b in result["boxes"]:
            lines.append(f"| {b['object']} | {b['cls']} | {b['frame']} | {b['range_m']:.1f} | {b['cells']} | "
                         f"{b['lidar_hits']} | " + " | ".join(
                             f"{'yes' if o else 'no'} ({p:.1f}, {c:.2f}, {k:.2f})" for o, p, c, k in b["maps"].values()) + " |")
        for name in result["boxes"][0]["maps"]:
            found = sum(b["maps"][name][0] for b in result["boxes"])
            chance = np.median([b["maps"][name][2] for b in result["boxes"]])
            rank = np.nanmean([b["maps"][name][3] for b in result["boxes"]])
            lines.append(f"{name}: {found} of {len(result['boxes'])} boxes occupied (median chance {chance:.2f}); "
                         f"mean rank of a box among its copies turned about the radar {rank:.2f} (0.5: no better than "
                         f"anywhere at its range)")
    return lines


def _crop(arrays, margin_m=5.0):
    """(slice y, slice x, GridSpec) of the plane grid around what the lidar knows and the boxes."""
    spec, truth = arrays["spec"], arrays["truth"]
    iy, ix = np.nonzero(truth.known)
    pts = [np.column_stack([spec.origin_m[0] + (ix + 0.5) * spec.voxel_m, spec.origin_m[1] + (iy + 0.5) * spec.voxel_m])]
    pts += [b[3] for b in arrays["boxes"]]
    pts = np.vstack(pts)
    lo = np.floor((pts.min(axis=0) - margin_m - spec.origin_m[:2]) / spec.voxel_m).astype(int)
    hi = np.ceil((pts.max(axis=0) + margin_m - spec.origin_m[:2]) / spec.voxel_m).astype(int)
    lo, hi = np.maximum(lo, 0), np.minimum(hi, spec.shape[:2])
    cropped = GridSpec((spec.origin_m[0] + lo[0] * spec.voxel_m, spec.origin_m[1] + lo[1] * spec.voxel_m,
                        spec.origin_m[2]), spec.voxel_m, (int(hi[0] - lo[0]), int(hi[1] - lo[1]), 1))
    return slice(lo[1], hi[1]), slice(lo[0], hi[0]), cropped


def plot(arrays, out_dir, best):
    """Two top-down PNGs in ``out_dir`` around what the lidar knows: the lidar truth and the map
    ``best`` with the annotated boxes; returns their paths."""
    out_dir = Path(out_dir)
    truth = arrays["truth"]
    ys, xs, spec = _crop(arrays)
    path = arrays["per_beam"][:, arrays["per_beam"].shape[1] // 2]
    t = np.where(truth.occupied, 1.0, np.where(truth.free, -1.0, 0.0))[ys, xs]
    fig = figures.plane_map_figure(t, spec, path, "lidar truth: red occupied, blue free", "radar path",
                                   "lidar truth (+1 occupied, -1 free)")
    truth_png = out_dir / "lidar_truth.png"
    figures.save(fig, truth_png, dpi=80)
    fig = figures.plane_map_figure(arrays["maps"][best][ys, xs], spec, path, f"{best}, annotated vehicles in green",
                                   "radar path")
    ax = fig.axes[0]
    for _, _, _, corners, _ in arrays["boxes"]:
        c = np.vstack([corners, corners[:1]])
        ax.plot(c[:, 1], c[:, 0], "-", color="tab:green", lw=1.2)
    map_png = out_dir / "lidar_map.png"
    figures.save(fig, map_png, dpi=80)
    return truth_png, map_png


def write_json(result, path):
    """The result as JSON (numpy scalars as numbers)."""
    Path(path).write_text(json.dumps(result, indent=1, default=lambda v: v.item() if hasattr(v, "item") else str(v)))
