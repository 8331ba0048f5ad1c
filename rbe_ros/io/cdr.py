"""CDR encoding of message dicts, straight to the bytes ROS 2 sends; no rclpy.

Why: an rclpy message costs a Python object per field value before it is serialised at all,
and a report of a 1000-block wall holds ~50k Points. Here a message dict
(:mod:`rbe_ros.io.messages`) becomes bytes directly, and a sequence of Points given as an
``(n, 3)`` numpy array is one ``tobytes`` (the cost of a report message is in
docs/SCALING.md, ``make scaling``).

Format: little-endian plain CDR (XCDR1) as ROS 2 (Fast CDR) writes it: the encapsulation
header ``00 01 00 00``, then the fields in order, each primitive aligned to its size (at
most 8) relative to the byte after the header; a string is a uint32 length (with the NUL),
the UTF-8 bytes and a NUL (a string ends at its first NUL, as rclpy's C strings do); a
sequence is a uint32 count and the items (aligned only when there are any); a fixed array
is the items alone. Padding bytes are zeros, as rosbags writes them. rclpy's
``serialize_message`` gives the same bytes except that it leaves padding uninitialised: heap
garbage, different from run to run (~8800 of the 168k bytes of a 117-block wall's report),
zeros only when its buffer is fresh memory.

The layout comes from a rosbags typestore (``fielddefs``, parsed from the .msg files):
nothing here knows a message type. Per type a writer is generated once (Python source,
``exec``): a complete message dict is written without a check per field, the primitives
that follow one another (nested messages inline) packed by one precompiled ``struct`` per
alignment phase. Anything else (missing fields, values to cast, wrong shapes, errors) goes
to the slow path, which makes the dict complete and so defines the semantics:

* a missing field (or ``None``) takes its zero value: 0, ``""``, an empty sequence, a
  fixed array of zeros. The typestore has no .msg default values, so a missing
  ``Quaternion.w`` is 0 here where rclpy's default is 1: give it;
* numbers are cast with ``float``/``int``/``bool`` (strings too: "2.5"), integers
  range-checked;
* an unknown key, a fixed array of the wrong length, an array of the wrong shape or a value
  out of range raises ``ValueError``, a value that is no message dict or no sequence
  ``TypeError``, each naming the field (``rbe_msgs/msg/StabilityReport.interfaces[3].kern``);
* a sequence of messages whose fields are all of one numeric type (Point, Vector3,
  Quaternion, ColorRGBA) may be an ``(n, k)`` array of their field values in field order,
  a sequence of numbers a 1-D array (cast when numpy casts it safely, else per element).

Bounded strings and sequences are not checked against their bound; ``wstring`` fields are
not supported.
"""
from __future__ import annotations

import struct
import threading
from collections.abc import Callable, Mapping
from itertools import chain
from operator import itemgetter

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

HEADER = b"\x00\x01\x00\x00"       # CDR_LE encapsulation, options 0

#: struct codes of the primitive types (``char`` and ``byte`` are uint8 in ROS 2)
_CODES = {"bool": "?", "byte": "B", "char": "B", "int8": "b", "uint8": "B", "int16": "h",
          "uint16": "H", "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q",
          "float32": "f", "float64": "d"}
_PAD = tuple(bytes(i) for i in range(8))
_U32 = struct.Struct("<I").pack


class _Incomplete(Exception):
    """A value the generated fast path does not take (the slow path completes it)."""


def encoder(store: Typestore, msgtype: str) -> Callable[[Mapping | None], bytes]:
    """The CDR encoder of ``msgtype`` (e.g. ``rbe_msgs/msg/StabilityReport``) with the layout
    of ``store``: message dict -> bytes. Made once per store and type, then cached (for the
    life of the process: in practice one store, :func:`rbe_ros.io.bag.typestore`); thread-safe."""
    with _LOCK:
        codecs = _CODECS.get(store)
        if codecs is None:
            codecs = _CODECS[store] = _Codecs(store)
        return codecs.encoder(msgtype)


def encode(store: Typestore, msgtype: str, data: Mapping | None) -> bytes:
    """The CDR bytes of the message dict ``data`` of type ``msgtype`` (see :func:`encoder`)."""
    return encoder(store, msgtype)(data)


_LOCK = threading.Lock()
_CODECS: dict[Typestore, _Codecs] = {}


class _Codecs:
    """The generated encoders of one typestore's types, in one namespace."""

    def __init__(self, store: Typestore):
        self.store = store
        self.encoders: dict[str, Callable] = {}
        self.ns = {"_PAD": _PAD, "_U32": _U32, "_Incomplete": _Incomplete,
                   "complete": self.complete}
        self.count = 0

    # --- fast path: generated code ----------------------------------------------------------

    def encoder(self, msgtype: str) -> Callable[[Mapping | None], bytes]:
        found = self.encoders.get(msgtype)
        if found is None:
            if msgtype not in self.store.fielddefs:
                raise KeyError(f"unknown message type {msgtype!r}")
            write = self._writer(msgtype)

            def found(data: Mapping | None) -> bytes:
                buf = bytearray()
                write(buf, data)
                return HEADER + buf
            self.encoders[msgtype] = found
        return found

    def _writer(self, msgtype: str) -> Callable:
        """The generated ``(buf, value)`` writer of a message type (and of its dependencies)."""
        name = "_enc_" + msgtype.replace("/", "__")
        if name not in self.ns:
            body: list[str] = []
            run: list[tuple[str, str]] = []
            self._fields(msgtype, "v", body, run)
            self._flush(body, run)
            source = "\n".join([
                f"def {name}(buf, v, retry=True):",
                "    start = len(buf)",
                "    try:",
                *(f"        {line}" for line in body),
                "        return",
                "    except Exception:",
                "        if not retry:",
                "            raise",
                "        del buf[start:]",
                f"    {name}(buf, complete({msgtype!r}, v, {msgtype!r}), False)",
                ""])
            exec(compile(source, f"<cdr {msgtype}>", "exec"), self.ns)
        return self.ns[name]

    def _fields(self, msgtype: str, var: str, body: list, run: list) -> None:
        """Lines writing the complete message dict ``var``; nested messages inline, their
        primitives joining the pending ``run`` of (struct code, value expression)."""
        fields = self.store.fielddefs[msgtype][1]
        body.append(f"if len({var}) != {len(fields)}: raise _Incomplete")
        for field, (kind, detail) in fields:
            value = f"{var}[{field!r}]"
            if kind == Nodetype.BASE and detail[0] in _CODES:
                run.append((_CODES[detail[0]], value))
            elif kind == Nodetype.NAME:
                sub = f"m{len(body)}"
                body.append(f"{sub} = {value}")
                self._fields(detail, sub, body, run)
            elif kind == Nodetype.BASE:
                _require_string(detail[0])
                self._flush(body, run)
                body += [f"s = {value}.encode()", *_STRING]
            elif kind == Nodetype.ARRAY and detail[0][0] == Nodetype.BASE \
                    and detail[0][1][0] in _CODES:
                sub = f"a{len(body)}"
                body += [f"{sub} = {value}",
                         f"if len({sub}) != {detail[1]}: raise _Incomplete"]
                run.append((f"{detail[1]}{_CODES[detail[0][1][0]]}", f"*{sub}"))
            else:
                self._flush(body, run)
                body.append(f"{self._add('_h', self._array_writer(kind, detail))}(buf, {value})")

    def _flush(self, body: list, run: list) -> None:
        """One ``struct`` pack of the pending primitives, chosen by the alignment phase."""
        if not run:
            return
        packs = tuple(struct.Struct(_run_format(run, phase)).pack for phase in range(8))
        body.append(f"buf += {self._add('_s', packs)}[len(buf) & 7]"
                    f"({', '.join(v for _, v in run)})")
        run.clear()

    def _add(self, prefix: str, value) -> str:
        """A new global name of the generated code, bound to ``value``."""
        self.count += 1
        self.ns[name := f"{prefix}{self.count}"] = value
        return name

    def _array_writer(self, kind, detail) -> Callable:
        """The ``(buf, value)`` writer of a sequence, or of a fixed array of strings or
        messages."""
        (sub_kind, sub), length = detail
        fixed = length if kind == Nodetype.ARRAY else None
        if sub_kind == Nodetype.BASE and sub[0] in _CODES:
            return _numbers_writer(_CODES[sub[0]])
        if sub_kind == Nodetype.BASE:
            _require_string(sub[0])
            return _strings_writer(fixed)
        uniform = self._uniform(sub)
        if uniform is not None and fixed is None:
            return _rows_writer(*uniform)
        return _messages_writer(self._writer(sub), fixed)

    def _uniform(self, msgtype: str) -> tuple[tuple[str, ...], str] | None:
        """(field names, struct code) of a message whose fields are all of one numeric
        type, else None."""
        fields = self.store.fielddefs[msgtype][1]
        kinds = {detail[0] if kind == Nodetype.BASE else None for _, (kind, detail) in fields}
        if len(kinds) == 1 and (typ := kinds.pop()) in _CODES and typ != "bool":
            return tuple(name for name, _ in fields), _CODES[typ]
        return None

    # --- slow path: complete message dicts --------------------------------------------------

    def complete(self, msgtype: str, value, where: str) -> dict:
        """The complete message dict of ``value`` (missing fields filled in, numbers cast),
        as the generated writers take it; raises naming the field at fault."""
        if value is None:
            value = {}
        if not isinstance(value, Mapping):
            raise TypeError(f"{where}: expected a message dict ({msgtype}), "
                            f"got {type(value).__name__}")
        fields = self.store.fielddefs[msgtype][1]
        names = {name for name, _ in fields}
        for key in value:
            if key not in names:
                raise ValueError(f"{where}: {msgtype} has no field {key!r}")
        return {name: self._complete_value(desc, value.get(name), f"{where}.{name}")
                for name, desc in fields}

    def _complete_value(self, desc, value, where: str):
        kind, detail = desc
        if kind == Nodetype.BASE:
            return _cast(detail[0], value, where)
        if kind == Nodetype.NAME:
            return self.complete(detail, value, where)
        (sub_kind, sub), length = detail
        if isinstance(value, np.ndarray):
            items = self._array_items(sub_kind, sub, value, where)
        elif value is None:
            items = []
        elif isinstance(value, (str, Mapping)) or not hasattr(value, "__iter__"):
            raise TypeError(f"{where}: expected a sequence, got {type(value).__name__}")
        else:
            items = list(value)
        if kind == Nodetype.ARRAY and len(items) != length:
            if items:
                raise ValueError(f"{where}: fixed array needs {length} items, got {len(items)}")
            items = [None] * length
        values = [self._complete_value((sub_kind, sub), v, f"{where}[{i}]")
                  for i, v in enumerate(items)]
        if sub_kind == Nodetype.BASE and sub[0] in _CODES:
            return np.array(values, dtype=_dtype(_CODES[sub[0]]))
        return values

    def _array_items(self, sub_kind, sub, value: np.ndarray, where: str) -> list:
        """The items of a numpy array given for a sequence or array field."""
        if sub_kind == Nodetype.BASE and sub[0] in _CODES:
            if value.ndim != 1:
                raise ValueError(f"{where}: expected a 1-D array, got shape {value.shape}")
            return value.tolist()
        uniform = self._uniform(sub) if sub_kind == Nodetype.NAME else None
        if uniform is None:
            raise TypeError(f"{where}: {sub} items cannot be given as an array")
        names = uniform[0]
        if value.ndim != 2 or value.shape[1] != len(names):
            raise ValueError(f"{where}: expected an (n, {len(names)}) array of {sub} field "
                             f"values, got shape {value.shape}")
        return [dict(zip(names, row)) for row in value.tolist()]


# --- generated-code helpers -------------------------------------------------------------------

def _run_format(run: list[tuple[str, str]], phase: int) -> str:
    """The struct format of a run of primitives starting at offset ``phase`` (mod 8): each
    aligned to its size, with explicit zero pad bytes."""
    fmt, offset = "<", phase
    for code, _ in run:
        count, size = int(code[:-1] or 1), struct.calcsize(code[-1])
        pad = -offset % min(size, 8)
        fmt += "x" * pad + code
        offset += pad + count * size
    return fmt


#: the lines writing the UTF-8 bytes ``s`` of a string; it ends at a NUL, as rclpy's C
#: strings do
_STRING = ["if 0 in s: s = s[:s.index(0)]", "buf += _PAD[-len(buf) & 3]",
           "buf += _U32(len(s) + 1)", "buf += s", "buf += b'\\x00'"]


def _require_string(typ: str) -> None:
    if typ != "string":
        raise TypeError(f"CDR encoding of {typ} fields is not supported")


def _dtype(code: str) -> np.dtype:
    return np.dtype("<" + code)


def _numbers_writer(code: str) -> Callable:
    """Writer of a sequence of primitives: a 1-D array (one ``tobytes``), or numbers."""
    dtype, size = _dtype(code), struct.calcsize(code)
    align = min(size, 8) - 1

    def write(buf: bytearray, values) -> None:
        if isinstance(values, np.ndarray):
            data = _array_bytes(values, (), dtype)
        elif code == "B" and isinstance(values, (bytes, bytearray)):
            data = bytes(values)
        else:
            data = struct.pack(f"<{len(values)}{code}", *values)
        buf += _PAD[-len(buf) & 3]
        buf += _U32(len(data) // size)
        if data:
            buf += _PAD[-len(buf) & align]
            buf += data
    return write


def _length(buf: bytearray, items, fixed: int | None) -> None:
    """The count of a sequence; none for a fixed array, whose length must be ``fixed``."""
    if fixed is None:
        buf += _PAD[-len(buf) & 3]
        buf += _U32(len(items))
    elif len(items) != fixed:
        raise _Incomplete


def _strings_writer(fixed: int | None) -> Callable:
    def write(buf: bytearray, values) -> None:
        _length(buf, values, fixed)
        for s in values:
            s = s.encode()
            if 0 in s:
                s = s[:s.index(0)]
            buf += _PAD[-len(buf) & 3]
            buf += _U32(len(s) + 1)
            buf += s
            buf += b"\x00"
    return write


def _rows_writer(names: tuple[str, ...], code: str) -> Callable:
    """Writer of a sequence of messages of ``len(names)`` fields of one type: an (n, k) array
    of field values (one ``tobytes``), or message dicts with exactly those keys."""
    k, dtype, size = len(names), _dtype(code), struct.calcsize(code)
    align = min(size, 8) - 1
    get = itemgetter(*names) if k > 1 else (lambda item: (item[names[0]],))

    def write(buf: bytearray, items) -> None:
        n = len(items)
        if isinstance(items, np.ndarray):
            data = _array_bytes(items, (k,), dtype)
        else:
            # every dict has the k keys (else KeyError) and k keys in all: exactly those
            if sum(map(len, items)) != k * n:
                raise _Incomplete
            data = struct.pack(f"<{k * n}{code}", *chain.from_iterable(map(get, items)))
        buf += _PAD[-len(buf) & 3]
        buf += _U32(n)
        if n:
            buf += _PAD[-len(buf) & align]
            buf += data
    return write


def _array_bytes(values: np.ndarray, row: tuple, dtype: np.dtype) -> bytes:
    """The bytes of an array of shape ``(n, *row)`` as ``dtype``; an array of another
    shape, or one numpy cannot cast safely, is left to the slow path."""
    if values.ndim != len(row) + 1 or values.shape[1:] != row:
        raise _Incomplete
    if values.dtype is not dtype:
        if not np.can_cast(values.dtype, dtype):
            raise _Incomplete
        values = values.astype(dtype)
    return values.tobytes()


def _messages_writer(write_item: Callable, fixed: int | None) -> Callable:
    def write(buf: bytearray, items) -> None:
        _length(buf, items, fixed)
        for item in items:
            write_item(buf, item)
    return write


# --- slow-path casts --------------------------------------------------------------------------

_CASTS = {"bool": bool, "float32": float, "float64": float}


def _cast(typ: str, value, where: str):
    """``value`` cast to the primitive or string type ``typ`` (None: its zero value)."""
    if typ == "string":
        return "" if value is None else str(value)
    code = _CODES[typ]
    if value is None:
        value = 0
    elif code == "B" and isinstance(value, (bytes, bytearray)) and len(value) == 1:
        value = value[0]        # an rclpy byte field
    try:
        cast = _CASTS.get(typ, int)(value)
        struct.pack("<" + code, cast)       # in range, as the fast path needs it
    except TypeError as exc:
        raise TypeError(f"{where}: {value!r} is not a {typ}: {exc}") from None
    except (ValueError, OverflowError, struct.error) as exc:
        raise ValueError(f"{where}: {value!r} is not a valid {typ}: {exc}") from None
    return cast


_FORMATS = {"float64": "d", "float32": "f", "int8": "b", "uint8": "B", "int16": "h",
            "uint16": "H", "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q"}


class Repeats:
    """CDR of messages that repeat the last one but for the header stamp and some top-level
    numbers (a report's ``solve_time`` and ``dropped_states``): encoded and decoded by
    patching or reading those bytes instead of a pass over the whole message (a session's
    report of an unchanged 300-block wall, about 1 MB, again and again). Where each number
    lies is found by encoding the message with it changed; a message this encoder does not
    make byte for byte (another writer's) is never patched."""

    def __init__(self, store: Typestore, msgtype: str, fields: tuple[str, ...]):
        self.encode_full = encoder(store, msgtype)
        types = dict(store.fielddefs[msgtype][1])
        self.formats = {f: _FORMATS[types[f][1][0]] for f in fields}
        self.last: tuple[Mapping, bytes, dict[str, int]] | None = None

    def learn(self, data: Mapping, raw: bytes) -> None:
        """Take ``data`` and its CDR ``raw`` as the message the next ones may repeat."""
        self.last = None
        if len(raw) < 12 or raw[:4] != HEADER or self.encode_full(data) != raw:
            return
        offsets = {}
        for name, code in self.formats.items():
            value = data[name]
            other = self.encode_full({**data, name: value + 1.0 if isinstance(value, float)
                                      else value ^ 1})
            if len(other) != len(raw):
                return
            changed = np.flatnonzero(np.frombuffer(raw, np.uint8) !=
                                     np.frombuffer(other, np.uint8))
            if not len(changed):
                return
            width = struct.calcsize(code)
            start = 4 + (int(changed[0]) - 4) // width * width
            if int(changed[-1]) >= start + width:
                return
            offsets[name] = start
        self.last = (data, raw, offsets)

    def _repeats(self, data: Mapping) -> bool:
        """Whether ``data`` is the last message but for the stamp and the fields."""
        known = self.last[0]
        try:
            return len(data) == len(known) and \
                data["header"]["frame_id"] == known["header"]["frame_id"] and all(
                    k in known and bool(data[k] == known[k]) for k in data
                    if k != "header" and k not in self.formats)
        except ValueError:          # arrays: not compared here, encoded in full
            return False

    def _spans(self) -> list[tuple[int, int]]:
        """The byte ranges a repeat may differ in: the stamp and the fields."""
        return sorted([(4, 12)] + [(o, o + struct.calcsize(self.formats[n]))
                                   for n, o in self.last[2].items()])

    def decode(self, raw: bytes) -> dict | None:
        """The message dict of ``raw`` if it repeats the last message (else None)."""
        if self.last is None or len(raw) != len(self.last[1]):
            return None
        data, known, offsets = self.last
        cut = 0
        for a, b in self._spans():
            if raw[cut:a] != known[cut:a]:
                return None
            cut = b
        if raw[cut:] != known[cut:]:
            return None
        sec, nanosec = struct.unpack_from("<iI", raw, 4)
        values = {n: struct.unpack_from("<" + self.formats[n], raw, o)[0]
                  for n, o in offsets.items()}
        return {**data, **values, "header": {**data["header"],
                                             "stamp": {"sec": sec, "nanosec": nanosec}}}

    def encode(self, data: Mapping) -> bytes:
        """The CDR of ``data``: the last message's bytes patched where it repeats it."""
        if self.last is not None and self._repeats(data):
            _, known, offsets = self.last
            out = bytearray(known)
            stamp = data["header"]["stamp"]
            struct.pack_into("<iI", out, 4, int(stamp["sec"]), int(stamp["nanosec"]))
            for n, o in offsets.items():
                struct.pack_into("<" + self.formats[n], out, o, data[n])
            return bytes(out)
        raw = self.encode_full(data)
        self.learn(data, raw)
        return raw


__all__ = ["HEADER", "Repeats", "encode", "encoder"]
