"""Who may do what on the bus: one Zenoh identity per process and the router's access control.

Zenoh does the enforcing: clients authenticate with user/password (transport/auth/usrpwd), the
router checks them against a dictionary file and applies `access_control` with
default_permission "deny". The rules are built from what each Node declares: it may put on its
outputs and its diagnostics key, subscribe to its inputs, answer its queryables and declare its
liveliness token — nothing else, but for watching the others' tokens where it must (the lockstep
coordinator; a source, which waits for the listeners before its first message). Measured on zenoh 1.10 (tests/test_acl.py):
- a publisher must be allowed to *learn* of the subscribers (egress declare_subscriber), or its
  puts are never sent: without that rule a put is dropped without a word. A rule matches a
  declaration only if it includes the declared expression, so a publisher of omninav/r1/odom learns
  of the recorder's omninav/** only through a rule on omninav/**: every publisher may learn of
  every subscription (who listens to what, not a right to send);
- a put reaches a subscriber only through an egress put rule on the subscriber's identity;
- the launcher's own session lives inside the router and is not subject to the rules.
"""
from __future__ import annotations

import json
import os
import secrets
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Iterable

from ...schemas.keys import ALL, KeyLayout
from .node import Node

CREDENTIALS_ENV = "OMNINAV_CREDENTIALS"     # path of a file "user:password", readable by its owner only
DICTIONARY = "router.dict"                  # the router's user:password list, in the credentials folder
PUTS = "puts.json"                          # identity -> the keys it may put: replay picks its identities by it
TOOL, TELEOP, OPERATOR = "tool", "teleop", "operator"


@dataclass(frozen=True)
class Grants:
    """The key expressions one identity may use, per kind of access."""
    put: tuple[str, ...] = ()
    subscribe: tuple[str, ...] = ()
    queryable: tuple[str, ...] = ()
    query: tuple[str, ...] = ()
    token: tuple[str, ...] = ()          # liveliness tokens it declares
    watch: tuple[str, ...] = ()          # liveliness it may query or subscribe to


def node_grants(node: Node) -> Grants:
    """What a service may do: exactly what its Node declared."""
    keys = node.keys
    follows = (keys.lockstep_of_all(),) if node.coordinates_lockstep else ()
    # a source asks which services are ready before its first message (live.LISTENERS_ENV)
    watches = follows or node.pace_s() is not None
    return Grants(put=(*node.outputs, node.diagnostics.key, keys.lockstep(node.name)),
                  subscribe=(*node.subscriptions(), *follows), queryable=tuple(node.queryables),
                  # watching liveliness is read-only; a rule on the token expression alone did not
                  # pass a token's deletion to the coordinator (measured: `up --lockstep` waited on)
                  token=(keys.alive(node.name),), watch=(ALL,) if watches else ())


def union(grants: Iterable[Grants]) -> Grants:
    """What a process running several services may do: what any of them may (a container)."""
    merged: dict[str, list[str]] = {f.name: [] for f in fields(Grants)}
    for one in grants:
        for name, keys in merged.items():
            keys += [k for k in getattr(one, name) if k not in keys]
    return Grants(**{name: tuple(keys) for name, keys in merged.items()})


def client_grants(robot: str) -> dict[str, Grants]:
    """The identities `up` makes besides its services: the tools (read-only: topics, echo, hz, get,
    record), teleop (its cmd_vel_teleop, into the command mux) and the operator (goals, cancels,
    initial poses, as RViz would send them; `navigate`'s mission uses it)."""
    keys = KeyLayout(robot)
    read = Grants(subscribe=(ALL,), query=(ALL,), watch=(ALL,))
    return {
        TOOL: read,
        TELEOP: Grants(put=(keys.robot("cmd_vel_teleop"), keys.lockstep("teleop")), subscribe=read.subscribe,
                       query=read.query, watch=read.watch, token=(keys.alive("teleop"),)),
        # navigate's mission takes part in a lockstep run as the service "navigate"
        OPERATOR: Grants(put=(*(keys.robot(t) for t in ("goal", "cancel", "initialpose")), keys.lockstep("navigate")),
                         subscribe=read.subscribe, query=read.query, watch=read.watch,
                         token=(keys.alive("navigate"),)),
    }


# (grant field, flow, zenoh message kinds): each grant becomes these rules on the router, on its key
# expressions, or on every key where the field name is followed by "*"
_RULES = (
    ("put", "ingress", ("put",)),
    ("put*", "egress", ("declare_subscriber",)),     # a publisher sends only to subscribers it knows of
    ("subscribe", "ingress", ("declare_subscriber",)),
    ("subscribe", "egress", ("put",)),
    ("queryable", "ingress", ("declare_queryable", "reply")),
    ("queryable", "egress", ("query",)),
    ("query", "ingress", ("query",)),
    ("query", "egress", ("reply", "declare_queryable")),
    ("token", "ingress", ("liveliness_token",)),
    ("watch", "ingress", ("liveliness_query", "declare_liveliness_subscriber")),
    ("watch", "egress", ("liveliness_token",)),
)


def access_control(identities: dict[str, Grants]) -> dict:
    """The router's `access_control` section: deny by default, each identity's grants allowed."""
    rules, subjects, policies = [], [], []
    for user, grants in identities.items():
        ids = []
        for field, flow, messages in _RULES:
            key_exprs = getattr(grants, field.rstrip("*"))
            if key_exprs and field.endswith("*"):
                key_exprs = (ALL,)
            if key_exprs:
                ids.append(f"{user}/{field}/{flow}")
                rules.append({"id": ids[-1], "permission": "allow", "flows": [flow], "messages": list(messages),
                              "key_exprs": sorted(set(key_exprs))})
        subjects.append({"id": user, "usernames": [user]})
        policies.append({"id": user, "rules": ids, "subjects": [user]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def write_credentials(folder: Path, identities: dict[str, Grants]) -> Path:
    """A fresh password per identity: one file per identity (for its process), the router's
    dictionary and what each may put, all readable by this user only; returns the dictionary's path."""
    dictionary = write_passwords(folder, list(identities))
    write_puts(folder, identities)
    return dictionary


def write_passwords(folder: Path, users: list[str]) -> Path:
    """A fresh password per user, one file each and the router's dictionary, readable by this user
    only (`up` writes them before it knows the rights, so processes can start meanwhile)."""
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(folder, 0o700)
    lines = []
    for user in users:
        line = f"{user}:{secrets.token_urlsafe(24)}\n"
        write_private(folder / user, line)
        lines.append(line)
    dictionary = folder / DICTIONARY
    write_private(dictionary, "".join(lines))
    return dictionary


def write_puts(folder: Path, identities: dict[str, Grants]) -> None:
    """What each identity may put, for replay (publishers_of)."""
    write_private(folder / PUTS, json.dumps({user: list(g.put) for user, g in identities.items()}, indent=1))


def publishers_of(folder: Path, keys: set[str]) -> dict[str, Path]:
    """key -> the credentials file of the run's identity that may put it (a replay plays each key
    as the service that published it); ValueError naming the keys no identity may put."""
    try:
        puts = json.loads((folder / PUTS).read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{folder}: not the identities folder of an `omninav up` run ({exc})") from None
    owners = {key: user for user, allowed in puts.items() for key in allowed}
    orphans = sorted(keys - owners.keys())
    if orphans:
        raise ValueError(f"no identity of this run may put {', '.join(orphans)} (replay only keys one of its "
                         f"services publishes, with --keys)")
    return {key: folder / owners[key] for key in keys}


def write_private(path: Path, text: str) -> None:
    """Written beside it, then renamed: whoever waits for the file to exist (navigate, bench kills)
    never reads it half written."""
    part = path.with_name(f".{path.name}.part")
    fd = os.open(part, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as file:
        file.write(text)
    os.replace(part, path)


def read_credentials(path: str | Path) -> tuple[str, str]:
    """(user, password) from a credentials file; ValueError naming the file when it is unusable."""
    try:
        text = Path(path).read_text().strip()
    except OSError as exc:
        raise ValueError(f"{CREDENTIALS_ENV}={path}: cannot read it ({exc.strerror})") from None
    user, sep, password = text.partition(":")
    if not sep or not user or not password or "\n" in text:
        raise ValueError(f"{CREDENTIALS_ENV}={path}: expected one line 'user:password'")
    return user, password


def auth_json(user: str, password: str) -> str:
    return json.dumps({"user": user, "password": password})
