"""rosbag2-compatible MCAP recording and reading without ROS.

A bag is what ``ros2 bag record -s mcap`` makes: a directory ``<name>/`` holding
``<name>_0.mcap`` (profile ``ros2``; one schema per type, encoding ``ros2msg`` with the complete
concatenated .msg text; channels with message encoding ``cdr`` and metadata
``offered_qos_profiles``/``topic_type_hash``; a ``rosbag2`` metadata record) and a version-9
``metadata.yaml``. CDR is written by :mod:`rbe_ros.io.cdr` (the bytes rclpy gives) and read by
rosbags' deserializer; the container is written with the ``mcap`` library (rosbags' own
writer keeps up to 1 MiB of messages in memory and writes nothing recoverable before close).
Messages go in and come out as *message dicts* (:mod:`rbe_ros.io.messages`); raw CDR bytes
(``rclpy.serialization.serialize_message``) are accepted as well. Never imports rclpy.
"""
from __future__ import annotations

import functools
import io
import os
import re
import sys
from collections.abc import Collection, Iterator, Mapping
from importlib.metadata import version
from pathlib import Path
from typing import NamedTuple

from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore
from ruamel.yaml import YAML

from . import cdr

MCAP_MAGIC = b"\x89MCAP0\r\n"
#: The messages of an .action file, in its order (separated by ``---`` lines).
ACTION_PARTS = ("Goal", "Result", "Feedback")
_DELIM = "=" * 80
# RMW_DURATION_INFINITE as rosbag2 (Jazzy, metadata version 9) writes it.
_INFINITE = {"sec": 9223372036, "nsec": 854775807}


class BagMessage(NamedTuple):
    """One message of a bag, as a message dict, with its topic, type and log time."""

    topic: str
    msgtype: str
    stamp_ns: int
    data: dict


# --- types ------------------------------------------------------------------------------------

def _prefixes() -> list[Path]:
    env = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return [Path(p) for p in env] + [Path(sys.prefix)]


def msg_dir() -> Path:
    """Directory of the rbe_msgs .msg files: installed share/ first, else the repository's."""
    for prefix in _prefixes():
        d = prefix / "share" / "rbe_msgs" / "msg"
        if any(d.glob("*.msg")):
            return d
    return Path(__file__).resolve().parents[1] / "msg_defs" / "msg"


@functools.cache
def typestore() -> Typestore:
    """rosbags' ROS 2 Jazzy typestore plus the rbe_msgs messages (cached; do not mutate)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict = {}
    for f in sorted(msg_dir().glob("*.msg")):
        types.update(get_types_from_msg(f.read_text(), f"rbe_msgs/msg/{f.stem}"))
    # an action's goal, result and feedback are messages of their own (as rosidl makes them),
    # recorded like any other: rbe_msgs/action/<Name>_Goal, _Result, _Feedback
    for f in sorted((msg_dir().parent / "action").glob("*.action")):
        parts = re.split(r"^---[ \t]*$", f.read_text(), flags=re.MULTILINE)
        for part, text in zip(ACTION_PARTS, parts):
            types.update(get_types_from_msg(text, f"rbe_msgs/action/{f.stem}_{part}"))
    store.register(types)
    return store


def _normalize(msgtype: str) -> str:
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else msgtype


def _nested(desc) -> str | None:
    """Message type named by a field description (through arrays), else None."""
    kind, detail = desc
    if kind == Nodetype.NAME:
        return detail
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return _nested(detail[0])
    return None


def _msg_text(store: Typestore, msgtype: str) -> str:
    """The .msg text of one type: its installed file (comments kept, as rosbag2 stores it),
    else rosbags' rendering of the type."""
    pkg, _, name = msgtype.split("/")
    dirs = [msg_dir()] if pkg == "rbe_msgs" else [p / "share" / pkg / "msg" for p in _prefixes()]
    for d in dirs:
        if (f := d / f"{name}.msg").is_file():
            return f.read_text().strip()
    return store.generate_msgdef(msgtype, ros_version=2)[0].split(_DELIM)[0].strip()


def message_definition(msgtype: str, store: Typestore | None = None) -> str:
    """Complete ``ros2msg`` definition: the type's text, then each dependency (depth first,
    once) after a line of 80 '=' and a ``MSG: pkg/Type`` line."""
    store = store or typestore()
    order: list[str] = []

    def visit(t: str) -> None:
        for _, desc in store.fielddefs[t][1]:
            if (dep := _nested(desc)) and dep not in order:
                order.append(dep)
                visit(dep)

    visit(msgtype)
    parts = [_msg_text(store, msgtype)]
    for dep in order:
        pkg, _, name = dep.split("/")
        parts.append(f"{_DELIM}\nMSG: {pkg}/{name}\n{_msg_text(store, dep)}")
    return "\n".join(parts) + "\n"


# --- rosbags objects -> message dicts ----------------------------------------------------------

def _scalar(typ: str, value):
    if typ == "string" or typ == "wstring":
        return "" if value is None else str(value)
    if value is None:
        value = 0
    if typ == "bool":
        return bool(value)
    return float(value) if typ.startswith("float") else int(value)


def to_dict(store: Typestore, msgtype: str, obj) -> dict:
    """The message dict of a rosbags message object (what :func:`rbe_ros.io.cdr.encode` takes)."""
    return {name: _value_to_dict(store, desc, getattr(obj, name))
            for name, desc in store.fielddefs[msgtype][1]}


def _value_to_dict(store: Typestore, desc, value):
    kind, detail = desc
    if kind == Nodetype.BASE:
        return _scalar(detail[0], value)
    if kind == Nodetype.NAME:
        return to_dict(store, detail, value)
    return [_value_to_dict(store, detail[0], v) for v in value]


# --- writing ----------------------------------------------------------------------------------

def _dump_yaml(data) -> str:
    yaml = YAML(typ="safe", pure=True)
    yaml.default_flow_style = False
    yaml.sort_base_mapping_type_on_output = False
    yaml.width = 4096
    out = io.StringIO()
    yaml.dump(data, out)
    return out.getvalue()


class BagWriter:
    """Write a rosbag2 (MCAP storage, metadata version 9) bag directory.

    Durability: every :meth:`write` puts the message in its own (zstd-compressed) MCAP chunk
    (with its message index) and flushes the file to the OS, so a process killed at any
    moment (SIGKILL) leaves every written message on disk; only the summary/footer and the
    final ``metadata.yaml`` are missing. A provisional ``metadata.yaml`` (message counts 0)
    is written at open and whenever a topic is added, so a killed recording is still a bag
    directory; :func:`read_bag` recovers its messages by scanning the MCAP file (``mcap
    recover`` or ``ros2 bag reindex`` repair it for other tools). With ``fsync=True`` each
    write is also fsync'ed (survives power loss, costs a disk sync per message).
    One chunk per message costs ~80 bytes of chunk header and message index on disk and one
    chunk-index entry in memory per message: meant for low-rate topics (states, reports), not
    sensor streams. ``stamp_ns`` may go backwards (chunks are indexed, readers merge by time).
    """

    def __init__(self, path, *, depth: int = 10, fsync: bool = False,
                 custom_data: Mapping[str, str] | None = None):
        self.path = Path(path)
        # metadata.yaml custom_data (rosbag2: string to string), e.g. the check options
        self.custom_data = {str(k): str(v) for k, v in (custom_data or {}).items()}
        if self.path.exists():
            raise FileExistsError(f"bag {str(self.path)!r} exists already, not overwriting")
        self.depth, self.fsync = int(depth), fsync
        self.store = typestore()
        self.path.mkdir(parents=True)
        self.mcap_path = self.path / f"{self.path.name}_0.mcap"
        self._file = self.mcap_path.open("xb")
        # zstd chunks: a report's markers (block meshes as triangle lists) shrink about 5x
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library=f"rbe_ros bag.py, mcap {version('mcap')}")
        self._file.flush()
        self._schemas: dict[str, int] = {}
        self._topics: dict[str, dict] = {}  # topic -> channel_id, msgtype, qos, hash, count
        self._start, self._end = None, None
        self._write_metadata()

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def add_topic(self, topic: str, msgtype: str, *, transient_local: bool = False) -> None:
        """Register ``topic`` (QoS offered: reliable, keep_last ``depth``, durability
        transient_local or volatile)."""
        msgtype = _normalize(msgtype)
        if topic in self._topics:
            raise ValueError(f"topic {topic!r} was added already")
        if msgtype not in self.store.fielddefs:
            raise KeyError(f"unknown message type {msgtype!r}")
        if msgtype not in self._schemas:
            self._schemas[msgtype] = self._writer.register_schema(
                msgtype, "ros2msg", message_definition(msgtype, self.store).encode())
        qos = [{"history": "keep_last", "depth": self.depth, "reliability": "reliable",
                "durability": "transient_local" if transient_local else "volatile",
                "deadline": dict(_INFINITE), "lifespan": dict(_INFINITE),
                "liveliness": "automatic", "liveliness_lease_duration": dict(_INFINITE),
                "avoid_ros_namespace_conventions": False}]
        digest = self.store.hash_rihs01(msgtype)
        cid = self._writer.register_channel(topic, "cdr", self._schemas[msgtype], {
            "offered_qos_profiles": _dump_yaml(qos).strip(), "topic_type_hash": digest})
        self._topics[topic] = {"id": cid, "msgtype": msgtype, "qos": qos, "hash": digest,
                               "encode": cdr.encoder(self.store, msgtype), "count": 0}
        self._write_metadata()

    def write(self, topic: str, message, stamp_ns: int) -> None:
        """Append ``message`` (a message dict, or raw CDR bytes) to ``topic`` at ``stamp_ns``."""
        if self._writer is None:
            raise RuntimeError("bag is closed")
        info = self._topics.get(topic)
        if info is None:
            raise KeyError(f"topic {topic!r} was not added")
        if isinstance(message, (bytes, bytearray, memoryview)):
            data = bytes(message)
        else:
            data = info["encode"](message)
        stamp_ns = int(stamp_ns)
        self._writer.add_message(info["id"], log_time=stamp_ns, data=data,
                                 publish_time=stamp_ns, sequence=info["count"])
        self._writer.flush()  # finishes the one-message chunk and flushes the file
        if self.fsync:
            os.fsync(self._file.fileno())
        info["count"] += 1
        self._start = stamp_ns if self._start is None else min(self._start, stamp_ns)
        self._end = stamp_ns if self._end is None else max(self._end, stamp_ns)

    def close(self) -> None:
        """Finish the MCAP file (summary, footer, ``rosbag2`` metadata record) and write
        the final ``metadata.yaml``. Idempotent."""
        if self._writer is None:
            return
        info = self._info()
        self._writer.add_metadata("rosbag2", {"serialized_metadata": _dump_yaml(info).strip(),
                                              "ros_distro": "jazzy"})
        self._writer.finish()
        self._file.close()
        self._writer = None
        self._write_metadata(info)

    def _info(self) -> dict:
        start = self._start or 0
        duration = (self._end - self._start) if self._start is not None else 0
        count = sum(t["count"] for t in self._topics.values())
        return {
            "version": 9,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": count,
            "topics_with_message_count": [
                {"topic_metadata": {"name": topic, "type": t["msgtype"],
                                    "serialization_format": "cdr",
                                    "offered_qos_profiles": t["qos"],
                                    "type_description_hash": t["hash"]},
                 "message_count": t["count"]}
                for topic, t in self._topics.items()],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.mcap_path.name],
            "files": [{"path": self.mcap_path.name,
                       "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration}, "message_count": count}],
            "custom_data": dict(self.custom_data),
            "ros_distro": "jazzy",
        }

    def _write_metadata(self, info: dict | None = None) -> None:
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(_dump_yaml({"rosbag2_bagfile_information": info or self._info()}))
        tmp.replace(self.path / "metadata.yaml")


# --- reading ----------------------------------------------------------------------------------

def read_custom_data(path) -> dict[str, str]:
    """The ``custom_data`` of a bag directory's metadata.yaml (empty if it has none)."""
    meta = Path(path) / "metadata.yaml"
    if not meta.is_file():
        return {}
    info = YAML(typ="safe", pure=True).load(meta.read_text()) or {}
    data = (info.get("rosbag2_bagfile_information") or {}).get("custom_data") or {}
    return {str(k): str(v) for k, v in data.items()}


def _mcap_files(path: Path) -> list[Path]:
    return sorted(path.glob("*.mcap")) if path.is_dir() else [path]


def _finished(mcap_path: Path) -> bool:
    with mcap_path.open("rb") as f:
        if f.seek(0, os.SEEK_END) < 2 * len(MCAP_MAGIC):
            return False
        f.seek(-len(MCAP_MAGIC), os.SEEK_END)
        return f.read() == MCAP_MAGIC


def read_bag(path, msgtypes: Collection[str] | None = None) -> Iterator[BagMessage]:
    """The messages of a bag directory (or a single .mcap file) as message dicts (only
    those of ``msgtypes``, e.g. ``{"rbe_msgs/msg/StabilityReport"}``, if given).

    A finished bag is read with rosbags' AnyReader (types from the definitions stored in the
    bag, in time order). An MCAP file without footer (a recording that was killed) is scanned
    record by record in file order up to its last complete chunk.
    """
    path = Path(path)
    if all(_finished(f) for f in _mcap_files(path)):
        with AnyReader([path]) as reader:
            connections = [c for c in reader.connections
                           if msgtypes is None or c.msgtype in msgtypes]
            for conn, stamp, raw in reader.messages(connections=connections):
                obj = reader.deserialize(raw, conn.msgtype)
                yield BagMessage(conn.topic, conn.msgtype, stamp,
                                 to_dict(reader.typestore, conn.msgtype, obj))
        return
    for f in _mcap_files(path):
        yield from _scan_mcap(f, msgtypes)


def _scan_mcap(path: Path, msgtypes: Collection[str] | None = None) -> Iterator[BagMessage]:
    store = get_typestore(Stores.EMPTY)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    with path.open("rb") as f:
        records = StreamReader(f, emit_chunks=False).records
        while True:
            try:
                rec = next(records)
            except (StopIteration, McapError, ValueError):  # end, or a truncated last record
                return
            if isinstance(rec, Schema):
                schemas[rec.id] = rec
                store.register(get_types_from_msg(rec.data.decode(), rec.name))
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
            elif isinstance(rec, Message) and rec.channel_id in channels:
                ch = channels[rec.channel_id]
                msgtype = schemas[ch.schema_id].name
                if msgtypes is not None and msgtype not in msgtypes:
                    continue
                obj = store.deserialize_cdr(rec.data, msgtype)
                yield BagMessage(ch.topic, msgtype, rec.log_time, to_dict(store, msgtype, obj))


__all__ = ["BagMessage", "BagWriter", "message_definition", "msg_dir", "read_bag",
           "read_custom_data", "to_dict", "typestore"]
