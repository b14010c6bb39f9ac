"""What a truncated ROS1 bag still holds (:func:`salvage_bag`).

A ROS1 bag (format 2.0) keeps its index (connection records, chunk infos) after its chunks,
at the position its bag header names; a recording cut short (a full disk, a killed
recorder, a partial copy) has no index, and an indexed reader refuses it. Its records still
follow one another from the start: each a ``u32``-length header of ``name=value`` fields
(``op`` its type), a ``u32`` data length and the data. A chunk's data holds connection and
message-data records; this module reads the chunks in file order up to the cut and returns
every whole message before it, deserialised with the message definitions that the bag's
own connection records carry (no ROS package needed).
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

BAG_MAGIC = b"#ROSBAG V2.0\n"
OP_MSGDATA, OP_CHUNK, OP_CONNECTION = 2, 5, 7


@dataclass(frozen=True)
class Salvage:
    """The whole messages of a truncated bag: ``messages`` as ``(topic, message)`` in file
    order, ``kept_bytes`` the bytes read up to the last whole chunk, ``size`` the file's."""

    messages: list[tuple[str, object]]
    kept_bytes: int
    size: int


def _records(src: io.BytesIO | io.BufferedReader) -> Iterator[tuple[dict[str, bytes], bytes]]:
    """The whole records of ``src`` from its position: ``(header fields, data)``; stops at
    the first record cut short."""
    from rosbags.rosbag1.reader import Header, ReaderError, read_bytes, read_uint32

    while True:
        try:
            header = Header.read(src)
            data = read_bytes(src, read_uint32(src))
        except (ReaderError, ValueError):
            return
        yield header, data


def salvage_bag(path: Path, typestore: object) -> Salvage:
    """Every whole message of the ROS1 bag at ``path`` in file order, read without its
    index (see module); ``typestore`` (rosbags) gets the bag's message types registered."""
    from rosbags.rosbag1.reader import decompressors
    from rosbags.typesys import get_types_from_msg
    from rosbags.typesys.msg import normalize_msgtype

    size = path.stat().st_size
    messages: list[tuple[str, object]] = []
    connections: dict[int, tuple[str, str]] = {}
    kept = len(BAG_MAGIC)
    with path.open("rb") as f:
        if f.read(len(BAG_MAGIC)) != BAG_MAGIC:
            return Salvage(messages, 0, size)
        for header, data in _records(f):
            if header.get_uint8("op") != OP_CHUNK:
                kept = f.tell()
                continue
            decompress = decompressors.get(header.get_string("compression"))
            if decompress is None:
                break
            for inner, body in _records(io.BytesIO(decompress(data))):
                op = inner.get_uint8("op")
                if op == OP_CONNECTION:
                    fields = next(_records(io.BytesIO(_as_record(body))))[0]
                    msgtype = normalize_msgtype(fields.get_string("type"))
                    typestore.register(get_types_from_msg(
                        fields.get_string("message_definition"), msgtype))
                    connections[inner.get_uint32("conn")] = (inner.get_string("topic"),
                                                             msgtype)
                elif op == OP_MSGDATA and (conn := inner.get_uint32("conn")) in connections:
                    topic, msgtype = connections[conn]
                    messages.append((topic, typestore.deserialize_ros1(body, msgtype)))
            kept = f.tell()
    return Salvage(messages, kept, size)


def _as_record(fields: bytes) -> bytes:
    """A connection record's data (bare header fields) framed as a record with no data."""
    return len(fields).to_bytes(4, "little") + fields + (0).to_bytes(4, "little")
