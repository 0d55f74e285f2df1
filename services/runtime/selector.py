"""Zenoh selectors as users type them: `KEY?a=1;b=2`, or `KEY;a=1;b=2` (a key may not contain ';')."""
from __future__ import annotations


def parse_parameters(text: str) -> dict[str, str]:
    """'a=1;b=2' -> {'a': '1', 'b': '2'}; a bare name maps to ''."""
    out = {}
    for part in text.split(";"):
        if part:
            name, _, value = part.partition("=")
            out[name] = value
    return out


def split_selector(selector: str) -> tuple[str, dict[str, str]]:
    """'omninav/r1/plan;start=0,0;goal=1,1' -> ('omninav/r1/plan', {...}); '?' works too."""
    if "?" in selector:
        key, _, params = selector.partition("?")
    else:
        key, _, params = selector.partition(";")
    return key, parse_parameters(params)


def join_selector(key: str, params: dict[str, str]) -> str:
    if not params:
        return key
    return key + "?" + ";".join(f"{k}={v}" if v != "" else k for k, v in params.items())
