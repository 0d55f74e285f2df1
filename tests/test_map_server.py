"""map_server and `omninav map save | show`: the node in-process (answers `get` with the file's grid,
publishes once at start or on the sim clock, refuses bad files); served over the bus and saved back
to an equal file; pictures of maps with their origin and yaw honoured; bad inputs fail clearly."""
import math

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from conftest import SHARED_DATA, wait_until
from omninav.cli.main import main as omninav
from omninav.cli.map import UNKNOWN_SHADE, draw_grid
from omninav.schemas import decode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Header, MapMetaData, OccupancyGrid, Pose2D
from omninav.services.demo.talker import Talker, TalkerParams
from omninav.services.map_server.mapio import MapError, load_map, save_map
from omninav.geometry.grid import cell_to_world
from omninav.services.map_server.node import MapServerNode, MapServerParams
from omninav.services.runtime.inprocess import InProcessRunner
from omninav.parameters.declare import ParamError
from omninav.services.runtime.run import build_node
from omninav.services.runtime.zenoh_config import open_client

MAP_KEY = KeyLayout("r1").robot("map")
WILLOW = SHARED_DATA / "maps" / "willow-full-0.05.yaml"
EXIT_TIMEOUT_S = 60


def a_grid(origin=Pose2D(-1.5, 2.0, 0.3), resolution=0.1) -> OccupancyGrid:
    """12 x 9 cells: walls round the edge, free inside, an unknown block and a pillar."""
    data = np.zeros((9, 12), np.int8)
    data[[0, -1], :] = data[:, [0, -1]] = 100
    data[2:5, 6:10] = -1
    data[6, 3] = 100
    info = MapMetaData(resolution=resolution, width=12, height=9, origin=origin)
    return OccupancyGrid(header=Header(frame_id="map"), info=info, data=data)


def written_map(tmp_path, grid=None):
    return save_map(grid if grid is not None else a_grid(), tmp_path / "small")


def assert_same_map(a: OccupancyGrid, b: OccupancyGrid) -> None:
    assert (a.info.width, a.info.height, a.info.resolution) == (b.info.width, b.info.height, b.info.resolution)
    assert (a.info.origin.x, a.info.origin.y, a.info.origin.theta) == (b.info.origin.x, b.info.origin.y,
                                                                      b.info.origin.theta)
    np.testing.assert_array_equal(a.data, b.data)


# ---------------------------------------------------------------- the node in-process

def test_get_on_the_map_key_answers_the_files_grid(tmp_path):
    path = written_map(tmp_path)
    node = MapServerNode(MapServerParams(yaml_filename=str(path), frame_id="world"))
    reply = node.answer(MAP_KEY, {})
    assert isinstance(reply, OccupancyGrid) and reply.header.frame_id == "world"
    assert_same_map(reply, load_map(path))
    assert_same_map(reply, a_grid())
    assert node.inputs == []            # no clock needed to serve the map


def _maps_published(runner) -> list[OccupancyGrid]:
    maps = []
    runner.tap(lambda key, payload, stamp: maps.append(decode(payload, OccupancyGrid)) if key == MAP_KEY else None)
    return maps


def test_once_at_start_in_a_run_whatever_the_clock_does(tmp_path):
    path = written_map(tmp_path)
    server = MapServerNode(MapServerParams(yaml_filename=str(path)))
    runner = InProcessRunner([Talker(TalkerParams(clock_hz=100.0)), server])
    maps = _maps_published(runner)
    runner.run_until(lambda: False, max_steps=30)
    assert len(maps) == 1
    assert (maps[0].header.stamp_ns, maps[0].header.seq) == (0, 1)
    assert_same_map(maps[0], a_grid())
    assert server.answer(MAP_KEY, {}).header.seq == 1


def test_a_publish_period_republishes_on_the_sim_clock(tmp_path):
    path = written_map(tmp_path)
    server = MapServerNode(MapServerParams(yaml_filename=str(path), publish_period_s=0.05))
    assert server.pace_s() is None and [i.key for i in server.inputs] == ["omninav/sim/clock"]
    runner = InProcessRunner([Talker(TalkerParams(clock_hz=100.0)), server])
    maps = _maps_published(runner)
    runner.run_until(lambda: False, max_steps=20)      # clocks at 10, 20, ... 200 ms
    assert [m.header.stamp_ns for m in maps] == [10_000_000, 60_000_000, 110_000_000, 160_000_000]
    assert [m.header.seq for m in maps] == [1, 2, 3, 4]
    for published in maps:
        assert_same_map(published, a_grid())
    current = server.answer(MAP_KEY, {})
    assert (current.header.stamp_ns, current.header.seq) == (160_000_000, 4)


def test_a_missing_or_broken_map_is_refused_naming_the_file(tmp_path):
    missing = tmp_path / "nowhere.yaml"
    with pytest.raises(MapError, match=f"yaml_filename: {missing}: no such file"):
        MapServerNode(MapServerParams(yaml_filename=str(missing)))
    broken = tmp_path / "broken.yaml"
    broken.write_text("image: broken.pgm\nresolution: [oops\n")
    with pytest.raises(ValueError, match=f"{broken}: not valid YAML"):
        build_node("map_server", overrides={"yaml_filename": str(broken)})
    no_image = written_map(tmp_path)
    no_image.with_suffix(".pgm").unlink()
    with pytest.raises(MapError, match=r"small\.pgm: no such file"):
        build_node("map_server", overrides={"yaml_filename": str(no_image)})
    with pytest.raises(ParamError, match="yaml_filename must be non-empty"):
        build_node("map_server")
    with pytest.raises(ParamError, match="publish_period_s must be ≥ 0, got -1.0"):
        build_node("map_server", overrides={"yaml_filename": str(no_image), "publish_period_s": -1.0})


# ---------------------------------------------------------------- over the bus

def _finished(processes, proc) -> tuple[int, str]:
    return proc.wait(EXIT_TIMEOUT_S), processes.log_of(proc)


def test_served_map_is_published_answered_and_saved_back_equal(processes, router_endpoint, tmp_path):
    original = WILLOW if WILLOW.exists() else written_map(tmp_path)
    expected = load_map(original)
    heard = []
    with open_client(router_endpoint) as session:
        # subscribed before the server starts: the publication at start must reach it
        sub = session.declare_subscriber(MAP_KEY, lambda s: heard.append(s.payload.to_bytes()))
        server = processes.omninav("run", "map_server", "--set", f"yaml_filename={original}")

        def answered():
            return any(r.ok is not None for r in session.get(MAP_KEY, timeout=5.0))

        wait_until(answered, 60, interval=0.2, what="map_server to answer get")
        wait_until(lambda: heard, 30, what="the map published at start")
        sub.undeclare()
    published = decode(heard[0], OccupancyGrid, key=MAP_KEY)
    assert (published.header.stamp_ns, published.header.seq, published.header.frame_id) == (0, 1, "map")
    assert_same_map(published, expected)

    code, out = _finished(processes, processes.omninav("get", MAP_KEY, "--timeout", "30"))
    assert code == 0, out
    assert f"--- {MAP_KEY} (OccupancyGrid)" in out
    assert f"width: {expected.info.width}" in out and f"height: {expected.info.height}" in out
    assert f"resolution: {expected.info.resolution}" in out

    target = tmp_path / "saved" / "x"
    code, out = _finished(processes, processes.omninav("map", "save", "-o", str(target), "--timeout", "30"))
    assert code == 0, out
    assert f"wrote {target}.yaml and {target}.pgm (mode trinary): " \
           f"{expected.info.width} x {expected.info.height} cells at {expected.info.resolution:g} m/cell" in out
    assert_same_map(load_map(f"{target}.yaml"), expected)

    before = (target.with_suffix(".yaml").read_bytes(), target.with_suffix(".pgm").read_bytes())
    code, out = _finished(processes, processes.omninav("map", "save", "-o", str(target), "--timeout", "30"))
    assert code == 1 and "already exist; choose another -o or add --force" in out, out
    assert (target.with_suffix(".yaml").read_bytes(), target.with_suffix(".pgm").read_bytes()) == before
    code, out = _finished(processes, processes.omninav("map", "save", "-o", str(target), "--force",
                                                       "--timeout", "30"))
    assert code == 0, out
    assert_same_map(load_map(f"{target}.yaml"), expected)
    assert server.poll() is None, processes.log_of(server)


def test_run_with_a_missing_map_exits_2_naming_it(processes, tmp_path):
    missing = tmp_path / "gone.yaml"
    code, out = _finished(processes, processes.omninav("run", "map_server", "--set", f"yaml_filename={missing}"))
    assert code == 2, out
    assert f"yaml_filename: {missing}: no such file" in out and "Traceback" not in out


def test_save_without_a_server_fails_clearly_and_writes_nothing(router_endpoint, tmp_path, capsys):
    target = tmp_path / "none"
    code = omninav(["map", "save", "-o", str(target), "--timeout", "1", "--router", router_endpoint])
    assert code == 1
    assert f"omninav map save: no reply on {MAP_KEY} within 1 s" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_save_refuses_bad_arguments_before_connecting(tmp_path, capsys):
    # the router endpoint is a closed port: every one of these must fail before trying it
    router = "tcp/127.0.0.1:9"
    for args, message in ((["--timeout", "0"], "--timeout must be positive"),
                          (["-o", str(tmp_path)], f"-o {tmp_path} is a folder"),
                          (["--key", "omninav/r1/m?p"], "invalid key expression 'omninav/r1/m?p'")):
        assert omninav(["map", "save", "--router", router, *args]) == 2
        assert message in capsys.readouterr().err
    (tmp_path / "taken.pgm").write_bytes(b"mine")
    assert omninav(["map", "save", "-o", str(tmp_path / "taken"), "--router", router]) == 1
    assert f"{tmp_path / 'taken.pgm'} already exists" in capsys.readouterr().err
    assert (tmp_path / "taken.pgm").read_bytes() == b"mine"


# ---------------------------------------------------------------- pictures

def _colour_at(fig: Figure, ax, points) -> np.ndarray:
    """Grey level (0..1) of the rendered picture at map-frame points."""
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    pixels = np.asarray(canvas.buffer_rgba())[:, :, :3].mean(axis=2) / 255
    xy = ax.transData.transform(np.asarray(points, float))
    rows = (pixels.shape[0] - xy[:, 1]).astype(int)
    return pixels[rows, xy[:, 0].astype(int)]


@pytest.mark.parametrize("origin", [Pose2D(0.0, 0.0, 0.0), Pose2D(3.0, -2.0, math.pi / 2), Pose2D(-4.0, 1.0, 2.5)])
def test_cells_are_drawn_where_the_origin_and_yaw_put_them(origin):
    grid = a_grid(origin, resolution=1.0)
    fig = Figure(figsize=(6, 6), dpi=100)
    ax = fig.add_subplot()
    ax.set_aspect("equal")
    draw_grid(ax, grid)
    cells = {"occupied": (6, 3), "free": (6, 6), "unknown": (3, 7), "wall": (0, 5)}
    xs, ys = cell_to_world(grid.info, [r for r, _ in cells.values()], [c for _, c in cells.values()])
    shade = dict(zip(cells, _colour_at(fig, ax, np.column_stack([xs, ys]))))
    assert shade["occupied"] == pytest.approx(0.0, abs=0.02) and shade["wall"] == pytest.approx(0.0, abs=0.02)
    assert shade["free"] == pytest.approx(1.0, abs=0.02)
    assert shade["unknown"] == pytest.approx(UNKNOWN_SHADE, abs=0.02)


def test_map_show_writes_a_picture_of_a_map_file(tmp_path, capsys):
    path = written_map(tmp_path, a_grid(Pose2D(2.0, 1.0, math.pi)))
    picture = tmp_path / "pics" / "small.png"
    assert omninav(["map", "show", str(path), "-o", str(picture)]) == 0
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "12 x 9 cells at 0.1 m/cell" in capsys.readouterr().out


def test_map_show_refuses_bad_inputs_clearly(tmp_path, capsys):
    path = written_map(tmp_path)
    image_before = path.with_suffix(".pgm").read_bytes()
    broken = tmp_path / "broken.yaml"
    broken.write_text("image: small.pgm\nresolution: -1\norigin: [0, 0, 0]\nnegate: 0\n"
                      "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    for args, message in (([str(tmp_path / "nope.yaml"), "-o", str(tmp_path / "a.png")], "nope.yaml: no such file"),
                          ([str(broken), "-o", str(tmp_path / "a.png")], "key 'resolution': expected a positive"),
                          ([str(path), "-o", str(path.with_suffix(".pgm"))], "is the map's own file"),
                          ([str(path), "-o", str(tmp_path / "a.bogus")], "cannot write")):
        assert omninav(["map", "show", *args]) == 2
        err = capsys.readouterr().err
        assert err.startswith("omninav map show: ") and message in err, err
    assert path.with_suffix(".pgm").read_bytes() == image_before
    assert not (tmp_path / "a.png").exists()
