"""The Zenoh attachment every omninav publisher sends: seq, stamp and type without decoding the payload.

Layout: little-endian uint64 seq, int64 stamp_ns, then the message type name in UTF-8. Recorders and
tools read it to stay fast; payloads without it (foreign publishers) are still accepted.
"""
from __future__ import annotations

import struct
from typing import NamedTuple

_HEAD = struct.Struct("<Qq")


class Envelope(NamedTuple):
    seq: int
    stamp_ns: int
    type_name: str


def pack_attachment(seq: int, stamp_ns: int, type_name: str) -> bytes:
    return _HEAD.pack(seq, stamp_ns) + type_name.encode()


def unpack_attachment(data: bytes | None) -> Envelope | None:
    """The envelope, or None when the attachment is absent or not ours."""
    if not data or len(data) <= _HEAD.size:
        return None
    seq, stamp = _HEAD.unpack_from(data)
    try:
        name = data[_HEAD.size:].decode()
    except UnicodeDecodeError:
        return None
    return Envelope(seq, stamp, name)
