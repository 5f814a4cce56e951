"""`radarcl evaluate-lidar`: radar maps of a recording scored against the lidar that came with
it (``evaluation.lidar``), per range band, beside the controls that use no radar data and the
raw intensity, and the annotated vehicles checked (RADIATE).

Every map is fused on one plane grid (the radar's plane around its path) from the same scans
and poses: the configurations named (``MODELS``: the sensor's own defaults, i.e. the paper's
constants; the tuned ones; the calibrated occlusion-aware ones; the detection-statistics model,
scored as its reading reads it) or given as files (any
configuration ``--config`` takes, e.g. of a new sensor model), so that any model can be scored
with no code change.

A part of the recording (``scans``: a slice of its scans in order, e.g. the part a model was not
fitted on) is scored against the lidar frames taken while those scans were; the part is named in
the result and the table's first line. Beside the ranking scores, each map is read at the
costmap's own thresholds (``evaluation.lidar.costmap_scores``), and the raw intensity is
thresholded at each map's recall to show whether the model calls fewer phantoms than raw
intensity at equal recall.
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
from radarcl.gridspec import GridSpec
from radarcl.io import files, radiate
from radarcl.io.inputs import open_input, polar_source
from radarcl.maps.map import FREE_NATS, KNOWN_LOOKS, OCCUPIED_NATS
from radarcl.pipeline import Mapping, new_grid
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


def lidar_frames(root, track, report=print, mount=None, window_ns=None):
    """[(time_ns, pose, REP-103 points)] of the recording's lidar frames that the trajectory
    covers (the others named in one line), and with ``window_ns`` (t0, t1) [UNIX ns] only those
    taken within it; the lidar's pose is the radar's times ``mount`` (default: RADIATE's
    lidar-to-radar calibration, ``radiate.lidar_mount``)."""
    mount = radiate.lidar_mount() if mount is None else np.asarray(mount, float)
    out, left = [], []
    for name, t, path in radiate.lidar_frames(root):
        if window_ns is not None and not window_ns[0] <= t <= window_ns[1]:
            continue
        try:
            pose = track.at([t])[0] @ mount
        except FrameFormatError:
            left.append(name)
            continue
        out.append((t, pose, radiate.lidar_to_rep103(radiate.read_lidar_frame(path))))
    if left:
        report(f"lidar frames {left[0]}..{left[-1]} ({len(left)}) lie outside the trajectory: left out")
    if not out:
        within = "" if window_ns is None else " and the scans' time"
        raise FrameFormatError(f"{root}: no lidar frame lies within the trajectory{within}")
    return out


def format_scans(scans):
    """``scans`` (start, stop) as the text --scans takes: "A:B", either side empty for None."""
    return ":".join("" if v is None else str(v) for v in scans)


def select_scans(scans, n):
    """(start, stop) indices of the recording's ``n`` scans that ``scans`` selects: (start,
    stop) as a Python slice takes them (None: from the first / to the end; negative: counted
    from the end), or None for all. ConfigError in a sentence when a bound lies outside the
    recording or the range holds no scan (a slice would quietly shrink or empty it)."""
    if scans is None:
        return 0, n
    start, stop = scans
    a = 0 if start is None else start + n if start < 0 else start
    b = n if stop is None else stop + n if stop < 0 else stop
    if not (0 <= a <= n and 0 <= b <= n):
        raise ConfigError(f"--scans {format_scans(scans)} lies outside the recording's {n} scans: its "
                          f"bounds run from 0 to {n} (or -{n} to -1 from the end)")
    if b <= a:
        raise ConfigError(f"--scans {format_scans(scans)} selects no scan (scans {a} up to, not including, {b} of the "
                          f"recording's {n})")
    return a, b


def scan_part(source, start, stop):
    """The ``io.inputs.FrameSource`` of polar scans ``start:stop`` of ``source`` (its poses,
    trajectory and notes kept)."""
    scans = source.frames.scans
    part = polar_source(source.sensor, scans[start:stop], source.poses[start:stop],
                        f"scans {start}:{stop} of {source.summary}")
    part.posed, part.notes, part.trajectory = source.posed, source.notes, source.trajectory
    return part


def _scan_range(all_scans, start, stop, lidar_within):
    """The result's description of the scans scored: indices, names, times."""
    first, last = all_scans[start], all_scans[stop - 1]
    t0, t1 = int(first.timestamps_ns.min()), int(last.timestamps_ns.max())
    origin = int(all_scans[0].timestamps_ns.min())
    return dict(start=start, stop=stop, total=len(all_scans), first=first.path.stem, last=last.path.stem,
                start_s=(t0 - origin) / 1e9, end_s=(t1 - origin) / 1e9, start_unix_s=t0 / 1e9, end_unix_s=t1 / 1e9,
                lidar_within=lidar_within)


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


def lidar_part(sensor, data, voxel_m=0.3, range_m=L.BANDS_M[-1], poses=None, poses_format=None, clock_offset_s=None,
               report=print, scan_slice=None):
    """The recording ``data`` read as ``sensor``, or its scans ``scan_slice`` ((start, stop),
    ``select_scans``), with the lidar frames taken meanwhile: (the posed ``FrameSource`` of the
    scans, the scans' description, the lidar frames, their ``LidarTruth`` on a plane grid of
    ``voxel_m`` reaching ``range_m`` past the radar's path)."""
    source = open_input(sensor, data, poses=poses, poses_format=poses_format, clock_offset_s=clock_offset_s,
                        report=report)
    if not source.posed:
        raise ConfigError(f"{data}: scoring against the lidar needs the radar's poses (none given or found); give "
                          f"--poses FILE")
    all_scans = source.frames.scans
    start, stop = select_scans(scan_slice, len(all_scans))
    is_part = (start, stop) != (0, len(all_scans))
    if is_part:
        source = scan_part(source, start, stop)
    scans, per_beam = source.frames.scans, np.asarray(source.poses)      # a part's poses, held
    scan_range = _scan_range(all_scans, start, stop, lidar_within=is_part)
    window = (int(scans[0].timestamps_ns.min()), int(scans[-1].timestamps_ns.max())) if is_part else None
    frames = lidar_frames(Path(data), source.trajectory, report, window_ns=window)
    spec = L.plane_spec(per_beam[..., :3, 3], range_m, voxel_m)
    truth = L.lidar_truth(spec, [(pose, points) for _, pose, points in frames])
    report(f"lidar truth from {len(frames)} frames on a {spec.shape[0]} x {spec.shape[1]} grid of {voxel_m:g} m: "
           f"{int(truth.occupied.sum())} occupied, {int(truth.free.sum())} free cells; each frame reaches "
           f"{np.min(truth.reach_m):.1f}-{np.max(truth.reach_m):.1f} m ({L.REACH_PERCENTILE:g} % of its points)")
    return source, scan_range, frames, truth


def run(runtime, models, data, voxel_m=0.3, bands=L.BANDS_M, poses=None, poses_format=None, clock_offset_s=None,
        report=print, progress=None, scan_slice=None):
    """Score ``models`` [(label, Resolved)] on the recording ``data``, or on its scans
    ``scan_slice`` ((start, stop) as a slice takes them, ``select_scans``) against the lidar
    frames taken meanwhile; returns the result dict (the scans scored, rows per band, boxes, the
    truth's summary) and the arrays to draw ({name: (ny, nx)}; ``known``: {name: (ny, nx) bool}
    of the maps with the knowledge channel)."""
    sensor = models[0][1].sensor
    source, scan_range, frames, truth = lidar_part(sensor, data, voxel_m, bands[-1], poses, poses_format,
                                                   clock_offset_s, report, scan_slice)
    models = [(label, c.for_sensor(source.sensor)) for label, c in models]
    scans, per_beam, track = source.frames.scans, np.asarray(source.poses), source.trajectory
    spec, root = truth.spec, Path(data)
    maps, known = {}, {}
    for k, (label, config) in enumerate(models):
        if config["grid.voxel_m"] != spec.voxel_m:        # the plane grid's cells: a default prior follows them
            config = config.replaced(grid__voxel_m=spec.voxel_m)
        mapping = Mapping.from_config(runtime, config=config, grid=new_grid(runtime, config, spec),
                                      per_beam_poses=True)
        mapping.fuse_source(source)
        # a map of the detection-statistics model is scored as it reads (its reading), not its sums,
        # and a cell it does not know is unknown whatever it reads (the costmap export's rule)
        if mapping.grid.has_knowledge:
            units, knows = read_units(mapping.grid, config)
            maps[label], known[label] = L.nats_of(units), knows[0]
        else:
            maps[label] = L.nats_of(mapping.snapshot())
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
    rows = L.band_scores(truth, distance, *scored, bands, known=known, equal_recall=RAW)
    rows_visible = L.band_scores(truth, distance, *scored, bands, mask=visible, known=known, equal_recall=RAW)
    for row in rows + rows_visible:                  # the range control with whichever sign ranks better
        row["auc"][RANGE] = max(row["auc"][RANGE], 1 - row["auc"][RANGE])
    placed, boxes = [], []
    if (root / "annotations" / "annotations.json").is_file():
        placed = object_boxes(root, source, track)
        boxes = L.box_scores(spec, placed, {**maps, RAW: raw}, truth)
    result = dict(data=str(data), sensor=sensor.name, scans=len(scans), scan_range=scan_range,
                  lidar_frames=len(frames), voxel_m=voxel_m,
                  models={label: c.as_dict() for label, c in models}, notes=list(source.notes),
                  reach_m=[float(r) for r in truth.reach_m], occupied=int(truth.occupied.sum()),
                  free=int(truth.free.sum()), visible_occupied=int((truth.occupied & visible).sum()),
                  visible_free=int((truth.free & visible).sum()), bands=rows, bands_visible=rows_visible,
                  boxes=boxes, goal=goal(rows),
                  costmap_thresholds=dict(occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS, known_looks=KNOWN_LOOKS))
    arrays = dict(truth=truth, maps=maps, known=known, raw=raw, count=count, spec=spec, per_beam=per_beam,
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


def scans_line(result):
    """One line: which of the recording's scans were scored (indices, count, names, times) and
    against which lidar frames."""
    r = result["scan_range"]
    which = "all" if (r["start"], r["stop"]) == (0, r["total"]) else f"{r['stop'] - r['start']} scans"
    lidar = "taken meanwhile" if r["lidar_within"] else "(all the trajectory covers)"
    return (f"scans {r['start']}:{r['stop']} of {r['total']} ({which}: {r['first']}..{r['last']}), "
            f"{r['start_s']:.2f}-{r['end_s']:.2f} s after the recording's first (UNIX {r['start_unix_s']:.3f}-"
            f"{r['end_unix_s']:.3f} s); {result['lidar_frames']} lidar frames {lidar}")


def _share(v):
    return "-" if v is None or not np.isfinite(v) else f"{v:.3f}"


def _raw_cell(c):
    """The raw intensity at the map's recall: "phantom rate @ threshold [nat]"."""
    t = c.get("equal_recall_threshold")
    if t is None or np.isnan(t):
        return "-"
    return f"{_share(c['equal_recall_phantom'])} @ {'none' if np.isinf(t) else f'{t:.2f}'}"


def _costmap_tables(result):
    """Lines: per map, its costmap figures per band (every cell the lidar knows, then the cells
    the radar could see)."""
    t = result["costmap_thresholds"]
    lines = [f"at the costmap's thresholds (occupied above {t['occupied_nats']:g} nat, free below "
             f"{t['free_nats']:g} nat; unknown between them, where a map holds no evidence, and where a map with "
             f"knowledge knows less than {t['known_looks']:g} look whatever it reads), of the cells the lidar knows "
             "in the band:",
             "  recall: occupied ones called occupied; phantom: free ones called occupied; raw @recall: the raw "
             "intensity's phantom rate @ the threshold [nat] above which it calls the same share of occupied ones "
             "occupied (ties at it split to match); miss: occupied ones called free; unknown: called neither; ECE (10 "
             "bins) of the map's p against the lidar over the cells the map knows (cells), those it does not know "
             "left out (they count in unknown)"]
    sets = [("", result["bands"]), ("radar-visible ", result.get("bands_visible") or [])]
    for name in result["bands"][0]["costmap"]:
        lines += ["", f"{name}:", "| band | recall | phantom | raw @recall | miss | unknown | ECE (cells) |",
                  "|---|---|---|---|---|---|---|"]
        for prefix, rows in sets:
            for row in rows:
                c = row["costmap"][name]
                cells = [_share(c["recall"]), _share(c["phantom"]), _raw_cell(c), _share(c["miss"]),
                         _share(c["unknown"]), f"{_share(c['ece'])} ({c['ece_cells']})"]
                lines.append(f"| {prefix}{row['band'][0]:g}-{row['band'][1]:g} m | " + " | ".join(cells) + " |")
    return lines


def table(result):
    """Lines: the scans scored; the per-band tables (AUC of every map and baseline, IoU of every
    map; over all the cells the lidar knows, then over those the radar could see); per map its
    figures at the costmap's thresholds; the boxes."""
    rows = result["bands"]
    if not rows:
        return [scans_line(result), "no range band holds enough cells the lidar knows"]
    lines = [scans_line(result), "",
             f"every cell the lidar knows ({result['occupied']} occupied, {result['free']} free):"] + _band_table(rows)
    for band, (best, a, met) in result["goal"].items():
        lines.append(f"goal {band}: best map {best} AUC {a:.3f}: {'met' if met else 'not met'} (>= controls + 0.10 "
                     "and > raw intensity)")
    if result.get("bands_visible"):
        lines += ["", f"cells the radar could see, the lidar's truth taken as the world ({result['visible_occupied']} "
                      f"occupied, {result['visible_free']} free):"] + _band_table(result["bands_visible"])
    lines += [""] + _costmap_tables(result)
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
    """Top-down PNGs in ``out_dir`` around what the lidar knows: the lidar truth, the map ``best``
    with the annotated boxes (the cells a map with knowledge does not know grey), and the two side
    by side; returns their paths."""
    from PIL import Image

    out_dir = Path(out_dir)
    truth = arrays["truth"]
    ys, xs, spec = _crop(arrays)
    path = arrays["per_beam"][:, arrays["per_beam"].shape[1] // 2]
    t = np.where(truth.occupied, 1.0, np.where(truth.free, -1.0, 0.0))[ys, xs]
    fig = figures.plane_map_figure(t, spec, path, "lidar truth: red occupied, blue free", "radar path",
                                   "lidar truth (+1 occupied, -1 free)")
    truth_png = out_dir / "lidar_truth.png"
    figures.save(fig, truth_png, dpi=80)
    unknown = None if best not in arrays["known"] else ~arrays["known"][best][ys, xs]
    fig = figures.plane_map_figure(arrays["maps"][best][ys, xs], spec, path, f"{best}, annotated vehicles in green",
                                   "radar path", unknown=unknown)
    ax = fig.axes[0]
    for _, _, _, corners, _ in arrays["boxes"]:
        c = np.vstack([corners, corners[:1]])
        ax.plot(c[:, 1], c[:, 0], "-", color="tab:green", lw=1.2)
    map_png = out_dir / "lidar_map.png"
    figures.save(fig, map_png, dpi=80)
    beside_png = out_dir / "lidar_beside_map.png"
    with Image.open(truth_png) as left, Image.open(map_png) as right, files.atomic(beside_png) as tmp:
        both = Image.new("RGB", (left.width + right.width, max(left.height, right.height)), "white")
        both.paste(left, (0, 0))
        both.paste(right, (left.width, 0))
        both.save(tmp, format="PNG")
    return truth_png, map_png, beside_png


def write_json(result, path):
    """The result as JSON (numpy scalars as numbers)."""
    Path(path).write_text(json.dumps(result, indent=1, default=lambda v: v.item() if hasattr(v, "item") else str(v)))
