"""`omninav bench transport --json`: a short run gives every figure, loses nothing and leaves no peer behind."""
import json
import os

import pytest

from omninav.services.runtime.zenoh_config import SHM_ENV, client_config, router_config

FIELDS = ("rtt_median_ms", "rtt_p99_ms", "rtt_raw_median_ms", "rtt_raw_p99_ms", "msgs_per_s", "msgs_raw_per_s",
          "grid_get_ms", "grid_get_raw_ms")


def test_short_bench_reports_sane_figures_and_stops_its_peer(processes_no_router):
    bench = processes_no_router.omninav("bench", "transport", "--json", "--round-trips", "30",
                                        "--messages", "300", "--gets", "3", "--warmup", "3")
    code = bench.wait(120)
    out = processes_no_router.log_of(bench)
    assert code == 0, out
    figures = json.loads(out.strip().splitlines()[-1])
    for name in FIELDS:
        assert figures[name] > 0, name
    assert figures["rtt_p99_ms"] >= figures["rtt_median_ms"]
    assert figures["lost"] == 0 and figures["lost_raw"] == 0
    assert figures["round_trips"] == 30 and figures["messages"] == 300 and figures["gets"] == 3
    assert figures["grid_bytes"] > 2000 * 2000 and figures["scan_bytes"] > 360 * 4 * 2
    assert isinstance(figures["shared_memory"], bool)
    with pytest.raises(ProcessLookupError):  # the peer ran in the bench's process group; none is left
        os.killpg(bench.pid, 0)


def test_bad_count_is_refused(processes_no_router):
    bench = processes_no_router.omninav("bench", "transport", "--gets", "0")
    assert bench.wait(60) == 2
    assert "--gets must be at least 1" in processes_no_router.log_of(bench)


def test_shared_memory_switch(monkeypatch):
    def shm(conf):
        return json.loads(conf.get_json("transport/shared_memory/enabled"))

    monkeypatch.delenv(SHM_ENV, raising=False)
    assert shm(client_config("tcp/127.0.0.1:7447")) is True  # zenoh's default
    monkeypatch.setenv(SHM_ENV, "off")
    assert shm(client_config("tcp/127.0.0.1:7447")) is False
    assert shm(router_config("tcp/127.0.0.1:7447")) is False
    monkeypatch.setenv(SHM_ENV, "maybe")
    with pytest.raises(ValueError, match="OMNINAV_SHM='maybe'"):
        client_config("tcp/127.0.0.1:7447")
