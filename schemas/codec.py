"""msgpack codec for wire messages, on msgspec.

A payload is a msgpack map: {"_type": name, "_version": v, <field>: <value>, …} in field order, so
the same message always encodes to the same bytes. ndarrays travel as {"dtype", "shape", "data"}
and decode as read-only views over the received bytes (no copy). Decoding checks every field, then
the type's own rules (its `problem()`: sizes that must agree, REP 117 ranges, …), and raises
MessageError naming the key, the type and the field.
"""
from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass
from functools import cache
from typing import Annotated, Any, Callable, Literal, Union

import msgspec
import numpy as np

from . import messages  # noqa: F401  (registers every message type)
from .fields import ArraySpec, surely_finite
from .registry import by_name, type_info

TYPE_FIELD = "_type"
VERSION_FIELD = "_version"


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


# ---------------------------------------------------------------- mirrors
# msgspec encodes and parses Structs in C. Each message type has a mirror Struct: the same fields
# in the same order, nested types mirrored, arrays as {dtype, shape, data}, and for a top-level
# type `_type` and `_version` first, as literals. Parsing into a mirror checks every field's type,
# refuses missing and unknown fields; encoding one writes the map a payload is.

_SIZE = Annotated[int, msgspec.Meta(ge=0)]


@cache
def _wire_array(spec: ArraySpec) -> type:
    """The mirror of an array map: dtype and the sizes of fixed axes as literals."""
    shape = tuple[tuple(_SIZE if n is None else Literal[n] for n in spec.shape)] if spec.shape else tuple[()]
    return msgspec.defstruct("WireArray", [("dtype", Literal[spec.dtype]), ("shape", shape), ("data", memoryview)],
                             forbid_unknown_fields=True)


_SCALARS = {"float": float, "int": int, "str": str, "bool": bool, "dict": dict[str, Union[int, float, str]]}


@cache
def _mirror(cls: type, envelope: tuple[tuple[str, Any], ...] = ()) -> type:
    fields = [*((name, Literal[value]) for name, value in envelope)]
    for f in _plan(cls):
        kind = (_wire_array(f.array) if f.kind == "array" else _mirror(f.struct) if f.kind == "struct"
                else _SCALARS[f.kind])
        fields.append((f.name, kind))
    return msgspec.defstruct("Wire" + cls.__name__, fields, forbid_unknown_fields=True)


def _envelope_mirror(cls: type) -> type:
    """The mirror of a top-level message: its type name and version first."""
    name, version = type_info(cls)
    return _mirror(cls, ((TYPE_FIELD, name), (VERSION_FIELD, version)))


# ---------------------------------------------------------------- encode
# Each type gets a generated function building its mirror from a message (one call, no per-field
# calls): the stack publishes odometry, wheel states and the clock at the sim rate.

def _mirror_args(cls: type, var: str, lines: list[str], names: dict[str, Any]) -> str:
    """The arguments building the mirror of the struct held in local `var` (arrays and nested
    structs get locals of their own, assigned in `lines`; constants the code needs go into `names`)."""
    args = []
    for f in _plan(cls):
        value, local = f"{var}.{f.name}", f"{var}_{f.name}"
        if f.kind == "array":
            names[f"dtype_{local}"], names[f"Array_{local}"] = np.dtype(f.array.dtype), _wire_array(f.array)
            # the array's own buffer: msgspec copies it once into the payload, tobytes() would copy twice
            lines.append(f"    {local} = ascontiguousarray({value}, dtype_{local})")
            args.append(f"Array_{local}({f.array.dtype!r}, {local}.shape, {local}.data)")
        elif f.kind == "struct":
            names[f"Wire_{local}"] = _mirror(f.struct)
            lines.append(f"    {local} = {value}")
            args.append(f"Wire_{local}({_mirror_args(f.struct, local, lines, names)})")
        elif f.kind in ("float", "int", "dict"):
            args.append(f"{f.kind}({value})")
        else:
            args.append(value)
    return ", ".join(args)


@cache
def _wire_builder(cls: type) -> Callable[[Any], Any]:
    """The mirror of a message of this type, generated: _type, _version, its fields."""
    name, version = type_info(cls)
    lines: list[str] = []
    names: dict[str, Any] = {"ascontiguousarray": np.ascontiguousarray, "Wire": _envelope_mirror(cls)}
    args = _mirror_args(cls, "m", lines, names)
    source = "\n".join(["def to_mirror(m):", *lines, f"    return Wire({name!r}, {version!r}, {args})"])
    exec(compile(source, f"<to_mirror {name}>", "exec"), names)
    return names["to_mirror"]


_encoder = msgspec.msgpack.Encoder()


def encode(msg: Any) -> bytes:
    return _encoder.encode(_wire_builder(type(msg))(msg))


def to_wire(msg: Any) -> dict:
    """The map a message's payload holds, in plain Python (maps, lists, bytes): for building
    payloads by hand."""
    return msgspec.msgpack.decode(encode(msg))


# ---------------------------------------------------------------- decode
# The checking decoder: built once per type from its plan, a closure per field, over the payload
# unpacked into plain maps; it runs when the fast path below doubts a payload and names what is
# wrong. Field paths are assembled only when something is.

class _Bad(Exception):
    def __init__(self, reason: str):
        self.reason, self.path = reason, []


def _array_decoder(spec: ArraySpec):
    dtype = np.dtype(spec.dtype)
    ndim = len(spec.shape)
    fixed = [(axis, n) for axis, n in enumerate(spec.shape) if n is not None]
    check_finite = not spec.allow_nonfinite and dtype.kind == "f"
    keys = {"dtype", "shape", "data"}

    def dec(raw):
        if type(raw) is not dict or raw.keys() != keys:
            raise _Bad("expected an array map with dtype, shape and data")
        if raw["dtype"] != spec.dtype:
            raise _Bad(f"dtype {raw['dtype']!r}, expected {spec.dtype!r}")
        shape = raw["shape"]
        if type(shape) is not list or not all(type(n) is int and n >= 0 for n in shape):
            raise _Bad(f"shape {shape!r} is not a list of sizes")
        if len(shape) != ndim or any(shape[axis] != n for axis, n in fixed):
            raise _Bad(f"shape {tuple(shape)}, expected {spec.shape} (None = any)")
        data = raw["data"]
        if type(data) is not bytes:
            raise _Bad("array data is not binary")
        if len(data) != math.prod(shape) * dtype.itemsize:
            raise _Bad(f"{len(data)} bytes do not fill shape {tuple(shape)} of {spec.dtype}")
        arr = np.frombuffer(data, dtype=dtype).reshape(shape)
        if check_finite and arr.size and not np.isfinite(arr).all():
            raise _Bad("contains NaN or infinity")
        return arr

    return dec


def _float_decoder(allow_nonfinite: bool):
    def dec(raw):
        kind = type(raw)
        if kind is float:
            if not allow_nonfinite and not math.isfinite(raw):
                raise _Bad(f"{raw} is not finite")
            return raw
        if kind is int:
            return float(raw)
        raise _Bad(f"expected a number, got {kind.__name__}")

    return dec


def _exact_decoder(kind: type, what: str):
    def dec(raw):
        if type(raw) is not kind:
            raise _Bad(f"expected {what}, got {type(raw).__name__}")
        return raw

    return dec


def _dict_decoder(raw):
    if type(raw) is not dict or not all(type(k) is str and type(v) in (int, float, str) for k, v in raw.items()):
        raise _Bad("expected a map of names to numbers or strings")
    return raw


def _field_decoder(f: _Field):
    if f.kind == "array":
        return _array_decoder(f.array)
    if f.kind == "struct":
        return _struct_decoder(f.struct)
    if f.kind == "float":
        return _float_decoder(f.allow_nonfinite)
    if f.kind == "dict":
        return _dict_decoder
    return _exact_decoder({"int": int, "str": str, "bool": bool}[f.kind],
                          {"int": "an integer", "str": "a string", "bool": "true or false"}[f.kind])


@cache
def _struct_decoder(cls: type, envelope: tuple[str, ...] = ()):
    fields = tuple((f.name, _field_decoder(f)) for f in _plan(cls))
    expected = frozenset(name for name, _ in fields) | frozenset(envelope)
    check = getattr(cls, "problem", None)       # the type's own consistency rules (messages.py)

    def dec(raw):
        if type(raw) is not dict:
            raise _Bad(f"expected a map for {cls.__name__}, got {type(raw).__name__}")
        if raw.keys() != expected:
            missing = [name for name, _ in fields if name not in raw]
            if missing:
                bad = _Bad("missing")
                bad.path.append(missing[0])
                raise bad
            raise _Bad(f"unknown field(s) {sorted(map(str, set(raw) - expected))}")
        values = []
        for name, field_dec in fields:
            try:
                values.append(field_dec(raw[name]))
            except _Bad as bad:
                bad.path.insert(0, name)
                raise
        msg = cls(*values)
        if check is not None:
            problem = check(msg)
            if problem is not None:
                bad = _Bad(problem[1])
                bad.path.extend(problem[0].split("."))
                raise bad
        return msg

    return dec


# The checking decoders above explain what is wrong, at a few calls per field. Most payloads are
# sound, so each type also gets a fast decoder for the happy path: msgspec parses the payload
# straight into a mirror of the type (the same fields, every one required, nothing else allowed,
# `_type` and `_version` as literals) and checks the field types in C; a generated function then
# turns the mirror into the message with the checks msgspec cannot make (finite floats, array
# sizes, the type's `problem()`), giving up (None) at the first doubt; the checking decoder then
# runs and names it. Whatever the fast path accepts, the checking one accepts as the same message.

def _from_mirror(cls: type, var: str, lines: list[str], names: dict[str, Any]) -> str:
    """Statements turning the mirror in local `var` into a `cls`; returns the expression building it.
    Constants the code needs go into `names`."""
    indent, out, values = "    ", lines.append, []
    for f in _plan(cls):
        v = f"{var}_{f.name}"
        out(f"{indent}{v} = {var}.{f.name}")
        if f.kind == "struct":
            out(f"{indent}{v} = {_from_mirror(f.struct, v, lines, names)}")
        elif f.kind == "array":
            _array_from_mirror(f.array, v, lines, names)
        elif f.kind == "float" and not f.allow_nonfinite:
            out(f"{indent}if not isfinite({v}): return None")
        values.append(v)
    names[f"cls_{var}"] = cls
    if getattr(cls, "problem", None) is None:
        return f"cls_{var}({', '.join(values)})"
    out(f"{indent}{var}_built = cls_{var}({', '.join(values)})")
    out(f"{indent}if {var}_built.problem() is not None: return None")
    return f"{var}_built"


def _array_from_mirror(spec: ArraySpec, var: str, lines: list[str], names: dict[str, Any]) -> None:
    """As _from_mirror for an array field: its size check and its read-only view over the payload."""
    indent, out = "    ", lines.append
    dtype = np.dtype(spec.dtype)
    names[f"dtype_{var}"] = dtype
    sizes = [f"{var}_n{axis}" for axis in range(len(spec.shape))]
    if sizes:
        out(f"{indent}{', '.join(sizes)}, = {var}.shape")
    out(f"{indent}if len({var}.data) != {' * '.join([*sizes, str(dtype.itemsize)])}: return None")
    out(f"{indent}{var}_flat = frombuffer({var}.data, dtype_{var})")
    if not spec.allow_nonfinite and dtype.kind == "f":
        out(f"{indent}if not all_finite({var}_flat): return None")
    # frombuffer already gives the one axis of a 1-D field
    out(f"{indent}{var} = {var}_flat" + (f".reshape({var}.shape)" if len(spec.shape) != 1 else ""))


_SHORT_ARRAY = 32


def _all_finite(flat: np.ndarray) -> bool:
    """Whether a float array holds only finite values: its sign bytes (fields.surely_finite), else
    one sum (NaN and infinities make it non-finite; a sum that overflows from finite values only
    sends the payload to the checking decoder). A short array is summed in Python: numpy's
    reduction costs about 0.6 µs however short the array (a covariance), a Python sum of its list
    0.15 µs."""
    if len(flat) <= _SHORT_ARRAY:
        return math.isfinite(sum(flat.tolist()))
    return surely_finite(flat) or math.isfinite(np.add.reduce(flat))


@cache
def _fast_decoder(cls: type) -> Callable[[Any], Any]:
    """The happy-path decoder of a message type: payload → its message, or None at the first doubt
    (msgspec's own errors included)."""
    name = type_info(cls)[0]
    parse = msgspec.msgpack.Decoder(_envelope_mirror(cls)).decode
    lines: list[str] = []
    names: dict[str, Any] = {"isfinite": math.isfinite, "frombuffer": np.frombuffer, "parse": parse,
                             "Invalid": msgspec.MsgspecError, "all_finite": _all_finite}
    built = _from_mirror(cls, "w", lines, names)
    source = "\n".join(["def decode_fast(data):", "    try:", "        w = parse(data)",
                        "    except Invalid:", "        return None", *lines, f"    return {built}"])
    exec(compile(source, f"<decode {name}>", "exec"), names)
    return names["decode_fast"]


def _unpack(data: bytes | bytearray | memoryview) -> dict:
    try:
        raw = msgspec.msgpack.decode(data)
    except msgspec.DecodeError as exc:
        raise MessageError(f"not a msgpack payload ({exc})") from None
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
    if type(data) is not bytes:     # arrays are views over the payload: it must never change
        data = bytes(data)
    cls = expected if expected is not None else _claimed_type(data)
    if cls is not None:
        msg = _fast_decoder(cls)(data)
        if msg is not None:
            return msg
    try:
        return _checked_decode(_unpack(data), expected)
    except MessageError as exc:
        if key and not exc.key:
            raise MessageError(exc.reason, field=exc.field, type_name=exc.type_name, key=key) from None
        raise


class _Claim(msgspec.Struct):
    """What a payload says it is; every other field is skipped unread."""
    _type: str = ""


_read_claim = msgspec.msgpack.Decoder(_Claim).decode


def _claimed_type(data: bytes | bytearray | memoryview) -> type | None:
    try:
        return by_name(_read_claim(data)._type)
    except msgspec.MsgspecError:
        return None


def _checked_decode(raw: dict, expected: type | None) -> Any:
    """The message in an unpacked payload, or MessageError naming the first thing wrong with it."""
    name = raw.get(TYPE_FIELD)
    cls = by_name(name) if type(name) is str else None
    if cls is None:
        raise MessageError(f"unknown message type {name!r}", field=TYPE_FIELD)
    if expected is not None and cls is not expected:
        raise MessageError(f"got {name}, expected {type_info(expected)[0]}", field=TYPE_FIELD)
    want_version = type_info(cls)[1]
    if raw.get(VERSION_FIELD) != want_version:
        raise MessageError(f"version {raw.get(VERSION_FIELD)!r}, this build reads {want_version}",
                           field=VERSION_FIELD, type_name=name)
    try:
        return _struct_decoder(cls, (TYPE_FIELD, VERSION_FIELD))(raw)
    except _Bad as bad:
        raise MessageError(bad.reason, field=".".join(bad.path), type_name=name) from None


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
