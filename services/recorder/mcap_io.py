"""MCAP files of omninav messages: one channel per key, the type's JSON schema attached.

Per message: log_time is the wall time it was received (what live replay paces by), publish_time
is its sim stamp (what deterministic replay orders by), sequence is the publisher's header seq.
"""
from __future__ import annotations

import json
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Iterable, Iterator

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.reader import NonSeekingReader, make_reader
from mcap.summary import Summary
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, McapRecord, Metadata,
                          MetadataIndex, Schema, Statistics, SummaryOffset)

from ...schemas.codec import describe
from ...schemas.registry import by_name

MESSAGE_ENCODING = "msgpack"
SCHEMA_ENCODING = "jsonschema"
PROFILE = "omninav"
MAGIC = b"\x89MCAP0\r\n"
_U32 = 0xFFFFFFFF
# a Message record: opcode, record length, channel id, sequence, log_time, publish_time, then the data
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_MESSAGE_FIXED = 2 + 4 + 8 + 8
_MESSAGE_INDEX_HEAD = struct.Struct("<BQHI")
_FOOTER_HEAD = struct.Struct("<BQQQ")


@dataclass(frozen=True, slots=True)
class Record:
    key: str
    type_name: str
    payload: bytes
    seq: int
    stamp_ns: int
    log_time_ns: int


def _record_bytes(record: McapRecord) -> bytes:
    builder = RecordBuilder()
    record.write(builder)
    return builder.end()


class RecordingWriter:
    """Writes Records; small zstd chunks plus flush() bound what a SIGKILL can lose.

    The layout is the one mcap's reference Writer produces (schema and channel records inside the
    chunk that first uses them, message indexes after each chunk, a summary with statistics and
    chunk indexes), but each message costs one struct.pack here: the reference Writer spends about
    5 us per message, which alone would hold a recorder near 100k messages/s.
    """

    def __init__(self, path: str | Path, *, chunk_size: int = 256 * 1024, metadata: dict[str, str] | None = None):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: BinaryIO = open(self.path, "wb")
        self._chunk_size = chunk_size
        self._compressor = zstandard.ZstdCompressor()
        self._schemas: dict[str, Schema] = {}
        self._channels: dict[str, Channel] = {}
        # key -> (channel id, [log_time, offset, log_time, offset, ...] of its messages in the open chunk)
        self._index: dict[str, tuple[int, list[int]]] = {}
        self._message_counts: dict[int, int] = {}
        self._chunk = bytearray()
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._start_time = self._end_time = 0
        self.count = 0
        self.bytes = 0
        self._file.write(MAGIC)
        self._file.write(_record_bytes(Header(profile=PROFILE, library="omninav")))
        if metadata:
            offset = self._file.tell()
            data = _record_bytes(Metadata(name="omninav", metadata={k: str(v) for k, v in metadata.items()}))
            self._file.write(data)
            self._metadata_indexes.append(MetadataIndex(offset=offset, length=len(data), name="omninav"))

    @property
    def file_bytes(self) -> int:
        """Bytes written to the file so far (the open chunk not included)."""
        return self._file.tell()

    def _register(self, key: str, type_name: str) -> tuple[int, list[int]]:
        schema = self._schemas.get(type_name)
        if schema is None:
            cls = by_name(type_name)
            schema = Schema(id=len(self._schemas) + 1, name=type_name or "unknown",
                            encoding=SCHEMA_ENCODING if cls else "",
                            data=json.dumps(describe(cls)).encode() if cls else b"")
            self._schemas[type_name] = schema
            self._chunk += _record_bytes(schema)
        channel = Channel(id=len(self._channels) + 1, topic=key, message_encoding=MESSAGE_ENCODING,
                          schema_id=schema.id, metadata={"type": type_name})
        self._channels[key] = channel
        self._message_counts[channel.id] = 0
        self._chunk += _record_bytes(channel)
        entry = self._index[key] = (channel.id, [])
        return entry

    def write(self, key: str, type_name: str, payload: bytes, seq: int, stamp_ns: int, log_time_ns: int) -> None:
        # the hot path of the recorder: keep it to a few operations per message
        channel, index = self._index.get(key) or self._register(key, type_name)
        chunk = self._chunk
        index += (log_time_ns, len(chunk))
        chunk += _MESSAGE_HEAD.pack(Opcode.MESSAGE, _MESSAGE_FIXED + len(payload), channel, seq & _U32,
                                    log_time_ns, max(0, stamp_ns))
        chunk += payload
        self.count += 1
        self.bytes += len(payload)
        if len(chunk) >= self._chunk_size:
            self._finish_chunk()

    def write_record(self, rec: Record) -> None:
        self.write(rec.key, rec.type_name, rec.payload, rec.seq, rec.stamp_ns, rec.log_time_ns)

    def _finish_chunk(self) -> None:
        indexed = [(channel, entries) for channel, entries in self._index.values() if entries]
        if not indexed:
            return
        times = [t for _, entries in indexed for t in entries[::2]]
        start, end = min(times), max(times)
        data = bytes(self._chunk)
        compressed = self._compressor.compress(data)
        chunk_offset = self._file.tell()
        chunk_record = _record_bytes(Chunk(compression="zstd", data=compressed, message_start_time=start,
                                           message_end_time=end, uncompressed_crc=zlib.crc32(data),
                                           uncompressed_size=len(data)))
        index_offsets, index_records = {}, []
        position = chunk_offset + len(chunk_record)
        for channel, entries in indexed:
            body = struct.pack(f"<{len(entries)}Q", *entries)
            record = _MESSAGE_INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 2 + 4 + len(body), channel, len(body)) + body
            index_offsets[channel] = position
            position += len(record)
            index_records.append(record)
            self._message_counts[channel] += len(entries) // 2
            entries.clear()
        self._file.write(chunk_record)
        self._file.write(b"".join(index_records))
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start, message_end_time=end, chunk_start_offset=chunk_offset,
            chunk_length=len(chunk_record), message_index_offsets=index_offsets,
            message_index_length=position - chunk_offset - len(chunk_record), compression="zstd",
            compressed_size=len(compressed), uncompressed_size=len(data)))
        first = len(self._chunk_indexes) == 1
        self._start_time = start if first else min(self._start_time, start)
        self._end_time = end if first else max(self._end_time, end)
        self._chunk = bytearray()

    def flush(self) -> None:
        """Close the open chunk and push it to the OS, so a killed process loses nothing before now."""
        self._finish_chunk()
        self._file.flush()

    def _summary(self, summary_start: int) -> tuple[bytes, int]:
        """The summary section (schemas, channels, statistics, indexes, then their offsets)."""
        groups = [
            (Opcode.SCHEMA, list(self._schemas.values())),
            (Opcode.CHANNEL, list(self._channels.values())),
            (Opcode.STATISTICS, [Statistics(
                message_count=self.count, schema_count=len(self._schemas), channel_count=len(self._channels),
                attachment_count=0, metadata_count=len(self._metadata_indexes),
                chunk_count=len(self._chunk_indexes), message_start_time=self._start_time,
                message_end_time=self._end_time, channel_message_counts=dict(self._message_counts))]),
            (Opcode.CHUNK_INDEX, self._chunk_indexes),
            (Opcode.METADATA_INDEX, self._metadata_indexes),
        ]
        body, offsets = bytearray(), bytearray()
        for opcode, records in groups:
            if records:
                start = len(body)
                for record in records:
                    body += _record_bytes(record)
                offsets += _record_bytes(SummaryOffset(group_opcode=opcode, group_start=summary_start + start,
                                                       group_length=len(body) - start))
        return bytes(body + offsets), summary_start + len(body)

    def close(self) -> None:
        if self._file.closed:
            return
        self._finish_chunk()
        self._file.write(_record_bytes(DataEnd(data_section_crc=0)))
        summary_start = self._file.tell()
        summary, offsets_start = self._summary(summary_start)
        footer_head = _FOOTER_HEAD.pack(Opcode.FOOTER, 8 + 8 + 4, summary_start, offsets_start)
        self._file.write(summary)
        self._file.write(_record_bytes(Footer(summary_start=summary_start, summary_offset_start=offsets_start,
                                              summary_crc=zlib.crc32(footer_head, zlib.crc32(summary)))))
        self._file.write(MAGIC)
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


def check_mcap_file(path: str | Path) -> Path:
    """The path, if it names an existing file that starts like an MCAP file (FileNotFoundError, McapError)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such recording")
    with open(path, "rb") as f:
        if f.read(len(MAGIC)) != MAGIC:
            raise McapError(f"{path}: not an MCAP file (it does not start with the MCAP magic bytes)")
    return path


def recording_summary(path: str | Path) -> Summary:
    """Channels and statistics of a finished recording; a damaged or unfinished one raises McapError."""
    path = check_mcap_file(path)
    with open(path, "rb") as f:
        try:
            summary = make_reader(f).get_summary()
        except McapError as exc:
            summary, why = None, str(exc)
        else:
            why = "it has no summary section"
    if summary is None or summary.statistics is None:
        raise McapError(f"{path}: not a finished recording ({why}); `omninav recover {path}` saves what is readable")
    return summary


class RecordingError(ValueError):
    """A recording that cannot be read: one line naming the file and what is wrong with it."""


def read_records(path: str | Path, keys: Iterable[str] | None = None) -> Iterator[Record]:
    """Every message of a finished recording, in file order; RecordingError when there is no such
    file, it is not MCAP, or it is damaged."""
    try:
        path = check_mcap_file(path)
    except (FileNotFoundError, McapError) as exc:
        raise RecordingError(str(exc)) from None
    with open(path, "rb") as f:
        try:
            yield from _records(make_reader(f), keys)
        except (McapError, EOFError, ValueError, OSError, struct.error) as exc:
            raise RecordingError(f"{path}: not a readable MCAP recording ({type(exc).__name__}: {exc}); "
                                 f"`omninav recover {path}` rewrites what is readable") from None


def read_readable_records(path: str | Path) -> tuple[list[Record], str | None]:
    """What can be read of a possibly damaged recording, and why reading stopped (None if it did not)."""
    out: list[Record] = []
    with open(path, "rb") as f:
        try:
            for rec in _records(NonSeekingReader(f, validate_crcs=True), None):
                out.append(rec)
        except EndOfFile:
            return out, "the file ends inside a record (its writer stopped before finishing it)"
        except (McapError, EOFError, ValueError, KeyError, OSError) as exc:  # corrupt tail
            return out, f"{type(exc).__name__}: {exc}"
    return out, None
