"""`omninav view --rerun` seen in a real browser, and `omninav export --rerun`.

A short mission in the demo's room is recorded in-process, then replayed live onto the bus into the
view; headless Chromium opens the URL the view prints, and its screenshots must show the map (free
and wall colours where the map is), the robot, the scan and the global plan: pixels, not just a page. The export of
the same recording must be a file Rerun loads, with one row per recorded message.

The README's picture: `OMNINAV_VIEW_PNG=docs/images/view.png .venv/bin/python -m pytest -q
tests/test_view_rerun.py -k browser` writes the screenshot the test accepted.
"""
import os
import re
import socket
import subprocess
import time
from collections import Counter

import numpy as np
import pytest

from omninav.cli.main import main as cli_main
from omninav.schemas.keys import KeyLayout
from omninav.services.recorder.mcap_io import read_records
from omninav.services.view.convert import ROUTES, Converter, RouteTable
from omninav.services.view.rerun_node import RERUN_BINARY, listening
from omninav.services.view.rerun_scene import (FREE_RGB, OCCUPIED_RGB, PLAN_RGB, RERUN_ROUTES, ROBOT_RGB, SCAN_RGB, UNKNOWN_RGB,
                                               occupancy_colours, scan_points)
from omninav.schemas import messages as m

from conftest import free_port, wait_alive, wait_until
from headless_chromium import CHROMIUM, Chromium
from view_fixtures import stack_messages

MISSION = ["navigate", "--world", "room", "--in-process", "--goal", "3.2", "0.9", "30", "--timeout", "3"]
SHOWN_WITHIN_S = 180.0      # wall s for the page to show the mission (Wasm compiled in SwiftShader on 2 busy cores)


@pytest.fixture(scope="module")
def mission(tmp_path_factory):
    """The recording of a short mission (it cannot arrive in 3 s: the robot is on its way, most of its plan still ahead)."""
    out = tmp_path_factory.mktemp("mission")
    cli_main([*MISSION, "-o", str(out), "--json"])
    return out / "run.mcap"


def test_the_rerun_routes_show_what_the_foxglove_view_shows():
    assert [r.source for r in RERUN_ROUTES] == [r.source for r in ROUTES]
    routes, converter = RouteTable(KeyLayout("r1"), RERUN_ROUTES), Converter()
    for key, msg in stack_messages(0).items():
        assert converter.outputs(routes.route_for(key), msg), key


def test_map_colours_and_scan_points():
    colours = occupancy_colours(np.array([[-1, 0, 100]], np.int8))
    assert colours[0].tolist() == [list(UNKNOWN_RGB), list(FREE_RGB), list(OCCUPIED_RGB)]
    scan = m.LaserScan(m.Header(frame_id="laser"), 0.0, np.pi / 2, np.pi / 2, range_min=0.1, range_max=5.0,
                       ranges=np.array([1.0, 2.0, np.inf], np.float32))
    assert np.allclose(scan_points(scan), [[1.0, 0.0], [0.0, 2.0]])     # the inf return is not drawn


# ---------------------------------------------------------------- what a screenshot shows

def colour(pixels: np.ndarray, rgb, tolerance: int) -> np.ndarray:
    return np.all(np.abs(pixels.astype(int) - np.array(rgb)) <= tolerance, axis=-1)


def drawn(pixels: np.ndarray) -> dict[str, int]:
    """Pixels of each colour in the map's area (the box of the free cells' colour, widened by a
    tenth: the walls are around the free space), and of the walls' colour outside it."""
    free = colour(pixels, FREE_RGB, 6)
    ys, xs = np.nonzero(free)
    if len(xs) < 1000:
        return {"free": int(len(xs))}
    (x0, x1), (y0, y1) = np.percentile(xs, [1, 99]), np.percentile(ys, [1, 99])
    mx, my = (x1 - x0) / 10 + 5, (y1 - y0) / 10 + 5
    area = np.zeros(free.shape, bool)
    area[max(int(y0 - my), 0):int(y1 + my) + 1, max(int(x0 - mx), 0):int(x1 + mx) + 1] = True
    walls = colour(pixels, OCCUPIED_RGB, 12)
    return {"free": int((free & area).sum()), "walls": int((walls & area).sum()),
            "walls_elsewhere": int((walls & ~area).sum()), "robot": int((colour(pixels, ROBOT_RGB, 40) & area).sum()),
            "scan": int((colour(pixels, SCAN_RGB, 40) & area).sum()),
            "plan": int((colour(pixels, PLAN_RGB, 40) & area).sum())}


def shows_the_mission(counts: dict[str, int]) -> bool:
    return (counts["free"] >= 5000 and counts.get("walls", 0) >= 500 and counts["walls_elsewhere"] <= counts["walls"] / 20
            and counts["robot"] >= 30 and counts["scan"] >= 30 and counts["plan"] >= 30) if "walls" in counts else False


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (apt-get install chromium; .ci/run does)")
def test_the_browser_shows_the_map_the_robot_the_scan_and_the_plan(mission, processes, router_endpoint, tmp_path):
    web_port, grpc_port = free_port(), free_port()
    # rerun's own settings (its analytics opt-in file) go to this test's folder, not the user's home
    xdg = {"XDG_CONFIG_HOME": str(tmp_path / "config"), "XDG_DATA_HOME": str(tmp_path / "data")}
    view = processes.omninav("view", "--rerun", "--port", str(web_port), "--grpc-port", str(grpc_port),
                             "--router", router_endpoint, env=xdg)
    url = wait_until(lambda: re.search(r"view: open (\S+)", processes.log_of(view)), 120,
                     what="the view's URL").group(1)
    assert url.startswith(f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}")
    wait_alive(router_endpoint, ["rerun_view"])
    with Chromium(tmp_path / "chromium", tmp_path / "chromium.log") as browser:
        browser.open(url)
        replay = processes.omninav("replay", str(mission))      # the mission, live onto the bus
        assert replay.wait(120) == 0, processes.log_of(replay)
        deadline, counts = time.monotonic() + SHOWN_WITHIN_S, {}
        while time.monotonic() < deadline:
            png = browser.screenshot_png()
            counts = drawn(browser.pixels(png))
            if shows_the_mission(counts):
                break
            time.sleep(1.0)
        (tmp_path / "view.png").write_bytes(png)
    assert shows_the_mission(counts), f"the page does not show the mission: {counts}; see {tmp_path / 'view.png'}"
    if os.environ.get("OMNINAV_VIEW_PNG"):
        with open(os.environ["OMNINAV_VIEW_PNG"], "wb") as f:
            f.write(png)
    assert processes.stop(view) == 0
    assert not listening(web_port) and not listening(grpc_port)     # the rerun binary stopped with the view


def test_a_taken_port_stops_the_rerun_view_with_one_line_saying_so(processes, router_endpoint):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        view = processes.omninav("view", "--rerun", "--port", str(port), "--grpc-port", "0", "--router", router_endpoint)
        assert view.wait(120) == 1
    assert f"127.0.0.1:{port} is taken" in processes.log_of(view)


def test_export_rerun_writes_a_file_rerun_loads_row_by_row(mission, tmp_path, capsys):
    exported = tmp_path / "run.rrd"
    assert cli_main(["export", "--rerun", str(mission), "-o", str(exported)]) == 0
    assert "world/robot" in capsys.readouterr().out
    verify = subprocess.run([RERUN_BINARY, "rrd", "verify", str(exported)], capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr
    printed = subprocess.run([RERUN_BINARY, "rrd", "print", str(exported)], capture_output=True, text=True,
                             timeout=120).stdout
    rows: Counter[str] = Counter()
    for found in re.finditer(r"with (\d+) rows .*? - (/\S+) - ", printed):
        rows[found.group(2)] += int(found.group(1))
    recorded = Counter(record.key for record in read_records(mission))
    key = KeyLayout("r1").resolve
    assert rows["/world/robot"] == recorded[key("sim/truth")]
    assert rows["/world/map/odom/base_link/laser/scan"] == recorded[key("scan")]
    assert rows["/world/map/odom/base_link"] == recorded[key("odom")]
    assert rows["/world/map/plan"] == recorded[key("plan")]
    assert 1 <= rows["/world/map/occupancy"] <= recorded[key("map")]
    assert cli_main(["export", "--rerun", str(mission), "-o", str(exported)]) == 2     # never overwrites
