"""The ROS 2 bridge as a service: omninav's bus on one side, a ROS 2 robot's rmw_zenoh router on the other.

omninav side (a Node like every service, so `up` grants it exactly this): it puts sim/clock, scan,
odom, goal and initialpose (what the robot's sensors and a ROS user's requests become) and subscribes
to cmd_vel (the collision monitor's output: the bridge takes the chassis's place), map, pose, plan
and tf/map_odom, all sporadic.
ROS side (a second Zenoh session, a client of the robot's router, loopback only, without omninav's
credentials): one ROS node with a subscription per input topic and a publisher per output topic,
each announced by its liveliness token as rmw_zenoh does (rmw.py), so `ros2 topic list` and
`ros2 node list` on the robot show them. Transient-local topics use Zenoh's advanced publisher and
subscriber as rmw_zenoh does: /tf_static sent before the bridge started still reaches it, and /map
reaches an RViz that starts later. ROS samples wait in an inbox that the node drains on its
own thread (it is paced like a source), so the Node's state is touched by one thread only.

Before it declares anything on the robot's graph the bridge reads it (graph.py): a robot whose
rmw_zenoh is older than rmw.SUPPORTED_RMW_ZENOH is refused in one line, and a /cmd_vel subscriber of
the other type is warned about; tokens that appear later are read the same way.
No put to the robot ever blocks the node's thread (every publisher drops when its queue is full, as
rmw_zenoh's KEEP_LAST ones do), and /cmd_vel goes on a higher Zenoh priority, express, so a large
/map over a slow link queues behind it, never in front: publisher_options.
"""
from __future__ import annotations

import json
import queue
import threading
from collections.abc import Callable

import zenoh
from zenoh.ext import (CacheConfig, HistoryConfig, MissDetectionConfig, RecoveryConfig, declare_advanced_publisher,
                       declare_advanced_subscriber)

from ..runtime.live import LiveRunner
from ..runtime.node import Node
from ..runtime.zenoh_config import (check_loopback, checked_login_config, foreign_client_config, login_endpoints,
                                   login_refused)
from .graph import cmd_vel_type_warning, graph_selectors, older_rmw_zenoh, refusal
from .translate import INPUTS, Bridge, Ros2BridgeParams, RosTopic
from .rmw import (PUBLISHER, RELIABLE, SUBSCRIPTION, TRANSIENT_LOCAL, NodeIdentity, entity_gid, pack_attachment,
                  publishing, topic_key, unpack_attachment)

POLL_S = 0.01       # wall s between drains of the ROS inbox (a source's pace: it adds at most this latency)
RETRY_S = 1.0       # wall s between attempts to reach the robot's router
GRAPH_S = 5.0       # wall s at most for the robot's router to answer for its graph (it answers at once)


REFUSALS = 3        # attempts in a row that the robot's router accepts over tcp but not in Zenoh: a refused login


class LoginRefused(Exception):
    """The robot's router is there but does not let the bridge in (credentials or certificates)."""


class OlderRmwZenoh(Exception):
    """The robot runs an rmw_zenoh older than the bridge speaks (graph.refusal: one line)."""


def robot_graph(ros: zenoh.Session, domain: int) -> list[str]:
    """The liveliness tokens of the robot's graph now (graph.graph_selectors)."""
    return [str(reply.ok.key_expr) for selector in graph_selectors(domain)
            for reply in ros.liveliness().get(selector, timeout=GRAPH_S) if reply.ok is not None]


def refuse_older_peer(tokens: list[str]) -> None:
    """OlderRmwZenoh naming the first token that shows an older rmw_zenoh, if any does."""
    for token in tokens:
        reason = older_rmw_zenoh(token)
        if reason is not None:
            raise OlderRmwZenoh(refusal(reason))


# Zenoh's priorities: /cmd_vel above the default one every other output (and rmw_zenoh) uses
URGENT_PRIORITY = zenoh.Priority.INTERACTIVE_HIGH


def publisher_options(topic: RosTopic) -> dict:
    """declare_advanced_publisher's options for one of the bridge's outputs: rmw_zenoh's for its QoS
    (rmw.publishing: DROP unless reliable keep-all, which the bridge never uses; a transient-local
    topic's cache, announced, and its heartbeat), and for an urgent one (/cmd_vel) a higher priority,
    express: Zenoh keeps a queue per priority and sends the higher first, so a large /map (fragmented,
    on the default priority) is never in front of a command, and a full queue drops rather than
    blocks the node's one thread."""
    how = publishing(topic.qos)
    options = dict(
        congestion_control=zenoh.CongestionControl.BLOCK if how.block else zenoh.CongestionControl.DROP,
        reliability=zenoh.Reliability.RELIABLE if how.reliable else zenoh.Reliability.BEST_EFFORT,
        priority=URGENT_PRIORITY if topic.urgent else zenoh.Priority.DEFAULT, express=topic.urgent,
        publisher_detection=how.cache_depth is not None)
    if how.cache_depth is not None:
        options["cache"] = CacheConfig(max_samples=how.cache_depth)
    if how.heartbeat_s is not None:
        options["sample_miss_detection"] = MissDetectionConfig(heartbeat=None, sporadic_heartbeat=how.heartbeat_s)
    return options


def ros_login(p: Ros2BridgeParams) -> zenoh.Config | None:
    """The login the parameters give (checked_login_config: ValueError naming what is wrong), or None."""
    if not (p.ros_zenoh_config or p.ros_user or p.ros_password_file):
        return None
    return checked_login_config(p.ros_zenoh_config or None, p.ros_user or None, p.ros_password_file or None)


def ros_endpoints(p: Ros2BridgeParams) -> list[str]:
    login = ros_login(p)
    return (login_endpoints(login) if login is not None else []) or [check_loopback(p.ros_router)]


def ros_session_config(p: Ros2BridgeParams) -> zenoh.Config:
    """A client of the robot's router, logged in as the parameters say, that gives up after RETRY_S if
    it does not answer; samples carry timestamps, as in rmw_zenoh's sessions (Zenoh's advanced
    publisher, for transient-local topics, orders by them)."""
    conf = foreign_client_config(p.ros_router, ros_login(p))
    conf.insert_json5("timestamping/enabled", "true")
    conf.insert_json5("connect/timeout_ms", json.dumps(round(RETRY_S * 1000)))    # give up, to be retried
    return conf


def who(p: Ros2BridgeParams) -> str:
    if p.ros_zenoh_config:
        return f"with {p.ros_zenoh_config}" + (f" as user {p.ros_user}" if p.ros_user else "")
    return f"as user {p.ros_user}" if p.ros_user else "without credentials"


def open_ros_session(p: Ros2BridgeParams, stopped: Callable[[], bool],
                     waiting: Callable[[], None] = lambda: None) -> zenoh.Session | None:
    """A session with the robot's router, tried until it opens (None once stopped() is true; waiting()
    after each attempt that found no router). LoginRefused, one line, when the router accepts the
    connection but refuses the session REFUSALS times in a row."""
    conf, endpoints, refusals = ros_session_config(p), ros_endpoints(p), 0
    while not stopped():
        try:
            return zenoh.open(conf)
        except zenoh.ZError:
            if not login_refused(endpoints):
                refusals = 0
                waiting()
                continue
            refusals += 1
            if refusals >= REFUSALS:
                raise LoginRefused(f"the robot's router at {', '.join(endpoints)} refused the bridge's login "
                                   f"({who(p)})") from None
    return None


def _bytes(attachment: zenoh.ZBytes | None) -> bytes:
    return b"" if attachment is None else attachment.to_bytes()


def declare_ros_subscription(ros: zenoh.Session, me: NodeIdentity, entity_id: int, topic: RosTopic, type_hash: str,
                             on_sample: Callable[[bytes, bytes], None]) -> list:
    """A subscription of node `me`, as rmw_zenoh's: its subscriber on the topic's data key, calling
    on_sample(CDR payload, attachment or b"") on Zenoh's thread for the robot's samples only (not what
    this process itself puts on /tf), and its liveliness token. Returns both, to undeclare."""
    latched = topic.qos.durability == TRANSIENT_LOCAL
    # as rmw_zenoh's transient-local subscriptions: ask late-detected publishers' caches for what they
    # sent before (robot_state_publisher's /tf_static, sent once at its start), and, reliable, fetch a
    # last sample that their heartbeat says was missed
    history = HistoryConfig(detect_late_publishers=True, max_samples=topic.qos.depth) if latched else None
    recovery = (RecoveryConfig(periodic_queries=None, heartbeat=True)
                if latched and topic.qos.reliability == RELIABLE else None)
    subscriber = declare_advanced_subscriber(
        ros, topic_key(me.domain, topic.name, topic.msgtype, type_hash),
        lambda sample: on_sample(sample.payload.to_bytes(), _bytes(sample.attachment)),
        allowed_origin=zenoh.Locality.REMOTE, history=history, recovery=recovery, subscriber_detection=latched)
    token = me.entity_token(entity_id, SUBSCRIPTION, topic.name, topic.msgtype, type_hash, topic.qos)
    return [subscriber, ros.liveliness().declare_token(token)]


class Ros2BridgeNode(Node):
    service = "ros2_bridge"
    Params = Ros2BridgeParams

    def setup(self) -> None:
        p = self.params
        check_loopback(p.ros_router)
        ros_login(p)        # refuses a login config that opens more than loopback, naming the key
        self.refused: str | None = None
        if p.domain < 0:
            raise ValueError(f"{self.name}: domain must be a ROS domain id ≥ 0, got {p.domain}")
        self.bridge = Bridge(p)
        # (topic, CDR payload, rmw_zenoh attachment or b"")
        self.inbox: queue.SimpleQueue[tuple[RosTopic, bytes, bytes]] = queue.SimpleQueue()
        self._last_seq: dict[bytes, int] = {}      # a ROS publisher's GID -> its last sequence number
        # liveliness tokens that appeared on the robot's graph, read on the node's thread (read_graph_token)
        self.graph_inbox: queue.SimpleQueue[str] = queue.SimpleQueue()
        self.stopping = threading.Event()         # run_live's stop: a refusal sets it
        # (ROS topic, CDR payload, stamp_ns) -> the robot; set by the ROS session (or a test)
        self.ros_sink: Callable[[RosTopic, bytes, int], None] | None = None
        self._reported: set[str] = set()
        self.to_stack = {name: self.publisher(name) for name in ("sim/clock", "scan", "odom", "goal", "initialpose")}
        self.cmd_vel = next(topic for topic in self.bridge.outputs if topic.omninav == "cmd_vel")
        for topic in self.bridge.outputs:
            self.subscribe(topic.omninav, lambda msg, t=topic: self._to_robot(t, msg), synced=False)

    def pace_s(self) -> float:
        return POLL_S

    def tick(self) -> None:
        while not self.graph_inbox.empty():
            self.read_graph_token(self.graph_inbox.get_nowait(), self.stopping)
        while True:
            try:
                topic, payload, attachment = self.inbox.get_nowait()
            except queue.Empty:
                return
            self.from_robot(topic, payload, attachment)

    def from_robot(self, topic: RosTopic, payload: bytes, attachment: bytes = b"") -> None:
        """One ROS sample into the stack (a sample that does not decode is counted and logged once)."""
        key = f"ros2{topic.name}"     # how counters and logs name a ROS topic
        self.counters[f"received/{key}"] += 1
        self._count_lost(key, attachment)
        try:
            pairs = self.bridge.from_ros(topic, payload)
        except Exception as exc:    # rosbags raises several kinds on a bad payload
            self.handler_failed(key, exc)
            return
        for problem in self.bridge.problems:
            if problem not in self._reported:
                self._reported.add(problem)
                self.log.error("%s", problem)
        for name, msg in pairs:
            self.now_ns = max(self.now_ns, msg.header.stamp_ns)
            self.to_stack[name].publish(msg)

    def _count_lost(self, key: str, attachment: bytes) -> None:
        """Samples a ROS publisher numbered but that never came (as rmw_zenoh's message-lost event);
        one without rmw_zenoh's attachment (which rmw_zenoh itself would drop) is taken, and counted."""
        try:
            seq, _, gid = unpack_attachment(attachment)
        except ValueError:
            self.counters[f"no_attachment/{key}"] += 1
            return
        last = self._last_seq.get(gid)
        if last is not None and seq > last + 1:
            self.counters[f"lost/{key}"] += seq - last - 1
        self._last_seq[gid] = seq

    def _to_robot(self, topic: RosTopic, msg) -> None:
        sink = self.ros_sink        # once: a refusal on Zenoh's thread may clear it meanwhile
        if sink is not None:
            sink(topic, self.bridge.to_ros(topic, msg), msg.header.stamp_ns)
            self.counters[f"sent/ros2{topic.name}"] += 1

    def diagnostic(self):
        diag = super().diagnostic()
        diag.values.update(self.bridge.counts)
        return diag

    def run_live(self, router: str | None, stop_event: threading.Event) -> None:
        """omninav's side on this thread; the robot's side joined on another as soon as its router
        answers, and left only after the last omninav input was handled."""
        runner = LiveRunner(self, router)
        runner.stops_with(stop_event)       # `omninav run`'s signal handlers set this one
        self.stopping = stop_event
        finished = threading.Event()
        robot = threading.Thread(target=self._join_robot, args=(stop_event, finished), name="ros2-session")
        robot.start()
        try:
            runner.run()
        finally:
            finished.set()
            robot.join()
        if self.refused:
            raise SystemExit(f"{self.name}: {self.refused}")

    def _join_robot(self, stop: threading.Event, finished: threading.Event) -> None:
        p, told = self.params, []

        def waiting() -> None:
            if not told:
                told.append(True)
                self.log.warning("waiting for the robot's router at %s (rmw_zenohd)", ", ".join(ros_endpoints(p)))
            stop.wait(RETRY_S)
        try:
            ros = open_ros_session(p, stop.is_set, waiting)
        except LoginRefused as exc:     # the omninav side stops too: no /cmd_vel without the robot's consent
            self.refused = str(exc)
            stop.set()
            return
        if ros is None:
            return
        with ros:
            try:
                handles = self._declare_ros(ros)
            except OlderRmwZenoh as exc:     # nothing declared yet: no /cmd_vel ever went out
                self.refused = str(exc)
                stop.set()
                return
            self.log.info("on the robot's ROS 2 graph (domain %d, router %s) as node %s", p.domain,
                          ", ".join(ros_endpoints(p)), p.node_name)
            finished.wait()
            self.ros_sink = None
            for handle in handles:
                handle.undeclare()

    def _declare_ros(self, ros: zenoh.Session) -> list:
        """The bridge's node on the robot's graph, once that graph shows a robot it can drive
        (OlderRmwZenoh if not), with a watch on the tokens that come later."""
        p = self.params
        # watched from before the graph is read, so that no token falls between the two (a refusal
        # leaves them to the session's close); read on the node's thread, as every ROS sample
        handles = [ros.liveliness().declare_subscriber(selector, self._queue_token)
                   for selector in graph_selectors(p.domain)]
        tokens = robot_graph(ros, p.domain)
        refuse_older_peer(tokens)
        for token in tokens:
            self._warn_cmd_vel_type(token)
        me = NodeIdentity(p.domain, str(ros.info.zid()), p.node_name, p.namespace)
        handles.append(ros.liveliness().declare_token(me.node_token()))
        publishers = {}
        for entity_id, topic in enumerate((*INPUTS, *self.bridge.outputs), start=me.nid + 1):
            type_hash = self.bridge.store.hash_rihs01(topic.msgtype)
            if topic in INPUTS:
                handles += declare_ros_subscription(
                    ros, me, entity_id, topic, type_hash,
                    lambda payload, attachment, t=topic: self.inbox.put((t, payload, attachment)))
                continue
            token = me.entity_token(entity_id, PUBLISHER, topic.name, topic.msgtype, type_hash, topic.qos)
            publishers[topic.name] = (declare_advanced_publisher(
                ros, topic_key(p.domain, topic.name, topic.msgtype, type_hash), **publisher_options(topic)),
                entity_gid(token), [0])
            handles += [publishers[topic.name][0], ros.liveliness().declare_token(token)]

        def sink(topic: RosTopic, payload: bytes, stamp_ns: int) -> None:
            publisher, gid, seq = publishers[topic.name]
            seq[0] += 1
            publisher.put(payload, attachment=pack_attachment(seq[0], stamp_ns, gid))
        if not self.refused:        # an older rmw_zenoh may have joined meanwhile (read_graph_token)
            self.ros_sink = sink
        return handles

    def _queue_token(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:     # a token that appears; not one that goes
            self.graph_inbox.put(str(sample.key_expr))

    def read_graph_token(self, token: str, stop: threading.Event) -> None:
        """A token that appeared on the robot's graph: an older rmw_zenoh that joins later stops the
        bridge at once, as one there from the start would have."""
        reason = older_rmw_zenoh(token)
        if reason is None:
            self._warn_cmd_vel_type(token)
        elif not self.refused:
            self.ros_sink = None        # no command after this one
            self.refused = refusal(reason)      # run_live ends with it: one line
            stop.set()

    def _warn_cmd_vel_type(self, token: str) -> None:
        warning = cmd_vel_type_warning(token, self.cmd_vel)
        if warning is not None and warning not in self._reported:
            self._reported.add(warning)
            self.log.warning("%s", warning)
