"""services/runtime/child.py: work in a child process, its answers read as they come, also by a
third process they are relayed to (`navigate` hands its child's preparation to `up --prepared`)."""
import os
from pathlib import Path

import pytest

from omninav.services.runtime.child import Answers, Child, ChildDied


def count_then_fail(n: int):
    """Run in the child: 0..n-1, then an error."""
    yield from range(n)
    raise ValueError("nothing more to count")


def test_a_childs_answers_relayed_onto_a_pipe_are_read_there_in_order_with_its_error(monkeypatch):
    monkeypatch.setenv("PYTHONPATH", str(Path(__file__).parent))      # the child imports this module
    with Child(count_then_fail, 3) as child:
        assert child.next() == 0
        read_end, write_end = os.pipe()
        child.relay(open(write_end, "wb"))
        with open(read_end, "rb") as stream:
            relayed = Answers(stream, "count_then_fail")
            assert [relayed.next(), relayed.next()] == [1, 2]
            with pytest.raises(ValueError, match="nothing more to count"):
                relayed.next()
            with pytest.raises(ChildDied, match="count_then_fail ended before it answered"):
                relayed.next()      # the child is gone, the relay closed the pipe
