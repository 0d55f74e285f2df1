"""`omninav bench recorder`: how many small messages/s the recorder writes with nothing lost.

A publisher in its own process sends N Chatter messages as fast as it can (congestion control
BLOCK) through a loopback router, alternately to the recorder (writing MCAP to a temporary
directory) and, as the reference in the same run, to a bare subscriber that only counts. A rate is
N / (time the last message was written or counted - time the first was sent); rates are medians
over the repeats, `lost` is the most any run lost (messages that never arrived, or seq gaps).
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import zenoh

from ..schemas.attachment import pack_attachment
from ..schemas.codec import encode
from ..schemas.keys import KeyLayout
from ..schemas.messages import Chatter, Header
from ..schemas.registry import type_info
from ..services.runtime.zenoh_config import free_loopback_endpoint, open_client, open_router
from ..services.recorder.node import RecorderNode, RecorderParams

KEY = KeyLayout().robot("chatter")
_SETTLE_S = 3.0     # no progress for this long = the rest is lost
_NOTHING_S = 30.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--messages", type=int, default=100_000, metavar="N", help="messages per run (default 100000)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each receiver (default 3)")


def publish(router: str, n: int) -> None:
    """The publisher process: wait for a subscriber, send n messages, print when sending started."""
    payload = encode(Chatter(header=Header(stamp_ns=1, frame_id="bench"), text="hello 1", value=0.5))
    type_name = type_info(Chatter)[0]
    attachments = [pack_attachment(seq, seq, type_name) for seq in range(1, n + 1)]
    with open_client(router) as session:
        pub = session.declare_publisher(KEY, congestion_control=zenoh.CongestionControl.BLOCK,
                                        reliability=zenoh.Reliability.RELIABLE)
        while not pub.matching_status.matching:
            time.sleep(0.01)
        time.sleep(0.2)     # let the router finish routing to the new subscriber
        start_ns = time.time_ns()
        for attachment in attachments:
            pub.put(payload, attachment=attachment)
        print(start_ns, flush=True)
        sys.stdin.read()    # stay connected until the parent has counted (closing may drop queued data)


def _measure(router: str, n: int, received) -> tuple[float, int]:
    """Run one publisher against a receiver whose progress `received()` reports; (msgs/s, lost)."""
    proc = subprocess.Popen([sys.executable, "-m", __name__, router, str(n)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        last, progress_at = -1, time.monotonic()
        while True:
            count = received()
            now = time.monotonic()
            if count >= n:
                done_ns = time.time_ns()
                break
            if count != last:
                last, progress_at = count, now
            elif last > 0 and now - progress_at > _SETTLE_S:
                done_ns = time.time_ns()
                break
            elif now - progress_at > _NOTHING_S:
                raise RuntimeError(f"nothing arrived in {_NOTHING_S:.0f} s")
            if proc.poll() not in (None, 0):
                raise RuntimeError(f"the publisher process failed with exit code {proc.returncode}")
            time.sleep(0.001)
        proc.stdin.close()
        start_ns = int(proc.stdout.readline())
    finally:
        if proc.poll() is None:
            proc.terminate()
        proc.wait(10)
    return count * 1e9 / (done_ns - start_ns), n - count


def recorder_run(router: str, n: int, path: Path) -> tuple[float, int]:
    node = RecorderNode(RecorderParams(output=str(path), keys=(KEY,)))
    stop = threading.Event()
    thread = threading.Thread(target=node.record, args=(router, stop), daemon=True)
    thread.start()
    try:
        rate, lost = _measure(router, n, lambda: node.tally.total)
    finally:
        stop.set()
        thread.join(30)
    if node.tally.lost > lost:
        lost = node.tally.lost
    return rate, lost


def reference_run(router: str, n: int) -> tuple[float, int]:
    """A bare subscriber: takes samples the way the recorder does and only counts them."""
    count = [0]
    stop = threading.Event()
    with open_client(router) as session:
        sub = session.declare_subscriber(KEY, zenoh.handlers.FifoChannel(16384))

        def drain():
            while not stop.is_set():
                if sub.try_recv() is None:
                    time.sleep(0.002)
                else:
                    count[0] += 1

        thread = threading.Thread(target=drain, daemon=True)
        thread.start()
        try:
            return _measure(router, n, lambda: count[0])
        finally:
            stop.set()
            thread.join(10)
            sub.undeclare()


def main(args: argparse.Namespace) -> int:
    if args.messages <= 0 or args.repeats <= 0:
        print("--messages and --repeats must be positive", file=sys.stderr)
        return 2
    router = free_loopback_endpoint()
    recorded, reference = [], []
    with open_router(router), tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeats):
            recorded.append(recorder_run(router, args.messages, Path(tmp) / f"bench{i}.mcap"))
            reference.append(reference_run(router, args.messages))
    figures = {
        "messages": args.messages,
        "repeats": args.repeats,
        "msgs_per_s": round(statistics.median(r for r, _ in recorded)),
        "lost": max(lost for _, lost in recorded),
        "reference_msgs_per_s": round(statistics.median(r for r, _ in reference)),
        "reference_lost": max(lost for _, lost in reference),
    }
    if args.json:
        print(json.dumps(figures))
    else:
        print(f"recorder: {figures['msgs_per_s']} msgs/s (median of {args.repeats} runs of {args.messages}), "
              f"lost {figures['lost']} (most in any run)")
        print(f"reference (bare subscriber that only counts): {figures['reference_msgs_per_s']} msgs/s, "
              f"lost {figures['reference_lost']}")
    return 0


if __name__ == "__main__":
    publish(sys.argv[1], int(sys.argv[2]))
