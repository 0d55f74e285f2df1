"""The door in front of the view's WebSocket server when goals are allowed (`omninav view --allow-goals`).

foxglove-sdk (0.30) shows its listener only a client's id: neither the URL a client connected to nor
its HTTP headers (Origin) reach Python. So the door is a loopback TCP relay on the view's port that
reads each connection's HTTP upgrade request itself, checks it, then relays the bytes both ways to
the SDK's server, which listens on another loopback port:
- a connection is *admitted* when its URL carries the run's token (`?token=…`, compared in constant
  time) and its Origin header is absent (a program, not a browser page) or allowed
  (`origin_allowed`); for an admitted connection the door sends the SDK's server, before any byte
  of the client's, one setParameters message with an in-process secret (`admit_message`), which the
  view's listener takes as "this client may send goals";
- any other connection is relayed all the same (it may view) and its refusal is logged once, with
  the reason. The token never goes further than the door: the request is relayed without its query.
A process that finds the SDK's own port and connects there directly may view too, but can never be
admitted: the in-process secret is never printed or sent to a client.
"""
from __future__ import annotations

import json
import logging
import os
import secrets
import selectors
import socket
import struct
import threading
from urllib.parse import parse_qs, urlsplit, urlunsplit

# the Foxglove app on the web; the desktop app and a locally served one (any port) come from these
FOXGLOVE_ORIGINS = ("https://app.foxglove.dev",)
LOCAL_HOSTS = ("localhost", "127.0.0.1")
TOKEN_PARAM = "token"
MAX_HEAD = 16384        # bytes of an HTTP request or response head
HEAD_TIMEOUT_S = 10.0   # wall s a connection has to send its request head


def normal_origin(origin: str) -> str:
    """`scheme://host[:port]` in lower case, ValueError for anything else (a path, no host)."""
    parts = urlsplit(origin.strip().lower())
    if parts.scheme not in ("http", "https") or not parts.hostname or parts.path not in ("", "/") \
            or parts.query or parts.fragment or parts.username:
        raise ValueError(f"origin {origin!r}: expected http(s)://host[:port]")
    try:
        port = parts.port
    except ValueError:
        raise ValueError(f"origin {origin!r}: bad port") from None
    return f"{parts.scheme}://{parts.hostname}" + (f":{port}" if port is not None else "")


def origin_allowed(origin: str | None, extra: tuple[str, ...] = ()) -> bool:
    """No Origin (not a browser), the Foxglove app's, http://localhost or http://127.0.0.1 on any port,
    or one of `extra` (normalised origins)."""
    if origin is None:
        return True
    try:
        normal = normal_origin(origin)
    except ValueError:              # "null" (a sandboxed page, a file), garbage
        return False
    parts = urlsplit(normal)
    return (normal in FOXGLOVE_ORIGINS or normal in extra
            or (parts.scheme == "http" and parts.hostname in LOCAL_HOSTS))


def refusal(target: str, origin: str | None, multiple_origins: bool, token: str, extra: tuple[str, ...]) -> str:
    """Why a connection may not send goals ('' when it may)."""
    if multiple_origins:
        return "several Origin headers"
    if not origin_allowed(origin, extra):
        return f"Origin {origin} is not allowed (--allow-origin adds one)"
    given = parse_qs(urlsplit(target).query).get(TOKEN_PARAM, [])
    if not given:
        return "no token in its URL"
    if len(given) > 1 or not secrets.compare_digest(given[0].encode(), token.encode()):
        return "wrong token"
    return ""


def masked_text_frame(payload: bytes) -> bytes:
    """One WebSocket text frame as a client sends it (masked, RFC 6455 5.3)."""
    mask, n = os.urandom(4), len(payload)
    if n < 126:
        head = struct.pack("!BB", 0x81, 0x80 | n)
    elif n < 1 << 16:
        head = struct.pack("!BBH", 0x81, 0x80 | 126, n)
    else:
        head = struct.pack("!BBQ", 0x81, 0x80 | 127, n)
    return head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))


def _read_head(sock: socket.socket) -> tuple[bytes, bytes]:
    """(the HTTP head up to and with its blank line, what came after it); ValueError if none came."""
    data = b""
    while b"\r\n\r\n" not in data:
        if len(data) > MAX_HEAD:
            raise ValueError("HTTP head too long")
        chunk = sock.recv(4096)
        if not chunk:
            raise ValueError("closed before its HTTP head")
        data += chunk
    head, _, rest = data.partition(b"\r\n\r\n")
    return head + b"\r\n\r\n", rest


def _parse_request(head: bytes) -> tuple[str, list[str], bytes]:
    """(request target, its Origin header values, the head with the target's query removed)."""
    lines = head.decode("latin-1").split("\r\n")
    method, target, version = lines[0].split(" ", 2)
    origins = [line.partition(":")[2].strip() for line in lines[1:] if line.lower().startswith("origin:")]
    parts = urlsplit(target)
    lines[0] = f"{method} {urlunsplit(('', '', parts.path or '/', '', ''))} {version}"
    return target, origins, "\r\n".join(lines).encode("latin-1")


class Gate:
    """The door on host:port relaying to the SDK's server on host:upstream_port (see the module)."""

    def __init__(self, host: str, port: int, upstream_port: int, token: str, extra_origins: tuple[str, ...],
                 admit_message: bytes, log: logging.Logger):
        self.host, self.upstream_port, self.token = host, upstream_port, token
        self.extra_origins = tuple(normal_origin(o) for o in extra_origins)
        self.admit_frame = masked_text_frame(admit_message)
        self.log = log
        self.listener = socket.create_server((host, port))
        self.port = self.listener.getsockname()[1]
        self._stopped = threading.Event()
        self._lock = threading.Lock()
        self._open: set[socket.socket] = set()
        self._threads: list[threading.Thread] = []
        self._count = 0
        self._acceptor = threading.Thread(target=self._accept, name="view-gate", daemon=True)
        self._acceptor.start()

    def _accept(self) -> None:
        self.listener.settimeout(0.5)     # closing a socket does not wake a thread blocked in accept()
        while not self._stopped.is_set():
            try:
                client, _ = self.listener.accept()
            except TimeoutError:
                continue
            except OSError:         # closed by stop()
                return
            client.settimeout(None)
            with self._lock:
                self._count += 1
                self._open.add(client)
                thread = threading.Thread(target=self._serve, args=(client, self._count), daemon=True,
                                          name=f"view-gate-{self._count}")
                self._threads = [t for t in self._threads if t.is_alive()] + [thread]
            thread.start()

    def _serve(self, client: socket.socket, number: int) -> None:
        upstream = None
        try:
            client.settimeout(HEAD_TIMEOUT_S)
            request, early = _read_head(client)
            target, origins, relayed = _parse_request(request)
            origin = origins[0] if origins else None
            why = refusal(target, origin, len(origins) > 1, self.token, self.extra_origins)
            upstream = socket.create_connection((self.host, self.upstream_port))
            self._track(upstream)
            upstream.sendall(relayed)
            response, rest = _read_head(upstream)
            client.sendall(response + rest)
            if response.split(b" ", 2)[1:2] != [b"101"]:
                why = why or "not a WebSocket connection"
            if why:
                self.log.warning("view connection %d (Origin %s): goals refused, %s; it may view", number,
                                 origin or "none", why)
            else:
                upstream.sendall(self.admit_frame)
                self.log.info("view connection %d (Origin %s): may send goals", number, origin or "none")
            if early:
                upstream.sendall(early)
            client.settimeout(None)
            self._relay(client, upstream)
        except (OSError, ValueError) as exc:
            if not self._stopped.is_set():
                self.log.info("view connection %d ended: %s", number, exc)
        finally:
            for sock in (client, upstream):
                if sock is not None:
                    self._untrack(sock)
                    sock.close()

    def _relay(self, a: socket.socket, b: socket.socket) -> None:
        with selectors.DefaultSelector() as selector:
            selector.register(a, selectors.EVENT_READ, b)
            selector.register(b, selectors.EVENT_READ, a)
            while not self._stopped.is_set():
                for key, _ in selector.select(timeout=0.5):
                    data = key.fileobj.recv(65536)
                    if not data:
                        return
                    key.data.sendall(data)

    def _track(self, sock: socket.socket) -> None:
        with self._lock:
            self._open.add(sock)

    def _untrack(self, sock: socket.socket) -> None:
        with self._lock:
            self._open.discard(sock)

    def stop(self) -> None:
        self._stopped.set()
        self._acceptor.join()
        self.listener.close()
        with self._lock:
            for sock in self._open:
                try:
                    sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
            threads = list(self._threads)
        for thread in threads:
            thread.join()


def admit_message(param_name: str, secret: str) -> bytes:
    """The setParameters message the door sends for an admitted connection (Foxglove WebSocket protocol)."""
    return json.dumps({"op": "setParameters", "parameters": [{"name": param_name, "value": secret}]}).encode()
