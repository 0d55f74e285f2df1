"""MCAP files of omninav messages: one channel per key, the type's JSON schema attached.

Per message: log_time is the wall time it was received (what live replay paces by), publish_time
is its sim stamp (what deterministic replay orders by), sequence is the publisher's header seq.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Iterable, Iterator

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap.writer import CompressionType, Writer

from ...schemas.codec import describe
from ...schemas.registry import by_name

MESSAGE_ENCODING = "msgpack"
SCHEMA_ENCODING = "jsonschema"
PROFILE = "omninav"
_U32 = 0xFFFFFFFF


@dataclass(frozen=True, slots=True)
class Record:
    key: str
    type_name: str
    payload: bytes
    seq: int
    stamp_ns: int
    log_time_ns: int


class RecordingWriter:
    """Writes Records; small zstd chunks plus flush() bound what a SIGKILL can lose."""

    def __init__(self, path: str | Path, *, chunk_size: int = 256 * 1024, metadata: dict[str, str] | None = None):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: BinaryIO = open(self.path, "wb")
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="omninav")
        if metadata:
            self._writer.add_metadata("omninav", {k: str(v) for k, v in metadata.items()})
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.count = 0
        self.bytes = 0

    def _channel(self, key: str, type_name: str) -> int:
        channel = self._channels.get(key)
        if channel is None:
            schema = self._schemas.get(type_name)
            if schema is None:
                cls = by_name(type_name)
                data = json.dumps(describe(cls)).encode() if cls else b""
                schema = self._writer.register_schema(type_name or "unknown", SCHEMA_ENCODING if cls else "", data)
                self._schemas[type_name] = schema
            channel = self._writer.register_channel(key, MESSAGE_ENCODING, schema, {"type": type_name})
            self._channels[key] = channel
        return channel

    def write(self, key: str, type_name: str, payload: bytes, seq: int, stamp_ns: int, log_time_ns: int) -> None:
        self._writer.add_message(self._channel(key, type_name), log_time=log_time_ns, data=payload,
                                 publish_time=max(0, stamp_ns), sequence=seq & _U32)
        self.count += 1
        self.bytes += len(payload)

    def write_record(self, rec: Record) -> None:
        self.write(rec.key, rec.type_name, rec.payload, rec.seq, rec.stamp_ns, rec.log_time_ns)

    def flush(self) -> None:
        """Close the open chunk and push it to the OS, so a killed process loses nothing before now."""
        self._writer.flush()
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self._writer.finish()
            self._file.close()

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _records(reader, keys: Iterable[str] | None) -> Iterator[Record]:
    wanted = set(keys) if keys is not None else None
    for schema, channel, message in reader.iter_messages(
            topics=list(wanted) if wanted is not None else None, log_time_order=False):
        yield Record(channel.topic, channel.metadata.get("type") or (schema.name if schema else ""),
                     message.data, message.sequence, message.publish_time, message.log_time)


def read_records(path: str | Path, keys: Iterable[str] | None = None) -> Iterator[Record]:
    """Every message of a finished recording, in file order (raises McapError on a damaged file)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such recording")
    with open(path, "rb") as f:
        yield from _records(make_reader(f), keys)


def read_readable_records(path: str | Path) -> tuple[list[Record], str | None]:
    """What can be read of a possibly damaged recording, and why reading stopped (None if it did not)."""
    out: list[Record] = []
    with open(path, "rb") as f:
        try:
            for rec in _records(NonSeekingReader(f, validate_crcs=True), None):
                out.append(rec)
        except (McapError, EOFError, ValueError, KeyError, OSError) as exc:  # truncated or corrupt tail
            return out, f"{type(exc).__name__}: {exc}"
    return out, None
