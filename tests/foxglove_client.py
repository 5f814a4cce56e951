"""A Foxglove WebSocket protocol client for the tests, written from the protocol's specification (in
the foxglove/ws-protocol repository): it subscribes to every channel advertised and
decodes each message with the protobuf schema the server advertised (google.protobuf, not the
SDK that encoded it), for a bounded time, stopping by itself."""

import base64
import json
import struct
import time

# the SDK's server speaks the protocol under its newer name; the older one is the ws-protocol's
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01


def message_classes(schema_name, descriptor_set):
    """The protobuf class of ``schema_name`` from a serialised FileDescriptorSet."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fds = descriptor_pb2.FileDescriptorSet.FromString(descriptor_set)
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def listen(url, seconds, on_message=None, open_timeout=30.0):
    """Connect to ``url``, subscribe to every channel, and collect (topic, log_time_ns,
    received monotonic s, decoded message) until the server closes or ``seconds`` pass.
    ``on_message(item)`` may return True to stop early."""
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    deadline = time.monotonic() + open_timeout
    while True:
        try:
            ws = connect(url, subprotocols=SUBPROTOCOLS, max_size=None, open_timeout=5)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)
    got, subs, next_id = [], {}, 1
    end = time.monotonic() + seconds
    with ws:
        while time.monotonic() < end:
            try:
                frame = ws.recv(timeout=max(0.01, end - time.monotonic()))
            except TimeoutError:
                break
            except ConnectionClosed:
                break
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg.get("op") == "advertise":
                    new = []
                    for ch in msg["channels"]:
                        assert ch["encoding"] == "protobuf" and ch.get("schemaEncoding", "protobuf") == "protobuf", ch
                        cls = message_classes(ch["schemaName"], base64.b64decode(ch["schema"]))
                        subs[next_id] = (ch["topic"], cls)
                        new.append({"id": next_id, "channelId": ch["id"]})
                        next_id += 1
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            if frame[0] != MESSAGE_DATA:
                continue
            sub, log_time = struct.unpack_from("<IQ", frame, 1)
            topic, cls = subs[sub]
            item = (topic, log_time, time.monotonic(), cls.FromString(frame[13:]))
            got.append(item)
            if on_message is not None and on_message(item):
                break
    return got
