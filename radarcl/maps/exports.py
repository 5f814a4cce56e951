"""Maps out of the engine, in the formats the field's tools read (``radarcl export``).

The formats are one table, ``FORMATS``: each an ``Export`` naming its ``--to`` name, the
extensions of the file it writes, what it holds (``radarcl export --help`` says it) and the
function that writes it. The command, its help and the table of formats in docs/guide/maps.md read this
table (tests/test_exports.py checks that page against it); a new format is one ``Export``
here (``register``) and its test.

Every export says what the map says: occupied above the occupancy threshold, free below the
free threshold, unknown otherwise (``maps.map``), the same thresholds in every format. Every
exporter takes a ``maps.Map`` and the file to write, and of ``OPTIONS`` only those it names;
it returns a dict with the files it wrote and its counts by class; an empty map gives valid
empty files. Coordinates are the map's world frame (x forward, y left, z up, REP-103).
"""

import base64
import importlib
import inspect
import logging
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from radarcl import logodds
from radarcl.errors import ConfigError
from radarcl.io.files import atomic
from radarcl.maps import octree, ros
from radarcl.maps.map import FREE, FREE_NATS, KNOWN_LOOKS, OCCUPIED, OCCUPIED_NATS, check_thresholds, classes

log = logging.getLogger(__name__)
CLAMP_NATS = 13.8            # OctoMap keeps log-odds within its clamping thresholds: p in [1e-6, 1 - 1e-6]
LATTICE_TOLERANCE = 1e-6     # of a voxel: an origin closer than this to OctoMap's lattice lies on it
COLOURS = ("log-odds", "height")


def _need(module, extra="export"):
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ConfigError(f"this export needs {module.split('.')[0]} (pip install 'radarcl[{extra}]'): {exc}") from None


def check_suffix(fmt, path):
    """ConfigError when ``path``'s extension names another format than ``fmt`` (its ``Export.suffixes``)."""
    if fmt not in FORMATS:
        raise ConfigError(f"unknown export format {fmt!r}; formats: {', '.join(FORMATS)}")
    suffix = Path(path).suffix.lower()
    allowed = FORMATS[fmt].suffixes
    if suffix in allowed:
        return
    if allowed == ("",):
        raise ConfigError(f"--to {fmt} writes a directory; give --out a name without an extension, not {path}")
    owner = next((f.name for f in FORMATS.values() if suffix and suffix in f.suffixes), None)
    named = f" (a {owner} file)" if owner else ""
    raise ConfigError(f"--to {fmt} writes {' or '.join(allowed)} files; {path} names a {suffix or 'file without an'} "
                      f"extension{named}: give --out {Path(path).with_suffix(allowed[0])}")


def _warn_empty(path, n):
    if n == 0:
        log.warning("%s: the map has no voxel to export; wrote a valid empty file", path)


def lattice_shift(spec):
    """How far (x, y, z) [m] the map's voxels would move if taken as OctoMap's, whose lattice
    starts at 0: a voxel centre c lands in OctoMap's voxel floor(c / r), centred half a voxel up."""
    v = spec.voxel_m
    centre = np.asarray(spec.origin_m) + 0.5 * v
    return (np.floor(centre / v) + 0.5) * v - centre + 0.0


def resample_to_lattice(m, units):
    """OctoMap voxel indices (n, 3) and log-odds [nat] of ``m``'s observed voxels (``units``
    their values) interpolated onto OctoMap's lattice: each lattice voxel takes the trilinear
    mean of the observed voxel centres around its own, weights renormalised over the observed
    ones (an unobserved neighbour is not evidence of 0)."""
    idx, _ = m.voxels()
    cells = np.asarray(m.spec.origin_m) / m.spec.voxel_m
    base = np.floor(cells).astype(np.int64)
    f = cells - base                                 # our voxel i overlaps lattice voxels i + base, i + base + 1
    nats = units.astype(np.float64) / logodds.SCALE
    targets, weights = [], []
    for corner in range(8):
        d = np.array([(corner >> a) & 1 for a in range(3)])
        w = np.prod(np.where(d == 1, f, 1.0 - f))
        if w <= 0:
            continue
        targets.append(idx + base + d)
        weights.append(np.full(len(idx), w))
    t = np.concatenate(targets)
    w = np.concatenate(weights)
    v = np.concatenate([nats] * len(targets))
    keys, inverse = np.unique(t, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    total = np.bincount(inverse, weights=w, minlength=len(keys))
    value = np.bincount(inverse, weights=w * v, minlength=len(keys)) / total
    return keys, value


def octomap(m, path, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS, binary=None, resample=False):
    """The occupied and the free voxels as an OctoMap of the map's voxel size (``maps.octree``):
    ``.bt`` (occupied/free) or ``.ot`` (their log-odds). OctoMap's lattice starts at 0: a map
    whose origin is off it by more than ``LATTICE_TOLERANCE`` of a voxel is refused with the
    shift, unless ``resample`` (``resample_to_lattice``). Returns the files and counts."""
    occ, free = check_thresholds(occupied_nats, free_nats)
    path = Path(path)
    binary = path.suffix == ".bt" if binary is None else binary
    res = m.spec.voxel_m
    shift = lattice_shift(m.spec)
    planar = m.spec.shape[2] == 1 and abs(abs(shift[2]) - 0.5 * res) <= LATTICE_TOLERANCE * res
    if planar and not np.any(np.abs(shift[:2]) > LATTICE_TOLERANCE * res):
        # a planar sensor's map is one layer centred on its plane, which OctoMap's lattice cannot
        # centre a layer on: the layer goes whole into the lattice layer above the plane (no voxel
        # split in two, as a resampling would), and the note says so
        shift = np.array([shift[0], shift[1], 0.0])
    off = np.any(np.abs(shift) > LATTICE_TOLERANCE * res)
    if resample and off:
        keys, nats = resample_to_lattice(m, m.voxels()[1])
        keys = keys + octree.CENTRE_KEY
        note = "resampled onto OctoMap's lattice"
    elif off:
        raise ConfigError(f"the map's grid origin {list(m.spec.origin_m)} m is not on OctoMap's lattice of {res:g} m "
                          f"voxels (which starts at 0): as OctoMap voxels the map would move by "
                          f"{[round(float(v), 6) + 0.0 for v in shift]} m; pass --resample to interpolate it onto the "
                          "lattice, or fuse with a grid.origin_m that is a multiple of grid.voxel_m")
    else:
        idx, units = m.decided(occ, free)              # the undecided voxels never leave the bricks
        # on the lattice: OctoMap's key of voxel i is i plus the origin's whole voxels
        first = np.floor((np.asarray(m.spec.origin_m) + 0.5 * res) / res + LATTICE_TOLERANCE).astype(np.int64)
        keys = idx + (first + octree.CENTRE_KEY)
        nats = units.astype(np.float64) / logodds.SCALE
        note = "on OctoMap's lattice"
        if planar:
            z = float(m.spec.origin_m[2]) + 0.5 * res
            note += (f"; the planar map's one layer (centred at z = {z:g} m) is OctoMap's layer from "
                     f"{first[2] * res:g} to {(first[2] + 1) * res:g} m")
    if len(keys) and (keys.min() < 0 or keys.max() >= 2 * octree.CENTRE_KEY):
        raise ConfigError(f"the map does not fit OctoMap's tree of {2 * octree.CENTRE_KEY} voxels per axis")
    c = classes(np.rint(nats * logodds.SCALE).astype(np.int64), occ, free)
    keep = (c == OCCUPIED) | (c == FREE)
    values = np.clip(nats[keep], -CLAMP_NATS, CLAMP_NATS).astype(np.float32)
    with atomic(path) as tmp, open(tmp, "wb") as f:
        nodes = octree.write(f, keys[keep], values, res, binary)
    _warn_empty(path, int(keep.sum()))
    return dict(files=[path], occupied_voxels=int((c == OCCUPIED).sum()), free_voxels=int((c == FREE).sum()),
                nodes=nodes, lattice=note)


def _colours(values, scheme):
    """(n, 3) uint8 colours of ``values`` on a perceptual colormap over their 1st-99th percentile."""
    import matplotlib

    if not len(values):
        return np.zeros((0, 3), np.uint8)
    lo, hi = np.percentile(values, [1, 99]) if len(values) > 1 else (values[0], values[0] + 1)
    t = np.clip((values - lo) / max(hi - lo, 1e-9), 0, 1)
    cmap = matplotlib.colormaps["inferno" if scheme == "log-odds" else "viridis"]
    return (cmap(t)[:, :3] * 255 + 0.5).astype(np.uint8)


def _ply_comments(m, frame_id, what):
    """The header comments of a PLY export: what it holds, its frame, units and voxel size (a
    PLY has no fields for them; readers show comments, plyfile gives them as ``comments``)."""
    spec = m.spec
    return [f"radarcl {what}", f"frame_id {frame_id}", "units m", f"voxel_m {spec.voxel_m:g}",
            "origin_m " + " ".join(f"{v:g}" for v in spec.origin_m), "shape " + " ".join(map(str, spec.shape))]


def ply_points(m, path, occupied_nats=OCCUPIED_NATS, colour="log-odds", frame_id="map"):
    """The occupied voxels as a PLY point cloud: x, y, z [m], red, green, blue (``colour`` by
    log-odds or height), log_odds [nat], probability; the header's comments name the frame
    (``frame_id``), the units and the voxel size."""
    plyfile = _need("plyfile")
    if colour not in COLOURS:
        raise ConfigError(f"colour must be one of {', '.join(COLOURS)}, got {colour!r}")
    centres, nats = m.occupied(occupied_nats)
    v = np.empty(len(centres), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"),
                                      ("blue", "u1"), ("log_odds", "f4"), ("probability", "f4")])
    v["x"], v["y"], v["z"] = centres.T
    rgb = _colours(nats if colour == "log-odds" else centres[:, 2], colour)
    v["red"], v["green"], v["blue"] = rgb.T
    v["log_odds"], v["probability"] = nats, 1.0 / (1.0 + np.exp(-nats))
    _warn_empty(path, len(v))
    with atomic(path) as tmp:
        plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")], text=False,
                        comments=_ply_comments(m, frame_id, f"occupied voxel centres above {occupied_nats:g} nat")
                        ).write(str(tmp))
    return dict(files=[Path(path)], points=len(v))


def ply_mesh(m, path, occupied_nats=OCCUPIED_NATS, band=None, frame_id="map"):
    """The isosurface at ``occupied_nats`` (marching cubes over the dense log-odds as read,
    ``Map.dense``: unseen 0, or a knowledge map's prior) as a PLY mesh in metres, the frame,
    units and voxel size in its header's comments."""
    plyfile = _need("plyfile")
    mcubes = _need("mcubes")
    occ, _ = check_thresholds(occupied_nats, 0.0)
    d = m.dense(band)
    z0 = 0 if band is None else m._band(band)[0]
    above = np.argwhere(d >= occ * logodds.SCALE)                    # (z, y, x)
    verts, faces = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    if len(above):
        lo = np.maximum(above.min(axis=0) - 1, 0)
        hi = np.minimum(above.max(axis=0) + 2, d.shape)
        sub = d[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        # float32 nats in (x, y, z) order (what marching cubes wants), padded with "free" so the
        # surface closes at the box: one allocation beside the dense copy
        volume = np.full(np.asarray(sub.shape[::-1]) + 2, min(-1.0, occ - 1.0), np.float32)
        volume[1:-1, 1:-1, 1:-1] = sub.transpose(2, 1, 0) * np.float32(1.0 / logodds.SCALE)
        verts, faces = mcubes.marching_cubes(volume, float(occ))
        first = np.array([lo[2], lo[1], lo[0] + z0]) - 1                # voxel index of volume[0, 0, 0]
        verts = np.asarray(m.spec.origin_m) + (verts + first + 0.5) * m.spec.voxel_m
    vertex = np.empty(len(verts), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    if len(verts):
        vertex["x"], vertex["y"], vertex["z"] = np.asarray(verts).T
    face = np.empty(len(faces), dtype=[("vertex_indices", "i4", (3,))])
    face["vertex_indices"] = faces
    _warn_empty(path, len(vertex))
    with atomic(path) as tmp:
        plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex"), plyfile.PlyElement.describe(face, "face")],
                        text=False, comments=_ply_comments(m, frame_id, f"isosurface at {occupied_nats:g} nat")
                        ).write(str(tmp))
    return dict(files=[Path(path)], vertices=len(vertex), faces=len(face))


VTI_BLOCK = 1 << 20            # bytes per zlib block of the .vti data


def _vti_array(name, vtk_type, values):
    """One binary DataArray of VTK's XML image data, zlib-compressed in blocks
    (vtkZLibDataCompressor's layout, UInt64 headers)."""
    raw = values.reshape(-1).tobytes()
    blocks = [zlib.compress(raw[i:i + VTI_BLOCK], 1) for i in range(0, len(raw), VTI_BLOCK)]
    last = len(raw) % VTI_BLOCK or (VTI_BLOCK if raw else 0)
    header = np.array([len(blocks), VTI_BLOCK, last] + [len(b) for b in blocks], "<u8")
    payload = base64.b64encode(header.tobytes()).decode() + base64.b64encode(b"".join(blocks)).decode()
    return f'        <DataArray type="{vtk_type}" Name="{name}" format="binary">\n{payload}\n        </DataArray>\n'


def _vti_string(name, text):
    """A one-string DataArray of VTK's XML field data (ASCII: the characters' codes, 0-ended)."""
    codes = " ".join(str(b) for b in text.encode("utf-8")) + " 0"
    return f'      <DataArray type="String" Name="{name}" NumberOfTuples="1" format="ascii">{codes}</DataArray>\n'


def vti(m, path, band=None, frame_id="map"):
    """Dense log-odds [nat] (float32) and an ``observed`` mask (uint8: some beam reached the
    voxel; with the knowledge channel: the map knows it, ``Map.known``) as VTK XML image data:
    origin at the first voxel centre, spacing the voxel size, x fastest (VTK's point order);
    its field data name the frame (``frame_id``), the units and the voxel size."""
    d = m.dense(band)
    z0 = 0 if band is None else m._band(band)[0]
    nz, ny, nx = d.shape
    nats = (d * np.float32(1.0 / logodds.SCALE)).astype("<f4")
    known = m.dense_knowledge(band)
    observed = ((d != 0) if known is None else (known >= KNOWN_LOOKS)).astype(np.uint8)
    origin = np.asarray(m.spec.origin_m) + 0.5 * m.spec.voxel_m + np.array([0, 0, z0 * m.spec.voxel_m])
    s = m.spec.voxel_m
    extent = f"0 {nx - 1} 0 {ny - 1} 0 {nz - 1}"
    xml = (f'<?xml version="1.0"?>\n'
           f'<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" header_type="UInt64" '
           f'compressor="vtkZLibDataCompressor">\n'
           f'  <ImageData WholeExtent="{extent}" '
           f'Origin="{float(origin[0])!r} {float(origin[1])!r} {float(origin[2])!r}" Spacing="{s!r} {s!r} {s!r}">\n'
           '    <FieldData>\n' + _vti_string("frame_id", frame_id) + _vti_string("units", "m") +
           f'      <DataArray type="Float64" Name="voxel_m" NumberOfTuples="1" format="ascii">{s!r}</DataArray>\n'
           '    </FieldData>\n'
           f'    <Piece Extent="{extent}">\n'
           f'      <PointData Scalars="log_odds">\n'
           + _vti_array("log_odds", "Float32", nats) + _vti_array("observed", "UInt8", observed) +
           '      </PointData>\n    </Piece>\n  </ImageData>\n</VTKFile>\n')
    with atomic(path) as tmp:
        Path(tmp).write_text(xml)
    return dict(files=[Path(path)], voxels=int(d.size), observed_voxels=int(observed.sum()))


def is_bag(path):
    """True when ``path`` is a ROS 2 bag directory (it holds the bag's metadata.yaml)."""
    return (Path(path) / "metadata.yaml").is_file()


BAG_FILES = (".db3", ".mcap", ".db3-shm", ".db3-wal", ".db3-journal")


def only_a_bag(path):
    """A directory --force may replace with a bag: a ROS 2 bag (``is_bag``) holding nothing but
    a bag's files; notes or data of anyone else's beside them keep it."""
    return is_bag(path) and all(p.is_file() and (p.name == "metadata.yaml" or p.name.endswith(BAG_FILES))
                                for p in Path(path).iterdir())


def costmap(m, path, band=None, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS):
    """``maps.ros.costmap``, with a warning when no cell of the band is known."""
    out = ros.costmap(m, path, band, occupied_nats, free_nats)
    if out["occupied_cells"] + out["free_cells"] == 0:
        log.warning("%s: no column of the band is occupied or free; the costmap is all unknown", path)
    return out


def rosbag(m, path, band=None, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS, frame_id="map", stamp_ns=None,
           poses=None, times_ns=None):
    """``maps.ros.rosbag`` (rosbags must be installed)."""
    _need("rosbags")
    return ros.rosbag(m, path, band, occupied_nats, free_nats, frame_id, stamp_ns, poses, times_ns)


# -- the formats ---------------------------------------------------------------------------------------
OPTIONS = {                       # what ``radarcl export`` hands an exporter that names it
    "occupied_nats": "--occupied-threshold [nat]",
    "free_nats": "--free-threshold [nat]",
    "band": "--band (z_min, z_max) [m], or None for the whole grid",
    "resample": "--resample",
    "colour": "--colour, one of COLOURS",
    "frame_id": "--frame-id",
    "stamp_ns": "when the map was saved [ns since the epoch]",
    "poses": "the sensor poses the map keeps (n, 4, 4), or None",
    "times_ns": "their frames' times [ns since the epoch] where the map keeps them, or None",
}


@dataclass(frozen=True)
class Export:
    """One format of ``radarcl export --to NAME``.

    name: the ``--to`` name; suffixes: the extensions ``--out`` may have (``("",)``: it writes a
    directory, named without one); describes: what it writes, for ``--help``; write: the
    exporter, ``write(map, path, **options)`` for the ``OPTIONS`` its signature names, returning
    {"files": [...], counts by class}; companions: (suffix, what) of further files it writes
    beside ``--out`` (checked as ``--out`` is); directory: (what, is_ours) for a format that
    writes a directory, which ``--force`` may replace only where ``is_ours(path)``."""

    name: str
    suffixes: tuple
    describes: str
    write: Callable
    companions: tuple = ()
    directory: tuple = None

    @property
    def options(self):
        """The ``OPTIONS`` the exporter takes, in its signature's order."""
        return tuple(p for p in inspect.signature(self.write).parameters if p in OPTIONS)

    @property
    def thresholds(self):
        """The thresholds its classes follow: ("occupied", "free"), ("occupied",) or () (it writes values)."""
        return tuple(t for t in ("occupied", "free") if f"{t}_nats" in self.options)


def register(export):
    """Add ``export`` (an ``Export``) to ``FORMATS``: ``radarcl export --to`` and its help take it
    from there. Its name must be new, its suffixes lower-case extensions (or ``("",)``), and its
    exporter may take, besides the map and the path, only ``OPTIONS`` (all with defaults but
    those)."""
    if export.name in FORMATS:
        raise ConfigError(f"export format {export.name!r} is registered already")
    if not export.suffixes or not all(s == s.lower() and (s.startswith(".") or export.suffixes == ("",))
                                      for s in export.suffixes):
        raise ConfigError(f"export format {export.name!r}: suffixes must be extensions like '.ply' (or ('',) for "
                          f"a directory), got {export.suffixes!r}")
    params = list(inspect.signature(export.write).parameters.values())[2:]
    unknown = [p.name for p in params if p.name not in OPTIONS and p.default is inspect.Parameter.empty]
    if unknown:
        raise ConfigError(f"export format {export.name!r}: its exporter takes {', '.join(unknown)}, which radarcl "
                          f"export does not give; it gives {', '.join(OPTIONS)}")
    FORMATS[export.name] = export
    return export


FORMATS = {}
register(Export("octomap", (".bt", ".ot"), ".bt (occupied/free) or .ot (their log-odds) on OctoMap's lattice, read "
                                           "by OctoMap and octovis", octomap))
register(Export("ply", (".ply",), "the occupied voxels with colours, log_odds and probability", ply_points))
register(Export("mesh", (".ply",), "the isosurface at the occupied threshold as a PLY mesh", ply_mesh))
register(Export("vti", (".vti",), "the dense log-odds and an observed mask as VTK image data for ParaView", vti))
register(Export("costmap", (".pgm",), "a ROS map_server PGM + YAML projected over --band (occupied, free, unknown)",
                costmap, companions=((".yaml", "costmap YAML"),)))
register(Export("rosbag", ("",), "a ROS 2 bag with the same grid on /map (latched), the occupied voxels on "
                                 "/map/points, the trajectory on /trajectory, /tf and /tf_static, stamped with the "
                                 "recording's time", rosbag, directory=("ROS 2 bag", only_a_bag)))
