"""The map out to Foxglove (``maps.foxglove_out``): a protocol client on loopback (tests/
foxglove_client.py) subscribes while `radarcl fuse` and `radarcl live` run and decodes the map,
which must equal the map store's; the MCAP recording read back with the mcap library holds the
same; a client that stalls or leaves holds nothing up; the server listens on 127.0.0.1 only."""

import os
import socket
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import foxglove_client
from radarcl.bench.foxglove import stalled_client
from radarcl.cli import main
from radarcl.io.trajectory import rotations
from radarcl.maps.disk import read_poses
from radarcl.maps.map import Map

pytest.importorskip("foxglove")
pytest.importorskip("websockets")
pytest.importorskip("google.protobuf")

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "navtech_oxford"
SCANS = DATA / "radar"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def fuse(out, *more):
    return main(["fuse", str(SCANS), "--sensor", "navtech-cts350x", "--out", str(out), "--no-report", "--no-progress",
                 *map(str, more)])


def last(got, topic):
    return [m for t, _, _, m in got if t == topic][-1]


def check_against_store(msgs, out):
    """The decoded channels' last messages against the map store ``out``: the grid cell for cell,
    the occupied voxels and their log-odds, the trajectory's and TF's last pose."""
    m = Map.open(out)
    grid = msgs["/map"]
    cells = np.frombuffer(grid.data, np.int8).reshape(-1, grid.column_count)
    expected = m.projection()
    assert np.array_equal(cells, expected)
    assert grid.cell_size.x == m.spec.voxel_m and grid.pose.position.x == m.spec.origin_m[0]
    counts = {v: int((cells == v).sum()) for v in (100, 0, -1)}
    assert counts == {v: int((expected == v).sum()) for v in (100, 0, -1)} and counts[100] > 0 and counts[0] > 0
    cloud = msgs["/map/voxels"]
    points = np.frombuffer(cloud.data, [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("log_odds", "<f4")])
    centres, nats = m.occupied()
    assert len(points) == len(centres) > 0 and cloud.point_stride == 16
    assert np.array_equal(points["log_odds"], nats.astype(np.float32))
    assert np.array_equal(points["x"], centres[:, 0].astype(np.float32))
    poses = read_poses(out)
    p = msgs["/trajectory"].poses
    assert len(p) == len(poses)
    tf = msgs["/tf"].transforms[-1]
    assert tf.parent_frame_id == "map" and tf.child_frame_id == "radar"
    q = tf.rotation
    got = np.eye(4)
    got[:3, :3] = rotations(np.array([[q.w, q.x, q.y, q.z]]))[0]
    got[:3, 3] = tf.translation.x, tf.translation.y, tf.translation.z
    np.testing.assert_allclose(got, poses[-1], rtol=0, atol=1e-9)   # float64 -> quaternion -> float64


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    out = tmp_path_factory.mktemp("plain") / "plain.npz"
    assert fuse(out) == 0
    return out


def test_a_client_decodes_the_fused_map_as_the_store_holds_it(tmp_path, plain):
    port = free_port()
    got = {}
    client = threading.Thread(target=lambda: got.setdefault("m", foxglove_client.listen(f"ws://127.0.0.1:{port}", 120)))
    client.start()
    out, rec = tmp_path / "m.npz", tmp_path / "m.mcap"
    assert fuse(out, "--foxglove", port, "--mcap", rec) == 0
    client.join(150)
    assert not client.is_alive()
    msgs = got["m"]
    topics = {t for t, _, _, _ in msgs}
    assert topics == {"/map", "/map/voxels", "/scan", "/trajectory", "/tf"}
    check_against_store({t: last(msgs, t) for t in topics}, out)
    # the map is the same with or without Foxglove, bit for bit
    a, b = np.load(out), np.load(plain)
    assert all(np.array_equal(a[k], b[k]) for k in ("keys", "data", "knowledge", "looks", "poses"))
    # stamped with the recording's time: the last scan's middle azimuth, not the time it ran
    first_scan_us = sorted(int(p.stem) for p in SCANS.glob("*.png"))[-1]
    assert abs(msgs[-1][1] - first_scan_us * 1000) < 10 ** 9 and msgs[-1][1] < 2 * 10 ** 18
    # the MCAP holds the same channels, read back with the mcap library and decoded from its schemas
    from mcap.reader import make_reader

    with open(rec, "rb") as f:
        reader = make_reader(f)
        decoded = {}
        for schema, channel, message in reader.iter_messages():
            cls = foxglove_client.message_classes(schema.name, schema.data)
            decoded[channel.topic] = cls.FromString(message.data)
            assert message.log_time < 2 * 10 ** 18
    assert set(decoded) == topics
    check_against_store(decoded, out)


def test_a_stalled_or_departing_client_holds_up_neither_the_map_nor_other_clients(tmp_path, plain):
    port = free_port()
    out = tmp_path / "m.npz"
    stalled, got, departed = [], {}, threading.Event()

    def stall():
        stalled.append(stalled_client(port)[0])

    def depart():
        # reads one message, then drops the connection mid-stream
        foxglove_client.listen(f"ws://127.0.0.1:{port}", 120, on_message=lambda item: True)
        departed.set()

    threads = [threading.Thread(target=stall), threading.Thread(target=depart),
               threading.Thread(target=lambda: got.setdefault("m", foxglove_client.listen(f"ws://127.0.0.1:{port}", 120)))]
    for t in threads:
        t.start()
    # every frame offered (a rate no frame can keep below): the stalled client's queue fills
    assert fuse(out, "--foxglove", port, "--foxglove-rate", 1000) == 0
    for t in threads:
        t.join(150)
    assert not any(t.is_alive() for t in threads) and departed.is_set() and stalled
    msgs = got["m"]
    assert len([1 for t, _, _, _ in msgs if t == "/map"]) == 11          # one per frame, none lost to the stall
    check_against_store({t: last(msgs, t) for t in {t for t, _, _, _ in msgs}}, out)
    a, b = np.load(out), np.load(plain)
    assert all(np.array_equal(a[k], b[k]) for k in ("keys", "data", "knowledge", "looks", "poses"))
    for s in stalled:
        s.close()


def test_the_server_listens_on_loopback_only(tmp_path):
    from radarcl.maps.foxglove_out import FoxgloveOut

    fox = FoxgloveOut(0)
    try:
        # the kernel's own table of listening sockets: every one on the port is bound to 127.0.0.1
        listening = []
        for table in ("/proc/net/tcp", "/proc/net/tcp6"):
            if os.path.exists(table):
                for row in open(table).read().splitlines()[1:]:
                    local, state = row.split()[1], row.split()[3]
                    if state == "0A" and int(local.rsplit(":", 1)[1], 16) == fox.port:
                        listening.append(local.rsplit(":", 1)[0])
        assert listening == ["0100007F"], listening
        addresses = [a for a in _addresses() if a != "127.0.0.1"]
        for a in addresses:                               # another address of this machine: refused
            with pytest.raises(OSError):
                socket.create_connection((a, fox.port), timeout=2).close()
        socket.create_connection(("127.0.0.1", fox.port), timeout=2).close()
    finally:
        fox.close()


def _addresses():
    import subprocess

    try:
        text = subprocess.run(["hostname", "-I"], capture_output=True, text=True, timeout=5).stdout
    except (OSError, subprocess.SubprocessError):
        return []
    return [a for a in text.split() if "." in a]


def test_bad_foxglove_options_are_refused_before_anything_is_fused(tmp_path, capsys):
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    try:
        assert fuse(tmp_path / "m.npz", "--foxglove", busy.getsockname()[1]) == 2
        assert "cannot open the Foxglove output" in capsys.readouterr().err
    finally:
        busy.close()
    (tmp_path / "x.mcap").write_bytes(b"keep")
    assert fuse(tmp_path / "m.npz", "--mcap", tmp_path / "x.mcap") == 2
    assert (tmp_path / "x.mcap").read_bytes() == b"keep" and not (tmp_path / "m.npz").exists()
    assert fuse(tmp_path / "m.npz", "--foxglove", 0, "--window") == 2
    assert "--window and --foxglove" in capsys.readouterr().err


def test_radarcl_live_streams_the_emulated_radar_to_a_client(tmp_path):
    """`radarcl emulate` onto a pty, `radarcl live --foxglove` reading it: the client's last map
    is the store's."""
    import subprocess

    from radarcl.io import emulator, recording
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    obs = observe(paper_scene(), (-9.2, -5.2), seed=1)
    rec = tmp_path / "rec.npz"
    recording.save(rec, recording.Recording(obs.samples, obs.poses, "paper"))
    master, name, slave = emulator.open_pty()
    port, out = free_port(), tmp_path / "live.rcmap"
    got = {}
    client = threading.Thread(target=lambda: got.setdefault("m", foxglove_client.listen(f"ws://127.0.0.1:{port}", 120)))
    client.start()
    proc = subprocess.Popen([sys.executable, "-m", "radarcl", "live", name, "--voxel", "0.4", "--out", str(out),
                             "--quiet", "--checkpoint", "0.5", "--duration", "60", "--foxglove", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    emu = emulator.Emulator(emulator.beam_packets(obs.samples, obs.poses), lambda b: os.write(master, b), None,
                            close=lambda: (os.close(master), os.close(slave)))
    try:
        line = ""
        while "radarcl live: reading" not in line:
            line = proc.stderr.readline()
            assert line, proc.stderr.read()
        emu.start()
        emu.done.wait(60)
        emu.stop()
        stdout, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    client.join(150)
    assert proc.returncode == 0, err
    msgs = got["m"]
    assert len([1 for t, _, _, _ in msgs if t == "/map"]) >= 1
    check_against_store({t: last(msgs, t) for t in ("/map", "/map/voxels", "/trajectory", "/tf")}, out)
