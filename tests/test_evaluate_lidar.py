"""evaluate-lidar on a synthetic recording whose lidar truth is known exactly: a street of solids
(radarcl.scene.spinning.street), a spinning radar's polar scans and a 16-ring lidar cast against
it, written as RADIATE writes them (range-row PNGs with Navtech_Polar.txt, headerless lidar csv in
x right / y forward, annotations in Cartesian-image pixels), with a TUM trajectory. The truth built
from the lidar is checked against the solids; the radar map beats the controls that use no radar
data; the parked car's box is occupied."""

import json
import math

import numpy as np
import pytest
from PIL import Image

from radarcl.config import mapconfig
from radarcl.evaluation import lidar as L
from radarcl.geometry import pose_from_xyz_rpy
from radarcl.io import radiate
from radarcl.io.trajectory import Trajectory
from radarcl.jobs import evaluate_lidar as job
from radarcl.scene import spinning

T0 = 1_700_000_000_000_000_000
SPEED, HEIGHT, FOG_M = 8.0, 1.8, 15.0
BIN_M, N_BINS, N_AZ, PERIOD = 0.173611, 576, 400, 250_000_000
RINGS_DEG = np.linspace(-20.0, 10.0, 16)


def _ns_text(t):
    return f"{t // 10 ** 9}.{t % 10 ** 9:09d}"


def _write_recording(root, n_scans=6):
    """A RADIATE-layout recording of the street; returns (scene, trajectory, lidar poses)."""
    scene = spinning.street(HEIGHT)
    t = T0 + np.arange(0, 61, dtype=np.int64) * 50_000_000
    track = Trajectory(t, np.stack([pose_from_xyz_rpy(SPEED * (k - t[0]) / 1e9, 0.0, 0.0) for k in t]), "street")
    (root / "street.tum").write_text(track.tum_text())
    raised = np.diag([1.0, 1.0, 1.0, 1.0])
    raised[2, 3] = HEIGHT
    rng = np.random.default_rng(7)
    (root / "Navtech_Polar").mkdir(parents=True)
    stamps = []
    for k in range(n_scans):
        stamp = T0 + 500_000_000 + k * PERIOD                 # RADIATE: the time of arrival, 0.25 s after the
        stamps.append(f"Frame: {k + 1:06d} Time: {_ns_text(stamp)}")     # middle azimuth (the profile's reading)
        column = np.arange(N_AZ)
        times = stamp - 250_000_000 + ((column - (N_AZ // 2 - 1)) * PERIOD) // N_AZ
        angle = np.radians(-(column + 0.5) * 0.9)             # column c at (c + 0.5) x 0.9 deg clockwise
        turn = np.stack([pose_from_xyz_rpy(yaw=a) for a in angle])
        poses = raised @ track.at(times) @ turn
        levels = spinning.polar_scan(scene, poses, N_BINS, BIN_M, rng)      # (azimuth, bin)
        Image.fromarray(np.ascontiguousarray(levels.T)).save(root / "Navtech_Polar" / f"{k + 1:06d}.png")
    (root / "Navtech_Polar.txt").write_text("\n".join(stamps) + "\n")
    (root / "velo_lidar").mkdir()
    lines, lidar = [], []
    for j, lt in enumerate(range(T0 + 300_000_000, T0 + 2_100_000_000, 100_000_000)):
        pose = raised @ track.at([lt])[0] @ radiate.lidar_mount()       # where RADIATE's lidar sits
        p = spinning.lidar_points(scene, pose, RINGS_DEG, 720, FOG_M)
        rows = np.column_stack([-p[:, 1], p[:, 0], p[:, 2], np.ones(len(p)), np.zeros(len(p))])   # x right, y fwd
        np.savetxt(root / "velo_lidar" / f"{j + 1:06d}.csv", rows, delimiter=",", fmt="%.5f")
        lines.append(f"Frame: {j + 1:06d} Time: {_ns_text(lt)}")
        lidar.append(pose)
    (root / "velo_lidar.txt").write_text("\n".join(lines) + "\n")
    boxes = []
    for k in range(n_scans):                                   # the parked car in each scan's Cartesian image,
        stamp = T0 + 500_000_000 + k * PERIOD                  # where the azimuth that looks at it saw it
        x_f = float(track.at([stamp - PERIOD // 2])[0][0, 3])
        for _ in range(3):
            column = int(math.degrees(-math.atan2(-3.23, 22.28 - x_f)) / 0.9 - 0.5) % N_AZ
            x_f = float(track.at([stamp - 250_000_000 + ((column - (N_AZ // 2 - 1)) * PERIOD) // N_AZ])[0][0, 3])
        u0, u1 = 576 + 2.33 / BIN_M, 576 + 4.13 / BIN_M       # x right = -y
        v0, v1 = 576 - (24.53 - x_f) / BIN_M, 576 - (20.03 - x_f) / BIN_M
        boxes.append({"position": [u0, v0, u1 - u0, v1 - v0], "rotation": 0.0})
    (root / "annotations").mkdir()
    (root / "annotations" / "annotations.json").write_text(json.dumps([{"id": 1, "class_name": "car",
                                                                         "bboxes": boxes}]))
    return scene, track, lidar


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """(root, scene, lidar poses) of the synthetic recording (six scans)."""
    root = tmp_path_factory.mktemp("street")
    scene, _, lidar = _write_recording(root)
    return root, scene, lidar


QUIET = "detection statistics, 50 dB"

@pytest.fixture(scope="module")
def evaluated(runtime, recording):
    root, scene, lidar = recording
    models = job.resolve_models("radiate-cts350x", ["paper", "calibrated", "detstats"])
    models.append((QUIET, mapconfig.resolve("radiate-cts350x", program={"interpret.model": "detstats"},
                                            flags={"sensor_model.snr_1m2_at_10m_db": 50.0})))
    result, arrays = job.run(runtime, models, root, voxel_m=0.5, poses=root / "street.tum", report=lambda *_: None)
    return scene, lidar, result, arrays


def _band_heights():
    return L.CLEARANCE_M, L.TOP_M


def test_the_lidar_truth_is_the_street(evaluated):
    """Every occupied cell touches a solid between CLEARANCE_M and TOP_M above the road; no free
    cell lies inside a solid's footprint; nothing is known beyond the fog's reach; the wall's
    face is occupied wherever the lidar came within 10 m of it."""
    scene, lidar, _, arrays = evaluated
    truth, spec = arrays["truth"], arrays["spec"]
    lo_h, hi_h = _band_heights()
    v = spec.voxel_m
    # the evaluation's world is the first scan's frame: the scene's, moved back along x
    shift = arrays["trajectory"].at([T0])[0][:3, 3]
    assert np.allclose(arrays["trajectory"].at([T0])[0][:3, :3], np.eye(3)) and shift[1] == 0
    lidar = [p + np.pad(shift[:, None], ((0, 1), (3, 0))) for p in lidar]
    iy, ix = np.nonzero(truth.known)
    lo = np.column_stack([spec.origin_m[0] + ix * v, spec.origin_m[1] + iy * v, np.full(len(ix), lo_h)])
    hi = lo + [v, v, hi_h - lo_h]
    touches, inside = np.zeros(len(ix), bool), np.zeros(len(ix), bool)
    for obj in scene.objects[1:]:                              # every solid but the road
        b_lo, b_hi = (b + shift * [1, 1, 0] for b in obj.shape.bounds())
        touches |= ((lo[:, :2] <= b_hi[:2] + 1e-9) & (hi[:, :2] >= b_lo[:2] - 1e-9)).all(1) & (b_hi[2] >= lo_h)
        inside |= ((lo[:, :2] >= b_lo[:2]) & (hi[:, :2] <= b_hi[:2])).all(1)
    occ = truth.occupied[iy, ix]
    assert occ.sum() > 100 and touches[occ].all()
    assert not (truth.free[iy, ix] & inside).any()
    centres = np.column_stack([lo[:, 0] + v / 2, lo[:, 1] + v / 2])
    d = np.min([np.hypot(*(centres - p[:2, 3]).T) for p in lidar], axis=0)
    assert d.max() <= FOG_M + v * math.sqrt(2)
    assert max(arrays["truth"].reach_m) <= FOG_M
    # the wall's face cells (y 6.03) within 10 m of a lidar position are occupied
    xs = spec.origin_m[0] + (np.arange(spec.shape[0]) + 0.5) * v
    face_y = int(math.floor((6.03 + shift[1] - spec.origin_m[1]) / v))
    near = np.array([min(math.hypot(x - p[0, 3], 6.03 - p[1, 3]) for p in lidar) < 10.0 for x in xs])
    assert near.sum() > 20 and truth.occupied[face_y, near].mean() > 0.9


def test_the_radar_map_beats_the_controls(evaluated):
    """In every band the lidar covers, the best radar map ranks occupied above free cells at
    least 0.10 better than either control that uses no radar data."""
    _, _, result, _ = evaluated
    assert len(result["bands"]) >= 2
    for row in result["bands"]:
        best = max(row["iou"], key=lambda m: row["auc"][m])
        controls = max(row["auc"][job.COUNT], row["auc"][job.RANGE])
        assert row["auc"][best] >= controls + 0.10, row


def test_the_parked_car_is_occupied(evaluated):
    _, _, result, _ = evaluated
    boxes = result["boxes"]
    assert len(boxes) == 6 and all(b["cells"] > 20 for b in boxes)
    assert all(b["maps"]["paper constants"][0] for b in boxes)
    chance = [b["maps"]["paper constants"][2] for b in boxes]
    assert max(chance) < 1.0                                  # a map occupied everywhere would pass every box


def test_the_detection_statistics_map_is_scored_as_it_reads(evaluated):
    """`--model detstats` fuses with the knowledge channel and is scored through its reading: the
    cells its radar has not observed (less than half a look of knowledge) read the prior (the base
    rate), exactly, whatever evidence reached them, not the raw sums' 0, and it is ranked in every
    band beside the others."""
    from radarcl import sensor_model

    _, _, result, arrays = evaluated
    m = arrays["maps"][QUIET]                         # a less sensitive radar leaves cells it cannot see
    unknown = ~arrays["known"][QUIET]
    prior = sensor_model.prior_for_voxel(sensor_model.DEFAULTS["prior_nats"], 0.5)   # the base rate at the cells' 0.5 m
    assert unknown.mean() > 0.01 and (m > 1.0).any()
    assert np.all(np.abs(m[unknown] - prior) <= 1.0 / 1024)
    assert (m == 0).mean() < 1e-3                     # 0 only where evidence and the prior happen to cancel
    assert all(np.isfinite(row["auc"][name]) for row in result["bands"] for name in ("detection statistics", QUIET))


def test_a_box_ranks_against_its_turned_copies():
    """box_scores' rank: a box that alone stands out ranks 1; in a map occupied everywhere it
    passes (occupied, chance 1) but ranks 0.5, as a box anywhere at its range would."""
    from radarcl.gridspec import GridSpec

    spec = GridSpec((-20.0, -20.0, -0.1), 0.2, (200, 200, 1))
    corners = np.array([[9.0, -1.0], [11.0, -1.0], [11.0, 1.0], [9.0, 1.0]])
    box = [("car", "car", 0, corners, np.zeros(2))]
    alone = np.full((200, 200), -2.0)
    alone[95:105, 145:155] = 5.0                       # y -1..1, x 9..11
    everywhere = np.full((200, 200), 5.0)
    (row,) = L.box_scores(spec, box, {"alone": alone, "everywhere": everywhere})
    occupied, peak, chance, rank = row["maps"]["alone"]
    # the copies turned by 5 and 10 deg still overlap the box (2 m wide at 10 m): they tie
    assert occupied and peak == 5.0 and chance < 0.1 and rank > 0.95
    occupied, _, chance, rank = row["maps"]["everywhere"]
    assert occupied and chance == 1.0 and rank == 0.5
    # capped evidence: one cell at the cap in the box and in every copy (a tie by the peak), the
    # rest of the box occupied where the copies are free: the mean tells the box apart
    capped = np.full((200, 200), -2.0)
    capped[::10, ::10] = 14.0                         # a speckle at the cap, one cell in every box
    capped[96:104, 146:154] = np.maximum(capped[96:104, 146:154], 5.0)
    (row,) = L.box_scores(spec, box, {"capped": capped})
    occupied, peak, _, rank = row["maps"]["capped"]
    assert peak == 14.0 and rank > 0.9


def _p(nats):
    return 1.0 / (1.0 + math.exp(-nats))


def test_costmap_scores_by_hand():
    """Classes at the export thresholds (strictly above 1 nat occupied, strictly below -1 free);
    without a knowledge channel a cell of no evidence (0) is unknown, with one every cell the map
    does not know is unknown whatever it reads, and is left out of the ECE."""
    nats = np.array([[2.0, 1.0, 0.5, -1.5, 0.0, 3.0, -2.0, -0.5]])
    pos = np.array([[1, 1, 1, 1, 0, 0, 0, 0]], bool)             # the lidar's occupied cells
    neg = ~pos
    s = L.costmap_scores(nats, pos, neg)
    # occupied: 2.0 (pos), 3.0 (neg); free: -1.5 (pos), -2.0 (neg); 1.0 sits on the threshold (undecided)
    assert s["recall"] == 1 / 4 and s["miss"] == 1 / 4 and s["phantom"] == 1 / 4
    assert s["unknown"] == 4 / 8                                  # 1.0, 0.5 | 0.0 (no evidence), -0.5
    # ECE over the seven cells with evidence, ten bins: -1.5 (y 1) and -2.0 (y 0) share (0.1, 0.2]
    mixed = 2 * abs(0.5 - (_p(-1.5) + _p(-2.0)) / 2)
    ece = ((1 - _p(2.0)) + (1 - _p(1.0)) + (1 - _p(0.5)) + mixed + _p(3.0) + _p(-0.5)) / 7
    assert s["ece_cells"] == 7 and s["ece"] == pytest.approx(ece, abs=1e-12)

    known = np.array([[1, 1, 0, 1, 1, 0, 0, 1]], bool)
    s = L.costmap_scores(nats, pos, neg, known)
    # 3.0 and -2.0 are not known: no phantom, and -2.0 is not free; 0.0 is known and undecided
    assert s["recall"] == 1 / 4 and s["miss"] == 1 / 4 and s["phantom"] == 0.0
    assert s["unknown"] == 6 / 8                                  # 1.0, 0.5 | 0.0, 3.0, -2.0, -0.5
    ece = ((1 - _p(2.0)) + (1 - _p(1.0)) + (1 - _p(-1.5)) + _p(0.0) + _p(-0.5)) / 5    # one cell per bin
    assert s["ece_cells"] == 5 and s["ece"] == pytest.approx(ece, abs=1e-12)
    empty = L.costmap_scores(nats, pos, np.zeros_like(neg))
    assert math.isnan(empty["phantom"]) and empty["recall"] == 1 / 4


def test_the_raw_threshold_at_equal_recall_by_hand():
    """The raw map calls the same share of the lidar's occupied cells occupied as the map does:
    every cell above the threshold, at it the share of the tied ones that makes the recall
    exact; its phantom rate counts the free cells tied at the threshold by the same share."""
    score = np.array([5.0, 4.0, 4.0, 2.0, 1.0, 4.0, 3.0, 0.0, 0.0])
    pos = np.array([1, 1, 1, 1, 1, 0, 0, 0, 0], bool)
    neg = ~pos
    assert L.phantom_at_recall(score, pos, neg, 1 / 5) == (5.0, 0.0)
    assert L.phantom_at_recall(score, pos, neg, 2 / 5) == (4.0, 0.5 / 4)     # half the two 4s: half the free 4
    assert L.phantom_at_recall(score, pos, neg, 3 / 5) == (4.0, 1 / 4)
    assert L.phantom_at_recall(score, pos, neg, 4 / 5) == (2.0, 2 / 4)
    assert L.phantom_at_recall(score, pos, neg, 1.0) == (1.0, 2 / 4)
    assert L.phantom_at_recall(score, pos, neg, 0.0) == (math.inf, 0.0)
    assert all(math.isnan(v) for v in L.phantom_at_recall(score, pos, np.zeros_like(neg), 0.5))


def test_band_scores_carry_the_costmap_figures():
    """band_scores gives each map its costmap_scores over the band's cells and the baseline's
    phantom rate at that map's recall."""
    from radarcl.gridspec import GridSpec

    rng = np.random.default_rng(3)
    n = 60
    hits = np.zeros((1, n), np.int32)
    hits[0, :25] = 1
    truth = L.LidarTruth(GridSpec((0.0, 0.0, -0.1), 0.2, (n, 1, 1)), hits, (1 - hits) * 2, [10.0])
    distance = np.full((1, n), 3.0)
    distance[0, -5:] = 7.0                                          # five free cells in another band
    nats = np.round(rng.normal(0, 2, (1, n)), 1)
    raw = np.round(rng.normal(0, 1, (1, n)), 1)
    known = rng.random((1, n)) < 0.8
    (row,) = L.band_scores(truth, distance, {"m": nats}, {"raw": raw}, bands=(2.0, 5.0, 10.0),
                           known={"m": known}, equal_recall="raw")
    band = distance < 5.0
    pos, neg = truth.occupied & band, truth.free & band
    want = L.costmap_scores(nats, pos, neg, known)
    t, phantom = L.phantom_at_recall(raw, pos, neg, want["recall"])
    assert row["costmap"]["m"] == dict(want, equal_recall_threshold=t, equal_recall_phantom=phantom)
    assert (row["occupied"], row["free"]) == (25, 30)


def test_the_job_reads_each_map_as_its_costmap_does(evaluated):
    """The job's costmap figures are those of each map as it reads: the detection-statistics map
    with its knowledge (cells it does not know unknown), the others by their evidence alone; the
    raw intensity at each map's recall."""
    _, _, result, arrays = evaluated
    truth, maps, known = arrays["truth"], arrays["maps"], arrays["known"]
    assert set(known) == {"detection statistics", QUIET} and all(k.dtype == bool for k in known.values())
    assert not known[QUIET].all()
    distance = L.range_from_path(arrays["spec"], arrays["per_beam"][..., :3, 3].reshape(-1, 3))
    row = result["bands"][0]
    band = (distance >= row["band"][0]) & (distance < row["band"][1])
    pos, neg = truth.occupied & band, truth.free & band
    for name in maps:
        want = L.costmap_scores(maps[name], pos, neg, known.get(name))
        want["equal_recall_threshold"], want["equal_recall_phantom"] = L.phantom_at_recall(arrays["raw"], pos, neg,
                                                                                           want["recall"])
        assert row["costmap"][name] == want
    lines = job.table(result)
    assert lines[0].startswith("scans 0:6 of 6 (all: 000001..000006), 0.00-1.50 s after the recording's first")
    assert "detection statistics:" in lines
    assert "| band | recall | phantom | raw @recall | miss | unknown | ECE (cells) |" in lines


def test_select_scans_is_a_checked_slice():
    assert job.select_scans(None, 6) == (0, 6)
    assert job.select_scans((None, -2), 6) == (0, 4) and job.select_scans((-3, None), 6) == (3, 6)
    assert job.select_scans((2, 6), 6) == (2, 6)
    from radarcl.errors import ConfigError

    for bad, words in (((4, 4), "selects no scan"), ((5, 2), "selects no scan"), ((3, 9), "outside"),
                       ((-7, None), "outside")):
        with pytest.raises(ConfigError, match=words):
            job.select_scans(bad, 6)


def test_scans_scores_a_part_of_the_recording_and_says_which(recording, tmp_path, capsys):
    """`evaluate-lidar --scans 2:` fuses scans 2-5 only, against the lidar frames taken while they
    were (0.7-1.6 s: the scans' azimuths run from 0.626 to 1.625 s), names them in its first
    line and in --json; a range outside the recording or holding no scan is refused in a
    sentence, before anything is fused."""
    from radarcl.cli import main

    root = recording[0]
    common = [str(root), "--poses", str(root / "street.tum"), "--model", "paper", "--voxel", "0.5", "--no-progress"]
    assert main(["evaluate-lidar", *common, "--scans", "2:", "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert ("scans 2:6 of 6 (4 scans: 000003..000006), 0.50-1.50 s after the recording's first (UNIX "
            "1700000000.626-1700000001.625 s); 10 lidar frames taken meanwhile") in out
    r = json.loads((tmp_path / "r.json").read_text())
    assert r["scans"] == 4 and r["lidar_frames"] == 10
    assert {k: r["scan_range"][k] for k in ("start", "stop", "total", "first", "last", "lidar_within")} == \
        dict(start=2, stop=6, total=6, first="000003", last="000006", lidar_within=True)
    figures = {"phantom", "miss", "unknown", "recall", "ece", "ece_cells", "equal_recall_threshold",
               "equal_recall_phantom"}
    assert r["bands"] and all(figures == set(row["costmap"]["paper constants"]) for row in r["bands"])
    assert r["costmap_thresholds"] == dict(occupied_nats=1.0, free_nats=-1.0, known_looks=0.5)
    for bad, words in (("4:4", "selects no scan"), ("3:9", "outside the recording's 6 scans"),
                       ("-7:", "outside the recording's 6 scans")):
        assert main(["evaluate-lidar", *common, f"--scans={bad}"]) == 2
        err = capsys.readouterr().err
        assert f"--scans {bad}" in err and words in err, err
    with pytest.raises(SystemExit):
        main(["evaluate-lidar", *common, "--scans", "2-4"])
    assert "expected START:STOP" in capsys.readouterr().err


def test_bin_cells_are_the_cells_a_beam_walks(evaluated):
    """``bin_cells`` (the cell under each bin, for fit-sensor --lidar) puts a scan's bins in the
    cells ``radar_visible`` walks along the same beams, turned by the same poses: over a truth with
    nothing occupied, the two mark the same cells."""
    _, _, _, arrays = evaluated
    spec, per_beam = arrays["spec"], arrays["per_beam"][:1]
    shape = arrays["truth"].occupied.shape
    empty = L.LidarTruth(spec, np.zeros(shape, np.int32), np.ones(shape, np.int32), [])
    r = np.arange(2.0, 30.0, spec.voxel_m / L.STEPS_PER_CELL)
    iy, ix, inside = L.bin_cells(spec, per_beam[0], r)
    mine = np.zeros(shape, bool)
    mine[iy[inside], ix[inside]] = True
    assert mine.sum() > 1000 and np.array_equal(mine, L.radar_visible(empty, per_beam, 2.0, 30.0))
