"""Zenoh session configuration that can only ever use loopback.

Zenoh's defaults listen on every interface and scout by multicast; here every session has scouting
off, and every endpoint is checked to be tcp on 127.0.0.0/8 or ::1, or a unix socket.
"""
from __future__ import annotations

import ipaddress
import json
import os
import socket
from pathlib import Path
from typing import Callable

import zenoh

from .acl import auth_json
from .joining import Identity, listening, login_identity, refusal

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
ROUTER_ENV = "OMNINAV_ROUTER"
# Zenoh's shared memory is on by default (a 16 MiB pool per process in /dev/shm); "off" disables it
# for every session of a run (a mix of on and off is slower than either), e.g. where /dev/shm is small
SHM_ENV = "OMNINAV_SHM"
# the largest message a session receives (zenoh's default, 1 GiB: a 4000 x 4000 map of 16 MB passes);
# LiveRunner refuses to publish anything bigger, naming the key and the size
MAX_MESSAGE_SIZE = "transport/link/rx/max_message_size"
CONNECT_RETRY = {"period_init_ms": 50, "period_max_ms": 100, "period_increase_factor": 2}
OPEN_ATTEMPT_S = 1.0     # how long one attempt to reach the router waits; open_client makes as many as it takes
REFUSED_AFTER = 3        # failed attempts (1 + 2 + 4 s) with a router listening: its login was refused
_SWITCH = {"on": True, "1": True, "true": True, "off": False, "0": False, "false": False}


def router_endpoint(explicit: str | None = None) -> str:
    """The router endpoint to use: the argument, else $OMNINAV_ROUTER, else the default."""
    return check_loopback(explicit or os.environ.get(ROUTER_ENV) or DEFAULT_ROUTER)


def free_loopback_port() -> int:
    """A tcp port on 127.0.0.1 that is free right now (whoever binds it next may lose a race for it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_loopback_endpoint() -> str:
    """A tcp endpoint on 127.0.0.1 with a port that is free right now (for benches and demos)."""
    return f"tcp/127.0.0.1:{free_loopback_port()}"


def check_loopback(endpoint: str) -> str:
    """Return the endpoint if it is a loopback tcp or unix-socket endpoint; raise otherwise."""
    proto, _, address = endpoint.partition("/")
    if proto == "unixsock-stream" and address:
        return endpoint
    if proto != "tcp" or not address:
        raise ValueError(f"endpoint {endpoint!r}: only tcp/127.x.x.x:PORT, tcp/[::1]:PORT or unixsock-stream/PATH")
    host, _, port = address.rpartition(":")
    try:
        ip = ipaddress.ip_address(host.strip("[]"))
    except ValueError:
        raise ValueError(f"endpoint {endpoint!r}: host must be a loopback IP address, not a name") from None
    if not ip.is_loopback or not port.isdigit():
        raise ValueError(f"endpoint {endpoint!r} is not a loopback address with a port")
    return endpoint


def _base(mode: str) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    shm = os.environ.get(SHM_ENV)
    if shm is not None:
        if shm.lower() not in _SWITCH:
            raise ValueError(f"{SHM_ENV}={shm!r}: use on or off")
        conf.insert_json5("transport/shared_memory/enabled", json.dumps(_SWITCH[shm.lower()]))
    return conf


def router_config(listen: str, dictionary: Path | None = None, access_control: dict | None = None) -> zenoh.Config:
    """A router; with a dictionary file ("user:password" lines) only those users can connect, and
    with an access_control section (acl.py) they may do only what it allows."""
    conf = _base("router")
    conf.insert_json5("listen/endpoints", json.dumps([check_loopback(listen)]))
    if dictionary is not None:
        conf.insert_json5("transport/auth/usrpwd", json.dumps({"dictionary_file": str(dictionary)}))
    if access_control is not None:
        conf.insert_json5("access_control", json.dumps(access_control))
    return conf


def client_config(router: str | None = None, credentials: str | None = None) -> zenoh.Config:
    """A client that connects to the router and waits for it (start order does not matter); it
    authenticates with the credentials file given, else $OMNINAV_CREDENTIALS's, if any."""
    endpoint = router_endpoint(router)
    return logging_in(endpoint, login_identity(endpoint, credentials))


def logging_in(endpoint: str, identity: Identity) -> zenoh.Config:
    """A client of endpoint that logs in as identity (if it is one)."""
    conf = foreign_client_config(endpoint)
    if identity.user is not None:
        conf.insert_json5("transport/auth/usrpwd", auth_json(identity.user, identity.password))
    return conf


def foreign_client_config(endpoint: str, login: zenoh.Config | None = None) -> zenoh.Config:
    """A client of the router at endpoint (loopback only) that waits for it, without omninav's
    credentials: as such it also joins another system's router, e.g. a ROS 2 robot's rmw_zenoh one.
    With `login` (checked_login_config: another system's config, e.g. with its usrpwd or TLS) it is
    that config with these rules over it, and connects to the login's connect/endpoints if it has any."""
    conf = _base("client") if login is None else login
    if login is not None:
        conf.insert_json5("mode", '"client"')
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("scouting/gossip/enabled", "false")
    endpoints = login_endpoints(login) if login is not None else []
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("connect/endpoints", json.dumps(endpoints or [check_loopback(endpoint)]))
    conf.insert_json5("connect/timeout_ms", "-1")
    conf.insert_json5("connect/exit_on_failure", "false")
    # zenoh retries a connection 1 s, then 2 s, then every 4 s: a service started before `up` opens
    # its router (it imports and builds meanwhile) joined up to 4 s after it opened (measured 3.0 s);
    # a refused loopback connection costs nothing, so retry every 0.1 s
    conf.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
    return conf


# ---------------------------------------------------------------- another system's config (a robot's rmw_zenoh)

_ZENOH_DEFAULTS = zenoh.Config()
_TLS_FILES = ("root_ca_certificate", "connect_certificate", "connect_private_key")


def _set(conf: zenoh.Config, key: str):
    """The file's value of key, or None where the file left zenoh's default."""
    value = json.loads(conf.get_json(key))
    return None if value == json.loads(_ZENOH_DEFAULTS.get_json(key)) else value


def _flat(endpoints) -> list[str]:
    """A list of endpoints, or zenoh's per-mode mapping of them, as one list."""
    if isinstance(endpoints, dict):
        return [e for listed in endpoints.values() for e in listed or []]
    return list(endpoints or [])


def _is_loopback_listen(endpoint: str) -> bool:
    proto, _, address = endpoint.partition("/")
    if proto.startswith("unixsock"):
        return True
    host = address.partition("#")[0].rpartition(":")[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def checked_login_config(path: str | Path | None = None, user: str | None = None,
                         password_file: str | Path | None = None) -> zenoh.Config:
    """Another system's Zenoh config (JSON5, e.g. zenoh_security_tools' for rmw_zenoh: transport/auth/usrpwd
    or transport/link/tls), and/or user + password file as its usrpwd, for foreign_client_config.
    ValueError naming the key when the file would open more than loopback and scouting-free (a listen
    endpoint off loopback, scouting on, plugins, mode router) or cannot work (a TLS file missing, half a login)."""
    where = f"--zenoh-config {path}" if path else "--user"
    if path:
        try:
            conf = zenoh.Config.from_file(str(path))
        except (zenoh.ZError, OSError) as exc:
            raise ValueError(f"--zenoh-config {path}: not a Zenoh config ({exc})") from None
    else:
        conf = zenoh.Config()
    mode = _set(conf, "mode")
    if mode not in (None, "client", "peer"):
        raise ValueError(f"{where}: mode {mode!r}: the bridge is a client of the robot's router, never a router")
    off_loopback = [e for e in _flat(_set(conf, "listen/endpoints")) if not _is_loopback_listen(e)]
    if off_loopback:
        raise ValueError(f"{where}: listen/endpoints {off_loopback} is not loopback: the bridge listens on nothing")
    for key in ("scouting/multicast/enabled", "scouting/gossip/enabled", "plugins_loading/enabled"):
        if _set(conf, key):
            raise ValueError(f"{where}: {key} is true: the bridge only connects to the router (set it false)")
    if _set(conf, "plugins"):
        raise ValueError(f"{where}: plugins: the bridge loads none")
    tls = _set(conf, "transport/link/tls") or {}
    for name in _TLS_FILES:
        if tls.get(name) and not os.access(tls[name], os.R_OK):
            raise ValueError(f"{where}: transport/link/tls/{name} {tls[name]}: cannot read it")
    if bool(tls.get("connect_certificate")) != bool(tls.get("connect_private_key")):
        raise ValueError(f"{where}: transport/link/tls: connect_certificate and connect_private_key go together")
    usrpwd = _set(conf, "transport/auth/usrpwd") or {}     # half a usrpwd: zenoh refuses the file itself
    if bool(user) != bool(password_file):
        raise ValueError("--user and --password-file go together")
    if user:
        if usrpwd.get("user"):
            raise ValueError(f"{where}: transport/auth/usrpwd/user is set there and by --user: give one")
        try:
            password = Path(password_file).read_text().strip()
        except OSError as exc:
            raise ValueError(f"--password-file {password_file}: cannot read it ({exc.strerror})") from None
        if not password or "\n" in password:
            raise ValueError(f"--password-file {password_file}: expected the password alone on one line")
        conf.insert_json5("transport/auth/usrpwd", auth_json(user, password))
    return conf


def login_endpoints(login: zenoh.Config) -> list[str]:
    """The robot's router endpoints a login config names (connect/endpoints; may be off loopback, e.g. tls/…)."""
    return _flat(_set(login, "connect/endpoints"))


def login_refused(endpoints: list[str]) -> bool:
    """Whether a router listens on one of these endpoints: if so, a session that cannot open was
    refused (Zenoh says "Timeout" alike for a refused login and for no router)."""
    return any(listening(endpoint) for endpoint in endpoints)


def open_client(router: str | None = None, credentials: str | None = None,
                stopped: Callable[[], bool] = lambda: False, as_tool: bool = False,
                warn: Callable[[str], None] | None = None) -> zenoh.Session | None:
    """A client session once the router answers; None if stopped() turns true before it does.
    zenoh.open's own wait for a router cannot be interrupted (a signal handler runs only once it
    returns: `omninav run` started before `up` could not be stopped), so the wait is made of
    attempts of OPEN_ATTEMPT_S each, with stopped() asked, and Ctrl-C taken, between them.
    It logs in as joining.login_identity says (a tool also through the run's entry), asked again at
    every attempt (`up` writes the entry once its router is open); a tool gets joining.LoginRefused
    once a router listens there but did not let it in REFUSED_AFTER times, each attempt twice as long
    as the last (zenoh says the same for a refused login as for no router; a slow handshake is not a
    refusal); a service is told (`warn`) and goes on trying."""
    endpoint, refusals, told = router_endpoint(router), 0, set()

    def once(text: str) -> None:
        if warn and text not in told:
            told.add(text)
            warn(text)

    while not stopped():
        identity = login_identity(endpoint, credentials, as_tool, once)
        conf = logging_in(endpoint, identity)
        conf.insert_json5("connect/timeout_ms", json.dumps(round(OPEN_ATTEMPT_S * 2 ** refusals * 1000)))
        try:
            return zenoh.open(conf)
        except zenoh.ZError:
            if not listening(endpoint):
                refusals = 0        # no router there (yet): wait for it
                continue
            refusals = min(refusals + 1, REFUSED_AFTER)
            if refusals >= REFUSED_AFTER:
                if as_tool:
                    raise refusal(endpoint, identity) from None
                # a service under `up` keeps trying: three slow handshakes on a loaded machine are no
                # proof of a refused login, and its supervisor sees a service that never comes up
                once(f"{refusal(endpoint, identity)}; still trying")
    return None


def open_in_attempts(conf: zenoh.Config, stopped: Callable[[], bool]) -> zenoh.Session | None:
    """zenoh.open(conf) again after every failure (conf's connect/timeout_ms bounds each attempt)
    until it succeeds, or None once stopped() is true."""
    while not stopped():
        try:
            return zenoh.open(conf)
        except zenoh.ZError:
            continue
    return None


def open_router(listen: str | None = None, dictionary: Path | None = None,
                access_control: dict | None = None) -> zenoh.Session:
    return zenoh.open(router_config(router_endpoint(listen), dictionary, access_control))
