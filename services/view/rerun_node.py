"""The Rerun view (`omninav view --rerun`): the running stack in a browser, in Rerun's web viewer
served from this machine (nothing to install beyond omninav; the page and its Wasm come from
rerun-sdk's wheel, nothing is fetched from the internet).

rerun-sdk 0.41's in-process servers listen on every interface (`serve_web_viewer` takes no bind
address), so the view runs the `rerun` binary that ships with rerun-sdk as its child, bound to
127.0.0.1: it serves the viewer page on `port` and, on `grpc_port`, a proxy that keeps what was
logged (up to its memory limit), so a browser opened late still gets the map. The node subscribes
to the keys of RERUN_ROUTES (none synced: a viewer never holds anything up), converts each message
(rerun_scene.py, the same as `omninav export --rerun`) and logs it to the proxy. Nothing a browser
does reaches the bus. The child dies with the view, even a killed one (PR_SET_PDEATHSIG).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

import rerun as rr
import rerun_cli

from ..runtime.joining import listening as endpoint_listening
from ..runtime.node import Node
from ..runtime.zenoh_config import free_loopback_port
from .bus import follow_the_bus
from .convert import Converter, Route, RouteTable, ViewParams
from .rerun_scene import APPLICATION_ID, RERUN_ROUTES, blueprint, log_at, log_static
from ...parameters.declare import param

LOOPBACK = "127.0.0.1"
SERVER_START_S = 60.0       # wall s the rerun binary has to listen (a loaded 2-core machine)
SERVER_STOP_S = 10.0
RERUN_BINARY = Path(rerun_cli.__file__).with_name("rerun")
# run in a fresh interpreter before exec'ing the binary: the kernel then stops the binary when the
# view ends, however it ends; without preexec_fn, which may deadlock in a process that has threads
_DIE_WITH_PARENT = ("import ctypes, os, signal, sys\n"
                    "ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG\n"
                    "if os.getppid() != int(sys.argv[1]): sys.exit(1)  # the parent ended before prctl\n"
                    "os.execv(sys.argv[2], sys.argv[2:])\n")


@dataclass(frozen=True)
class RerunViewParams(ViewParams):
    port: int = param(9090, ge=0, le=65535)        # the viewer page on 127.0.0.1 (0: any free port)
    grpc_port: int = param(9876, ge=0, le=65535)   # the proxy the page and the node connect to (0: any free port)
    grid_period_s: float = param(1.0, ge=0)        # sim time between two publications of one grid, at least


def listening(port: int) -> bool:
    """Whether anything accepts a connection on this port of 127.0.0.1."""
    return endpoint_listening(f"tcp/{LOOPBACK}:{port}")


def viewer_url(web_port: int, grpc_url: str) -> str:
    return f"http://{LOOPBACK}:{web_port}/?url={quote(grpc_url, safe='')}"


class RerunServer:
    """The `rerun` binary serving the web viewer and its gRPC proxy on loopback ports, as a child."""

    def __init__(self, web_port: int, grpc_port: int, stopped=lambda: False):
        self.web_port, self.grpc_port = web_port or free_loopback_port(), grpc_port or free_loopback_port()
        self.grpc_url = f"rerun+http://{LOOPBACK}:{self.grpc_port}/proxy"
        self.url = viewer_url(self.web_port, self.grpc_url)
        taken = [port for port in (self.web_port, self.grpc_port) if listening(port)]
        if taken:       # else another program's server there would pass for the binary's below
            raise RuntimeError(f"{LOOPBACK}:{taken[0]} is taken (--port, --grpc-port choose others)")
        command = [str(RERUN_BINARY), "--serve-web", "--bind", LOOPBACK, "--port", str(self.grpc_port),
                   "--web-viewer-port", str(self.web_port), "--hide-welcome-screen"]
        self.proc = subprocess.Popen([sys.executable, "-c", _DIE_WITH_PARENT, str(os.getpid()), *command],
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     env={**os.environ, "RUST_LOG": "warn"},    # its errors on our stderr
                                     # not stopped by a Ctrl-C to the view's group before the view has
                                     # flushed to it; it stops when the view stops it, or dies
                                     start_new_session=True)
        deadline = time.monotonic() + SERVER_START_S
        while not (listening(self.web_port) and listening(self.grpc_port)):
            if self.proc.poll() is not None or stopped() or time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"the rerun binary did not serve on {LOOPBACK}:{self.web_port} and "
                                   f":{self.grpc_port} (a port taken? its own message is above)")
            time.sleep(0.1)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(SERVER_STOP_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


class RerunViewNode(Node):
    service = "rerun_view"
    Params = RerunViewParams

    def setup(self) -> None:
        self.converter = Converter(self.params, self.params.grid_period_s)
        self.routes = RouteTable(self.keys, RERUN_ROUTES)
        self.recording: rr.RecordingStream | None = None    # none until run_live: `replay --into` converts only
        self.server: RerunServer | None = None
        for route in RERUN_ROUTES:
            self.subscribe(self.routes.key_expr(route), lambda msg, route=route: self.show(route, msg), synced=False)

    def show(self, route: Route, msg) -> None:
        outputs = self.converter.outputs(route, msg)
        if self.recording is not None:
            log_at(self.recording, msg.header.stamp_ns, outputs)

    def start_server(self, stopped=lambda: False) -> None:
        """The binary's servers, this node's stream to them, and the URL to open, printed."""
        self.server = RerunServer(self.params.port, self.params.grpc_port, stopped)
        self.recording = rr.RecordingStream(APPLICATION_ID, recording_id=str(uuid.uuid4()))
        self.recording.connect_grpc(self.server.grpc_url, default_blueprint=blueprint())
        log_static(self.recording)
        self.log.info("Rerun web viewer on http://%s:%d, gRPC proxy on %s", LOOPBACK, self.server.web_port,
                      self.server.grpc_url)
        print(f"view: open {self.server.url}", flush=True)

    def run_live(self, router: str | None, stop_event: threading.Event) -> None:
        """Serve the viewer while the bus is followed; the servers live only as long as the live run."""
        try:
            self.start_server(stop_event.is_set)
        except RuntimeError as exc:
            raise SystemExit(f"view: {exc}") from None
        follow_the_bus(self, router, stop_event)

    def close(self) -> None:
        if self.recording is not None:
            try:
                self.recording.flush(timeout_sec=SERVER_STOP_S)
            except RuntimeError as exc:     # the binary is gone (killed): nothing more to hand it
                self.log.warning("the rerun binary did not take the last messages: %s", exc)
            self.recording.disconnect()
            self.recording = None
        if self.server is not None:
            self.server.stop()
            self.server = None
