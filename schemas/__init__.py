"""The wire contract: message types, their msgpack codec and the key layout. Imports nothing else of ours."""
from . import messages
from .codec import MessageError, decode, encode, peek_type
from .keys import KeyLayout, type_for_key
from .registry import all_types, type_info

__all__ = ["messages", "MessageError", "decode", "encode", "peek_type", "KeyLayout", "type_for_key",
           "all_types", "type_info"]
