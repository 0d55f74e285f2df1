"""`omninav bench transport`: the bus between two separate processes through a loopback router.

This process runs the router and the measuring client; it starts a peer process (this module with
the hidden `--role peer`) that echoes scans, counts small messages and answers grid queries. Each
figure is measured twice in the same run, interleaved: through the omninav codec (encode, publish
with the attachment, decode on the other side) and with raw bytes of the same size (the reference),
so the codec's share is visible. Wall time is what a benchmark measures.
"""
from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import zenoh

from ..schemas.attachment import pack_attachment
from ..schemas.codec import decode, encode
from ..schemas.keys import KeyLayout
from ..schemas.messages import Chatter, Header, LaserScan, MapMetaData, OccupancyGrid
from ..schemas.registry import type_info
from ..services.runtime.acl import CREDENTIALS_ENV, Grants, access_control, write_credentials
from ..services.runtime.zenoh_config import client_config, free_loopback_endpoint, open_client, open_router

BEAMS = 360
GRID_CELLS = 2000
END = "end"                  # the Chatter text (or raw payload) that closes a throughput burst
_REPLY_TIMEOUT_S = 10.0      # a peer that does not answer within this is broken, not slow
_AIM_RTT_MS, _AIM_GRID_MS = 0.5, 10.0


# ---------------------------------------------------------------- what travels

@dataclass(frozen=True)
class Route:
    """The keys of one path; the codec and raw paths use separate robot namespaces of the layout."""
    ping: str
    pong: str
    burst: str
    ack: str
    grid: str

    @classmethod
    def of(cls, namespace: str) -> Route:
        there, back = KeyLayout(namespace), KeyLayout(namespace + "_back")
        return cls(there.robot("scan"), back.robot("scan"), there.robot("chatter"), back.robot("chatter"),
                   there.robot("map"))


CODEC, RAW = Route.of("bench"), Route.of("bench_raw")


def bench_scan() -> LaserScan:
    angles = np.linspace(-np.pi, np.pi, BEAMS, endpoint=False)
    return LaserScan(header=Header(frame_id="laser"), angle_min=-np.pi,
                     angle_max=np.pi - 2 * np.pi / BEAMS, angle_increment=2 * np.pi / BEAMS, scan_time=0.1,
                     range_min=0.1, range_max=12.0, ranges=(2.0 + np.sin(3 * angles)).astype("<f4"),
                     intensities=np.full(BEAMS, 100.0, dtype="<f4"))


def bench_chatter(seq: int, text: str = "bench") -> Chatter:
    return Chatter(header=Header(stamp_ns=seq, frame_id="bench", seq=seq), text=text, value=float(seq))


def bench_grid() -> OccupancyGrid:
    data = np.zeros((GRID_CELLS, GRID_CELLS), dtype="i1")
    data[::50, :] = 100
    data[:, :100] = -1
    return OccupancyGrid(header=Header(frame_id="map"),
                         info=MapMetaData(resolution=0.05, width=GRID_CELLS, height=GRID_CELLS), data=data)


def _put(pub: zenoh.Publisher, msg: Any) -> None:
    """Publish as every omninav publisher does: encoded payload plus the attachment."""
    pub.put(encode(msg), attachment=pack_attachment(msg.header.seq, msg.header.stamp_ns, type_info(type(msg))[0]))


def _publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    return session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK,
                                     reliability=zenoh.Reliability.RELIABLE)


# ---------------------------------------------------------------- the peer process

def _guarded(handler: Callable[[Any], None]) -> Callable[[Any], None]:
    """Zenoh swallows exceptions in callbacks; the peer prints them so a broken echo is visible."""
    def run(arg: Any) -> None:
        try:
            handler(arg)
        except Exception:
            traceback.print_exc(file=sys.stderr)
    return run


def run_peer(router: str) -> None:
    """Echo scans, count bursts, answer grid queries; print `ready`, run until stdin closes."""
    grid = bench_grid()
    raw_grid = encode(grid)  # the reference answers with bytes of the same size, never encoding
    counts = {CODEC.burst: 0, RAW.burst: 0}
    with open_client(router) as session:
        pubs = {key: _publisher(session, key) for key in (CODEC.pong, CODEC.ack, RAW.pong, RAW.ack)}

        def on_burst(sample: zenoh.Sample) -> None:
            msg = decode(sample.payload.to_bytes(), Chatter, key=CODEC.burst)
            if msg.text != END:
                counts[CODEC.burst] += 1
                return
            _put(pubs[CODEC.ack], bench_chatter(msg.header.seq, str(counts[CODEC.burst])))
            counts[CODEC.burst] = 0

        def on_raw_burst(sample: zenoh.Sample) -> None:
            if sample.payload.to_bytes() != END.encode():
                counts[RAW.burst] += 1
                return
            pubs[RAW.ack].put(str(counts[RAW.burst]).encode())
            counts[RAW.burst] = 0

        def on_grid(query: zenoh.Query) -> None:
            query.reply(CODEC.grid, encode(grid))  # encoded per query, as a node answers a get
            query.drop()

        def on_raw_grid(query: zenoh.Query) -> None:
            query.reply(RAW.grid, raw_grid)
            query.drop()

        def on_scan(sample: zenoh.Sample) -> None:
            _put(pubs[CODEC.pong], decode(sample.payload.to_bytes(), LaserScan, key=CODEC.ping))

        handles = [
            session.declare_subscriber(CODEC.burst, _guarded(on_burst)),
            session.declare_subscriber(RAW.burst, _guarded(on_raw_burst)),
            session.declare_queryable(CODEC.grid, _guarded(on_grid)),
            session.declare_queryable(RAW.grid, _guarded(on_raw_grid)),
            session.declare_subscriber(RAW.ping, _guarded(lambda s: pubs[RAW.pong].put(s.payload.to_bytes()))),
            session.declare_subscriber(CODEC.ping, _guarded(on_scan)),
        ]
        print("ready", flush=True)
        sys.stdin.read()  # the bench closes our stdin to stop us (also when it dies)
        for handle in handles:
            handle.undeclare()


# ---------------------------------------------------------------- the measuring side

class PeerError(RuntimeError):
    """The peer process did not start or stopped answering."""


class Client:
    """The measuring session: one publisher per key, replies (pongs, acks) handed over through queues."""

    def __init__(self, session: zenoh.Session):
        self.session = session
        self.pubs = {key: _publisher(session, key) for route in (CODEC, RAW) for key in (route.ping, route.burst)}
        self.inbox = {key: queue.SimpleQueue() for route in (CODEC, RAW) for key in (route.pong, route.ack)}
        self.subs = [session.declare_subscriber(key, lambda s, q=q: q.put(s.payload.to_bytes()))
                     for key, q in self.inbox.items()]

    def wait(self, key: str, timeout: float = _REPLY_TIMEOUT_S) -> bytes:
        try:
            return self.inbox[key].get(timeout=timeout)
        except queue.Empty:
            raise PeerError(f"no message on {key} from the peer within {timeout:g} s") from None

    def handshake(self, scan: LaserScan, tries: int = 40) -> None:
        """Ping until the peer answers: its declarations reach the router some time after it is ready.

        The peer declares its scan echo last, and the router handles one link's messages in order,
        so once a scan comes back every other path of the peer is known to the router too.
        """
        for _ in range(tries):
            _put(self.pubs[CODEC.ping], scan)
            try:
                self.inbox[CODEC.pong].get(timeout=0.25)
                break
            except queue.Empty:
                continue
        else:
            raise PeerError(f"the peer did not answer on {CODEC.ping}")
        time.sleep(0.3)  # answers to the pings that were not lost may still be on their way
        for q in self.inbox.values():
            while not q.empty():
                q.get_nowait()

    # -- (a) round trip

    def round_trip(self, scan: LaserScan) -> float:
        start = time.perf_counter()
        _put(self.pubs[CODEC.ping], scan)
        decode(self.wait(CODEC.pong), LaserScan, key=CODEC.pong)
        return time.perf_counter() - start

    def raw_round_trip(self, payload: bytes) -> float:
        start = time.perf_counter()
        self.pubs[RAW.ping].put(payload)
        self.wait(RAW.pong)
        return time.perf_counter() - start

    # -- (b) throughput

    def burst(self, count: int) -> tuple[float, int]:
        """(seconds until the peer has seen them all, how many it got)."""
        pub = self.pubs[CODEC.burst]
        start = time.perf_counter()
        for seq in range(1, count + 1):
            _put(pub, bench_chatter(seq))
        _put(pub, bench_chatter(count + 1, END))
        got = int(decode(self.wait(CODEC.ack), Chatter).text)
        return time.perf_counter() - start, got

    def raw_burst(self, count: int, size: int) -> tuple[float, int]:
        pub, payload = self.pubs[RAW.burst], bytes(size)
        start = time.perf_counter()
        for _ in range(count):
            pub.put(payload)
        pub.put(END.encode())
        got = int(self.wait(RAW.ack))
        return time.perf_counter() - start, got

    # -- (c) grid get

    def _get(self, key: str) -> bytes:
        for reply in self.session.get(key, timeout=_REPLY_TIMEOUT_S):
            if reply.ok is None:
                raise PeerError(f"{key}: error reply {reply.err.payload.to_bytes()!r}")
            return reply.ok.payload.to_bytes()
        raise PeerError(f"no reply on {key} within {_REPLY_TIMEOUT_S:g} s")

    def grid_get(self) -> float:
        start = time.perf_counter()
        decode(self._get(CODEC.grid), OccupancyGrid, key=CODEC.grid)
        return time.perf_counter() - start

    def raw_grid_get(self) -> float:
        start = time.perf_counter()
        self._get(RAW.grid)
        return time.perf_counter() - start

    def close(self) -> None:
        for handle in [*self.subs, *self.pubs.values()]:
            handle.undeclare()


def _start_peer(router: str, credentials: Path | None) -> subprocess.Popen:
    env = {**os.environ, **({CREDENTIALS_ENV: str(credentials)} if credentials else {})}
    peer = subprocess.Popen(
        [sys.executable, "-m", "omninav.cli.bench", "transport", "--role", "peer", "--router", router],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    line: list[str] = []
    reader = threading.Thread(target=lambda: line.append(peer.stdout.readline()), daemon=True)
    reader.start()
    reader.join(60)
    if not line or line[0].strip() != "ready":
        _stop_peer(peer)
        raise PeerError(f"the peer process did not start (exit code {peer.returncode})")
    return peer


def _stop_peer(peer: subprocess.Popen) -> None:
    try:
        peer.stdin.close()
        peer.wait(10)
    except (subprocess.TimeoutExpired, OSError):
        peer.kill()
        peer.wait()


def _ms(seconds: list[float], q: float = 50) -> float:
    return round(float(np.percentile(seconds, q)) * 1000, 4)


@dataclass(frozen=True)
class BenchSize:
    round_trips: int
    messages: int
    gets: int
    warmup: int


def measure(client: Client, size: BenchSize) -> dict:
    """All figures; the codec and raw variants alternate so that both see the same machine load."""
    scan = bench_scan()
    scan_bytes, chatter_bytes = len(encode(scan)), len(encode(bench_chatter(1)))
    raw_scan = bytes(scan_bytes)
    client.handshake(scan)
    for _ in range(size.warmup):
        client.round_trip(scan)
        client.raw_round_trip(raw_scan)
    client.burst(size.warmup)
    client.raw_burst(size.warmup, chatter_bytes)
    client.grid_get()
    client.raw_grid_get()

    rtt, rtt_raw = [], []
    for seq in range(1, size.round_trips + 1):
        scan.header.seq = scan.header.stamp_ns = seq
        rtt.append(client.round_trip(scan))
        rtt_raw.append(client.raw_round_trip(raw_scan))
    burst_s, got = client.burst(size.messages)
    raw_burst_s, raw_got = client.raw_burst(size.messages, chatter_bytes)
    grid, grid_raw = [], []
    for _ in range(size.gets):
        grid.append(client.grid_get())
        grid_raw.append(client.raw_grid_get())
    return {
        "rtt_median_ms": _ms(rtt), "rtt_p99_ms": _ms(rtt, 99),
        "rtt_raw_median_ms": _ms(rtt_raw), "rtt_raw_p99_ms": _ms(rtt_raw, 99),
        "round_trips": size.round_trips, "scan_bytes": scan_bytes,
        "msgs_per_s": round(size.messages / burst_s), "lost": size.messages - got,
        "msgs_raw_per_s": round(size.messages / raw_burst_s), "lost_raw": size.messages - raw_got,
        "messages": size.messages, "chatter_bytes": chatter_bytes,
        "grid_get_ms": _ms(grid), "grid_get_raw_ms": _ms(grid_raw),
        "gets": size.gets, "grid_bytes": len(encode(bench_grid())),
    }


def bench_grants() -> dict[str, Grants]:
    """The two identities of the bench under the ACL: each may use exactly its own keys."""
    routes = (CODEC, RAW)
    return {
        "bench": Grants(put=tuple(k for r in routes for k in (r.ping, r.burst)),
                        subscribe=tuple(k for r in routes for k in (r.pong, r.ack)), query=tuple(r.grid for r in routes)),
        "peer": Grants(put=tuple(k for r in routes for k in (r.pong, r.ack)),
                       subscribe=tuple(k for r in routes for k in (r.ping, r.burst)),
                       queryable=tuple(r.grid for r in routes)),
    }


def run_bench(size: BenchSize, acl: bool = False) -> dict:
    """The figures through a router without access control, or (acl) with user/password
    authentication and the deny-by-default ACL `omninav up` uses (acl.py)."""
    with tempfile.TemporaryDirectory(prefix="omninav-bench-") as folder:
        figures = _run_bench(size, Path(folder) if acl else None)
    return {**figures, "acl": acl}


def _run_bench(size: BenchSize, credentials: Path | None) -> dict:
    router = free_loopback_endpoint()
    grants = bench_grants()
    dictionary = write_credentials(credentials, grants) if credentials else None
    with open_router(router, dictionary, access_control(grants) if credentials else None):
        peer = _start_peer(router, credentials / "peer" if credentials else None)
        try:
            with open_client(router, str(credentials / "bench") if credentials else None) as session:
                client = Client(session)
                try:
                    figures = measure(client, size)
                finally:
                    client.close()
        finally:
            _stop_peer(peer)
    shm = json.loads(client_config(router).get_json("transport/shared_memory/enabled"))
    return {**figures, "shared_memory": shm, "zenoh": importlib.metadata.version("eclipse-zenoh"),
            "setup": "2 processes (bench + peer), router inside the bench process, tcp loopback"}


def report(fig: dict) -> str:
    def met(ok: bool) -> str:
        return "met" if ok else "NOT met"

    shm = "on" if fig["shared_memory"] else "off"
    acl = "with user/password authentication and ACL" if fig["acl"] else "no access control"
    return "\n".join([
        f"omninav bench transport: {fig['setup']}; zenoh {fig['zenoh']}, shared memory {shm}, {acl}",
        f"{'':44s}{'omninav codec':>16s}{'raw bytes (ref)':>18s}",
        f"{'LaserScan round trip, median':44s}{fig['rtt_median_ms']:13.3f} ms{fig['rtt_raw_median_ms']:15.3f} ms"
        f"   ({fig['round_trips']} round trips, {fig['scan_bytes']} B)",
        f"{'LaserScan round trip, p99':44s}{fig['rtt_p99_ms']:13.3f} ms{fig['rtt_raw_p99_ms']:15.3f} ms",
        f"{'Chatter throughput, congestion control BLOCK':44s}{fig['msgs_per_s']:12,d} /s"
        f"{fig['msgs_raw_per_s']:14,d} /s   ({fig['messages']} messages of {fig['chatter_bytes']} B)",
        f"{'  lost':44s}{fig['lost']:16d}{fig['lost_raw']:18d}",
        f"{'OccupancyGrid 2000x2000 get, median':44s}{fig['grid_get_ms']:13.2f} ms{fig['grid_get_raw_ms']:15.2f} ms"
        f"   ({fig['gets']} gets, {fig['grid_bytes'] / 1e6:.1f} MB)",
        f"aims: round trip median <= {_AIM_RTT_MS} ms {met(fig['rtt_median_ms'] <= _AIM_RTT_MS)}; "
        f"grid get <= {_AIM_GRID_MS:g} ms {met(fig['grid_get_ms'] <= _AIM_GRID_MS)}; "
        f"nothing lost {met(fig['lost'] == 0 and fig['lost_raw'] == 0)}",
    ])


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--round-trips", type=int, default=3000, metavar="N", help="scan round trips (default 3000)")
    parser.add_argument("--messages", type=int, default=50000, metavar="N", help="burst of small messages (default 50000)")
    parser.add_argument("--gets", type=int, default=20, metavar="N", help="grid gets (default 20)")
    parser.add_argument("--warmup", type=int, default=50, metavar="N", help="round trips and burst size before measuring")
    parser.add_argument("--acl", choices=("off", "on", "both"), default="off",
                        help="through a router with the ACL `up` uses; both: without, then with, and the cost")
    parser.add_argument("--role", choices=("bench", "peer"), default="bench", help=argparse.SUPPRESS)
    parser.add_argument("--router", help=argparse.SUPPRESS)


def main(args: argparse.Namespace) -> int:
    if args.role == "peer":
        run_peer(args.router)
        return 0
    counts = {"--round-trips": args.round_trips, "--messages": args.messages, "--gets": args.gets,
              "--warmup": args.warmup}
    bad = [name for name, n in counts.items() if n < 1]
    if bad:
        print(f"omninav bench transport: {', '.join(bad)} must be at least 1", file=sys.stderr)
        return 2
    size = BenchSize(args.round_trips, args.messages, args.gets, args.warmup)
    try:
        runs = [run_bench(size, acl) for acl in {"off": [False], "on": [True], "both": [False, True]}[args.acl]]
    except PeerError as exc:
        print(f"omninav bench transport: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(runs[0] if len(runs) == 1 else {"without_acl": runs[0], "with_acl": runs[1]}), flush=True)
        return 0
    print("\n\n".join(report(figures) for figures in runs), flush=True)
    if len(runs) == 2:
        print(acl_cost(*runs), flush=True)
    return 0


def acl_cost(without: dict, with_acl: dict) -> str:
    rtt = with_acl["rtt_median_ms"] - without["rtt_median_ms"]
    return (f"ACL cost: LaserScan round trip median {rtt:+.3f} ms ({without['rtt_median_ms']:.3f} -> "
            f"{with_acl['rtt_median_ms']:.3f} ms), p99 {without['rtt_p99_ms']:.3f} -> {with_acl['rtt_p99_ms']:.3f} ms; "
            f"throughput {without['msgs_per_s']:,d} -> {with_acl['msgs_per_s']:,d} /s; "
            f"grid get {without['grid_get_ms']:.2f} -> {with_acl['grid_get_ms']:.2f} ms")
