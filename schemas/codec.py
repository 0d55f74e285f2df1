"""msgpack codec for wire messages.

A payload is a msgpack map: {"_type": name, "_version": v, <field>: <value>, …} in field order, so
the same message always encodes to the same bytes. ndarrays travel as {"dtype", "shape", "data"}
and decode as read-only views over the received bytes (no copy). Decoding checks every field and
raises MessageError naming the key, the type and the field.
"""
from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass
from functools import cache
from typing import Any

import msgpack
import numpy as np

from . import messages  # noqa: F401  (registers every message type)
from .fields import ArraySpec
from .registry import by_name, type_info

TYPE_FIELD = "_type"
VERSION_FIELD = "_version"
_MAX_PAYLOAD = 256 * 1024 * 1024


class MessageError(ValueError):
    """A payload that is not a valid message; says where (key), what (type.field) and why."""

    def __init__(self, reason: str, *, field: str = "", type_name: str = "", key: str = ""):
        self.reason, self.field, self.type_name, self.key = reason, field, type_name, key
        where = ".".join(p for p in (type_name, field) if p)
        text = f"{where}: {reason}" if where else reason
        super().__init__(f"{key}: {text}" if key else text)


@dataclass(frozen=True)
class _Field:
    name: str
    kind: str                       # int | float | str | bool | dict | array | struct
    array: ArraySpec | None = None
    struct: type | None = None
    allow_nonfinite: bool = False


@cache
def _plan(cls: type) -> tuple[_Field, ...]:
    hints = typing.get_type_hints(cls)
    plan = []
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if "array" in f.metadata:
            plan.append(_Field(f.name, "array", array=f.metadata["array"]))
        elif dataclasses.is_dataclass(hint):
            plan.append(_Field(f.name, "struct", struct=hint))
        elif hint in (int, float, str, bool):
            plan.append(_Field(f.name, hint.__name__, allow_nonfinite=f.metadata.get("allow_nonfinite", False)))
        elif typing.get_origin(hint) is dict:
            plan.append(_Field(f.name, "dict"))
        else:
            raise TypeError(f"{cls.__name__}.{f.name}: unsupported field type {hint!r}")
    return tuple(plan)


# ---------------------------------------------------------------- encode

def _encode_struct(obj: Any) -> dict:
    out = {}
    for f in _plan(type(obj)):
        value = getattr(obj, f.name)
        if f.kind == "array":
            arr = np.ascontiguousarray(value, dtype=f.array.dtype)
            out[f.name] = {"dtype": f.array.dtype, "shape": list(arr.shape), "data": arr.tobytes()}
        elif f.kind == "struct":
            out[f.name] = _encode_struct(value)
        elif f.kind == "float":
            out[f.name] = float(value)
        elif f.kind == "int":
            out[f.name] = int(value)
        elif f.kind == "dict":
            out[f.name] = dict(value)
        else:
            out[f.name] = value
    return out


def to_wire(msg: Any) -> dict:
    """The msgpack-ready map of a message, with its type name and version first."""
    name, version = type_info(type(msg))
    return {TYPE_FIELD: name, VERSION_FIELD: version, **_encode_struct(msg)}


def encode(msg: Any) -> bytes:
    return msgpack.packb(to_wire(msg), use_bin_type=True)


# ---------------------------------------------------------------- decode

def _fail(reason: str, path: str) -> typing.NoReturn:
    raise MessageError(reason, field=path)


def _decode_array(raw: Any, spec: ArraySpec, path: str) -> np.ndarray:
    if not isinstance(raw, dict) or set(raw) != {"dtype", "shape", "data"}:
        _fail("expected an array map with dtype, shape and data", path)
    if raw["dtype"] != spec.dtype:
        _fail(f"dtype {raw['dtype']!r}, expected {spec.dtype!r}", path)
    shape = raw["shape"]
    if not isinstance(shape, list) or not all(type(n) is int and n >= 0 for n in shape):
        _fail(f"shape {shape!r} is not a list of sizes", path)
    if len(shape) != len(spec.shape) or any(w is not None and n != w for n, w in zip(shape, spec.shape)):
        _fail(f"shape {tuple(shape)}, expected {spec.shape} (None = any)", path)
    data = raw["data"]
    if not isinstance(data, bytes):
        _fail("array data is not binary", path)
    dtype = np.dtype(spec.dtype)
    if len(data) != math.prod(shape) * dtype.itemsize:
        _fail(f"{len(data)} bytes do not fill shape {tuple(shape)} of {spec.dtype}", path)
    arr = np.frombuffer(data, dtype=dtype).reshape(shape)
    if not spec.allow_nonfinite and dtype.kind == "f" and not np.isfinite(arr).all():
        _fail("contains NaN or infinity", path)
    return arr


def _decode_scalar(raw: Any, f: _Field, path: str) -> Any:
    if f.kind == "float":
        if type(raw) not in (float, int):
            _fail(f"expected a number, got {type(raw).__name__}", path)
        value = float(raw)
        if not f.allow_nonfinite and not math.isfinite(value):
            _fail(f"{value} is not finite", path)
        return value
    if f.kind == "int":
        if type(raw) is not int:
            _fail(f"expected an integer, got {type(raw).__name__}", path)
        return raw
    if f.kind == "str":
        if type(raw) is not str:
            _fail(f"expected a string, got {type(raw).__name__}", path)
        return raw
    if f.kind == "bool":
        if type(raw) is not bool:
            _fail(f"expected true or false, got {type(raw).__name__}", path)
        return raw
    if not isinstance(raw, dict) or not all(
        type(k) is str and type(v) in (int, float, str) for k, v in raw.items()
    ):
        _fail("expected a map of names to numbers or strings", path)
    return raw


def _decode_struct(raw: Any, cls: type, path: str, skip: tuple[str, ...] = ()) -> Any:
    if not isinstance(raw, dict):
        _fail(f"expected a map for {cls.__name__}, got {type(raw).__name__}", path)
    plan = _plan(cls)
    unknown = set(raw) - {f.name for f in plan} - set(skip)
    if unknown:
        _fail(f"unknown field(s) {sorted(map(str, unknown))}", path)
    values = {}
    for f in plan:
        sub = f"{path}.{f.name}" if path else f.name
        if f.name not in raw:
            _fail("missing", sub)
        if f.kind == "array":
            values[f.name] = _decode_array(raw[f.name], f.array, sub)
        elif f.kind == "struct":
            values[f.name] = _decode_struct(raw[f.name], f.struct, sub)
        else:
            values[f.name] = _decode_scalar(raw[f.name], f, sub)
    return cls(**values)


def _unpack(data: bytes | bytearray | memoryview) -> dict:
    try:
        raw = msgpack.unpackb(data, raw=False, strict_map_key=True, max_bin_len=_MAX_PAYLOAD)
    except Exception as exc:  # msgpack raises several unrelated types for damaged input
        raise MessageError(f"not a msgpack payload ({type(exc).__name__}: {exc})") from None
    if not isinstance(raw, dict):
        raise MessageError(f"payload is a {type(raw).__name__}, not a message map")
    return raw


def peek_type(data: bytes | bytearray | memoryview) -> str:
    """The type name a payload claims, without validating the rest."""
    name = _unpack(data).get(TYPE_FIELD)
    if not isinstance(name, str):
        raise MessageError("payload has no _type")
    return name


def decode(data: bytes | bytearray | memoryview, expected: type | None = None, *, key: str = "") -> Any:
    """Decode and validate a payload; `expected` (a message class) also checks the type."""
    try:
        raw = _unpack(data)
        name = raw.get(TYPE_FIELD)
        cls = by_name(name) if isinstance(name, str) else None
        if cls is None:
            raise MessageError(f"unknown message type {name!r}", field=TYPE_FIELD)
        want_name, want_version = type_info(cls)
        if expected is not None and cls is not expected:
            raise MessageError(f"got {name}, expected {type_info(expected)[0]}", field=TYPE_FIELD)
        if raw.get(VERSION_FIELD) != want_version:
            raise MessageError(
                f"version {raw.get(VERSION_FIELD)!r}, this build reads {want_version}",
                field=VERSION_FIELD, type_name=want_name,
            )
        try:
            return _decode_struct(raw, cls, "", skip=(TYPE_FIELD, VERSION_FIELD))
        except MessageError as exc:
            raise MessageError(exc.reason, field=exc.field, type_name=want_name) from None
    except MessageError as exc:
        if key and not exc.key:
            raise MessageError(exc.reason, field=exc.field, type_name=exc.type_name, key=key) from None
        raise


def describe(cls: type) -> dict:
    """A JSON-Schema description of a message type, attached to recordings."""

    def schema_of(c: type) -> dict:
        props = {}
        for f in _plan(c):
            if f.kind == "array":
                props[f.name] = {
                    "type": "object",
                    "description": f"ndarray dtype={f.array.dtype} shape={list(f.array.shape)}",
                    "properties": {"dtype": {"type": "string"}, "shape": {"type": "array"}, "data": {}},
                }
            elif f.kind == "struct":
                props[f.name] = schema_of(f.struct)
            else:
                props[f.name] = {
                    "type": {"float": "number", "int": "integer", "str": "string", "bool": "boolean",
                             "dict": "object"}[f.kind]
                }
        return {"type": "object", "title": c.__name__, "properties": props}

    name, version = type_info(cls)
    schema = schema_of(cls)
    schema["title"] = name
    schema["properties"] = {
        TYPE_FIELD: {"const": name},
        VERSION_FIELD: {"const": version},
        **schema["properties"],
    }
    return schema
