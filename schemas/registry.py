"""Names and versions of wire message types."""
from __future__ import annotations

_BY_NAME: dict[str, type] = {}
_NAME_OF: dict[type, tuple[str, int]] = {}


def message(name: str, version: int):
    """Class decorator: register a top-level wire message under `name` at `version`."""

    def register(cls: type) -> type:
        if name in _BY_NAME:
            raise ValueError(f"message type {name!r} registered twice")
        _BY_NAME[name] = cls
        _NAME_OF[cls] = (name, version)
        return cls

    return register


def type_info(cls: type) -> tuple[str, int]:
    """(name, version) of a registered message class."""
    try:
        return _NAME_OF[cls]
    except KeyError:
        raise TypeError(f"{cls.__name__} is not a registered wire message") from None


def by_name(name: str) -> type | None:
    return _BY_NAME.get(name)


def all_types() -> dict[str, type]:
    return dict(_BY_NAME)
