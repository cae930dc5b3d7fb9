# Copyright 2026 The mv3dpose_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
CDR (the DDS wire format of ROS 2 messages) read and written by hand, for the fast codecs.

The message codecs (``messages``: ``Person2DArray`` in, ``TrackedSkeletonArray`` out;
``images``: ``Image`` / ``CompressedImage`` in; ``markers``: ``MarkerArray`` out; ``frames``:
``PoseArray`` out) skip rclpy's one Python object per point or keypoint by reading and writing
the bytes directly. This module is the one place that knows the format:

- a 4-byte encapsulation header (byte 1: the kind, odd = little endian), then the body;
- alignment counts from the body start (byte 4): a value of n bytes starts at a multiple of n;
- a string is a uint32 length (with its NUL), the UTF-8 bytes, a NUL;
- a sequence is a uint32 count, then its elements (each aligned as its first member);
- ``std_msgs/Header`` is ``int32 sec, uint32 nanosec, string frame_id``.

``CdrReader`` reads as rclpy (rmw_fastrtps and the generated C type support) does, quirks
included; ``CdrWriter`` writes little-endian plain CDR with zero padding, what rosbags writes
and rclpy reads (rclpy's own padding bytes are left uninitialised, so only the values compare).
"""

import functools
import struct
from typing import Any, Dict, Tuple, Union

import numpy as np

#: std_msgs/Header's stamp, little endian (builtin_interfaces/Time: int32 sec, uint32 nanosec)
STAMP = struct.Struct('<iI')
#: a sequence count or string length, little endian
U32 = struct.Struct('<I')


class CdrError(ValueError):
    """Bytes that are no valid CDR of the expected type; the text says where and why."""


class Encapsulations(dict):
    """Encapsulation kinds (byte 1) a reader accepts -> struct byte order, with their name."""

    def __init__(self, orders: Dict[int, str], name: str) -> None:
        super().__init__(orders)
        self.name = name


# rmw_fastrtps reads CDR, PL_CDR, CDR2, D_CDR2 and PL_CDR2 (even = big endian, odd = little
# endian). Its generated type support reads a body without 8-byte members, parameter lists or
# delimiters the same way under each; the two option bytes are ignored; kinds 4, 5, >= 12 fail.
ANY_CDR = Encapsulations({0: '>', 1: '<', 2: '>', 3: '<', 6: '>', 7: '<', 8: '>', 9: '<',
                          10: '>', 11: '<'}, 'CDR, PL_CDR or XCDR2 (00 00..03, 00 06..0b)')
#: plain CDR only (what every ROS 2 publisher of Jazzy sends)
PLAIN_CDR = Encapsulations({0: '>', 1: '<'}, 'plain CDR (00 00 or 00 01)')


class CdrReader:
    """
    Read a serialised message front to back, as rclpy's type support reads it.

    ``pos`` is the offset of the next value in the buffer (the encapsulation header included);
    every read aligns first. Formats are ``struct`` formats without a byte order (the
    encapsulation gives it), explicit padding inside them. Truncation raises ``CdrError``.
    """

    __slots__ = ('buf', 'size', 'order', 'pos', '_structs', '_u32')
    _ORDERS: Dict[str, Dict[str, struct.Struct]] = {o: {'I': struct.Struct(o + 'I')}
                                                    for o in '<>'}

    def __init__(self, data: Union[bytes, bytearray, memoryview],
                 kinds: Encapsulations = ANY_CDR) -> None:
        """Check the encapsulation header of ``data``; ``CdrError`` if ``kinds`` lacks it."""
        buf = memoryview(data).cast('B')
        order = kinds.get(buf[1]) if len(buf) >= 4 and buf[0] == 0 else None
        if order is None:
            raise CdrError(f'{len(buf)} bytes with encapsulation '
                           f'{bytes(buf[:4]).hex() or "none"}, expected {kinds.name}')
        self.buf = buf
        self.size = len(buf)
        self.order = order
        self.pos = 4
        self._structs = self._ORDERS[order]
        self._u32 = self._structs['I']

    @property
    def remaining(self) -> int:
        """Bytes after ``pos``."""
        return self.size - self.pos

    def unpack(self, fmt: str, align: int = 4) -> Tuple[Any, ...]:
        """Align, then read the values of ``fmt`` (e.g. ``'iI'``)."""
        compiled = self._structs.get(fmt)
        if compiled is None:
            compiled = self._structs[fmt] = struct.Struct(self.order + fmt)
        pos = self.pos + -(self.pos - 4) % align
        try:
            values = compiled.unpack_from(self.buf, pos)
        except struct.error as exc:
            raise self._truncated(exc) from None
        self.pos = pos + compiled.size
        return values

    def u32(self) -> int:
        """Read a ``uint32`` (a sequence count or a string length); ``unpack('I')``, faster."""
        pos = self.pos + -self.pos % 4
        try:
            (value,) = self._u32.unpack_from(self.buf, pos)
        except struct.error as exc:
            raise self._truncated(exc) from None
        self.pos = pos + 4
        return value

    def _truncated(self, exc: struct.error) -> CdrError:
        return CdrError(f'truncated ({self.size} bytes): {exc}')

    def string(self) -> str:
        """
        Read a string as rclpy does.

        Fast CDR drops one terminating NUL if there is one (none is required), the C message
        keeps the text up to its first NUL, and Python decodes it as UTF-8 with U+FFFD for
        invalid bytes. A length running past the end raises ``CdrError``.
        """
        n = self.u32()
        if n == 0:
            return ''
        pos = self.pos
        end = pos + n
        if end > self.size:
            raise CdrError(f'string of {n} bytes at offset {pos} runs past the end '
                           f'({self.size} bytes)')
        raw = bytes(self.buf[pos:end])
        nul = raw.find(0)
        if nul >= 0:
            raw = raw[:nul]
        self.pos = end
        return raw.decode('utf-8', 'replace')

    def header(self) -> Tuple[int, int, str]:
        """Read a ``std_msgs/Header``: ``(sec, nanosec, frame_id)``."""
        sec, nanosec = self.unpack('iI')
        return sec, nanosec, self.string()

    def take(self, n: int) -> memoryview:
        """Return the next ``n`` bytes as a view (no copy); ``CdrError`` if fewer are left."""
        if n > self.size - self.pos:
            raise CdrError(f'{n} bytes declared at offset {self.pos}, {self.size - self.pos} '
                           'present')
        view = self.buf[self.pos:self.pos + n]
        self.pos += n
        return view


@functools.lru_cache(maxsize=4096)
def _strings(texts: Tuple[str, ...], sequence: bool) -> bytes:
    """Return CDR strings (after their count if ``sequence``) as written from a 4-aligned start."""
    out = bytearray()
    if sequence:
        out += U32.pack(len(texts))
    for text in texts:
        out += bytes(-len(out) % 4)
        data = text.encode('utf-8')
        out += U32.pack(len(data) + 1)
        out += data
        out += b'\x00'
    return bytes(out)


class CdrWriter:
    """
    Little-endian plain CDR written straight from Python values and numpy arrays.

    For outputs published as bytes (``Publisher.publish(bytes)``), which skips building one
    Python message object per point or joint and rclpy's conversion of them. Alignment counts
    from the payload start, after the 4-byte encapsulation header, as rmw_fastrtps does;
    padding is zeros.
    """

    def __init__(self) -> None:
        self.buf = bytearray(b'\x00\x01\x00\x00')    # plain CDR, little endian

    def align(self, n: int) -> None:
        """Pad to a multiple of ``n`` bytes from the payload start."""
        self.buf += bytes(-(len(self.buf) - 4) % n)

    def pack(self, fmt: struct.Struct, *values: Any, align: int = 4) -> None:
        """Align, then write ``values`` with ``fmt`` (explicit padding inside the format)."""
        self.buf += bytes(-(len(self.buf) - 4) % align)
        self.buf += fmt.pack(*values)

    def raw(self, data: Union[bytes, memoryview], align: int = 1) -> None:
        """Align, then write ``data`` as it is (already serialised members)."""
        self.buf += bytes(-(len(self.buf) - 4) % align)
        self.buf += data

    def strings(self, texts: Tuple[str, ...], sequence: bool = True) -> None:
        """Write strings back to back (a ``string[]`` with its count when ``sequence``)."""
        self.buf += bytes(-(len(self.buf) - 4) % 4)
        self.buf += _strings(tuple(texts), sequence)

    def header(self, header: Any, *texts: str) -> None:
        """Write a ``std_msgs/Header`` (stamp, frame_id), then the strings ``texts``."""
        stamp = header.stamp
        self.pack(STAMP, stamp.sec, stamp.nanosec)
        self.strings((header.frame_id, *texts), sequence=False)

    def sequence(self, records: np.ndarray, align: int) -> None:
        """
        Write a sequence: its count, then ``records`` (a little-endian array, one per element).

        Elements start at a multiple of ``align``; a record dtype must hold the element's
        padding (its size a multiple of its alignment), as the joints of ``tracks_to_cdr`` do.
        """
        self.pack(U32, len(records))
        if len(records):
            self.raw(memoryview(np.ascontiguousarray(records)).cast('B'), align)

    def getvalue(self) -> bytes:
        """Return the serialised message."""
        return bytes(self.buf)

    def body(self) -> bytes:
        """Return what was written without the encapsulation header (members to splice in)."""
        return bytes(self.buf[4:])
