"""The lockstep barrier (services/runtime/lockstep.py): when the simulator may take its next step."""
from __future__ import annotations

from omninav.schemas.codec import decode, encode
from omninav.schemas.messages import Diagnostic
from omninav.services.runtime.lockstep import Barrier, Lockstep, Report, matches

CLOCK, SCAN, ODOM, CMD = "omninav/sim/clock", "omninav/r1/scan", "omninav/r1/odom", "omninav/r1/cmd_vel"
SIM_OUT = {CLOCK: 5}
SIM_IN = (CMD,)


def report(name: str, received: dict, published: dict, subscribed=(), run: int = 1, hold: bool = False) -> Report:
    return Report(name, run, tuple(subscribed) or tuple(received), received, published, hold)


def barrier_with(*reports: Report, wait_for=()) -> Barrier:
    barrier = Barrier(tuple(wait_for))
    for one in reports:
        barrier.update(one)
    return barrier


def test_a_report_survives_the_wire():
    sent = report("lidar", {CLOCK: 3}, {SCAN: 2}, hold=True)
    back = Report.from_message(decode(encode(sent.to_message(7)), Diagnostic))
    assert back == sent


def test_the_step_waits_until_every_subscriber_has_every_published_message():
    lidar = report("lidar", {CLOCK: 5}, {SCAN: 5})
    planner = report("planner", {SCAN: 4}, {CMD: 4}, subscribed=(SCAN,))
    barrier = barrier_with(lidar, planner)
    assert barrier.ready(SIM_OUT, {CMD: 4}, SIM_IN)           # admits both: each had all there was
    barrier.update(report("planner", {SCAN: 4}, {CMD: 4}, subscribed=(SCAN,)))
    assert not barrier.ready(SIM_OUT, {CMD: 4}, SIM_IN)       # scan 5 is still on its way to the planner
    assert barrier.waiting_on(SIM_OUT) == ["planner"]
    barrier.update(report("planner", {SCAN: 5}, {CMD: 5}, subscribed=(SCAN,)))
    assert not barrier.ready(SIM_OUT, {CMD: 4}, SIM_IN)       # the sim has not taken command 5 yet
    assert barrier.ready(SIM_OUT, {CMD: 5}, SIM_IN)


def test_the_first_step_waits_for_the_named_services():
    barrier = barrier_with(report("lidar", {}, {}), wait_for=("lidar", "planner"))
    assert not barrier.ready({}, {}, SIM_IN)
    assert barrier.waiting_on({}) == ["planner (not started)"]
    barrier.update(report("planner", {}, {}, subscribed=(SCAN,)))
    assert barrier.ready({}, {}, SIM_IN)
    barrier.leave("planner")                    # once under way, one that left is not waited for
    assert barrier.ready({}, {}, SIM_IN)


def test_a_joiner_waits_only_for_what_was_published_after_it_joined():
    barrier = barrier_with(report("lidar", {CLOCK: 5}, {SCAN: 5}))
    assert barrier.ready(SIM_OUT, {}, SIM_IN)
    barrier.update(report("late", {}, {}, subscribed=(SCAN,)))
    assert barrier.ready(SIM_OUT, {}, SIM_IN)                 # scans 1..5 went out before it subscribed
    barrier.update(report("lidar", {CLOCK: 6}, {SCAN: 6}))
    assert not barrier.ready({CLOCK: 6}, {}, SIM_IN)          # scan 6 it must have
    barrier.update(report("late", {SCAN: 6}, {}, subscribed=(SCAN,)))
    assert barrier.ready({CLOCK: 6}, {}, SIM_IN)


def test_a_restarted_participant_is_admitted_afresh_and_a_gone_one_is_not_waited_for():
    barrier = barrier_with(report("lidar", {CLOCK: 5}, {SCAN: 5}), report("planner", {SCAN: 5}, {}))
    assert barrier.ready(SIM_OUT, {}, SIM_IN)
    barrier.update(report("lidar", {CLOCK: 6}, {SCAN: 6}))
    assert not barrier.ready({CLOCK: 6}, {}, SIM_IN)
    barrier.leave("planner")                                  # it died: nobody waits for its scan 6
    assert barrier.ready({CLOCK: 6}, {}, SIM_IN)
    barrier.update(report("planner", {}, {}, subscribed=(SCAN,), run=2))
    assert barrier.ready({CLOCK: 6}, {}, SIM_IN) and "planner" in barrier.members


def test_a_participant_that_holds_stops_the_run():
    barrier = barrier_with(report("navigate", {CLOCK: 5}, {}, hold=True))
    assert not barrier.ready(SIM_OUT, {}, SIM_IN)
    assert barrier.waiting_on(SIM_OUT) == ["navigate (held the run: it is over)"]
    barrier.leave("navigate")                   # it stopped before the sim did: the run stays over
    assert not barrier.ready(SIM_OUT, {}, SIM_IN)


def test_wildcard_subscriptions_match_like_zenoh_key_expressions():
    assert matches("omninav/r1/*", SCAN) and not matches("omninav/*", SCAN)
    assert matches("omninav/**", SCAN) and matches(SCAN, SCAN) and not matches(ODOM, SCAN)
    barrier = barrier_with(report("lidar", {CLOCK: 5}, {SCAN: 5}))
    assert barrier.ready(SIM_OUT, {}, SIM_IN)
    barrier.update(report("view", {SCAN: 4}, {}, subscribed=("omninav/r1/*",)))
    barrier.ready(SIM_OUT, {}, SIM_IN)
    assert "view" in barrier.pending                          # not admitted while behind on scan
    barrier.update(report("view", {SCAN: 5}, {}, subscribed=("omninav/r1/*",)))
    assert barrier.ready(SIM_OUT, {}, SIM_IN) and "view" in barrier.members


def test_the_launcher_setting_travels_in_the_environment():
    assert Lockstep.from_env({}) is None
    assert Lockstep.from_env({"OMNINAV_LOCKSTEP": "-"}) == Lockstep(())
    assert Lockstep.from_env({"OMNINAV_LOCKSTEP": Lockstep(("a", "b")).env_value()}) == Lockstep(("a", "b"))
