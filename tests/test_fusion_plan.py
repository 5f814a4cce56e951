"""kernels/fusion_plan.cl <-> radarcl/stages/fusion_plan.py against its float64 oracle,
radarcl.stages.fusion_plan.candidate_windows: every brick's window of candidate beams.

The device adds DEVICE_REACH_M to every brick's reach, beyond float32's rounding, so its window
holds the oracle's on every brick (wider by one beam where the oracle's bound lies within that
of a beam), and a plan made on the device lists every brick the float64 windows list, maybe a
few more. Neither plan loses evidence: at the paper's scale, every voxel a brute-force float64
sweep of the beams finds lies in a planned brick whose window holds its beam."""

import math

import numpy as np
import pytest

from radarcl.config.stage_config import RadarConfig
from radarcl.geometry import BeamLattice, BeamModel, pose_from_xyz_rpy
from radarcl.gridspec import BRICK, GridSpec
from radarcl.stages.fusion_plan import (BLOCK, COLUMN_TILE, FusionPlanner, HeadFrame, brick_geometry, candidate_windows,
                                        column_tiles)

RADAR = RadarConfig()
WINDOWS_DIFFERING_MAX = 0.02     # share of bricks whose device window is wider (by one index) than float64's

CASES = {
    "paper, tilt -7 deg": (BeamLattice.from_radar(RADAR, tilt_deg=-7.0), pose_from_xyz_rpy(1.0, -2.0, 0.3, yaw=0.4),
                           0.0, 0.0),
    "spinning, 400 azimuths": (BeamLattice.spinning(400, az0_rad=0.01), pose_from_xyz_rpy(0.5, 0.5, 0.0, yaw=-1.0),
                               0.0, 0.0),
    "paper, moving while it scans": (BeamLattice.from_radar(RADAR, tilt_deg=-3.0), pose_from_xyz_rpy(0.0, 0.0, 0.5),
                                     0.8, 0.05),
}


@pytest.mark.parametrize("vector_width", [1, 8])
@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
@pytest.mark.parametrize("near_field", [True, False])
def test_windows_match_the_float64_oracle(runtime, case, near_field, vector_width):
    check_windows(runtime, case, near_field, vector_width, GridSpec((-30.0, -30.0, -6.0), 0.1, (600, 600, 120)))


@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
def test_planar_bricks_windows_match_the_float64_oracle(runtime, case):
    """-D BRICK_Z=1: bricks 8 x 8 x 1 voxels (a brick's z edge an eighth of its x edge), against
    the oracle at the same bricks' centres and radius (``brick_geometry``)."""
    check_windows(runtime, case, True, 8, GridSpec((-30.0, -30.0, -1.0), 0.1, (600, 600, 20), brick_z=1))


def check_windows(runtime, case, near_field, vector_width, spec):
    lattice, pose, trans_margin, rot_margin = case
    model = BeamModel.from_radar(RADAR, near_field=near_field)
    origin = pose[:3, 3] - np.asarray(spec.origin_m)
    frame = HeadFrame(pose[:3, :3] @ lattice.head_rotation(), origin, trans_margin, rot_margin)
    r_lo, r_hi = 1.0, 28.0
    shape = np.asarray(spec.brick_shape)
    blocks = np.stack(np.meshgrid(*[np.arange(0, n, BLOCK) for n in shape], indexing="ij"), -1).reshape(-1, 3)
    got = FusionPlanner(runtime, lattice, model, r_lo, r_hi, vector_width, spec.brick_z).windows(
        blocks, shape, BRICK * spec.voxel_m, frame)
    bricks = FusionPlanner.bricks_of(blocks)
    inside = (bricks < shape).all(axis=1)
    assert (got[~inside] == (0, -1, 0, -1)).all(), "bricks past the grid get empty windows"
    index = FusionPlanner.brick_index(blocks, np.flatnonzero(inside), shape)
    assert np.array_equal(index, (bricks[inside, 2] * shape[1] + bricks[inside, 1]) * shape[0] + bricks[inside, 0])
    got, bricks = got[inside], bricks[inside]
    centres, radius = brick_geometry(bricks, BRICK * spec.voxel_m, spec.brick_z)
    if spec.brick_z == BRICK:
        assert np.allclose(centres, (bricks + 0.5) * BRICK * spec.voxel_m)
        assert radius == pytest.approx(0.5 * math.sqrt(3) * BRICK * spec.voxel_m)
    want = candidate_windows(centres, radius, frame, r_lo, r_hi, lattice, model)
    empty = lambda w: (w[:, 0] > w[:, 1]) | (w[:, 2] > w[:, 3])          # noqa: E731
    both_empty = empty(got) & empty(want)
    same = both_empty | (got == want).all(axis=1)
    reached = ~empty(want)
    assert reached.sum() > 1000, "the case reaches too few bricks to test anything"
    # the device's window holds the oracle's (a brick the oracle lists is listed) ...
    g, w = got[reached].astype(np.int64), want[reached]
    assert not empty(got)[reached].any()
    every_azimuth = g[:, 1] - g[:, 0] + 1 >= lattice.n_az                # a turn (a spinning radar's wrap)
    assert ((every_azimuth | ((g[:, 0] <= w[:, 0]) & (g[:, 1] >= w[:, 1]))) & (g[:, 2] <= w[:, 2])
            & (g[:, 3] >= w[:, 3])).all()
    # ... and is wider by one beam at most, on few bricks (where a bound lies within DEVICE_REACH_M
    # of a beam; within a few metres of the radar, where asin(rs / r) grows fast, by a few)
    assert (~same).mean() <= WINDOWS_DIFFERING_MAX, (~same).mean()
    near = np.linalg.norm(centres - origin, axis=1)[reached] < 4.0
    assert (every_azimuth[:, None] | near[:, None] | (np.abs(g - w) <= 1)).all()
    extra = ~reached & ~empty(got)            # bricks only the device lists (at the ends of the range, or
    assert extra.sum() <= WINDOWS_DIFFERING_MAX * reached.sum()     # of a bound): few


def test_a_device_plan_lists_the_hosts_bricks(runtime):
    """Fusion.plan (device windows) against the numpy windows of the same blocks: every brick the
    float64 windows list is listed, with a window that holds the float64 one (a device plan may
    add bricks and beams, never drop one)."""
    from radarcl.grid import EvidenceGrid
    from radarcl.stages.fusion import Fusion

    lattice, model = BeamLattice.from_radar(RADAR, tilt_deg=-7.0), BeamModel.from_radar(RADAR)
    spec = GridSpec((-8.0, -35.0, -10.0), 0.2, (400, 350, 100))
    f = Fusion(runtime, EvidenceGrid(runtime, spec), lattice, model, 512, 0.125, 8, 511)
    pose = pose_from_xyz_rpy(2.0, 1.0, 0.2, yaw=0.3)
    plan = f.plan(pose)
    head = HeadFrame(pose[:3, :3] @ lattice.head_rotation(), pose[:3, 3] - np.asarray(spec.origin_m), 0.0, 0.0)
    shape = np.asarray(spec.brick_shape)
    bz, by, bx = np.indices(shape[::-1]).reshape(3, -1)
    bricks = np.stack([bx, by, bz], axis=1)
    want = f._windows(bricks, BRICK, head)
    listed = (want[:, 0] <= want[:, 1]) & (want[:, 2] <= want[:, 3])
    got = {tuple(b) for b in plan.bricks[:, :3]}
    host = {tuple(b) for b in bricks[listed]}
    assert len(got) == len(plan.bricks), "each brick listed once"
    assert host <= got and len(got - host) <= WINDOWS_DIFFERING_MAX * len(host), (len(host - got), len(got - host))
    # listed in pool order, each with its own slot and window
    slots = plan.bricks[:, 3]
    assert (np.diff(slots) > 0).all()
    assert np.array_equal(f.grid.table[plan.bricks[:, 2], plan.bricks[:, 1], plan.bricks[:, 0]], slots)
    index = {tuple(b): i for i, b in enumerate(bricks.tolist())}
    mine = want[[index[tuple(b)] for b in plan.bricks[:, :3].tolist()]]
    w, held = plan.windows.astype(np.int64), (mine[:, 0] <= mine[:, 1]) & (mine[:, 2] <= mine[:, 3])
    holds = (w[:, 0] <= mine[:, 0]) & (w[:, 1] >= mine[:, 1]) & (w[:, 2] <= mine[:, 2]) & (w[:, 3] >= mine[:, 3])
    assert holds[held].all()
    assert (np.abs(w - mine)[held] <= 1).all()


def test_planar_bricks_are_listed_by_tiles_of_columns(runtime):
    """A planar grid's plan (a spinning radar's, its pool in several chunks): the same bricks and
    windows as in pool order, each chunk's bricks one run (a launch each), within a chunk each
    tile of COLUMN_TILE x COLUMN_TILE columns one run, and within a tile pool order."""
    from radarcl.grid import EvidenceGrid
    from radarcl.stages.fusion import Fusion

    lattice, model = BeamLattice.spinning(90, az0_rad=0.01), BeamModel.from_radar(RADAR)
    spec = GridSpec((-12.0, -12.0, -1.2), 0.1, (240, 240, 24), brick_z=1)
    grid = EvidenceGrid(runtime, spec, chunk_bricks=4096)
    fusion = Fusion(runtime, grid, lattice, model, 512, 0.05, 4, 400)
    plan_poses = pose_from_xyz_rpy(0.3, -0.2, 0.0, yaw=0.2)[None]
    plan = fusion.plan(plan_poses[0])
    b = plan.bricks.astype(np.int64)
    chunk = b[:, 3] // grid.chunk_bricks
    assert len(np.unique(chunk)) > 2, "the plan must span several chunks"
    tile = (chunk * 1000 + b[:, 1] // COLUMN_TILE) * 1000 + b[:, 0] // COLUMN_TILE
    runs = np.concatenate([[True], np.diff(tile) != 0])
    assert len(np.unique(tile)) == runs.sum(), "each tile's bricks are one run"
    assert (np.diff(chunk) >= 0).all()
    same_tile = ~runs[1:]
    assert (np.diff(b[:, 3])[same_tile] > 0).all(), "pool order within a tile"
    assert (np.diff(b[:, 3]) < 0).any(), "tiles reorder the pool's layers"
    pooled = np.argsort(b[:, 3])
    assert np.array_equal(plan.bricks[pooled][column_tiles(plan.bricks[pooled], grid.chunk_bricks)], plan.bricks)
    # each brick kept its own window: it holds the float64 window of that brick
    want = fusion._windows(plan.bricks[:, :3], BRICK, fusion.head_frame(plan_poses))
    held = (want[:, 0] <= want[:, 1]) & (want[:, 2] <= want[:, 3])
    w = plan.windows.astype(np.int64)
    assert held.sum() > 0.9 * len(held)
    assert ((w[:, 0] <= want[:, 0]) & (w[:, 1] >= want[:, 1]) & (w[:, 2] <= want[:, 2]) & (w[:, 3] >= want[:, 3]))[held].all()


# -- conservativeness at the paper's scale, against a brute-force sweep of the beams ----------------
def beam_frames(lattice, pose):
    """(n_beams, 3, 3) world axes (columns u, v, w) of each beam, from the geometry's definition
    (radarcl/geometry.py's docstring): u = (cos el cos az, cos el sin az, sin el), v = (-sin az,
    cos az, 0), w = u x v, in the head frame; the head tilted by ``tilt`` about y (nose up);
    then the pose. Written out here rather than taken from ``BeamLattice``."""
    az = lattice.az0_rad + lattice.az_step_rad * np.arange(lattice.n_az)
    el = lattice.el0_rad + lattice.el_step_rad * np.arange(lattice.n_el)
    az, el = np.repeat(az, lattice.n_el), np.tile(el, lattice.n_az)           # beam b = i * n_el + k
    u = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
    v = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], -1)
    w = np.cross(u, v)
    c, s = math.cos(lattice.tilt_rad), math.sin(lattice.tilt_rad)
    tilt = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])              # x up towards z for tilt > 0
    return np.asarray(pose)[:3, :3] @ tilt @ np.stack([u, v, w], -1)


# the 28 edges of the convex hull's candidates: every pair of the 8 corners
_PAIRS = np.array([(a, b) for a in range(8) for b in range(a + 1, 8)])


def swept_bricks(spec, lattice, model, pose, spacing, first_bin, last_bin, margin, chunk=1 << 21, voxels=False):
    """For every beam, the bricks (flat indices (bz * nby + by) * nbx + bx; with ``voxels``, the
    voxels' own flat indices (iz * ny + iy) * nx + ix) holding a voxel centre the beam may
    reach: d > 0, rho2 <= 1 + margin, r / spacing within margin of
    [first_bin - 0.5, last_bin + 0.5], all in float64 (the fusion kernel decides in float32
    within FUSION_DECISION_MARGIN of the same). Brute force over the voxels of each beam's
    hull, plane by plane, chunked; it uses no planner.

    The beam {0 < d <= D, (y / W_az(d))^2 + (z / W_el(d))^2 <= 1} with W(d) = max(a, d tan(theta
    / 2)) convex in d lies within |y| <= W_az and |z| <= W_el, and these within their chords
    between d = 0 and D: the convex hull of two rectangles, 8 corners. Its section by a voxel
    plane is a convex polygon whose vertices lie on its edges, so the corners' 28 joining
    segments cut by the plane bound it; every voxel centre in that bound is tested."""
    frames = beam_frames(lattice, pose)
    origin = np.asarray(pose, np.float64)[:3, 3]
    grid0, vox, shape = np.asarray(spec.origin_m, np.float64), spec.voxel_m, np.array(spec.shape)
    nbx, nby, _ = spec.brick_shape
    inflate = math.sqrt(1 + margin) * (1 + 1e-9)
    t_az, t_el = math.tan(model.beamwidth_az_rad / 2), math.tan(model.beamwidth_el_rad / 2)
    a_az, a_el = (model.half_aperture_az_m, model.half_aperture_el_m) if model.near_field else (0.0, 0.0)
    r_lo, r_hi = (first_bin - 0.5 - margin) * spacing, (last_bin + 0.5 + margin) * spacing
    reach = r_hi                                          # d <= r <= r_hi
    out, counted = [], 0
    for b in range(lattice.n_beams):
        u, v, w = frames[b].T
        corners = np.array([origin + d * u + sy * half_y * v + sz * half_z * w
                            for d, half_y, half_z in ((0.0, a_az, a_el),
                                                      (reach, max(a_az, reach * t_az), max(a_el, reach * t_el)))
                            for sy in (-inflate, inflate) for sz in (-inflate, inflate)])
        q = (corners - grid0) / vox - 0.5                 # voxel index coordinates of the corners
        axis = int(np.argmax(np.abs(u)))                  # planes across the beam's main direction
        o1, o2 = [i for i in range(3) if i != axis]
        planes = np.arange(max(0, math.floor(q[:, axis].min())), min(shape[axis] - 1, math.ceil(q[:, axis].max())) + 1)
        if not len(planes):
            out.append(np.zeros(0, np.int64))
            continue
        p, e = q[_PAIRS[:, 0]], q[_PAIRS[:, 1]] - q[_PAIRS[:, 0]]              # (28, 3) segments
        with np.errstate(divide="ignore", invalid="ignore"):             # segments in a plane: t = nan
            t = (planes[:, None] - p[None, :, axis]) / e[None, :, axis]          # (n_planes, 28)
            hit = (t >= 0) & (t <= 1)
            c1 = np.where(hit, p[None, :, o1] + t * e[None, :, o1], np.nan)
            c2 = np.where(hit, p[None, :, o2] + t * e[None, :, o2], np.nan)
        keep = hit.any(axis=1)
        planes, c1, c2 = planes[keep], c1[keep], c2[keep]
        lo1 = np.clip(np.floor(np.nanmin(c1, axis=1)) - 1, 0, shape[o1] - 1).astype(np.int64)
        hi1 = np.clip(np.ceil(np.nanmax(c1, axis=1)) + 1, 0, shape[o1] - 1).astype(np.int64)
        lo2 = np.clip(np.floor(np.nanmin(c2, axis=1)) - 1, 0, shape[o2] - 1).astype(np.int64)
        hi2 = np.clip(np.ceil(np.nanmax(c2, axis=1)) + 1, 0, shape[o2] - 1).astype(np.int64)
        n1, n2 = hi1 - lo1 + 1, hi2 - lo2 + 1
        per_plane = n1 * n2
        starts = np.concatenate([[0], np.cumsum(per_plane)])
        bricks = []
        for c0 in range(0, int(starts[-1]), chunk):      # the candidates, a chunk at a time
            flat = np.arange(c0, min(c0 + chunk, int(starts[-1])))
            plane = np.searchsorted(starts, flat, side="right") - 1
            local = flat - starts[plane]
            idx = np.empty((len(flat), 3), np.int64)
            idx[:, axis] = planes[plane]
            idx[:, o1] = lo1[plane] + local // n2[plane]
            idx[:, o2] = lo2[plane] + local % n2[plane]
            x = grid0 + (idx + 0.5) * vox - origin
            d, y, z = x @ u, x @ v, x @ w
            r = np.sqrt(np.einsum("ij,ij->i", x, x))
            with np.errstate(divide="ignore", invalid="ignore"):
                rho2 = (y / np.maximum(a_az, d * t_az)) ** 2 + (z / np.maximum(a_el, d * t_el)) ** 2
            inside = (d > 0) & (rho2 <= 1 + margin) & (r >= r_lo) & (r <= r_hi)
            if voxels:
                hits = idx[inside]
                bricks.append((hits[:, 2] * shape[1] + hits[:, 1]) * shape[0] + hits[:, 0])
            else:
                hits = idx[inside] // BRICK
                bricks.append((hits[:, 2] * nby + hits[:, 1]) * nbx + hits[:, 0])
            counted += int(inside.sum())
        out.append(np.unique(np.concatenate(bricks)) if bricks else np.zeros(0, np.int64))
    return out, counted


SWEEP_MODELS = {"paper, cylindrical-conical": BeamModel.from_radar(RADAR),
                "paper, cone": BeamModel.from_radar(RADAR, near_field=False),
                "10 x 6 deg, cylinder to 4.6 m": BeamModel(math.radians(10.0), math.radians(6.0), 0.4, 0.25)}


@pytest.mark.parametrize("model", SWEEP_MODELS.values(), ids=SWEEP_MODELS.keys())
def test_the_sweep_finds_what_the_float64_oracle_fuses(model):
    """The sweep below is itself checked: on a small grid (12 x 2 beams spread over 55 x 4 deg,
    to 22 m: the near-field cylinder and the cone beyond it) it finds every voxel
    ``oracle.fusion`` (every beam against every voxel centre) updates, and none that no float64
    decision could give."""
    from tolerances import FUSION_DECISION_MARGIN

    from radarcl import oracle

    lattice = BeamLattice(12, 2, math.radians(-27.5), math.radians(5.0), math.radians(-2.0), math.radians(4.0),
                          math.radians(-5.0))
    spec = GridSpec((-1.0, -12.0, -4.0), 0.25, (100, 96, 32))
    pose = pose_from_xyz_rpy(0.013, -0.021, 0.4, yaw=0.003)
    assert np.allclose(beam_frames(lattice, pose), pose[:3, :3] @ lattice.beam_rotations(), atol=1e-12)
    ev = np.ones((lattice.n_beams, 96), np.int32)
    _, updates, ambiguous = oracle.fusion(spec, ev, lattice, model, pose, 0.25, 4, 88, margin=FUSION_DECISION_MARGIN)
    found, _ = swept_bricks(spec, lattice, model, pose, 0.25, 4, 88, FUSION_DECISION_MARGIN, voxels=True)
    swept = np.zeros(updates.size, bool)
    swept[np.concatenate(found)] = True
    swept = swept.reshape(updates.shape)
    assert (updates > 0).sum() > 2000 and swept[updates > 0].all()
    assert not (swept & (updates == 0) & ~ambiguous).any()      # nothing a float64 beam cannot reach


@pytest.mark.parametrize("near_field", [True, False], ids=["cylindrical-conical", "cone"])
def test_the_plans_lose_no_voxel_at_the_papers_scale(runtime, near_field):
    """One frame of the paper's radar (64 x 4 beams to 64 m, n_fft 1024) on the paper's grid (80 x
    70 x 20 m at 0.1 m: 112 M voxels, 220,000 bricks): every voxel a beam may reach, found by the
    brute-force float64 sweep above, lies in a brick of the host's float64 plan
    (``candidate_windows`` of every brick) and of the device's plan (``Fusion.plan``) whose window
    holds that beam; and the device plan lists every brick the float64 plan lists (it may list
    more: its float32 bounds carry the slack, never less)."""
    from tolerances import FUSION_DECISION_MARGIN

    from radarcl.config.stage_config import InterpretConfig
    from radarcl.grid import EvidenceGrid
    from radarcl.stages.fusion import Fusion

    lattice, model = BeamLattice.from_radar(RADAR, tilt_deg=-7.0), BeamModel.from_radar(RADAR, near_field=near_field)
    spec = GridSpec((-8.0, -35.0, -10.0), 0.1, (800, 700, 200))
    spacing = RADAR.bin_spacing_m(1024)
    first, last = InterpretConfig().bin_interval(spacing, 512)
    pose = pose_from_xyz_rpy(0.013, -0.021, 1.5, yaw=0.003)             # off the voxel lattice's symmetries
    fusion = Fusion(runtime, EvidenceGrid(runtime, spec), lattice, model, 512, spacing, first, last)
    plan = fusion.plan(pose)
    shape = np.asarray(spec.brick_shape)
    nbx, nby, _ = shape
    # the host's float64 plan: every brick's window
    bz, by, bx = np.indices(shape[::-1]).reshape(3, -1)
    head = HeadFrame(pose[:3, :3] @ lattice.head_rotation(), pose[:3, 3] - np.asarray(spec.origin_m), 0.0, 0.0)
    host = fusion._windows(np.stack([bx, by, bz], axis=1), BRICK, head)            # flat brick order
    host_listed = np.flatnonzero((host[:, 0] <= host[:, 1]) & (host[:, 2] <= host[:, 3]))
    # the device's plan, as a flat table of windows
    device = np.tile(np.array([0, -1, 0, -1], np.int64), (len(host), 1))
    listed = (plan.bricks[:, 2].astype(np.int64) * nby + plan.bricks[:, 1]) * nbx + plan.bricks[:, 0]
    device[listed] = plan.windows
    assert len(np.unique(listed)) == len(listed)
    missing = np.setdiff1d(host_listed, listed)
    assert len(missing) == 0, f"the device plan drops {len(missing)} of the float64 plan's {len(host_listed)} bricks"

    found, reached = swept_bricks(spec, lattice, model, pose, spacing, first, last, FUSION_DECISION_MARGIN)
    assert reached > 5_000_000, "the frame reaches too few voxels to test anything"
    lost = {"host": 0, "device": 0}
    for b, bricks in enumerate(found):
        i, k = divmod(b, lattice.n_el)
        for name, w in (("host", host[bricks]), ("device", device[bricks])):
            holds = (w[:, 0] <= i) & (i <= w[:, 1]) & (w[:, 2] <= k) & (k <= w[:, 3])
            lost[name] += int((~holds).sum())
    assert lost == {"host": 0, "device": 0}, f"(brick, beam) pairs whose window misses a beam that reaches it: {lost}"
