"""Reading rosbag2 bags (MCAP or SQLite3) with the ``rosbags`` library alone: no rclpy, no ROS
message packages, so ``ecahd eval-bag`` runs on any machine with numpy and rosbags.

Messages come back as rosbags dataclasses with the ROS field names (``msg.pose.position.x``),
deserialised with the definitions stored in the bag, or with the ROS 2 Jazzy typestore for a
bag that stores none. The helpers below read the few fields the evaluation needs from them (or
from rclpy messages, which have the same names).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from rosbags.typesys import Stores, get_typestore

from ecahd_core.errors import BagError

TYPESTORE = Stores.ROS2_JAZZY  # the message definitions bags are written and read with


def _bag_folder(path) -> Path:
    path = Path(path)
    if not (path / "metadata.yaml").is_file():
        raise BagError(f"{str(path)!r} is not a rosbag2 directory (no metadata.yaml)")
    return path


def bag_topics(path) -> dict[str, int]:
    """The topics of a rosbag2 bag -> {topic: message count}, from its index alone (no message
    is read), so a caller can pick what to read from a large bag. Raises as :func:`read_bag`."""
    from rosbags.highlevel import AnyReader, AnyReaderError

    path = _bag_folder(path)
    try:
        with AnyReader([path], default_typestore=get_typestore(TYPESTORE)) as reader:
            return {topic: int(info.msgcount) for topic, info in reader.topics.items()}
    except AnyReaderError as exc:
        raise BagError(f"cannot read bag {str(path)!r}: {exc}") from exc


def read_bag(path, topics=None) -> dict[str, list[tuple[int, object]]]:
    """Read a rosbag2 bag (MCAP or SQLite3) -> {topic: [(receive time [ns], message), ...]} in
    time order, every recorded topic present (maybe with an empty list: a topic that was
    advertised but never published). topics: names to keep (default all). Raises BagError for
    a folder without metadata.yaml or a bag rosbags cannot read."""
    from rosbags.highlevel import AnyReader, AnyReaderError

    path = _bag_folder(path)
    try:
        with AnyReader([path], default_typestore=get_typestore(TYPESTORE)) as reader:
            connections = [c for c in reader.connections if topics is None or c.topic in topics]
            out: dict[str, list[tuple[int, object]]] = {c.topic: [] for c in connections}
            if not connections:  # rosbags reads every connection when given none
                return out
            for conn, t_ns, raw in reader.messages(connections=connections):
                out[conn.topic].append((int(t_ns), reader.deserialize(raw, conn.msgtype)))
    except AnyReaderError as exc:
        raise BagError(f"cannot read bag {str(path)!r}: {exc}") from exc
    return out


def stamp_seconds(stamp) -> float:
    """builtin_interfaces/Time -> [s]."""
    return stamp.sec + stamp.nanosec * 1e-9


def quaternion_yaw(q) -> float:
    """Heading [rad] of a geometry_msgs/Quaternion (rotation about z)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


# ------------------------------------------------------------------ streaming, damaged bags
_MCAP_MAGIC = b"\x89MCAP0\r\n"


@dataclass
class BagScan:
    """What :func:`scan_bag` read: messages handed on, and what it had to skip."""

    read: int = 0  # messages of the wanted topics handed to the callback
    skipped_messages: int = 0  # messages of the wanted topics known lost
    skipped_chunks: int = 0  # MCAP chunks that could not be read (their messages unknown)
    skipped_bytes: int = 0  # a truncated MCAP file's unreadable tail
    problem: str = ""  # what was wrong, "" for an intact bag

    @property
    def damaged(self) -> bool:
        return bool(self.problem)

    def describe(self) -> str:
        """'' for an intact bag, else one phrase: what was skipped and why."""
        if not self.problem:
            return ""
        parts = [f"{n} {what}" for n, what in ((self.skipped_messages, "message(s)"),
                                               (self.skipped_chunks, "unreadable chunk(s)"),
                                               (self.skipped_bytes, "byte(s) of a cut-off tail"))
                 if n]
        return f"{self.problem}; read {self.read} message(s), skipped {', '.join(parts) or 'nothing'}"


def scan_bag(path, topics, handle) -> BagScan:
    """Stream a rosbag2 bag's messages on ``topics`` (names, or a predicate of a name) to ``handle(topic, t_ns, msg)`` without
    holding them (a bag larger than memory is fine), in file order (time order within each
    MCAP chunk; callers sort what they need).

    MCAP files are walked record by record (the format's own layout: schema, channel, message
    and chunk records), so a bag that is damaged part-way gives what can be read: a chunk
    that does not decompress is skipped and counted, a file cut off mid-record (a recorder
    that died: no summary, no footer, maybe no metadata.yaml) is read up to the cut. SQLite3
    bags go through rosbags; an error part-way keeps what was read and counts the rest of the
    index as skipped. Raises BagError when nothing can be read at all (not a bag, no MCAP
    magic, a database rosbags cannot open)."""
    path = Path(path)
    wanted = _Wanted(topics)
    mcaps = sorted(path.glob("*.mcap")) if path.is_dir() else []
    if mcaps:
        scan = BagScan()
        for file in mcaps:
            _scan_mcap(file, wanted, handle, scan)
        return scan
    return _scan_anyreader(_bag_folder(path), wanted, handle)


def _scan_anyreader(path: Path, wanted, handle) -> BagScan:
    from rosbags.highlevel import AnyReader, AnyReaderError

    scan = BagScan()
    try:
        with AnyReader([path], default_typestore=get_typestore(TYPESTORE)) as reader:
            conns = [c for c in reader.connections if c.topic in wanted]
            total = sum(int(c.msgcount) for c in conns)
            if not conns:
                return scan
            try:
                for conn, t_ns, raw in reader.messages(connections=conns):
                    handle(conn.topic, int(t_ns), reader.deserialize(raw, conn.msgtype))
                    scan.read += 1
            except (AnyReaderError, Exception) as exc:  # noqa: BLE001  (damage part-way)
                if scan.read == 0:
                    raise BagError(f"cannot read bag {str(path)!r}: {exc}") from exc
                scan.problem = f"unreadable after {scan.read} messages ({exc})"
                scan.skipped_messages = max(total - scan.read, 0)
    except AnyReaderError as exc:
        raise BagError(f"cannot read bag {str(path)!r}: {exc}") from exc
    return scan


def _scan_mcap(file: Path, wanted, handle, scan: BagScan) -> None:
    """Walk one MCAP file's records (module :func:`scan_bag`), memory-mapped."""
    import mmap
    import struct

    from rosbags.rosbag2.storage_mcap import decompress

    typestore = get_typestore(TYPESTORE)
    size = file.stat().st_size
    if size < len(_MCAP_MAGIC) + 9:
        raise BagError(f"cannot read bag file {str(file)!r}: {size} bytes, not an MCAP file")
    with open(file, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
        if buf[:8] != _MCAP_MAGIC:
            raise BagError(f"cannot read bag file {str(file)!r}: not an MCAP file (no magic)")
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}  # id -> (topic, msgtype)

        def string(data, at: int) -> tuple[str, int]:
            (n,) = struct.unpack_from("<I", data, at)
            return bytes(data[at + 4:at + 4 + n]).decode(), at + 4 + n

        def records(data, start: int, end: int, top: bool) -> None:
            pos = start
            while pos < end:
                if pos + 9 > end:
                    raise _Truncated(pos)
                op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
                body, nxt = pos + 9, pos + 9 + length
                if nxt > end:
                    if op == 0x06 and top:  # a cut-off chunk: its records up to the cut
                        _cut_chunk(data, body, end)
                    raise _Truncated(pos)
                if op == 0x03:  # schema: id, name, encoding, data
                    (sid,) = struct.unpack_from("<H", data, body)
                    schemas[sid] = string(data, body + 2)[0]
                elif op == 0x04:  # channel: id, schema id, topic, ...
                    cid, sid = struct.unpack_from("<HH", data, body)
                    channels[cid] = (string(data, body + 4)[0], schemas.get(sid, ""))
                elif op == 0x05:  # message: channel, sequence, log time, publish time, data
                    cid, _, log_time = struct.unpack_from("<HIQ", data, body)
                    topic, msgtype = channels.get(cid, ("", ""))
                    if topic in wanted:
                        raw = bytes(data[body + 22:nxt])
                        try:
                            msg = typestore.deserialize_cdr(raw, msgtype)
                        except Exception:  # noqa: BLE001  (a damaged message)
                            scan.skipped_messages += 1
                            scan.problem = scan.problem or "damaged messages"
                        else:
                            handle(topic, int(log_time), msg)
                            scan.read += 1
                elif op == 0x06 and top:  # chunk: start, end, size, crc, compression, records
                    _, _, usize, crc = struct.unpack_from("<QQQI", data, body)
                    compression, at = string(data, body + 28)
                    (csize,) = struct.unpack_from("<Q", data, at)
                    try:
                        if at + 8 + csize > nxt:
                            raise ValueError("compressed data beyond the chunk")
                        inner = decompress(bytes(data[at + 8:at + 8 + csize]), compression,
                                           usize, crc)
                        records(inner, 0, len(inner), False)
                    except (_Truncated, ValueError, struct.error, Exception) as exc:  # noqa: BLE001
                        scan.skipped_chunks += 1
                        scan.problem = scan.problem or f"a damaged chunk ({exc})"
                elif op == 0x02 and top:  # footer: the end
                    return
                pos = nxt

        def _cut_chunk(data, body: int, end: int) -> None:
            """An uncompressed chunk cut off by the end of the file: its whole records are
            read (a compressed one cannot be)."""
            compression, at = string(data, body + 28)
            if compression:
                return
            records(data, at + 8, end, False)  # raises _Truncated at the cut record

        try:
            records(buf, 8, size, True)
        except _Truncated as cut:
            scan.skipped_bytes += size - cut.at
            scan.problem = scan.problem or f"{file.name} is cut off (a recording that died?)"
        except struct.error as exc:
            scan.skipped_bytes += 1
            scan.problem = scan.problem or f"{file.name} has a damaged record ({exc})"


class _Truncated(Exception):
    """An MCAP record runs past the end of its data."""

    def __init__(self, at: int) -> None:
        super().__init__(at)
        self.at = at


class _Wanted:
    """``topic in wanted`` for a collection of names or a predicate."""

    def __init__(self, topics) -> None:
        self._test = topics if callable(topics) else set(topics).__contains__

    def __contains__(self, topic: str) -> bool:
        return bool(self._test(topic))
