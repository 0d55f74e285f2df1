"""Decode Foxglove well-known messages the way a viewer does: from the protobuf schema that travels
with the channel (FileDescriptorSet), not from compiled classes."""
import json

from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory

_factory = DecoderFactory()
_schema_ids: dict[tuple[str, bytes], int] = {}


def decode_with_schema(encoding: str, schema_name: str, schema_encoding: str, schema_data: bytes, data: bytes):
    """A decoded message: a protobuf message for protobuf channels, a dict for JSON ones."""
    if encoding == "json":
        return json.loads(data)
    # the factory caches generated classes by schema id: give each distinct schema its own
    schema_id = _schema_ids.setdefault((schema_name, schema_data), len(_schema_ids) + 1)
    decoder = _factory.decoder_for(encoding, Schema(id=schema_id, name=schema_name, encoding=schema_encoding,
                                                    data=schema_data))
    assert decoder is not None, f"no decoder for {encoding} / {schema_encoding} {schema_name}"
    return decoder(data)


def decode_foxglove(message):
    """A foxglove.messages instance, encoded and decoded again."""
    schema = type(message).get_schema()
    return decode_with_schema("protobuf", schema.name, schema.encoding, schema.data, message.encode())
