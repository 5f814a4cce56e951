"""A damaged ROS 2 bag read as far as it goes: what ``io.rosbag.Bag`` falls back to when rosbags
cannot open a storage file (an MCAP cut short has no summary or end magic; SQLite refuses a
database whose pages it cannot walk).

MCAP: the mcap library's stream reader walks the records from the start (schemas, channels,
messages, chunks) until the first one that cannot be read. SQLite: the messages in the order
they were written (by id), until SQLite meets a page it cannot read. A database cut short
still declares its whole size in its header, which makes SQLite refuse every page; a copy of
it (in a temporary folder: the bag is never written) declaring the pages that are there is
read instead. Either way the damage is named and nothing past it is guessed.
"""

import shutil
import sqlite3
import tempfile
from pathlib import Path

from radarcl.errors import FrameFormatError

STORAGE_SUFFIXES = (".db3", ".mcap")


def storage_files(path):
    """The storage files of a bag (its folder's, in name order, or the one file given)."""
    path = Path(path)
    files = sorted(p for p in path.iterdir() if p.suffix in STORAGE_SUFFIXES) if path.is_dir() else [path]
    files = [f for f in files if f.suffix in STORAGE_SUFFIXES]
    if not files:
        raise FrameFormatError(f"{path}: no .db3 or .mcap storage file in it, so it is no ROS 2 bag")
    return files


def said(exc):
    """An exception in words (the mcap library's EndOfFile says nothing itself)."""
    if type(exc).__name__ == "EndOfFile":
        return "the file ends inside a record (cut short)"
    return f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__


class Salvage:
    """The readable part of a bag that rosbags refused for ``why``: ``connections`` [(topic,
    type, definition format 'MSG'/'IDL'/'NONE', definition text)], ``topics()`` with the counts
    read, ``messages(topics)`` yielding (topic, type, log time [ns], CDR bytes) until the damage
    (raised there)."""

    def __init__(self, path, why):
        self.work = tempfile.TemporaryDirectory(prefix="radarcl-bag-")
        self.files = [_readable_sqlite(f, Path(self.work.name)) if f.suffix == ".db3" else f
                      for f in storage_files(path)]
        self.damage = f"{path} is damaged ({why})"
        self.connections = []
        for f in self.files:
            try:
                self.connections += _mcap_connections(f) if f.suffix == ".mcap" else _sqlite_connections(f)
            except Exception as exc:        # noqa: BLE001 - a file whose table of topics is lost
                raise FrameFormatError(f"{self.damage}; not even its topics can be read ({said(exc)}), so no "
                                       "scan is fused") from exc

    def close(self):
        """Remove the readable copies."""
        self.work.cleanup()

    def topics(self):
        counts = {}
        try:
            for topic, _, _, _ in self.messages({c[0] for c in self.connections}):
                counts[topic] = counts.get(topic, 0) + 1
        except Exception:                   # noqa: BLE001 - counted up to the damage
            pass
        types = {c[0]: c[1] for c in self.connections}
        return [(t, types[t], counts.get(t, 0)) for t in sorted(types)]

    def messages(self, topics):
        for f in self.files:
            yield from (_mcap_messages if f.suffix == ".mcap" else _sqlite_messages)(f, topics)


_MCAP_FORMATS = {"ros2msg": "MSG", "ros2idl": "IDL"}


def _mcap_records(path):
    from mcap.stream_reader import StreamReader

    with open(path, "rb") as f:
        yield from StreamReader(f, skip_magic=False).records


def _mcap_connections(path):
    from mcap.records import Channel, Schema

    schemas, out = {}, []
    try:
        for r in _mcap_records(path):
            if isinstance(r, Schema):
                schemas[r.id] = r
            elif isinstance(r, Channel) and r.schema_id in schemas:
                sc = schemas[r.schema_id]
                out.append((r.topic, sc.name, _MCAP_FORMATS.get(sc.encoding, "NONE"), sc.data.decode(errors="replace")))
    except Exception:                       # noqa: BLE001 - the channels before the damage
        if not out:
            raise
    return out


def _mcap_messages(path, topics):
    from mcap.records import Channel, Message, Schema

    schemas, channels = {}, {}
    for r in _mcap_records(path):
        if isinstance(r, Schema):
            schemas[r.id] = r.name
        elif isinstance(r, Channel):
            channels[r.id] = (r.topic, schemas.get(r.schema_id))
        elif isinstance(r, Message) and r.channel_id in channels:
            topic, msgtype = channels[r.channel_id]
            if topic in topics:
                yield topic, msgtype, r.log_time, r.data


def _readable_sqlite(path, work):
    """``path``, or where its header declares more pages than the file holds (a cut), a copy in
    ``work`` whose header declares the whole pages it has (bytes 28-31: the database size in
    pages, trusted by SQLite while bytes 92-95 match the change counter)."""
    header = Path(path).read_bytes()[:100] if Path(path).stat().st_size >= 100 else b""
    if len(header) < 100 or not header.startswith(b"SQLite format 3\x00"):
        return path
    page = int.from_bytes(header[16:18], "big") or 1
    page = 65536 if page == 1 else page
    pages = Path(path).stat().st_size // page
    if int.from_bytes(header[28:32], "big") <= pages:
        return path
    copy = work / Path(path).name
    shutil.copyfile(path, copy)
    with open(copy, "r+b") as f:
        f.seek(28)
        f.write(pages.to_bytes(4, "big"))
    return copy


def _sqlite(path):
    return sqlite3.connect(f"file:{Path(path).resolve()}?mode=ro&immutable=1", uri=True)


def _sqlite_connections(path):
    con = _sqlite(path)
    try:
        topics = con.execute("SELECT name, type FROM topics ORDER BY id").fetchall()
        try:
            defs = {t: (e, d) for t, e, d in con.execute(
                "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions")}
        except sqlite3.DatabaseError:       # a bag of metadata version < 8 carries none
            defs = {}
    finally:
        con.close()
    return [(name, msgtype, _MCAP_FORMATS.get(defs.get(msgtype, ("", ""))[0], "NONE"), defs.get(msgtype, ("", ""))[1])
            for name, msgtype in topics]


def _sqlite_messages(path, topics):
    con = _sqlite(path)
    try:
        names = dict(con.execute("SELECT id, name FROM topics").fetchall())
        types = dict(con.execute("SELECT name, type FROM topics").fetchall())
        for topic_id, t, data in con.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY id"):
            topic = names.get(topic_id)
            if topic in topics:
                yield topic, types[topic], int(t), bytes(data)
    finally:
        con.close()
