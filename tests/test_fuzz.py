"""No message kills a service: every registered service, built in-process, takes random bytes,
messages of the wrong type and messages with one field at an edge value on each of its inputs
(experiments/fuzz.py); nothing escapes, every refusal is counted."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import REPO
from omninav.experiments.fuzz import example, fuzz_node, mutated_payloads
from omninav.schemas import MessageError, all_types, decode, encode
from omninav.services.runtime.service_registry import SERVICES
from omninav.services.runtime.run import build_node

NOT_FUZZED = {"recorder"}       # it never decodes: it writes whatever arrives, untouched
PARAMS = {"map_server": {"yaml_filename": str(REPO / "compose" / "maps" / "room.yaml")}}


@pytest.mark.parametrize("cls", [cls for _, cls in sorted(all_types().items())], ids=lambda c: c.__name__)
def test_every_type_has_a_sound_example_and_its_mutations_decode_or_are_refused_cleanly(cls):
    assert type(decode(encode(example(cls)))) is cls
    for payload in mutated_payloads(example(cls)):
        try:
            decode(payload, cls)
        except MessageError:
            pass


@pytest.mark.parametrize("service", sorted(set(SERVICES) - NOT_FUZZED))
def test_no_input_kills_the_service(service):
    node = build_node(service, overrides=PARAMS.get(service))
    result = fuzz_node(node, np.random.default_rng(0), random_per_key=10)
    assert node.inputs == [] or result.sent > 0
    assert result.deaths == [] and result.rejected + result.handled == result.sent
    malformed = sum(v for k, v in node.counters.items() if k.startswith("malformed/"))
    assert malformed >= result.rejected        # the codec's refusals, and those the node's own checks made
    assert not result.handler_errors, result.handler_errors     # bad input is refused, not crashed on
