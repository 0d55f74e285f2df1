from hypothesis import given
from hypothesis import strategies as st

from omninav.services.runtime.merge import StampMerger, order_key


@st.composite
def streams_and_interleaving(draw):
    n = draw(st.integers(1, 4))
    streams = []
    for _ in range(n):
        stamps = sorted(draw(st.lists(st.integers(0, 30), min_size=1, max_size=12)))
        streams.append(stamps)
    # an arrival order that keeps each stream's own order (one publisher per key is FIFO)
    cursors = [0] * n
    arrivals = []
    while any(c < len(s) for c, s in zip(cursors, streams)):
        live = [i for i in range(n) if cursors[i] < len(streams[i])]
        i = draw(st.sampled_from(live))
        arrivals.append((i, streams[i][cursors[i]], cursors[i]))
        cursors[i] += 1
    return n, arrivals


@given(streams_and_interleaving())
def test_release_order_equals_sorted_order_whatever_the_arrival(case):
    n, arrivals = case
    merger = StampMerger([True] * n)
    released = []
    for stream, stamp, seq in arrivals:
        assert merger.push(stream, stamp, (stream, stamp, seq))
        released += merger.pop_ready()
    released += merger.drain()
    expected = sorted(((s, t, q) for s, t, q in arrivals), key=lambda x: order_key(x[1], x[0], x[2]))
    assert released == expected


def test_waits_for_a_silent_synced_stream_but_not_for_a_sporadic_one():
    merger = StampMerger([True, True, False])
    merger.push(0, 10, "a")
    assert merger.pop_ready() == []          # stream 1 has said nothing yet
    merger.push(1, 12, "b")
    assert merger.pop_ready() == ["a"]       # stream 2 is sporadic: nobody waits for it
    merger.push(2, 11, "goal")
    assert merger.pop_ready() == []          # waits for stream 0 to pass 11
    merger.push(0, 20, "c")
    assert merger.pop_ready() == ["goal", "b"]


def test_late_item_is_reported():
    merger = StampMerger([True, False])
    merger.push(0, 10, "a")
    assert merger.pop_ready() == ["a"]
    assert merger.push(1, 5, "late") is False
    assert merger.pop_oldest() == "late"
