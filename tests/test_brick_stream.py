"""The engine-to-viewer brick stream (radarcl/io/brick_stream.py) and `radarcl view --follow`:
a viewer that connects gets the whole map, then each change, and draws it; a bad stream stops
the subscriber with the reason."""

import socket
import struct

import numpy as np
import pytest

from radarcl.errors import ConfigError
from radarcl.gridspec import BRICK, GridSpec
from radarcl.io import brick_stream as bs

SPEC = GridSpec((-4.0, -3.0, -1.0), 0.25, (40, 32, 24))


def a_map(value=4.0):
    keys = np.array([[2, 1, 1], [0, 0, 0]], np.int32)
    data = np.full((2, BRICK, BRICK, BRICK), -1024, np.int32)
    data[0] = int(value * 1024)
    return keys, data


def wait_for(sub, kinds, timeout=10):
    got = []
    while {g[0] for g in got} < set(kinds):
        assert sub.arrived.wait(timeout), (got, sub.error)
        sub.arrived.clear()
        got += sub.take()
    return got


def test_a_viewer_gets_the_map_then_each_change():
    keys, data = a_map()
    poses = np.stack([np.eye(4)] * 2)
    pub = bs.BrickPublisher(lambda: (SPEC, keys, data, poses))
    sub = bs.BrickSubscriber(pub.address)
    try:
        for _ in range(200):                                 # until the server has accepted the viewer
            pub.publish()                                    # greets a new viewer
            if sub.arrived.wait(0.05):
                break
        got = wait_for(sub, ["spec", "bricks", "poses"])
        spec = next(g[1] for g in got if g[0] == "spec")
        k, d = next(g[1:] for g in got if g[0] == "bricks")
        assert spec == SPEC and np.array_equal(k, keys) and np.array_equal(d, data)
        change = np.full((1, BRICK, BRICK, BRICK), 7, np.int32)
        pub.publish(np.array([[1, 1, 1]], np.int32), change, poses[:1])
        got = wait_for(sub, ["bricks", "poses"])
        k, d = next(g[1:] for g in got if g[0] == "bricks")
        assert k.tolist() == [[1, 1, 1]] and (d == 7).all()
    finally:
        sub.close()
        pub.close()


def test_a_viewer_that_comes_before_the_first_beam_gets_an_empty_map():
    """`radarcl live --view` starts its viewer before the radar has sent anything: the greeting
    holds no brick (this crashed the engine: an empty array cannot be reshaped to (0, -1))."""
    keys, data = np.zeros((0, 3), np.int32), np.zeros((0, BRICK, BRICK, BRICK), np.int32)
    pub = bs.BrickPublisher(lambda: (SPEC, keys, data, None))
    sub = bs.BrickSubscriber(pub.address)
    try:
        for _ in range(200):
            pub.publish()
            if sub.arrived.wait(0.05):
                break
        got = wait_for(sub, ["spec", "bricks"])
        k, d = next(g[1:] for g in got if g[0] == "bricks")
        assert k.shape == (0, 3) and d.size == 0 and sub.error is None
    finally:
        sub.close()
        pub.close()


def test_a_bad_stream_stops_the_subscriber_with_the_reason():
    server = socket.create_server(("127.0.0.1", 0))
    addr = server.getsockname()[:2]
    sub = bs.BrickSubscriber(addr)
    conn, _ = server.accept()
    spec = b'{"origin_m": [0, 0, 0], "voxel_m": 1.0, "shape": [8, 8, 8]}'
    conn.sendall(struct.pack("<4sBI", b"RCVS", 1, len(spec)) + spec)
    conn.sendall(struct.pack("<4sBI", b"RCVS", 2, 16) + struct.pack("<I", 1) + struct.pack("<3i", 5, 0, 0))
    sub._thread.join(10)                                    # it stops on the bad message
    assert sub.error and "1 bricks need" in sub.error
    conn.close()
    server.close()
    sub.close()
    with pytest.raises(ConfigError, match="no radarcl engine"):
        bs.BrickSubscriber(addr, timeout_s=1)
    with pytest.raises(ConfigError, match="HOST:PORT"):
        bs.parse_address("here:there")


def test_the_viewer_follows_an_engine():
    from radarcl.viewer.app import ViewerApp, follow_engine, open_window
    from radarcl.viewer.camera import Camera
    from radarcl.viewer.renderer import read_rgb

    keys, data = a_map()
    state = dict(keys=keys, data=data)
    pub = bs.BrickPublisher(lambda: (SPEC, state["keys"], state["data"], None))
    import threading

    stop = threading.Event()

    def greet():                                            # the engine's loop, publishing as it fuses
        while not stop.wait(0.05):
            pub.publish()

    threading.Thread(target=greet, daemon=True).start()
    wnd = None
    try:
        sub, volume = follow_engine(f"{pub.address[0]}:{pub.address[1]}")
        wnd = open_window("headless", (160, 120), "follow")
        app = ViewerApp(wnd, "follow", volume, camera=Camera.fit(SPEC), follow=sub)
        app.frame()
        before = read_rgb(wnd.fbo).copy()
        change = np.full((1, BRICK, BRICK, BRICK), 6 * 1024, np.int32)
        pub.publish(np.array([[4, 3, 2]], np.int32), change)
        for _ in range(100):
            app.frame()
            if app.updates:
                break
            sub.arrived.wait(0.05)
        assert app.updates == 1 and "1 bricks" in app.message
        assert not np.array_equal(read_rgb(wnd.fbo), before)           # the new brick is drawn
        assert volume.values[2 * 8:3 * 8, 3 * 8:4 * 8, 4 * 8:5 * 8].min() == 6.0
    finally:
        stop.set()
        pub.close()
        if wnd is not None:
            wnd.destroy()
