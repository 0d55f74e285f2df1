"""`omninav demo` (what `make demo` runs) completes: recorded, replayed byte for byte, drawn."""
from omninav.services.recorder.mcap_io import read_records


def test_demo_runs_records_replays_and_draws(processes_no_router, tmp_path):
    out = tmp_path / "demo"
    # 1.1 m ahead of the room's start, turned 30°: the whole mission (plan, drive, approach, turn) in
    # 5.6 s of sim, so the demo's steps after it come sooner
    demo = processes_no_router.omninav("demo", "-o", str(out), "--goal", "2.3", "0.9", "30")
    assert demo.wait(300) == 0, processes_no_router.log_of(demo)
    log = processes_no_router.log_of(demo)
    assert "replay run.mcap --into chassis --compare\n   ok" in log
    assert {"omninav/r1/scan", "omninav/r1/odom"} <= {r.key for r in read_records(out / "run.mcap")}
    assert (out / "run.png").read_bytes()[:4] == b"\x89PNG"
