"""Fast CDR for messages of a fixed layout: patch a few fields into a preallocated buffer.

A contract message the loop sends every sample keeps its layout from sample to sample: the same
``frame_id``, the same joint names, the same sequence lengths; only the stamp and a few numbers
change. :class:`CdrLayout` computes, from one ``rosbags`` message instance, the byte offset of every
numeric field in its little-endian CDR (the rules of ``rosbags``' serializer: the 4-byte
encapsulation header, then each primitive aligned to its size relative to the end of the header,
strings and sequences as a ``uint32`` length before their elements). :class:`FixedWriter` keeps the
serialized message in a ``bytearray`` and writes the changing fields with one
``struct.pack_into``; :class:`FixedReader` reads them with one ``struct.unpack_from`` after checking
that the bytes have the same layout (else the caller decodes with ``rosbags``). Both are checked
byte for byte against ``rosbags`` (``tests/unit/contract/test_fixed_cdr.py``).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any

from rosbags.typesys.base import Nodetype

from stillframe.contract import messages

HEADER_BYTES = 4
#: struct code of each numeric ROS primitive in arrays and sequences (numpy's dtypes in
#: ``rosbags``); a scalar ``byte`` is signed, as ``rosbags`` packs it
SCALAR_BYTE = "b"
CODES = {"bool": "?", "byte": "B", "char": "B", "int8": "b", "uint8": "B", "int16": "h",
         "uint16": "H", "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q",
         "float32": "f", "float64": "d"}


class CdrLayout:
    """Offsets in the CDR of one message instance: ``fields[path] = (offset, code, count)`` for
    every numeric field (``header.stamp.sec``, ``position`` for a whole float64 sequence,
    ``orientation_covariance`` for an array), and ``fixed_spans``, the (start, end) of its
    strings and sequence lengths: bytes that fix where everything after them lies (adjacent
    spans merged)."""

    def __init__(self, msg: Any) -> None:
        self.template = messages.serialize(msg)
        self.fields: dict[str, tuple[int, str, int]] = {}
        self.fixed_spans: list[tuple[int, int]] = []
        self.pos = HEADER_BYTES
        self._message(msg, msg.__msgtype__, "")
        if self.pos != len(self.template):
            raise AssertionError(f"{msg.__msgtype__}: layout ends at {self.pos}, "
                                 f"rosbags wrote {len(self.template)} bytes")

    def _align(self, size: int) -> None:
        self.pos += -(self.pos - HEADER_BYTES) % size

    def _fixed(self, size: int) -> None:
        """``size`` bytes at the (aligned) position fix the layout."""
        self._align(4)
        if self.fixed_spans and self.fixed_spans[-1][1] == self.pos:
            self.fixed_spans[-1] = (self.fixed_spans[-1][0], self.pos + size)
        else:
            self.fixed_spans.append((self.pos, self.pos + size))
        self.pos += size

    def _message(self, msg: Any, type_name: str, prefix: str) -> None:
        for name, desc in messages.fielddefs(type_name):
            self._value(getattr(msg, name), desc, prefix + name)

    def _value(self, value: Any, desc: tuple[Nodetype, Any], path: str) -> None:
        kind, detail = desc
        if kind == Nodetype.NAME:
            self._message(value, detail, path + ".")
        elif kind == Nodetype.BASE:
            if detail[0] == "string":
                self._fixed(4 + len(value.encode()) + 1)
            else:
                self._numbers(detail[0], 1, path, scalar=True)
        else:
            sub, _ = detail
            if kind == Nodetype.SEQUENCE:
                self._fixed(4)
            if sub[0] == Nodetype.BASE and sub[1][0] != "string":
                if len(value):
                    self._numbers(sub[1][0], len(value), path)
            else:
                for i, item in enumerate(value):
                    self._value(item, sub, f"{path}[{i}]")

    def _numbers(self, prim: str, count: int, path: str, scalar: bool = False) -> None:
        code = SCALAR_BYTE if scalar and prim == "byte" else CODES[prim]
        size = struct.calcsize(code)
        self._align(size)
        self.fields[path] = (self.pos, code, count)
        self.pos += size * count


def _runs(layout: CdrLayout, paths: Sequence[str]) -> list[tuple[int, str, int]]:
    """``paths`` as runs of adjacent fields: (offset, struct format, number of values)."""
    runs: list[tuple[int, str, int]] = []
    end = -1
    for path in paths:
        offset, code, count = layout.fields[path]
        if offset < end:
            raise ValueError(f"fields {list(paths)} must be given in the order of the message")
        if offset == end:
            start, fmt, n = runs.pop()
            runs.append((start, fmt + f"{count}{code}", n + count))
        else:
            runs.append((offset, f"<{count}{code}", count))
        end = offset + struct.calcsize(code) * count
    return runs


class FixedWriter:
    """CDR of ``template`` (a ``rosbags`` message) with the fields ``paths`` rewritten per call.

    ``pack(*values)`` takes one value per scalar field and ``count`` values per array field, in
    the order of ``paths`` (which must follow the message's field order), and returns the
    buffer, padded to 4 bytes as Cyclone expects; the next call rewrites it. Every other field
    keeps the template's value.
    """

    def __init__(self, template: Any, paths: Sequence[str]) -> None:
        layout = CdrLayout(template)
        self.buffer = bytearray(layout.template + b"\0" * (-len(layout.template) % 4))
        self._runs = []
        first = 0
        for offset, fmt, n in _runs(layout, paths):
            self._runs.append((struct.Struct(fmt).pack_into, offset, first, first + n))
            first += n
        self.count = first

    def pack(self, *values: Any) -> bytearray:
        """Write ``values`` (in the layout's field order) into the preallocated buffer and return
        it; the buffer is reused, so publish it before the next pack."""
        buffer = self.buffer
        for pack_into, offset, first, last in self._runs:
            pack_into(buffer, offset, *values[first:last])
        return buffer


class FixedReader:
    """The fields ``paths`` of CDR bytes that have the layout of ``template``.

    ``unpack(data)`` returns their values as a flat tuple (in the order of ``paths``, arrays
    expanded), or None when ``data`` has another layout or other strings (other names, other
    sequence lengths, another size): then decode it with ``rosbags``.
    """

    def __init__(self, template: Any, paths: Sequence[str]) -> None:
        layout = CdrLayout(template)
        self.size = len(layout.template)
        self._fixed = [(a, b, layout.template[a:b]) for a, b in layout.fixed_spans]
        runs = _runs(layout, paths)
        start = runs[0][0]
        fmt, end = "<", start
        for offset, run_fmt, _ in runs:
            fmt += (f"{offset - end}x" if offset > end else "") + run_fmt[1:]
            end = offset + struct.calcsize(run_fmt)
        self._unpack_from = struct.Struct(fmt).unpack_from
        self._start = start

    def unpack(self, data: bytes | bytearray | memoryview) -> tuple[Any, ...] | None:
        """The field values of ``data``, or None when it is not this layout (size, encapsulation or
        a fixed part such as the frame id differ), so that the caller decodes it in full."""
        # little-endian CDR (the options bytes after it may carry the padding, as Fast DDS sets)
        if not self.size <= len(data) <= self.size + 3 or data[:2] != b"\0\x01":
            return None
        for start, end, fixed in self._fixed:
            if data[start:end] != fixed:
                return None
        return self._unpack_from(data, self._start)
